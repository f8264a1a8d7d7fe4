//! The `relume` command line, in process: run twice (second run all cached), plan, check,
//! nodes, and exit codes with messages a person can act on; and in a process of its own where
//! its output is read (`relume nodes --markdown`, the page committed as docs/reference/nodes.md).

use relume_cli::main_from;
use relume_tests::graphs_dir;
use std::path::Path;

fn relume(args: &[&str]) -> i32 {
    main_from(std::iter::once("relume").chain(args.iter().copied()))
}

fn report(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn running_image_error_twice_shows_every_node_cached_the_second_time() {
    let dir = tempfile::tempdir().unwrap();
    let d = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    let graph = graphs_dir().join("image_error.ron").to_string_lossy().into_owned();
    let args = |r: &str| {
        vec![
            "run".to_string(),
            graph.clone(),
            "--out".into(),
            d("o"),
            "--report".into(),
            d(r),
            "--cache".into(),
            d("cache"),
            "--cache-all".into(),
            "--quiet".into(),
        ]
    };
    let a1 = args("r1.json");
    assert_eq!(relume(&a1.iter().map(String::as_str).collect::<Vec<_>>()), 0);
    let a2 = args("r2.json");
    assert_eq!(relume(&a2.iter().map(String::as_str).collect::<Vec<_>>()), 0);
    let (r1, r2) = (report(&dir.path().join("r1.json")), report(&dir.path().join("r2.json")));
    for (r, want) in [(&r1, "ran"), (&r2, "cached")] {
        let nodes = r["nodes"].as_array().unwrap();
        assert_eq!(nodes.len(), 5);
        for n in nodes {
            assert_eq!(n["status"], want, "{n}");
            for field in ["id", "kind", "wall_ms", "bytes", "metrics"] {
                assert!(!n[field].is_null(), "{field} in {n}");
            }
        }
        assert!(r["total_ms"].as_f64().unwrap() > 0.0);
    }
    let err = r2["nodes"].as_array().unwrap().iter().find(|n| n["id"] == "error").unwrap();
    assert!(err["metrics"]["psnr_db"].as_f64().unwrap() > 15.0);
    for f in ["render.exr", "render.png", "denoised.exr", "error_map.png", "metrics.json"] {
        assert!(dir.path().join("o").join(f).is_file(), "{f}");
    }
}

#[test]
fn set_overrides_change_the_run_and_bad_ones_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let graph = graphs_dir().join("filters.ron");
    let (g, o, r) = (graph.to_str().unwrap(), dir.path().join("o"), dir.path().join("r.json"));
    let code = relume(&[
        "run",
        g,
        "--set",
        "blur.sigma=2.5",
        "--set",
        "tonemap.operator=Clamp",
        "--out",
        o.to_str().unwrap(),
        "--report",
        r.to_str().unwrap(),
        "--no-disk-cache",
        "-q",
    ]);
    assert_eq!(code, 0);
    assert!(o.join("image.png").is_file());
    assert_eq!(relume(&["run", g, "--set", "blur.sigma=-3", "--no-disk-cache", "-q"]), 2);
    assert_eq!(relume(&["run", g, "--set", "blur", "--no-disk-cache", "-q"]), 2);
    assert_eq!(relume(&["run", g, "--output", "nothing", "--no-disk-cache", "-q"]), 2);
}

#[test]
fn check_plan_and_nodes_succeed_and_a_broken_graph_exits_2() {
    let g = graphs_dir().join("image_error.ron");
    let g = g.to_str().unwrap();
    assert_eq!(relume(&["check", g]), 0);
    assert_eq!(relume(&["plan", g, "--no-disk-cache"]), 0);
    assert_eq!(relume(&["nodes"]), 0);
    assert_eq!(relume(&["nodes", "GaussianBlur"]), 0);
    assert_eq!(relume(&["nodes", "NoSuchNode"]), 2);
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.ron");
    std::fs::write(&bad, "Graph(version: 1, nodes: { \"a\": (kind: \"Nope\") })").unwrap();
    assert_eq!(relume(&["check", bad.to_str().unwrap()]), 2);
    assert_eq!(relume(&["run", dir.path().join("missing.ron").to_str().unwrap()]), 2);
}

