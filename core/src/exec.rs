//! The executor: runs a plan, reusing cached results, running ready nodes concurrently,
//! timing each node and honouring cancellation.

use crate::cache::{CacheEntry, DiskCache, MemoryCache};
use crate::ctx::{CancelToken, Event, NodeStatus, Observer, RunCtx};
use crate::error::NodeError;
use crate::error::{GraphError, GraphErrors};
use crate::graph::Graph;
use crate::hash::{Hash, Hasher};
use crate::node::{Caching, DynNode};
use crate::params::ParamValues;
use crate::plan::{make_plan, Plan};
use crate::port::Value;
use crate::registry::Registry;
use crate::report::{peak_rss_bytes, NodeReport, RunReport};
use crate::shard::{ShardMode, ShardStats};
use std::collections::VecDeque;
use std::sync::{mpsc, Arc, Mutex};
use std::time::Instant;

/// Holds the registry and the caches; runs graphs. Share it (`Arc<Engine>`) between threads.
pub struct Engine {
    registry: Registry,
    memory: Mutex<MemoryCache>,
    disk: Option<DiskCache>,
    disk_policy: DiskPolicy,
    max_parallel: usize,
    /// The rayon pool nodes run their inner loops in; `None`: rayon's global pool.
    pool: Option<Arc<rayon::ThreadPool>>,
    /// What one run may hold at once (the memory model, `memory.rs`).
    run_budget: u64,
    /// What set `run_budget`, in words (messages and `relume plan`).
    budget_source: String,
}

/// Which results an engine with a disk cache writes there.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DiskPolicy {
    /// The rule (docs/ARCHITECTURE.md, "Caching"): a result whose computation took longer than
    /// loading it would (`cache::worth_storing`).
    #[default]
    WhenCheaperToLoad,
    /// Every cacheable result (a cache shared by machines that must not recompute anything,
    /// tests of the disk cache itself).
    Always,
}

/// What to run and who watches.
#[derive(Default)]
pub struct RunOptions<'a> {
    /// Output names to produce; `None` for all of the graph's outputs.
    pub outputs: Option<Vec<String>>,
    pub cancel: CancelToken,
    pub observer: Option<&'a dyn Observer>,
    /// Where nodes may write files (default: below the graph file's folder only).
    pub writes: crate::ctx::WritePolicy,
    /// Node ids to run besides those the outputs need (`relume shard` names its node here and
    /// asks for no outputs).
    pub nodes: Vec<String>,
    /// Which chunks of sharded nodes this run computes (`shard.rs`).
    pub shards: crate::shard::ShardMode<'a>,
    /// Keep what this run computes in memory only, not on disk (the editor's live re-runs:
    /// a drag's many intermediate results are each not worth a disk write); what is on disk
    /// is still read.
    pub memory_only: bool,
}

pub struct RunResult {
    /// Requested outputs by name.
    pub outputs: Vec<(String, Value)>,
    pub report: RunReport,
}

impl RunResult {
    pub fn output(&self, name: &str) -> Option<&Value> {
        self.outputs.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }
}

#[derive(Debug)]
pub enum RunError {
    Graph(GraphErrors),
    Node { id: String, kind: String, error: NodeError },
    Cancelled,
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Graph(e) => write!(f, "{e}"),
            RunError::Node { id, kind, error } => write!(f, "node \"{id}\" ({kind}) failed: {error}"),
            RunError::Cancelled => f.write_str("run cancelled"),
        }
    }
}

impl std::error::Error for RunError {}

impl From<GraphErrors> for RunError {
    fn from(e: GraphErrors) -> Self {
        RunError::Graph(e)
    }
}

/// A node's parameters and cache key for this run.
pub(crate) struct Prepared {
    pub params: ParamValues,
    pub key: Hash,
}

type Done = (usize, Result<(CacheEntry, Option<ShardStats>), NodeError>, f64);

/// A node's run, handed to a thread or a pool.
type Job<'a> = Box<dyn FnOnce() + Send + 'a>;

/// `f`, typed so that the jobs it hands to its spawner may borrow what lives as long as `'a`
/// (one lifetime, not each call's own).
fn with_spawner<'a, F: FnMut(&dyn Fn(Job<'a>))>(f: F) -> F {
    f
}

