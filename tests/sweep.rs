//! `relume sweep`, in process: the CSV's rows and columns, the PNG plot, a generic integer
//! baseline, cache reuse between variants (a repeated variant costs 0 ms) and exit code 2
//! for input a person can correct; `relume results` drawing a sweep again from its CSV.

use relume_base::image::io::read_image;
use relume_cli::main_from;
use relume_tests::graphs_dir;
use std::path::Path;

fn relume(args: &[&str]) -> i32 {
    main_from(std::iter::once("relume").chain(args.iter().copied()))
}

/// The CSV as a header and rows of cells (no cell here contains a comma).
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().map(|l| l.split(',').map(String::from).collect::<Vec<_>>());
    let header = lines.next().expect("a header line");
    let rows: Vec<Vec<String>> = lines.collect();
    for r in &rows {
        assert_eq!(r.len(), header.len(), "row {r:?} against header {header:?}");
    }
    (header, rows)
}

fn col(header: &[String], name: &str) -> usize {
    header.iter().position(|h| h == name).unwrap_or_else(|| panic!("no column {name} in {header:?}"))
}

fn num(s: &str) -> f64 {
    s.parse().unwrap_or_else(|_| panic!("`{s}` is not a number"))
}

fn filters() -> String {
    graphs_dir().join("filters.ron").to_string_lossy().into_owned()
}

#[test]
fn sweeping_blur_sigma_writes_three_method_rows_with_different_errors_and_a_png_plot() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let g = filters();
    let code = relume(&["sweep", &g, "--vary", "blur.sigma=0.5,1,2", "--out", out.to_str().unwrap(), "--no-disk-cache", "-q"]);
    assert_eq!(code, 0);

    let (header, rows) = read_csv(&out.join("sweep.csv"));
    assert_eq!(&header[..6], ["series", "variant", "blur.sigma", "time_ms", "pipeline_ms", "total_ms"]);
    for name in ["error.mse", "error.rel_mse", "error.psnr_db", "error.l2_percent", "ms:clean", "ms:blur", "ms:error"] {
        col(&header, name);
    }
    assert_eq!(rows.len(), 3);
    let (sigma, rel, time) = (col(&header, "blur.sigma"), col(&header, "error.rel_mse"), col(&header, "time_ms"));
    let sigmas: Vec<f64> = rows.iter().map(|r| num(&r[sigma])).collect();
    assert_eq!(sigmas, [0.5, 1.0, 2.0]);
    for r in &rows {
        assert_eq!(r[0], "method");
        assert!(num(&r[time]) > 0.0, "blur and everything below it ran: {r:?}");
        // The pipeline behind the error node's image (noisy, sum, median, blur; not the clean
        // reference) costs its full compute time in every row, cached parts included.
        assert!(num(&r[col(&header, "pipeline_ms")]) >= num(&r[col(&header, "ms:blur")]), "{r:?}");
    }
    let pipe = col(&header, "pipeline_ms");
    assert!(num(&rows[2][pipe]) > num(&rows[2][col(&header, "ms:blur")]), "the cached median and noise still count");
    let rels: Vec<f64> = rows.iter().map(|r| num(&r[rel])).collect();
    assert!(rels.iter().all(|v| v.is_finite() && *v > 0.0), "{rels:?}");
    assert!(rels[0] != rels[1] && rels[1] != rels[2] && rels[0] != rels[2], "{rels:?}");
    // The first variant ran the sources; later ones took them from the cache.
    let (ms_clean, ms_blur) = (col(&header, "ms:clean"), col(&header, "ms:blur"));
    assert!(num(&rows[0][ms_clean]) > 0.0);
    assert_eq!(num(&rows[1][ms_clean]), 0.0);
    assert!(num(&rows[1][ms_blur]) > 0.0);

    // Decoded with the image crate (through relume's own PNG reader).
    let img = read_image(&out.join("sweep.png")).expect("the plot decodes");
    assert_eq!((img.width, img.height), (1024, 720));
    let first = img.pixels[0];
    assert!(img.pixels.iter().any(|p| *p != first), "the plot is not a single colour");
}

