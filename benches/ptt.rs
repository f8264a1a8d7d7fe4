//! Pipeline 2 on envlit (49,261 vertices): the frames a second of each kind of edit of [S]
//! table 5-1 (view only; view + BRDF; view + BRDF + lighting), through the engine, asking
//! for the relit image only (the references are not asked for). The precompute comes from
//! the workspace's disk cache (`.relume-cache/`, filled by the first run: several minutes of
//! visibility and transfer tracing on 2 cores). In test mode (`-- --test`, as CI runs every
//! bench once) the graph runs at test size instead, on the Spot-and-teapot scene, in a cache of
//! its own.
//! `cargo bench -p relume-benches --bench ptt`; `PTT_BENCH_NODES=1` prints each edit's node
//! times, `PTT_BENCH_KINDS=view,view+brdf` times only those kinds (to profile one).
//! `PTT_BENCH_GRAPH=ptt_envlit_pair.ron PTT_BENCH_BRDF=spot.s` times the two-object graph
//! instead (its BRDF edit on Spot, which re-runs both objects' projections).

use relume_benches::{graphs_dir, test_mode};
use relume_core::{Engine, Graph, RunOptions};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

fn main() {
    divan::main();
}

/// ptt_envlit.ron: full size with the workspace's disk cache, or test size.
fn graph_and_engine() -> (Graph, Engine) {
    let reg = relume_cli::registry();
    let name = std::env::var("PTT_BENCH_GRAPH").unwrap_or_else(|_| "ptt_envlit.ron".into());
    let mut g = Graph::load(&graphs_dir().join(name), &reg).expect("graph loads");
    let mut e = Engine::new(relume_cli::registry());
    if let Some(mb) = std::env::var("PTT_BENCH_CACHE_MB").ok().and_then(|v| v.parse::<usize>().ok()) {
        e = e.with_memory_budget(mb << 20);
    }
    if test_mode() {
        g.shrink_to_test_size(&reg).unwrap();
        g.set_param_text(&reg, "scene.width", "24").unwrap();
        g.set_param_text(&reg, "scene.height", "24").unwrap();
        if std::env::var("PTT_BENCH_GRAPH").is_err() {
            // The Spot-and-teapot scene: the same edits from fewer vertices than the bunny's.
            g.set_param_text(&reg, "scene.path", "scenes/envlit-pair.ron").unwrap();
            g.set_param_text(&reg, "project.object", "\"spot\"").unwrap();
        }
        (g, e)
    } else {
        (g, e.with_disk_cache(graphs_dir().join("../.relume-cache")))
    }
}

/// The edits of each kind: (node.param, the k-th value).
/// "view@1spp" is an orbit with one camera sample per pixel (`hits.spp` 1, as a GPU
/// rasteriser without multisampling draws), "view@16uniform" one with 16 samples in every
/// pixel (`hits.adaptive` off); the others keep the graph's 16 samples at edges and one
/// elsewhere.
const KINDS: &[&str] = &["view", "view@1spp", "view@16uniform", "view+brdf", "view+brdf+lighting"];

/// The values of the k-th edit of `kind`: (node.param, value), new each time and different
/// between kinds, so that no edit finds a result another kind's edit left in the cache.
fn edits(kind: &str, k: u64) -> Vec<(&'static str, String)> {
    // The untimed edits before the timed ones (`WARM_EDITS`, numbered from `WARM_FIRST`) get
    // values of their own.
    let warm = if k >= WARM_FIRST { 0.0625 } else { 0.0 };
    let salt = KINDS.iter().position(|&x| x == kind).expect("a kind") as f64 * 0.125 + warm;
    let view = ("camera.azimuth", format!("{}", (k % 360) as f64 + 0.5 + salt));
    let brdf = (brdf_param(), format!("{}", 20.0 + (k % 100) as f64 + 0.25 + salt));
    let light = ("turn.rotation_deg", format!("{}", (k % 360) as f64 + 0.75 + salt));
    let spp = ("hits.spp", if kind == "view@1spp" { "1" } else { "16" }.to_string());
    let adaptive = ("hits.adaptive", (kind != "view@1spp" && kind != "view@16uniform").to_string());
    match kind {
        "view" | "view@1spp" | "view@16uniform" => vec![spp, adaptive, view],
        "view+brdf" => vec![spp, adaptive, view, brdf],
        _ => vec![spp, adaptive, view, brdf, light],
    }
}

/// The parameter a BRDF edit sets (`PTT_BENCH_BRDF`, default `project.s`).
fn brdf_param() -> &'static str {
    static P: OnceLock<String> = OnceLock::new();
    P.get_or_init(|| std::env::var("PTT_BENCH_BRDF").unwrap_or_else(|_| "project.s".into()))
}