impl Engine {
    /// An engine with a 2 GiB memory cache, no disk cache, and as many concurrent nodes as cores.
    pub fn new(registry: Registry) -> Self {
        let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(2);
        Engine {
            registry,
            memory: Mutex::new(MemoryCache::new(2 << 30)),
            disk: None,
            disk_policy: DiskPolicy::default(),
            max_parallel: cores,
            pool: None,
            run_budget: crate::limits::default_budget(),
            budget_source: crate::limits::default_budget_source().source.clone(),
        }
    }
    pub fn with_memory_budget(mut self, bytes: usize) -> Self {
        self.memory = Mutex::new(MemoryCache::new(bytes));
        self
    }
    pub fn with_disk_cache(mut self, dir: impl Into<std::path::PathBuf>) -> Self {
        self.disk = Some(DiskCache::new(dir));
        self
    }
    pub fn with_disk_policy(mut self, policy: DiskPolicy) -> Self {
        self.disk_policy = policy;
        self
    }
    /// What one run may hold at once (default: 80 % of the smallest memory limit the process
    /// runs under, `limits.rs`), given by `source` (e.g. "--memory-budget"). A run whose
    /// estimate exceeds it is refused before anything runs, with the estimate per node.
    pub fn with_run_budget(mut self, bytes: u64, source: &str) -> Self {
        self.run_budget = bytes;
        self.budget_source = source.to_string();
        self
    }
    pub fn run_budget(&self) -> u64 {
        self.run_budget
    }
    /// What set the run budget, in words.
    pub fn budget_source(&self) -> &str {
        &self.budget_source
    }
    /// A graph whose nodes write files (`SaveImage`) is refused when a write would land on a
    /// file the run reads or on another of its writes (`RunFiles`); a graph that writes no
    /// file is not looked at further.
    pub fn check_files(&self, graph: &Graph, plan: &Plan) -> Result<(), GraphErrors> {
        let writes = plan.order.iter().any(|&i| {
            self.registry.node(&graph.nodes[i].kind).is_some_and(|k| k.schema().0.iter().any(|s| s.kind == crate::ParamKind::OutputFile))
        });
        if !writes {
            return Ok(());
        }
        crate::RunFiles::of_plan(graph, &self.registry, plan).check(graph)
    }
    /// The plan's memory estimate against the budget: the refusal as a graph error.
    pub fn check_memory(&self, graph: &Graph, plan: &Plan) -> Result<(), GraphErrors> {
        match self.estimate(graph, plan).refusal(graph, self.run_budget, &self.budget_source) {
            Some(m) => Err(GraphErrors::one(GraphError::new(m)).with_file(&graph.file)),
            None => Ok(()),
        }
    }
    /// Runs every node's inner loops on a pool of `threads` rayon threads (`--threads`; tests
    /// of "the same bytes on any thread count"). Without it nodes share rayon's global pool.
    pub fn with_threads(mut self, threads: usize) -> Self {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads.max(1)).build().expect("a rayon pool");
        self.pool = Some(Arc::new(pool));
        self
    }
    /// How many nodes may run at once (nodes also parallelise inside with rayon).
    pub fn with_parallelism(mut self, n: usize) -> Self {
        self.max_parallel = n.max(1);
        self
    }
    pub fn registry(&self) -> &Registry {
        &self.registry
    }
    /// The registry to change: kinds defined at run time (Python nodes) join or replace
    /// theirs between runs. Cached results of a replaced kind stay valid only where its
    /// `definition` is unchanged, which the cache keys check.
    pub fn registry_mut(&mut self) -> &mut Registry {
        &mut self.registry
    }

    /// Estimates, before running anything, what the plan will hold at once (`budget::estimate`).
    pub fn estimate(&self, graph: &Graph, plan: &Plan) -> crate::budget::RunEstimate {
        crate::budget::estimate(self.registry(), graph, plan)
    }
    pub fn disk(&self) -> Option<&DiskCache> {
        self.disk.as_ref()
    }
    pub fn disk_policy(&self) -> DiskPolicy {
        self.disk_policy
    }
    /// Stops reading and writing the disk cache, keeping what memory holds: a bench warms
    /// the engine from disk, then times edits that neither find earlier runs' results on
    /// disk nor pay for writing their own.
    pub fn without_disk_cache(mut self) -> Self {
        self.disk = None;
        self
    }
    /// Drops every in-memory result.
    pub fn clear_memory(&self) {
        self.memory.lock().unwrap().clear();
    }
    pub fn memory_bytes(&self) -> usize {
        self.memory.lock().unwrap().used_bytes()
    }

    fn kind_of(&self, graph: &Graph, i: usize) -> &Arc<dyn DynNode> {
        self.registry.node(&graph.nodes[i].kind).expect("validated graph")
    }

    /// Resolves parameters and computes the cache key from the input fingerprints:
    /// hash(KIND, VERSION, canonical params, input fingerprints). Input files hash by content.
    pub(crate) fn prepare(&self, graph: &Graph, i: usize, inputs: &[Hash]) -> Result<Prepared, GraphError> {
        let decl = &graph.nodes[i];
        let kind = self.kind_of(graph, i);
        let params = ParamValues::resolve(kind.schema(), &decl.params, &graph.base_dir).map_err(|missing| {
            GraphError::new(format!("missing required parameter `{}`", missing.join("`, `"))).at(decl.pos).node(&decl.id)
        })?;
        let mut h = Hasher::new();
        h.str("relume-key-v1").str(kind.kind()).u64(kind.version() as u64);
        if let Some(d) = kind.definition() {
            h.str("definition").hash(&d);
        }
        params.canonical_hash(kind.schema(), &mut h).map_err(|m| GraphError::new(m).at(decl.pos).node(&decl.id))?;
        for (port, fp) in kind.ports().inputs.iter().zip(inputs) {
            h.str(port.name).hash(fp);
        }
        Ok(Prepared { params, key: h.finish() })
    }

    /// Looks a key up in memory, then on disk.
    pub(crate) fn lookup(&self, kind: &dyn DynNode, node: &str, key: &Hash) -> Option<(Arc<CacheEntry>, NodeStatus)> {
        if kind.caching() == Caching::Never {
            return None;
        }
        let in_memory = self.memory.lock().unwrap().get_for(node, key);
        if let Some(e) = in_memory {
            if e.deps_unchanged() {
                return Some((e, NodeStatus::CachedMemory));
            }
            self.memory.lock().unwrap().remove(key);
        }
        {
            let found =
                self.disk.as_ref().and_then(|d| d.get(key, &kind.ports().outputs, &self.registry)).filter(CacheEntry::deps_unchanged);
            if let Some(e) = found {
                let e = Arc::new(e);
                self.memory.lock().unwrap().put_for(node, *key, e.clone());
                return Some((e, NodeStatus::CachedDisk));
            }
        }
        None
    }

    /// Keeps a result in memory, and on disk when it cost more to compute than loading it
    /// would (`cache::worth_storing`): the one rule for every `Caching::Auto` node.
    fn store(&self, kind: &dyn DynNode, node: &str, key: Hash, entry: Arc<CacheEntry>, memory_only: bool) {
        if kind.caching() == Caching::Never {
            return;
        }
        if !memory_only && (self.disk_policy == DiskPolicy::Always || crate::cache::worth_storing(&entry)) {
            if let Some(d) = &self.disk {
                // A failed write only costs a later recomputation.
                let _ = d.put(&key, &entry, &kind.ports().outputs);
            }
        }
        self.memory.lock().unwrap().put_for(node, key, entry);
    }

    /// Validates, plans and runs the graph.
    pub fn run(&self, graph: &Graph, opts: &RunOptions) -> Result<RunResult, RunError> {
        let start = Instant::now();
        graph.validate(&self.registry)?;
        let plan = crate::plan::make_plan_for(graph, &self.registry, opts.outputs.as_deref(), &opts.nodes)?;
        check_shard_run(graph, &plan, &opts.shards)?;
        self.check_memory(graph, &plan)?;
        self.check_files(graph, &plan)?;
        if let Some(o) = opts.observer {
            o.event(&Event::Planned { nodes: plan.order.len() });
        }
        let mut state = RunState::new(graph, &plan);
        let (tx, rx) = mpsc::channel::<Done>();
        let mut first_error: Option<RunError> = None;
        let write_roots = crate::ctx::WriteRoots::new(&opts.writes, &graph.base_dir);

        // The loop that hands ready nodes to `spawn` and gathers what they finish.
        let mut drive = with_spawner(|spawn| {
            let mut ready: VecDeque<usize> = plan.order.iter().copied().filter(|&i| plan.sources[i].is_empty()).collect();
            // Found in no cache: (node, its preparation, the bytes it will hold and its work
            // against its kind's other runs, both from its actual input sizes).
            let mut to_run: VecDeque<(usize, Prepared, u64, Option<f64>)> = VecDeque::new();
            let mut running = 0usize;
            let mut running_work: Vec<Option<f64>> = vec![None; graph.nodes.len()];
            // Bytes reserved by running nodes (their estimate with actual input sizes).
            let (mut reserved, mut reservation) = (0u64, vec![0u64; graph.nodes.len()]);
            loop {
                let stop = first_error.is_some() || opts.cancel.is_cancelled();
                while let (false, Some(i)) = (stop, ready.pop_front()) {
                    let t0 = Instant::now();
                    let fps: Vec<Hash> =
                        plan.sources[i].iter().map(|&(s, o)| state.values[s].as_ref().unwrap().outputs[o].fingerprint()).collect();
                    let prepared = match self.prepare(graph, i, &fps) {
                        Ok(p) => p,
                        Err(e) => {
                            first_error = Some(RunError::Graph(GraphErrors::one(e).with_file(&graph.file)));
                            break;
                        }
                    };
                    let kind = self.kind_of(graph, i);
                    // Across processes every process takes part in every sharded node (its
                    // chunks come from the disk cache when they are there): a process that
                    // found the whole result would leave its peers waiting for its chunks.
                    let take_part = matches!(opts.shards, ShardMode::Peers(_)) && kind.sharded().is_some();
                    let found = if take_part { None } else { self.lookup(kind.as_ref(), &graph.nodes[i].id, &prepared.key) };
                    match found {
                        Some((entry, status)) => {
                            let ms = t0.elapsed().as_secs_f64() * 1e3;
                            if let Some(o) = opts.observer {
                                o.event(&Event::Finished { id: &graph.nodes[i].id, kind: kind.kind(), status, wall_ms: ms });
                                announce_outputs(o, &plan, i, &entry);
                            }
                            ready.extend(state.complete(i, entry, status, prepared.key, ms, None));
                        }
                        None => {
                            let sizes: Vec<Option<crate::memory::PortSize>> =
                                plan.sources[i].iter().map(|&(s, o)| Some(state.values[s].as_ref().unwrap().outputs[o].size())).collect();
                            let need = kind.memory(&prepared.params, &sizes).map(|e| e.working + e.output_bytes()).unwrap_or(0);
                            let work = kind.work(&prepared.params, &sizes);
                            to_run.push_back((i, prepared, need, work));
                        }
                    }
                }
                while running < self.max_parallel && first_error.is_none() && !opts.cancel.is_cancelled() {
                    // The first waiting node that no smaller run of its kind holds back.
                    let held_back = |a: usize| {
                        let (i, _, _, work) = &to_run[a];
                        let kind = graph.nodes[*i].kind.as_str();
                        let waiting = to_run.iter().enumerate().filter(|&(b, _)| b != a).map(|(_, (j, _, _, w))| (*j, *w));
                        let started = running_work.iter().enumerate().map(|(j, w)| (j, *w));
                        waiting.chain(started).any(|(j, w)| much_smaller(w, *work) && graph.nodes[j].kind == kind)
                    };
                    let Some(at) = (0..to_run.len()).find(|&a| !held_back(a)) else { break };
                    let (i, prepared, need, work) = to_run.remove(at).expect("an index of to_run");
                    let inputs: Vec<Value> =
                        plan.sources[i].iter().map(|&(s, o)| state.values[s].as_ref().unwrap().outputs[o].clone()).collect();
                    // The node's estimate with its actual input sizes, against what is held.
                    let held = state.held_bytes() + reserved;
                    if held + need > self.run_budget {
                        if running > 0 {
                            // Wait for a running node to finish and free what it holds.
                            to_run.insert(at, (i, prepared, need, work));
                            break;
                        }
                        let n = &graph.nodes[i];
                        let m = format!(
                            "node \"{}\" ({}) would need about {} with {} already held, over the memory budget of {} ({}); lower its resolution or sample counts, or raise the budget with --memory-budget",
                            n.id, n.kind, crate::memory::fmt_bytes(need), crate::memory::fmt_bytes(held), crate::memory::fmt_bytes(self.run_budget), self.budget_source
                        );
                        first_error =
                            Some(RunError::Graph(GraphErrors::one(GraphError::new(m).at(n.pos).node(&n.id)).with_file(&graph.file)));
                        break;
                    }
                    (reserved, reservation[i]) = (reserved + need, need);
                    running += 1;
                    running_work[i] = work;
                    state.keys[i] = prepared.key;
                    let kind = self.kind_of(graph, i).clone();
                    let id = graph.nodes[i].id.as_str();
                    let (tx, cancel, observer, pool) = (tx.clone(), &opts.cancel, opts.observer, self.pool.as_deref());
                    let (writes, shards, memory_only) = (&write_roots, opts.shards, opts.memory_only);
                    spawn(Box::new(move || {
                        let t0 = Instant::now();
                        let node = NodeRun { kind: kind.as_ref(), id, params: &prepared.params, key: prepared.key, inputs: &inputs };
                        let go = || self.run_node(node, cancel, observer, writes, shards, memory_only);
                        let result = match pool {
                            Some(p) => p.install(go),
                            None => go(),
                        };
                        let _ = tx.send((i, result, t0.elapsed().as_secs_f64() * 1e3));
                    }));
                }
                if running == 0 && (ready.is_empty() || first_error.is_some() || opts.cancel.is_cancelled()) {
                    break;
                }
                if running == 0 {
                    continue;
                }
                let (i, result, ms) = rx.recv().expect("node threads hold a sender");
                running -= 1;
                reserved -= std::mem::take(&mut reservation[i]);
                running_work[i] = None;
                let kind = self.kind_of(graph, i);
                let id = &graph.nodes[i].id;
                match result {
                    Ok((mut entry, shards)) => {
                        entry.compute_ms = ms;
                        let entry = Arc::new(entry);
                        // One shard of a node is not the node's result: nothing to keep.
                        let whole = entry.outputs.len() == kind.ports().outputs.len();
                        if whole {
                            self.store(kind.as_ref(), id, state.keys[i], entry.clone(), opts.memory_only);
                        }
                        if let Some(o) = opts.observer.filter(|_| whole) {
                            o.event(&Event::Finished { id, kind: kind.kind(), status: NodeStatus::Ran, wall_ms: ms });
                            announce_outputs(o, &plan, i, &entry);
                        } else if let Some(o) = opts.observer {
                            o.event(&Event::Finished { id, kind: kind.kind(), status: NodeStatus::Ran, wall_ms: ms });
                        }
                        let key = state.keys[i];
                        ready.extend(state.complete(i, entry, NodeStatus::Ran, key, ms, shards));
                    }
                    Err(NodeError::Cancelled) => {}
                    Err(error) => {
                        if let Some(o) = opts.observer {
                            o.event(&Event::Failed { id, kind: kind.kind(), message: &error.to_string() });
                        }
                        first_error.get_or_insert(RunError::Node { id: id.clone(), kind: kind.kind().to_string(), error });
                    }
                }
            }
        });
        // Nodes run as jobs of the rayon pool their inner loops use, so that an edit of an
        // interactive graph starts no thread: an orbit of four nodes spent 0.69 ms of its 8 ms
        // outside them with a fresh thread per node, 0.56 ms as jobs (a new thread's stack
        // faults its pages in again, and its loops wake the pool from outside). On a thread
        // of that pool already (a run inside a parallel loop), this waiting loop would hold
        // the worker its nodes queue on, and a node that waits for its shard peers would hold
        // a worker the others need: there each node gets a thread of its own, as before.
        let on_pool = match self.pool.as_deref() {
            Some(p) => p.current_thread_index().is_some(),
            None => rayon::current_thread_index().is_some(),
        };
        if on_pool || matches!(opts.shards, ShardMode::Peers(_)) {
            std::thread::scope(|scope| {
                drive(&|job| {
                    scope.spawn(job);
                })
            });
        } else {
            match self.pool.as_deref() {
                Some(p) => p.in_place_scope(|scope| drive(&|job| scope.spawn(move |_| job()))),
                None => rayon::in_place_scope(|scope| drive(&|job| scope.spawn(move |_| job()))),
            }
        }

        if let Some(e) = first_error {
            return Err(e);
        }
        if opts.cancel.is_cancelled() {
            return Err(RunError::Cancelled);
        }
        let outputs =
            plan.outputs.iter().map(|(name, ni, oi)| (name.clone(), state.values[*ni].as_ref().unwrap().outputs[*oi].clone())).collect();
        let mut report = state.report;
        report.graph = graph.file.as_ref().map(|f| f.display().to_string()).unwrap_or_default();
        report.outputs = plan.outputs.iter().map(|o| o.0.clone()).collect();
        report.total_ms = start.elapsed().as_secs_f64() * 1e3;
        report.memory_cache_bytes = self.memory_bytes();
        report.peak_rss_bytes = peak_rss_bytes();
        if let Some(d) = &self.disk {
            report.notes.extend(d.take_notes());
        }
        Ok(RunResult { outputs, report })
    }

    /// Plans the graph for `relume plan`.
    pub fn plan(&self, graph: &Graph, outputs: Option<&[String]>) -> Result<Plan, GraphErrors> {
        graph.validate(&self.registry)?;
        let plan = make_plan(graph, &self.registry, outputs)?;
        self.check_memory(graph, &plan)?;
        Ok(plan)
    }
}

