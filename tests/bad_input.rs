//! Bad graph files (docs/QUALITY.md §4): every message names the file, line, node and parameter
//! it is about.

use relume_core::Graph;

/// Writes `text` as `bad.ron` in a temp folder, loads it, returns the error text.
fn load_error(text: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.ron");
    std::fs::write(&path, text).unwrap();
    let e = Graph::load(&path, &relume_cli::registry()).expect_err("the graph must be refused").to_string();
    assert!(e.contains("bad.ron:"), "names the file: {e}");
    e
}

const HEAD: &str = "Graph(\n    version: 1,\n    nodes: {\n";

#[test]
fn malformed_ron_names_the_line_and_column() {
    let e = load_error(&format!("{HEAD}        \"a\": (kind: \"Tonemap\" params: ()),\n    }},\n)"));
    assert!(e.contains("bad.ron:4:31: malformed RON: expected `,` or `)`"), "{e}");
}

#[test]
fn an_unknown_node_kind_names_the_node_and_suggests_a_kind() {
    let e = load_error(&format!("{HEAD}        \"t\": (kind: \"tonemap\", params: ()),\n    }},\n)"));
    assert!(e.contains("bad.ron:4:9: node \"t\": unknown node kind \"tonemap\" (did you mean \"Tonemap\"?)"), "{e}");
}

#[test]
fn an_unknown_node_kind_gets_the_closest_kind_by_edit_distance_not_only_for_case() {
    for (typo, want) in
        [("PathTracer", "PathTrace"), ("Tonemapper", "Tonemap"), ("GausianBlur", "GaussianBlur"), ("imageerror", "ImageError")]
    {
        let e = load_error(&format!("{HEAD}        \"n\": (kind: \"{typo}\", params: ()),\n    }},\n)"));
        assert!(e.contains(&format!("bad.ron:4:9: node \"n\": unknown node kind \"{typo}\" (did you mean \"{want}\"?)")), "{e}");
    }
    let e = load_error(&format!("{HEAD}        \"n\": (kind: \"Banana\", params: ()),\n    }},\n)"));
    assert!(e.contains("unknown node kind \"Banana\"; `relume nodes` lists them"), "no far-fetched suggestion: {e}");
}

#[test]
fn an_unknown_parameter_suggests_the_closest_one() {
    let e = load_error(&format!("{HEAD}        \"blur\": (kind: \"GaussianBlur\", params: (sigam: 1.0)),\n    }},\n)"));
    assert!(
        e.contains(
            "bad.ron:4:49: node \"blur\": parameter `sigam`: unknown parameter for GaussianBlur (did you mean `sigma`? it has parameters: sigma, truncate)"
        ),
        "{e}"
    );
    let reg = relume_cli::registry();
    let mut g = Graph::load(&relume_tests::graphs_dir().join("filters.ron"), &reg).unwrap();
    let e = g.set_param_text(&reg, "blur.truncat", "3").unwrap_err().to_string();
    assert!(e.contains("GaussianBlur has no parameter `truncat` (did you mean `truncate`? it has: sigma, truncate)"), "{e}");
}

#[test]
fn an_unconnected_input_names_the_graph_file_as_relume_check_reports_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.ron");
    std::fs::write(&path, "Graph(version: 1, nodes: {\n \"t\": (kind: \"Tonemap\", params: ()),\n})").unwrap();
    let reg = relume_cli::registry();
    let g = Graph::load(&path, &reg).unwrap();
    let e: Vec<String> = g.unconnected_inputs(&reg, "t").iter().map(|e| e.to_string()).collect();
    assert_eq!(e, [format!("{}:2:2: node \"t\": input `image` (Image) is not connected", path.display())]);
}

/// A graph in `dir/graph/g.ron` whose SaveImage writes `target` (relative to the graph).
fn saving_graph(dir: &std::path::Path, target: &str) -> std::path::PathBuf {
    let path = dir.join("graph").join("g.ron");
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(
        &path,
        format!(
            "Graph(version: 1, nodes: {{\n  \"p\": (kind: \"TestPattern\", params: (width: 4, height: 4)),\n  \"save\": (kind: \"SaveImage\", params: (path: \"{target}\")),\n}}, edges: [(\"p.image\", \"save.image\")], outputs: {{ \"x\": \"save.image\" }})"
        ),
    )
    .unwrap();
    path
}

