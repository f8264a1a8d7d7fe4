//! The shard contract end to end (`core/src/shard/`): two toy sharded nodes run by the
//! engine under every `ShardMode` — every chunk here, one shard of one node into a disk
//! cache (`relume shard`), peer processes (threads talking over channels) — give the bytes
//! of `run_standalone`; the report's `shards` says where every chunk came from; a summation
//! whose bits depend on its order has the same bits for any shard count; a cancelled run
//! resumes from the chunks it finished; a changed parameter leaves no stale chunk.

use relume_core::shard::{ShardMessage, ShardPayload, ShardPeers, ShardStats};
use relume_core::{
    node, outputs, run_standalone, CancelToken, DiskPolicy, Engine, Graph, Hash, NodeError, ParamValue, Params, PortValue, Registry,
    RunCtx, RunError, RunOptions, RunResult, ShardMode, ShardSpec,
};
use std::ops::Range;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError, Sender};
use std::sync::Mutex;
use std::time::{Duration, Instant};

// ---------------------------------------------------------------------------------------
// Port types

/// Numbers in item order: a partial result of `Squares` and its output.
#[derive(Clone, Debug, PartialEq)]
pub struct Floats(Vec<f64>);

impl PortValue for Floats {
    const NAME: &'static str = "Floats";
    const COLOR: [u8; 3] = [10, 20, 30];
    fn byte_size(&self) -> usize {
        self.0.len() * 8
    }
    fn encode(&self) -> Vec<u8> {
        self.0.iter().flat_map(|x| x.to_le_bytes()).collect()
    }
    fn decode(b: &[u8]) -> Option<Self> {
        if !b.len().is_multiple_of(8) {
            return None;
        }
        Some(Floats(b.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("chunks of 8 bytes"))).collect()))
    }
}

/// One single-precision sum: a partial result of `HarmonicSum` and its output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sum32(f32);

impl PortValue for Sum32 {
    const NAME: &'static str = "Sum32";
    const COLOR: [u8; 3] = [30, 20, 10];
    fn byte_size(&self) -> usize {
        4
    }
    fn encode(&self) -> Vec<u8> {
        self.0.to_le_bytes().to_vec()
    }
    fn decode(b: &[u8]) -> Option<Self> {
        Some(Sum32(f32::from_le_bytes(b.try_into().ok()?)))
    }
}

// ---------------------------------------------------------------------------------------
// Run counters: how many times each node's `run_items` really ran, one counter per test
// (tests run in parallel in one process), picked by the nodes' `tag` parameter.

static RUNS: [AtomicU64; 32] = [const { AtomicU64::new(0) }; 32];

fn runs(tag: u32) -> u64 {
    RUNS[tag as usize].load(Ordering::SeqCst)
}

/// The counter of `tag` before and after `f`: how many chunks `f` computed.
fn counting<T>(tag: u32, f: impl FnOnce() -> T) -> (T, u64) {
    let before = runs(tag);
    let out = f();
    (out, runs(tag) - before)
}

// ---------------------------------------------------------------------------------------
// Nodes

/// The squares of 0..n, times `scale`, computed in chunks of `chunk` items and concatenated
/// in item order.
#[derive(Params)]
pub struct Squares {
    /// work items
    #[param(default = 100, range = 0..=1_000_000)]
    pub n: u64,
    /// items per chunk
    #[param(default = 8, range = 1..=1_000_000)]
    pub chunk: u64,
    /// a factor on every square (changes every chunk's content)
    #[param(default = 1.0, range = -1000.0..=1000.0)]
    pub scale: f64,
    /// which run counter the chunks add to
    #[param(default = 0, range = 0..=31)]
    pub tag: u32,
}

outputs!(pub SquaresOut { out: Floats });

#[node(category = "test", sharded)]
impl Squares {
    fn shard(&self, _: &()) -> Result<ShardSpec, NodeError> {
        Ok(ShardSpec::new(self.n, self.chunk))
    }

    fn run_items(&self, _: &(), items: Range<u64>, _cx: &RunCtx) -> Result<Floats, NodeError> {
        RUNS[self.tag as usize].fetch_add(1, Ordering::SeqCst);
        Ok(Floats(items.map(|i| self.scale * (i * i) as f64).collect()))
    }

    fn gather(&self, _: &(), parts: &[&Floats], _cx: &RunCtx) -> Result<SquaresOut, NodeError> {
        Ok(SquaresOut { out: Floats(parts.iter().flat_map(|p| p.0.iter().copied()).collect()) })
    }
}