/// Whether a run of work `small` holds back one of `large` of the same kind: at most a quarter
/// of it (both known). Running the small one first and alone puts its result out in about its
/// own time instead of twice that beside the large one, and delays the large one by that much
/// at most (nothing where both use every core).
fn much_smaller(small: Option<f64>, large: Option<f64>) -> bool {
    matches!((small, large), (Some(s), Some(l)) if s * 4.0 <= l && s < l)
}

/// Tells `o` of each requested graph output that node `i` produced (`Event::Output`).
fn announce_outputs(o: &dyn Observer, plan: &Plan, i: usize, entry: &CacheEntry) {
    for (name, _, port) in plan.outputs.iter().filter(|(_, n, _)| *n == i) {
        if let Some(value) = entry.outputs.get(*port) {
            o.event(&Event::Output { name, value });
        }
    }
}

/// A run of one shard of node `node` gathers nothing: refuses a plan that reads its outputs
/// (asks for them, or runs a node downstream of it), and a shard index out of range.
fn check_shard_run(graph: &Graph, plan: &Plan, mode: &ShardMode) -> Result<(), GraphErrors> {
    let ShardMode::One { node, index, count } = *mode else { return Ok(()) };
    let refuse = |m: String| Err(GraphErrors::one(GraphError::new(m).node(node)).with_file(&graph.file));
    if index >= count {
        return refuse(format!("shard {index} of {count} does not exist (shards are numbered 0 to {})", count.saturating_sub(1)));
    }
    let Some(i) = graph.nodes.iter().position(|n| n.id == node) else {
        return refuse(format!("no node \"{node}\" in the graph"));
    };
    let read = plan.outputs.iter().any(|o| o.1 == i) || plan.order.iter().any(|&j| plan.sources[j].iter().any(|s| s.0 == i));
    if read {
        return refuse(format!(
            "a run of one shard of \"{node}\" produces no outputs (its chunks go to the disk cache): ask for no output that needs it"
        ));
    }
    Ok(())
}

