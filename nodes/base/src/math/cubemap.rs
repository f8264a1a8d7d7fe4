//! Cube maps: 6 faces of N × N texels over the sphere of directions (pipeline 2's lighting and
//! visibility, [S] chapter 5: 6 × 64 × 64; wavelet PBGI's radiance, 6 × 32 × 32).
//!
//! Faces in the order +X, −X, +Y, −Y, +Z, −Z; on each, the direction is the face axis plus u
//! and v ∈ [−1, 1] along two other axes (the OpenGL layout), texel (i, j) covering
//! u ∈ [−1 + 2i/N, −1 + 2(i+1)/N] and v likewise with j, stored face after face, row (j) after
//! row. Texels near the corners see less of the sphere: each carries its exact solid angle
//! (the integral of dω = du dv / (1 + u² + v²)^{3/2} over its square, a closed form), so sums
//! over texels are integrals over the sphere.

use glam::{Vec2, Vec3};
use std::borrow::Cow;
use std::f64::consts::PI;
use std::sync::OnceLock;
use std::sync::{Arc, Mutex};

/// The solid angle of the rectangle [x0, x1] × [y0, y1] on the plane at distance 1 from the
/// eye, seen from the eye (exact; also the texels of a light's shadow map).
pub fn rect_solid_angle(x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
    let f = |x: f64, y: f64| (x * y / (1.0 + x * x + y * y).sqrt()).atan();
    f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0)
}

/// Every texel's centre direction of a side-`n` map (`CubeMap::direction` for k = 0 …
/// 6n² − 1, the same bits), for loops over all texels of many maps: power-of-two sides up to
/// 1024 are computed once per process and kept, other sides each call.
pub fn texel_directions(n: usize) -> Cow<'static, [Vec3]> {
    static KEPT: [OnceLock<Vec<Vec3>>; 11] = [const { OnceLock::new() }; 11];
    per_texel(&KEPT, n, |map, k| map.direction(k))
}

/// Every texel's solid angle of a side-`n` map (`CubeMap::solid_angle`), kept the same way.
pub fn texel_solid_angles(n: usize) -> Cow<'static, [f32]> {
    static KEPT: [OnceLock<Vec<f32>>; 11] = [const { OnceLock::new() }; 11];
    per_texel(&KEPT, n, |map, k| map.solid_angle(k))
}

