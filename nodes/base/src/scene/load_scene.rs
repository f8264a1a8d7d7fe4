use super::format::{load_scene_file, scene_file_paths};
use crate::types::Scene;
use relume_core::{node, params, NodeError, RunCtx};
use std::path::PathBuf;

params! {
    /// Loads a scene file (RON: camera, materials, OBJ meshes and spheres, lights,
    /// environment; see `scene/format.rs`). OBJ `o`/`g` groups become objects. The
    /// meshes and maps it names are cache dependencies: editing any of them re-runs the node.
    /// Zero-area triangles are dropped and counted in the report's notes.
    pub struct LoadScene {
        /// scene file (.ron), relative to the graph file
        pub path: PathBuf, also_reads = scene_file_paths;
        /// image width; 0 keeps the scene file's camera
        pub width: usize = 0, range = 0..=16384, unit = "px", test = 24;
        /// image height; 0 keeps the scene file's camera
        pub height: usize = 0, range = 0..=16384, unit = "px", test = 20;
    }
}

#[node(category = "scene", version = 2, metrics = ["triangles", "objects"], outputs = [scene])]
impl LoadScene {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The scene's bytes are known only once its meshes are read; the resolution is the
        // override when one is given.
        let _ = inputs;
        let dims = (self.width > 0 && self.height > 0).then_some([self.width, self.height]);
        relume_core::MemoryEstimate { outputs: vec![dims.map(|d| relume_core::PortSize { bytes: 0, dims: Some(d) })], working: 0 }
    }

    fn run(&self, cx: &RunCtx) -> Result<Scene, NodeError> {
        let loaded = load_scene_file(&self.path).map_err(|m| NodeError::param("path", m))?;
        for (path, hash) in &loaded.files {
            cx.depends_on_file(path, *hash);
        }
        for n in loaded.notes {
            cx.note(n);
        }
        let mut scene = loaded.scene;
        if self.width > 0 {
            scene.camera.width = self.width;
        }
        if self.height > 0 {
            scene.camera.height = self.height;
        }
        cx.metric("triangles", scene.triangles.len() as f64);
        cx.metric("objects", scene.objects.len() as f64);
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::run_full;
    use relume_core::ParamValue;

    fn write_scene(dir: &std::path::Path) {
        std::fs::write(dir.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 0\nf 1 2 3\nf 1 4 2\n").unwrap();
        std::fs::write(
            dir.join("s.ron"),
            "Scene(camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 64, height: 48),\n materials: { \"m\": Lambert(albedo: 0.5) },\n shapes: [Obj(path: \"tri.obj\", material: \"m\")],\n lights: [Point(position: (0, 0, 2), intensity: 1)])",
        )
        .unwrap();
    }

    #[test]
    fn loads_overrides_the_resolution_and_records_the_mesh_as_a_dependency() {
        let dir = tempfile::tempdir().unwrap();
        write_scene(dir.path());
        let e = run_full::<LoadScene>(&[("path", ParamValue::Text("s.ron".into())), ("width", ParamValue::Int(16))], dir.path(), vec![])
            .unwrap();
        let s = e.outputs[0].get::<Scene>().unwrap();
        assert_eq!((s.camera.width, s.camera.height), (16, 48));
        assert_eq!(s.triangles.len(), 1);
        assert_eq!(e.notes, ["1 zero-area triangles dropped"]);
        assert!(e.deps.iter().any(|(p, _)| p.ends_with("tri.obj")), "{:?}", e.deps);
        assert!(e.deps_unchanged());
        std::fs::write(dir.path().join("tri.obj"), "v 0 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert!(!e.deps_unchanged(), "editing the mesh invalidates the result");
    }

    #[test]
    fn a_broken_scene_is_a_parameter_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("s.ron"), "Scene(camera: (origin: (0, 0, 3)))").unwrap();
        let e = run_full::<LoadScene>(&[("path", ParamValue::Text("s.ron".into()))], dir.path(), vec![]).unwrap_err();
        assert!(
            matches!(&e, NodeError::Param { name, msg } if name == "path" && msg.contains("s.ron:1:") && msg.contains("camera needs `target`")),
            "{e}"
        );
    }
}