#[test]
fn a_graph_cannot_make_save_image_write_outside_its_folder_unless_the_run_allows_it() {
    use relume_core::{RunOptions, WritePolicy};
    let dir = tempfile::tempdir().unwrap();
    let reg = relume_cli::registry();
    let escape = dir.path().join("elsewhere").join("x.png");
    let g = Graph::load(&saving_graph(dir.path(), "../elsewhere/x.png"), &reg).unwrap();
    let e = relume_tests::engine().run(&g, &RunOptions::default()).err().expect("refused").to_string();
    assert!(e.contains("node \"save\" (SaveImage) failed: parameter `path`: refusing to write"), "{e}");
    assert!(e.contains("outside the folders this run may write to") && e.contains("--allow-writes-anywhere"), "{e}");
    assert!(!escape.exists(), "nothing written outside");
    // Inside the graph's folder, or in a folder the run allows: written.
    let inside = Graph::load(&saving_graph(dir.path(), "sub/in.png"), &reg).unwrap();
    relume_tests::engine().run(&inside, &RunOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert!(dir.path().join("graph/sub/in.png").is_file());
    let opts = RunOptions { writes: WritePolicy::Within(vec![dir.path().join("elsewhere")]), ..Default::default() };
    relume_tests::engine().run(&g, &opts).unwrap_or_else(|e| panic!("{e}"));
    assert!(escape.is_file(), "an extra folder the run allows");
    std::fs::remove_file(&escape).unwrap();
    let opts = RunOptions { writes: WritePolicy::Anywhere, ..Default::default() };
    relume_tests::engine().run(&g, &opts).unwrap_or_else(|e| panic!("{e}"));
    assert!(escape.is_file(), "--allow-writes-anywhere");
}

#[test]
fn a_request_over_a_limit_is_a_refusal_not_a_failure() {
    let g = Graph::parse(
        "Graph(version: 1, nodes: {\n \"a\": (kind: \"TestPattern\", params: (width: 16384, height: 16384)),\n}, outputs: { \"x\": \"a.image\" })",
        Some(std::path::Path::new("g.ron")),
    )
    .unwrap();
    match relume_tests::engine().run(&g, &Default::default()) {
        Err(relume_core::RunError::Node { id, error, .. }) => {
            assert_eq!(id, "a");
            assert!(error.is_over_limit(), "{error:?}");
            assert_eq!(error.to_string(), "an image of 16384 × 16384 pixels needs 3.0 GiB, over the 2 GiB limit");
        }
        other => panic!("expected the node's refusal, got {:?}", other.map(|r| r.report.total_ms)),
    }
}

#[test]
fn an_unknown_parameter_names_node_parameter_and_the_valid_ones() {
    let e =
        load_error(&format!("{HEAD}        \"blur\": (kind: \"GaussianBlur\", params: (sigma: 1.0,\n            radius: 3)),\n    }},\n)"));
    assert!(
        e.contains(
            "bad.ron:5:13: node \"blur\": parameter `radius`: unknown parameter for GaussianBlur (it has parameters: sigma, truncate)"
        ),
        "{e}"
    );
}

#[test]
fn a_missing_required_parameter_names_node_and_parameter() {
    let e = load_error(&format!("{HEAD}        \"img\": (kind: \"LoadImage\", params: ()),\n    }},\n)"));
    assert!(e.contains("bad.ron:4:9: node \"img\": parameter `path`: missing required parameter"), "{e}");
}

#[test]
fn an_out_of_range_value_names_the_range_and_unit() {
    let e = load_error(&format!("{HEAD}        \"blur\": (kind: \"GaussianBlur\", params: (sigma: 500)),\n    }},\n)"));
    assert!(e.contains("bad.ron:4:49: node \"blur\": parameter `sigma`: 500 is out of range [0, 256] px"), "{e}");
    let e = load_error(&format!("{HEAD}        \"t\": (kind: \"Tonemap\", params: (operator: Filmic)),\n    }},\n)"));
    assert!(e.contains("parameter `operator`: `Filmic` is not one of Clamp, Reinhard, Aces"), "{e}");
    let e = load_error(&format!("{HEAD}        \"m\": (kind: \"MedianFilter\", params: (radius: 1.5)),\n    }},\n)"));
    assert!(e.contains("parameter `radius`: expected an integer, found `1.5`"), "{e}");
}

#[test]
fn an_edge_between_different_types_names_both_ends() {
    let e = load_error(&format!(
        "{HEAD}        \"e\": (kind: \"ImageError\", params: ()),\n        \"t\": (kind: \"Tonemap\", params: ()),\n    }},\n    edges: [\n        (\"e.metrics\", \"t.image\"),\n    ],\n)"
    ));
    assert!(e.contains("bad.ron:8:9: edge e.metrics → t.image joins different types: output `metrics` of \"e\" is Metrics, input `image` of \"t\" is Image"), "{e}");
}

#[test]
fn a_cycle_lists_its_nodes() {
    let e = load_error(&format!(
        "{HEAD}        \"a\": (kind: \"Tonemap\", params: ()),\n        \"b\": (kind: \"GaussianBlur\", params: ()),\n    }},\n    edges: [(\"a.image\", \"b.image\"), (\"b.image\", \"a.image\")],\n)"
    ));
    assert!(e.contains("bad.ron:4:9: node \"a\": the edges form a cycle: a → b → a"), "{e}");
}

#[test]
fn dangling_ports_name_the_missing_node_or_port() {
    let e =
        load_error(&format!("{HEAD}        \"t\": (kind: \"Tonemap\", params: ()),\n    }},\n    edges: [(\"x.image\", \"t.image\")],\n)"));
    assert!(e.contains("bad.ron:6:13: edge x.image → t.image: there is no node \"x\""), "{e}");
    let e = load_error(&format!("{HEAD}        \"t\": (kind: \"Tonemap\", params: ()),\n        \"u\": (kind: \"Tonemap\", params: ()),\n    }},\n    edges: [(\"t.img\", \"u.image\")],\n)"));
    assert!(e.contains("Tonemap \"t\" has no output `img` (outputs: image)"), "{e}");
    let e = load_error(&format!("{HEAD}        \"t\": (kind: \"Tonemap\", params: ()),\n    }},\n    edges: [(\"t.image\", \"t\")],\n)"));
    assert!(e.contains("\"t\" is not of the form \"node.port\""), "{e}");
}

#[test]
fn an_unconnected_input_of_a_needed_node_is_refused_before_running() {
    let g = Graph::parse(
        "Graph(version: 1, nodes: {\n \"t\": (kind: \"Tonemap\", params: ()),\n}, outputs: { \"x\": \"t.image\" })",
        Some(std::path::Path::new("g.ron")),
    )
    .unwrap();
    let e = relume_tests::engine().run(&g, &Default::default()).err().unwrap().to_string();
    assert!(e.contains("g.ron:2:2: node \"t\": input `image` (Image) is not connected"), "{e}");
}

#[test]
fn outputs_that_name_nothing_are_refused() {
    let e = load_error(&format!("{HEAD}        \"t\": (kind: \"TestPattern\", params: ()),\n    }},\n    outputs: {{\n        \"image\": \"t.picture\",\n        \"x\": \"nobody.image\",\n    }},\n)"));
    assert!(e.contains("bad.ron:7:9: output \"image\" names t.picture: TestPattern \"t\" has no output `picture`"), "{e}");
    assert!(e.contains("bad.ron:8:9: output \"x\" names nobody.image: there is no node \"nobody\""), "{e}");
}

#[test]
fn a_missing_input_file_names_node_parameter_and_path_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.ron");
    std::fs::write(&path, "Graph(version: 1, nodes: {\n  \"img\": (kind: \"LoadImage\", params: (path: \"nope.exr\")),\n}, outputs: { \"x\": \"img.image\" })").unwrap();
    let g = Graph::load(&path, &relume_cli::registry()).unwrap();
    let e = relume_tests::engine().run(&g, &Default::default()).err().unwrap().to_string();
    assert!(e.contains("g.ron:2:3: node \"img\": parameter `path`: cannot read") && e.contains("nope.exr"), "{e}");
}