/// `relume results` draws a sweep from its CSV and its command alone: the plot the sweep drew,
/// byte for byte, and a table with the baseline beside each method row.
#[test]
fn results_draw_a_sweep_again_byte_for_byte_from_its_csv_and_command() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("results");
    std::fs::create_dir_all(&folder).unwrap();
    let (csv, drawn) = (folder.join("sweep_blur.csv"), dir.path().join("drawn_by_the_sweep.png"));
    // With a goal: its dashed guide is part of the figure both draw.
    let command =
        format!("relume sweep {} --vary blur.sigma=0.5,1.5 --baseline median.radius --baseline-max 4 --goal 2 --no-disk-cache", filters());
    let mut args: Vec<&str> = command.split(' ').skip(1).collect();
    args.extend(["--csv", csv.to_str().unwrap(), "--plot", drawn.to_str().unwrap(), "-q"]);
    assert_eq!(relume(&args), 0);
    let (header, rows) = read_csv(&csv);
    for name in ["date", "machine", "threads", "commit"] {
        let c = col(&header, name);
        assert!(rows.iter().all(|r| !r[c].is_empty()), "every row says its {name}");
    }
    let manifest = format!("SweepResults(sweeps: [(name: \"blur\", caption: \"Blur\", command: \"{command}\")])");
    std::fs::write(folder.join("sweeps.ron"), manifest).unwrap();
    let folder_arg = folder.to_str().unwrap();
    assert_eq!(relume(&["results", folder_arg, "--check"]), 1, "nothing drawn yet");
    assert_eq!(relume(&["results", folder_arg]), 0);
    assert_eq!(std::fs::read(folder.join("sweep_blur.png")).unwrap(), std::fs::read(&drawn).unwrap());
    assert_eq!(relume(&["results", folder_arg, "--check"]), 0);
    let md = std::fs::read_to_string(folder.join("sweep_blur.md")).unwrap();
    assert!(md.contains("| blur.sigma=0.5 |") && md.contains("| median.radius=4 |"), "{md}");
    assert!(md.contains("speed-up at equal error"), "{md}");
    assert!(md.contains("The dashed line is the goal, 2×"), "{md}");
}

/// `relume sweep filters.ron --vary VARY --baseline BASELINE --baseline-max MAX` into `dir`:
/// the CSV's header and rows; the plot at `dir/plots/s.png`.
fn baseline_sweep(dir: &Path, vary: &str, baseline: &str, max: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let (csv, plot) = (dir.join("s.csv"), dir.join("plots/s.png"));
    let g = filters();
    let args = ["sweep", &g, "--vary", vary, "--baseline", baseline, "--baseline-max", max, "--csv", csv.to_str().unwrap()];
    let code = relume(&[&args[..], &["--plot", plot.to_str().unwrap(), "--no-disk-cache", "-q"]].concat());
    assert_eq!(code, 0);
    read_csv(&csv)
}

#[test]
fn a_baseline_on_a_float_parameter_takes_the_same_doubling_values() {
    // One method against another at its settings: a blur's width against itself, the way the
    // factorised gather is put against the plain one over the rasterisation threshold.
    let dir = tempfile::tempdir().unwrap();
    let (header, rows) = baseline_sweep(dir.path(), "median.radius=2", "blur.sigma", "2");
    let variants: Vec<&str> = rows.iter().map(|r| r[col(&header, "variant")].as_str()).collect();
    assert_eq!(variants, ["median.radius=2", "blur.sigma=1", "blur.sigma=2"]);
}

#[test]
fn a_baseline_on_an_integer_parameter_adds_rows_at_doubling_values() {
    let dir = tempfile::tempdir().unwrap();
    let (header, rows) = baseline_sweep(dir.path(), "blur.sigma=0.5,1.5", "median.radius", "4");
    let (radius, sigma) = (col(&header, "median.radius"), col(&header, "blur.sigma"));
    let series: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    assert_eq!(series, ["method", "method", "baseline", "baseline", "baseline"]);
    let radii: Vec<&str> = rows[2..].iter().map(|r| r[radius].as_str()).collect();
    assert_eq!(radii, ["1", "2", "4"]);
    let variants: Vec<&str> = rows[2..].iter().map(|r| r[1].as_str()).collect();
    assert_eq!(variants, ["median.radius=1", "median.radius=2", "median.radius=4"]);
    // The baseline keeps the varied parameter at its graph value (0.8 in filters.ron), and
    // the method rows keep the baseline parameter at its graph value (1).
    for r in &rows[2..] {
        assert_eq!(num(&r[sigma]), 0.8);
    }
    for r in &rows[..2] {
        assert_eq!(r[radius], "1");
    }
    assert!(dir.path().join("plots/s.png").is_file());
}

