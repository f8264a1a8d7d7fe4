//! Building scenes in code (tests, benchmarks, generated scenes).

use super::shapes::{sphere, vertex_normals};
use crate::types::{Camera, Environment, Light, Material, Object, Scene};
use glam::Vec3;

pub struct SceneBuilder {
    scene: Scene,
}

impl SceneBuilder {
    /// An empty scene seen by a camera at `origin` looking at `target` (y up).
    pub fn new(origin: Vec3, target: Vec3, fov_deg: f32, width: usize, height: usize) -> Self {
        let camera = Camera { origin, target, up: Vec3::Y, fov_deg, width, height };
        SceneBuilder {
            scene: Scene {
                objects: vec![],
                positions: vec![],
                normals: vec![],
                uvs: vec![],
                triangles: vec![],
                tri_object: vec![],
                lights: vec![],
                environment: None,
                camera,
                derived: Default::default(),
            },
        }
    }

    /// Adds a mesh; normals are computed (angle-weighted) when `normals` is `None`.
    pub fn mesh(
        mut self,
        name: &str,
        positions: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
        tris: Vec<[u32; 3]>,
        material: Material,
        emission: Vec3,
    ) -> Self {
        let s = &mut self.scene;
        let base = s.positions.len() as u32;
        let normals = normals.unwrap_or_else(|| vertex_normals(&positions, &tris));
        assert!(s.normals.len() == s.positions.len(), "add meshes before flat_shading()");
        s.positions.extend(positions);
        s.normals.extend(normals);
        let start = s.triangles.len() as u32;
        s.triangles.extend(tris.into_iter().map(|t| t.map(|i| base + i)));
        let end = s.triangles.len() as u32;
        s.tri_object.extend((start..end).map(|_| s.objects.len() as u32));
        s.objects.push(Object {
            name: name.into(),
            material,
            emission,
            dynamic: false,
            triangles: start..end,
            material_name: String::new(),
            maps: Box::default(),
        });
        self
    }

    /// A sphere; `inward` flips it so that its front faces the inside (a closed room).
    pub fn sphere(self, name: &str, center: Vec3, radius: f32, material: Material, emission: Vec3, inward: bool) -> Self {
        let (pos, mut nrm, mut tris) = sphere(center, radius, 48, 96);
        if inward {
            tris.iter_mut().for_each(|t| t.swap(1, 2));
            nrm.iter_mut().for_each(|n| *n = -*n);
        }
        self.mesh(name, pos, Some(nrm), tris, material, emission)
    }

    /// A parallelogram at `corner` spanned by `a` and `b`; its front faces a × b.
    pub fn quad(self, name: &str, corner: Vec3, a: Vec3, b: Vec3, material: Material, emission: Vec3) -> Self {
        let pos = vec![corner, corner + a, corner + a + b, corner + b];
        self.mesh(name, pos, None, vec![[0, 1, 2], [0, 2, 3]], material, emission)
    }

    pub fn light(mut self, l: Light) -> Self {
        self.scene.lights.push(l);
        self
    }

    pub fn environment(mut self, e: Environment) -> Self {
        self.scene.environment = Some(e);
        self
    }

    /// Drops the shading normals: every triangle is shaded with its geometric normal
    /// (interpolated normals on a tessellated surface do not conserve energy exactly).
    pub fn flat_shading(mut self) -> Self {
        self.scene.normals.clear();
        self
    }

    pub fn build(self) -> Scene {
        self.scene
    }
}
