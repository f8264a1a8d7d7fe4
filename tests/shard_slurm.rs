//! The Slurm back-end: `relume shard` as Slurm array tasks (processes with SLURM_ARRAY_TASK_ID
//! and SLURM_ARRAY_TASK_COUNT set) over one cache folder, gathered by `relume run`, gives the
//! unsharded image byte for byte; a failed or killed shard re-run alone computes only what is
//! missing; and `relume slurm` writes (and submits) the sbatch scripts it should.
//!
//! relume runs in separate processes: this test binary started again with `RELUME_CHILD_ARGS`
//! set runs the command line (`relume_cli::main_from`, what the `relume` binary runs)
//! in its test `child_process_runs_the_relume_command_line`, which does nothing otherwise.
//! (`tests/scripts/slurm_e2e.sh` runs the same on a real one-node Slurm cluster.)

use relume_tests::graphs_dir;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const CHILD_ARGS: &str = "RELUME_CHILD_ARGS";

/// When started by [`relume`] (RELUME_CHILD_ARGS holds the arguments as JSON): runs them as
/// the `relume` command line and exits with its code. Otherwise there is nothing to do.
#[test]
fn child_process_runs_the_relume_command_line() {
    let Ok(json) = std::env::var(CHILD_ARGS) else { return };
    let args: Vec<String> = serde_json::from_str(&json).expect("RELUME_CHILD_ARGS is a JSON list of strings");
    let code = relume_cli::main_from(std::iter::once("relume".to_string()).chain(args));
    std::process::exit(code);
}

/// A `relume ARGS` process (this test binary, see the module doc) with the environment
/// `envs`; Slurm's variables are cleared unless given.
fn relume(args: &[String], envs: &[(&str, String)]) -> Command {
    let mut c = Command::new(std::env::current_exe().unwrap());
    c.args(["--exact", "child_process_runs_the_relume_command_line", "--nocapture", "--test-threads", "1", "-q"])
        .env(CHILD_ARGS, serde_json::to_string(args).unwrap())
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("SLURM_ARRAY_TASK_COUNT")
        .env_remove("RELUME_CACHE")
        .envs(envs.iter().map(|(k, v)| (*k, v.as_str())))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    c
}

/// Runs `relume ARGS` to the end and returns its output; panics with its output on failure.
fn relume_ok(args: &[String], envs: &[(&str, String)]) -> Output {
    let out = relume(args, envs).output().unwrap();
    assert!(out.status.success(), "relume {args:?} failed ({}):\n{}\n{}", out.status, text(&out.stdout), text(&out.stderr));
    out
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

fn graph() -> String {
    s(&graphs_dir().join("reference_cornell.ron"))
}

/// The path tracer of `reference_cornell` at `spp`, its image only, on the cache `cache`.
fn base(cmd: &str, spp: u32, cache: &Path) -> Vec<String> {
    let spp = format!("reference.spp={spp}");
    [cmd, &graph(), "--set", &spp, "--output", "image", "--cache", &s(cache)].iter().map(|a| a.to_string()).collect()
}

fn with(mut v: Vec<String>, more: &[&str]) -> Vec<String> {
    v.extend(more.iter().map(|a| a.to_string()));
    v
}

/// `relume run` of the graph (unsharded, or the gather of shards in `cache`) into `out`,
/// with its report; returns the image bytes and the report's `reference.shards`.
fn run_image(spp: u32, cache: &Path, out: &Path) -> (Vec<u8>, serde_json::Value) {
    let report = out.join("report.json");
    relume_ok(&with(base("run", spp, cache), &["--out", &s(out), "--report", &s(&report), "-q"]), &[]);
    (std::fs::read(out.join("image.exr")).unwrap(), shards_of(&report))
}

/// The `shards` record of node `reference` in a run report.
fn shards_of(report: &Path) -> serde_json::Value {
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    let n = r["nodes"].as_array().unwrap().iter().find(|n| n["id"] == "reference").expect("node reference in the report");
    n["shards"].clone()
}

/// `relume shard` of shard `i` of `n` as Slurm array task `i` (the index and count from the
/// environment only), writing its report to `report`.
/// `extra`: more flags.
fn slurm_task(spp: u32, cache: &Path, i: u64, n: u64, report: &Path, extra: &[&str]) -> Command {
    let args = with(with(base("shard", spp, cache), &["--node", "reference", "--report", &s(report), "-q"]), extra);
    relume(&args, &[("SLURM_ARRAY_TASK_ID", i.to_string()), ("SLURM_ARRAY_TASK_COUNT", n.to_string())])
}

fn wait_ok(c: Child, what: &str) {
    let out = c.wait_with_output().unwrap();
    assert!(out.status.success(), "{what} failed ({}):\n{}\n{}", out.status, text(&out.stdout), text(&out.stderr));
}

fn n(v: &serde_json::Value, field: &str) -> u64 {
    v[field].as_u64().unwrap_or_else(|| panic!("{field} in {v}"))
}

/// `reference_cornell` at 256²: rows in chunks of 16 (4096 pixels), 16 chunks; 3 shards take
/// chunks 0..5, 5..10 and 10..16.
const CHUNKS: u64 = 16;
const SHARD_CHUNKS: [u64; 3] = [5, 5, 6];

#[test]
fn three_slurm_array_tasks_gathered_give_the_unsharded_image_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (cache, spp) = (d.join("shared cache"), 8);
    let tasks: Vec<Child> =
        (0..3).map(|i| slurm_task(spp, &cache, i, 3, &d.join(format!("shard-{i}.json")), &[]).spawn().unwrap()).collect();
    for (i, t) in tasks.into_iter().enumerate() {
        wait_ok(t, &format!("array task {i}"));
    }
    for i in 0..3u64 {
        let sh = shards_of(&d.join(format!("shard-{i}.json")));
        assert_eq!(
            (n(&sh, "chunks"), n(&sh, "here"), n(&sh, "ran"), n(&sh, "cached")),
            (CHUNKS, SHARD_CHUNKS[i as usize], SHARD_CHUNKS[i as usize], 0),
            "{sh}"
        );
        assert_eq!(sh["shard"], serde_json::json!([i, 3]), "{sh}");
    }
    let (unsharded, u) = run_image(spp, &d.join("cache-unsharded"), &d.join("unsharded"));
    let (gathered, g) = run_image(spp, &cache, &d.join("gathered"));
    assert_eq!((n(&u, "ran"), n(&u, "cached")), (CHUNKS, 0), "unsharded: {u}");
    assert_eq!((n(&g, "chunks"), n(&g, "cached"), n(&g, "ran")), (CHUNKS, CHUNKS, 0), "gather: {g}");
    assert!(gathered == unsharded, "the gathered image.exr differs from the unsharded one");
}