#[test]
fn a_variant_repeated_in_one_sweep_costs_zero_ms_because_every_node_is_cached() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let g = filters();
    let code = relume(&["sweep", &g, "--vary", "blur.sigma=1,1", "--out", out.to_str().unwrap(), "--no-disk-cache", "-q"]);
    assert_eq!(code, 0);
    let (header, rows) = read_csv(&out.join("sweep.csv"));
    assert_eq!(rows.len(), 2);
    let (time, rel) = (col(&header, "time_ms"), col(&header, "error.rel_mse"));
    assert!(num(&rows[0][time]) > 0.0);
    // Exactly zero: no node ran (times are written with four decimals; a run costs far more).
    assert_eq!(rows[1][time], "0.0000", "the repeat ran nothing: {:?}", rows[1]);
    assert_eq!(num(&rows[1][time]), 0.0);
    assert_eq!(rows[0][rel], rows[1][rel], "cached metrics are the same figures");
    for (h, cell) in header.iter().zip(&rows[1]) {
        if h.starts_with("ms:") {
            assert_eq!(num(cell), 0.0, "{h}");
        }
    }
    // The plot leaves the 0 ms point out (log axis) and still gets written.
    assert!(out.join("sweep.png").is_file());
}

#[test]
fn a_disk_cache_shared_between_two_sweeps_makes_the_second_one_cost_nothing_new() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let g = filters();
    for csv in ["a.csv", "b.csv"] {
        let csv = dir.path().join(csv);
        let args = [
            "sweep",
            &g,
            "--vary",
            "blur.sigma=0.7,1.3",
            "--csv",
            csv.to_str().unwrap(),
            "--cache",
            cache.to_str().unwrap(),
            "--cache-all",
            "-q",
        ];
        assert_eq!(relume(&args), 0);
    }
    let (header, a) = read_csv(&dir.path().join("a.csv"));
    let (_, b) = read_csv(&dir.path().join("b.csv"));
    let (time, ms_blur) = (col(&header, "time_ms"), col(&header, "ms:blur"));
    assert!(a.iter().all(|r| num(&r[ms_blur]) > 0.0));
    // With --cache-all every result was written: the second sweep computes nothing new.
    assert!(b.iter().all(|r| num(&r[ms_blur]) == 0.0), "{b:?}");
    assert_eq!(num(&b[1][time]), 0.0, "{b:?}");
}

#[test]
fn unknown_nodes_params_metrics_and_empty_lists_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let o = out.to_str().unwrap();
    let g = filters();
    let sweep = |extra: &[&str]| {
        let mut args = vec!["sweep", g.as_str(), "--out", o, "--no-disk-cache", "-q"];
        args.extend_from_slice(extra);
        relume(&args)
    };
    assert_eq!(sweep(&["--vary", "nosuch.sigma=1,2"]), 2);
    assert_eq!(sweep(&["--vary", "blur.nosuch=1,2"]), 2);
    assert_eq!(sweep(&["--vary", "blur.sigma="]), 2);
    assert_eq!(sweep(&["--vary", "blur.sigma=1,-2"]), 2, "out of range");
    assert_eq!(sweep(&["--vary", "blur.sigma=1", "--metric", "nosuch"]), 2);
    assert_eq!(sweep(&["--vary", "blur.sigma=1", "--error-node", "blur"]), 2, "blur reports no rel_mse");
    assert_eq!(sweep(&["--vary", "blur.sigma=1", "--baseline", "tonemap.operator"]), 2, "not a number");
    assert_eq!(sweep(&["--vary", "blur.sigma=1", "--goal", "2"]), 2, "a goal needs a baseline");
    assert_eq!(sweep(&["--vary", "blur.sigma=1", "--baseline", "median.radius", "--goal", "0.5"]), 2, "a goal under 1×");
    assert_eq!(sweep(&["--vary", "blur.sigma=1", "--baseline", "median.radius", "--baseline-max", "64"]), 2, "radius ≤ 16");
    assert_eq!(sweep(&[]), 2, "neither --vary nor --baseline");
    assert!(!out.join("sweep.csv").exists(), "nothing written for bad input");
}

