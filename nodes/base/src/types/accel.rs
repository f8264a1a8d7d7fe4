//! `Accel`: a compressed-wide BVH (obvhs CwBvh) over a scene's triangles, with closest-hit
//! queries that return barycentrics and shadow queries that stop at the first hit
//! (`ray_traverse_miss`; obvhs' `ray_traverse_anyhit` visits every hit). Coordinates are
//! stored multiplied by a power of two that brings the scene's size near 1024: obvhs skips
//! boxes that end closer than 10⁻⁴ along a ray (whatever the scene's units), which lost the
//! floor under rays starting a hair above it and, in a scene 10⁻³ across, every hit within a
//! few voxels; a power of two scales every rounding exactly, so hits are bit for bit those of
//! the unscaled triangles. Directions reach
//! obvhs with −0 components made +0: its traversal takes a component's sign from `< 0` but
//! its inverse from the sign bit, so a ray straight down the y axis written as −n, (−0, −1,
//! −0), missed a floor it stood on.

use crate::types::Scene;
use glam::{Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use relume_core::{ParamEnum, PortValue};

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
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
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
    /// The power of two the stored coordinates are multiplied by (see the module doc).
    scale: f32,
}

/// The power of two that brings a scene of size `size` near 1024 (1 for no size).
fn scale_for(size: f32) -> f32 {
    if !(size.is_finite() && size > 0.0) {
        return 1.0;
    }
    2f32.powi((10 - size.log2().ceil() as i32).clamp(-60, 60))
}

impl Accel {
    pub fn build(scene: &Scene, quality: BuildQuality) -> Accel {
        Accel::build_filtered(scene, quality, |_| true)
    }

    /// A BVH over the scene triangles `keep` accepts; hits still name scene triangle indices.
    pub fn build_filtered(scene: &Scene, quality: BuildQuality, keep: impl Fn(usize) -> bool) -> Accel {
        let kept: Vec<u32> = (0..scene.triangles.len() as u32).filter(|&t| keep(t as usize)).collect();
        let size = kept.iter().flat_map(|&t| scene.corners(t as usize)).fold(0.0f32, |m, p| m.max(p.abs().max_element()));
        let scale = scale_for(size);
        let obv: Vec<Triangle> = kept
            .iter()
            .map(|&t| {
                let [a, b, c] = scene.corners(t as usize).map(|p| Vec3A::from(p * scale));
                Triangle { v0: a, v1: b, v2: c }
            })
            .collect();
        let params = match quality {
            BuildQuality::Fast => BvhBuildParams::fast_build(),
            BuildQuality::Medium => BvhBuildParams::medium_build(),
            BuildQuality::Slow => BvhBuildParams::slow_build(),
        };
        let bvh = build_cwbvh_from_tris(&obv, params, &mut std::time::Duration::default());
        let tris = bvh
            .primitive_indices
            .iter()
            .map(|&i| {
                let t = &obv[i as usize];
                Tri { v0: t.v0, e1: t.v1 - t.v0, e2: t.v2 - t.v0 }
            })
            .collect();
        let prim = bvh.primitive_indices.iter().map(|&i| kept[i as usize]).collect();
        Accel { bvh, tris, prim, scale }
    }

    /// The bounding box of its triangles (an inverted box when it has none).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds_within(Vec3::splat(f32::NEG_INFINITY), Vec3::splat(f32::INFINITY))
            .unwrap_or((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)))
    }

    /// The bounding box of the triangles whose own boxes meet `lo … hi`, clipped to it: where
    /// a ray inside that box may hit something (`None` when nothing is there).
    pub fn bounds_within(&self, lo: Vec3, hi: Vec3) -> Option<(Vec3, Vec3)> {
        let k = 1.0 / self.scale;
        let (a, b) = self.tris.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(a, b), t| {
            let (p, q, r) = (Vec3::from(t.v0) * k, Vec3::from(t.v0 + t.e1) * k, Vec3::from(t.v0 + t.e2) * k);
            let (tl, th) = (p.min(q).min(r), p.max(q).max(r));
            if tl.cmple(hi).all() && th.cmpge(lo).all() {
                (a.min(tl), b.max(th))
            } else {
                (a, b)
            }
        });
        let (a, b) = (a.max(lo), b.min(hi));
        a.cmple(b).all().then_some((a, b))
    }

    /// Closest hit along `o + t d` for t in (tmin, tmax).
    pub fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        let (o, d) = (Vec3A::from(o) * self.scale, Vec3A::from(d) + Vec3A::ZERO);
        let (tmin, tmax) = (tmin * self.scale, tmax * self.scale);
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
        (found && hit.t < tmax).then(|| Hit { t: hit.t / self.scale, tri: self.prim[hit.primitive_id as usize], b1: best.1, b2: best.2 })
    }

    /// Whether anything blocks `o + t d` for t in (tmin, tmax); stops at the first blocker.
    pub fn occluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        let (o, d) = (Vec3A::from(o) * self.scale, Vec3A::from(d) + Vec3A::ZERO);
        let ray = Ray::new(o, d, tmin * self.scale, tmax * self.scale);
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