/// One node to run: its kind, id, parameters, key and inputs.
#[derive(Clone, Copy)]
struct NodeRun<'a> {
    kind: &'a dyn DynNode,
    id: &'a str,
    params: &'a ParamValues,
    key: Hash,
    inputs: &'a [Value],
}

impl Engine {
    /// Runs one node (a sharded one by `shards`), turning a panic into an error.
    fn run_node(
        &self,
        n: NodeRun,
        cancel: &CancelToken,
        observer: Option<&dyn Observer>,
        writes: &crate::ctx::WriteRoots,
        shards: ShardMode,
        memory_only: bool,
    ) -> Result<(CacheEntry, Option<ShardStats>), NodeError> {
        if let Some(o) = observer {
            o.event(&Event::Started { id: n.id, kind: n.kind.kind() });
        }
        let cx = RunCtx::new(n.id, cancel, observer)
            .with_write_roots(writes.clone())
            .with_memory_budget(self.run_budget)
            .with_memory_only(memory_only);
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match n.kind.sharded() {
            Some(sh) => {
                self.run_sharded(sh, n.id, n.params, n.key, n.inputs, &cx, shards).map(|r| (r.outputs.unwrap_or_default(), Some(r.stats)))
            }
            None => n.kind.run(n.params, n.inputs, &cx).map(|o| (o, None)),
        }));
        match outcome {
            Ok(Ok((outputs, shards))) => {
                // Fingerprinted here, on the node's thread, not by whoever asks first.
                for (port, v) in outputs.iter().enumerate() {
                    match n.kind.caching() {
                        Caching::Keyed => v.fingerprint_by_key(&n.key, port),
                        _ => {
                            v.fingerprint();
                        }
                    }
                }
                let (metrics, notes, deps) = cx.take();
                // A metric the node does not declare could not be put on a sweep's axis, nor
                // found in the catalogue: a defect of the node, refused so that tests catch it.
                if let Some((name, _)) = metrics.iter().find(|(m, _)| !n.kind.metrics().contains(&m.as_str())) {
                    return Err(NodeError::failed(format!(
                        "{} recorded the metric `{name}`, which it does not declare (#[node(metrics = […])] lists: {})",
                        n.kind.kind(),
                        n.kind.metrics().join(", ")
                    )));
                }
                Ok((CacheEntry { outputs, metrics, notes, deps, compute_ms: 0.0 }, shards))
            }
            Ok(Err(e)) => Err(e),
            Err(panic) => {
                let msg = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_default();
                Err(NodeError::failed(format!("panicked: {msg}")))
            }
        }
    }
}