/// Untimed edits of each kind before its timed ones, and the number of the first.
const WARM_EDITS: u64 = 12;
const WARM_FIRST: u64 = 1 << 20;

/// One engine and graph warmed once for all the benches.
fn warmed() -> &'static std::sync::Mutex<(Graph, Engine)> {
    static W: OnceLock<std::sync::Mutex<(Graph, Engine)>> = OnceLock::new();
    W.get_or_init(|| {
        let (g, e) = graph_and_engine();
        e.run(&g, &RunOptions { outputs: Some(vec!["image".into()]), ..Default::default() }).expect("the graph runs");
        // Edits are timed in memory: no result of an earlier bench run found on disk, no
        // writing of their own.
        std::sync::Mutex::new((g, e.without_disk_cache()))
    })
}

#[divan::bench(args = KINDS, sample_count = 10, sample_size = 1)]
fn edit(bencher: divan::Bencher, kind: &str) {
    // `PTT_BENCH_KINDS=view+brdf,view` times only those kinds (the others time nothing), to
    // profile one kind of edit.
    if std::env::var("PTT_BENCH_KINDS").is_ok_and(|only| !only.split(',').any(|x| x == kind)) {
        return bencher.bench_local(|| 0);
    }
    let opts = RunOptions { outputs: Some(vec!["image".into()]), ..Default::default() };
    let k = AtomicU64::new(1);
    let mut guard = warmed().lock().unwrap();
    let (g, e) = &mut *guard;
    // Untimed edits first: until the memory cache holds its 8 latest results of each node
    // (`RESULTS_PER_NODE`), an edit's outputs land on fresh pages, and the first edits of a
    // kind after loading run about a fifth slower than the steady state a user orbits in.
    for i in WARM_FIRST..WARM_FIRST + WARM_EDITS {
        for (param, value) in edits(kind, i) {
            g.set_param_text(e.registry(), param, &value).unwrap();
        }
        e.run(g, &opts).unwrap();
    }
    bencher.bench_local(|| {
        let i = k.fetch_add(1, Ordering::Relaxed);
        for (param, value) in edits(kind, i) {
            g.set_param_text(e.registry(), param, &value).unwrap();
        }
        let report = e.run(g, &opts).unwrap().report;
        if std::env::var_os("PTT_BENCH_NODES").is_some() {
            let ran: Vec<String> =
                report.nodes.iter().filter(|n| n.status == "ran").map(|n| format!("{} {:.2}", n.id, n.wall_ms)).collect();
            eprintln!("{kind}: {}", ran.join(", "));
        }
        report.ran
    });
}

/// `CameraHits` alone on envlit's scene and camera (87,883 triangles at 256²; 24² in test
/// mode), by samples per pixel: what an orbit costs before the shading.
#[divan::bench(args = [1, 4, 16], sample_count = 10, sample_size = 1)]
fn camera_hits(bencher: divan::Bencher, spp: i64) {
    time_camera_hits(bencher, spp, false, false);
}

/// As `camera_hits`, adaptive (the graph's): one sample at each pixel's centre, `spp` at edges.
#[divan::bench(args = [4, 16], sample_count = 10, sample_size = 1)]
fn camera_hits_adaptive(bencher: divan::Bencher, spp: i64) {
    time_camera_hits(bencher, spp, true, false);
}

/// As `camera_hits_adaptive`, leaving out the back faces (the graph's).
#[divan::bench(args = [16], sample_count = 10, sample_size = 1)]
fn camera_hits_adaptive_culled(bencher: divan::Bencher, spp: i64) {
    time_camera_hits(bencher, spp, true, true);
}

fn time_camera_hits(bencher: divan::Bencher, spp: i64, adaptive: bool, cull: bool) {
    use relume_core::{run_standalone, ParamValue, Value};
    use relume_ptt::camera_hits::CameraHits;
    let loaded = relume_base::scene::format::load_scene_file(&graphs_dir().join("scenes/envlit.ron")).expect("envlit loads");
    let mut scene = loaded.scene;
    if test_mode() {
        (scene.camera.width, scene.camera.height) = (24, 24);
    }
    let camera = scene.camera.clone();
    let inputs = [Value::new(scene), Value::new(camera)];
    let params = [("spp", ParamValue::Int(spp)), ("adaptive", ParamValue::Bool(adaptive)), ("cull_back_faces", ParamValue::Bool(cull))];
    bencher.bench_local(|| run_standalone::<CameraHits>(&params, std::path::Path::new("."), &inputs).expect("runs"));
}