/// Σ 1/(i+1) over 0..n in f32: a partial sum per chunk, the partials summed in chunk order.
/// Floating-point addition is not associative, so the bits depend on that order.
#[derive(Params)]
pub struct HarmonicSum {
    /// work items
    #[param(default = 10000, range = 0..=100_000_000)]
    pub n: u64,
    /// items per chunk
    #[param(default = 1000, range = 1..=100_000_000)]
    pub chunk: u64,
    /// which run counter the chunks add to
    #[param(default = 0, range = 0..=31)]
    pub tag: u32,
}

outputs!(pub HarmonicSumOut { sum: Sum32 });

/// Σ 1/(i+1) over `items`, in item order, in f32.
fn harmonic(items: Range<u64>) -> f32 {
    items.fold(0.0f32, |s, i| s + 1.0 / (i + 1) as f32)
}

#[node(category = "test", sharded)]
impl HarmonicSum {
    fn shard(&self, _: &()) -> Result<ShardSpec, NodeError> {
        Ok(ShardSpec::new(self.n, self.chunk))
    }

    fn run_items(&self, _: &(), items: Range<u64>, _cx: &RunCtx) -> Result<Sum32, NodeError> {
        RUNS[self.tag as usize].fetch_add(1, Ordering::SeqCst);
        Ok(Sum32(harmonic(items)))
    }

    fn gather(&self, _: &(), parts: &[&Sum32], _cx: &RunCtx) -> Result<HarmonicSumOut, NodeError> {
        Ok(HarmonicSumOut { sum: Sum32(parts.iter().fold(0.0f32, |s, p| s + p.0)) })
    }
}

/// The token `Interrupted` cancels (the run's own: the test puts it here before the run).
static TO_CANCEL: Mutex<Option<CancelToken>> = Mutex::new(None);

/// Squares that cancel the run right after finishing chunk `stop_after` (once: the token is
/// taken from `TO_CANCEL`).
#[derive(Params)]
pub struct Interrupted {
    /// work items
    #[param(default = 100, range = 0..=1_000_000)]
    pub n: u64,
    /// items per chunk
    #[param(default = 8, range = 1..=1_000_000)]
    pub chunk: u64,
    /// the chunk after which the run is cancelled
    #[param(default = 4, range = 0..=1_000_000)]
    pub stop_after: u64,
    /// which run counter the chunks add to
    #[param(default = 0, range = 0..=31)]
    pub tag: u32,
}

outputs!(pub InterruptedOut { out: Floats });

#[node(category = "test", sharded)]
impl Interrupted {
    fn shard(&self, _: &()) -> Result<ShardSpec, NodeError> {
        Ok(ShardSpec::new(self.n, self.chunk))
    }

    fn run_items(&self, _: &(), items: Range<u64>, _cx: &RunCtx) -> Result<Floats, NodeError> {
        RUNS[self.tag as usize].fetch_add(1, Ordering::SeqCst);
        let out = Floats(items.clone().map(|i| (i * i) as f64).collect());
        if items.start / self.chunk == self.stop_after {
            if let Some(token) = TO_CANCEL.lock().unwrap().take() {
                token.cancel();
            }
        }
        Ok(out)
    }

    fn gather(&self, _: &(), parts: &[&Floats], _cx: &RunCtx) -> Result<InterruptedOut, NodeError> {
        Ok(InterruptedOut { out: Floats(parts.iter().flat_map(|p| p.0.iter().copied()).collect()) })
    }
}

fn registry() -> Registry {
    let mut r = Registry::new();
    r.add::<Squares>().add::<HarmonicSum>().add::<Interrupted>();
    r
}

// ---------------------------------------------------------------------------------------
// Helpers

/// A graph of one node `id` of `kind` with `params`, its first output as the graph output
/// `out`.
fn one_node(id: &str, kind: &str, port: &str, params: &str) -> Graph {
    let text = format!(r#"(version: 1, nodes: {{ "{id}": (kind: "{kind}", params: ({params})) }}, outputs: {{ "out": "{id}.{port}" }})"#);
    Graph::parse(&text, None).expect("a valid test graph")
}

fn squares(params: &str) -> Graph {
    one_node("sq", "Squares", "out", params)
}

fn harmonic_graph(params: &str) -> Graph {
    one_node("hs", "HarmonicSum", "sum", params)
}

/// Squares and HarmonicSum side by side (two sharded nodes in one run): outputs `sq`, `hs`.
fn both(sq: &str, hs: &str) -> Graph {
    let text = format!(
        r#"(version: 1, nodes: {{ "sq": (kind: "Squares", params: ({sq})), "hs": (kind: "HarmonicSum", params: ({hs})) }},
           outputs: {{ "sq": "sq.out", "hs": "hs.sum" }})"#
    );
    Graph::parse(&text, None).expect("a valid test graph")
}

