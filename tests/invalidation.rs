//! Which nodes re-run after an edit: the incremental cache, asserted node by node.

use relume_core::{DiskPolicy, Engine, Graph, RunOptions};
use relume_tests::{engine, files_under, graphs_dir, ran, run, test_registry, Log};
use std::path::Path;

fn filters() -> Graph {
    Graph::load(&graphs_dir().join("filters.ron"), &relume_cli::registry()).unwrap()
}

fn set(g: &mut Graph, e: &Engine, lhs: &str, v: &str) {
    g.set_param_text(e.registry(), lhs, v).unwrap();
}

#[test]
fn a_second_identical_run_runs_nothing() {
    let e = engine();
    let g = filters();
    assert_eq!(ran(&run(&e, &g)).len(), 7);
    let r = run(&e, &g);
    assert!(ran(&r).is_empty());
    assert_eq!(r.cached, 7);
}

#[test]
fn editing_a_parameter_reruns_only_the_nodes_downstream_of_it() {
    let e = engine();
    let mut g = filters();
    run(&e, &g);
    set(&mut g, &e, "blur.sigma", "1.2");
    assert_eq!(ran(&run(&e, &g)), ["blur", "error", "tonemap"]);
    set(&mut g, &e, "tonemap.exposure", "-1");
    assert_eq!(ran(&run(&e, &g)), ["tonemap"]);
}

#[test]
fn an_upstream_rerun_that_reproduces_identical_bytes_stops_the_wave() {
    let e = engine();
    let mut g = filters();
    run(&e, &g);
    // `clean` has no noise, so its seed changes its key but not its pixels.
    set(&mut g, &e, "clean.seed", "99");
    assert_eq!(ran(&run(&e, &g)), ["clean"]);
}

#[test]
fn reverting_an_edit_finds_the_earlier_results_in_the_cache() {
    let e = engine();
    let mut g = filters();
    run(&e, &g);
    set(&mut g, &e, "median.radius", "2");
    assert_eq!(ran(&run(&e, &g)), ["blur", "error", "median", "tonemap"]);
    set(&mut g, &e, "median.radius", "1");
    assert!(ran(&run(&e, &g)).is_empty());
}

fn copy_image_error_graph(dir: &Path) -> Graph {
    std::fs::create_dir_all(dir.join("assets")).unwrap();
    for f in ["image_error.ron", "assets/reference.exr", "assets/render.exr"] {
        std::fs::copy(graphs_dir().join(f), dir.join(f)).unwrap();
    }
    Graph::load(&dir.join("image_error.ron"), &relume_cli::registry()).unwrap()
}

#[test]
fn changing_a_referenced_files_content_reruns_its_loader_and_everything_below() {
    let dir = tempfile::tempdir().unwrap();
    let g = copy_image_error_graph(dir.path());
    let e = engine();
    assert_eq!(ran(&run(&e, &g)).len(), 5);
    // Same bytes written again: the key hashes content, not the modification time.
    let bytes = std::fs::read(dir.path().join("assets/render.exr")).unwrap();
    std::fs::write(dir.path().join("assets/render.exr"), &bytes).unwrap();
    assert!(ran(&run(&e, &g)).is_empty());
    // New content: the loader and what depends on it re-run; the reference side does not.
    std::fs::copy(dir.path().join("assets/reference.exr"), dir.path().join("assets/render.exr")).unwrap();
    let r = run(&e, &g);
    assert_eq!(ran(&r), ["denoise", "error", "error_denoised", "render"]);
    assert_eq!(r.node("error").unwrap().metrics["mse"], 0.0);
}

#[test]
fn moving_a_node_in_the_editor_section_reruns_nothing() {
    let e = engine();
    let mut g = filters();
    run(&e, &g);
    for (_, p) in &mut g.editor.positions {
        p[0] += 37.5;
    }
    g.editor.positions.reverse();
    assert!(ran(&run(&e, &g)).is_empty());
}

#[test]
fn a_branch_that_no_requested_output_needs_never_runs() {
    let e = engine();
    let g = filters();
    let opts = RunOptions { outputs: Some(vec!["image".into()]), ..Default::default() };
    let r = e.run(&g, &opts).unwrap().report;
    assert_eq!(ran(&r), ["blur", "clean", "median", "noisy", "sum", "tonemap"]);
    assert!(r.node("error").is_none(), "the error node is not needed for `image`");
}

#[test]
fn a_second_engine_on_a_disk_cache_written_with_the_always_policy_finds_every_node_cached() {
    let dir = tempfile::tempdir().unwrap();
    let g = copy_image_error_graph(&dir.path().join("g"));
    let cache = dir.path().join("cache");
    let first = Engine::new(relume_cli::registry()).with_disk_cache(&cache).with_disk_policy(DiskPolicy::Always);
    assert_eq!(run(&first, &g).ran, 5);
    let second = Engine::new(relume_cli::registry()).with_disk_cache(&cache);
    let r = run(&second, &g);
    assert_eq!((r.ran, r.cached), (0, 5));
    assert!(r.nodes.iter().all(|n| n.cache == Some("disk")));
    assert_eq!(r.node("error").unwrap().metrics.len(), 7, "metrics come back from the disk cache");
}

