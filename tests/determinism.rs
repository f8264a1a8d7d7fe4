//! Every graph of `graphs/` runs (at test size), its outputs are finite, and it gives the same
//! bytes on any thread count: each graph is run with one thread and with two, every output
//! checked for non-finite pixels and metrics and compared byte for byte. One engine for each
//! thread count serves all the graphs, as one serves a user's session: a node that several
//! graphs share (a scene, a BRDF basis, a precompute) is computed once on one thread and once
//! on two, and every graph's outputs are still compared. (One pass over the graphs does both
//! checks: the graphs are the test command's largest cost.) The two runs of a graph go at
//! once: the one-thread run alone would leave a second core idle.

use relume_base::types::{Image, Metrics};
use relume_core::{Engine, RunOptions, Value};
use relume_tests::{all_graphs, at_test_size};

/// Panics when `v` is an image with a non-finite pixel or metrics empty or not finite.
fn assert_finite(graph: &str, name: &str, v: &Value) {
    if let Some(img) = v.get::<Image>() {
        assert_eq!(img.nonfinite_pixels(), 0, "{graph}: {name}");
    }
    if let Some(m) = v.get::<Metrics>() {
        assert!(!m.0.is_empty() && m.0.iter().all(|(_, x)| x.is_finite()), "{graph}: {name}: {m:?}");
    }
}

#[test]
fn every_graph_runs_with_finite_outputs_and_the_same_bytes_on_one_thread_and_on_two() {
    let engines = [1, 2].map(|threads| Engine::new(relume_cli::registry()).with_threads(threads).with_parallelism(threads));
    for path in all_graphs() {
        let g = at_test_size(&path);
        let shown = path.display().to_string();
        let run = |e: &Engine| e.run(&g, &RunOptions::default()).unwrap_or_else(|err| panic!("{shown}: {err}"));
        let (one, two) = std::thread::scope(|s| {
            let one = s.spawn(|| run(&engines[0]));
            let two = run(&engines[1]);
            (one.join().unwrap_or_else(|p| std::panic::resume_unwind(p)), two)
        });
        assert_eq!(one.outputs.len(), g.outputs.len(), "{shown}");
        for ((name, a), (_, b)) in one.outputs.iter().zip(&two.outputs) {
            assert_finite(&shown, name, a);
            assert!(a.encode() == b.encode(), "{shown}: output {name} differs between 1 and 2 threads");
        }
    }
}