fn engine() -> Engine {
    Engine::new(registry())
}

fn cached_engine(dir: &Path) -> Engine {
    Engine::new(registry()).with_disk_cache(dir)
}

/// A normal run (every chunk here, then the gather).
fn run_all(e: &Engine, g: &Graph) -> RunResult {
    e.run(g, &RunOptions::default()).unwrap_or_else(|err| panic!("the run failed: {err}"))
}

/// A `relume shard` run: shard `index` of `count` of node `id`, no outputs.
fn run_shard(e: &Engine, g: &Graph, id: &str, index: u64, count: u64) -> RunResult {
    let opts = RunOptions {
        outputs: Some(vec![]),
        nodes: vec![id.to_string()],
        shards: ShardMode::One { node: id, index, count },
        ..Default::default()
    };
    e.run(g, &opts).unwrap_or_else(|err| panic!("shard {index} of {count} failed: {err}"))
}

/// The report's `shards` of node `id`.
fn stats(r: &RunResult, id: &str) -> ShardStats {
    let node = r.report.node(id).unwrap_or_else(|| panic!("no report line for {id}"));
    node.shards.clone().unwrap_or_else(|| panic!("{id} has no shard stats (status {}, cache {:?})", node.status, node.cache))
}

/// The disk encoding of output `name`.
fn bytes(r: &RunResult, name: &str) -> Vec<u8> {
    r.output(name).unwrap_or_else(|| panic!("no output {name}")).encode()
}

/// The bytes of `N`'s only output run outside any engine.
fn standalone<N: relume_core::Node>(params: &[(&str, ParamValue)]) -> Vec<u8> {
    let e = run_standalone::<N>(params, Path::new("."), &[]).unwrap_or_else(|err| panic!("run_standalone failed: {err}"));
    e.outputs[0].encode()
}

fn int(v: i64) -> ParamValue {
    ParamValue::Int(v)
}

/// `f32` bits of a `Sum32` encoding.
fn sum_bits(b: &[u8]) -> u32 {
    u32::from_le_bytes(b.try_into().expect("a Sum32 is 4 bytes"))
}

fn expected_squares(n: u64, scale: f64) -> Vec<u8> {
    Floats((0..n).map(|i| scale * (i * i) as f64).collect()).encode()
}

// ---------------------------------------------------------------------------------------
// 1. ShardMode::All

#[test]
fn an_engine_run_has_the_bytes_of_run_standalone_and_runs_every_chunk_here() {
    const TAG: u32 = 1;
    let spec = ShardSpec::new(100, 8);
    assert_eq!(spec.chunks(), 13, "the last chunk is short (4 items)");
    let (r, ran) = counting(TAG, || run_all(&engine(), &squares("n: 100, chunk: 8, tag: 1")));
    let alone = standalone::<Squares>(&[("n", int(100)), ("chunk", int(8)), ("tag", int(TAG as i64))]);
    assert_eq!(bytes(&r, "out"), alone, "engine run and run_standalone differ");
    assert_eq!(alone, expected_squares(100, 1.0), "the gather concatenates in item order");
    let s = stats(&r, "sq");
    assert_eq!((s.chunks, s.items, s.here, s.ran, s.cached), (13, 100, 13, 13, 0), "{s:?}");
    assert!(s.received.is_empty() && s.shard.is_none(), "{s:?}");
    assert!(s.ran_ms >= s.max_chunk_ms && s.max_chunk_ms >= 0.0, "{s:?}");
    assert_eq!(ran, 13, "run_items calls in the engine run");

    // The order-sensitive sum too, and no work at all.
    let r = run_all(&engine(), &harmonic_graph("n: 10000, chunk: 1000, tag: 1"));
    assert_eq!(bytes(&r, "out"), standalone::<HarmonicSum>(&[("n", int(10000)), ("chunk", int(1000)), ("tag", int(1))]));
    let s = stats(&r, "hs");
    assert_eq!((s.chunks, s.items, s.here, s.ran, s.cached), (10, 10000, 10, 10, 0), "{s:?}");
    let r = run_all(&engine(), &squares("n: 0, tag: 1"));
    assert_eq!(bytes(&r, "out"), Vec::<u8>::new());
    let s = stats(&r, "sq");
    assert_eq!((s.chunks, s.items, s.here, s.ran), (0, 0, 0, 0), "{s:?}");
}

// ---------------------------------------------------------------------------------------
// 2. ShardMode::One into a shared disk cache, then a normal run gathers

