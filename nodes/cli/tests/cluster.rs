//! Sharded nodes across processes, through the `relume` binary: `PathTrace` on `cornell`
//! unsharded, as 3 Slurm-style shards (`relume shard` with SLURM_ARRAY_TASK_ID/COUNT) over one
//! cache folder gathered by `relume run`, and over timely with 2 and 3 local processes — the
//! same image bytes every time. A timely process killed midway: the others stop with an error
//! saying so, and the re-run computes only the chunks that were missing. A peer that never
//! starts is a start-up timeout, not a hang.

use serde_json::Value;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_relume");

fn graph() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../graphs/reference_cornell.ron").to_string_lossy().into_owned()
}

/// `relume run graphs/reference_cornell.ron` for the image output at `spp`, plus `extra`.
fn run_args(spp: u32, extra: &[&str]) -> Vec<String> {
    let mut a: Vec<String> =
        ["run", &graph(), "--output", "image", "--set", &format!("reference.spp={spp}"), "-q"].map(String::from).into();
    a.extend(extra.iter().map(|s| s.to_string()));
    a
}

fn relume(args: &[String]) -> Command {
    let mut c = Command::new(BIN);
    c.args(args).env_remove("RELUME_CACHE").env_remove("SLURM_ARRAY_TASK_ID").env_remove("SLURM_ARRAY_TASK_COUNT");
    c.stdout(Stdio::piped()).stderr(Stdio::piped());
    c
}

fn ok(out: Output, what: &str) -> Output {
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    assert!(out.status.success(), "{what} failed ({}):\n{}\n{}", out.status, text(&out.stdout), text(&out.stderr));
    out
}

fn p(dir: &Path, name: &str) -> String {
    dir.join(name).to_string_lossy().into_owned()
}

fn report(path: &str) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The `shards` entry of node `reference` in a run report.
fn shards(r: &Value) -> &Value {
    let node = r["nodes"].as_array().unwrap().iter().find(|n| n["id"] == "reference").expect("node reference in the report");
    &node["shards"]
}

fn num(v: &Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("not a count: {v}"))
}

/// Chunks that came from a cache, here or in the other processes, and that ran anywhere.
fn cached_and_ran(s: &Value) -> (u64, u64) {
    let (mut cached, mut ran) = (num(&s["cached"]), num(&s["ran"]));
    if let Some(peers) = s["received"].as_object() {
        for r in peers.values() {
            cached += num(&r["cached"]);
            ran += num(&r["chunks"]) - num(&r["cached"]);
        }
    }
    (cached, ran)
}

#[test]
fn unsharded_slurm_style_and_timely_runs_give_the_same_image_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spp = 8;
    ok(relume(&run_args(spp, &["--no-disk-cache", "--out", &p(d, "whole")])).output().unwrap(), "unsharded run");
    let whole = std::fs::read(d.join("whole/image.exr")).unwrap();

    // Slurm-style: three array tasks at once over one cache folder, then the gather.
    let cache = p(d, "slurm-cache");
    let tasks: Vec<Child> = (0..3)
        .map(|i| {
            let args: Vec<String> =
                ["shard", &graph(), "--node", "reference", "--set", &format!("reference.spp={spp}"), "--cache", &cache, "-q"]
                    .map(String::from)
                    .into();
            relume(&args).env("SLURM_ARRAY_TASK_ID", i.to_string()).env("SLURM_ARRAY_TASK_COUNT", "3").spawn().unwrap()
        })
        .collect();
    for t in tasks {
        ok(t.wait_with_output().unwrap(), "a shard");
    }
    let gather_report = p(d, "slurm.json");
    ok(relume(&run_args(spp, &["--cache", &cache, "--out", &p(d, "slurm"), "--report", &gather_report])).output().unwrap(), "gather");
    let s = report(&gather_report);
    assert_eq!((num(&shards(&s)["cached"]), num(&shards(&s)["ran"])), (16, 0), "the gather found every chunk: {}", shards(&s));

    // timely: 2 processes sharing a cache folder (partials travel as keys), 3 without one
    // (partials travel as bytes).
    let r2 = p(d, "t2.json");
    let args2 = run_args(spp, &["--processes", "2", "--cache", &p(d, "t2-cache"), "--out", &p(d, "t2"), "--report", &r2]);
    let out2 = ok(relume(&args2).output().unwrap(), "timely, 2 processes");
    let r3 = p(d, "t3.json");
    let out3 = ok(
        relume(&run_args(spp, &["--processes", "3", "--no-disk-cache", "--out", &p(d, "t3"), "--report", &r3])).output().unwrap(),
        "timely, 3",
    );
    for out in [out2, out3] {
        assert_eq!(String::from_utf8_lossy(&out.stdout), "", "-q: nothing on standard output, the transport's messages included");
    }
    for (r, n) in [(report(&r2), 2usize), (report(&r3), 3)] {
        let s = shards(&r);
        let received = s["received"].as_object().unwrap();
        assert_eq!(received.len(), n - 1, "chunks came from every other process: {s}");
        let from_peers: u64 = received.values().map(|r| num(&r["chunks"])).sum();
        assert_eq!(num(&s["here"]) + from_peers, 16, "{s}");
        assert_eq!(cached_and_ran(s), (0, 16), "{s}");
    }

    for name in ["slurm", "t2", "t3"] {
        assert!(std::fs::read(d.join(name).join("image.exr")).unwrap() == whole, "{name}: the image differs from the unsharded run");
    }
}