#[test]
fn a_failed_array_task_leaves_only_its_chunks_for_the_gather_to_compute() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (cache, spp) = (d.join("cache"), 8);
    // Task 1 "failed": only tasks 0 and 2 ran.
    let tasks: Vec<Child> =
        [0, 2].iter().map(|&i| slurm_task(spp, &cache, i, 3, &d.join(format!("s{i}.json")), &[]).spawn().unwrap()).collect();
    for t in tasks {
        wait_ok(t, "array task");
    }
    let (gathered, g) = run_image(spp, &cache, &d.join("gathered"));
    assert_eq!((n(&g, "cached"), n(&g, "ran")), (SHARD_CHUNKS[0] + SHARD_CHUNKS[2], SHARD_CHUNKS[1]), "gather: {g}");
    let (unsharded, _) = run_image(spp, &d.join("cache-unsharded"), &d.join("unsharded"));
    assert!(gathered == unsharded, "the gathered image.exr differs from the unsharded one");
}

/// The partial results in a cache folder (`.rlc` entries, not temporary files).
fn entries(cache: &Path) -> usize {
    fn walk(p: &Path, n: &mut usize) {
        for e in std::fs::read_dir(p).into_iter().flatten().flatten() {
            let p = e.path();
            let name = e.file_name().to_string_lossy().into_owned();
            if p.is_dir() {
                walk(&p, n);
            } else if name.ends_with(".rlc") && !name.starts_with('.') {
                *n += 1;
            }
        }
    }
    let mut n = 0;
    walk(cache, &mut n);
    n
}

#[test]
fn an_array_task_killed_midway_and_re_run_computes_only_the_chunks_it_had_not_finished() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 64 samples per pixel on one thread: each chunk of task 1 takes a good fraction of a
    // second, so the kill lands long before its 5 chunks are done. --cache-all: tasks 0 and 2
    // leave the scene and the BVH on disk, so that task 1 adds nothing but its chunks.
    let (cache, spp) = (d.join("cache"), 64);
    for i in [0, 2] {
        wait_ok(slurm_task(spp, &cache, i, 3, &d.join(format!("s{i}.json")), &["--cache-all"]).spawn().unwrap(), "array task");
    }
    let before = entries(&cache);
    let mut task = slurm_task(spp, &cache, 1, 3, &d.join("killed.json"), &["--cache-all", "--threads", "1"]).spawn().unwrap();
    let t0 = Instant::now();
    while entries(&cache) == before {
        assert!(task.try_wait().unwrap().is_none(), "task 1 ended before it wrote a chunk");
        assert!(t0.elapsed() < Duration::from_secs(120), "task 1 wrote no chunk in 120 s");
        std::thread::sleep(Duration::from_millis(2));
    }
    task.kill().unwrap();
    let status = task.wait().unwrap();
    assert!(!status.success(), "task 1 had finished before it was killed");
    let kept = (entries(&cache) - before) as u64;
    assert!((1..SHARD_CHUNKS[1]).contains(&kept), "{kept} chunks of task 1 in the cache");
    eprintln!("task 1 killed after {kept} of its {} chunks", SHARD_CHUNKS[1]);
    // Re-run alone: it finds the chunks it finished and computes the rest.
    wait_ok(slurm_task(spp, &cache, 1, 3, &d.join("rerun.json"), &[]).spawn().unwrap(), "task 1 re-run");
    let r = shards_of(&d.join("rerun.json"));
    assert_eq!((n(&r, "cached"), n(&r, "ran")), (kept, SHARD_CHUNKS[1] - kept), "re-run of task 1: {r}");
    let (gathered, g) = run_image(spp, &cache, &d.join("gathered"));
    assert_eq!((n(&g, "cached"), n(&g, "ran")), (CHUNKS, 0), "gather: {g}");
    let (unsharded, _) = run_image(spp, &d.join("cache-unsharded"), &d.join("unsharded"));
    assert!(gathered == unsharded, "the gathered image.exr differs from the unsharded one");
}

