//! Shared helpers for the integration tests: test-only node kinds that log what ran, and
//! small utilities around graphs and reports.
//!
//! A graph of `graphs/` at test size (each parameter with a declared test value turned to it),
//! run on an engine with every node kind, and what ran read from the report:
//!
//! ```
//! use relume_tests::{engine, graphs_dir, at_test_size, ran, run};
//!
//! let g = at_test_size(&graphs_dir().join("filters.ron"));
//! let e = engine();
//! let first = run(&e, &g);
//! assert!(ran(&first).contains(&"blur".to_string()));
//! assert!(ran(&run(&e, &g)).is_empty(), "a second run of the same graph takes everything from the cache");
//! ```

use relume_core::{
    inputs, node, outputs, Caching, DynNode, Engine, Graph, Hasher, NodeError, ParamValues, Params, PortDecl, PortValue, Ports, Registry,
    RunCtx, RunOptions, RunReport, Schema, Value,
};
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// The repository's `graphs/` folder.
pub fn graphs_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../graphs")
}

/// The `tests/` folder (its `scenes/` hold test-only scenes).
pub fn tests_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Loads `graphs/NAME` and applies `--set`-style overrides (`node.param`, value text).
pub fn load_graph(name: &str, sets: &[(&str, &str)]) -> Graph {
    let reg = relume_cli::registry();
    let mut g = Graph::load(&graphs_dir().join(name), &reg).unwrap_or_else(|e| panic!("{e}"));
    for (k, v) in sets {
        g.set_param_text(&reg, k, v).unwrap_or_else(|e| panic!("--set {k}={v}: {e}"));
    }
    g
}

/// Adds a graph output `name` for port `node.port` (to read an intermediate result).
pub fn add_output(g: &mut Graph, name: &str, port: &str) {
    let port = relume_core::graph::PortRef::parse(port).expect("node.port");
    g.outputs.push(relume_core::graph::Output { name: name.into(), port, pos: Default::default() });
}

/// Runs the named outputs of a graph and returns the result (panics with the error's text).
pub fn run_outputs(engine: &Engine, g: &Graph, outputs: &[&str]) -> relume_core::RunResult {
    let opts = RunOptions { outputs: Some(outputs.iter().map(|s| s.to_string()).collect()), ..Default::default() };
    engine.run(g, &opts).unwrap_or_else(|e| panic!("{e}"))
}

/// Runs one registered node kind by name with its default parameters on `inputs` (declared
/// order): a stage on inputs no graph produces (hand-made stiff cases).
pub fn run_kind(kind: &str, inputs: &[Value]) -> Result<Vec<Value>, NodeError> {
    relume_core::run_kind(&relume_cli::registry(), kind, &[], &graphs_dir(), inputs).map(|e| e.outputs)
}

/// Every file below `dir` (a cache folder), sorted.
pub fn files_under(dir: &std::path::Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(files_under(&p));
        } else {
            out.push(p);
        }
    }
    out.sort();
    out
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
    Engine::new(relume_cli::registry())
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
    fn byte_size(&self) -> usize {
        8
    }
    fn encode(&self) -> Vec<u8> {
        self.0.to_le_bytes().to_vec()
    }
    fn decode(b: &[u8]) -> Option<Self> {
        Some(Num(u64::from_le_bytes(b.try_into().ok()?)))
    }
}

/// Shared record of which test nodes ran, in order.
pub type Log = Arc<Mutex<Vec<String>>>;

type RunFn = dyn Fn(i64, &[Value], &RunCtx) -> Result<Vec<Value>, NodeError> + Send + Sync;

/// A test node kind that carries state of its own (a log, a rendezvous), registered in its
/// type-erased form with `Registry::add_dyn`; its one parameter is `salt`.
pub struct TestNode {
    kind: &'static str,
    ports: Ports,
    schema: Schema,
    run: Box<RunFn>,
    /// The working memory it states (the memory model's tests).
    working: u64,
}

impl TestNode {
    fn erased(kind: &'static str, inputs: &[&'static str], run: Box<RunFn>) -> Arc<dyn DynNode> {
        let ports = Ports { inputs: inputs.iter().map(|n| PortDecl::of::<Num>(n)).collect(), outputs: vec![PortDecl::of::<Num>("out")] };
        let schema = Schema::new().int("salt", 0, i64::MIN, i64::MAX).help("changes the output");
        Arc::new(TestNode { kind, ports, schema, run, working: 0 })
    }
}

