//! The build-script half of node registration: a crate's `build.rs` calls [`register_nodes`],
//! which finds every file under `src/` holding a `#[node(…)]` impl and writes
//! `$OUT_DIR/register.rs`, a `pub fn register(reg)` that adds each of those kinds. The crate
//! includes it (`include!(concat!(env!("OUT_DIR"), "/register.rs"));`), so adding a node takes
//! its own file and the one `pub mod` line that declares it: nothing lists it a second time.
//!
//! What it reads of a node file, and the module path it registers the node under:
//!
//! ```
//! use relume_build::{module_path, node_type};
//! use std::path::Path;
//!
//! let file = "params! { pub struct Blur { pub sigma: f32 = 1.0; } }\n#[node(category = \"image\")]\nimpl Blur {}\n";
//! assert_eq!(node_type(file).as_deref(), Some("Blur"));
//! assert_eq!(node_type("fn main() {}"), None);
//! assert_eq!(module_path(Path::new("src"), Path::new("src/image/blur.rs")), "image::blur");
//! ```

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A node found in a source file: the module path from the crate root and the type's name.
#[derive(Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Found {
    pub module: String,
    pub ty: String,
}

/// The type a `#[node(…)]` impl is for, in the non-test part of `text` (`None`: no node).
pub fn node_type(text: &str) -> Option<String> {
    let code = text.split("\n#[cfg(test)]").next().unwrap_or(text);
    let at = code.lines().position(|l| l.starts_with("#[node(") || l == "#[node]")?;
    let rest = code.lines().skip(at).find_map(|l| l.strip_prefix("impl"))?.trim_start();
    // `impl<'a> X` names the type after its generics.
    let rest = match rest.strip_prefix('<') {
        Some(g) => g.split_once('>')?.1.trim_start(),
        None => rest,
    };
    Some(rest.split([' ', '<', '{']).next().unwrap_or("").to_string())
}

/// The module path of `file` (under `src`): `image/blur.rs` → `image::blur`, `a/mod.rs` → `a`.
pub fn module_path(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).unwrap_or(file).with_extension("");
    let mut parts: Vec<String> = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts.join("::")
}

/// Every node under `src`, sorted by module path.
pub fn find_nodes(src: &Path) -> Vec<Found> {
    let mut files = Vec::new();
    let mut dirs = vec![src.to_path_buf()];
    while let Some(d) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                files.push(p);
            }
        }
    }
    let mut found: Vec<Found> = files
        .iter()
        .filter_map(|f| {
            let ty = node_type(&std::fs::read_to_string(f).ok()?)?;
            Some(Found { module: module_path(src, f), ty })
        })
        .collect();
    found.sort();
    found
}

/// The text of `register.rs` for these nodes.
pub fn register_source(nodes: &[Found]) -> String {
    let mut s = String::from(
        "/// Registers every node kind of this crate: each file under `src/` with a `#[node]` impl\n\
         /// (found by the build script).\n\
         pub fn register(reg: &mut relume_core::Registry) {\n",
    );
    for n in nodes {
        let path = if n.module.is_empty() { n.ty.clone() } else { format!("{}::{}", n.module, n.ty) };
        writeln!(s, "    reg.add::<crate::{path}>();").unwrap();
    }
    s.push_str("}\n");
    s
}

/// For a crate's `build.rs`: writes `$OUT_DIR/register.rs` and asks cargo to run again when
/// anything under `src/` changes.
pub fn register_nodes() {
    let dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("run from a build script"));
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("run from a build script"));
    let src = dir.join("src");
    println!("cargo:rerun-if-changed=src");
    let text = register_source(&find_nodes(&src));
    let target = out.join("register.rs");
    // Rewritten only when it changes, so that an unrelated edit does not touch it.
    if std::fs::read_to_string(&target).ok().as_deref() != Some(text.as_str()) {
        std::fs::write(&target, text).expect("write register.rs");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_node_type_outside_tests_only() {
        let text = "use x;\n/// doc\n#[node(category = \"image\", outputs = [image])]\nimpl Blur {\n    fn run() {}\n}\n";
        assert_eq!(node_type(text).as_deref(), Some("Blur"));
        assert_eq!(node_type("#[node]\nimpl<'a> Plain {}\n").as_deref(), Some("Plain"));
        assert_eq!(node_type("fn f() {}\n#[cfg(test)]\nmod tests {\n#[node(category = \"x\")]\nimpl T {}\n}\n"), None);
        // A mention in a comment or string is not a node.
        assert_eq!(node_type("/// put #[node(…)] on the impl\nfn f() {}\n"), None);
    }

    #[test]
    fn module_paths_follow_the_files() {
        let src = Path::new("/c/src");
        assert_eq!(module_path(src, Path::new("/c/src/image/blur.rs")), "image::blur");
        assert_eq!(module_path(src, Path::new("/c/src/image/mod.rs")), "image");
        assert_eq!(module_path(src, Path::new("/c/src/lib.rs")), "");
        assert_eq!(module_path(src, Path::new("/c/src/top.rs")), "top");
    }

    #[test]
    fn the_source_registers_each_node_once() {
        let nodes = vec![Found { module: "a::b".into(), ty: "B".into() }, Found { module: "".into(), ty: "Root".into() }];
        let s = register_source(&nodes);
        assert!(s.contains("reg.add::<crate::a::b::B>();\n    reg.add::<crate::Root>();"), "{s}");
        assert_eq!(s.matches("reg.add").count(), 2);
    }
}
