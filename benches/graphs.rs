//! Every pipeline graph of `graphs/` cold (nothing cached), warm (everything cached in
//! memory: the framework's overhead) and after its representative edit (`graph_edits` in
//! lib.rs: the light moved, a filter's sigma, a seed), at bench size (`bench_graph`).
//! `cargo bench -p relume-benches --bench graphs`.

use relume_benches::{bench_graph, graph_edits};
use relume_core::{Engine, RunOptions};
use std::sync::atomic::{AtomicU64, Ordering};

fn main() {
    divan::main();
}

const GRAPHS: &[&str] =
    &["filters.ron", "image_error.ron", "reference_cornell.ron", "pbgi_cornell.ron", "fpbgi_cornell.ron", "pbgi_vs_reference.ron"];

fn engine() -> Engine {
    Engine::new(relume_cli::registry())
}

#[divan::bench(args = GRAPHS, sample_count = 3, sample_size = 1)]
fn cold(bencher: divan::Bencher, name: &str) {
    let g = bench_graph(name);
    bencher.with_inputs(engine).bench_local_values(|e| e.run(&g, &RunOptions::default()).unwrap().report.ran);
}

#[divan::bench(args = GRAPHS, sample_count = 50)]
fn warm(bencher: divan::Bencher, name: &str) {
    let g = bench_graph(name);
    let e = engine();
    e.run(&g, &RunOptions::default()).unwrap();
    bencher.bench_local(|| {
        let r = e.run(&g, &RunOptions::default()).unwrap();
        assert_eq!(r.report.ran, 0);
        r.report.cached
    });
}

#[divan::bench(args = GRAPHS, sample_count = 5, sample_size = 1)]
fn after_one_edit(bencher: divan::Bencher, name: &str) {
    let mut g = bench_graph(name);
    let (_, param, value) = graph_edits().into_iter().find(|e| e.0 == name).expect("every graph has an edit");
    let e = engine();
    e.run(&g, &RunOptions::default()).unwrap();
    let k = AtomicU64::new(1);
    bencher.bench_local(|| {
        g.set_param_text(e.registry(), param, &value(k.fetch_add(1, Ordering::Relaxed))).unwrap();
        e.run(&g, &RunOptions::default()).unwrap().report.ran
    });
}
