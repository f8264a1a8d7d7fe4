//! `Scene`: world-space triangles grouped into objects with materials, lights, an optional
//! environment and a camera. Conventions (Mitsuba 3's): right-handed, y up, linear RGB.

use super::material::Material;
use crate::math::sampling::Distribution2D;
use glam::{Vec2, Vec3};
use relume_core::{Hash, Hasher, PortValue};
use std::ops::Range;

/// Look-at pinhole camera; `fov_deg` is measured on the smaller image axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub origin: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub fov_deg: f32,
    pub width: usize,
    pub height: usize,
}

/// Delta lights. Area lights are objects with emission; the environment is separate.
#[derive(Clone, Debug, PartialEq)]
pub enum Light {
    /// Radiant intensity in W/sr per channel.
    Point { position: Vec3, intensity: Vec3 },
    /// Intensity along `direction`, full inside `cos_inner`, smoothly to 0 at `cos_outer`.
    Spot { position: Vec3, direction: Vec3, intensity: Vec3, cos_inner: f32, cos_outer: f32 },
    /// Light travelling along `direction` with `irradiance` on a surface facing it.
    Directional { direction: Vec3, irradiance: Vec3 },
}

/// A lat-long radiance map with its importance-sampling distribution.
/// Pixel (u, v) looks along (sin θ sin φ, cos θ, −sin θ cos φ), θ = π v, φ = 2π u.
#[derive(Clone, Debug)]
pub struct EnvMap {
    pub width: usize,
    pub height: usize,
    pub texels: Vec<Vec3>,
    pub distribution: Distribution2D,
}

#[derive(Clone, Debug)]
pub enum Environment {
    Constant(Vec3),
    Map(EnvMap),
}

/// One object: a contiguous range of triangles sharing a material.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub name: String,
    pub material: Material,
    /// Radiance emitted from the front face (counter-clockwise winding), zero if not a light.
    pub emission: Vec3,
    /// Its material may be edited at run time (the relighting pipelines' split).
    pub dynamic: bool,
    pub triangles: Range<u32>,
}

#[derive(Clone, Debug)]
pub struct Scene {
    pub objects: Vec<Object>,
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (same length as positions), or empty for flat shading
    /// (the geometric normal everywhere).
    pub normals: Vec<Vec3>,
    /// Per-vertex UVs, empty when the meshes have none.
    pub uvs: Vec<Vec2>,
    pub triangles: Vec<[u32; 3]>,
    /// Object index of each triangle.
    pub tri_object: Vec<u32>,
    pub lights: Vec<Light>,
    pub environment: Option<Environment>,
    pub camera: Camera,
}

impl Scene {
    /// Corner positions of triangle `t`.
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        self.triangles[t].map(|i| self.positions[i as usize])
    }

    /// Geometric normal (from the winding) and area of triangle `t`.
    pub fn normal_area(&self, t: usize) -> (Vec3, f32) {
        let [a, b, c] = self.corners(t);
        let cr = (b - a).cross(c - a);
        let len = cr.length();
        (if len > 0.0 { cr / len } else { Vec3::ZERO }, 0.5 * len)
    }

    /// Smallest and largest corner of the bounding box of all triangles.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
    }

    /// Length of the bounding-box diagonal (1 for an empty scene): sets ray epsilons.
    pub fn extent(&self) -> f32 {
        let (lo, hi) = self.bounds();
        let d = (hi - lo).length();
        if d.is_finite() && d > 0.0 {
            d
        } else {
            1.0
        }
    }

    /// Whether anything emits light.
    pub fn has_lights(&self) -> bool {
        !self.lights.is_empty() || self.objects.iter().any(|o| o.emission.max_element() > 0.0) || self.environment.is_some()
    }
}

fn hash_vec3s(h: &mut Hasher, v: &[Vec3]) {
    let floats: Vec<f32> = v.iter().flat_map(|p| p.to_array()).collect();
    h.f32s(&floats);
}

impl PortValue for Scene {
    const NAME: &'static str = "Scene";
    const COLOR: [u8; 3] = [96, 160, 230];
    const DOC: &'static str = "triangles, objects, materials, lights, environment, camera";

    fn fingerprint(&self) -> Hash {
        let mut h = Hasher::new();
        h.str(Self::NAME);
        hash_vec3s(&mut h, &self.positions);
        hash_vec3s(&mut h, &self.normals);
        let uv: Vec<f32> = self.uvs.iter().flat_map(|p| p.to_array()).collect();
        h.f32s(&uv);
        for t in &self.triangles {
            h.u64(t[0] as u64 | (t[1] as u64) << 21 | (t[2] as u64) << 42);
        }
        // Objects, lights, environment and camera are small: hash their debug text, which
        // prints every float exactly (shortest round-trip form).
        h.str(&format!("{:?}{:?}{:?}{:?}", self.objects, self.lights, self.tri_object.len(), self.camera));
        match &self.environment {
            None => h.tag(0),
            Some(Environment::Constant(c)) => h.tag(1).str(&format!("{c:?}")),
            Some(Environment::Map(m)) => {
                h.tag(2).u64(m.width as u64).u64(m.height as u64);
                hash_vec3s(&mut h, &m.texels);
                &mut h
            }
        };
        h.finish()
    }

    fn byte_size(&self) -> usize {
        let env = match &self.environment {
            Some(Environment::Map(m)) => m.texels.len() * 20,
            _ => 0,
        };
        self.positions.len() * 24 + self.uvs.len() * 8 + self.triangles.len() * 16 + env
    }
}