/// `f` over every texel of a side-`n` map, kept in `kept` (by log₂ n) for power-of-two sides.
fn per_texel<T: Clone>(kept: &'static [OnceLock<Vec<T>>; 11], n: usize, f: impl Fn(&CubeMap, usize) -> T) -> Cow<'static, [T]> {
    let all = || {
        let map = CubeMap { n, texels: Vec::new() };
        (0..6 * n * n).map(|k| f(&map, k)).collect::<Vec<T>>()
    };
    if n.is_power_of_two() && n <= 1024 {
        Cow::Borrowed(kept[n.trailing_zeros() as usize].get_or_init(all).as_slice())
    } else {
        Cow::Owned(all())
    }
}

/// The direction (not unit) of point (u, v) ∈ [−1, 1]² on `face`.
pub fn face_point(face: usize, u: f32, v: f32) -> Vec3 {
    match face {
        0 => Vec3::new(1.0, -v, -u),
        1 => Vec3::new(-1.0, -v, u),
        2 => Vec3::new(u, 1.0, v),
        3 => Vec3::new(u, -1.0, -v),
        4 => Vec3::new(u, -v, 1.0),
        _ => Vec3::new(-u, -v, -1.0),
    }
}

/// The face holding direction `d` and its (u, v) there (the inverse of `face_point`; the
/// largest component picks the face, ties toward x, then y; not finite or zero: face 0's
/// centre).
pub fn locate(d: Vec3) -> (usize, f32, f32) {
    let a = d.abs();
    if !(d.is_finite() && a.max_element() > 0.0) {
        return (0, 0.0, 0.0);
    }
    if a.x >= a.y && a.x >= a.z {
        let (u, v) = (-d.z / a.x, -d.y / a.x);
        if d.x > 0.0 {
            (0, u, v)
        } else {
            (1, -u, v)
        }
    } else if a.y >= a.z {
        if d.y > 0.0 {
            (2, d.x / a.y, d.z / a.y)
        } else {
            (3, d.x / a.y, -d.z / a.y)
        }
    } else if d.z > 0.0 {
        (4, d.x / a.z, -d.y / a.z)
    } else {
        (5, -d.x / a.z, -d.y / a.z)
    }
}

/// The solid angles of the n² texels of one face of a cube map of side `n`, row after row
/// (the same on every face; four arc tangents each, in parallel).
pub fn face_solid_angles(n: usize) -> Vec<f64> {
    use rayon::prelude::*;
    let e = |t: usize| -1.0 + 2.0 * t as f64 / n as f64;
    (0..n * n).into_par_iter().map(|k| rect_solid_angle(e(k % n), e(k % n + 1), e(k / n), e(k / n + 1))).collect()
}

/// The sub-texels of a side-`n` map split `s` × `s` a texel (side m = n s): each centre's
/// lat-long coordinates (`latlong::dir_to_uv`), face after face, sub-row after sub-row, and the
/// solid angles of one face's sub-texels (the same on every face).
struct SubTexels {
    uv: Vec<Vec2>,
    dws: Vec<f64>,
}

/// Pairs (n, s) whose sub-texels are kept (8.3 MiB each at 64 × 6).
const SUB_TEXELS_KEPT: usize = 4;

/// The most bytes of sub-texels kept for one pair; larger ones are made for the call alone.
const SUB_TEXELS_KEEP_BYTES: usize = 64 << 20;

/// Bytes of the sub-texels of a side-`m` split (lat-long coordinates of six faces, solid angles
/// of one).
pub fn sub_texel_bytes(m: usize) -> usize {
    6 * m * m * std::mem::size_of::<Vec2>() + m * m * std::mem::size_of::<f64>()
}

/// The sub-texels of (`n`, `s`), made on first use and kept (the last `SUB_TEXELS_KEPT` pairs
/// of at most `SUB_TEXELS_KEEP_BYTES` each).
fn sub_texels(n: usize, s: usize) -> Arc<SubTexels> {
    use rayon::prelude::*;
    static KEPT: Mutex<Vec<((usize, usize), Arc<SubTexels>)>> = Mutex::new(Vec::new());
    if let Some((_, t)) = KEPT.lock().unwrap_or_else(|e| e.into_inner()).iter().find(|(k, _)| *k == (n, s)) {
        return t.clone();
    }
    let m = n * s;
    let e = |t: usize| -1.0 + 2.0 * t as f64 / m as f64;
    let uv = (0..6 * m * m)
        .into_par_iter()
        .map(|k| {
            let (face, b, a) = (k / (m * m), k / m % m, k % m);
            let (u, v) = (((e(a) + e(a + 1)) / 2.0) as f32, ((e(b) + e(b + 1)) / 2.0) as f32);
            super::latlong::dir_to_uv(face_point(face, u, v).normalize())
        })
        .collect();
    let t = Arc::new(SubTexels { uv, dws: face_solid_angles(m) });
    if sub_texel_bytes(m) > SUB_TEXELS_KEEP_BYTES {
        return t;
    }
    let mut kept = KEPT.lock().unwrap_or_else(|e| e.into_inner());
    if kept.len() == SUB_TEXELS_KEPT {
        kept.remove(0);
    }
    kept.push(((n, s), t.clone()));
    t
}

/// The texel of a map of side `n` that direction `d` falls in.
pub fn texel_of_side(n: usize, d: Vec3) -> usize {
    CubeAt::of(d).texel(n)
}

/// Where a direction falls on the cube (`locate`: its face and (u, v) there), found once
/// and read from maps of any side: a shader that reads several maps at one direction
/// locates it once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CubeAt {
    pub face: usize,
    pub u: f32,
    pub v: f32,
}

impl CubeAt {
    pub fn of(d: Vec3) -> CubeAt {
        let (face, u, v) = locate(d);
        CubeAt { face, u, v }
    }

    /// The texel of a map of side `n` holding this place.
    pub fn texel(&self, n: usize) -> usize {
        let t = |x: f32| (((x + 1.0) * 0.5 * n as f32) as usize).min(n - 1);
        (self.face * n + t(self.v)) * n + t(self.u)
    }

    /// The bilinear taps between texel centres on a map of side `n`: the texel indices of
    /// the two rows' starts, the two columns, and the weights toward the second of each.
    #[inline]
    pub fn taps(&self, n: usize) -> Taps {
        let g = |x: f32| ((x + 1.0) * 0.5 * n as f32 - 0.5).clamp(0.0, (n - 1) as f32);
        let (x, y) = (g(self.u), g(self.v));
        let (i0, j0) = (x as usize, y as usize);
        let (i1, j1) = ((i0 + 1).min(n - 1), (j0 + 1).min(n - 1));
        ([(self.face * n + j0) * n, (self.face * n + j1) * n], [i0, i1], x - i0 as f32, y - j0 as f32)
    }
}

/// Where a bilinear lookup reads a map of one side (`CubeAt::taps`): the texel indices of
/// the two rows' starts, the two columns, and the weights toward the second of each.
pub type Taps = ([usize; 2], [usize; 2], f32, f32);

/// A cube map's texels borrowed from wherever they are held (a port value's own array),
/// read as `CubeMap` reads its own.
#[derive(Clone, Copy, Debug)]
pub struct CubeView<'a> {
    pub n: usize,
    pub texels: &'a [Vec3],
}

