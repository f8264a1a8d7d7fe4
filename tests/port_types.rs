//! Every registered port type survives the disk cache: encode → decode gives the same bytes
//! and fingerprint, a second engine reads every node's result back from disk, and a truncated
//! entry of each type is a miss that is recomputed, never a crash.

use relume_core::{DiskPolicy, Engine, Graph, Hash, RunOptions};
use relume_tests::{add_output, files_under, load_graph, load_test_graph};
use std::collections::BTreeSet;

/// `pbgi_vs_reference.ron` at test size with every output port of every node as an output:
/// with `relight_ring.ron`, `relight_sv_spot.ron`, `voxelize_glass.ron`, `refract_glass.ron`,
/// `ptt_envlit.ron` and `wpbgi_ring.ron` (its `bdpt` node's bands too) it produces every port
/// type relume registers.
fn every_port_graph() -> Graph {
    let g = load_graph(
        "pbgi_vs_reference.ron",
        &[
            ("scene.width", "16"),
            ("scene.height", "16"),
            ("points.count", "2000"),
            ("shade.samples", "2"),
            ("direct.pixel_samples", "2"),
            ("reference.spp", "4"),
            ("pt.spp", "2"),
        ],
    );
    every_port(g)
}

/// `g` with every output port of every node as an output.
fn every_port(mut g: Graph) -> Graph {
    let reg = relume_cli::registry();
    g.outputs.clear();
    for n in g.nodes.clone() {
        for p in &reg.node(&n.kind).unwrap().ports().outputs {
            add_output(&mut g, &format!("{}__{}", n.id, p.name), &format!("{}.{}", n.id, p.name));
        }
    }
    g
}

/// A relighting graph at test size: 12 × 10 pixels, a small BRDF space, few paths.
fn small_relight(name: &str, extra: &[(&str, &str)]) -> Graph {
    let mut set = vec![
        ("scene.width", "12"),
        ("scene.height", "10"),
        ("space.n_theta_i", "8"),
        ("space.n_theta_o", "8"),
        ("space.n_phi", "16"),
        ("space.samples", "21"),
        ("transfer.spp", "2"),
        ("transfer.bounce_rays", "2"),
        ("reference.spp", "2"),
    ];
    set.extend_from_slice(extra);
    load_graph(name, &set)
}

