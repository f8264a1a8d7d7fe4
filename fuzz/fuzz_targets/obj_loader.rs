//! The OBJ/MTL path: the input is an OBJ file and, after the first NUL byte, the MTL file
//! `m.mtl` beside it (no NUL: no MTL file at all). Both are written into a temporary folder
//! and the OBJ is loaded through `load_obj`, the function scene files use. Any input must
//! give meshes or an error message, never a panic, a stack overflow or a hang.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relume_base::scene::obj::load_obj;
use std::sync::OnceLock;

static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let dir = DIR.get_or_init(|| tempfile::tempdir().expect("a temporary folder")).path();
    let (obj, mtl) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], Some(&data[i + 1..])),
        None => (data, None),
    };
    let mtl_path = dir.join("m.mtl");
    match mtl {
        Some(m) => std::fs::write(&mtl_path, m).expect("write the MTL"),
        None => {
            let _ = std::fs::remove_file(&mtl_path);
        }
    }
    // Scene files read the OBJ as bytes and require UTF-8 before parsing.
    let Ok(text) = std::str::from_utf8(obj) else { return };
    if let Ok(models) = load_obj(&dir.join("m.obj"), text) {
        for m in &models {
            assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < m.positions.len()), "triangle index out of range");
        }
    }
});
