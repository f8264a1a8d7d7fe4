//! Same inputs, same bytes, on any thread count: every graph of `graphs/` (at test size) run
//! with one thread and with two, every output compared byte for byte.

use relume_core::{Engine, Graph, RunOptions};
use relume_tests::all_graphs;

/// The graph at test size (as `graphs_run.rs` runs it).
fn test_size(path: &std::path::Path) -> Graph {
    let reg = relume_nodes::registry();
    let mut g = Graph::load(path, &reg).unwrap_or_else(|e| panic!("{e}"));
    for n in g.nodes.clone() {
        let set = |g: &mut Graph, p: &str, v: &str| g.set_param_text(&reg, &format!("{}.{p}", n.id), v).unwrap();
        match n.kind.as_str() {
            "LoadScene" => {
                set(&mut g, "width", "24");
                set(&mut g, "height", "20");
            }
            "PathTrace" => set(&mut g, "spp", "4"),
            "SampleSurface" => set(&mut g, "count", "3000"),
            "DirectLight" => set(&mut g, "pixel_samples", "4"),
            "Voxelize" | "VolumeSource" => set(&mut g, "resolution", "32"),
            "EmitPhotons" => set(&mut g, "resolution", "64"),
            kind => relume_nodes::ptt::test_size(kind).iter().for_each(|(p, v)| set(&mut g, p, v)),
        }
    }
    g
}

#[test]
fn every_graph_gives_the_same_bytes_on_one_thread_and_on_two() {
    for path in all_graphs() {
        let g = test_size(&path);
        let run = |threads| {
            let e = Engine::new(relume_nodes::registry()).with_threads(threads).with_parallelism(threads);
            e.run(&g, &RunOptions::default()).unwrap_or_else(|err| panic!("{}: {err}", path.display()))
        };
        let (one, two) = (run(1), run(2));
        assert_eq!(one.outputs.len(), g.outputs.len());
        for ((name, a), (_, b)) in one.outputs.iter().zip(&two.outputs) {
            assert!(a.encode() == b.encode(), "{}: output {name} differs between 1 and 2 threads", path.display());
        }
    }
}
