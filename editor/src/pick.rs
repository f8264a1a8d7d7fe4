//! What is under a pixel of the viewed image. The probe takes the scene and the camera the
//! viewed image is rendered from — the nearest `Scene` and `Camera` outputs upstream of it
//! (the scene's own camera where no `Camera` output is) — through the engine, so they come
//! from the cache when the image ran; a ray through the pixel then finds the object, the point,
//! its texture coordinates, and the middle of the object along the ray (where a volume brush
//! lands).

use glam::{Vec2, Vec3};
use relume_base::render::camera::CameraRays;
use relume_base::types::accel::BuildQuality;
use relume_base::types::{Accel, Camera, Scene};
use relume_core::graph::PortRef;
use relume_core::{Engine, Graph, Registry, RunOptions, Value};
use std::collections::{HashSet, VecDeque};

/// Graph outputs the probe adds for its run.
const SCENE_OUTPUT: &str = "__probe_scene";
const CAMERA_OUTPUT: &str = "__probe_camera";

/// The scene and camera behind the viewed image, with an acceleration structure for picks.
pub struct Probe {
    scene: Value,
    pub camera: Camera,
    accel: Option<Accel>,
}

/// What a pick hit.
#[derive(Clone, Debug, PartialEq)]
pub struct Picked {
    pub object: String,
    /// The hit point.
    pub position: Vec3,
    /// Texture coordinates at the hit, where the scene has them.
    pub uv: Option<Vec2>,
    /// The middle of the object along the ray: between the hit and where the ray leaves it.
    pub inside: Vec3,
}

/// The nearest output of type `ty` upstream of `node` (its own outputs first, then breadth
/// first along its inputs).
pub fn upstream_port(graph: &Graph, reg: &Registry, node: &str, ty: &str) -> Option<PortRef> {
    let mut seen = HashSet::from([node.to_string()]);
    let mut todo = VecDeque::from([node.to_string()]);
    while let Some(n) = todo.pop_front() {
        let kind = graph.node(&n).and_then(|d| reg.node(&d.kind))?;
        if let Some(p) = kind.ports().outputs.iter().find(|p| p.ty.name == ty) {
            return Some(PortRef { node: n, port: p.name.into() });
        }
        for e in graph.edges.iter().filter(|e| e.to.node == n) {
            if seen.insert(e.from.node.clone()) {
                todo.push_back(e.from.node.clone());
            }
        }
    }
    None
}

impl Probe {
    /// Runs (or takes from the cache) the scene and camera upstream of `view_node`.
    pub fn new(engine: &Engine, graph: &Graph, view_node: &str) -> Result<Probe, String> {
        let reg = engine.registry();
        let scene_port = upstream_port(graph, reg, view_node, "Scene").ok_or("the viewed image is not rendered from a scene")?;
        let camera_port = upstream_port(graph, reg, view_node, "Camera");
        let mut g = graph.clone();
        crate::edit::set_output(&mut g, &scene_port, SCENE_OUTPUT, true);
        let mut outputs = vec![SCENE_OUTPUT.to_string()];
        if let Some(p) = &camera_port {
            crate::edit::set_output(&mut g, p, CAMERA_OUTPUT, true);
            outputs.push(CAMERA_OUTPUT.into());
        }
        let run = engine.run(&g, &RunOptions { outputs: Some(outputs), ..Default::default() }).map_err(|e| e.to_string())?;
        let scene = run.output(SCENE_OUTPUT).cloned().ok_or("the probe's run gave no scene")?;
        let s = scene.get::<Scene>().ok_or("the probe's scene port holds no scene")?;
        let camera = match run.output(CAMERA_OUTPUT) {
            Some(v) => v.get::<Camera>().cloned().ok_or("the probe's camera port holds no camera")?,
            None => s.camera.clone(),
        };
        Ok(Probe { scene, camera, accel: None })
    }

    pub fn scene(&self) -> &Scene {
        self.scene.get::<Scene>().expect("checked when made")
    }

    /// Scene units per pixel of an image `image_width` wide, at the distance of the target.
    pub fn units_per_pixel(&self, image_width: usize) -> f32 {
        let c = &self.camera;
        let span = 2.0 * (c.origin - c.target).length() * (c.fov_deg.to_radians() * 0.5).tan();
        span / c.width.min(c.height).max(1) as f32 * (c.width as f32 / image_width.max(1) as f32)
    }

    /// The camera's right and up axes.
    pub fn axes(&self) -> (Vec3, Vec3) {
        let c = &self.camera;
        let forward = (c.target - c.origin).normalize_or_zero();
        let right = forward.cross(c.up).normalize_or_zero();
        (right, right.cross(forward))
    }

    /// What is under pixel `p` of an image of `size` pixels showing this camera's view.
    pub fn pick(&mut self, p: egui::Pos2, size: [usize; 2]) -> Option<Picked> {
        if self.accel.is_none() {
            self.accel = Some(Accel::build(self.scene(), BuildQuality::Fast));
        }
        let (scene, accel) = (self.scene.get::<Scene>()?, self.accel.as_ref()?);
        let c = &self.camera;
        let (x, y) = (p.x * c.width as f32 / size[0].max(1) as f32, p.y * c.height as f32 / size[1].max(1) as f32);
        let (o, d) = CameraRays::new(c).ray(x, y);
        let hit = accel.intersect(o, d, 0.0, f32::INFINITY)?;
        let object = scene.tri_object[hit.tri as usize] as usize;
        let corners = scene.triangles[hit.tri as usize];
        let uv = (scene.uvs.len() == scene.positions.len()).then(|| {
            let [a, b, c] = corners.map(|i| scene.uvs[i as usize]);
            a * (1.0 - hit.b1 - hit.b2) + b * hit.b1 + c * hit.b2
        });
        // Where the ray leaves the object: the last hit on it before another object's.
        let eps = 1e-4 * scene.extent().max(1e-6);
        let (mut t, mut exit) = (hit.t, hit.t);
        while let Some(h) = accel.intersect(o, d, t + eps, f32::INFINITY) {
            if scene.tri_object[h.tri as usize] as usize != object {
                break;
            }
            (t, exit) = (h.t, h.t);
        }
        Some(Picked { object: scene.objects[object].name.clone(), position: o + d * hit.t, uv, inside: o + d * (0.5 * (hit.t + exit)) })
    }
}
