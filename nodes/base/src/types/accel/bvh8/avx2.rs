//! The walk of a `Bvh8` compiled for AVX2, for CPUs that have it: the ray is broadcast into
//! eight-lane registers once, a node's eight slab tests take one register, and a leaf's packets
//! are tested two at a time (an odd last packet beside an empty one). Every operation is the
//! portable walk's, lane by lane and in the same order, so it visits the same leaves in the
//! same order and returns the same bits.

use super::{descend, leaf_range, lowest, pop, Bvh8, Node, Slabs, Tri4, FAR_WIDEN, LEAF, WIDTH};
use glam::Vec3A;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// An all-zero packet: its determinants are zero, so no ray hits it.
static NO_PACKET: Tri4 = Tri4 { c: [[0.0; 4]; 9] };

/// A ray broadcast over eight lanes: origin, direction and inverse direction, which stored
/// bound each axis enters by, and the start of its interval.
struct Ray8 {
    o: [__m256; 3],
    d: [__m256; 3],
    inv: [__m256; 3],
    near: [usize; 3],
    tmin: f32,
}

#[target_feature(enable = "avx2")]
fn broadcast(v: [f32; 3]) -> [__m256; 3] {
    v.map(|x| _mm256_set1_ps(x))
}

impl Ray8 {
    #[target_feature(enable = "avx2")]
    fn new(o: Vec3A, d: Vec3A, tmin: f32) -> Ray8 {
        let slabs = Slabs::new(o, d);
        Ray8 { o: broadcast(slabs.o), d: broadcast(d.to_array()), inv: broadcast(slabs.inv), near: slabs.near, tmin }
    }
}

/// Entry distances of a node's children and the mask of those the ray meets within
/// (tmin, tmax), operation for operation as `Slabs::enter_halves`.
#[target_feature(enable = "avx2")]
#[inline]
fn enter(node: &Node, o: &[__m256; 3], inv: &[__m256; 3], near_bound: [usize; 3], tmin: f32, tmax: f32) -> ([f32; WIDTH], u32) {
    const _: () = assert!(WIDTH == 8);
    let (mut near, mut far) = (_mm256_set1_ps(tmin), _mm256_set1_ps(tmax));
    for a in 0..3 {
        // SAFETY: each bounds row is eight floats; unaligned loads.
        let (lo, hi) =
            unsafe { (_mm256_loadu_ps(node.bounds[near_bound[a]].as_ptr()), _mm256_loadu_ps(node.bounds[near_bound[a] ^ 1].as_ptr())) };
        near = _mm256_max_ps(_mm256_mul_ps(_mm256_sub_ps(lo, o[a]), inv[a]), near);
        far = _mm256_min_ps(_mm256_mul_ps(_mm256_sub_ps(hi, o[a]), inv[a]), far);
    }
    let hit = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(near, _mm256_mul_ps(far, _mm256_set1_ps(FAR_WIDEN))));
    let mut out = [0.0; WIDTH];
    // SAFETY: `out` holds eight floats.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), near) };
    (out, hit as u32)
}

#[target_feature(enable = "avx2")]
#[inline]
fn cross(a: &[__m256; 3], b: &[__m256; 3]) -> [__m256; 3] {
    [
        _mm256_sub_ps(_mm256_mul_ps(a[1], b[2]), _mm256_mul_ps(a[2], b[1])),
        _mm256_sub_ps(_mm256_mul_ps(a[2], b[0]), _mm256_mul_ps(a[0], b[2])),
        _mm256_sub_ps(_mm256_mul_ps(a[0], b[1]), _mm256_mul_ps(a[1], b[0])),
    ]
}

#[target_feature(enable = "avx2")]
#[inline]
fn dot(a: &[__m256; 3], b: &[__m256; 3]) -> __m256 {
    _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(a[0], b[0]), _mm256_mul_ps(a[1], b[1])), _mm256_mul_ps(a[2], b[2]))
}