#[test]
fn shards_run_apart_into_one_cache_are_gathered_without_recomputing() {
    const TAG: u32 = 2;
    let g = squares("n: 100, chunk: 8, tag: 2");
    let spec = ShardSpec::new(100, 8);
    let unsharded = bytes(&run_all(&engine(), &g), "out");
    let dir = tempfile::tempdir().unwrap();
    for index in 0..3 {
        let (r, ran) = counting(TAG, || run_shard(&cached_engine(dir.path()), &g, "sq", index, 3));
        assert!(r.outputs.is_empty(), "a shard run gathers nothing");
        let s = stats(&r, "sq");
        let mine = spec.shard_chunks(index, 3).count() as u64;
        assert_eq!((s.chunks, s.here, s.ran, s.cached, s.shard), (13, mine, mine, 0, Some((index, 3))), "shard {index}: {s:?}");
        assert_eq!(ran, mine, "shard {index} computed its own chunks only");
    }
    // A shard run again finds its chunks.
    let (r, ran) = counting(TAG, || run_shard(&cached_engine(dir.path()), &g, "sq", 1, 3));
    let s = stats(&r, "sq");
    assert_eq!((s.here, s.ran, s.cached, ran), (4, 0, 4, 0), "{s:?}");

    let (r, ran) = counting(TAG, || run_all(&cached_engine(dir.path()), &g));
    let s = stats(&r, "sq");
    assert_eq!((s.chunks, s.here, s.cached, s.ran), (13, 13, 13, 0), "the gather found every chunk: {s:?}");
    assert_eq!(ran, 0, "the gather computed nothing");
    assert_eq!(bytes(&r, "out"), unsharded, "gathered shards differ from the unsharded run");

    // Shard 1 never ran: the gather computes exactly its chunks.
    let dir = tempfile::tempdir().unwrap();
    for index in [0, 2] {
        run_shard(&cached_engine(dir.path()), &g, "sq", index, 3);
    }
    let (r, ran) = counting(TAG, || run_all(&cached_engine(dir.path()), &g));
    let missing = spec.shard_chunks(1, 3).count() as u64;
    let s = stats(&r, "sq");
    assert_eq!((s.here, s.ran, s.cached), (13, missing, 13 - missing), "{s:?}");
    assert_eq!(ran, missing, "run_items calls in the gather");
    assert_eq!(bytes(&r, "out"), unsharded);
}

#[test]
fn harmonic_sum_has_the_same_bits_for_any_shard_count_though_its_order_matters() {
    const TAG: u32 = 3;
    let (n, chunk) = (10000u64, 1000u64);
    let g = harmonic_graph("n: 10000, chunk: 1000, tag: 3");
    let spec = ShardSpec::new(n, chunk);
    let unsharded = sum_bits(&bytes(&run_all(&engine(), &g), "out"));
    let chunk_order = (0..spec.chunks()).fold(0.0f32, |s, k| s + harmonic(spec.chunk_items(k)));
    assert_eq!(unsharded, chunk_order.to_bits(), "the gather sums the chunks' partials in chunk order");

    // The order matters: one sequential sum, or partials summed per shard, give other bits.
    assert_ne!(harmonic(0..n).to_bits(), unsharded, "pick n and chunk where the order changes the bits");
    let per_shard = |count: u64| {
        (0..count)
            .map(|i| spec.shard_chunks(i, count).fold(0.0f32, |s, k| s + harmonic(spec.chunk_items(k))))
            .fold(0.0f32, |s, x| s + x)
            .to_bits()
    };
    assert!((2..=7).any(|c| per_shard(c) != unsharded), "a per-shard reduction would change the bits");

    for count in 1..=7u64 {
        let dir = tempfile::tempdir().unwrap();
        for index in 0..count {
            run_shard(&cached_engine(dir.path()), &g, "hs", index, count);
        }
        let (r, ran) = counting(TAG, || run_all(&cached_engine(dir.path()), &g));
        assert_eq!(ran, 0, "{count} shards: the gather found every chunk");
        assert_eq!(sum_bits(&bytes(&r, "out")), unsharded, "{count} shards: other bits than unsharded");
    }
    for processes in 1..=7 {
        for (p, r) in run_peers(processes, false, None, &g).iter().enumerate() {
            assert_eq!(sum_bits(&bytes(r, "out")), unsharded, "process {p} of {processes}: other bits than unsharded");
        }
    }
}

// ---------------------------------------------------------------------------------------
// 3. A shard run of a node cached whole

