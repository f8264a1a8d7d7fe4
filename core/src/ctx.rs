//! What a running node sees besides its data: cancellation, progress, metrics and notes.

use crate::error::NodeError;
use crate::hash::Hash;
use crate::port::Value;
use rayon::prelude::*;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Shared cancellation flag: the caller sets it, nodes poll it through `RunCtx::check`.
#[derive(Clone, Default, Debug)]
pub struct CancelToken(Arc<AtomicBool>);

impl CancelToken {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn cancel(&self) {
        self.0.store(true, Ordering::SeqCst)
    }
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// Where a run's nodes may write files (`ParamKind::OutputFile` parameters): a graph from
/// someone else must not write outside the folders the person running it chose. The command
/// line confines what a graph reads with the same rule (`RunFiles::outside`).
#[derive(Clone, Debug, PartialEq)]
pub enum WritePolicy {
    /// Below the graph file's own folder (the engine adds it) and below these folders (the
    /// command line adds its output folder). The default, with no extra folder.
    Within(Vec<PathBuf>),
    /// Anywhere (`--allow-writes-anywhere`: the person running the graph trusts it).
    Anywhere,
}

impl Default for WritePolicy {
    fn default() -> Self {
        WritePolicy::Within(Vec::new())
    }
}

/// The folders a run may write below, resolved once (`resolve_write_path`); `None`: anywhere.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WriteRoots(Option<Vec<PathBuf>>);

impl WriteRoots {
    /// No restriction (a node run on its own, outside a graph).
    pub fn anywhere() -> Self {
        WriteRoots(None)
    }

    /// The roots of `policy` for a graph whose relative paths resolve against `base_dir`.
    pub fn new(policy: &WritePolicy, base_dir: &Path) -> Self {
        match policy {
            WritePolicy::Anywhere => WriteRoots(None),
            WritePolicy::Within(extra) => {
                let mut roots = vec![resolve_write_path(base_dir)];
                roots.extend(extra.iter().map(|d| resolve_write_path(d)));
                roots.dedup();
                WriteRoots(Some(roots))
            }
        }
    }

    /// The resolved folders (`None`: anywhere).
    pub fn folders(&self) -> Option<&[PathBuf]> {
        self.0.as_deref()
    }

    /// `Ok` when a file written at `path` lands below one of the roots; otherwise a sentence
    /// saying where it would land and what to do.
    pub fn check(&self, path: &Path) -> Result<(), String> {
        let Some(roots) = &self.0 else { return Ok(()) };
        let real = resolve_write_path(path);
        if roots.iter().any(|r| real.starts_with(r)) {
            return Ok(());
        }
        let list: Vec<String> = roots.iter().map(|r| r.display().to_string()).collect();
        Err(format!(
            "refusing to write {}: it is outside the folders this run may write to ({}); write below one of them, \
             or, if you trust this graph, allow it with `--allow-writes-anywhere`",
            real.display(),
            list.join(", ")
        ))
    }
}

/// Where a file written at `path` would land: made absolute against the current folder, the
/// longest part that exists resolved by the file system (symbolic links followed, so a link
/// cannot lead outside), and `.` and `..` applied to the rest.
pub fn resolve_write_path(path: &Path) -> PathBuf {
    use std::path::Component;
    let abs = if path.is_absolute() { path.to_path_buf() } else { std::env::current_dir().unwrap_or_default().join(path) };
    let comps: Vec<Component> = abs.components().collect();
    for k in (1..=comps.len()).rev() {
        let prefix: PathBuf = comps[..k].iter().collect();
        let Ok(mut out) = prefix.canonicalize() else { continue };
        for c in &comps[k..] {
            match c {
                Component::ParentDir => {
                    out.pop();
                }
                Component::Normal(n) => out.push(n),
                _ => {}
            }
        }
        return out;
    }
    abs
}

/// Whether a node's result came from running it or from a cache.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NodeStatus {
    Ran,
    CachedMemory,
    CachedDisk,
}

impl NodeStatus {
    pub fn as_str(&self) -> &'static str {
        match self {
            NodeStatus::Ran => "ran",
            NodeStatus::CachedMemory | NodeStatus::CachedDisk => "cached",
        }
    }
}

