//! The surface point a ray hit: position, geometric and shading normals, object.

use crate::types::accel::Hit;
use crate::types::{Material, Scene};
use glam::{Vec2, Vec3};

/// Ray offsets off a surface, as a fraction of the scene's size (`Tracer::eps`) and of the
/// point's coordinates (`Surface::spawn`).
pub const OFFSET_FRACTION: f32 = 1e-6;

#[derive(Clone, Copy, Debug)]
pub struct Surface {
    pub p: Vec3,
    /// Geometric normal from the winding (front side).
    pub ng: Vec3,
    /// Interpolated shading normal, on the same side as `ng`.
    pub ns: Vec3,
    pub object: u32,
    pub tri: u32,
    pub area: f32,
    /// Interpolated texture coordinates (zero when the scene has none).
    pub uv: Vec2,
}

impl Surface {
    pub fn at(scene: &Scene, hit: &Hit, o: Vec3, d: Vec3) -> Surface {
        let t = hit.tri as usize;
        let (ng, area) = (hit.ng, hit.area);
        let [i0, i1, i2] = scene.triangles[t].map(|i| i as usize);
        let b0 = 1.0 - hit.b1 - hit.b2;
        let ns = if scene.normals.is_empty() {
            ng
        } else {
            (scene.normals[i0] * b0 + scene.normals[i1] * hit.b1 + scene.normals[i2] * hit.b2).try_normalize().unwrap_or(ng)
        };
        let ns = if ns.dot(ng) < 0.0 { -ns } else { ns };
        let p = o + d * hit.t;
        let uv = if scene.uvs.is_empty() { Vec2::ZERO } else { scene.uvs[i0] * b0 + scene.uvs[i1] * hit.b1 + scene.uvs[i2] * hit.b2 };
        Surface { p, ng, ns, object: scene.tri_object[t], tri: hit.tri, area, uv }
    }

    /// The material at this point: the object's, with its texture maps applied at `uv`.
    pub fn material(&self, scene: &Scene) -> Material {
        let o = &scene.objects[self.object as usize];
        if o.maps.is_empty() {
            o.material
        } else {
            o.maps.apply(o.material, self.uv)
        }
    }

    /// A ray origin just off the surface on the side `dir` leaves to. The offset is `eps`
    /// (the scene's size times `OFFSET_FRACTION`: docs/QUALITY.md, self-intersection epsilon
    /// scaled to scene size) plus the same fraction of the point's largest coordinate, since
    /// the spacing of floats grows with it (a small scene far from the origin). Both terms
    /// are lengths, so the offset scales with the scene: it was `eps × (1 + |p|)`, which grows
    /// with the square of the scene's size and, in a Cornell box a hundred units across or
    /// more, lifted shadow rays' origins far enough to lose a sixth of the light.
    pub fn spawn(&self, dir: Vec3, eps: f32) -> Vec3 {
        let side = if dir.dot(self.ng) >= 0.0 { 1.0 } else { -1.0 };
        self.p + self.ng * (side * (eps + OFFSET_FRACTION * self.p.abs().max_element()))
    }
}
