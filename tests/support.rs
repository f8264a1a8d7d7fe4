//! Shared helpers for the integration tests: test-only node kinds that log what ran, and
//! small utilities around graphs and reports.

use relume_core::{
    Caching, Documented, Engine, Graph, Hash, Hasher, Io, Node, NodeError, ParamValues, Params, PortValue, Ports, Registry, RunCtx,
    RunOptions, RunReport, Schema,
};
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// The repository's `graphs/` folder.
pub fn graphs_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../graphs")
}

/// Every `*.ron` graph in `graphs/` (not the scenes).
pub fn all_graphs() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> =
        std::fs::read_dir(graphs_dir()).unwrap().map(|e| e.unwrap().path()).filter(|p| p.extension().is_some_and(|e| e == "ron")).collect();
    v.sort();
    v
}

/// An engine over every relume node, no disk cache.
pub fn engine() -> Engine {
    Engine::new(relume_nodes::registry())
}

/// Runs all outputs and returns the report (panics with the error's text on failure).
pub fn run(engine: &Engine, g: &Graph) -> RunReport {
    engine.run(g, &RunOptions::default()).unwrap_or_else(|e| panic!("{e}")).report
}

/// Ids of the nodes that ran (not cached), sorted.
pub fn ran(r: &RunReport) -> Vec<String> {
    r.ran_ids().into_iter().map(String::from).collect()
}

/// A number flowing between test nodes.
#[derive(Clone, Debug, PartialEq)]
pub struct Num(pub u64);

impl PortValue for Num {
    const NAME: &'static str = "Num";
    const COLOR: [u8; 3] = [90, 90, 220];
    fn fingerprint(&self) -> Hash {
        Hasher::new().str("Num").u64(self.0).finish()
    }
    fn byte_size(&self) -> usize {
        8
    }
    fn encode(&self) -> Option<Vec<u8>> {
        Some(self.0.to_le_bytes().to_vec())
    }
    fn decode(b: &[u8]) -> Option<Self> {
        Some(Num(u64::from_le_bytes(b.try_into().ok()?)))
    }
}

/// Shared record of which test nodes ran, in order.
pub type Log = Arc<Mutex<Vec<String>>>;

pub struct SaltParams {
    pub salt: i64,
}

impl Params for SaltParams {
    fn schema() -> Schema {
        Schema::new().int("salt", 0, i64::MIN, i64::MAX).help("changes the output")
    }
    fn from_values(v: &ParamValues) -> Self {
        SaltParams { salt: v.int("salt") }
    }
}

/// Test node with N inputs `in0..`: output = hash(salt, inputs); logs its id when it runs.
pub struct Mix<const N: usize>(pub Log);

impl<const N: usize> Documented for Mix<N> {
    const DOC: &'static str = "Test node: hashes its inputs and salt.";
}

const MIX_KINDS: [&str; 4] = ["Mix0", "Mix1", "Mix2", "Mix3"];
const INPUT_NAMES: [&str; 3] = ["in0", "in1", "in2"];

impl<const N: usize> Node for Mix<N> {
    const KIND: &'static str = MIX_KINDS[N];
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "test";
    const CACHING: Caching = Caching::Disk;
    type Params = SaltParams;
    fn ports() -> Ports {
        INPUT_NAMES[..N].iter().fold(Ports::new(), |p, n| p.input::<Num>(n)).output::<Num>("out")
    }
    fn run(&self, p: &SaltParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        self.0.lock().unwrap().push(cx.node_id().to_string());
        let mut h = Hasher::new();
        h.i64(p.salt);
        for n in &INPUT_NAMES[..N] {
            h.u64(io.input::<Num>(n)?.0);
        }
        let v = u64::from_le_bytes(h.finish().0[..8].try_into().unwrap());
        io.set("out", Num(v))
    }
}

/// Waits (up to 20 s) until `parties` Rendezvous nodes are running at the same time; fails
/// if they never are, which proves that independent nodes run concurrently.
pub struct Rendezvous {
    pub state: Arc<(Mutex<usize>, Condvar)>,
    pub parties: usize,
}

impl Documented for Rendezvous {
    const DOC: &'static str = "Test node: meets its siblings.";
}

impl Node for Rendezvous {
    const KIND: &'static str = "Rendezvous";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "test";
    type Params = SaltParams;
    fn ports() -> Ports {
        Ports::new().output::<Num>("out")
    }
    fn run(&self, p: &SaltParams, io: &mut Io, _cx: &RunCtx) -> Result<(), NodeError> {
        let (lock, cv) = &*self.state;
        let mut n = lock.lock().unwrap();
        *n += 1;
        cv.notify_all();
        let (n, timeout) = cv.wait_timeout_while(n, Duration::from_secs(20), |n| *n < self.parties).unwrap();
        if timeout.timed_out() {
            return Err(NodeError::failed(format!("only {} of {} ran at once", *n, self.parties)));
        }
        io.set("out", Num(p.salt as u64))
    }
}

/// Runs until cancelled (at most 20 s), reporting progress; for cancellation tests.
pub struct UntilCancelled;

impl Documented for UntilCancelled {
    const DOC: &'static str = "Test node: spins until the run is cancelled.";
}

impl Node for UntilCancelled {
    const KIND: &'static str = "UntilCancelled";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "test";
    type Params = ();
    fn ports() -> Ports {
        Ports::new().input::<Num>("in0").output::<Num>("out")
    }
    fn run(&self, _: &(), io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        for step in 0..20_000u64 {
            cx.check()?;
            cx.progress(step, 20_000);
            std::thread::sleep(Duration::from_millis(1));
        }
        io.set("out", Num(0))
    }
}

/// A registry of the Mix test nodes sharing one log.
pub fn test_registry(log: &Log) -> Registry {
    let mut r = Registry::new();
    r.add(Mix::<0>(log.clone())).add(Mix::<1>(log.clone())).add(Mix::<2>(log.clone())).add(Mix::<3>(log.clone()));
    r
}

/// The cornell scene at 32 × 32 (for tests that trace it).
pub fn small_cornell() -> relume_nodes::types::Scene {
    let mut s = relume_nodes::scene::format::load_scene_file(&graphs_dir().join("scenes/cornell.ron")).unwrap().scene;
    s.camera.width = 32;
    s.camera.height = 32;
    s
}
