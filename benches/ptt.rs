//! Pipeline 2 on envlit (49,261 vertices): the frames a second of each kind of edit of [S]
//! table 5-1 (view only; view + BRDF; view + BRDF + lighting), through the engine, asking
//! for the relit image only (the references are not asked for). The precompute comes from
//! the workspace's disk cache (`.relume-cache/`, filled by the first run: several minutes of
//! visibility and transfer tracing on 2 cores). In test mode (`-- --test`, as CI runs every
//! bench once) the graph runs at test size instead, in a cache of its own.
//! `cargo bench -p relume-benches --bench ptt`.

use relume_benches::graphs_dir;
use relume_core::{Engine, Graph, RunOptions};
use relume_nodes::ptt::test_size as ptt_test_size;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

fn main() {
    divan::main();
}

/// Whether divan runs each bench once (`--test`).
fn test_mode() -> bool {
    std::env::args().any(|a| a == "--test")
}

/// ptt_envlit.ron: full size with the workspace's disk cache, or test size.
fn graph_and_engine() -> (Graph, Engine) {
    let reg = relume_nodes::registry();
    let mut g = Graph::load(&graphs_dir().join("ptt_envlit.ron"), &reg).expect("graph loads");
    let e = Engine::new(relume_nodes::registry());
    if test_mode() {
        g.set_param_text(&reg, "scene.width", "24").unwrap();
        g.set_param_text(&reg, "scene.height", "24").unwrap();
        for n in g.nodes.clone() {
            for (param, value) in ptt_test_size(&n.kind) {
                g.set_param_text(&reg, &format!("{}.{param}", n.id), value).unwrap();
            }
        }
        (g, e)
    } else {
        (g, e.with_disk_cache(graphs_dir().join("../.relume-cache")))
    }
}

/// The edits of each kind: (node.param, the k-th value).
const KINDS: &[&str] = &["view", "view+brdf", "view+brdf+lighting"];

/// A parameter (`node.param`) and its value at the k-th edit (new each time: never cached).
type Edit = (&'static str, fn(u64) -> String);

fn edits(kind: &str) -> Vec<Edit> {
    let view: Edit = ("camera.azimuth", |k| format!("{}", (k % 360) as f64 + 0.5));
    let brdf: Edit = ("project.s", |k| format!("{}", 20.0 + (k % 100) as f64 + 0.25));
    let light: Edit = ("turn.rotation_deg", |k| format!("{}", (k % 360) as f64 + 0.75));
    match kind {
        "view" => vec![view],
        "view+brdf" => vec![view, brdf],
        _ => vec![view, brdf, light],
    }
}

/// One engine and graph warmed once for all the benches.
fn warmed() -> &'static std::sync::Mutex<(Graph, Engine)> {
    static W: OnceLock<std::sync::Mutex<(Graph, Engine)>> = OnceLock::new();
    W.get_or_init(|| {
        let (g, e) = graph_and_engine();
        e.run(&g, &RunOptions { outputs: Some(vec!["image".into()]), ..Default::default() }).expect("the graph runs");
        std::sync::Mutex::new((g, e))
    })
}

#[divan::bench(args = KINDS, sample_count = 10, sample_size = 1)]
fn edit(bencher: divan::Bencher, kind: &str) {
    let opts = RunOptions { outputs: Some(vec!["image".into()]), ..Default::default() };
    let k = AtomicU64::new(1);
    let mut guard = warmed().lock().unwrap();
    let (g, e) = &mut *guard;
    bencher.bench_local(|| {
        let i = k.fetch_add(1, Ordering::Relaxed);
        for (param, value) in edits(kind) {
            g.set_param_text(e.registry(), param, &value(i)).unwrap();
        }
        e.run(g, &opts).unwrap().report.ran
    });
}