#[test]
fn a_node_failure_exits_1_and_a_request_over_a_limit_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("o");
    let g = dir.path().join("g.ron");
    // Sizes that only meet at run time: the error node fails.
    std::fs::write(
        &g,
        r#"Graph(version: 1, nodes: { "a": (kind: "TestPattern", params: (width: 8, height: 8)), "b": (kind: "TestPattern", params: (width: 9, height: 8)), "e": (kind: "ImageError") }, edges: [("a.image", "e.image"), ("b.image", "e.reference")], outputs: { "x": "e.metrics" })"#,
    )
    .unwrap();
    assert_eq!(relume(&["run", g.to_str().unwrap(), "--no-disk-cache", "-q", "--out", o.to_str().unwrap()]), 1);
    // An image over MAX_IMAGE_BYTES is refused: bad input, like an out-of-range parameter.
    std::fs::write(
        &g,
        r#"Graph(version: 1, nodes: { "a": (kind: "TestPattern", params: (width: 16384, height: 16384)) }, outputs: { "x": "a.image" })"#,
    )
    .unwrap();
    assert_eq!(relume(&["run", g.to_str().unwrap(), "--no-disk-cache", "-q", "--out", o.to_str().unwrap()]), 2);
}

#[test]
fn each_output_is_written_as_soon_as_it_exists_even_when_a_later_node_fails() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("o");
    let g = dir.path().join("g.ron");
    // `early` is ready once `a` has run; the error node, which needs `b` too, fails after it.
    std::fs::write(
        &g,
        r#"Graph(version: 1, nodes: { "a": (kind: "TestPattern", params: (width: 8, height: 8)), "b": (kind: "TestPattern", params: (width: 9, height: 8)), "e": (kind: "ImageError") }, edges: [("a.image", "e.image"), ("b.image", "e.reference")], outputs: { "early": "a.image", "x": "e.metrics" })"#,
    )
    .unwrap();
    assert_eq!(relume(&["run", g.to_str().unwrap(), "--no-disk-cache", "-q", "--out", o.to_str().unwrap()]), 1);
    let img = relume_base::image::io::read_image(&o.join("early.exr")).expect("the output that existed before the failure was written");
    assert_eq!((img.width, img.height), (8, 8));
    assert!(o.join("early.png").exists());
    assert!(!o.join("x.json").exists(), "the failed output is not written");
}

/// `relume run` of `filters.ron` into `dir` with a disk cache that keeps every result
/// (`dir/cache`), plus `extra` arguments.
fn run_filters(dir: &Path, extra: &[&str]) -> i32 {
    let g = graphs_dir().join("filters.ron");
    let cache = dir.join("cache");
    let mut args = vec!["run", g.to_str().unwrap(), "--cache", cache.to_str().unwrap(), "--cache-all", "-q"];
    args.extend_from_slice(extra);
    relume(&args)
}

#[test]
fn unwritable_destinations_are_refused_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "").unwrap();
    let f = file.to_str().unwrap();
    let report_under_file = file.join("r.json");
    let report_is_a_folder = dir.path().to_str().unwrap().to_string();
    for extra in [
        vec!["--out", f],
        vec!["--out", &*dir.path().join("o").to_string_lossy(), "--report", report_under_file.to_str().unwrap()],
        vec!["--out", &*dir.path().join("o").to_string_lossy(), "--report", &report_is_a_folder],
    ] {
        assert_eq!(run_filters(dir.path(), &extra), 2, "{extra:?}");
        assert!(!dir.path().join("cache").exists(), "nothing ran, nothing was cached: {extra:?}");
    }
    assert_eq!(std::fs::read(&file).unwrap(), b"", "the file is left alone");
}

#[test]
fn the_output_and_report_folders_are_created_when_missing() {
    let dir = tempfile::tempdir().unwrap();
    let (o, r) = (dir.path().join("new/o"), dir.path().join("reports/today/r.json"));
    assert_eq!(run_filters(dir.path(), &["--out", o.to_str().unwrap(), "--report", r.to_str().unwrap()]), 0);
    assert!(o.join("image.png").is_file());
    assert_eq!(report(&r)["ran"], 7);
}

#[test]
fn a_cache_that_cannot_be_written_is_said_in_the_report_and_the_run_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let g = graphs_dir().join("filters.ron");
    let file = dir.path().join("cache-file");
    std::fs::write(&file, "").unwrap();
    let r = dir.path().join("r.json");
    let o = dir.path().join("o");
    let run = |cache: &Path| {
        relume(&[
            "run",
            g.to_str().unwrap(),
            "--cache",
            cache.to_str().unwrap(),
            "--out",
            o.to_str().unwrap(),
            "--report",
            r.to_str().unwrap(),
            "-q",
        ])
    };
    assert_eq!(run(&file), 0);
    let notes = report(&r)["notes"].clone();
    let note = notes[0].as_str().unwrap_or_else(|| panic!("a note: {notes}"));
    assert!(note.contains("cache-file (from --cache) could not be written") && note.contains("is a file, not a folder"), "{note}");
    assert!(note.contains("results were not kept on disk"), "{note}");
    // A writable cache: no note.
    assert_eq!(run(&dir.path().join("cache")), 0);
    assert!(report(&r)["notes"].is_null(), "{}", report(&r));
    // A read-only folder (where permissions bind: not for root).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let ro = dir.path().join("ro");
        std::fs::create_dir(&ro).unwrap();
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
        if std::fs::write(ro.join("probe"), "").is_err() {
            assert_eq!(run(&ro), 0);
            assert!(report(&r)["notes"][0].as_str().unwrap().contains("cannot write in"), "{}", report(&r));
        }
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
}