/// Free ports on 127.0.0.1 for a host file.
fn hostfile(dir: &Path, n: usize) -> String {
    let l: Vec<std::net::TcpListener> = (0..n).map(|_| std::net::TcpListener::bind("127.0.0.1:0").unwrap()).collect();
    let text: String = l.iter().map(|l| format!("127.0.0.1:{}\n", l.local_addr().unwrap().port())).collect();
    let path = p(dir, "hosts.txt");
    std::fs::write(&path, text).unwrap();
    path
}

fn entries(dir: &Path) -> usize {
    let Ok(top) = std::fs::read_dir(dir) else { return 0 };
    top.flatten()
        .filter_map(|e| std::fs::read_dir(e.path()).ok())
        .map(|d| d.flatten().filter(|f| f.path().extension().is_some_and(|x| x == "rlc")).count())
        .sum()
}

#[test]
fn a_timely_process_killed_midway_stops_the_others_and_the_rerun_computes_only_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let spp = 48;
    let cache = p(d, "cache");
    let hosts = hostfile(d, 3);
    let procs: Vec<Child> = (0..3)
        .map(|i| {
            let extra = ["--cache", &cache, "--shared-cache", "--out", &p(d, "first"), "--workers", &hosts, "--process", &i.to_string()];
            relume(&run_args(spp, &extra)).spawn().unwrap()
        })
        .collect();
    let mut procs: Vec<Option<Child>> = procs.into_iter().map(Some).collect();
    // Wait until some chunks are in the cache (scene and bvh entries aside), then kill process 2.
    let t0 = Instant::now();
    while entries(Path::new(&cache)) < 6 {
        assert!(t0.elapsed() < Duration::from_secs(120), "no chunk reached the cache");
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut victim = procs[2].take().unwrap();
    victim.kill().unwrap();
    victim.wait().unwrap();
    for (i, c) in procs.into_iter().enumerate().filter_map(|(i, c)| c.map(|c| (i, c))) {
        let out = c.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        if out.status.success() {
            // Possible only when its share was done and sent before the kill.
            continue;
        }
        assert!(err.contains("lost the other processes"), "process {i} says why it stopped: {err}");
    }
    let kept = entries(Path::new(&cache));

    let rep = p(d, "rerun.json");
    let out = relume(&run_args(spp, &["--processes", "3", "--cache", &cache, "--out", &p(d, "rerun"), "--report", &rep])).output().unwrap();
    ok(out, "the re-run");
    let r = report(&rep);
    let (cached, ran) = cached_and_ran(shards(&r));
    assert_eq!(cached + ran, 16, "{}", shards(&r));
    assert!(
        cached >= 3 && ran >= 1,
        "the re-run took the finished chunks from the cache and computed the rest: {} ({kept} entries kept)",
        shards(&r)
    );

    ok(relume(&run_args(spp, &["--no-disk-cache", "--out", &p(d, "whole")])).output().unwrap(), "unsharded run");
    assert!(std::fs::read(d.join("rerun/image.exr")).unwrap() == std::fs::read(d.join("whole/image.exr")).unwrap(), "same bytes");
}

#[test]
fn a_graph_that_does_not_load_is_said_once_before_any_process_starts() {
    let dir = tempfile::tempdir().unwrap();
    let missing = p(dir.path(), "missing.ron");
    let out = relume(&["run", &missing, "--processes", "2", "-q"].map(String::from)).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.matches("cannot read graph").count(), 1, "{err}");
    assert!(!err.contains("process 0 exited"), "{err}");
}

#[test]
fn a_peer_that_never_starts_is_a_start_up_timeout_not_a_hang() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let hosts = hostfile(d, 2);
    let t0 = Instant::now();
    let extra = ["--no-disk-cache", "--out", &p(d, "o"), "--workers", &hosts, "--process", "0", "--connect-timeout", "2"];
    let out = relume(&run_args(4, &extra)).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("not every peer connected within 2 s"), "{err}");
    assert!(t0.elapsed() < Duration::from_secs(30));
}

#[test]
fn bad_host_files_and_process_indices_are_errors_naming_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let hosts = p(d, "hosts.txt");
    std::fs::write(&hosts, "# two workstations\n127.0.0.1:4000\nnot-an-address\n").unwrap();
    let out = relume(&run_args(4, &["--out", &p(d, "o"), "--workers", &hosts, "--process", "0"])).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("hosts.txt:3: `not-an-address` is not host:port"));
    std::fs::write(&hosts, "127.0.0.1:4000\n127.0.0.1:4001\n").unwrap();
    let out = relume(&run_args(4, &["--out", &p(d, "o"), "--workers", &hosts, "--process", "2"])).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("lists 2 processes (0 to 1)"));
}