impl DynNode for TestNode {
    fn kind(&self) -> &'static str {
        self.kind
    }
    fn version(&self) -> u32 {
        1
    }
    fn category(&self) -> &'static str {
        "test"
    }
    fn doc(&self) -> &str {
        "Test node."
    }
    fn ports(&self) -> &Ports {
        &self.ports
    }
    fn schema(&self) -> &Schema {
        &self.schema
    }
    fn caching(&self) -> Caching {
        Caching::Auto
    }
    fn run(&self, params: &ParamValues, inputs: &[Value], cx: &RunCtx) -> Result<Vec<Value>, NodeError> {
        (self.run)(params.int("salt"), inputs, cx)
    }
    fn memory(&self, _: &ParamValues, _: &[Option<relume_core::PortSize>]) -> Result<relume_core::MemoryEstimate, NodeError> {
        Ok(relume_core::MemoryEstimate { outputs: vec![Some(relume_core::PortSize::bytes(8))], working: self.working })
    }
}

/// Test node `Big`: states `working` bytes of working memory, records when it ran
/// (start, end) in `log` and sleeps 50 ms in between.
pub fn big(working: u64, log: &Arc<Mutex<Vec<(std::time::Instant, std::time::Instant)>>>) -> Arc<dyn DynNode> {
    let log = log.clone();
    let run: Box<RunFn> = Box::new(move |salt, _, _| {
        let t0 = std::time::Instant::now();
        std::thread::sleep(Duration::from_millis(50));
        log.lock().unwrap().push((t0, std::time::Instant::now()));
        Ok(vec![Value::new(Num(salt as u64))])
    });
    let ports = Ports { inputs: vec![], outputs: vec![PortDecl::of::<Num>("out")] };
    let schema = Schema::new().int("salt", 0, i64::MIN, i64::MAX).help("changes the output");
    Arc::new(TestNode { kind: "Big", ports, schema, run, working })
}

const MIX_KINDS: [&str; 4] = ["Mix0", "Mix1", "Mix2", "Mix3"];
const INPUT_NAMES: [&str; 3] = ["in0", "in1", "in2"];

/// Test node `MixN` with N inputs `in0..`: output = hash(salt, inputs); logs its id when it runs.
pub fn mix(n: usize, log: &Log) -> Arc<dyn DynNode> {
    let log = log.clone();
    TestNode::erased(
        MIX_KINDS[n],
        &INPUT_NAMES[..n],
        Box::new(move |salt, inputs, cx| {
            log.lock().unwrap().push(cx.node_id().to_string());
            let mut h = Hasher::new();
            h.i64(salt);
            for v in inputs {
                h.u64(v.get::<Num>().expect("Num input").0);
            }
            Ok(vec![Value::new(Num(u64::from_le_bytes(h.finish().0[..8].try_into().unwrap())))])
        }),
    )
}

/// Test node `Rendezvous`: waits (up to 20 s) until `parties` of its kind are running at the
/// same time; fails if they never are, which proves that independent nodes run concurrently.
pub fn rendezvous(parties: usize) -> Arc<dyn DynNode> {
    let state = Arc::new((Mutex::new(0usize), Condvar::new()));
    TestNode::erased(
        "Rendezvous",
        &[],
        Box::new(move |salt, _, _| {
            let (lock, cv) = &*state;
            let mut n = lock.lock().unwrap();
            *n += 1;
            cv.notify_all();
            let (n, timeout) = cv.wait_timeout_while(n, Duration::from_secs(20), |n| *n < parties).unwrap();
            if timeout.timed_out() {
                return Err(NodeError::failed(format!("only {} of {parties} ran at once", *n)));
            }
            Ok(vec![Value::new(Num(salt as u64))])
        }),
    )
}

/// Test node: spins until the run is cancelled (at most 20 s), reporting progress.
#[derive(Params)]
pub struct UntilCancelled;

inputs!(pub UntilCancelledIn { in0: Num });
outputs!(pub UntilCancelledOut { out: Num });