/// Events a run sends to whoever watches it (the CLI's progress bars, the editor).
#[derive(Clone, Debug)]
pub enum Event<'a> {
    /// The plan is made: `nodes` nodes are needed.
    Planned {
        nodes: usize,
    },
    Started {
        id: &'a str,
        kind: &'a str,
    },
    /// Fraction in [0, 1] of a node's own work.
    Progress {
        id: &'a str,
        fraction: f32,
    },
    Finished {
        id: &'a str,
        kind: &'a str,
        status: NodeStatus,
        wall_ms: f64,
    },
    Failed {
        id: &'a str,
        kind: &'a str,
        message: &'a str,
    },
    /// A graph output is ready: its node finished or was found in a cache. Sent once per
    /// requested output, as soon as it exists, so that a watcher can show or write it while
    /// the rest of the run goes on (the command line writes each output file at once).
    Output {
        name: &'a str,
        value: &'a Value,
    },
    /// A result before the node's end, for display while it runs: a sharded node's chunk
    /// once it is done (or a pass of it), or a node's whole output so far. `chunk`: the items
    /// the value covers and the node's item count, for a sharded node (an `ImageRows` band of
    /// a renderer sharded over rows holds, layer by layer, its outputs' rows). Sent only to
    /// observers that want them.
    Partial {
        id: &'a str,
        value: &'a Value,
        chunk: Option<(Range<u64>, u64)>,
    },
}

/// Receives run events; called from the coordinating thread and from node threads.
pub trait Observer: Send + Sync {
    fn event(&self, e: &Event<'_>);

    /// Whether to send `Event::Partial` (building a partial result costs the node a copy).
    fn wants_partials(&self) -> bool {
        false
    }
}

/// What a run recorded besides its outputs: metrics, notes, file dependencies.
pub(crate) type Recorded = (Vec<(String, f64)>, Vec<String>, Vec<(PathBuf, Hash)>);

/// Handed to `Node::run`.
pub struct RunCtx<'a> {
    pub(crate) id: &'a str,
    pub(crate) cancel: &'a CancelToken,
    pub(crate) observer: Option<&'a dyn Observer>,
    pub(crate) metrics: Mutex<Vec<(String, f64)>>,
    pub(crate) notes: Mutex<Vec<String>>,
    pub(crate) deps: Mutex<Vec<(PathBuf, Hash)>>,
    writes: WriteRoots,
    /// What the whole run may hold (`--memory-budget`).
    memory_budget: u64,
    last_permille: AtomicU64,
    /// The share of the node's whole work that progress reports now cover, in permille
    /// (`from << 32 | to`), set by `phase`.
    span: AtomicU64,
    /// The share of the node's work that `phase` subdivides (all of it, or one chunk of a
    /// sharded node: see `shard.rs`), in the same form.
    outer: AtomicU64,
    /// The chunk a sharded node is computing and its item count (set by the sharded runner).
    chunk: Mutex<Option<(Range<u64>, u64)>>,
    /// The run keeps its results in memory only (`RunOptions::memory_only`).
    memory_only: bool,
}

impl<'a> RunCtx<'a> {
    pub fn new(id: &'a str, cancel: &'a CancelToken, observer: Option<&'a dyn Observer>) -> Self {
        RunCtx {
            id,
            cancel,
            observer,
            metrics: Mutex::default(),
            notes: Mutex::default(),
            deps: Mutex::default(),
            writes: WriteRoots::anywhere(),
            memory_budget: crate::limits::default_budget(),
            last_permille: AtomicU64::new(u64::MAX),
            span: AtomicU64::new(1000),
            outer: AtomicU64::new(1000),
            chunk: Mutex::new(None),
            memory_only: false,
        }
    }

    /// Keeps the run's results (a sharded node's chunks too) off the disk cache.
    pub(crate) fn with_memory_only(mut self, on: bool) -> Self {
        self.memory_only = on;
        self
    }

    pub(crate) fn memory_only(&self) -> bool {
        self.memory_only
    }

    /// Whether anyone watches for partial results: build one only then.
    pub fn wants_partials(&self) -> bool {
        self.observer.is_some_and(|o| o.wants_partials())
    }

    /// Sends a result before the node's end (see `Event::Partial`): for a sharded node, a
    /// value of the chunk it is computing, which the event names.
    pub fn partial(&self, value: Value) {
        if let Some(o) = self.observer.filter(|o| o.wants_partials()) {
            let chunk = self.chunk.lock().unwrap().clone();
            o.event(&Event::Partial { id: self.id, value: &value, chunk });
        }
    }

    /// Says which chunk of how many items a sharded node computes now (`None`: the whole).
    pub(crate) fn set_chunk(&self, chunk: Option<(Range<u64>, u64)>) {
        *self.chunk.lock().unwrap() = chunk;
    }

