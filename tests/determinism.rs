//! Same inputs, same bytes, on any thread count: every graph of `graphs/` (at test size) run
//! with one thread and with two, every output compared byte for byte. One engine for each
//! thread count serves all the graphs, as one serves a user's session: a node that several
//! graphs share (a scene, a BRDF basis, a precompute) is computed once on one thread and once
//! on two, and every graph's outputs are still compared.

use relume_core::{Engine, RunOptions};
use relume_tests::{all_graphs, at_test_size};

#[test]
fn every_graph_gives_the_same_bytes_on_one_thread_and_on_two() {
    let engines = [1, 2].map(|threads| Engine::new(relume_cli::registry()).with_threads(threads).with_parallelism(threads));
    for path in all_graphs() {
        let g = at_test_size(&path);
        let run = |e: &Engine| e.run(&g, &RunOptions::default()).unwrap_or_else(|err| panic!("{}: {err}", path.display()));
        let (one, two) = (run(&engines[0]), run(&engines[1]));
        assert_eq!(one.outputs.len(), g.outputs.len());
        for ((name, a), (_, b)) in one.outputs.iter().zip(&two.outputs) {
            assert!(a.encode() == b.encode(), "{}: output {name} differs between 1 and 2 threads", path.display());
        }
    }
}