#[test]
fn a_device_or_a_folder_named_as_an_input_file_or_a_scene_is_an_error_not_a_hang() {
    // Before: `path: "/dev/zero"` read forever (the cache key hashes an input file's content).
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("folder.exr")).unwrap();
    for (param, target) in [("LoadImage", "/dev/zero"), ("LoadImage", "folder.exr"), ("LoadScene", "/dev/zero")] {
        let path = dir.path().join("g.ron");
        let out = if param == "LoadImage" { "img.image" } else { "img.scene" };
        std::fs::write(&path, format!("Graph(version: 1, nodes: {{\n  \"img\": (kind: \"{param}\", params: (path: \"{target}\")),\n}}, outputs: {{ \"x\": \"{out}\" }})")).unwrap();
        let g = Graph::load(&path, &relume_cli::registry()).unwrap();
        let e = relume_tests::engine().run(&g, &Default::default()).err().unwrap().to_string();
        assert!(e.contains("g.ron:2:3: node \"img\": parameter `path`: cannot read") && e.contains("it is"), "{e}");
    }
}

#[test]
fn structural_mistakes_are_all_reported_in_one_go() {
    let e = load_error("Graph(\n  version: 1,\n  nodes: {\n    \"a b\": (kind: \"Tonemap\"),\n    \"c\": (kind: 5),\n    \"d\": (kind: \"Tonemap\", colour: 1),\n  },\n  edgez: [],\n)");
    let lines: Vec<&str> = e.lines().collect();
    assert_eq!(lines.len(), 4, "{e}");
    assert!(e.contains("4:5: node id \"a b\" may use only letters"), "{e}");
    assert!(e.contains("5:17: node \"c\": `kind` must be a quoted node kind"), "{e}");
    assert!(e.contains("6:28: node \"d\": unknown field `colour`"), "{e}");
    assert!(e.contains("8:3: unknown field `edgez`"), "{e}");
}