    /// The node's id in the graph.
    pub fn node_id(&self) -> &str {
        self.id
    }

    /// Limits where the node may write (`check_write_path`); the engine sets the run's roots.
    pub fn with_write_roots(mut self, roots: WriteRoots) -> Self {
        self.writes = roots;
        self
    }

    /// Sets the run's memory budget (the engine passes `--memory-budget`).
    pub fn with_memory_budget(mut self, bytes: u64) -> Self {
        self.memory_budget = bytes;
        self
    }

    /// What the whole run may hold, in bytes: a node whose needs are known only at run time
    /// (they depend on its inputs' content) refuses, before allocating, what would exceed it.
    pub fn memory_budget(&self) -> u64 {
        self.memory_budget
    }

    /// Call before writing a file named by parameter `param` (an output file): refuses, as a
    /// `NodeError::Param` naming it, a path outside the folders this run may write to.
    pub fn check_write_path(&self, param: &str, path: &Path) -> Result<(), NodeError> {
        self.writes.check(path).map_err(|m| NodeError::param(param, m))
    }

    /// Returns `Err(Cancelled)` once the run is cancelled; call it in long loops.
    pub fn check(&self) -> Result<(), NodeError> {
        if self.cancel.is_cancelled() {
            Err(NodeError::Cancelled)
        } else {
            Ok(())
        }
    }

    /// Reports `done` of `total` units of work (cheap: forwards at most 1000 steps).
    pub fn progress(&self, done: u64, total: u64) {
        let Some(obs) = self.observer else { return };
        let local = (done.min(total) * 1000).checked_div(total).unwrap_or(1000);
        let span = self.span.load(Ordering::Relaxed);
        let (from, to) = (span >> 32, span & 0xffff_ffff);
        let permille = from + (to - from) * local / 1000;
        if self.last_permille.swap(permille, Ordering::Relaxed) != permille {
            obs.event(&Event::Progress { id: self.id, fraction: permille as f32 / 1000.0 });
        }
    }

    /// Says that the progress reported from now on (by `progress`, `tick` and the parallel
    /// helpers, each counting its own 0..n) covers the fraction `from..to` of the node's whole
    /// work: a node with phases (two blur passes, passes of doubling sample counts) shows one
    /// bar that never goes back.
    pub fn phase(&self, from: f64, to: f64) {
        let outer = self.outer.load(Ordering::Relaxed);
        let (o0, o1) = ((outer >> 32) as f64, (outer & 0xffff_ffff) as f64);
        let p = |x: f64| (o0 + x.clamp(0.0, 1.0) * (o1 - o0)).round() as u64;
        let (a, b) = (p(from), p(to).max(p(from)));
        self.span.store(a << 32 | b, Ordering::Relaxed);
    }

    /// Makes `from..to` of the node's work the whole that `phase` and progress subdivide
    /// (the sharded runner gives each chunk its share; nodes call `phase` inside it as usual).
    pub(crate) fn set_outer(&self, from: f64, to: f64) {
        let p = |x: f64| (x.clamp(0.0, 1.0) * 1000.0).round() as u64;
        let v = p(from) << 32 | p(to).max(p(from));
        self.outer.store(v, Ordering::Relaxed);
        self.span.store(v, Ordering::Relaxed);
    }

    /// `check` and `progress` in one call, for sequential loops: `cx.tick(i, n)?`.
    pub fn tick(&self, done: u64, total: u64) -> Result<(), NodeError> {
        self.check()?;
        self.progress(done, total);
        Ok(())
    }

    /// Maps `f` over the items `0..n` in parallel (rayon), reporting progress and stopping
    /// soon after the run is cancelled. Results come back in item order, so a reduction over
    /// them in order gives the same bytes on any thread count.
    pub fn par_map<T: Send>(&self, n: usize, f: impl Fn(usize) -> T + Sync + Send) -> Result<Vec<T>, NodeError> {
        self.par_try_map(n, |i| Ok(f(i)))
    }

    /// As `par_map`, with scratch space per rayon thread made by `init` (rayon's `map_init`):
    /// buffers a task overwrites and reuses, never state that carries from one item to the
    /// next, so the results are the same bytes on any thread count.
    pub fn par_map_init<T: Send, S>(
        &self,
        n: usize,
        init: impl Fn() -> S + Sync + Send,
        f: impl Fn(&mut S, usize) -> T + Sync + Send,
    ) -> Result<Vec<T>, NodeError> {
        self.par_blocks(n, init, |scratch, i| Ok(f(scratch, i)))
    }