#[test]
fn truncated_or_corrupted_disk_cache_entries_are_misses_not_crashes() {
    let dir = tempfile::tempdir().unwrap();
    let log = Log::default();
    let g = Graph::parse(
        r#"Graph(version: 1, nodes: { "a": (kind: "Mix0", params: (salt: 1)), "b": (kind: "Mix1", params: ()), "c": (kind: "Mix1", params: ()) },
           edges: [("a.out", "b.in0"), ("b.out", "c.in0")], outputs: { "x": "c.out" })"#,
        None,
    )
    .unwrap();
    let cache = dir.path().join("cache");
    let fresh = || Engine::new(test_registry(&log)).with_disk_cache(&cache).with_disk_policy(DiskPolicy::Always);
    assert_eq!(run(&fresh(), &g).ran, 3);
    let mut files: Vec<_> = files_under(&cache);
    files.sort();
    assert_eq!(files.len(), 3);
    // Truncate one entry, flip a byte in another, leave the third alone.
    let b0 = std::fs::read(&files[0]).unwrap();
    std::fs::write(&files[0], &b0[..b0.len() / 2]).unwrap();
    let mut b1 = std::fs::read(&files[1]).unwrap();
    b1[60] ^= 0xff;
    std::fs::write(&files[1], &b1).unwrap();
    let r = run(&fresh(), &g);
    assert_eq!(r.ran, 2, "the two damaged entries are recomputed");
    assert_eq!(r.cached, 1);
    assert_eq!(run(&fresh(), &g).ran, 0, "recomputed entries were written back whole");
}

#[test]
fn cache_keys_of_the_filters_graph_are_pinned() {
    // If this fails, a key changed: bump the VERSION of the node whose output changed, or,
    // if the key scheme itself changed on purpose, update these values.
    let r = run(&engine(), &filters());
    let key = |id: &str| r.node(id).unwrap().key[..16].to_string();
    let got: Vec<_> =
        ["clean", "noisy", "sum", "median", "blur", "error", "tonemap"].iter().map(|id| format!("{id}={}", key(id))).collect();
    assert_eq!(got, PINNED, "cache keys changed");
}

// Updated on purpose with the node API v2: an image's fingerprint is now the hash
// of its disk encoding (type name, then the length-prefixed encoded bytes), so the key of
// every node fed an image changed; the two sources, whose keys depend on their parameters
// only, kept theirs (parameter hashing did not change, only its normalisation).
const PINNED: [&str; 7] = [
    "clean=8985c21ab8a2d0b1",
    "noisy=af35dfb8813909b6",
    "sum=6004bef7f8189fc0",
    "median=cc1649220ce77563",
    "blur=866c5bd3ae9ec4fa",
    "error=1a665f0afaafb51b",
    "tonemap=a2599a99a9e7d24c",
];

#[test]
fn editing_a_mesh_named_inside_a_scene_file_reruns_the_scene_loader_and_what_follows() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("scenes")).unwrap();
    std::fs::create_dir_all(dir.path().join("assets/cornell")).unwrap();
    for f in ["scenes/cornell.ron", "assets/cornell/cornell_box.obj", "assets/cornell/cornell_box.mtl"] {
        std::fs::copy(graphs_dir().join(f), dir.path().join(f)).unwrap();
    }
    let text = r#"Graph(version: 1, nodes: {
        "scene": (kind: "LoadScene", params: (path: "scenes/cornell.ron", width: 8, height: 8)),
        "bvh": (kind: "BuildBvh", params: ()),
        "pt": (kind: "PathTrace", params: (spp: 2, max_depth: 2)),
    }, edges: [("scene.scene", "bvh.scene"), ("scene.scene", "pt.scene"), ("bvh.accel", "pt.accel")],
    outputs: { "image": "pt.image" })"#;
    std::fs::write(dir.path().join("g.ron"), text).unwrap();
    let g = Graph::load(&dir.path().join("g.ron"), &relume_cli::registry()).unwrap();
    let e = engine();
    assert_eq!(ran(&run(&e, &g)), ["bvh", "pt", "scene"]);
    assert!(ran(&run(&e, &g)).is_empty());
    // A colour in the MTL changes: the scene's content changes, so everything re-runs.
    let mtl = dir.path().join("assets/cornell/cornell_box.mtl");
    let text = std::fs::read_to_string(&mtl).unwrap().replace("Kd 0.570068", "Kd 0.470068");
    std::fs::write(&mtl, text).unwrap();
    assert_eq!(ran(&run(&e, &g)), ["bvh", "pt", "scene"]);
}
