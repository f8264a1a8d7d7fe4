//! `Scene`: world-space triangles grouped into objects with materials, lights, an optional
//! environment and a camera. Conventions (Mitsuba 3's): right-handed, y up, linear RGB.

use super::material::Material;
use super::triangle_planes::{SceneDerived, TrianglePlanes};
use crate::math::sampling::Bilinear2D;
use glam::{Vec2, Vec3};
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::ops::Range;

/// Look-at pinhole camera; `fov_deg` is measured on the smaller image axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub origin: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub fov_deg: f32,
    pub width: usize,
    pub height: usize,
}

impl Camera {
    /// Whether the camera can render: finite vectors, origin ≠ target, `up` not along the view
    /// direction, 1 … 16384 pixels a side, a field of view strictly between 0° and 180°.
    pub fn is_consistent(&self) -> bool {
        let dir = self.target - self.origin;
        self.origin.is_finite()
            && self.target.is_finite()
            && self.up.is_finite()
            && dir.length_squared() > 0.0
            && dir.cross(self.up).length_squared() > 0.0
            && (1..=16384).contains(&self.width)
            && (1..=16384).contains(&self.height)
            && self.fov_deg > 0.0
            && self.fov_deg < 180.0
    }
}

/// A camera on its own port: a render that takes it as an input re-runs alone when only the
/// view changes (`OrbitCamera`). Decoding refuses a camera that could not render.
impl PortValue for Camera {
    const NAME: &'static str = "Camera";
    const COLOR: [u8; 3] = [235, 120, 120];
    const DOC: &'static str = "a look-at pinhole camera: origin, target, up, field of view, resolution";
    /// Bytes, and the resolution: the size of the images rendered from it.
    fn size(&self) -> relume_core::PortSize {
        relume_core::PortSize { bytes: self.byte_size() as u64, dims: Some([self.width, self.height]) }
    }
    fn byte_size(&self) -> usize {
        std::mem::size_of::<Camera>()
    }
    relume_core::serde_codec!(check Camera::is_consistent);
}

/// Delta lights. Area lights are objects with emission; the environment is separate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Light {
    /// Radiant intensity in W/sr per channel.
    Point { position: Vec3, intensity: Vec3 },
    /// Intensity along `direction`, full inside `cos_inner`, smoothly to 0 at `cos_outer`.
    Spot { position: Vec3, direction: Vec3, intensity: Vec3, cos_inner: f32, cos_outer: f32 },
    /// Light travelling along `direction` with `irradiance` on a surface facing it.
    Directional { direction: Vec3, irradiance: Vec3 },
}

/// A lat-long radiance map with its importance-sampling distribution, read as Mitsuba 3's
/// `envmap` reads it (scene/envmap.rs): (u, v) looks along (sin θ sin φ, cos θ, −sin θ cos φ),
/// θ = π v, φ = 2π u; texel (x, y) sits at u = (x + ½)/width, v = y/(height − 1), and lookups
/// interpolate bilinearly.
#[derive(Clone, Debug)]
pub struct EnvMap {
    pub width: usize,
    pub height: usize,
    pub texels: Vec<Vec3>,
    /// Luminance × sin θ on the texels, interpolated bilinearly (rebuilt from the texels on decoding).
    pub distribution: Bilinear2D,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub enum Environment {
    Constant(Vec3),
    Map(EnvMap),
}

/// One object: a contiguous range of triangles sharing a material.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Object {
    pub name: String,
    pub material: Material,
    /// Radiance emitted from the front face (counter-clockwise winding), zero if not a light.
    pub emission: Vec3,
    /// Its material may be edited at run time (the relighting pipelines' split).
    pub dynamic: bool,
    pub triangles: Range<u32>,
    /// The scene file's name of its material ("" for a material from an OBJ's MTL or built in
    /// code). Dynamic objects sharing a named material form one dynamic object (the thesis'
    /// "white walls": floor, ceiling and back edited together), see `Scene::dynamic_groups`.
    #[serde(default)]
    pub material_name: String,
    /// Texture maps multiplying its material's parameters at each point (`material_at`).
    #[serde(default)]
    pub maps: Box<super::MaterialMaps>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Scene {
    pub objects: Vec<Object>,
    #[serde(with = "pod_vec")]
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (same length as positions), or empty for flat shading
    /// (the geometric normal everywhere).
    #[serde(with = "pod_vec")]
    pub normals: Vec<Vec3>,
    /// Per-vertex UVs, empty when the meshes have none.
    #[serde(with = "pod_vec")]
    pub uvs: Vec<Vec2>,
    #[serde(with = "pod_vec")]
    pub triangles: Vec<[u32; 3]>,
    /// Object index of each triangle.
    #[serde(with = "pod_vec")]
    pub tri_object: Vec<u32>,
    pub lights: Vec<Light>,
    pub environment: Option<Environment>,
    pub camera: Camera,
    /// What is derived from the geometry on first use (`triangle_planes`); not serialised.
    #[serde(skip)]
    pub derived: SceneDerived,
}

impl Scene {
    /// Every triangle's plane, found on the first call and kept with the scene (16 bytes a
    /// triangle; a clone finds its own).
    pub fn triangle_planes(&self) -> &TrianglePlanes {
        self.derived.planes(&self.positions, &self.triangles)
    }