/// Byte offsets of the 4-byte numbers inside a `CwBvhNode` (`p`, `child_base_idx`,
/// `primitive_base_idx`); the other bytes are `u8` fields.
const NODE_WORDS: [usize; 5] = [0, 4, 8, 16, 20];
const NODE_BYTES: usize = std::mem::size_of::<CwBvhNode>();
const _: () = assert!(NODE_BYTES == 80);

/// Appends little-endian bytes of plain values whose 4-byte numbers sit at `words`
/// (a copy on little-endian machines).
fn put_le<T: bytemuck::Pod>(out: &mut Vec<u8>, v: &[T], words: &[usize]) {
    let start = out.len();
    out.extend_from_slice(bytemuck::cast_slice(v));
    if cfg!(target_endian = "big") {
        for e in out[start..].chunks_exact_mut(std::mem::size_of::<T>()) {
            for &w in words {
                e[w..w + 4].reverse();
            }
        }
    }
}

/// Reads `n` values written by `put_le`; `None` when the bytes run out.
fn get_le<T: bytemuck::Pod>(r: &mut Reader<'_>, n: usize, words: &[usize]) -> Option<Vec<T>> {
    let size = std::mem::size_of::<T>();
    let b = r.take(n.checked_mul(size)?)?;
    let mut v = vec![T::zeroed(); n];
    let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut v);
    dst.copy_from_slice(b);
    if cfg!(target_endian = "big") {
        for e in dst.chunks_exact_mut(size) {
            for &w in words {
                e[w..w + 4].reverse();
            }
        }
    }
    Some(v)
}

const FLOATS6: [usize; 6] = [0, 4, 8, 12, 16, 20];
const FLOATS9: [usize; 9] = [0, 4, 8, 12, 16, 20, 24, 28, 32];

fn aabb_floats(a: &Aabb) -> [f32; 6] {
    let (lo, hi) = (a.min.to_array(), a.max.to_array());
    [lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]]
}

fn aabb_of(f: [f32; 6]) -> Aabb {
    Aabb { min: Vec3A::new(f[0], f[1], f[2]), max: Vec3A::new(f[3], f[4], f[5]) }
}

struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if n > self.0.len() {
            return None;
        }
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        Some(a)
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn count(&mut self) -> Option<usize> {
        usize::try_from(self.u64()?).ok()
    }
    fn byte(&mut self) -> Option<u8> {
        Some(self.take(1)?[0])
    }
}

impl Accel {
    /// Whether every child and primitive a node points to exists (what a decoded BVH must
    /// satisfy before traversal indexes with it).
    fn indices_in_range(&self) -> bool {
        let (nodes, prims) = (self.bvh.nodes.len() as u64, self.prim.len() as u64);
        self.bvh.nodes.iter().all(|n| {
            let inner_ok = n.child_base_idx as u64 + n.imask.count_ones() as u64 <= nodes;
            let leaves_ok = (0..8).filter(|&ch| n.imask & (1 << ch) == 0).all(|ch| {
                let meta = n.child_meta[ch];
                let first = n.primitive_base_idx as u64 + (meta & 0b11111) as u64;
                (0..3).filter(|i| meta & (0b1_00000 << i) != 0).all(|i| first + i < prims)
            });
            inner_ok && leaves_ok
        })
    }
}

