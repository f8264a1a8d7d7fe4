//! The built `relume` binary end to end: real process, real exit codes, real files.

use std::process::Command;

mod common;

fn graphs() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../graphs")
}

#[test]
fn the_binary_runs_a_graph_and_writes_image_report_and_exit_code_0() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_relume"))
        .arg("run")
        .arg(graphs().join("filters.ron"))
        .arg("--out")
        .arg(dir.path().join("o"))
        .arg("--report")
        .arg(dir.path().join("r.json"))
        .arg("--cache")
        .arg(dir.path().join("c"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("7 ran, 0 cached"), "{table}");
    assert!(dir.path().join("o/image.png").is_file() && dir.path().join("o/image.exr").is_file());
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join("r.json")).unwrap()).unwrap();
    assert_eq!(report["nodes"].as_array().unwrap().len(), 7);
}

#[test]
fn the_binary_exits_2_with_the_file_and_line_on_a_bad_graph() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("bad.ron");
    std::fs::write(&g, "Graph(version: 1,\n nodes: { \"b\": (kind: \"GaussianBlur\", params: (sigma: 1e9)) })").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_relume")).arg("check").arg(&g).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.ron:2:48: node \"b\": parameter `sigma`: 1000000000.0 is out of range [0, 256] px"), "{err}");
}

#[test]
fn two_processes_can_share_one_disk_cache() {
    let dir = tempfile::tempdir().unwrap();
    let run = |report: &str| {
        Command::new(env!("CARGO_BIN_EXE_relume"))
            .arg("run")
            .arg(graphs().join("image_error.ron"))
            .args(["--quiet", "--out"])
            .arg(dir.path().join(format!("o-{report}")))
            .arg("--report")
            .arg(dir.path().join(report))
            .arg("--cache")
            .arg(dir.path().join("cache"))
            .spawn()
            .unwrap()
    };
    // Two processes write the same entries at the same time.
    let (mut a, mut b) = (run("a.json"), run("b.json"));
    assert!(a.wait().unwrap().success() && b.wait().unwrap().success());
    // A third finds every entry whole.
    assert!(run("c.json").wait().unwrap().success());
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join("c.json")).unwrap()).unwrap();
    let nodes = report["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 5);
    // The filter and the two error figures (milliseconds each) are found whole; the image
    // loaders may re-run: reading the EXR is cheaper than reading a cache entry of the same
    // size (the disk rule).
    for n in nodes {
        assert!(n["status"] == "cached" || n["kind"] == "LoadImage", "{report}");
    }
    assert!(
        ["denoise", "error", "error_denoised"].iter().all(|id| nodes.iter().any(|n| n["id"] == *id && n["status"] == "cached")),
        "{report}"
    );
    let leftovers: Vec<_> = walk(&dir.path().join("cache")).into_iter().filter(|p| p.to_string_lossy().ends_with(".tmp")).collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .flat_map(|e| {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p)
            } else {
                vec![p]
            }
        })
        .collect()
}