    /// The material of triangle `tri`'s object at the point of barycentric weights `b` (of its
    /// three corners): the object's texture maps applied at the interpolated UV, or its plain
    /// material where it has no maps or the scene no UVs.
    pub fn material_on(&self, tri: usize, b: [f32; 3]) -> Material {
        let o = &self.objects[self.tri_object[tri] as usize];
        if o.maps.is_empty() || self.uvs.is_empty() {
            return o.material;
        }
        o.maps.apply(o.material, self.uv_on(tri, b))
    }

    /// The diffuse texture map of triangle `tri`'s object at barycentric `b`: the factor it
    /// multiplies Kd with there (`None` without a map or without UVs).
    pub fn kd_map_on(&self, tri: usize, b: [f32; 3]) -> Option<Vec3> {
        let map = self.objects[self.tri_object[tri] as usize].maps.kd.as_ref()?;
        (!self.uvs.is_empty()).then(|| map.lookup(self.uv_on(tri, b)))
    }

    /// The UV of triangle `tri` at barycentric `b` (the scene must have UVs).
    fn uv_on(&self, tri: usize, b: [f32; 3]) -> Vec2 {
        self.triangles[tri].iter().zip(b).map(|(&i, w)| self.uvs[i as usize] * w).sum()
    }

    /// The dynamic objects as the relighting pipelines edit them: (name, scene object indices),
    /// in order of first appearance. Dynamic objects with the same named material form one
    /// group named after the material; others are a group of their own, named after the object.
    pub fn dynamic_groups(&self) -> Vec<(String, Vec<u32>)> {
        let mut groups: Vec<(String, Vec<u32>)> = Vec::new();
        for (i, o) in self.objects.iter().enumerate().filter(|(_, o)| o.dynamic) {
            let name = if o.material_name.is_empty() { &o.name } else { &o.material_name };
            match groups.iter_mut().find(|(n, _)| n == name) {
                Some((_, members)) => members.push(i as u32),
                None => groups.push((name.clone(), vec![i as u32])),
            }
        }
        groups
    }

    /// Radiance arriving from the environment along unit direction `d` (pointing away from
    /// the scene); zero without an environment.
    pub fn environment_radiance(&self, d: Vec3) -> Vec3 {
        match &self.environment {
            Some(Environment::Constant(c)) => *c,
            Some(Environment::Map(m)) => m.eval(d),
            None => Vec3::ZERO,
        }
    }

    /// `environment_radiance` of each of `dirs`, into `out` (cleared first), a map's
    /// through `EnvMap::eval_many_fast` (a polynomial atan2; the path tracer keeps the
    /// library's).
    pub fn environment_radiance_many_fast(&self, dirs: &[Vec3], out: &mut Vec<Vec3>) {
        match &self.environment {
            Some(Environment::Map(m)) => m.eval_many_fast(dirs, out),
            other => {
                let c = match other {
                    Some(Environment::Constant(c)) => *c,
                    _ => Vec3::ZERO,
                };
                out.clear();
                out.resize(dirs.len(), c);
            }
        }
    }

    /// Corner positions of triangle `t`.
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        self.triangles[t].map(|i| self.positions[i as usize])
    }

    /// Geometric normal (from the winding) and area of triangle `t`.
    pub fn normal_area(&self, t: usize) -> (Vec3, f32) {
        let [a, b, c] = self.corners(t);
        normal_area_of(b - a, c - a)
    }

    /// Smallest and largest corner of the bounding box of all triangles.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
    }

    /// Length of the bounding-box diagonal (1 for an empty scene): sets ray epsilons. It walks
    /// every vertex: compute it once per render, not per sample.
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

/// Geometric normal and area of the triangle with edges `e1` and `e2` from one corner.
pub fn normal_area_of(e1: Vec3, e2: Vec3) -> (Vec3, f32) {
    let cr = e1.cross(e2);
    let len = cr.length();
    (if len > 0.0 { cr / len } else { Vec3::ZERO }, 0.5 * len)
}

/// Encoded as width, height and texels; decoding rebuilds the sampling distribution (the
/// same bytes as at load time: `EnvMap::new` is deterministic) and refuses inconsistent maps.
impl Serialize for EnvMap {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        (self.width, self.height, pod_vec::Slice(&self.texels)).serialize(s)
    }
}

