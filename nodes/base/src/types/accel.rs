//! `Accel`: an eight-wide BVH (`bvh8`) over a scene's triangles, built by collapsing obvhs'
//! binary PLOC build, with closest-hit queries that return barycentrics and shadow queries
//! that stop at the first hit. Coordinates are stored multiplied by a power of two that brings
//! the scene's size near 1024, so that a scene 10⁻³ or 10³ across is traversed in the same
//! range of floats as one of unit size; a power of two scales every rounding exactly, so hits
//! are bit for bit those of the unscaled triangles.

mod bvh8;

use crate::types::Scene;
use bvh8::{Bvh8, Node, Tri, Tri4};
use glam::{Vec3, Vec3A};
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use relume_core::{ParamEnum, PortValue};

/// A closest hit: distance, scene triangle index, barycentrics of corners 1 and 2, and the
/// triangle's geometric normal and area (bit for bit `Scene::normal_area`, read from the
/// packet the hit was found in rather than from the scene's scattered vertices).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub tri: u32,
    pub b1: f32,
    pub b2: f32,
    pub ng: Vec3,
    pub area: f32,
}

/// Build quality (obvhs presets).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum BuildQuality {
    Fast,
    Medium,
    Slow,
}

pub struct Accel {
    bvh: Bvh8,
    /// Packet lane → scene triangle index (`u32::MAX` for an empty lane).
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
    /// The most triangles one BVH holds (leaf references keep 27 bits for the first one;
    /// spatial splits may place a triangle in several leaves, so `Slow` holds fewer).
    pub const MAX_TRIANGLES: usize = bvh8::MAX_TRIS / 2;

    /// Panics over `MAX_TRIANGLES` triangles (`BuildBvh` refuses them first).
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
        let b2 = if obv.is_empty() { Default::default() } else { build_bvh2_from_tris(&obv, params, &mut std::time::Duration::default()) };
        let (bvh, lanes) = Bvh8::collapse(&b2, |i| {
            let t = &obv[i];
            Tri { v0: t.v0, e1: t.v1 - t.v0, e2: t.v2 - t.v0 }
        })
        .unwrap_or_else(|e| panic!("{e}"));
        let prim = lanes.iter().map(|&i| if i == u32::MAX { i } else { kept[i as usize] }).collect();
        Accel { bvh, prim, scale }
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
        let (a, b) = self.lane_tris().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(a, b), t| {
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
        let (o, d) = (Vec3A::from(o) * self.scale, Vec3A::from(d));
        let (t, i, b1, b2) = self.bvh.intersect(o, d, tmin * self.scale, tmax * self.scale)?;
        // Unscaling by a power of two is exact: these are the scene's edges b − a and c − a.
        let p = &self.bvh.packets[i / 4].c;
        let edge = |k: usize| Vec3::new(p[k][i % 4], p[k + 1][i % 4], p[k + 2][i % 4]) / self.scale;
        let (ng, area) = crate::types::scene::normal_area_of(edge(3), edge(6));
        Some(Hit { t: t / self.scale, tri: self.prim[i], b1, b2, ng, area })
    }