/// `Tri4::solve` for two packets at once (`a` in lanes 0–3, `b` in lanes 4–7), operation for
/// operation, so every lane gets the same bits: the mask of lanes hit within (tmin, tmax),
/// with t, b1 and b2 of every lane.
#[target_feature(enable = "avx2")]
#[inline]
fn solve(a: &Tri4, b: &Tri4, o: &[__m256; 3], d: &[__m256; 3], tmin: f32, tmax: f32) -> (u32, [f32; 8], [f32; 8], [f32; 8]) {
    // SAFETY: each row of a packet is four floats; unaligned loads.
    let c: [__m256; 9] = std::array::from_fn(|k| unsafe { _mm256_loadu2_m128(b.c[k].as_ptr(), a.c[k].as_ptr()) });
    let (v0, e1, e2) = ([c[0], c[1], c[2]], [c[3], c[4], c[5]], [c[6], c[7], c[8]]);
    let p = cross(d, &e2);
    let det = dot(&e1, &p);
    let inv = _mm256_div_ps(_mm256_set1_ps(1.0), det);
    let s = [_mm256_sub_ps(o[0], v0[0]), _mm256_sub_ps(o[1], v0[1]), _mm256_sub_ps(o[2], v0[2])];
    let u = _mm256_mul_ps(dot(&s, &p), inv);
    let q = cross(&s, &e1);
    let v = _mm256_mul_ps(dot(d, &q), inv);
    let t = _mm256_mul_ps(dot(&e2, &q), inv);
    let abs = _mm256_and_ps(det, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff)));
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    let ok = [
        _mm256_cmp_ps::<_CMP_GE_OQ>(abs, _mm256_set1_ps(1e-30)),
        _mm256_cmp_ps::<_CMP_GE_OQ>(u, zero),
        _mm256_cmp_ps::<_CMP_LE_OQ>(u, one),
        _mm256_cmp_ps::<_CMP_GE_OQ>(v, zero),
        _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_add_ps(u, v), one),
        _mm256_cmp_ps::<_CMP_GT_OQ>(t, _mm256_set1_ps(tmin)),
        _mm256_cmp_ps::<_CMP_LT_OQ>(t, _mm256_set1_ps(tmax)),
    ]
    .into_iter()
    .fold(_mm256_castsi256_ps(_mm256_set1_epi32(-1)), |m, c| _mm256_and_ps(m, c));
    let mask = _mm256_movemask_ps(ok) as u32;
    let (mut tt, mut uu, mut vv) = ([0.0; 8], [0.0; 8], [0.0; 8]);
    if mask != 0 {
        // SAFETY: each array holds eight floats.
        unsafe {
            _mm256_storeu_ps(tt.as_mut_ptr(), t);
            _mm256_storeu_ps(uu.as_mut_ptr(), u);
            _mm256_storeu_ps(vv.as_mut_ptr(), v);
        }
    }
    (mask, tt, uu, vv)
}

impl Slabs {
    /// `enter_halves` in one AVX register of eight lanes, with the same bits (tests compare).
    #[cfg(test)]
    #[target_feature(enable = "avx2")]
    pub(super) fn enter_avx2(&self, node: &Node, tmin: f32, tmax: f32) -> ([f32; WIDTH], u32) {
        enter(node, &broadcast(self.o), &broadcast(self.inv), self.near, tmin, tmax)
    }
}

impl Tri4 {
    /// `solve` for two packets at once (`a` in lanes 0–3, `b` in lanes 4–7), with the same bits
    /// (tests compare).
    #[cfg(test)]
    #[target_feature(enable = "avx2")]
    pub(super) fn solve_pair(a: &Tri4, b: &Tri4, o: [f32; 3], d: [f32; 3], tmin: f32, tmax: f32) -> (u32, [f32; 8], [f32; 8], [f32; 8]) {
        solve(a, b, &broadcast(o), &broadcast(d), tmin, tmax)
    }
}

impl Bvh8 {
    /// The walk of `Bvh8::walk` with AVX2, its leaf tests included: with `CLOSEST`, the
    /// closest hit (t, packet lane, b1, b2); otherwise `Some` at the first blocker found.
    #[target_feature(enable = "avx2")]
    pub(super) fn walk_avx2<const CLOSEST: bool>(
        &self,
        o: Vec3A,
        d: Vec3A,
        tmin: f32,
        tmax: f32,
        stack: &mut [MaybeUninit<(u32, f32)>],
    ) -> Option<(f32, usize, f32, f32)> {
        let ray = Ray8::new(o, d, tmin);
        let (mut sp, mut cur, mut tmax) = (0, 0u32, tmax);
        let mut best = None;
        loop {
            if cur & LEAF != 0 {
                let (first, count) = leaf_range(cur);
                for k in (first..first + count).step_by(2) {
                    let b = if k + 1 < first + count { &self.packets[k + 1] } else { &NO_PACKET };
                    let (mask, t, u, v) = solve(&self.packets[k], b, &ray.o, &ray.d, ray.tmin, tmax);
                    if mask == 0 {
                        continue;
                    }
                    if !CLOSEST {
                        return Some((t[0], 0, 0.0, 0.0));
                    }
                    if let Some((lane, t, u, v)) = lowest(mask, &t, &u, &v) {
                        tmax = t;
                        best = Some((t, 4 * k + lane, u, v));
                    }
                }
            } else {
                let node = &self.nodes[cur as usize];
                let (near, mask) = enter(node, &ray.o, &ray.inv, ray.near, ray.tmin, tmax);
                if mask != 0 {
                    cur = descend::<CLOSEST>(node, &near, mask, stack, &mut sp);
                    continue;
                }
            }
            match pop(stack, &mut sp, tmax) {
                Some(c) => cur = c,
                None => return best,
            }
        }
    }
}