#[test]
fn a_shard_run_of_a_node_cached_whole_runs_nothing() {
    const TAG: u32 = 4;
    let g = squares("n: 100, chunk: 8, tag: 4");
    let dir = tempfile::tempdir().unwrap();
    let e = cached_engine(dir.path()).with_disk_policy(DiskPolicy::Always);
    let (_, ran) = counting(TAG, || run_all(&e, &g));
    assert_eq!(ran, 13);
    for (what, e) in [("the same engine (memory)", e), ("a new engine (disk)", cached_engine(dir.path()))] {
        let (r, ran) = counting(TAG, || run_shard(&e, &g, "sq", 1, 3));
        assert_eq!(ran, 0, "{what}: a shard run recomputed chunks of a node cached whole");
        assert_eq!(r.report.ran, 0, "{what}: {}", r.report.table());
        let node = r.report.node("sq").expect("a report line for sq");
        assert_eq!(node.status, "cached", "{what}");
        assert!(node.shards.is_none(), "{what}: no chunk was looked at: {:?}", node.shards);
    }
}

// ---------------------------------------------------------------------------------------
// 4. ShardMode::Peers over channels

/// One process's view of the others: a channel to each, an inbox, and the messages that
/// arrived for another node than the one waiting.
struct ChannelPeers {
    me: usize,
    to: Vec<Option<Sender<ShardMessage>>>,
    inbox: Mutex<Receiver<ShardMessage>>,
    held: Mutex<Vec<ShardMessage>>,
    shared: bool,
    /// How long `recv` waits for a message before it fails (instead of hanging the test).
    patience: Duration,
    /// Payloads sent, by kind: [keys, bytes].
    sent: [AtomicU64; 2],
}

impl ChannelPeers {
    /// `n` processes connected to each other. Each inbox starts with a message for a node
    /// key no node has, which `recv` must hold aside.
    fn group(n: usize, shared: bool, patience: Duration) -> Vec<ChannelPeers> {
        let (senders, inboxes): (Vec<_>, Vec<_>) = (0..n).map(|_| channel::<ShardMessage>()).unzip();
        for (me, s) in senders.iter().enumerate() {
            let decoy = ShardMessage {
                node_key: Hash::default(),
                chunk: 0,
                from: (me + 1) % n,
                cached: false,
                ms: 0.0,
                payload: ShardPayload::Bytes(vec![]),
            };
            s.send(decoy).expect("the inbox is there");
        }
        inboxes
            .into_iter()
            .enumerate()
            .map(|(me, inbox)| ChannelPeers {
                me,
                to: senders.iter().enumerate().map(|(p, s)| (p != me).then(|| s.clone())).collect(),
                inbox: Mutex::new(inbox),
                held: Mutex::new(Vec::new()),
                shared,
                patience,
                sent: [AtomicU64::new(0), AtomicU64::new(0)],
            })
            .collect()
    }

    fn take_held(&self, key: &Hash) -> Option<ShardMessage> {
        let mut held = self.held.lock().unwrap();
        let at = held.iter().position(|m| m.node_key == *key)?;
        Some(held.remove(at))
    }
}

impl ShardPeers for ChannelPeers {
    fn process(&self) -> usize {
        self.me
    }
    fn processes(&self) -> usize {
        self.to.len()
    }
    fn shared_cache(&self) -> bool {
        self.shared
    }
    fn send(&self, msg: ShardMessage) -> Result<(), NodeError> {
        assert_eq!(msg.from, self.me, "a message names its sender");
        let kind = matches!(msg.payload, ShardPayload::Bytes(_)) as usize;
        self.sent[kind].fetch_add(1, Ordering::SeqCst);
        for s in self.to.iter().flatten() {
            s.send(msg.clone()).map_err(|_| NodeError::failed("a peer is gone"))?;
        }
        Ok(())
    }
    fn recv(&self, key: &Hash, cancel: &CancelToken) -> Result<ShardMessage, NodeError> {
        let deadline = Instant::now() + self.patience;
        loop {
            if let Some(m) = self.take_held(key) {
                return Ok(m);
            }
            if cancel.is_cancelled() {
                return Err(NodeError::Cancelled);
            }
            if Instant::now() > deadline {
                return Err(NodeError::failed(format!("process {} waited {:?} for a chunk that never came", self.me, self.patience)));
            }
            let got = self.inbox.lock().unwrap().recv_timeout(Duration::from_millis(5));
            match got {
                Ok(m) if m.node_key == *key => return Ok(m),
                Ok(m) => self.held.lock().unwrap().push(m),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    return self.take_held(key).ok_or_else(|| NodeError::failed("every peer is gone"));
                }
            }
        }
    }
}

