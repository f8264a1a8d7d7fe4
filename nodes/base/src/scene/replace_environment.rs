use crate::image::io::read_image;
use crate::types::{EnvMap, Environment, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, MemoryEstimate, NodeError, PortSize, RunCtx};
use std::path::PathBuf;

params! {
    /// The scene under another sky: its environment replaced by the lat-long map in `path`
    /// (OpenEXR or Radiance HDR, linear; PNG decoded from sRGB), each texel times `scale`, as
    /// a scene file's `environment: Map(path, scale)` loads it. The lighting edit that swaps
    /// the sky: placed between `LoadScene` and what reads the sky (`TurnEnvironment`, the
    /// environment lighting, the reference), it leaves the precompute, which reads the scene as
    /// loaded, untouched, so a new map costs only the sky's own stages. The cache key hashes
    /// the file's content. The map must be finite and non-negative; its size is read from the
    /// file's header and refused over the memory budget before the texels are decoded.
    pub struct ReplaceEnvironment {
        /// lat-long environment map (.exr, .hdr or .png), relative to the graph file
        pub path: PathBuf;
        /// radiance multiplier
        pub scale: f64 = 1.0, range = 0.0..=1.0e6;
    }
}

/// Bytes the scene's new map holds while it is built: the decoded image, its texels and the
/// map's sampling table (about three copies of the texels).
fn map_bytes(width: u64, height: u64) -> u64 {
    width * height * 12 * 3
}

#[node(category = "scene", outputs = [scene])]
impl ReplaceEnvironment {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        let map = ::image::image_dimensions(&self.path).ok().map(|(w, h)| map_bytes(w as u64, h as u64));
        MemoryEstimate {
            outputs: vec![inputs[0].map(|s| PortSize { bytes: s.bytes + map.unwrap_or(0) / 3, ..s })],
            working: map.unwrap_or(0),
        }
    }

    fn run(&self, scene: &Scene, cx: &RunCtx) -> Result<Scene, NodeError> {
        self.replaced(scene, cx)
    }
}

impl ReplaceEnvironment {
    /// The node's work: the map's size read from its header and checked against the budget,
    /// then the map decoded and put in place.
    fn replaced(&self, scene: &Scene, cx: &RunCtx) -> Result<Scene, NodeError> {
        if let Ok((w, h)) = ::image::image_dimensions(&self.path) {
            let bytes = map_bytes(w as u64, h as u64);
            if bytes > cx.memory_budget() {
                return Err(NodeError::over_limit(format!(
                    "the {w} × {h} map would need {}, over the {} budget",
                    fmt_bytes(bytes),
                    fmt_bytes(cx.memory_budget())
                )));
            }
        }
        let img = read_image(&self.path).map_err(|m| NodeError::param("path", m))?;
        let map =
            EnvMap::from_image(&img, self.scale as f32).map_err(|m| NodeError::param("path", format!("{}: {m}", self.path.display())))?;
        let mut scene = scene.clone();
        scene.environment = Some(Environment::Map(map));
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builder::SceneBuilder;
    use crate::testing::run_node;
    use crate::types::Image;
    use glam::Vec3;
    use relume_core::{ParamValue, Value};

    fn run(dir: &std::path::Path, file: &str, scale: f64, scene: Scene) -> Result<Scene, NodeError> {
        let p = [("path", ParamValue::Text(file.into())), ("scale", ParamValue::Float(scale))];
        Ok(run_node::<ReplaceEnvironment>(&p, dir, vec![Value::new(scene)])?[0].get::<Scene>().unwrap().clone())
    }

    #[test]
    fn the_scene_takes_the_files_sky_scaled_and_keeps_the_rest() {
        let dir = tempfile::tempdir().unwrap();
        let img = Image::from_fn(16, 8, |x, y| [x as f32, y as f32, 1.0]);
        crate::image::io::write_exr(&dir.path().join("sky.exr"), &img).unwrap();
        let before = SceneBuilder::new(Vec3::Z, Vec3::ZERO, 40.0, 8, 8).environment(Environment::Constant(Vec3::ONE)).build();
        let after = run(dir.path(), "sky.exr", 2.0, before.clone()).unwrap();
        let Some(Environment::Map(m)) = &after.environment else { panic!("a map") };
        assert_eq!((m.width, m.height), (16, 8));
        assert!(m.texels.iter().zip(&img.pixels).all(|(t, p)| *t == Vec3::from(*p) * 2.0));
        assert_eq!(after.camera, before.camera);
        assert_eq!(after.triangles, before.triangles);
    }

    #[test]
    fn a_map_over_the_budget_is_refused_from_its_header_before_it_is_decoded() {
        let dir = tempfile::tempdir().unwrap();
        crate::image::io::write_exr(&dir.path().join("sky.exr"), &Image::from_fn(16, 8, |_, _| [1.0; 3])).unwrap();
        let node = ReplaceEnvironment { path: dir.path().join("sky.exr"), scale: 1.0 };
        let scene = SceneBuilder::new(Vec3::Z, Vec3::ZERO, 40.0, 8, 8).build();
        let cancel = relume_core::CancelToken::new();
        let need = map_bytes(16, 8);
        let e = node.replaced(&scene, &RunCtx::new("sky", &cancel, None).with_memory_budget(need - 1)).expect_err("over the budget");
        assert!(matches!(e, NodeError::OverLimit { .. }) && e.to_string().contains("16 × 8"), "{e}");
        assert!(node.replaced(&scene, &RunCtx::new("sky", &cancel, None).with_memory_budget(need)).is_ok());
    }

    #[test]
    fn a_missing_unreadable_or_negative_sky_is_refused_by_parameter() {
        let dir = tempfile::tempdir().unwrap();
        let scene = SceneBuilder::new(Vec3::Z, Vec3::ZERO, 40.0, 8, 8).build();
        let is_path = |e: &NodeError| matches!(e, NodeError::Param { name, .. } if name == "path");
        let e = run(dir.path(), "none.exr", 1.0, scene.clone()).unwrap_err();
        assert!(is_path(&e) && e.to_string().contains("none.exr"), "{e}");
        std::fs::write(dir.path().join("junk.exr"), b"not an exr").unwrap();
        let e = run(dir.path(), "junk.exr", 1.0, scene.clone()).unwrap_err();
        assert!(is_path(&e) && e.to_string().contains("not a readable"), "{e}");
        let bad = Image::from_fn(4, 4, |x, _| [if x == 2 { -1.0 } else { 0.5 }, 0.5, 0.5]);
        crate::image::io::write_exr(&dir.path().join("neg.exr"), &bad).unwrap();
        let e = run(dir.path(), "neg.exr", 1.0, scene).unwrap_err();
        assert!(is_path(&e) && e.to_string().contains("texel (2, 0)"), "{e}");
    }
}