impl CubeView<'_> {
    /// As `CubeMap::box_downsample`, without a copy of the texels. The fine texels' solid
    /// angles (four arc tangents each) are the same on every face: computed for one.
    pub fn box_downsample(&self, m: usize) -> CubeMap {
        let n = self.n;
        assert!(m > 0 && n.is_multiple_of(m), "a cube map of side {n} cannot be box-filtered to side {m}");
        // As `CubeMap::solid_angle` gives them (rounded to f32).
        let face_w: Vec<f64> = face_solid_angles(n).into_iter().map(|w| w as f32 as f64).collect();
        let r = n / m;
        let mut sum = vec![[0.0f64; 4]; 6 * m * m];
        for (k, t) in self.texels.iter().enumerate() {
            let w = face_w[k % (n * n)];
            let (face, i, j) = (k / (n * n), k % n, k / n % n);
            let s = &mut sum[(face * m + j / r) * m + i / r];
            for c in 0..3 {
                s[c] += t[c] as f64 * w;
            }
            s[3] += w;
        }
        let texels = sum.iter().map(|s| Vec3::new((s[0] / s[3]) as f32, (s[1] / s[3]) as f32, (s[2] / s[3]) as f32)).collect();
        CubeMap { n: m, texels }
    }

    /// Bilinear lookup at direction `d` within its face (as `CubeMap::lookup`).
    pub fn lookup(&self, d: Vec3) -> Vec3 {
        self.lookup_at(&CubeAt::of(d))
    }

    /// `lookup` at a place already located.
    #[inline]
    pub fn lookup_at(&self, at: &CubeAt) -> Vec3 {
        self.lookup_taps(at.taps(self.n))
    }

    /// `lookup_at` where the place's taps on a map of this side are known (several maps of
    /// one side read at one place locate it once).
    #[inline]
    pub fn lookup_taps(&self, ([r0, r1], [i0, i1], fx, fy): Taps) -> Vec3 {
        let t = &self.texels;
        (t[r0 + i0] * (1.0 - fx) + t[r0 + i1] * fx) * (1.0 - fy) + (t[r1 + i0] * (1.0 - fx) + t[r1 + i1] * fx) * fy
    }
}

/// An RGB cube map (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct CubeMap {
    /// Texels along a face's side.
    pub n: usize,
    /// 6 n² texels, face after face, row after row.
    pub texels: Vec<Vec3>,
}

impl CubeMap {
    /// A map of `value` everywhere.
    pub fn constant(n: usize, value: Vec3) -> CubeMap {
        CubeMap { n, texels: vec![value; 6 * n * n] }
    }

    /// Bytes of a map of side `n` (what a node checks against its budget before allocating).
    pub fn bytes_for(n: usize) -> u64 {
        6 * (n as u64).pow(2) * std::mem::size_of::<Vec3>() as u64
    }

    /// The index of texel (i, j) of `face`.
    pub fn index(&self, face: usize, i: usize, j: usize) -> usize {
        (face * self.n + j) * self.n + i
    }

    /// The unit direction through the centre of texel `k`.
    pub fn direction(&self, k: usize) -> Vec3 {
        let (face, i, j) = (k / (self.n * self.n), k % self.n, k / self.n % self.n);
        let c = |t: usize| -1.0 + (2 * t + 1) as f32 / self.n as f32;
        face_point(face, c(i), c(j)).normalize()
    }

    /// The solid angle of texel `k` (the same on every face).
    pub fn solid_angle(&self, k: usize) -> f32 {
        let (i, j) = (k % self.n, k / self.n % self.n);
        let e = |t: usize| -1.0 + 2.0 * t as f64 / self.n as f64;
        rect_solid_angle(e(i), e(i + 1), e(j), e(j + 1)) as f32
    }

    /// The texel direction `d` falls in.
    pub fn texel_of(&self, d: Vec3) -> usize {
        texel_of_side(self.n, d)
    }