    /// As `par_map` for work that can fail: the first error rayon meets stops the run.
    pub fn par_try_map<T: Send>(&self, n: usize, f: impl Fn(usize) -> Result<T, NodeError> + Sync + Send) -> Result<Vec<T>, NodeError> {
        self.par_blocks(n, || (), |_, i| f(i))
    }

    /// The parallel maps' one loop: the items in blocks of consecutive indices (`block_len`),
    /// cancellation checked per item, progress counted per block. Counting per item made
    /// both cores write one shared counter for every item, and the line's trips between them
    /// cost more than a light item (a vertex shaded for an orbit) itself.
    fn par_blocks<T: Send, S>(
        &self,
        n: usize,
        init: impl Fn() -> S + Sync + Send,
        f: impl Fn(&mut S, usize) -> Result<T, NodeError> + Sync + Send,
    ) -> Result<Vec<T>, NodeError> {
        let block = block_len(n, rayon::current_num_threads());
        let done = AtomicU64::new(0);
        let parts: Vec<Vec<T>> = (0..n.div_ceil(block))
            .into_par_iter()
            // Every block its own piece, so that an idle thread can take any one. Measured
            // in the refraction pipeline's camera edit (the engine running `EikonalPaths` on a
            // 2-thread pool): left to rayon's own splitting, its 64 blocks went 128 rows to
            // each thread, one busy 36 ms with the sky and the other 92 ms with the glass, the
            // node using 1.4 cores; with this, 156 and 100 rows, both busy.
            .with_max_len(1)
            .map_init(init, |scratch, b| {
                let items = b * block..((b + 1) * block).min(n);
                let len = items.len() as u64;
                let mut out = Vec::with_capacity(items.len());
                for i in items {
                    self.check()?;
                    out.push(f(scratch, i)?);
                }
                self.progress(done.fetch_add(len, Ordering::Relaxed) + len, n as u64);
                Ok(out)
            })
            .collect::<Result<_, NodeError>>()?;
        let mut all = Vec::with_capacity(n);
        parts.into_iter().for_each(|p| all.extend(p));
        Ok(all)
    }

    /// Runs `f(chunk_index, chunk)` over `data` split into chunks of `chunk` elements (rows
    /// of an image, tiles, …) in parallel, with progress and cancellation as `par_map`, in
    /// pieces of at most `block_len` chunks that an idle thread can take.
    pub fn par_chunks_mut<T: Send>(
        &self,
        data: &mut [T],
        chunk: usize,
        f: impl Fn(usize, &mut [T]) + Sync + Send,
    ) -> Result<(), NodeError> {
        let n = data.len().div_ceil(chunk.max(1));
        let done = AtomicU64::new(0);
        data.par_chunks_mut(chunk.max(1)).enumerate().with_max_len(block_len(n, rayon::current_num_threads())).try_for_each(|(i, c)| {
            self.check()?;
            f(i, c);
            self.progress(done.fetch_add(1, Ordering::Relaxed) + 1, n as u64);
            Ok(())
        })
    }

    /// Adds a quality figure to the report (`metrics` of this node).
    pub fn metric(&self, name: &str, value: f64) {
        self.metrics.lock().unwrap().push((name.to_string(), value));
    }

    /// Adds a sentence to the report, e.g. what the node left out because the scene lacks it.
    pub fn note(&self, text: impl Into<String>) {
        self.notes.lock().unwrap().push(text.into());
    }

    /// Records a file the node read that is not one of its file parameters (a mesh named in a
    /// scene file): the cached result is reused only while the file keeps this content.
    /// `content_hash` is `Hash::of_bytes` of the file's bytes as the node read them.
    pub fn depends_on_file(&self, path: &Path, content_hash: Hash) {
        self.deps.lock().unwrap().push((path.to_path_buf(), content_hash));
    }

    pub(crate) fn take(self) -> Recorded {
        (self.metrics.into_inner().unwrap(), self.notes.into_inner().unwrap(), self.deps.into_inner().unwrap())
    }
}