/// Runs the binary with `args` (and environment `env`), returning exit code and stderr.
fn relume_with_env(args: &[&std::ffi::OsStr], env: &[(&str, &std::ffi::OsStr)]) -> (Option<i32>, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_relume"));
    cmd.args(args).env_remove("RELUME_CACHE");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn relume(args: &[&std::ffi::OsStr]) -> (Option<i32>, String) {
    relume_with_env(args, &[])
}

fn os<S: AsRef<std::ffi::OsStr> + ?Sized>(s: &S) -> &std::ffi::OsStr {
    s.as_ref()
}

#[test]
fn bad_destinations_and_an_unwritable_cache_get_their_messages() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "").unwrap();
    let g = graphs().join("filters.ron");
    let (code, err) = relume(&[os("run"), os(&g), os("--out"), os(&file), os("--no-disk-cache"), os("-q")]);
    assert_eq!(code, Some(2));
    let want = format!(
        "error: --out {}: this is a file; --out names the folder the outputs are written to (created when missing): give a folder",
        file.display()
    );
    assert!(err.contains(&want), "{err}");

    let report = file.join("r.json");
    let o = dir.path().join("o");
    let (code, err) = relume(&[os("run"), os(&g), os("--out"), os(&o), os("--report"), os(&report), os("--no-disk-cache"), os("-q")]);
    assert_eq!(code, Some(2));
    assert!(err.contains(&format!("error: --report {}: cannot create its folder {}:", report.display(), file.display())), "{err}");

    // RELUME_CACHE naming a file: said once, and the run goes on.
    let (code, err) = relume_with_env(&[os("run"), os(&g), os("--out"), os(&o), os("-q")], &[("RELUME_CACHE", os(&file))]);
    assert_eq!(code, Some(0), "{err}");
    let want = format!(
        "warning: the disk cache {} (from RELUME_CACHE) cannot be written: {} is a file, not a folder; results will not be kept on disk for later runs (point --cache or RELUME_CACHE at a writable folder, or pass --no-disk-cache)",
        file.display(),
        file.display()
    );
    assert_eq!(err.matches(&want).count(), 1, "{err}");
}

#[test]
fn check_names_the_file_for_an_unconnected_input_and_limits_exit_2_with_the_node_line() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("g.ron");
    std::fs::write(&g, "Graph(version: 1, nodes: {\n \"t\": (kind: \"Tonemap\", params: ()),\n})").unwrap();
    let (code, err) = relume(&[os("check"), os(&g)]);
    assert_eq!(code, Some(2));
    assert!(err.contains(&format!("error: {}:2:2: node \"t\": input `image` (Image) is not connected", g.display())), "{err}");

    std::fs::write(
        &g,
        "Graph(version: 1, nodes: {\n \"a\": (kind: \"TestPattern\", params: (width: 16384, height: 16384)),\n}, outputs: { \"x\": \"a.image\" })",
    )
    .unwrap();
    let (code, err) = relume(&[os("run"), os(&g), os("--out"), os(&dir.path().join("o")), os("--no-disk-cache"), os("-q")]);
    assert_eq!(code, Some(2));
    let want = format!(
        "error: {}:2:2: node \"a\" (TestPattern) refused: an image of 16384 × 16384 pixels needs 3.0 GiB, over the 2 GiB limit; ask for less (a smaller size or count)",
        g.display()
    );
    assert!(err.contains(&want), "{err}");
}

#[test]
fn sweep_names_the_metrics_that_exist_and_save_image_outside_is_refused_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("o");
    let (code, err) = relume(&[
        os("sweep"),
        os(&graphs().join("filters.ron")),
        os("--vary"),
        os("blur.sigma=1,2"),
        os("--metric"),
        os("ssmi"),
        os("--out"),
        os(&o),
        os("--no-disk-cache"),
        os("-q"),
    ]);
    assert_eq!(code, Some(2));
    assert!(
        err.contains("error: --metric ssmi: no node the outputs need reports it; did you mean `ssim`? metrics reported: error.mse, error.rel_mse, error.psnr_db, error.l2_percent, error.flip, error.ssim, error.nonfinite_pixels"),
        "{err}"
    );

    let g = dir.path().join("g.ron");
    std::fs::write(
        &g,
        "Graph(version: 1, nodes: {\n  \"p\": (kind: \"TestPattern\", params: ()),\n  \"save\": (kind: \"SaveImage\", params: (path: \"../../../../tmp/x.png\")),\n}, edges: [(\"p.image\", \"save.image\")], outputs: { \"x\": \"save.image\" })",
    )
    .unwrap();
    let (code, err) = relume(&[os("run"), os(&g), os("--out"), os(&o), os("--no-disk-cache"), os("-q")]);
    assert_eq!(code, Some(2));
    let want = format!(
        "error: {}:3:40: node \"save\": parameter `path`: refusing to write /tmp/x.png: it is outside the folders this run may write to",
        g.display()
    );
    assert!(err.contains(&want), "{err}");
    assert!(err.contains("allow it with `--allow-writes-anywhere`"), "{err}");
}