    /// The map borrowed (for texels held elsewhere without a copy, see `CubeView`).
    pub fn view(&self) -> CubeView<'_> {
        CubeView { n: self.n, texels: &self.texels }
    }

    /// The map of side `n` whose texels are the solid-angle-weighted means of `f` over
    /// `s` × `s` sub-texels each (a box filter over the texel's piece of sphere).
    pub fn from_fn(n: usize, s: usize, f: impl Fn(Vec3) -> Vec3 + Sync) -> CubeMap {
        let s = s.max(1);
        let m = n * s;
        let e = |t: usize| -1.0 + 2.0 * t as f64 / m as f64;
        // The sub-texels' solid angles are the same on every face: computed once (four arc
        // tangents each), not six times.
        let dws = face_solid_angles(m);
        CubeMap::box_filtered(n, s, &dws, |face, a, b| {
            let (u, v) = (((e(a) + e(a + 1)) / 2.0) as f32, ((e(b) + e(b + 1)) / 2.0) as f32);
            f(face_point(face, u, v).normalize())
        })
    }

    /// `from_fn` of a latitude-longitude map read at lat-long coordinates by `lookup`: `f(d)`
    /// being `lookup(latlong::dir_to_uv(d))`, the same texels, bit for bit. The sub-texels'
    /// coordinates and solid angles depend on `n` and `s` alone: they are found once per
    /// process (the last few pairs kept), so a new or turned map costs only the lookups.
    pub fn from_latlong(n: usize, s: usize, lookup: impl Fn(Vec2) -> Vec3 + Sync) -> CubeMap {
        let s = s.max(1);
        let m = n * s;
        let sub = sub_texels(n, s);
        CubeMap::box_filtered(n, s, &sub.dws, |face, a, b| lookup(sub.uv[(face * m + b) * m + a]))
    }

    /// Each texel the mean of `sample(face, a, b)` over its `s` × `s` sub-texels (a, b along the
    /// face's side of n s), weighted by their solid angles `dws` (one face's, row-major).
    fn box_filtered(n: usize, s: usize, dws: &[f64], sample: impl Fn(usize, usize, usize) -> Vec3 + Sync) -> CubeMap {
        use rayon::prelude::*;
        let m = n * s;
        let texels = (0..6 * n * n)
            .into_par_iter()
            .map(|k| {
                let (face, i, j) = (k / (n * n), k % n, k / n % n);
                let (mut sum, mut w) = (Vec3::ZERO, 0.0f64);
                for b in j * s..(j + 1) * s {
                    for a in i * s..(i + 1) * s {
                        let dw = dws[b * m + a];
                        sum += sample(face, a, b) * dw as f32;
                        w += dw;
                    }
                }
                sum / w as f32
            })
            .collect();
        CubeMap { n, texels }
    }

    /// The value at direction `d`, bilinear between texel centres on its face (clamped at the
    /// face's edges).
    pub fn lookup(&self, d: Vec3) -> Vec3 {
        self.view().lookup(d)
    }

    /// ∫ over the sphere: Σ texel × its solid angle (in f64, texel order).
    pub fn integral(&self) -> Vec3 {
        let mut sum = [0.0f64; 3];
        for (k, t) in self.texels.iter().enumerate() {
            let w = self.solid_angle(k) as f64;
            for c in 0..3 {
                sum[c] += t[c] as f64 * w;
            }
        }
        Vec3::new(sum[0] as f32, sum[1] as f32, sum[2] as f32)
    }

    /// The map convolved with a Gaussian lobe of angular standard deviation `sigma` (radians)
    /// on the sphere, at side `n`: each output texel is the mean of the input texels weighted
    /// by exp(−θ²/2σ²) × their solid angle, θ the angle between the texels' centres, over
    /// θ < 4σ (the Gaussian-prefiltered environment the specular lobes read, [S] 5.3.1).
    /// Normalised per texel, so a constant map stays constant; σ = 0 resamples (the texel
    /// the output texel's centre falls in). Output texels in parallel, each summed in texel
    /// order: the same bytes on any thread count.
    pub fn gaussian_prefilter(&self, sigma: f32, n: usize) -> CubeMap {
        use rayon::prelude::*;
        let out = CubeMap::constant(n, Vec3::ZERO);
        if sigma.is_nan() || sigma <= 0.0 {
            let texels = (0..out.texels.len()).map(|k| self.texels[self.texel_of(out.direction(k))]).collect();
            return CubeMap { n, texels };
        }
        let dirs: Vec<Vec3> = (0..self.texels.len()).map(|k| self.direction(k)).collect();
        let omega: Vec<f32> = (0..self.texels.len()).map(|k| self.solid_angle(k)).collect();
        let reach = (4.0 * sigma).min(std::f32::consts::PI);
        let cos_reach = reach.cos();
        let kernel = GaussKernel::new(sigma, cos_reach);
        // Tiles of b × b texels with a bounding cone (axis, half-angle): a tile wholly beyond
        // the reach of an output direction is skipped; the others are summed row by row in
        // texel order, as a loop over every texel would.
        let b = (self.n / 8).max(1);
        let tiles = self.n.div_ceil(b);
        let cones: Vec<(Vec3, f32)> = (0..6 * tiles * tiles)
            .map(|t| {
                let (face, tj, ti) = (t / (tiles * tiles), t / tiles % tiles, t % tiles);
                let ks: Vec<usize> = (tj * b..((tj + 1) * b).min(self.n))
                    .flat_map(|j| (ti * b..((ti + 1) * b).min(self.n)).map(move |i| (face * self.n + j) * self.n + i))
                    .collect();
                let axis = ks.iter().map(|&k| dirs[k]).sum::<Vec3>().normalize();
                // The texels' centres, widened by a texel's half-diagonal.
                let half = ks.iter().map(|&k| axis.dot(dirs[k]).clamp(-1.0, 1.0).acos()).fold(0.0f32, f32::max);
                let h = half + std::f32::consts::PI / self.n as f32;
                // Whether every direction is near (the cone and the reach cover the sphere),
                // else the least cosine to the axis of a direction within reach of the tile.
                let all = reach >= std::f32::consts::PI || reach + h >= std::f32::consts::PI;
                (axis, if all { f32::NEG_INFINITY } else { (reach + h).cos() })
            })
            .collect();
        // Eight outputs at a time (neighbours along a row, near the same tiles): each keeps its
        // own sum in the same texel order as alone, so the bytes are those of one output at a
        // time; a lane adds nothing from a tile only its neighbours are near, where no texel
        // is within its reach (the tiles' cones are wider than their texels by a texel's
        // half-diagonal). Eight independent sums keep the adder busy where one waited on
        // each addition before the next.
        const LANES: usize = 8;
        let all = reach >= std::f32::consts::PI;
        let groups: Vec<[Vec3; LANES]> = (0..out.texels.len().div_ceil(LANES))
            .into_par_iter()
            .map(|g| {
                let first = g * LANES;
                let lanes = LANES.min(out.texels.len() - first);
                let d: [Vec3; LANES] = std::array::from_fn(|l| out.direction(first + l.min(lanes - 1)));
                let near: Vec<bool> = cones.iter().map(|(a, least)| d[..lanes].iter().any(|d| d.dot(*a) >= *least)).collect();
                let (mut sum, mut w) = ([Vec3::ZERO; LANES], [0.0f64; LANES]);
                for face in 0..6 {
                    for j in 0..self.n {
                        for ti in 0..tiles {
                            if !near[(face * tiles + j / b) * tiles + ti] {
                                continue;
                            }
                            for i in ti * b..((ti + 1) * b).min(self.n) {
                                let t = (face * self.n + j) * self.n + i;
                                let (dir, texel, om) = (dirs[t], self.texels[t], omega[t]);
                                for l in 0..LANES {
                                    let c = d[l].dot(dir);
                                    if c >= cos_reach || all {
                                        let g = kernel.at(c) * om;
                                        sum[l] += texel * g;
                                        w[l] += g as f64;
                                    }
                                }
                            }
                        }
                    }
                }
                std::array::from_fn(|l| if w[l] > 0.0 { sum[l] / w[l] as f32 } else { self.texels[self.texel_of(d[l])] })
            })
            .collect();
        let texels = groups.into_iter().flatten().take(out.texels.len()).collect();
        CubeMap { n, texels }
    }

    /// The index, in a map of side `m` (a divisor of this map's side), of the coarse texel
    /// that fine texel `k` lies in.
    pub fn coarse_of(&self, k: usize, m: usize) -> usize {
        let r = self.n / m;
        let (face, i, j) = (k / (self.n * self.n), k % self.n, k / self.n % self.n);
        (face * m + j / r) * m + i / r
    }

    /// The map at side `m` (a divisor of the side): each coarse texel the solid-angle-weighted
    /// mean of the fine texels it covers, so the integral over the sphere is kept (the box
    /// lighting bases of the one- and two-bounce transfer, [S] 5.3.3.4–5). Summed in texel
    /// order in f64.
    pub fn box_downsample(&self, m: usize) -> CubeMap {
        self.view().box_downsample(m)
    }

    /// A `width` × `height` latitude-longitude image of the map in the scenes' convention
    /// (`scene::envmap::uv_to_dir`: row 0 at the +y pole), bilinear lookups.
    pub fn to_latlong(&self, width: usize, height: usize) -> Vec<Vec3> {
        let mut out = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                let uv = glam::Vec2::new((x as f32 + 0.5) / width as f32, (y as f32 + 0.5) / height as f32);
                out.push(self.lookup(crate::math::latlong::uv_to_dir(uv)));
            }
        }
        out
    }
}