#[test]
fn bad_set_overrides_name_the_node_and_parameter() {
    let reg = relume_cli::registry();
    let mut g = Graph::load(&relume_tests::graphs_dir().join("filters.ron"), &reg).unwrap();
    let e = g.set_param_text(&reg, "blur.sigma", "-1").unwrap_err().to_string();
    assert_eq!(e, "node \"blur\": parameter `sigma`: -1 is out of range [0, 256] px");
    let e = g.set_param_text(&reg, "blur.size", "1").unwrap_err().to_string();
    assert!(e.contains("GaussianBlur has no parameter `size` (it has: sigma, truncate)"), "{e}");
    assert!(g.set_param_text(&reg, "nobody.sigma", "1").unwrap_err().to_string().contains("no node \"nobody\""));
}

mod never_panics {
    use proptest::prelude::*;
    use relume_core::Graph;

    fn valid_text() -> String {
        std::fs::read_to_string(relume_tests::graphs_dir().join("filters.ron")).unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        /// Arbitrary text: an error or a graph, never a panic.
        #[test]
        fn the_loader_survives_arbitrary_text(text in "\\PC{0,200}") {
            if let Ok(g) = Graph::parse(&text, None) {
                let _ = g.validate(&relume_cli::registry());
            }
        }

        /// A valid graph with a byte range deleted or replaced: an error that names a
        /// position, or a graph, never a panic.
        #[test]
        fn the_loader_survives_damaged_graphs(start in 0usize..2000, len in 0usize..40, junk in "[(){}\\[\\]\":,. a-z0-9-]{0,8}") {
            let text = valid_text();
            let start = start.min(text.len());
            let end = (start + len).min(text.len());
            if !text.is_char_boundary(start) || !text.is_char_boundary(end) {
                return Ok(());
            }
            let damaged = format!("{}{}{}", &text[..start], junk, &text[end..]);
            match Graph::parse(&damaged, None) {
                Ok(g) => {
                    if let Err(e) = g.validate(&relume_cli::registry()) {
                        prop_assert!(!e.0.is_empty());
                    }
                }
                Err(e) => prop_assert!(e.0.iter().all(|x| x.pos.is_some()), "{}", e),
            }
        }
    }
}
