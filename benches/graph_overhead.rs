//! Per-graph benchmarks on a generated 200-node graph: cold (nothing cached), warm
//! (everything cached: the framework's own overhead) and after one parameter edit; and
//! loading, validating and planning generated graphs of 2,000 to 32,000 nodes, whose times
//! should grow with the size, not its square.

use relume_benches::{edit_node, generated_graph, generated_graph_text};
use relume_core::{make_plan, Engine, Graph, RunOptions};
use std::sync::atomic::{AtomicU64, Ordering};

const N: usize = 200;

fn main() {
    divan::main();
}

#[divan::bench(sample_count = 20)]
fn cold(bencher: divan::Bencher) {
    let g = generated_graph(N);
    bencher
        .with_inputs(|| Engine::new(relume_cli::registry()))
        .bench_local_values(|engine| engine.run(&g, &RunOptions::default()).unwrap().report.ran);
}

#[divan::bench(sample_count = 200)]
fn warm(bencher: divan::Bencher) {
    let g = generated_graph(N);
    let engine = Engine::new(relume_cli::registry());
    engine.run(&g, &RunOptions::default()).unwrap();
    bencher.bench_local(|| {
        let r = engine.run(&g, &RunOptions::default()).unwrap();
        assert_eq!(r.report.ran, 0);
        r.report.cached
    });
}

#[divan::bench(sample_count = 50)]
fn after_one_edit(bencher: divan::Bencher) {
    let mut g = generated_graph(N);
    let engine = Engine::new(relume_cli::registry());
    engine.run(&g, &RunOptions::default()).unwrap();
    let node = edit_node(N);
    let step = AtomicU64::new(0);
    bencher.bench_local(|| {
        // A new sigma every time, so the edit is never found in the cache.
        let k = step.fetch_add(1, Ordering::Relaxed);
        g.set_param_text(engine.registry(), &format!("{node}.sigma"), &format!("{}", 1.0 + k as f64 * 1e-6)).unwrap();
        engine.run(&g, &RunOptions::default()).unwrap().report.ran
    });
}

#[divan::bench(args = [2_000, 8_000, 32_000], sample_count = 5)]
fn load_validate_plan(bencher: divan::Bencher, n: usize) {
    let text = generated_graph_text(n);
    let reg = relume_cli::registry();
    bencher.bench_local(|| {
        let g = Graph::parse(&text, None).unwrap();
        g.validate(&reg).unwrap();
        make_plan(&g, &reg, None).unwrap().order.len()
    });
}