#[test]
fn save_image_outside_the_graph_and_output_folders_needs_allow_writes_anywhere() {
    let dir = tempfile::tempdir().unwrap();
    let graph = dir.path().join("graph/g.ron");
    std::fs::create_dir_all(graph.parent().unwrap()).unwrap();
    let write = |target: &str| {
        std::fs::write(
            &graph,
            format!("Graph(version: 1, nodes: {{\n  \"p\": (kind: \"TestPattern\", params: (width: 4, height: 4)),\n  \"save\": (kind: \"SaveImage\", params: (path: \"{target}\")),\n}}, edges: [(\"p.image\", \"save.image\")], outputs: {{ \"x\": \"save.image\" }})"),
        )
        .unwrap()
    };
    write("../elsewhere/x.png");
    let escape = dir.path().join("elsewhere/x.png");
    let (g, o) = (graph.to_str().unwrap(), dir.path().join("o"));
    let o = o.to_str().unwrap();
    assert_eq!(relume(&["check", g, "--out", o]), 2);
    assert_eq!(relume(&["plan", g, "--out", o, "--no-disk-cache"]), 2);
    assert_eq!(relume(&["run", g, "--out", o, "--no-disk-cache", "-q"]), 2);
    assert!(!escape.exists(), "refused before running");
    assert_eq!(relume(&["run", g, "--out", o, "--no-disk-cache", "-q", "--allow-writes-anywhere"]), 0);
    assert!(escape.is_file());
    // A path into the output folder is allowed without the flag.
    write("../o/saved.png");
    assert_eq!(relume(&["check", g, "--out", o]), 0);
    assert_eq!(relume(&["run", g, "--out", o, "--no-disk-cache", "-q"]), 0);
    assert!(dir.path().join("o/saved.png").is_file());
}

#[test]
fn exr_layers_hold_every_image_output_of_a_real_run_bit_identical_with_its_provenance() {
    use exr::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let graph = graphs_dir().join("reference_cornell.ron").to_string_lossy().into_owned();
    let sets = ["scene.width=16", "scene.height=12", "reference.spp=4", "truth.spp=8"];
    let mut args = vec!["run", &graph, "--out", out.to_str().unwrap(), "--no-disk-cache", "--quiet", "--exr-layers"];
    for s in &sets {
        args.extend(["--set", s]);
    }
    assert_eq!(relume(&args), 0);
    let path = out.join("reference_cornell.layers.exr");
    let img = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(&path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(img.layer_data.len(), 1);
    let layer = &img.layer_data[0];
    assert_eq!((layer.size.0, layer.size.1), (16, 12));
    let names: Vec<String> = layer.channel_data.list.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(names, ["image.B", "image.G", "image.R", "variance.B", "variance.G", "variance.R"]);
    for output in ["image", "variance"] {
        let single = relume_base::image::io::read_image(&out.join(format!("{output}.exr"))).unwrap();
        for (c, s) in ["R", "G", "B"].iter().enumerate() {
            let ch = layer.channel_data.list.iter().find(|ch| ch.name.to_string() == format!("{output}.{s}")).unwrap();
            assert!(matches!(ch.sample_data, FlatSamples::F32(_)), "full float by default");
            let got: Vec<u32> = ch.sample_data.values_as_f32().map(f32::to_bits).collect();
            let want: Vec<u32> = single.pixels.iter().map(|p| p[c].to_bits()).collect();
            assert_eq!(got, want, "{output}.{s} is bit-identical to {output}.exr");
        }
    }
    let attr = |k: &str| match layer.attributes.other.get(&Text::from(k)) {
        Some(AttributeValue::Text(t)) => String::from_utf8(t.bytes().to_vec()).unwrap(),
        other => panic!("{k}: {other:?}"),
    };
    assert!(attr("relume.graph").ends_with("reference_cornell.ron"));
    let layers: serde_json::Value = serde_json::from_str(&attr("relume.layers")).unwrap();
    assert_eq!(layers[0]["layer"], "image");
    assert_eq!(layers[0]["node"], "reference");
    assert_eq!(layers[0]["kind"], "PathTrace");
    assert!(layers[0]["params"].as_str().unwrap().contains("spp: 4"), "{layers}");
    assert!(layer.attributes.software_name.as_ref().unwrap().to_string().starts_with("relume "));
}

/// Set by [`relume_output`]: the arguments, as JSON, of the `relume` command line that this
/// test binary, started again, runs in `child_process_runs_the_relume_command_line`.
const CHILD_ARGS: &str = "RELUME_CLI_CHILD_ARGS";

/// When started by [`relume_output`]: runs the arguments as the `relume` command line
/// (`relume_cli::main_from`, what the binary runs) and exits with its code. Otherwise nothing.
#[test]
fn child_process_runs_the_relume_command_line() {
    let Ok(json) = std::env::var(CHILD_ARGS) else { return };
    let args: Vec<String> = serde_json::from_str(&json).expect("RELUME_CLI_CHILD_ARGS is a JSON list of strings");
    std::process::exit(main_from(std::iter::once("relume".to_string()).chain(args)));
}

/// What `relume ARGS` prints on stdout, run in a process of its own (this test binary, see
/// above: its stdout starts with the test harness' "running 1 test" line); panics on failure.
fn relume_output(args: &[&str]) -> String {
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_process_runs_the_relume_command_line", "--nocapture", "--test-threads", "1", "-q"])
        .env(CHILD_ARGS, serde_json::to_string(args).unwrap())
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8(out.stdout).unwrap(), String::from_utf8_lossy(&out.stderr).into_owned());
    assert!(out.status.success(), "relume {args:?} failed ({}):\n{stdout}\n{stderr}", out.status);
    stdout
}

