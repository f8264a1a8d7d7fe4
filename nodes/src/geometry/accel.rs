//! `Accel`: a compressed-wide BVH (obvhs CwBvh) over a scene's triangles, with closest-hit
//! queries that return barycentrics and shadow queries that stop at the first hit
//! (`ray_traverse_miss`; obvhs' `ray_traverse_anyhit` visits every hit).

use crate::types::Scene;
use glam::{Vec3, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use relume_core::{Hash, Hasher, PortValue};

/// A triangle prepared for Möller–Trumbore: corner and two edges.
#[derive(Clone, Copy, Debug)]
struct Tri {
    v0: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
}

impl Tri {
    /// (t, b1, b2) of the hit within (tmin, tmax), if any.
    #[inline(always)]
    fn intersect(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let p = d.cross(self.e2);
        let det = self.e1.dot(p);
        if det.abs() < 1e-30 {
            return None;
        }
        let inv = 1.0 / det;
        let s = o - self.v0;
        let u = s.dot(p) * inv;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let q = s.cross(self.e1);
        let v = d.dot(q) * inv;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = self.e2.dot(q) * inv;
        (t > tmin && t < tmax).then_some((t, u, v))
    }
}

/// A closest hit: distance, scene triangle index, barycentrics of corners 1 and 2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub tri: u32,
    pub b1: f32,
    pub b2: f32,
}

/// Build quality (obvhs presets).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildQuality {
    Fast,
    Medium,
    Slow,
}

pub struct Accel {
    bvh: CwBvh,
    /// Triangles in BVH leaf order.
    tris: Vec<Tri>,
    /// BVH leaf order → scene triangle index.
    prim: Vec<u32>,
    fingerprint: Hash,
}

impl Accel {
    pub fn build(scene: &Scene, quality: BuildQuality) -> Accel {
        let obv: Vec<Triangle> = (0..scene.triangles.len())
            .map(|t| {
                let [a, b, c] = scene.corners(t);
                Triangle { v0: a.into(), v1: b.into(), v2: c.into() }
            })
            .collect();
        let params = match quality {
            BuildQuality::Fast => BvhBuildParams::fast_build(),
            BuildQuality::Medium => BvhBuildParams::medium_build(),
            BuildQuality::Slow => BvhBuildParams::slow_build(),
        };
        let bvh = build_cwbvh_from_tris(&obv, params, &mut std::time::Duration::default());
        let prim = bvh.primitive_indices.clone();
        let tris = prim
            .iter()
            .map(|&i| {
                let t = &obv[i as usize];
                Tri { v0: t.v0, e1: t.v1 - t.v0, e2: t.v2 - t.v0 }
            })
            .collect();
        let fingerprint = Hasher::new().str("Accel").hash(&scene.fingerprint()).str(&format!("{quality:?}")).finish();
        Accel { bvh, tris, prim, fingerprint }
    }

    /// Closest hit along `o + t d` for t in (tmin, tmax).
    pub fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        let (o, d) = (Vec3A::from(o), Vec3A::from(d));
        let ray = Ray::new(o, d, tmin, tmax);
        let mut hit = RayHit::none();
        let mut best = (f32::INFINITY, 0.0, 0.0);
        let found = self.bvh.ray_traverse(ray, &mut hit, |r, id| match self.tris[id].intersect(o, d, r.tmin, r.tmax) {
            Some((t, u, v)) => {
                best = (t, u, v);
                t
            }
            None => f32::INFINITY,
        });
        (found && hit.t < tmax).then(|| Hit { t: hit.t, tri: self.prim[hit.primitive_id as usize], b1: best.1, b2: best.2 })
    }

    /// Whether anything blocks `o + t d` for t in (tmin, tmax); stops at the first blocker.
    pub fn occluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        let (o, d) = (Vec3A::from(o), Vec3A::from(d));
        let ray = Ray::new(o, d, tmin, tmax);
        !self.bvh.ray_traverse_miss(ray, |r, id| self.tris[id].intersect(o, d, r.tmin, r.tmax).map_or(f32::INFINITY, |h| h.0))
    }

    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    pub fn node_count(&self) -> usize {
        self.bvh.nodes.len()
    }
}

/// Brute-force intersection of one triangle (for tests).
#[cfg(test)]
pub(crate) fn brute(a: Vec3, b: Vec3, c: Vec3, o: Vec3, d: Vec3) -> Option<f32> {
    Tri { v0: a.into(), e1: (b - a).into(), e2: (c - a).into() }.intersect(o.into(), d.into(), 0.0, f32::INFINITY).map(|h| h.0)
}

impl PortValue for Accel {
    const NAME: &'static str = "Accel";
    const COLOR: [u8; 3] = [150, 120, 220];
    const DOC: &'static str = "ray-tracing acceleration structure (BVH) over a scene";
    fn fingerprint(&self) -> Hash {
        self.fingerprint
    }
    fn byte_size(&self) -> usize {
        self.tris.len() * 52 + self.bvh.nodes.len() * 80
    }
}