#[test]
fn a_metric_or_destination_that_cannot_work_is_refused_before_the_first_variant_runs() {
    let dir = tempfile::tempdir().unwrap();
    let (cache, out) = (dir.path().join("cache"), dir.path().join("o"));
    let file = dir.path().join("a-file");
    std::fs::write(&file, "").unwrap();
    let g = filters();
    let sweep = |extra: &[&str]| {
        let mut args = vec!["sweep", g.as_str(), "--vary", "blur.sigma=1,2", "--cache", cache.to_str().unwrap(), "--cache-all", "-q"];
        args.extend_from_slice(extra);
        relume(&args)
    };
    let o = out.to_str().unwrap();
    for extra in [
        vec!["--out", o, "--metric", "nope"],
        vec!["--out", o, "--metric", "psnr"],
        vec!["--out", o, "--error-node", "blur"],
        vec!["--out", file.to_str().unwrap()],
        vec!["--out", o, "--csv", &*file.join("s.csv").to_string_lossy()],
        vec!["--out", o, "--plot", &*dir.path().to_string_lossy()],
    ] {
        assert_eq!(sweep(&extra), 2, "{extra:?}");
        assert!(!cache.exists(), "nothing ran: {extra:?}");
    }
    // A metric the error node reports: the sweep runs.
    assert_eq!(sweep(&["--out", o, "--metric", "psnr_db"]), 0);
    assert!(out.join("sweep.csv").is_file());
}

#[test]
fn the_baseline_can_plot_its_own_error_node_and_an_unknown_one_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let graph = relume_tests::graphs_dir().join("image_error.ron");
    let g = graph.to_str().unwrap();
    let out = dir.path().to_str().unwrap();
    let ok = relume(&[
        "sweep",
        g,
        "--baseline",
        "denoise.radius",
        "--baseline-max",
        "2",
        "--error-node",
        "error",
        "--baseline-error-node",
        "error_denoised",
        "--out",
        out,
        "--no-disk-cache",
        "-q",
    ]);
    assert_eq!(ok, 0);
    assert!(dir.path().join("sweep.png").is_file());
    let bad = relume(&[
        "sweep",
        g,
        "--baseline",
        "denoise.radius",
        "--baseline-max",
        "2",
        "--baseline-error-node",
        "nobody",
        "--out",
        out,
        "--no-disk-cache",
        "-q",
    ]);
    assert_eq!(bad, 2);
}

/// `relume sweep filters.ron EXTRA… --csv CSV --no-disk-cache -q`.
fn sweep_filters(csv: &Path, extra: &[&str]) -> i32 {
    let g = filters();
    let mut args = vec!["sweep", g.as_str()];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--csv", csv.to_str().unwrap(), "--no-disk-cache", "-q"]);
    relume(&args)
}

#[test]
fn x_and_series_plot_one_line_per_value_of_a_varied_parameter_against_another() {
    let dir = tempfile::tempdir().unwrap();
    let (csv, plot) = (dir.path().join("s.csv"), dir.path().join("s.png"));
    let (vary_r, vary_s) = ("median.radius=1,2", "blur.sigma=0.5,1,2");
    let extra = ["--vary", vary_r, "--vary", vary_s, "--x", "blur.sigma", "--series", "median.radius", "--plot", plot.to_str().unwrap()];
    assert_eq!(sweep_filters(&csv, &extra), 0);
    let (header, rows) = read_csv(&csv);
    assert_eq!(rows.len(), 6);
    let (radius, sigma) = (col(&header, "median.radius"), col(&header, "blur.sigma"));
    let pairs: Vec<(&str, f64)> = rows.iter().map(|r| (r[radius].as_str(), num(&r[sigma]))).collect();
    assert_eq!(pairs, [("1", 0.5), ("1", 1.0), ("1", 2.0), ("2", 0.5), ("2", 1.0), ("2", 2.0)]);
    // Two lines in the first two colours of the palette, no baseline (red).
    let img = image::open(&plot).unwrap().to_rgb8();
    assert!(img.pixels().any(|p| p.0 == [31, 119, 180]), "the line of median.radius = 1");
    assert!(img.pixels().any(|p| p.0 == [255, 127, 14]), "the line of median.radius = 2");
    assert!(!img.pixels().any(|p| p.0 == [214, 39, 40]), "no baseline");

    // A metric as the x axis: error against the error's own PSNR also plots.
    let (csv2, plot2) = (dir.path().join("m.csv"), dir.path().join("m.png"));
    assert_eq!(sweep_filters(&csv2, &["--vary", "blur.sigma=0.5,1", "--x", "error.psnr_db", "--plot", plot2.to_str().unwrap()]), 0);
    assert!(plot2.is_file());
}

