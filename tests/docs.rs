//! The documentation stays true to the tree: the README's node example is a real node file,
//! quoted whole, and no document or source file points outside the repository.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn the_readme_quotes_a_real_node_file_whole() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let node = std::fs::read_to_string(root().join("nodes/base/src/image/combine.rs")).unwrap();
    assert!(node.contains("#[node("), "the quoted file is a node");
    assert!(
        readme.contains(&format!("```rust\n{node}```")),
        "README's \"Writing a node\" must quote nodes/base/src/image/combine.rs whole"
    );
}

/// Every text file the repository tracks, by extension.
fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if p.is_dir() {
            if !name.starts_with('.') && name != "target" && name != "corpus" {
                files(&p, out);
            }
        } else if ["rs", "md", "ron", "toml", "py", "sh"].iter().any(|x| name.ends_with(&format!(".{x}"))) {
            out.push(p);
        }
    }
}

#[test]
fn nothing_points_outside_the_repository() {
    let mut all = Vec::new();
    files(&root(), &mut all);
    assert!(all.len() > 100, "found {} files", all.len());
    // Built from parts, so that this file does not hold what it looks for.
    let outside = [["..", "/shared"].concat(), ["shared", "/spec"].concat(), ["shared", "/seeds"].concat()];
    let bad: Vec<String> = all
        .iter()
        .filter(|p| std::fs::read_to_string(p).is_ok_and(|t| outside.iter().any(|o| t.contains(o.as_str()))))
        .map(|p| p.strip_prefix(root()).unwrap_or(p).display().to_string())
        .collect();
    assert!(bad.is_empty(), "files that point outside the repository: {bad:?}");
}
