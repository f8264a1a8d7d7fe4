//! The scene loader: the input is a scene file (RON), written into a temporary folder that
//! also holds small meshes (with an MTL, one with UVs), a texture and an environment map, and
//! loaded through `load_scene_file`, the function the LoadScene node calls. Any input must give
//! a scene or an error message, never a panic, a stack overflow or a hang.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relume_base::scene::format::load_scene_file;
use std::path::PathBuf;
use std::sync::OnceLock;

static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();

fn dir() -> &'static PathBuf {
    &DIR.get_or_init(|| {
        let d = tempfile::tempdir().expect("a temporary folder");
        let w = |name: &str, bytes: &[u8]| std::fs::write(d.path().join(name), bytes).expect("write a fuzz asset");
        // The names the seed scenes use.
        w("tri.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
        w("box.obj", include_bytes!("../../graphs/assets/cornell/cornell_box.obj"));
        w("cornell_box.mtl", include_bytes!("../../graphs/assets/cornell/cornell_box.mtl"));
        w("floor.obj", include_bytes!("../../graphs/assets/glass/floor.obj"));
        // A triangle with UVs and a texture for the material maps.
        w("uv.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n");
        w("kd.png", include_bytes!("../../graphs/assets/spot/spot_kd.png"));
        // A 4 × 2 Radiance HDR map (flat RGBE scanlines).
        let mut hdr = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 4\n".to_vec();
        for i in 0..8u8 {
            hdr.extend_from_slice(&[100 + i, 90, 80, 129]);
        }
        w("sky.hdr", &hdr);
        let p = d.path().join("s.ron");
        (d, p)
    })
    .1
}

fuzz_target!(|data: &[u8]| {
    let path = dir();
    std::fs::write(path, data).expect("write the scene file");
    if let Err(e) = load_scene_file(path) {
        assert!(!e.is_empty());
    }
});