#[test]
fn every_port_type_round_trips_through_its_encoding_and_the_disk_cache() {
    let reg = relume_cli::registry();
    let g = every_port_graph();
    let dir = tempfile::tempdir().unwrap();
    let first = Engine::new(relume_cli::registry()).with_disk_cache(dir.path()).with_disk_policy(DiskPolicy::Always);
    let r1 = first.run(&g, &RunOptions::default()).unwrap();
    // The relighting types come from the ring's relighting graph (same engine, same cache).
    let b = every_port(small_relight("relight_ring.ron", &[]));
    let rb = first.run(&b, &RunOptions::default()).unwrap();
    // The spatially varying relighting's transfer from its own graph.
    let c = every_port(small_relight("relight_sv_spot.ron", &[("transfer.sub_regions", "4")]));
    let rc = first.run(&c, &RunOptions::default()).unwrap();
    // The volume of pipeline 3.
    let d = every_port(load_graph("voxelize_glass.ron", &[("voxelize.resolution", "12")]));
    let rd = first.run(&d, &RunOptions::default()).unwrap();
    // Photons, their caustic map and the camera from the refraction graph.
    let e = every_port(load_graph(
        "refract_glass.ron",
        &[("voxelize.resolution", "12"), ("emit.resolution", "24"), ("reference.spp", "1"), ("scene.width", "8"), ("scene.height", "8")],
    ));
    let re = first.run(&e, &RunOptions::default()).unwrap();
    // The transfer tensors of pipeline 2 at test size, precompute to relit image, on the
    // Spot-and-teapot scene: the same types as on the bunny's, from fewer vertices (the test
    // took 14.7 s against 24.4 s).
    let f = load_test_graph(
        "ptt_envlit.ron",
        &[
            ("scene.path", "scenes/envlit-pair.ron"),
            ("project.object", "\"spot\""),
            ("reference.spp", "1"),
            ("scene.width", "8"),
            ("scene.height", "8"),
        ],
    );
    let f = every_port(f);
    let rf = first.run(&f, &RunOptions::default()).unwrap();
    // The wavelet PBGI's per-point wavelets and coded tree from the ring's graph, and the
    // bidirectional path tracer's bands with their splats.
    let h = every_port(load_graph(
        "wpbgi_ring.ron",
        &[
            ("scene.width", "8"),
            ("scene.height", "8"),
            ("points.count", "500"),
            ("wavelets.resolution", "8"),
            ("direct.pixel_samples", "1"),
            ("reference.spp", "1"),
            ("bdpt.spp", "2"),
        ],
    ));
    let rh = first.run(&h, &RunOptions::default()).unwrap();

    // Every registered port type is produced by this graph (as an output, or as the partial
    // results of its sharded nodes, kept on disk chunk by chunk), and each value decodes to
    // itself.
    let mut produced: BTreeSet<&str> = r1
        .outputs
        .iter()
        .chain(&rb.outputs)
        .chain(&rc.outputs)
        .chain(&rd.outputs)
        .chain(&re.outputs)
        .chain(&rf.outputs)
        .chain(&rh.outputs)
        .map(|(_, v)| v.type_name())
        .collect();
    for n in r1
        .report
        .nodes
        .iter()
        .chain(&rb.report.nodes)
        .chain(&rc.report.nodes)
        .chain(&rd.report.nodes)
        .chain(&re.report.nodes)
        .chain(&rf.report.nodes)
        .chain(&rh.report.nodes)
    {
        let kind = reg.node(&n.kind).unwrap();
        if let (Some(sh), Some(stats)) = (kind.sharded(), &n.shards) {
            assert_eq!((stats.ran, stats.cached), (stats.chunks, 0), "{}: every chunk ran", n.id);
            produced.insert(sh.partial_decl().ty.name);
        }
    }
    let registered: BTreeSet<&str> = reg.port_types().map(|t| t.name).collect();
    assert_eq!(produced, registered, "the graph covers every registered port type");
    for (name, v) in
        r1.outputs.iter().chain(&rb.outputs).chain(&rc.outputs).chain(&rd.outputs).chain(&re.outputs).chain(&rf.outputs).chain(&rh.outputs)
    {
        let bytes = v.encode();
        let info = reg.port_type(v.type_name()).unwrap();
        let back = (info.decode)(&bytes, v.fingerprint()).unwrap_or_else(|| panic!("{name} ({}) does not decode", v.type_name()));
        assert_eq!(back.encode(), bytes, "{name}: decode then encode gives the same bytes");
        assert!(
            (info.decode)(&bytes[..bytes.len() / 2], Hash::default()).is_none_or(|_| bytes.len() < 2),
            "{name}: half the bytes is no value"
        );
    }

    // A second engine (another process) gets every node's result from disk, the same values.
    let second = Engine::new(relume_cli::registry()).with_disk_cache(dir.path());
    for (graph, r) in [(&g, &r1), (&b, &rb), (&c, &rc), (&d, &rd), (&e, &re), (&f, &rf), (&h, &rh)] {
        let r2 = second.run(graph, &RunOptions::default()).unwrap();
        assert_eq!(r2.report.ran, 0, "{:?}", r2.report.ran_ids());
        // From disk, or from memory where an earlier graph or node had the same one (the BRDF
        // space and basis of the two relighting graphs; the refraction graph's `bvh` of the
        // unmoved lamp is `paths_bvh`'s; the transfer-tensor graph's orbit at its defaults is
        // `ref_camera`, the scene's view, and what it sees `ref_hits`).
        let not_disk: Vec<(&str, Option<&str>)> =
            r2.report.nodes.iter().filter(|n| n.cache != Some("disk")).map(|n| (n.id.as_str(), n.cache)).collect();
        assert!(
            not_disk.iter().all(|(id, c)| *c == Some("memory") && ["space", "pca", "bvh", "camera", "hits"].contains(id)),
            "{not_disk:?}"
        );
        for ((n1, v1), (n2, v2)) in r.outputs.iter().zip(&r2.outputs) {
            assert_eq!((n1, v1.fingerprint(), v1.encode()), (n2, v2.fingerprint(), v2.encode()));
        }
    }

    // Truncate every entry: each is a miss, recomputed and written back whole.
    for f in files_under(dir.path()) {
        let b = std::fs::read(&f).unwrap();
        std::fs::write(&f, &b[..b.len() / 2]).unwrap();
    }
    let third = Engine::new(relume_cli::registry()).with_disk_cache(dir.path()).with_disk_policy(DiskPolicy::Always);
    let r3 = third.run(&g, &RunOptions::default()).unwrap();
    assert_eq!(r3.report.ran, g.nodes.len(), "every truncated entry is a miss");
    for ((_, v1), (_, v3)) in r1.outputs.iter().zip(&r3.outputs) {
        assert_eq!(v1.fingerprint(), v3.fingerprint(), "recomputed results are the same bytes");
    }
}