/// 4π, the solid angle of the sphere.
pub const SPHERE: f64 = 4.0 * PI;

/// The Gaussian exp(−θ²/2σ²) of the angle θ = acos c, as a function of c = cos θ on
/// [`lo`, 1], tabled when `lo` ≥ 0 (a reach of at most 90°): θ² is smooth in c there
/// (≈ 2(1 − c) near 1), so linear interpolation between 4096 samples is within 10⁻⁵ of the
/// exact value (tested), at the cost of one lookup instead of an arc cosine and an
/// exponential per texel pair. Toward c = −1, θ(c) has a square-root singularity: wider
/// reaches are computed exactly.
pub struct GaussKernel {
    lo: f32,
    scale: f32,
    /// 2σ², for the exact path.
    s2: f32,
    table: Vec<f32>,
}

impl GaussKernel {
    const SAMPLES: usize = 4096;

    pub fn new(sigma: f32, lo: f32) -> GaussKernel {
        let lo = lo.clamp(-1.0, 1.0);
        let (s2, h) = (2.0 * (sigma as f64).powi(2), (1.0 - lo as f64) / Self::SAMPLES as f64);
        let table = (0..=Self::SAMPLES)
            .filter(|_| lo >= 0.0)
            .map(|k| {
                let theta = (lo as f64 + k as f64 * h).clamp(-1.0, 1.0).acos();
                (-(theta * theta) / s2).exp() as f32
            })
            .collect();
        GaussKernel { lo, scale: if h > 0.0 { (1.0 / h) as f32 } else { 0.0 }, s2: s2 as f32, table }
    }