/// Sends SIGINT to a child process.
fn interrupt(child: &std::process::Child) {
    let ok = Command::new("sh").args(["-c", &format!("kill -INT {}", child.id())]).status().unwrap();
    assert!(ok.success());
}

/// Waits up to `secs` for the child; kills it and fails past that.
fn wait_for(child: &mut std::process::Child, secs: u64) -> std::process::ExitStatus {
    let t0 = std::time::Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if t0.elapsed().as_secs() > secs {
            let _ = child.kill();
            panic!("the process did not stop within {secs} s of Ctrl-C");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Starts the reference pipeline (its 4096-spp ground truth takes minutes) and waits until
/// it is running (its disk cache folder exists).
fn start_slow_run(dir: &std::path::Path) -> std::process::Child {
    let child = Command::new(env!("CARGO_BIN_EXE_relume"))
        .arg("run")
        .arg(graphs().join("reference_cornell.ron"))
        .args(["--set", "truth.spp=65536", "-q", "--cache-all", "--out"])
        .arg(dir.join("o"))
        .arg("--report")
        .arg(dir.join("r.json"))
        .arg("--cache")
        .arg(dir.join("cache"))
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !dir.join("cache").exists() {
        assert!(t0.elapsed().as_secs() < 60, "the run did not start");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // Past loading: the scene and its BVH are computed (and cached), the path tracers run.
    std::thread::sleep(std::time::Duration::from_millis(1500));
    child
}

#[test]
fn ctrl_c_cancels_the_run_cleanly_exits_130_and_leaves_no_temp_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = start_slow_run(dir.path());
    let t0 = std::time::Instant::now();
    interrupt(&child);
    let status = wait_for(&mut child, 60);
    let stopped_in = t0.elapsed().as_secs_f64();
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted: cancelling… (press Ctrl-C again to quit at once)"), "{err}");
    assert!(
        err.contains("interrupted: the run was cancelled; nothing was written (results of the nodes that finished are kept in the cache)"),
        "{err}"
    );
    assert!(stopped_in < 30.0, "stopped {stopped_in:.1} s after Ctrl-C");
    assert!(!dir.path().join("o/image.exr").exists() && !dir.path().join("r.json").exists(), "no outputs, no report");
    let files = walk(&dir.path().join("cache"));
    assert!(files.iter().all(|p| !p.to_string_lossy().ends_with(".tmp")), "temporary files left: {files:?}");
    assert!(files.iter().any(|p| p.extension().is_some_and(|e| e == "rlc")), "the nodes that finished are cached: {files:?}");
    eprintln!("stopped {stopped_in:.2} s after Ctrl-C");
}

#[test]
fn a_stale_temp_file_in_the_cache_is_swept_when_a_run_opens_it() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    std::fs::create_dir_all(cache.join("ab")).unwrap();
    let plant = |name: &str, age_s: u64| {
        let p = cache.join("ab").join(name);
        std::fs::write(&p, "half an entry").unwrap();
        let t = std::time::SystemTime::now() - std::time::Duration::from_secs(age_s);
        std::fs::File::options().write(true).open(&p).unwrap().set_modified(t).unwrap();
        p
    };
    // Named as relume names an entry's temporary file: the key (64 hex digits, the first two
    // its folder's name), the writer's process id and a counter.
    let key = format!("ab{}", "c".repeat(62));
    let stale = plant(&format!(".{key}.rlc.4194399.1.tmp"), 3600);
    let live = plant(&format!(".{key}.rlc.{}.2.tmp", std::process::id()), 5);
    let (code, err) = relume(&[
        os("run"),
        os(&graphs().join("filters.ron")),
        os("--out"),
        os(&dir.path().join("o")),
        os("--cache"),
        os(&cache),
        os("-q"),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(!stale.exists(), "an hour-old temporary file of a writer that is gone is removed");
    assert!(live.exists(), "a fresh one of a running writer (this test) is kept");
}

#[test]
fn a_second_ctrl_c_exits_at_once_while_a_step_that_cannot_stop_runs() {
    // ImageError on two 4000² images spends seconds inside FLIP and SSIM, which do not poll
    // for cancellation: measured here, a Ctrl-C 1.5 to 8 s into the run takes 3.6 to 7.4 s to
    // be honoured. A second Ctrl-C must not wait for it.
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("g.ron");
    std::fs::write(
        &g,
        r#"Graph(version: 1, nodes: {
  "a": (kind: "TestPattern", params: (width: 4000, height: 4000, pattern: Checker)),
  "b": (kind: "TestPattern", params: (width: 4000, height: 4000, noise: 0.1)),
  "e": (kind: "ImageError"),
}, edges: [("a.image", "e.image"), ("b.image", "e.reference")], outputs: { "m": "e.metrics" })"#,
    )
    .unwrap();
    // Without a disk cache (writing the two images there would shift the phases); the output
    // folder, created just before the run starts, tells that it has started.
    let out = dir.path().join("o");
    let mut child = Command::new(env!("CARGO_BIN_EXE_relume"))
        .arg("run")
        .arg(&g)
        .args(["-q", "--no-disk-cache", "--out"])
        .arg(&out)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !out.exists() {
        assert!(t0.elapsed().as_secs() < 60, "the run did not start");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // Unloaded, FLIP runs from about 1.5 s to 8.6 s into the run: 5 s is inside it for a
    // machine up to 3 times slower or busier.
    std::thread::sleep(std::time::Duration::from_secs(5));
    interrupt(&child);
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert!(child.try_wait().unwrap().is_none(), "the first Ctrl-C waits for the step under way (FLIP) to end");
    let t1 = std::time::Instant::now();
    interrupt(&child);
    let status = wait_for(&mut child, 10);
    let exited_in = t1.elapsed().as_secs_f64();
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted: cancelling…") && err.contains("interrupted again: exiting now"), "{err}");
    assert!(exited_in < 1.0, "exited {exited_in:.2} s after the second Ctrl-C");
    assert!(!dir.path().join("o/m.json").exists());
    eprintln!("exited {exited_in:.3} s after the second Ctrl-C");
}

#[test]
fn a_thread_count_past_the_cap_is_refused_before_anything_starts() {
    let dir = tempfile::tempdir().unwrap();
    let g = graphs().join("filters.ron");
    let out = dir.path().join("o");
    for (n, want) in [("100000", "at most 1024 threads"), ("0", "at least 1 thread"), ("99999999999999999999999", "too large")] {
        let (code, err) = relume(&[os("run"), g.as_os_str(), os("--out"), out.as_os_str(), os("--no-disk-cache"), os("--threads"), os(n)]);
        assert_eq!(code, Some(2), "--threads {n}: {err}");
        assert!(err.contains(want), "--threads {n}: {err}");
    }
    assert!(!out.exists(), "nothing ran");
}

#[test]
fn control_characters_in_a_graph_never_reach_the_terminal() {
    let dir = tempfile::tempdir().unwrap();
    // A node id and a kind that would clear the screen, set the window title and reverse the
    // text if echoed raw.
    for (id, kind, echoed) in [
        ("a\\u{1b}[2J\\u{1b}]0;pwned\\u{7}", "TestPattern", "a\\u{1b}[2J\\u{1b}]0;pwned\\u{7}"),
        ("a", "Test\\u{202e}Pattern", "Test\\u{202e}Pattern"),
    ] {
        let g = dir.path().join("hostile.ron");
        std::fs::write(&g, format!("Graph(version: 1, nodes: {{ \"{id}\": (kind: \"{kind}\", params: ()) }}, edges: [], outputs: {{}})"))
            .unwrap();
        let (code, err) = relume(&[os("check"), g.as_os_str()]);
        assert_eq!(code, Some(2), "{err}");
        assert!(err.contains(echoed), "named, escaped: {err}");
        assert!(!err.chars().any(|c| c == '\u{1b}' || c == '\u{7}' || c == '\u{202e}'), "raw control characters: {err:?}");
    }
}

#[test]
fn a_line_break_in_a_value_the_slurm_scripts_repeat_is_refused_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let g = graphs().join("reference_cornell.ron");
    let (cache, out) = (dir.path().join("c"), dir.path().join("o"));
    let (code, err) = relume(&[
        os("slurm"),
        g.as_os_str(),
        os("--node"),
        os("reference"),
        os("--shards"),
        os("2"),
        os("--set"),
        os("scene.path=scenes/cornell.ron\ntouch PWNED"),
        os("--cache"),
        cache.as_os_str(),
        os("--out"),
        out.as_os_str(),
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--set scene.path=scenes/cornell.ron\\ntouch PWNED") && err.contains("line break"), "{err}");
    assert!(!cache.exists() && !out.exists(), "nothing written");
}

/// `relume` under `ulimit -v 3000000` (2.86 GiB of address space), with `args`.
fn relume_under_ulimit_v(args: &[&std::ffi::OsStr]) -> (Option<i32>, String, String) {
    common::relume_after("ulimit -v 3000000 || exit 77", args)
}

/// Under `ulimit -v` the filters graph at 6000² aborted on a failed allocation (SIGABRT): the
/// budget knew only physical memory. It now comes from the smallest limit, here RLIMIT_AS, and
/// the run is refused with the estimate before anything is allocated; `plan` names the limit.
#[test]
fn under_ulimit_v_a_run_past_the_limit_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let g = graphs().join("filters.ron");
    let out = dir.path().join("o");
    let mut args = vec![os("run"), g.as_os_str(), os("--out"), out.as_os_str(), os("--no-disk-cache")];
    for s in ["clean.width=6000", "clean.height=6000", "noisy.width=6000", "noisy.height=6000"] {
        args.extend([os("--set"), os(s)]);
    }
    let (code, _, err) = relume_under_ulimit_v(&args);
    assert_eq!(code, Some(2), "refused as bad input, not aborted: {err}");
    assert!(err.contains("over the memory budget of 2.29 GiB (80 % of RLIMIT_AS (ulimit -v): 2.86 GiB)"), "{err}");
    assert!(err.contains("\"error\" (ImageError)"), "the estimate per node: {err}");
    assert!(!out.join("image.png").exists(), "nothing ran");
    let (code, plan, err) = relume_under_ulimit_v(&[os("plan"), g.as_os_str(), os("--no-disk-cache")]);
    assert_eq!(code, Some(0), "{err}");
    assert!(plan.contains("memory budget 2.29 GiB (80 % of RLIMIT_AS (ulimit -v): 2.86 GiB)"), "{plan}");
}

#[test]
fn an_empty_relume_cache_is_unset_not_the_current_folder() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_relume"))
        .current_dir(dir.path())
        .env("RELUME_CACHE", "")
        .args([os("run"), graphs().join("filters.ron").as_os_str(), os("--out"), os("o"), os("-q")])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let top: Vec<String> = std::fs::read_dir(dir.path()).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    assert!(top.iter().all(|n| n == "o" || n == ".relume-cache"), "cache folders in the current folder: {top:?}");
    assert!(dir.path().join(".relume-cache").is_dir(), "the default cache: {top:?}");
}

#[test]
fn a_graph_without_outputs_is_refused_instead_of_running_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("no-outputs.ron");
    std::fs::write(&g, "Graph(version: 1, nodes: { \"p\": (kind: \"TestPattern\", params: ()) }, edges: [], outputs: {})").unwrap();
    for cmd in ["run", "check"] {
        let (code, err) = relume(&[os(cmd), g.as_os_str(), os("--no-disk-cache")]);
        assert_eq!(code, Some(2), "{cmd}: {err}");
        assert!(err.contains("no-outputs.ron: the graph names no outputs") && err.contains("\"p.image\""), "{cmd}: {err}");
    }
}