/// A stand-in `relume` for the scripts: prints its arguments one per line.
fn echo_binary(dir: &Path) -> PathBuf {
    let p = dir.join("fake relume");
    std::fs::write(&p, "#!/bin/sh\nprintf '%s\\n' \"$@\"\n").unwrap();
    make_executable(&p);
    p
}

fn make_executable(p: &Path) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(p, std::fs::Permissions::from_mode(0o755)).unwrap();
}

/// Runs a generated script with bash (as a Slurm task would) and returns the words it ran.
fn script_words(script: &Path, envs: &[(&str, &str)]) -> Vec<String> {
    let out = Command::new("bash").arg(script).envs(envs.iter().copied()).output().unwrap();
    assert!(out.status.success(), "bash {} failed:\n{}", script.display(), text(&out.stderr));
    text(&out.stdout).lines().map(String::from).collect()
}

#[test]
fn the_sbatch_scripts_hold_the_array_range_the_shard_command_and_the_gather_and_quote_paths() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fake = echo_binary(d);
    let (cache, out, scripts) = (d.join("my cache"), d.join("it's \"out\""), d.join("scripts $HOME"));
    let set = "scene.path=scenes/cornell.ron";
    let args: Vec<String> = [
        "slurm",
        &graph(),
        "--node",
        "reference",
        "--shards",
        "3",
        "--set",
        set,
        "--output",
        "image",
        "--cache",
        &s(&cache),
        "--out",
        &s(&out),
        "--script-dir",
        &s(&scripts),
        "--partition",
        "debug",
        "--time",
        "00:10:00",
        "--cpus-per-task",
        "2",
        "--mem",
        "4G",
        "--account",
        "lab",
        "--relume",
        &s(&fake),
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    let printed = text(&relume_ok(&args, &[]).stdout);
    let (array, gather) =
        (scripts.join("reference_cornell-reference-shards.sbatch"), scripts.join("reference_cornell-reference-gather.sbatch"));
    let (a, g) = (std::fs::read_to_string(&array).unwrap(), std::fs::read_to_string(&gather).unwrap());
    // The two sbatch commands, the gather depending on the array job.
    assert!(printed.contains("16 chunks; 3 array tasks of 5 or 6 chunks each"), "{printed}");
    assert!(printed.contains("ARRAY_JOB_ID=$(sbatch --parsable"), "{printed}");
    assert!(printed.contains("sbatch --dependency=afterok:$ARRAY_JOB_ID"), "{printed}");
    // The directives, before the first command.
    for (script, job) in [(&a, "relume-reference"), (&g, "relume-reference-gather")] {
        assert!(script.starts_with("#!/bin/bash\n# Generated by relume"), "{script}");
        assert!(script.contains("set -euo pipefail\n"), "{script}");
        let header: Vec<&str> = script.lines().take_while(|l| l.starts_with('#')).collect();
        for want in [
            format!("#SBATCH --job-name={job}"),
            "#SBATCH --partition=debug".into(),
            "#SBATCH --time=00:10:00".into(),
            "#SBATCH --cpus-per-task=2".into(),
            "#SBATCH --mem=4G".into(),
            "#SBATCH --account=lab".into(),
        ] {
            assert!(header.contains(&want.as_str()), "{want} in\n{script}");
        }
        assert!(header.iter().any(|l| l.starts_with("#SBATCH --output=\"") && l.contains("scripts $HOME/")), "{script}");
    }
    assert!(a.lines().any(|l| l == "#SBATCH --array=0-2"), "{a}");
    assert!(!g.contains("--array"), "{g}");
    // What the array task runs, word by word, as bash reads the script: absolute quoted
    // paths, the --set, the node and the shard count, the index from SLURM_ARRAY_TASK_ID.
    let words = script_words(&array, &[("SLURM_ARRAY_TASK_ID", "1")]);
    let report = s(&scripts.join("reference_cornell-reference-shard-1.json"));
    let want: Vec<String> = [
        "shard",
        &graph(),
        "--cache",
        &s(&cache),
        "--set",
        set,
        "--threads",
        "2",
        "--node",
        "reference",
        "--shards",
        "3",
        "--report",
        &report,
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    assert_eq!(words, want);
    assert!(Path::new(&words[1]).is_absolute() && Path::new(&words[3]).is_absolute());
    let words = script_words(&gather, &[]);
    let want: Vec<String> = [
        "run",
        &graph(),
        "--cache",
        &s(&cache),
        "--set",
        set,
        "--threads",
        "2",
        "--out",
        &s(&out),
        "--report",
        &s(&out.join("report.json")),
        "--output",
        "image",
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    assert_eq!(words, want);
    // Outside Slurm the array script says what it is instead of running.
    let o = Command::new("bash").arg(&array).env_remove("SLURM_ARRAY_TASK_ID").output().unwrap();
    assert!(!o.status.success() && text(&o.stderr).contains("submit it with sbatch"), "{}", text(&o.stderr));
}

#[test]
fn submit_calls_sbatch_for_the_array_then_the_gather_after_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bin = d.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    // A stand-in sbatch: logs its arguments, answers job 4242 (with a cluster name) then 4243.
    let log = d.join("sbatch.log");
    let sbatch = bin.join("sbatch");
    std::fs::write(
        &sbatch,
        format!(
            "#!/bin/sh\nprintf '%s\\n' \"$*\" >> '{}'\nif grep -q dependency '{}'; then echo 4243; else echo '4242;cluster'; fi\n",
            log.display(),
            log.display()
        ),
    )
    .unwrap();
    make_executable(&sbatch);
    let fake = echo_binary(d);
    let args = |cache: &str| -> Vec<String> {
        [
            "slurm",
            &graph(),
            "--node",
            "reference",
            "--shards",
            "2",
            "--cache",
            &s(&d.join(cache)),
            "--out",
            &s(&d.join("out")),
            "--relume",
            &s(&fake),
            "--submit",
        ]
        .iter()
        .map(|a| a.to_string())
        .collect()
    };
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    let printed = text(&relume_ok(&args("cache"), &[("PATH", path)]).stdout);
    let calls: Vec<String> = std::fs::read_to_string(&log).unwrap().lines().map(String::from).collect();
    let scripts = d.join("out/slurm");
    assert_eq!(
        calls,
        vec![
            format!("--parsable {}", s(&scripts.join("reference_cornell-reference-shards.sbatch"))),
            format!("--parsable --dependency=afterok:4242 {}", s(&scripts.join("reference_cornell-reference-gather.sbatch"))),
        ]
    );
    assert!(printed.contains("array job 4242\n") && printed.contains("gather job 4243\n"), "{printed}");
    // Without sbatch on PATH: a clear error, exit 1.
    let o = relume(&args("cache2"), &[("PATH", s(&d.join("nothing")))]).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("`sbatch`, which is not on PATH"), "{}", text(&o.stderr));
}

