//! Cancelling a run while each heavy node is midway: the run stops with `Cancelled`, nothing
//! of the cancelled node reaches the memory or disk cache, what finished before it stays
//! cached, and the next run computes the same bytes as a run never cancelled.

use relume_core::{CancelToken, DiskPolicy, Engine, Event, Observer, RunError, RunOptions};
use relume_tests::load_graph;

/// Cancels the run at the first progress report of node `target`.
struct CancelAt {
    target: &'static str,
    token: CancelToken,
}

impl Observer for CancelAt {
    fn event(&self, e: &Event<'_>) {
        if let Event::Progress { id, .. } = e {
            if *id == self.target {
                self.token.cancel();
            }
        }
    }
}

fn graph() -> relume_core::Graph {
    load_graph(
        "pbgi_vs_reference.ron",
        &[
            ("scene.width", "32"),
            ("scene.height", "32"),
            ("points.count", "10000"),
            ("shade.samples", "4"),
            ("direct.pixel_samples", "4"),
            ("reference.spp", "16"),
            ("pt.spp", "4"),
            ("clusters.tile", "8"),
            ("clusters.k", "4"),
        ],
    )
}

#[test]
fn cancelling_each_heavy_node_midway_stops_the_run_and_leaves_the_cache_consistent() {
    let g = graph();
    let clean = Engine::new(relume_cli::registry()).run(&g, &RunOptions::default()).unwrap();
    for target in ["points", "shade", "tree", "gbuffer", "clusters", "pbgi", "fpbgi", "direct", "reference", "pbgi_error"] {
        let dir = tempfile::tempdir().unwrap();
        let engine =
            Engine::new(relume_cli::registry()).with_disk_cache(dir.path()).with_disk_policy(DiskPolicy::Always).with_parallelism(1);
        let obs = CancelAt { target, token: CancelToken::new() };
        let opts = RunOptions { cancel: obs.token.clone(), observer: Some(&obs), ..Default::default() };
        let err = engine.run(&g, &opts).err();
        assert!(matches!(err, Some(RunError::Cancelled)), "{target}: the run did not stop: {err:?}");
        // A fresh engine on the same disk cache: the cancelled node left nothing there.
        let after = Engine::new(relume_cli::registry()).with_disk_cache(dir.path());
        let r = after.run(&g, &RunOptions::default()).unwrap();
        assert_eq!(r.report.node(target).unwrap().status, "ran", "{target} was cached although cancelled");
        // The same engine again: nothing of the cancelled node is in memory either, and the
        // results are the bytes of a run never cancelled.
        let again = engine.run(&g, &RunOptions::default()).unwrap();
        for ((name, a), (_, b)) in clean.outputs.iter().zip(&again.outputs) {
            assert!(a.encode() == b.encode(), "{target}: output {name} differs after a cancelled run");
        }
    }
}