    /// The kernel at c (clamped to [lo, 1]).
    pub fn at(&self, c: f32) -> f32 {
        if self.table.is_empty() {
            let theta = c.clamp(self.lo, 1.0).acos();
            return (-(theta * theta) / self.s2).exp();
        }
        let x = ((c.clamp(self.lo, 1.0) - self.lo) * self.scale).min(Self::SAMPLES as f32);
        let k = (x as usize).min(Self::SAMPLES - 1);
        let f = x - k as f32;
        self.table[k] + (self.table[k + 1] - self.table[k]) * f
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;

    #[test]
    fn a_lat_long_map_gives_from_fns_texels_to_the_bit_each_time() {
        // A lat-long field with detail in u and v, read through kept and fresh sub-texels.
        let field = |uv: Vec2| Vec3::new((uv.x * 40.0).sin() + 1.5, (uv.y * 17.0).cos() + 2.0, uv.x * uv.y);
        for (n, s) in [(8, 3), (4, 5), (8, 3)] {
            let direct = CubeMap::from_fn(n, s, |d| field(crate::math::latlong::dir_to_uv(d)));
            assert_eq!(CubeMap::from_latlong(n, s, field), direct, "side {n}, {s} sub-texels");
        }
    }

    #[test]
    fn the_kept_texel_directions_are_the_maps_to_the_bit() {
        for n in [1, 4, 32, 3] {
            let map = CubeMap::constant(n, Vec3::ZERO);
            let dirs = texel_directions(n);
            assert_eq!(dirs.len(), 6 * n * n);
            assert!((0..dirs.len()).all(|k| dirs[k] == map.direction(k)), "side {n}");
            let omega = texel_solid_angles(n);
            assert!((0..dirs.len()).all(|k| omega[k] == map.solid_angle(k)), "side {n}");
        }
    }

    fn unit(k: u64) -> Vec3 {
        crate::math::sampling::uniform_sphere(glam::Vec2::new(uniform(11, k, 0), uniform(11, k, 1)))
    }

    #[test]
    fn texel_solid_angles_cover_the_sphere_once() {
        for n in [1, 2, 3, 16, 64] {
            let m = CubeMap::constant(n, Vec3::ONE);
            let total: f64 = (0..6 * n * n).map(|k| m.solid_angle(k) as f64).sum();
            assert!((total / SPHERE - 1.0).abs() < 1e-6, "n = {n}: {total}");
            // Symmetric about the face's centre; the centre texels see most.
            if n >= 3 {
                assert_eq!(m.solid_angle(0), m.solid_angle(n * n - 1));
                assert!(m.solid_angle(0) < m.solid_angle(n / 2 * (n + 1)));
            }
        }
        // One face is a sixth of the sphere.
        assert!((rect_solid_angle(-1.0, 1.0, -1.0, 1.0) - SPHERE / 6.0).abs() < 1e-12);
    }

    #[test]
    fn directions_locate_back_to_their_texel_and_points_to_their_face() {
        let m = CubeMap::constant(16, Vec3::ZERO);
        for k in 0..m.texels.len() {
            assert_eq!(m.texel_of(m.direction(k)), k, "texel {k}");
            assert_eq!(m.texel_of(m.direction(k) * 7.5), k, "length does not matter");
        }
        for k in 0..500 {
            let d = unit(k);
            let (face, u, v) = locate(d);
            assert!(u.abs() <= 1.0 && v.abs() <= 1.0);
            let p = face_point(face, u, v);
            assert!((p.normalize() - d).length() < 1e-5, "{d} → {face} ({u}, {v}) → {p}");
        }
        // Edges, corners and bad directions land somewhere valid.
        for d in [Vec3::ONE, Vec3::new(1.0, -1.0, 0.0), -Vec3::ONE, Vec3::ZERO, Vec3::NAN, Vec3::INFINITY] {
            assert!(m.texel_of(d) < m.texels.len(), "{d}");
            assert!(m.lookup(d).is_finite());
        }
    }

    #[test]
    fn a_constant_stays_constant_and_integrals_match_the_analytic_ones() {
        let c = Vec3::new(0.5, 1.0, 2.0);
        let m = CubeMap::from_fn(8, 2, |_| c);
        for t in &m.texels {
            assert!((*t - c).abs().max_element() < 1e-6);
        }
        let i = m.integral();
        assert!((i / c - Vec3::splat(SPHERE as f32)).abs().max_element() < 1e-4, "{i}");
        // ∫ max(0, d · n) dω = π for any n (clamped cosine), here off every axis.
        let n = Vec3::new(0.3, -0.5, 0.8).normalize();
        let m = CubeMap::from_fn(32, 4, |d| Vec3::splat(d.dot(n).max(0.0)));
        let i = m.integral().x as f64;
        assert!((i / PI - 1.0).abs() < 1e-3, "{i}");
        // ∫ (d · z)² dω = 4π/3.
        let m = CubeMap::from_fn(32, 2, |d| Vec3::splat(d.z * d.z));
        assert!((m.integral().x as f64 / (SPHERE / 3.0) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn skipping_tiles_beyond_the_reach_gives_the_bytes_of_the_full_sum() {
        // The full sum over every texel, in texel order: what the tiles must reproduce.
        let full = |m: &CubeMap, sigma: f32, n: usize| {
            let out = CubeMap::constant(n, Vec3::ZERO);
            let reach = (4.0 * sigma).min(std::f32::consts::PI);
            let kernel = GaussKernel::new(sigma, reach.cos());
            (0..out.texels.len())
                .map(|k| {
                    let d = out.direction(k);
                    let (mut sum, mut w) = (Vec3::ZERO, 0.0f64);
                    for t in 0..m.texels.len() {
                        let c = d.dot(m.direction(t));
                        if c >= reach.cos() || reach >= std::f32::consts::PI {
                            let g = kernel.at(c) * m.solid_angle(t);
                            sum += m.texels[t] * g;
                            w += g as f64;
                        }
                    }
                    if w > 0.0 {
                        sum / w as f32
                    } else {
                        m.texels[m.texel_of(d)]
                    }
                })
                .collect::<Vec<Vec3>>()
        };
        let m = CubeMap::from_fn(16, 1, |d| Vec3::new(d.x.max(0.0).powi(8) * 50.0, (3.0 * d.y).sin() + 1.0, d.z * d.z));
        for (sigma_deg, n) in [(3.0f32, 16), (7.0, 8), (21.0, 4), (60.0, 8)] {
            let got = m.gaussian_prefilter(sigma_deg.to_radians(), n);
            assert_eq!(got.texels, full(&m, sigma_deg.to_radians(), n), "σ = {sigma_deg}°");
        }
    }

    #[test]
    fn the_tabled_gaussian_is_within_1e_5_of_the_exact_one() {
        for sigma_deg in [0.5f32, 7.0, 21.0, 60.0] {
            let sigma = sigma_deg.to_radians();
            let lo = (4.0 * sigma).min(std::f32::consts::PI).cos();
            let k = GaussKernel::new(sigma, lo);
            let mut worst = 0.0f64;
            for i in 0..=100_000 {
                let c = lo + (1.0 - lo) * i as f32 / 100_000.0;
                let theta = (c as f64).clamp(-1.0, 1.0).acos();
                let exact = (-(theta * theta) / (2.0 * (sigma as f64).powi(2))).exp();
                worst = worst.max((k.at(c) as f64 - exact).abs());
            }
            assert!(worst < 1e-5, "σ = {sigma_deg}°: {worst}");
            assert_eq!(k.table.is_empty(), sigma_deg > 22.5, "tabled up to a reach of 90°");
            assert_eq!(k.at(1.5), k.at(1.0), "clamped above");
        }
    }

    #[test]
    fn gaussian_prefiltering_keeps_constants_and_spreads_a_sun_by_sigma() {
        let c = CubeMap::constant(16, Vec3::splat(2.0));
        for t in &c.gaussian_prefilter(0.2, 8).texels {
            assert!((*t - Vec3::splat(2.0)).abs().max_element() < 1e-5);
        }
        // A sun (one texel of a 64² map) blurred by σ = 7°: the lobe's mean squared angle
        // from the sun is 2σ² (a 2-D Gaussian on the sphere's tangent plane) within 10 %, and
        // its energy is the sun's within 2 %.
        let mut m = CubeMap::constant(64, Vec3::ZERO);
        let sun = m.texel_of(Vec3::new(0.2, 0.9, 0.1));
        m.texels[sun] = Vec3::splat(1e4);
        let s = m.direction(sun);
        let sigma = 7f32.to_radians();
        let b = m.gaussian_prefilter(sigma, 64);
        let (mut e, mut m2) = (0.0f64, 0.0f64);
        for k in 0..b.texels.len() {
            let w = b.texels[k].x as f64 * b.solid_angle(k) as f64;
            let theta = b.direction(k).dot(s).clamp(-1.0, 1.0).acos() as f64;
            e += w;
            m2 += w * theta * theta;
        }
        let want = 2.0 * (sigma as f64).powi(2);
        assert!((m2 / e / want - 1.0).abs() < 0.1, "{} vs {want}", m2 / e);
        let sun_energy = 1e4 * m.solid_angle(sun) as f64;
        assert!((e / sun_energy - 1.0).abs() < 0.02, "{e} vs {sun_energy}");
        // σ = 0 is a resampling.
        assert_eq!(m.gaussian_prefilter(0.0, 64), m);
    }

    #[test]
    fn the_prefilter_is_the_plain_sum_over_every_texel_within_reach() {
        // Against a sum over every input texel with no tiles and one output at a time, at
        // output sides whose texel count is not a multiple of the eight outputs done together
        // (6 × 3² = 54, 6 × 5² = 150), and with a reach past the whole sphere (σ 50°).
        let m = CubeMap::from_fn(8, 1, |d| Vec3::new(1.0 + d.x, d.y * d.y, (4.0 * d.z).sin() + 2.0));
        for (sigma_deg, side) in [(7.0f32, 3usize), (20.0, 5), (50.0, 3)] {
            let sigma = sigma_deg.to_radians();
            let out = m.gaussian_prefilter(sigma, side);
            let reach = (4.0 * sigma).min(std::f32::consts::PI);
            for (k, got) in out.texels.iter().enumerate() {
                let d = out.direction(k);
                let (mut sum, mut w) = (glam::DVec3::ZERO, 0.0f64);
                for t in 0..m.texels.len() {
                    let theta = d.dot(m.direction(t)).clamp(-1.0, 1.0).acos();
                    if theta <= reach {
                        let g = (-(theta as f64).powi(2) / (2.0 * (sigma as f64).powi(2))).exp() * m.solid_angle(t) as f64;
                        sum += m.texels[t].as_dvec3() * g;
                        w += g;
                    }
                }
                let want = (sum / w).as_vec3();
                assert!(
                    (*got - want).abs().max_element() < 2e-3 * want.max_element(),
                    "σ {sigma_deg}°, side {side}, texel {k}: {got} against {want}"
                );
            }
        }
    }

    #[test]
    fn box_downsampling_keeps_the_integral_and_constants() {
        let m = CubeMap::from_fn(16, 1, |d| Vec3::new(1.0 + d.x, d.y * d.y, (4.0 * d.z).sin() + 2.0));
        for side in [1, 2, 8, 16] {
            let c = m.box_downsample(side);
            assert_eq!(c.texels.len(), 6 * side * side);
            assert!((c.integral() - m.integral()).abs().max_element() < 1e-4 * m.integral().max_element(), "side {side}");
        }
        let k = CubeMap::constant(16, Vec3::new(0.5, 1.0, 2.0)).box_downsample(4);
        assert!(k.texels.iter().all(|t| (*t - Vec3::new(0.5, 1.0, 2.0)).abs().max_element() < 1e-6));
        // Each fine texel's coarse texel holds its direction.
        let c = CubeMap::constant(4, Vec3::ZERO);
        for f in 0..m.texels.len() {
            let d = m.direction(f);
            assert!(d.dot(c.direction(m.coarse_of(f, 4))) > 0.8, "texel {f}");
        }
    }

    #[test]
    fn lookups_reproduce_a_smooth_field_and_a_latlong_round_trip() {
        let f = |d: Vec3| Vec3::new(1.0 + d.x, 1.5 + 0.5 * d.y * d.z, 2.0 - d.z);
        let m = CubeMap::from_fn(64, 1, f);
        let mut worst = 0.0f32;
        for k in 0..500 {
            let d = unit(k);
            worst = worst.max((m.lookup(d) - f(d)).abs().max_element());
        }
        assert!(worst < 0.02, "worst {worst}");
        // A texel centre returns the texel itself.
        for k in (0..m.texels.len()).step_by(97) {
            assert!((m.lookup(m.direction(k)) - m.texels[k]).abs().max_element() < 1e-5);
        }
        let ll = m.to_latlong(64, 32);
        assert_eq!(ll.len(), 64 * 32);
        for (p, v) in ll.iter().enumerate() {
            let uv = glam::Vec2::new(((p % 64) as f32 + 0.5) / 64.0, ((p / 64) as f32 + 0.5) / 32.0);
            assert!((*v - f(crate::math::latlong::uv_to_dir(uv))).abs().max_element() < 0.02);
        }
    }
}