    /// Whether anything blocks `o + t d` for t in (tmin, tmax); stops at the first blocker.
    pub fn occluded(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> bool {
        let (o, d) = (Vec3A::from(o) * self.scale, Vec3A::from(d));
        self.bvh.occluded(o, d, tmin * self.scale, tmax * self.scale)
    }

    /// The triangles its leaves hold (a triangle spatial splits place in several leaves counts
    /// once per leaf).
    pub fn triangle_count(&self) -> usize {
        self.prim.iter().filter(|&&p| p != u32::MAX).count()
    }

    /// The triangles its packet lanes hold, in the stored (scaled) coordinates.
    fn lane_tris(&self) -> impl Iterator<Item = Tri> + '_ {
        self.bvh.packets.iter().flat_map(|p| (0..4).map(move |lane| (p, lane))).zip(&self.prim).filter(|(_, &s)| s != u32::MAX).map(
            |((p, lane), _)| {
                let v = |k: usize| Vec3A::new(p.c[k][lane], p.c[k + 1][lane], p.c[k + 2][lane]);
                Tri { v0: v(0), e1: v(3), e2: v(6) }
            },
        )
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

const NODE_BYTES: usize = std::mem::size_of::<Node>();
const PACKET_BYTES: usize = std::mem::size_of::<Tri4>();
const _: () = assert!(NODE_BYTES == 224 && PACKET_BYTES == 144);
/// Byte offsets of the 4-byte numbers inside a `Node` or a `Tri4`: all of them.
const NODE_WORDS: [usize; NODE_BYTES / 4] = words();
const PACKET_WORDS: [usize; PACKET_BYTES / 4] = words();

const fn words<const N: usize>() -> [usize; N] {
    let mut w = [0; N];
    let mut i = 0;
    while i < N {
        w[i] = 4 * i;
        i += 1;
    }
    w
}

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
}

/// Disk encoding, little-endian: the counts of nodes and of triangle packets (u64), the
/// coordinate scale (f32), the nodes (224 bytes each: 48 f32 of boxes, 8 u32 of children),
/// the packets (36 f32 each: corner and edges over four lanes) and the scene triangle index of
/// each packet lane (u32; `u32::MAX` for an empty lane). Decoding checks the lengths, that
/// every inner child follows its parent and that every leaf lies within the packets.
impl PortValue for Accel {
    const NAME: &'static str = "Accel";
    const COLOR: [u8; 3] = [150, 120, 220];
    const DOC: &'static str = "ray-tracing acceleration structure (BVH) over a scene";
    fn byte_size(&self) -> usize {
        self.bvh.packets.len() * (PACKET_BYTES + 32) + self.bvh.nodes.len() * NODE_BYTES
    }
    fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(20 + self.bvh.nodes.len() * NODE_BYTES + self.bvh.packets.len() * (PACKET_BYTES + 16));
        for n in [self.bvh.nodes.len() as u64, self.bvh.packets.len() as u64] {
            out.extend_from_slice(&n.to_le_bytes());
        }
        put_le(&mut out, &[self.scale], &[0]);
        put_le(&mut out, &self.bvh.nodes, &NODE_WORDS);
        put_le(&mut out, &self.bvh.packets, &PACKET_WORDS);
        put_le(&mut out, &self.prim, &[0]);
        out
    }
    fn decode(bytes: &[u8]) -> Option<Self> {
        let mut r = Reader(bytes);
        let (n_nodes, n_packets) = (r.count()?, r.count()?);
        let scale = get_le::<f32>(&mut r, 1, &[0])?[0];
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        let nodes = get_le::<Node>(&mut r, n_nodes, &NODE_WORDS)?;
        let packets = get_le::<Tri4>(&mut r, n_packets, &PACKET_WORDS)?;
        let prim = get_le::<u32>(&mut r, n_packets.checked_mul(4)?, &[0])?;
        if !r.0.is_empty() {
            return None;
        }
        if prim.len() != 4 * packets.len() {
            return None;
        }
        let bvh = Bvh8::from_parts(nodes, packets)?;
        Some(Accel { bvh, prim, scale })
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
    fn out_of_range_or_looping_children_are_refused() {
        let scene = test_scene::spheres();
        let a = Accel::build(&scene, BuildQuality::Fast);
        let (node, lane) = (0..a.node_count())
            .flat_map(|n| (0..bvh8::WIDTH).map(move |l| (n, l)))
            .find(|&(n, l)| a.bvh.nodes[n].child[l] & (1 << 31) == 0)
            .unwrap();
        let with = |child: u32| {
            let mut b = Accel::decode(&a.encode()).unwrap();
            b.bvh.nodes[node].child[lane] = child;
            Accel::decode(&b.encode())
        };
        assert!(with(a.node_count() as u32).is_none(), "a child past the last node");
        assert!(with(node as u32).is_none(), "a node its own child");
        let packets = a.bvh.packets.len() as u32;
        assert!(with((1 << 31) | (2 << 27) | (packets - 2)).is_none(), "a leaf past the last packet");
        assert!(with((1 << 31) | (1 << 27) | (packets - 2)).is_some(), "the last two packets as a leaf");
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