/// The Markdown page in what `relume nodes --markdown` printed: from its title to the end.
fn markdown_page(stdout: &str) -> &str {
    &stdout[stdout.find("# Node catalogue\n").unwrap_or_else(|| panic!("no page title in:\n{stdout}"))..]
}

/// Checks that `page` has exactly one `## Kind` section and one contents line for each kind.
fn assert_one_section_per_kind(page: &str, kinds: &[String], what: &str) {
    for k in kinds {
        let sections = page.lines().filter(|l| *l == format!("## {k}")).count();
        assert_eq!(sections, 1, "{what}: {sections} sections \"## {k}\"");
        let links = page.lines().filter(|l| *l == format!("- [{k}](#{})", k.to_lowercase())).count();
        assert_eq!(links, 1, "{what}: {links} contents lines for {k}");
    }
    let sections = page.lines().filter(|l| l.starts_with("## ") && *l != "## Contents").count();
    assert_eq!(sections, kinds.len(), "{what}: sections for kinds that `relume nodes` does not list");
}

#[test]
fn nodes_markdown_has_a_section_per_kind_and_the_committed_page_is_its_output() {
    // The kinds `relume nodes` lists: its header lines, "Kind vN [category]".
    let kinds: Vec<String> = relume_output(&["nodes"])
        .lines()
        .filter(|l| l.split(' ').nth(1).is_some_and(|v| v.starts_with('v')) && l.ends_with(']') && !l.starts_with(' '))
        .map(|l| l.split(' ').next().unwrap().to_string())
        .collect();
    assert!(kinds.len() > 50 && kinds.iter().any(|k| k == "PathTrace"), "{kinds:?}");
    let stdout = relume_output(&["nodes", "--markdown"]);
    let page = markdown_page(&stdout);
    assert_one_section_per_kind(page, &kinds, "relume nodes --markdown");
    // A parameter row: its type, default, range and unit, in GaussianBlur's section.
    let blur = &page[page.find("\n## GaussianBlur\n").unwrap()..];
    let blur = &blur[..blur[1..].find("\n## ").map_or(blur.len(), |e| e + 1)];
    assert!(blur.contains("\n| `sigma` | float | `1.0` | `[0, 256]` | px |  | standard deviation of the Gaussian |\n"), "{blur}");
    // With a kind, the page holds that kind alone.
    let one = relume_output(&["nodes", "GaussianBlur", "--markdown"]);
    assert_one_section_per_kind(markdown_page(&one), &["GaussianBlur".to_string()], "relume nodes GaussianBlur --markdown");
    // The committed page is this output (regenerate it as its first paragraph says).
    let committed = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/reference/nodes.md")).unwrap();
    assert_one_section_per_kind(&committed, &kinds, "docs/reference/nodes.md");
    assert!(
        committed == page,
        "docs/reference/nodes.md is not what `relume nodes --markdown` prints: regenerate it with \
         `cargo build --release --bin relume && target/release/relume nodes --markdown > docs/reference/nodes.md`"
    );
}