#[test]
fn slurm_refuses_too_many_tasks_a_node_that_is_not_sharded_and_no_disk_cache_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scripts = d.join("scripts");
    let run = |extra: &[&str]| -> (Option<i32>, String) {
        let mut args = vec!["slurm".to_string(), graph(), "--cache".into(), s(&d.join("cache")), "--script-dir".into(), s(&scripts)];
        args.extend(extra.iter().map(|a| a.to_string()));
        let o = relume(&args, &[]).output().unwrap();
        (o.status.code(), text(&o.stderr))
    };
    let (code, err) = run(&["--node", "reference", "--shards", "4001"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("MaxArraySize") && err.contains("smaller --shards"), "{err}");
    let (code, err) = run(&["--node", "reference", "--shards", "17"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("only 16 chunks") && err.contains("--shards 16 or fewer"), "{err}");
    let (code, err) = run(&["--node", "error", "--shards", "2"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("does not split its work into shards") && err.contains("sharded nodes: reference, truth"), "{err}");
    let (code, err) = run(&["--node", "nope", "--shards", "2"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("no node \"nope\""), "{err}");
    let (code, err) = run(&["--node", "reference", "--shards", "2", "--no-disk-cache"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("drop --no-disk-cache"), "{err}");
    let (code, err) = run(&["--node", "reference", "--shards", "2", "--partition", "a b"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--partition"), "{err}");
    assert!(!scripts.exists(), "a refused command wrote its scripts");
}