/// Runs `g` on `processes` engines in threads, as peers; with `cache`, every engine uses
/// that disk-cache folder. Returns each process's result, in process order.
fn run_peers(processes: usize, shared: bool, cache: Option<&Path>, g: &Graph) -> Vec<RunResult> {
    let peers = ChannelPeers::group(processes, shared, Duration::from_secs(60));
    let results = run_peer_group(&peers, cache, g);
    let (keys, byte_msgs): (u64, u64) = peers
        .iter()
        .map(|p| (p.sent[0].load(Ordering::SeqCst), p.sent[1].load(Ordering::SeqCst)))
        .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    if processes > 1 {
        if shared && cache.is_some() {
            assert_eq!(byte_msgs, 0, "a shared cache sends keys, not bytes");
        } else {
            assert_eq!(keys, 0, "without a shared cache partials travel as bytes");
        }
    }
    results.into_iter().enumerate().map(|(p, r)| r.unwrap_or_else(|e| panic!("process {p} of {processes} failed: {e}"))).collect()
}

fn run_peer_group(peers: &[ChannelPeers], cache: Option<&Path>, g: &Graph) -> Vec<Result<RunResult, RunError>> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = peers
            .iter()
            .map(|p| {
                scope.spawn(move || {
                    let e = match cache {
                        Some(dir) => cached_engine(dir),
                        None => engine(),
                    };
                    e.run(g, &RunOptions { shards: ShardMode::Peers(p), ..Default::default() })
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("a peer thread panicked")).collect()
    })
}

/// Every process gathers the unsharded bytes; each ran its own shard and received every
/// other chunk from the process that holds it.
fn check_peers(processes: usize, shared: bool, tag: u32) {
    let (sq, hs) = (format!("n: 100, chunk: 8, tag: {tag}"), format!("n: 10000, chunk: 1000, tag: {tag}"));
    let g = both(&sq, &hs);
    let unsharded = run_all(&engine(), &g);
    let dir = tempfile::tempdir().unwrap();
    let cache = shared.then_some(dir.path());
    let (results, ran) = counting(tag, || run_peers(processes, shared, cache, &g));
    let specs = [("sq", ShardSpec::new(100, 8)), ("hs", ShardSpec::new(10000, 1000))];
    assert_eq!(ran, specs.iter().map(|s| s.1.chunks()).sum::<u64>(), "every chunk ran once, on one process");
    for (p, r) in results.iter().enumerate() {
        for (id, spec) in specs {
            assert_eq!(bytes(r, id), bytes(&unsharded, id), "process {p} of {processes}: {id} differs from unsharded");
            let s = stats(r, id);
            let mine = spec.shard_chunks(p as u64, processes as u64).count() as u64;
            assert_eq!((s.chunks, s.here, s.ran, s.cached), (spec.chunks(), mine, mine, 0), "process {p}, {id}: {s:?}");
            assert!(!s.received.contains_key(&p), "process {p} received from itself: {s:?}");
            let received: u64 = s.received.values().map(|r| r.chunks).sum();
            assert_eq!(received, s.chunks - s.here, "process {p}, {id}: received chunks: {s:?}");
            for (q, from) in &s.received {
                assert_eq!(from.chunks, spec.shard_chunks(*q as u64, processes as u64).count() as u64, "from {q}: {s:?}");
                assert_eq!(from.cached, 0, "process {q} ran its chunks: {s:?}");
            }
        }
    }
}

#[test]
fn peer_processes_without_a_shared_cache_send_bytes_and_each_gathers_the_unsharded_result() {
    check_peers(2, false, 5);
    check_peers(3, false, 5);
}

#[test]
fn peer_processes_over_one_cache_folder_send_keys_and_each_gathers_the_unsharded_result() {
    check_peers(2, true, 6);
    check_peers(3, true, 6);
}

// ---------------------------------------------------------------------------------------
// 5. Cancellation midway: the re-run computes only what did not finish

#[test]
fn a_cancelled_run_resumes_from_the_chunks_it_finished() {
    const TAG: u32 = 7;
    let g = one_node("x", "Interrupted", "out", "n: 100, chunk: 8, stop_after: 4, tag: 7");
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions::default();
    *TO_CANCEL.lock().unwrap() = Some(opts.cancel.clone());
    let e = cached_engine(dir.path()).with_disk_policy(DiskPolicy::Always);
    let (result, ran) = counting(TAG, || e.run(&g, &opts));
    assert!(matches!(result, Err(RunError::Cancelled)), "the run was cancelled: {:?}", result.err());
    assert_eq!(ran, 5, "chunks 0 to 4 ran, then the run stopped");
    assert!(TO_CANCEL.lock().unwrap().is_none(), "the token was used");

    let (r, ran) = counting(TAG, || run_all(&cached_engine(dir.path()).with_disk_policy(DiskPolicy::Always), &g));
    let s = stats(&r, "x");
    assert_eq!((s.chunks, s.cached, s.ran), (13, 5, 8), "{s:?}");
    assert_eq!(ran, 8, "the re-run computed only the chunks that did not finish");
    assert_eq!(bytes(&r, "out"), expected_squares(100, 1.0));
}

