//! LoadScene node.

use super::format::load_scene_file;
use crate::types::Scene;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};
use std::path::PathBuf;

node_doc! {
    /// Loads a scene file (RON: camera, materials, OBJ meshes and spheres, lights,
    /// environment; see nodes/src/scene/format.rs). OBJ `o`/`g` groups become objects. The
    /// meshes and maps it names are cache dependencies: editing any of them re-runs the node.
    /// Zero-area triangles are dropped and counted in the report's notes.
    pub struct LoadScene;
}

pub struct LoadSceneParams {
    pub path: PathBuf,
    pub width: usize,
    pub height: usize,
}

impl Params for LoadSceneParams {
    fn schema() -> Schema {
        Schema::new()
            .input_file("path")
            .help("scene file (.ron), relative to the graph file")
            .int("width", 0, 0, 16384)
            .unit("px")
            .help("image width; 0 keeps the scene file's camera")
            .int("height", 0, 0, 16384)
            .unit("px")
            .help("image height; 0 keeps the scene file's camera")
    }
    fn from_values(v: &ParamValues) -> Self {
        LoadSceneParams { path: v.path("path"), width: v.int("width") as usize, height: v.int("height") as usize }
    }
}

impl Node for LoadScene {
    const KIND: &'static str = "LoadScene";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "scene";
    const CACHING: Caching = Caching::Memory;
    type Params = LoadSceneParams;

    fn ports() -> Ports {
        Ports::new().output::<Scene>("scene")
    }

    fn run(&self, p: &LoadSceneParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        let loaded = load_scene_file(&p.path).map_err(|m| NodeError::param("path", m))?;
        for (path, hash) in &loaded.files {
            cx.depends_on_file(path, *hash);
        }
        for n in loaded.notes {
            cx.note(n);
        }
        let mut scene = loaded.scene;
        if p.width > 0 {
            scene.camera.width = p.width;
        }
        if p.height > 0 {
            scene.camera.height = p.height;
        }
        let s = &scene;
        cx.metric("triangles", s.triangles.len() as f64);
        cx.metric("objects", s.objects.len() as f64);
        io.set("scene", scene)
    }
}