/// Book-keeping of one run.
struct RunState<'g> {
    graph: &'g Graph,
    /// Results the run still holds: dropped once their last reader has run, unless they are
    /// outputs of the run (the memory cache may keep them longer, under its own budget).
    values: Vec<Option<Arc<CacheEntry>>>,
    sources: Vec<Vec<usize>>,
    readers_left: Vec<usize>,
    is_output: Vec<bool>,
    keys: Vec<Hash>,
    waiting: Vec<usize>,
    dependents: Vec<Vec<usize>>,
    report: RunReport,
}

impl<'g> RunState<'g> {
    fn new(graph: &'g Graph, plan: &Plan) -> Self {
        let n = graph.nodes.len();
        let mut dependents = vec![Vec::new(); n];
        for &i in &plan.order {
            for &(s, _) in &plan.sources[i] {
                dependents[s].push(i);
            }
        }
        let waiting = (0..n).map(|i| plan.sources[i].len()).collect();
        RunState {
            graph,
            values: vec![None; n],
            sources: (0..n).map(|i| plan.sources[i].iter().map(|s| s.0).collect()).collect(),
            readers_left: crate::budget::consumers(plan),
            is_output: crate::budget::output_nodes(plan),
            keys: vec![Hash::default(); n],
            waiting,
            dependents,
            report: RunReport::default(),
        }
    }