// ---------------------------------------------------------------------------------------
// 6. Partial keys follow the node's key

#[test]
fn a_changed_parameter_changes_every_chunk_key() {
    const TAG: u32 = 8;
    let dir = tempfile::tempdir().unwrap();
    // Chunks on disk, the whole result not: one shard of one.
    let base = "chunk: 8, tag: 8";
    let (_, ran) = counting(TAG, || run_shard(&cached_engine(dir.path()), &squares(&format!("n: 100, {base}")), "sq", 0, 1));
    assert_eq!(ran, 13);
    for (params, n, scale) in [("n: 100, scale: 2", 100, 2.0), ("n: 104", 104, 1.0), ("n: 100, scale: -1", 100, -1.0)] {
        let g = squares(&format!("{params}, {base}"));
        let (r, ran) = counting(TAG, || run_all(&cached_engine(dir.path()), &g));
        let s = stats(&r, "sq");
        assert_eq!((s.cached, s.ran), (0, s.chunks), "{params}: a stale chunk was reused: {s:?}");
        assert_eq!(ran, s.chunks, "{params}");
        assert_eq!(bytes(&r, "out"), expected_squares(n, scale), "{params}");
    }
    // The control: the original parameters find every chunk.
    let (r, ran) = counting(TAG, || run_all(&cached_engine(dir.path()), &squares(&format!("n: 100, {base}"))));
    let s = stats(&r, "sq");
    assert_eq!((s.cached, s.ran, ran), (13, 0, 0), "{s:?}");
    assert_eq!(bytes(&r, "out"), expected_squares(100, 1.0));
}

#[test]
fn a_peer_that_holds_the_whole_result_still_provides_its_chunks() {
    const TAG: u32 = 9;
    let g = squares("n: 100, chunk: 8, tag: 9");
    let unsharded = bytes(&run_all(&engine(), &g), "out");
    let warm = engine();
    run_all(&warm, &g);
    // Process 0 has the result in memory, process 1 has nothing: process 1 needs process 0's
    // chunks all the same (a short patience: a process left waiting fails the test).
    let peers = ChannelPeers::group(2, false, Duration::from_secs(5));
    let (results, ran) = counting(TAG, || {
        std::thread::scope(|scope| {
            let opts = |p| RunOptions { shards: ShardMode::Peers(p), ..Default::default() };
            let (a, b) = (opts(&peers[0]), opts(&peers[1]));
            let (warm, g) = (&warm, &g);
            let a = scope.spawn(move || warm.run(g, &a));
            let b = scope.spawn(move || engine().run(g, &b));
            [a.join().expect("process 0 panicked"), b.join().expect("process 1 panicked")]
        })
    });
    for (p, r) in results.iter().enumerate() {
        let r = r.as_ref().unwrap_or_else(|e| panic!("process {p} failed: {e}"));
        assert_eq!(bytes(r, "out"), unsharded, "process {p}");
        let s = stats(r, "sq");
        assert_eq!(s.received.values().map(|r| r.chunks).sum::<u64>(), s.chunks - s.here, "process {p}: {s:?}");
    }
    assert_eq!(ran, 13, "each process ran its own shard");
}

// Found while writing these tests: asking a shard run for the sharded node's outputs
// panicked in the engine; it is now refused before anything runs, as is a shard index out of
// range.

#[test]
fn a_shard_run_asked_for_the_nodes_output_fails_with_a_message_not_a_panic() {
    let g = squares("n: 100, chunk: 8, tag: 10");
    let dir = tempfile::tempdir().unwrap();
    let e = cached_engine(dir.path());
    // No `outputs: Some(vec![])`: the graph's output `out` is sq's, which a shard run does not gather.
    let opts = RunOptions { shards: ShardMode::One { node: "sq", index: 0, count: 3 }, ..Default::default() };
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| e.run(&g, &opts).map(|r| r.outputs.len())));
    match outcome {
        Err(_) => panic!("Engine::run panicked"),
        Ok(Ok(n)) => assert_eq!(n, 0, "a shard run delivers no output of its node"),
        Ok(Err(err)) => assert!(err.to_string().contains("sq"), "the error names the node: {err}"),
    }
    let out_of_range = RunOptions {
        outputs: Some(vec![]),
        nodes: vec!["sq".into()],
        shards: ShardMode::One { node: "sq", index: 5, count: 3 },
        ..Default::default()
    };
    let err = e.run(&g, &out_of_range).err().expect("shard 5 of 3 is refused");
    assert!(err.to_string().contains("shard 5 of 3 does not exist"), "{err}");
}