/// Items per block of the parallel maps for `n` items on `threads` threads: about 32 blocks
/// a thread (rayon balances their load), at most 256 items (a block of heavy items, a
/// vertex's precompute, still ends soon enough to show progress).
fn block_len(n: usize, threads: usize) -> usize {
    (n / (threads.max(1) * 32)).clamp(1, 256)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Record(Mutex<Vec<f32>>);
    impl Observer for Record {
        fn event(&self, e: &Event<'_>) {
            if let Event::Progress { fraction, .. } = e {
                self.0.lock().unwrap().push(*fraction);
            }
        }
    }

    #[test]
    fn phases_make_one_bar_that_never_goes_back_and_cancellation_stops_the_helpers() {
        let rec = Record(Mutex::default());
        let cancel = CancelToken::new();
        let cx = RunCtx::new("n", &cancel, Some(&rec));
        cx.phase(0.0, 0.25);
        assert_eq!(cx.par_map(100, |i| i * 2).unwrap()[99], 198, "results in item order");
        let first = rec.0.lock().unwrap().len();
        cx.phase(0.25, 1.0);
        let mut data = vec![0u32; 1000];
        cx.par_chunks_mut(&mut data, 10, |c, s| s.iter_mut().for_each(|x| *x = c as u32)).unwrap();
        assert_eq!(data[995], 99);
        let seen = rec.0.lock().unwrap().clone();
        assert!(first > 0 && seen[..first].iter().all(|f| *f <= 0.25), "{seen:?}");
        assert!(seen[first..].iter().all(|f| *f >= 0.25) && seen[first..].contains(&1.0), "{seen:?}");
        cancel.cancel();
        assert_eq!(cx.par_map(10, |i| i), Err(NodeError::Cancelled));
        assert_eq!(cx.tick(1, 2), Err(NodeError::Cancelled));
    }

    #[test]
    fn the_maps_keep_item_order_over_blocks_report_the_whole_and_stop_at_an_error() {
        assert_eq!((block_len(0, 2), block_len(100, 2), block_len(10_000, 2), block_len(1 << 20, 2)), (1, 1, 156, 256));
        let cancel = CancelToken::new();
        for n in [0, 1, 63, 64, 65, 10_000, 70_000] {
            let rec = Record(Mutex::default());
            let cx = RunCtx::new("n", &cancel, Some(&rec));
            let got = cx.par_map_init(n, || 7usize, |seven, i| i * *seven).unwrap();
            assert_eq!(got, (0..n).map(|i| i * 7).collect::<Vec<_>>(), "{n} items");
            assert!(n == 0 || rec.0.lock().unwrap().contains(&1.0), "{n} items: the bar reaches the end");
        }
        let cx = RunCtx::new("n", &cancel, None);
        let failing = cx.par_try_map(5000, |i| if i == 4321 { Err(NodeError::input("x", "item 4321")) } else { Ok(i) });
        assert!(failing.expect_err("fails").to_string().contains("item 4321"));
    }

    #[test]
    fn writes_stay_below_the_roots_and_neither_dot_dot_nor_a_link_leads_out() {
        let dir = tempfile::tempdir().unwrap();
        let (graph, out, elsewhere) = (dir.path().join("g"), dir.path().join("out"), dir.path().join("elsewhere"));
        for d in [&graph, &elsewhere] {
            std::fs::create_dir_all(d).unwrap();
        }
        let roots = WriteRoots::new(&WritePolicy::Within(vec![out.clone()]), &graph);
        let cancel = CancelToken::new();
        let cx = RunCtx::new("save", &cancel, None).with_write_roots(roots.clone());
        for ok in [graph.join("a.png"), graph.join("new/sub/a.png"), out.join("x.exr"), graph.join("new/../b.png")] {
            assert_eq!(cx.check_write_path("path", &ok), Ok(()), "{}", ok.display());
        }
        for bad in [graph.join("../../../../tmp/x.png"), elsewhere.join("x.png"), graph.join("new/../../elsewhere/x.png")] {
            let e = cx.check_write_path("path", &bad).unwrap_err();
            assert!(matches!(&e, NodeError::Param { name, msg } if name == "path" && msg.contains("--allow-writes-anywhere")), "{e}");
        }
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&elsewhere, graph.join("link")).unwrap();
            assert!(roots.check(&graph.join("link/x.png")).is_err(), "a link inside the graph's folder leads out");
        }
        assert_eq!(WriteRoots::new(&WritePolicy::Anywhere, &graph).check(&elsewhere.join("x.png")), Ok(()));
        assert_eq!(RunCtx::new("n", &cancel, None).check_write_path("path", Path::new("/x.png")), Ok(()), "standalone: no roots");
    }
}
