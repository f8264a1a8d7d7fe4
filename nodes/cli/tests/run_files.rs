//! The files a run reads and writes, checked before it runs: no write onto a file the run
//! reads (its graph, an input image, a scene's texture) or onto another of its writes, no read
//! outside the graph's folder unless allowed, and `check` names an input file that is not
//! there. Each refused with exit code 2, the files left as they were and none quoted.

use std::ffi::OsStr;
use std::path::Path;
use std::process::Command;

fn relume(dir: &Path, args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_relume"))
        .current_dir(dir)
        .args(args.iter().map(OsStr::new))
        .env_remove("RELUME_CACHE")
        .output()
        .unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// A folder holding `g.ron` (the graph text given), and what the folder's path resolves to.
fn folder_with(graph: &str) -> (tempfile::TempDir, String) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("g.ron"), graph).unwrap();
    let real = dir.path().canonicalize().unwrap().display().to_string();
    (dir, real)
}

const PATTERN: &str = "Graph(version: 1, nodes: {\n  \"p\": (kind: \"TestPattern\", params: (width: 8, height: 8)),\n}, edges: [], outputs: { \"x\": \"p.image\" })";

#[test]
fn the_report_or_a_sweep_csv_onto_the_graph_file_is_refused_and_the_graph_kept() {
    let (dir, real) = folder_with(PATTERN);
    let (code, err) = relume(dir.path(), &["run", "g.ron", "--out", "o", "--report", "g.ron", "--no-disk-cache", "-q"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(&format!("--report: writing {real}/g.ron would overwrite a file this run reads (the graph file); write it elsewhere")),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(dir.path().join("g.ron")).unwrap(), PATTERN);
    let filters = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../graphs/filters.ron")).unwrap();
    let (dir, _) = folder_with(&filters);
    for flag in ["--csv", "--plot"] {
        let (code, err) = relume(
            dir.path(),
            &["sweep", "g.ron", "--vary", "blur.sigma=1,2", "--metric", "mse", "--out", "o", flag, "g.ron", "--no-disk-cache", "-q"],
        );
        assert_eq!(code, Some(2), "{flag}: {err}");
        assert!(err.contains("would overwrite a file this run reads (the graph file)"), "{flag}: {err}");
    }
    assert_eq!(std::fs::read_to_string(dir.path().join("g.ron")).unwrap(), filters);
}

#[test]
fn the_report_onto_an_output_image_is_two_writes_of_one_file() {
    let (dir, real) = folder_with(PATTERN);
    let (code, err) = relume(dir.path(), &["run", "g.ron", "--out", "o", "--report", "o/x.png", "--no-disk-cache", "-q"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains(&format!("--report: output \"x\" writes {real}/o/x.png too, so one would overwrite the other")), "{err}");
    assert!(!dir.path().join("o/x.png").exists(), "nothing ran");
}

#[test]
fn save_image_onto_its_own_input_image_or_onto_another_save_is_refused_at_its_line() {
    let image = "Graph(version: 1, nodes: {\n  \"load\": (kind: \"LoadImage\", params: (path: \"in.png\")),\n  \"save\": (kind: \"SaveImage\", params: (path: \"in.png\")),\n}, edges: [(\"load.image\", \"save.image\")], outputs: { \"x\": \"save.image\" })";
    let (dir, real) = folder_with(image);
    let before = b"not really a png".to_vec();
    std::fs::write(dir.path().join("in.png"), &before).unwrap();
    for args in [&["run", "g.ron", "--out", "o", "--no-disk-cache", "-q"][..], &["check", "g.ron"]] {
        let cmd = args[0];
        let (code, err) = relume(dir.path(), args);
        assert_eq!(code, Some(2), "{cmd}: {err}");
        let want = format!(
            "g.ron:3:40: node \"save\": parameter `path`: writing {real}/in.png would overwrite a file this run reads (node \"load\" (LoadImage) parameter `path`)"
        );
        assert!(err.contains(&want), "{cmd}: {err}");
    }
    assert_eq!(std::fs::read(dir.path().join("in.png")).unwrap(), before);

    let two = "Graph(version: 1, nodes: {\n  \"p\": (kind: \"TestPattern\", params: ()),\n  \"a\": (kind: \"SaveImage\", params: (path: \"out/same.png\")),\n  \"b\": (kind: \"SaveImage\", params: (path: \"out/../out/same.png\")),\n}, edges: [(\"p.image\", \"a.image\"), (\"p.image\", \"b.image\")], outputs: { \"a\": \"a.image\", \"b\": \"b.image\" })";
    let (dir, real) = folder_with(two);
    let (code, err) = relume(dir.path(), &["run", "g.ron", "--out", "o", "--no-disk-cache", "-q"]);
    assert_eq!(code, Some(2), "{err}");
    let both = ["node \"a\": parameter `path`: node \"b\" (SaveImage)", "node \"b\": parameter `path`: node \"a\" (SaveImage)"];
    assert!(
        both.iter()
            .any(|w| err.contains(&format!("{w} parameter `path` writes {real}/out/same.png too, so one would overwrite the other"))),
        "{err}"
    );
}

#[test]
fn save_image_onto_a_texture_the_scene_reads_is_refused_and_check_names_a_missing_mesh() {
    let (dir, real) = folder_with(
        "Graph(version: 1, nodes: {\n  \"scene\": (kind: \"LoadScene\", params: (path: \"s.ron\")),\n  \"bvh\": (kind: \"BuildBvh\", params: ()),\n  \"render\": (kind: \"DirectLight\", params: ()),\n  \"save\": (kind: \"SaveImage\", params: (path: \"tex/wood.png\")),\n}, edges: [(\"scene.scene\", \"bvh.scene\"), (\"scene.scene\", \"render.scene\"), (\"bvh.accel\", \"render.accel\"), (\"render.image\", \"save.image\")], outputs: { \"x\": \"save.image\" })",
    );
    std::fs::write(
        dir.path().join("s.ron"),
        "Scene(camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8),\n materials: { \"m\": Lambert(albedo: 0.5, kd_map: \"tex/wood.png\") },\n shapes: [Obj(path: \"tri.obj\", material: \"m\")],\n lights: [Point(position: (0, 0, 2), intensity: 1)])",
    )
    .unwrap();
    std::fs::create_dir(dir.path().join("tex")).unwrap();
    std::fs::write(dir.path().join("tex/wood.png"), b"texels").unwrap();
    let (code, err) = relume(dir.path(), &["check", "g.ron"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains(&format!("node \"scene\": parameter `path`: reads {real}/tri.obj, which does not exist")), "{err}");
    assert!(
        err.contains(&format!("node \"save\": parameter `path`: writing {real}/tex/wood.png would overwrite a file this run reads (node \"scene\" (LoadScene) parameter `path`, which names it)")),
        "{err}"
    );
    std::fs::write(dir.path().join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let (code, err) = relume(dir.path(), &["run", "g.ron", "--out", "o", "--no-disk-cache", "-q"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("would overwrite a file this run reads (node \"scene\" (LoadScene) parameter `path`, which names it)"), "{err}");
    assert_eq!(std::fs::read(dir.path().join("tex/wood.png")).unwrap(), b"texels");
}

#[test]
fn a_file_of_a_kind_the_node_cannot_write_is_refused_when_the_graph_loads() {
    let (dir, _) = folder_with(
        "Graph(version: 1, nodes: {\n  \"p\": (kind: \"TestPattern\", params: ()),\n  \"save\": (kind: \"SaveImage\", params: (path: \"x.ron\")),\n}, edges: [(\"p.image\", \"save.image\")], outputs: { \"x\": \"save.image\" })",
    );
    let (code, err) = relume(dir.path(), &["check", "g.ron"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(
            "g.ron:3:40: node \"save\": parameter `path`: \"x.ron\" has the extension .ron; this parameter takes a .exr or .png file"
        ),
        "{err}"
    );
}

#[test]
fn a_megabyte_long_path_is_cut_in_the_message() {
    let long = format!("{}.png", "p".repeat(1 << 20));
    let (dir, _) = folder_with(&format!(
        "Graph(version: 1, nodes: {{\n  \"load\": (kind: \"LoadImage\", params: (path: \"{long}\")),\n}}, edges: [], outputs: {{ \"x\": \"load.image\" }})"
    ));
    let (code, err) = relume(dir.path(), &["check", "g.ron"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.len() < 4000, "{} bytes of message", err.len());
    assert!(err.contains("characters left out]…") && err.contains("ppp.png, which does not exist"), "{err}");
}

#[test]
fn reads_outside_the_graphs_folder_are_refused_and_never_quoted() {
    let secret = tempfile::tempdir().unwrap();
    let secret_file = secret.path().join("secret.png");
    std::fs::write(&secret_file, "root:x:0:0:root:/root:/bin/bash\n").unwrap();
    let secret_real = secret_file.canonicalize().unwrap().display().to_string();
    let load = |path: &str| {
        format!("Graph(version: 1, nodes: {{\n  \"load\": (kind: \"LoadImage\", params: (path: \"{path}\")),\n}}, edges: [], outputs: {{ \"x\": \"load.image\" }})")
    };
    let (dir, _) = folder_with(&load(&secret_real));
    let refused = format!(
        "g.ron:2:40: node \"load\": parameter `path`: refusing to read {secret_real}: it is outside the folders this run may read from"
    );
    for args in [&["check", "g.ron"][..], &["run", "g.ron", "--no-disk-cache", "-q"]] {
        let (code, err) = relume(dir.path(), args);
        assert_eq!(code, Some(2), "{err}");
        assert!(err.contains(&refused) && err.contains("`--allow-reads-anywhere`"), "{err}");
    }
    // Through `..` and through a link inside the folder.
    let up = format!("{}{}", "../".repeat(dir.path().components().count()), secret_real.trim_start_matches('/'));
    std::fs::write(dir.path().join("g.ron"), load(&up)).unwrap();
    let (code, err) = relume(dir.path(), &["check", "g.ron"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains(&format!("refusing to read {secret_real}")), "{err}");
    std::os::unix::fs::symlink(&secret_file, dir.path().join("link.png")).unwrap();
    std::fs::write(dir.path().join("g.ron"), load("link.png")).unwrap();
    let (code, err) = relume(dir.path(), &["check", "g.ron"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains(&format!("refusing to read {secret_real}")), "{err}");
    // A scene in the folder naming a mesh outside it.
    std::fs::write(
        dir.path().join("s.ron"),
        format!("Scene(camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8),\n materials: {{ \"m\": Lambert(albedo: 0.5) }},\n shapes: [Obj(path: \"{secret_real}\", material: \"m\")],\n lights: [])"),
    )
    .unwrap();
    std::fs::write(
        dir.path().join("g.ron"),
        "Graph(version: 1, nodes: {\n  \"scene\": (kind: \"LoadScene\", params: (path: \"s.ron\")),\n  \"bvh\": (kind: \"BuildBvh\", params: ()),\n}, edges: [(\"scene.scene\", \"bvh.scene\")], outputs: { \"x\": \"bvh.accel\" })",
    )
    .unwrap();
    let (code, err) = relume(dir.path(), &["run", "g.ron", "--no-disk-cache", "-q"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains(&format!("node \"scene\": parameter `path`: refusing to read {secret_real}")), "{err}");
    // Allowed, by its folder or anywhere, the read happens and fails without quoting the file.
    let secret_dir = secret.path().display().to_string();
    for allow in [&["--read-from", secret_dir.as_str()][..], &["--allow-reads-anywhere"]] {
        let mut args = vec!["run", "g.ron", "--no-disk-cache", "-q"];
        args.extend(allow);
        let (code, err) = relume(dir.path(), &args);
        assert_eq!(code, Some(1), "{allow:?}: {err}");
        assert!(err.contains("is not an OBJ statement") && !err.contains("root:"), "{allow:?}: {err}");
    }
}