#[test]
fn parameters_joined_by_plus_take_each_value_together() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    // The two patterns must keep the same size for `sum` to combine them.
    assert_eq!(sweep_filters(&csv, &["--vary", "clean.width+noisy.width=32,48"]), 0);
    let (header, rows) = read_csv(&csv);
    assert_eq!(rows.len(), 2);
    let (a, b) = (col(&header, "clean.width"), col(&header, "noisy.width"));
    let widths: Vec<(&str, &str)> = rows.iter().map(|r| (r[a].as_str(), r[b].as_str())).collect();
    assert_eq!(widths, [("32", "32"), ("48", "48")]);
    assert_eq!(rows[0][1], "clean.width=32 noisy.width=32");
}

#[test]
fn an_output_named_as_node_port_stops_the_sweep_at_that_node() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    // `error.metrics` is a port, not one of the graph's outputs (those are `image`, `metrics`).
    assert_eq!(sweep_filters(&csv, &["--vary", "blur.sigma=0.5,1", "--output", "error.metrics"]), 0);
    let (header, rows) = read_csv(&csv);
    assert_eq!(rows.len(), 2);
    col(&header, "ms:blur");
    assert!(!header.iter().any(|h| h == "ms:tonemap"), "nothing past the error ran: {header:?}");
}

#[test]
fn an_x_axis_series_or_port_output_that_does_not_exist_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    for extra in [
        ["--x", "nosuch"],
        ["--x", "blur.nosuch"],
        ["--x", "error.nosuch"],
        ["--x", "median.radius"],
        ["--series", "median.radius"],
        ["--output", "blur.nosuch"],
        ["--output", "nosuch.image"],
        ["--vary", "median.radius+nodot=1,2"],
    ] {
        assert_eq!(sweep_filters(&csv, &[&["--vary", "blur.sigma=1,2"], &extra[..]].concat()), 2, "{extra:?}");
    }
    assert!(!csv.exists(), "nothing written");
}

#[test]
fn each_sweep_graph_renders_the_image_of_the_pipeline_graph_it_compares() {
    // The sweep graphs are their pipeline graphs plus a path tracer as the baseline, with the
    // same node ids and parameters: at test size the same image, byte for byte, so each
    // pipeline graph's error bounds (tests/ptt.rs, tests/relight.rs) hold for its sweep graph.
    use relume_base::types::Image;
    use relume_tests::{engine, load_test_graph, run_outputs};
    let e = engine();
    for (sweep, pipeline) in [
        ("ptt_vs_reference.ron", "ptt_envlit.ron"),
        ("relight_vs_reference.ron", "relight_cornell_bunny.ron"),
        ("relight_sv_vs_reference.ron", "relight_sv_spot.ron"),
    ] {
        let image = |name: &str| {
            let r = run_outputs(&e, &load_test_graph(name, &[("scene.width", "24"), ("scene.height", "24")]), &["image"]);
            r.output("image").unwrap().get::<Image>().unwrap().clone()
        };
        let (a, b) = (image(sweep), image(pipeline));
        assert!(a.pixels.iter().any(|p| p[0] > 0.0), "{sweep}: an image");
        assert_eq!(a, b, "{sweep} renders {pipeline}'s image");
    }
}