impl<'de> Deserialize<'de> for EnvMap {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        struct Data(usize, usize, #[serde(with = "pod_vec")] Vec<Vec3>);
        let Data(width, height, texels) = Data::deserialize(d)?;
        EnvMap::new(width, height, texels).map_err(serde::de::Error::custom)
    }
}

impl Scene {
    /// Whether every index points inside its array (what a decoded scene must satisfy before
    /// anything indexes with it).
    fn is_consistent(&self) -> bool {
        let (nv, nt) = (self.positions.len(), self.triangles.len());
        (self.normals.is_empty() || self.normals.len() == nv)
            && (self.uvs.is_empty() || self.uvs.len() == nv)
            && self.triangles.iter().all(|t| t.iter().all(|&i| (i as usize) < nv))
            && self.tri_object.len() == nt
            && self.tri_object.iter().all(|&o| (o as usize) < self.objects.len())
            && self.objects.iter().all(|o| o.triangles.start <= o.triangles.end && o.triangles.end as usize <= nt)
    }
}

/// Disk encoding: serde through postcard, the big arrays (positions, normals, UVs, triangles,
/// triangle objects, environment texels) as little-endian byte strings; decoding checks that
/// every index is in range.
impl PortValue for Scene {
    const NAME: &'static str = "Scene";
    const COLOR: [u8; 3] = [96, 160, 230];
    const DOC: &'static str = "triangles, objects, materials, lights, environment, camera";
    /// Bytes, and the camera's resolution: the size of the images rendered from it.
    fn size(&self) -> relume_core::PortSize {
        relume_core::PortSize { bytes: self.byte_size() as u64, dims: Some([self.camera.width, self.camera.height]) }
    }

    relume_core::serde_codec!(check Scene::is_consistent);

    fn byte_size(&self) -> usize {
        let env = match &self.environment {
            Some(Environment::Map(m)) => m.texels.len() * 22,
            _ => 0,
        };
        let maps: usize = self.objects.iter().map(|o| o.maps.byte_size()).sum();
        self.positions.len() * 24 + self.uvs.len() * 8 + self.triangles.len() * 16 + env + maps
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::test_scene;

    fn with_env_map() -> Scene {
        let mut s = test_scene::spheres();
        let texels = (0..8 * 4).map(|i| Vec3::new(i as f32, 1.0, 0.5)).collect();
        s.environment = Some(Environment::Map(EnvMap::new(8, 4, texels).unwrap()));
        s.uvs = vec![Vec2::new(0.25, 0.5); s.positions.len()];
        s
    }

    #[test]
    fn encodes_and_decodes_to_the_same_fingerprint() {
        for s in [test_scene::spheres(), with_env_map()] {
            let b = s.encode();
            let back = Scene::decode(&b).unwrap();
            assert_eq!(back.fingerprint(), s.fingerprint());
            assert_eq!(back.encode(), b, "deterministic");
            assert_eq!((back.positions, back.triangles, back.objects), (s.positions, s.triangles, s.objects));
            assert!(Scene::decode(&b[..b.len() - 1]).is_none(), "truncated");
            assert!(Scene::decode(&b[..b.len() / 2]).is_none(), "truncated");
            assert!(Scene::decode(&[b.as_slice(), &[0]].concat()).is_none(), "trailing bytes");
        }
        let Some(Environment::Map(m)) = Scene::decode(&with_env_map().encode()).unwrap().environment else { panic!("a map") };
        assert_eq!(m.distribution, with_env_map_distribution(), "the distribution is rebuilt");
    }

    fn with_env_map_distribution() -> Bilinear2D {
        match with_env_map().environment {
            Some(Environment::Map(m)) => m.distribution,
            _ => unreachable!(),
        }
    }

    #[test]
    fn the_fingerprint_sees_every_part() {
        let s = test_scene::spheres();
        let mut t = s.clone();
        t.tri_object[0] = 1;
        assert_ne!(t.fingerprint(), s.fingerprint(), "triangle objects, not only their count");
        let mut t = s.clone();
        t.camera.fov_deg = 41.0;
        assert_ne!(t.fingerprint(), s.fingerprint());
        let mut t = s.clone();
        t.objects[0].dynamic = true;
        assert_ne!(t.fingerprint(), s.fingerprint());
    }

    #[test]
    fn indices_out_of_range_are_refused() {
        let mut s = test_scene::spheres();
        s.triangles[0][1] = s.positions.len() as u32;
        assert!(Scene::decode(&s.encode()).is_none());
        let mut s = test_scene::spheres();
        s.tri_object.pop();
        assert!(Scene::decode(&s.encode()).is_none());
    }
}