// ---------------------------------------------------------------------------------------
// Partial results: a watcher that asks for them gets every chunk as it is done, in order,
// named by its items, computed or from the disk cache; one that does not gets none.

/// A partial result as received: node, chunk items, item count, the chunk's numbers.
type Received = (String, Range<u64>, u64, Vec<f64>);

struct Partials {
    want: bool,
    got: Mutex<Vec<Received>>,
}

impl relume_core::Observer for Partials {
    fn event(&self, e: &relume_core::Event<'_>) {
        if let relume_core::Event::Partial { id, value, chunk } = e {
            let (items, total) = chunk.clone().expect("a sharded node names the chunk");
            self.got.lock().unwrap().push((id.to_string(), items, total, value.get::<Floats>().expect("a chunk").0.clone()));
        }
    }
    fn wants_partials(&self) -> bool {
        self.want
    }
}

#[test]
fn a_watcher_that_asks_gets_each_chunk_as_it_is_done_from_the_run_or_the_cache() {
    let dir = tempfile::tempdir().unwrap();
    let g = squares("n: 20, chunk: 8, tag: 9");
    let watch = |want| Partials { want, got: Mutex::new(Vec::new()) };
    let run = |e: &Engine, w: &Partials| e.run(&g, &RunOptions { observer: Some(w), ..Default::default() }).unwrap();
    let expect = |items: Range<u64>| items.map(|i| (i * i) as f64).collect::<Vec<_>>();
    let w = watch(true);
    run(&engine(), &w);
    let got = w.got.into_inner().unwrap();
    let ranges: Vec<(Range<u64>, u64)> = got.iter().map(|g| (g.1.clone(), g.2)).collect();
    assert_eq!(ranges, [(0..8, 20), (8..16, 20), (16..20, 20)]);
    for (id, items, _, values) in &got {
        assert_eq!((id.as_str(), values), ("sq", &expect(items.clone())));
    }
    // The first shard's chunks in the disk cache (`relume shard`), then a run: those come
    // from the cache, the rest are computed, and every chunk is sent, in order.
    let e = cached_engine(dir.path());
    run_shard(&e, &g, "sq", 0, 2);
    let e = cached_engine(dir.path());
    let w = watch(true);
    let (_, ran) = counting(9, || run(&e, &w));
    let got = w.got.into_inner().unwrap();
    assert_eq!(got.iter().map(|g| g.1.clone()).collect::<Vec<_>>(), [0..8, 8..16, 16..20]);
    assert!(ran > 0 && ran < 3, "{ran} chunks computed: the first shard's came from the cache");
    // Not asked: not sent.
    let w = watch(false);
    run(&engine(), &w);
    assert!(w.got.into_inner().unwrap().is_empty());
}

#[test]
fn a_memory_only_run_writes_nothing_to_disk_and_still_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let files = || walk(dir.path());
    let g = squares("n: 20, chunk: 8, tag: 10");
    let e = cached_engine(dir.path()).with_disk_policy(DiskPolicy::Always);
    let memory_only = RunOptions { memory_only: true, ..Default::default() };
    let (r, ran) = counting(10, || e.run(&g, &memory_only).unwrap());
    assert_eq!((ran, files()), (3, 0), "three chunks computed, no file written");
    assert_eq!(bytes(&r, "out"), expected_squares(20, 1.0));
    // The same engine has them in memory; a fresh one on the folder computes them again, and
    // a run that may write leaves them on disk for the next.
    assert_eq!(counting(10, || e.run(&g, &memory_only).unwrap()).1, 0);
    let fresh = cached_engine(dir.path()).with_disk_policy(DiskPolicy::Always);
    assert_eq!(counting(10, || run_all(&fresh, &g)).1, 3);
    assert!(files() > 0);
    let third = cached_engine(dir.path());
    assert_eq!(counting(10, || third.run(&g, &memory_only).unwrap()).1, 0, "what is on disk is read");
}

/// Files below `dir`, at any depth.
fn walk(dir: &Path) -> usize {
    std::fs::read_dir(dir).map_or(0, |rd| rd.flatten().map(|e| if e.path().is_dir() { walk(&e.path()) } else { 1 }).sum())
}
