//! The built `relume` binary end to end: real process, real exit codes, real files.

use std::process::Command;

fn graphs() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../graphs")
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