    /// Bytes of the results the run holds now.
    fn held_bytes(&self) -> u64 {
        self.values.iter().flatten().map(|e| e.bytes() as u64).sum()
    }

    /// Records a finished node; returns the nodes that became ready.
    fn complete(
        &mut self,
        i: usize,
        entry: Arc<CacheEntry>,
        status: NodeStatus,
        key: Hash,
        ms: f64,
        shards: Option<ShardStats>,
    ) -> Vec<usize> {
        let decl = &self.graph.nodes[i];
        self.report.nodes.push(NodeReport {
            id: decl.id.clone(),
            kind: decl.kind.clone(),
            status: status.as_str(),
            cache: match status {
                NodeStatus::Ran => None,
                NodeStatus::CachedMemory => Some("memory"),
                NodeStatus::CachedDisk => Some("disk"),
            },
            wall_ms: ms,
            compute_ms: entry.compute_ms,
            bytes: entry.bytes(),
            key: key.hex(),
            metrics: entry.metrics.iter().cloned().collect(),
            notes: entry.notes.clone(),
            shards,
        });
        if status == NodeStatus::Ran {
            self.report.ran += 1;
        } else {
            self.report.cached += 1;
        }
        self.keys[i] = key;
        self.values[i] = Some(entry);
        for k in 0..self.sources[i].len() {
            let s = self.sources[i][k];
            self.readers_left[s] -= 1;
            if self.readers_left[s] == 0 && !self.is_output[s] {
                self.values[s] = None;
            }
        }
        let mut now_ready = Vec::new();
        for &d in &self.dependents[i] {
            self.waiting[d] -= 1;
            if self.waiting[d] == 0 {
                now_ready.push(d);
            }
        }
        now_ready
    }
}

#[cfg(test)]
mod tests {
    use super::much_smaller;

    #[test]
    fn a_run_waits_only_for_one_of_a_quarter_of_its_work_or_less() {
        assert!(much_smaller(Some(1.0), Some(4.0)));
        assert!(much_smaller(Some(0.0), Some(1.0)));
        assert!(!much_smaller(Some(1.0), Some(3.9)));
        assert!(!much_smaller(Some(0.0), Some(0.0)), "equal runs never wait for each other");
        assert!(!much_smaller(None, Some(100.0)));
        assert!(!much_smaller(Some(1.0), None));
    }
}