#[node(category = "test")]
impl UntilCancelled {
    fn run(&self, _: UntilCancelledIn, cx: &RunCtx) -> Result<UntilCancelledOut, NodeError> {
        for step in 0..20_000u64 {
            cx.tick(step, 20_000)?;
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(UntilCancelledOut { out: Num(0) })
    }
}

/// A registry of the Mix test nodes sharing one log.
pub fn test_registry(log: &Log) -> Registry {
    let mut r = Registry::new();
    for n in 0..4 {
        r.add_dyn(mix(n, log));
    }
    r
}

/// The cornell scene at 32 × 32 (for tests that trace it).
pub fn small_cornell() -> relume_base::types::Scene {
    let mut s = relume_base::scene::format::load_scene_file(&graphs_dir().join("scenes/cornell.ron")).unwrap().scene;
    s.camera.width = 32;
    s.camera.height = 32;
    s
}

/// A graph of `graphs/` at test size: every parameter with a declared test value
/// (`#[param(test = …)]`) turned to it.
pub fn at_test_size(path: &std::path::Path) -> Graph {
    let reg = relume_cli::registry();
    let mut g = Graph::load(path, &reg).unwrap_or_else(|e| panic!("{e}"));
    g.shrink_to_test_size(&reg).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    g
}

/// `name` from `graphs/` at test size, then `sets` applied over it (as `load_graph`).
pub fn load_test_graph(name: &str, sets: &[(&str, &str)]) -> Graph {
    let reg = relume_cli::registry();
    let mut g = at_test_size(&graphs_dir().join(name));
    for (k, v) in sets {
        g.set_param_text(&reg, k, v).unwrap_or_else(|e| panic!("--set {k}={v}: {e}"));
    }
    g
}

/// The furnace of the point-based gathers (`tests/scenes/inside_sphere.ron`: the inside of a
/// sphere lit from its centre, every point of the wall at the same radiance L, so the indirect
/// light is albedo 0.5 × L at every pixel). Runs `g` (a PBGI graph on that scene whose
/// `indirect` output is the gather's and whose `shade` node shades the points) and returns
/// the least pixel, the mean and the largest pixel of the indirect image over 0.5 L.
pub fn furnace_ratios(g: &Graph) -> [f64; 3] {
    let mut g = g.clone();
    add_output(&mut g, "radiance", "shade.radiance");
    let out = run_outputs(&engine(), &g, &["indirect", "radiance"]);
    let radiance = &out.output("radiance").unwrap().get::<relume_pbgi::types::PointRadiance>().unwrap().0;
    let (lo, hi) = radiance.iter().fold((f32::INFINITY, 0.0f32), |(lo, hi), r| (lo.min(r.x), hi.max(r.x)));
    assert!(lo > 0.0 && hi / lo < 1.01, "the wall's radiance spreads from {lo} to {hi}");
    let expected = 0.5 * (lo + hi) as f64 / 2.0;
    let img = out.output("indirect").unwrap().get::<relume_base::types::Image>().unwrap();
    let red: Vec<f64> = img.pixels.iter().map(|p| p[0] as f64).collect();
    let (min, max) = red.iter().fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(*x), b.max(*x)));
    let mean = red.iter().sum::<f64>() / red.len() as f64;
    [min / expected, mean / expected, max / expected]
}

/// Σ over the three channels of the pixels with x ∈ [x0, x1) × width, y ∈ [y0, y1) × height
/// (fractions of the image).
pub fn region_sum(img: &relume_base::types::Image, x: [f32; 2], y: [f32; 2]) -> f64 {
    region_channels(img, x, y).iter().sum()
}

/// Per colour channel, the sum of `region_sum`'s pixels.
pub fn region_channels(img: &relume_base::types::Image, x: [f32; 2], y: [f32; 2]) -> [f64; 3] {
    let (w, h) = (img.width as f32, img.height as f32);
    let mut s = [0.0; 3];
    for py in (y[0] * h) as usize..(y[1] * h) as usize {
        for px in (x[0] * w) as usize..(x[1] * w) as usize {
            s.iter_mut().zip(img.pixels[py * img.width + px]).for_each(|(s, c)| *s += c as f64);
        }
    }
    s
}

/// Σ|a − b| / Σ|b| over two images' floats: how far `a` is from `b`, relative to `b`.
pub fn relative_l1(a: &relume_base::types::Image, b: &relume_base::types::Image) -> f64 {
    let diff: f64 = a.as_floats().iter().zip(b.as_floats()).map(|(x, y)| (x - y).abs() as f64).sum();
    diff / b.as_floats().iter().map(|y| y.abs() as f64).sum::<f64>()
}

/// A copy of the scene file `graphs/scenes/NAME` in `dir` with its asset paths made absolute
/// and each (from, to) text replacement made (the scale tests scale a scene this way); the
/// copy is named for `tag`. Panics when a replacement finds nothing to replace.
pub fn edited_scene(name: &str, tag: &str, dir: &std::path::Path, edits: &[(&str, String)]) -> PathBuf {
    let assets = graphs_dir().join("assets").display().to_string();
    let mut text =
        std::fs::read_to_string(graphs_dir().join("scenes").join(name)).unwrap().replace("\"../assets/", &format!("\"{assets}/"));
    for (from, to) in edits {
        assert!(text.contains(from), "{name} has no `{from}`");
        text = text.replace(from, to);
    }
    let path = dir.join(format!("{tag}-{name}"));
    std::fs::write(&path, text).unwrap();
    path
}

/// Runs `g` with its `scene` node reading the scene file `scene` and returns its `image` output.
pub fn image_with_scene(e: &Engine, mut g: Graph, scene: &std::path::Path) -> relume_base::types::Image {
    g.set_param_text(&relume_cli::registry(), "scene.path", &format!("{:?}", scene.display().to_string())).unwrap();
    run_outputs(e, &g, &["image"]).output("image").unwrap().get::<relume_base::types::Image>().unwrap().clone()
}
