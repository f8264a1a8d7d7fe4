//! The memory model: a whole run whose estimate exceeds the budget is refused before anything
//! runs, with the estimate per node; `plan` (and so `relume check`/`plan`) gives the same
//! refusal; a run inside the budget is unaffected.

use relume_core::{Engine, RunError, RunOptions};
use relume_tests::load_graph;

const SIX_K: [(&str, &str); 4] = [("clean.width", "6000"), ("clean.height", "6000"), ("noisy.width", "6000"), ("noisy.height", "6000")];

#[test]
fn filters_at_6000_squared_is_refused_under_a_4_gib_budget_before_any_node_runs() {
    let g = load_graph("filters.ron", &SIX_K);
    let e = Engine::new(relume_cli::registry()).with_run_budget(4 << 30, "the test");
    let plan = relume_core::make_plan(&g, e.registry(), None).unwrap();
    let est = e.estimate(&g, &plan);
    eprintln!("estimated peak {} bytes", est.peak);
    // Measured: this run peaks at 7.45 GiB RSS (the SSIM planes of the error node).
    assert!(est.peak > 6 << 30 && est.peak < 9 << 30, "estimate {} GiB", est.peak as f64 / (1u64 << 30) as f64);
    let err = e.run(&g, &RunOptions::default()).err().expect("refused");
    let msg = err.to_string();
    eprintln!("{msg}");
    assert!(matches!(err, RunError::Graph(_)), "a refusal is bad input, not a node failure");
    assert!(msg.contains("filters.ron") && msg.contains("over the memory budget of 4.00 GiB"), "{msg}");
    assert!(msg.contains("\"error\" (ImageError)") && msg.contains("working"), "{msg}");
    assert_eq!(e.memory_bytes(), 0, "nothing ran, nothing was cached");
    let planned = e.plan(&g, None).expect_err("plan refuses the same").to_string();
    assert_eq!(planned, msg, "check/plan give the refusal run gives");
    // The same graph fits a budget above the estimate (planned only: running it takes a minute).
    assert!(Engine::new(relume_cli::registry()).with_run_budget(16 << 30, "the test").plan(&g, None).is_ok());
}

#[test]
fn the_point_based_graphs_at_1024_squared_and_a_million_points_are_refused_before_any_node_runs() {
    // The theses' scale: each graph's estimate per node comes from its parameters alone (the
    // points' count, the image's size), so the refusal needs no node to run.
    let at_scale = |graph: &str, scene: Option<&'static str>| {
        let mut sets = vec![("scene.width", "1024"), ("scene.height", "1024"), ("points.count", "1000000")];
        sets.extend(scene.map(|s| ("scene.path", s)));
        load_graph(graph, &sets)
    };
    let cases = [
        ("pbgi_vs_reference.ron", Some("scenes/cornell-heavy.ron"), &["\"tree\" (PointTree)", "\"gbuffer\" (GBuffer)"][..]),
        ("vpbgi_cornell.ron", None, &["\"wavelets\" (SurfelWavelets)", "\"tree\" (PointTree)"][..]),
        ("wpbgi_ring.ron", None, &["\"wavelets\" (SurfelWavelets)", "\"tree\" (PointTree)"][..]),
    ];
    for (graph, scene, named) in cases {
        let g = at_scale(graph, scene);
        let e = Engine::new(relume_cli::registry()).with_run_budget(512 << 20, "the test");
        let msg = e.plan(&g, None).expect_err("refused").to_string();
        assert!(msg.contains("over the memory budget of 512.0 MiB"), "{graph}: {msg}");
        for node in named {
            assert!(msg.contains(node), "{graph}: {node} is among the estimates: {msg}");
        }
        let err = e.run(&g, &RunOptions::default()).err().expect("a run is refused the same");
        assert_eq!(err.to_string(), msg);
        assert_eq!(e.memory_bytes(), 0, "{graph}: nothing ran");
    }
    // PBGI's graph at that scale fits 4 GiB (its sweeps ran so, peaking at 1.1–1.2 GiB).
    let g = at_scale("pbgi_vs_reference.ron", Some("scenes/cornell-heavy.ron"));
    assert!(Engine::new(relume_cli::registry()).with_run_budget(4 << 30, "the test").plan(&g, None).is_ok());
}

#[test]
fn a_budget_too_small_for_one_node_with_actual_inputs_is_refused_at_that_node() {
    // LoadImage's size is known from the file header; downstream estimates follow from it.
    let g = load_graph("image_error.ron", &[]);
    let e = Engine::new(relume_cli::registry()).with_run_budget(1 << 20, "the test");
    let msg = e.run(&g, &RunOptions::default()).err().expect("refused").to_string();
    assert!(msg.contains("over the memory budget of 1.0 MiB"), "{msg}");
    let ok = Engine::new(relume_cli::registry()).with_run_budget(1 << 30, "the test").run(&g, &RunOptions::default());
    assert!(ok.is_ok(), "the same graph runs under 1 GiB");
}

#[test]
fn two_nodes_that_fit_the_budget_only_one_at_a_time_run_one_after_the_other() {
    use relume_core::{Graph, Registry};
    use std::sync::{Arc, Mutex};
    let log = Arc::new(Mutex::new(Vec::new()));
    let mut reg = Registry::new();
    reg.add_dyn(relume_tests::big(600, &log));
    let g = Graph::parse(
        r#"(version: 1, nodes: { "a": (kind: "Big", params: (salt: 1)), "b": (kind: "Big", params: (salt: 2)) }, outputs: { "a": "a.out", "b": "b.out" })"#,
        None,
    )
    .unwrap();
    // 600 + 8 bytes each: both fit 1000 bytes alone, not together (the static walk counts
    // them in turn, holding the first one's 8-byte output).
    let e = Engine::new(reg.clone()).with_run_budget(1000, "the test").with_parallelism(2);
    assert!(e.plan(&g, None).is_ok(), "the static walk fits: one at a time");
    let r = e.run(&g, &RunOptions::default()).unwrap();
    assert_eq!(r.report.ran, 2);
    let spans = log.lock().unwrap().clone();
    assert!(spans[0].1 <= spans[1].0, "the second started after the first ended: {spans:?}");
    // A node that does not fit alone is refused, by name.
    let msg = Engine::new(reg).with_run_budget(500, "the test").run(&g, &RunOptions::default()).err().unwrap().to_string();
    assert!(msg.contains("\"a\" (Big)") || msg.contains("\"b\" (Big)"), "{msg}");
}

#[test]
fn relume_check_plan_and_run_refuse_the_same_run_with_exit_code_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let graph = relume_tests::graphs_dir().join("filters.ron").display().to_string();
    let sets: Vec<String> = SIX_K.iter().map(|(k, v)| format!("{k}={v}")).collect();
    let relume = |cmd: &str, budget: &str| {
        let mut args = vec!["relume", cmd, &graph, "--no-disk-cache", "--memory-budget", budget];
        for s in &sets {
            args.extend(["--set", s.as_str()]);
        }
        if cmd == "run" {
            args.extend(["--out", out.to_str().unwrap(), "--quiet"]);
        }
        relume_cli::main_from(args.iter().copied())
    };
    assert_eq!(relume("check", "4G"), 2);
    assert_eq!(relume("plan", "4G"), 2);
    assert_eq!(relume("run", "4G"), 2);
    assert_eq!(relume("check", "16G"), 0);
}