/// Disk encoding, little-endian: the counts of nodes, primitives and exact node boxes
/// (u64; `u64::MAX` when there are none), whether the BVH uses spatial splits (one byte),
/// the total box (6 f32), the nodes (80 bytes each, obvhs' layout), the primitive indices
/// (u32), the prepared triangles in leaf order (9 f32 each) and the exact node boxes
/// (6 f32 each). Decoding checks the lengths and that every node's children and primitives
/// are in range.
impl PortValue for Accel {
    const NAME: &'static str = "Accel";
    const COLOR: [u8; 3] = [150, 120, 220];
    const DOC: &'static str = "ray-tracing acceleration structure (BVH) over a scene";
    fn byte_size(&self) -> usize {
        self.tris.len() * 52 + self.bvh.nodes.len() * 80
    }
    fn encode(&self) -> Vec<u8> {
        let b = &self.bvh;
        let exact = b.exact_node_aabbs.as_ref();
        let mut out = Vec::with_capacity(64 + b.nodes.len() * NODE_BYTES + self.prim.len() * 40 + exact.map_or(0, |e| e.len() * 24));
        for n in [b.nodes.len() as u64, self.prim.len() as u64, exact.map_or(u64::MAX, |e| e.len() as u64)] {
            out.extend_from_slice(&n.to_le_bytes());
        }
        out.push(b.uses_spatial_splits as u8);
        put_le(&mut out, &[self.scale], &[0]);
        put_le(&mut out, &[aabb_floats(&b.total_aabb)], &FLOATS6);
        put_le(&mut out, &b.nodes, &NODE_WORDS);
        put_le(&mut out, &self.prim, &[0]);
        let tris: Vec<[f32; 9]> = self
            .tris
            .iter()
            .map(|t| {
                let (a, b, c) = (t.v0.to_array(), t.e1.to_array(), t.e2.to_array());
                [a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]]
            })
            .collect();
        put_le(&mut out, &tris, &FLOATS9);
        if let Some(e) = exact {
            put_le(&mut out, &e.iter().map(aabb_floats).collect::<Vec<_>>(), &FLOATS6);
        }
        out
    }
    fn decode(bytes: &[u8]) -> Option<Self> {
        let mut r = Reader(bytes);
        let (n_nodes, n_prims, n_exact) = (r.count()?, r.count()?, r.u64()?);
        let uses_spatial_splits = match r.byte()? {
            0 => false,
            1 => true,
            _ => return None,
        };
        let scale = get_le::<f32>(&mut r, 1, &[0])?[0];
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        let total_aabb = aabb_of(get_le::<[f32; 6]>(&mut r, 1, &FLOATS6)?[0]);
        let nodes = get_le::<CwBvhNode>(&mut r, n_nodes, &NODE_WORDS)?;
        let prim = get_le::<u32>(&mut r, n_prims, &[0])?;
        let tris = get_le::<[f32; 9]>(&mut r, n_prims, &FLOATS9)?
            .into_iter()
            .map(|f| Tri { v0: Vec3A::new(f[0], f[1], f[2]), e1: Vec3A::new(f[3], f[4], f[5]), e2: Vec3A::new(f[6], f[7], f[8]) })
            .collect();
        let exact_node_aabbs = match n_exact {
            u64::MAX => None,
            n => Some(get_le::<[f32; 6]>(&mut r, usize::try_from(n).ok()?, &FLOATS6)?.into_iter().map(aabb_of).collect()),
        };
        if !r.0.is_empty() {
            return None;
        }
        let bvh = CwBvh { nodes, primitive_indices: prim.clone(), total_aabb, exact_node_aabbs, uses_spatial_splits };
        let accel = Accel { bvh, tris, prim, scale };
        accel.indices_in_range().then_some(accel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::test_scene;

    #[test]
    fn encodes_and_decodes_to_the_same_fingerprint_and_hits() {
        let scene = test_scene::spheres();
        let a = Accel::build(&scene, BuildQuality::Medium);
        let b = a.encode();
        assert_eq!(Accel::build(&scene, BuildQuality::Medium).encode(), b, "the build and the encoding are deterministic");
        let back = Accel::decode(&b).unwrap();
        assert_eq!(back.fingerprint(), a.fingerprint());
        assert_eq!(back.encode(), b);
        assert_eq!((back.node_count(), back.triangle_count()), (a.node_count(), a.triangle_count()));
        for i in 0..64u64 {
            let u = |d| crate::math::rng::uniform(9, i, d);
            let o = Vec3::new(u(0) * 4.0 - 2.0, u(1) * 4.0 - 2.0, 3.0);
            let d = Vec3::new(u(2) - 0.5, u(3) - 0.5, -1.0).normalize();
            assert_eq!(back.intersect(o, d, 0.0, f32::INFINITY), a.intersect(o, d, 0.0, f32::INFINITY), "ray {i}");
            assert_eq!(back.occluded(o, d, 0.0, 2.0), a.occluded(o, d, 0.0, 2.0), "ray {i}");
        }
        let mut moved = scene.clone();
        moved.positions[scene.triangles[0][0] as usize].x += 0.01;
        assert_ne!(Accel::build(&moved, BuildQuality::Medium).fingerprint(), a.fingerprint());
        for cut in [0, 1, 30, b.len() / 2, b.len() - 1] {
            assert!(Accel::decode(&b[..cut]).is_none(), "truncated to {cut} bytes");
        }
        assert!(Accel::decode(&[b.as_slice(), &[0]].concat()).is_none(), "trailing bytes");
    }

    #[test]
    fn out_of_range_node_indices_are_refused() {
        let scene = test_scene::spheres();
        let mut a = Accel::build(&scene, BuildQuality::Fast);
        assert!(a.bvh.nodes[0].imask != 0, "the root has inner children");
        a.bvh.nodes[0].child_base_idx = a.bvh.nodes.len() as u32;
        assert!(Accel::decode(&a.encode()).is_none(), "a child past the last node");
        let mut a = Accel::build(&scene, BuildQuality::Fast);
        let n = a.bvh.nodes.iter().position(|n| (0..8).any(|ch| n.imask & (1 << ch) == 0 && n.child_meta[ch] != 0)).unwrap();
        a.bvh.nodes[n].primitive_base_idx = a.prim.len() as u32;
        assert!(Accel::decode(&a.encode()).is_none(), "a primitive past the last one");
    }

    #[test]
    fn an_empty_scene_round_trips() {
        let mut scene = test_scene::spheres();
        (scene.objects, scene.positions, scene.normals, scene.triangles, scene.tri_object) = Default::default();
        let a = Accel::build(&scene, BuildQuality::Fast);
        let back = Accel::decode(&a.encode()).unwrap();
        assert_eq!(back.fingerprint(), a.fingerprint());
    }
}
