//! Sampling warps, their densities, MIS weights and tabulated distributions.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// Uniform point on the unit disk (Shirley–Chiu concentric map).
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() { (o.x, PI / 4.0 * (o.y / o.x)) } else { (o.y, PI / 2.0 - PI / 4.0 * (o.x / o.y)) };
    Vec2::new(r * theta.cos(), r * theta.sin())
}

/// Cosine-weighted direction on the +z hemisphere; density cos θ / π.
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Uniform direction on the unit sphere; density 1 / 4π.
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform barycentrics (b0, b1) on a triangle (the third is 1 − b0 − b1).
pub fn uniform_triangle(u: Vec2) -> (f32, f32) {
    let su = u.x.sqrt();
    (1.0 - su, u.y * su)
}

/// Veach's power heuristic (β = 2) for the technique with density `a` against `b`.
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2.is_infinite() {
        return 1.0;
    }
    if a2 + b2 == 0.0 {
        0.0
    } else {
        a2 / (a2 + b2)
    }
}

/// A piecewise-constant 1-D distribution over [0, 1) with `n` cells.
#[derive(Clone, Debug)]
pub struct Distribution1D {
    pub func: Vec<f32>,
    pub cdf: Vec<f32>,
    /// Integral of `func` over [0, 1).
    pub integral: f32,
}

impl Distribution1D {
    /// Negative or non-finite values count as 0; an all-zero function samples uniformly.
    pub fn new(func: &[f32]) -> Self {
        let n = func.len().max(1);
        let func: Vec<f32> = (0..n).map(|i| func.get(i).copied().filter(|x| x.is_finite() && *x > 0.0).unwrap_or(0.0)).collect();
        let mut cdf = vec![0.0f32; n + 1];
        let mut acc = 0.0f64;
        for i in 0..n {
            acc += func[i] as f64 / n as f64;
            cdf[i + 1] = acc as f32;
        }
        let integral = acc as f32;
        if integral > 0.0 {
            for c in &mut cdf[1..] {
                *c /= integral;
            }
        } else {
            for (i, c) in cdf.iter_mut().enumerate() {
                *c = i as f32 / n as f32;
            }
        }
        cdf[n] = 1.0;
        Distribution1D { func, cdf, integral }
    }

    pub fn len(&self) -> usize {
        self.func.len()
    }

    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// Samples a cell; returns (cell, probability of that cell).
    pub fn sample_discrete(&self, u: f32) -> (usize, f32) {
        let i = self.find(u);
        (i, self.cdf[i + 1] - self.cdf[i])
    }

    /// As `sample_discrete`, also returning u's position within the chosen cell rescaled to
    /// [0, 1): a stratified u stays stratified within each cell (sample reuse).
    pub fn sample_discrete_reuse(&self, u: f32) -> (usize, f32, f32) {
        let i = self.find(u);
        let width = self.cdf[i + 1] - self.cdf[i];
        let du = if width > 0.0 { ((u - self.cdf[i]) / width).clamp(0.0, 1.0 - f32::EPSILON) } else { 0.5 };
        (i, width, du)
    }

    /// Probability of drawing cell `i` with `sample_discrete`.
    pub fn discrete_pdf(&self, i: usize) -> f32 {
        self.cdf[i + 1] - self.cdf[i]
    }

    /// Samples x in [0, 1); returns (x, density at x, cell).
    pub fn sample_continuous(&self, u: f32) -> (f32, f32, usize) {
        let i = self.find(u);
        let width = self.cdf[i + 1] - self.cdf[i];
        let du = if width > 0.0 { (u - self.cdf[i]) / width } else { 0.5 };
        let x = ((i as f32 + du.clamp(0.0, 1.0)) / self.len() as f32).min(1.0 - f32::EPSILON);
        (x, self.pdf_cell(i), i)
    }

    /// Density of `sample_continuous` at any x in cell `i`.
    pub fn pdf_cell(&self, i: usize) -> f32 {
        if self.integral > 0.0 {
            self.func[i] / self.integral
        } else {
            1.0
        }
    }

    fn find(&self, u: f32) -> usize {
        // Last index with cdf[i] <= u, clamped to a valid cell.
        let n = self.len();
        let i = self.cdf.partition_point(|&c| c <= u).saturating_sub(1);
        let mut i = i.min(n - 1);
        while i > 0 && self.cdf[i + 1] == self.cdf[i] && self.cdf[i] > u {
            i -= 1;
        }
        // Skip zero-width cells (never sample a cell of zero probability).
        while i < n - 1 && self.cdf[i + 1] <= self.cdf[i] {
            i += 1;
        }
        i
    }
}

/// Kensler's hash permutation of 0..len ("Correlated Multi-Jittered Sampling", Pixar 2013):
/// element `i` of the permutation numbered `pattern`.
pub fn permute(i: u32, len: u32, pattern: u32) -> u32 {
    Permutation::new(len).numbered(pattern).at(i)
}

/// The permutations of 0..len: what Kensler's hash needs of the length, computed once.
#[derive(Clone, Copy, Debug)]
struct Permutation {
    len: u32,
    /// The smallest all-ones mask covering len − 1.
    mask: u32,
    /// 2³² mod len: what a wrapped `i + pattern` loses.
    wrap: u32,
}

impl Permutation {
    fn new(len: u32) -> Permutation {
        let len = len.max(1);
        let mut w = len - 1;
        w |= w >> 1;
        w |= w >> 2;
        w |= w >> 4;
        w |= w >> 8;
        w |= w >> 16;
        Permutation { len, mask: w, wrap: ((1u64 << 32) % len as u64) as u32 }
    }

    /// The permutation numbered `p`.
    fn numbered(self, p: u32) -> Numbered {
        Numbered { of: self, p, offset: p % self.len }
    }
}

/// One permutation of 0..len, its pattern's offset modulo len computed once.
#[derive(Clone, Copy, Debug)]
struct Numbered {
    of: Permutation,
    p: u32,
    offset: u32,
}

impl Numbered {
    /// Element `i` (< len): the hash walked until it lands below len, then shifted.
    #[inline]
    fn at(&self, mut i: u32) -> u32 {
        loop {
            i = self.hash(i);
            if i < self.of.len {
                return self.shift(i);
            }
        }
    }

    /// Elements 0..out.len() (each < len) at once: every first hash before any walk, so that
    /// the independent hashes overlap.
    fn fill(&self, out: &mut [u32]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.hash(i as u32);
        }
        for o in out.iter_mut() {
            while *o >= self.of.len {
                *o = self.hash(*o);
            }
            *o = self.shift(*o);
        }
    }

    /// One round of Kensler's hash, within the mask.
    #[inline]
    fn hash(&self, mut i: u32) -> u32 {
        let (p, w) = (self.p, self.of.mask);
        i ^= p;
        i = i.wrapping_mul(0xe170893d);
        i ^= p >> 16;
        i ^= (i & w) >> 4;
        i ^= p >> 8;
        i = i.wrapping_mul(0x0929eb3f);
        i ^= p >> 23;
        i ^= (i & w) >> 1;
        i = i.wrapping_mul(1 | p >> 27);
        i = i.wrapping_mul(0x6935fa69);
        i ^= (i & w) >> 11;
        i = i.wrapping_mul(0x74dcb303);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0x9e501cc3);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0xc860a3df);
        i &= w;
        i ^= i >> 5;
        i
    }

    /// A hash below len shifted by the pattern modulo len: `(i + p) mod 2³² mod len` without a
    /// division.
    #[inline]
    fn shift(&self, i: u32) -> u32 {
        let (p, len) = (self.p, self.of.len);
        // i + offset < 2 len; a wrapped sum lost 2³² ≡ wrap (mod len).
        let len = len as u64;
        let mut r = i as u64 + self.offset as u64;
        if i.overflowing_add(p).1 {
            r += len - self.of.wrap as u64;
        }
        while r >= len {
            r -= len;
        }
        r as u32
    }
}

/// Sample `s` of `n` correlated multi-jittered points in [0, 1)² (Kensler 2013): the n points
/// of one `pattern` fall one per cell of an m × ⌈n/m⌉ grid (m = ⌊√n⌋) and one per 1/n strip
/// along each axis. `jitter` (two uniforms in [0, 1)) places the point within its cell.
/// [`Cmj`] gives the same points with the work that depends only on n, or on n and the
/// pattern, done once.
pub fn cmj(s: u32, n: u32, pattern: u32, jitter: Vec2) -> Vec2 {
    Cmj::new(n).pattern(pattern).sample(s, jitter)
}

/// Correlated multi-jittered sets of n points: the grid and the permutations' lengths.
#[derive(Clone, Copy, Debug)]
pub struct Cmj {
    n: Permutation,
    m: Permutation,
    rows: Permutation,
    /// ⌈2⁶⁴ / m⌉, to divide by m with a multiplication (exact for every 32-bit dividend);
    /// 0 for m = 1.
    by_m: u64,
}

impl Cmj {
    /// The sets of `n` points (at least one).
    pub fn new(n: u32) -> Cmj {
        let n = n.max(1);
        let m = ((n as f32).sqrt() as u32).max(1);
        let by_m = if m == 1 { 0 } else { u64::MAX / m as u64 + 1 };
        Cmj { n: Permutation::new(n), m: Permutation::new(m), rows: Permutation::new(n.div_ceil(m)), by_m }
    }

    /// The set numbered `pattern`. A set of at most 256 points (`TABLED`) has its three
    /// permutations computed whole, once: its n samples then cost n + m + ⌈n/m⌉ evaluations of
    /// the hash, independent of each other, against about 3n one sample at a time.
    pub fn pattern(&self, pattern: u32) -> CmjPattern {
        let s = self.n.numbered(pattern.wrapping_mul(0x51633e2d));
        let x = self.m.numbered(pattern.wrapping_mul(0x68bc21eb));
        let y = self.rows.numbered(pattern.wrapping_mul(0x02e5be93));
        let tables = (self.n.len as usize <= TABLED).then(|| {
            let mut t = Tables { s: [0; TABLED], x: [0; TABLED_SIDE], y: [0; TABLED_SIDE] };
            s.fill(&mut t.s[..self.n.len as usize]);
            x.fill(&mut t.x[..self.m.len as usize]);
            y.fill(&mut t.y[..self.rows.len as usize]);
            t
        });
        CmjPattern { of: *self, s, x, y, tables }
    }

    /// (s / m, s mod m).
    #[inline]
    fn div_m(&self, s: u32) -> (u32, u32) {
        if self.by_m == 0 {
            return (s, 0);
        }
        let q = ((s as u128 * self.by_m as u128) >> 64) as u32;
        (q, s - q * self.m.len)
    }
}

/// The most points of a set whose permutations [`Cmj::pattern`] computes whole, and the most
/// columns or rows such a set's grid has (m = ⌊√n⌋ ≤ 16, ⌈n/m⌉ ≤ 16 + 1).
const TABLED: usize = 256;
const TABLED_SIDE: usize = 17;

/// A set's three permutations whole.
#[derive(Clone, Copy, Debug)]
struct Tables {
    s: [u32; TABLED],
    x: [u32; TABLED_SIDE],
    y: [u32; TABLED_SIDE],
}

/// One correlated multi-jittered set of points: [`cmj`] with a fixed n and pattern.
#[derive(Clone, Copy, Debug)]
pub struct CmjPattern {
    of: Cmj,
    s: Numbered,
    x: Numbered,
    y: Numbered,
    /// The permutations whole, for a small set.
    tables: Option<Tables>,
}

impl CmjPattern {
    /// Sample `s` (taken modulo n), `jitter` placing it within its cell.
    #[inline]
    pub fn sample(&self, s: u32, jitter: Vec2) -> Vec2 {
        let (n, m, rows) = (self.of.n.len, self.of.m.len, self.of.rows.len);
        let s = if s < n { s } else { s % n };
        let (s, (sx, sy)) = match &self.tables {
            Some(t) => {
                let s = t.s[s as usize];
                let (q, r) = self.of.div_m(s);
                (s, (t.x[r as usize], t.y[q as usize]))
            }
            None => {
                let s = self.s.at(s);
                let (q, r) = self.of.div_m(s);
                (s, (self.x.at(r), self.y.at(q)))
            }
        };
        let x = (sx as f32 + (sy as f32 + jitter.x) / rows as f32) / m as f32;
        let y = (s as f32 + jitter.y) / n as f32;
        Vec2::new(x.min(1.0 - f32::EPSILON), y.min(1.0 - f32::EPSILON))
    }
}

/// A density on [0, 1]² proportional to the bilinear interpolant of a `width` × `height` grid
/// of non-negative values, node (x, y) at (x / (width − 1), y / (height − 1)) (the corner nodes
/// on the corners of the square), sampled by hierarchical sample warping: Mitsuba 3's
/// `Hierarchical2D` (include/mitsuba/core/distr_2d.h), what its `envmap` emitter samples with.
///
/// A descent from a 2 × 2 top level through a MIP pyramid of patch integrals picks one
/// bilinear patch with probability equal to its share of the integral, rescaling the sample at
/// each level; inside the patch the marginal in y and the conditional in x (both linear) are
/// inverted in closed form. The map is a bijection of [0, 1]² with low distortion, and
/// [`Bilinear2D::invert`] is its inverse. Negative or non-finite values count as 0.
#[derive(Clone, Debug, PartialEq)]
pub struct Bilinear2D {
    /// Number of nodes along x and y (≥ 2 each).
    width: usize,
    height: usize,
    /// The node values scaled so that their interpolant integrates to 1 over [0, 1]² (the
    /// density), row-major; all zero when the grid is.
    density: Vec<f32>,
    /// `levels[0]`: the integral of each patch, `levels[k]`: sums of 2 × 2 blocks of
    /// `levels[k − 1]`, each zero-padded to even sizes, up to a 2 × 2 top level.
    levels: Vec<Level>,
    /// Integral over [0, 1]² of the interpolant of the values as given (their mean over the
    /// square); 0 for an all-zero grid, which samples nothing.
    pub integral: f32,
}

#[derive(Clone, Debug, PartialEq)]
struct Level {
    width: usize,
    data: Vec<f32>,
}

impl Level {
    fn quad(&self, x: usize, y: usize) -> [f32; 4] {
        let at = |x: usize, y: usize| self.data[y * self.width + x];
        [at(x, y), at(x + 1, y), at(x, y + 1), at(x + 1, y + 1)]
    }
}

/// Inverse CDF on [0, 1] of the density ∝ a linear function from `a` at 0 to `b` at 1 (a, b ≥
/// 0): the root of (b − a) x²/2 + a x = u (a + b)/2, written without cancellation (exact u
/// for a = b, √u for a = 0).
fn linear_to_interval(a: f32, b: f32, u: f32) -> f32 {
    let sum = a + b;
    if sum <= 0.0 {
        return u;
    }
    (u * sum / (a + (a * a + (b * b - a * a) * u).max(0.0).sqrt())).clamp(0.0, 1.0)
}

/// The CDF that [`linear_to_interval`] inverts.
fn interval_to_linear(a: f32, b: f32, x: f32) -> f32 {
    let sum = a + b;
    if sum <= 0.0 {
        return x;
    }
    (x * ((2.0 - x) * a + x * b) / sum).clamp(0.0, 1.0)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

impl Bilinear2D {
    /// `values` is row-major, `width` × `height` nodes, both at least 2.
    pub fn new(values: &[f32], width: usize, height: usize) -> Self {
        assert!(width >= 2 && height >= 2 && values.len() == width * height, "Bilinear2D needs at least 2 × 2 nodes");
        let values: Vec<f32> = values.iter().map(|&v| if v.is_finite() && v > 0.0 { v } else { 0.0 }).collect();
        let (px, py) = (width - 1, height - 1);
        // Patch integrals (mean of the four corners), summed in f64 for the normalisation.
        let mut patches = vec![0.0f64; px * py];
        let mut sum = 0.0f64;
        for y in 0..py {
            for x in 0..px {
                let i = y * width + x;
                let avg = 0.25 * (values[i] as f64 + values[i + 1] as f64 + values[i + width] as f64 + values[i + width + 1] as f64);
                patches[y * px + x] = avg;
                sum += avg;
            }
        }
        let integral = (sum / (px * py) as f64) as f32;
        let scale = if sum > 0.0 { (px * py) as f64 / sum } else { 0.0 };
        let density = values.iter().map(|&v| (v as f64 * scale) as f32).collect();
        // The pyramid: ⌈log₂ max(px, py)⌉ levels above the patches.
        let depth = usize::BITS - (px.max(py) - 1).leading_zeros();
        let mut levels: Vec<Level> = Vec::with_capacity(depth as usize);
        let (mut w, mut h) = (px, py);
        for _ in 0..depth {
            let (pw, ph) = (w + (w & 1), h + (h & 1));
            let mut data = vec![0.0f32; pw * ph];
            for y in 0..h {
                for x in 0..w {
                    data[y * pw + x] = match levels.last() {
                        None => (patches[y * px + x] * scale) as f32,
                        Some(below) => below.quad(2 * x, 2 * y).iter().sum(),
                    };
                }
            }
            levels.push(Level { width: pw, data });
            (w, h) = (pw / 2, ph / 2);
        }
        Bilinear2D { width, height, density, levels, integral }
    }

    fn corners(&self, x: usize, y: usize) -> [f32; 4] {
        let i = y * self.width + x;
        let d = &self.density;
        [d[i], d[i + 1], d[i + self.width], d[i + self.width + 1]]
    }

    /// The patch holding `p` (clamped into the square) and `p`'s position within it.
    fn locate(&self, p: Vec2) -> (usize, usize, Vec2) {
        let (px, py) = (self.width - 1, self.height - 1);
        let q = p.clamp(Vec2::ZERO, Vec2::ONE) * Vec2::new(px as f32, py as f32);
        let (x, y) = ((q.x as usize).min(px - 1), (q.y as usize).min(py - 1));
        (x, y, (q - Vec2::new(x as f32, y as f32)).clamp(Vec2::ZERO, Vec2::ONE))
    }

    /// Warps a uniform sample of [0, 1]² to the density; returns (point, density there).
    /// `None` for an all-zero grid or a point of zero density.
    pub fn sample(&self, u: Vec2) -> Option<(Vec2, f32)> {
        if self.integral <= 0.0 {
            return None;
        }
        let mut s = u.clamp(Vec2::ZERO, Vec2::ONE);
        let (mut ox, mut oy) = (0usize, 0usize);
        for level in self.levels.iter().rev() {
            (ox, oy) = (2 * ox, 2 * oy);
            let [v00, v10, v01, v11] = level.quad(ox, oy);
            // The row (never one of zero weight), then the column within it.
            let (r0, r1) = (v00 + v10, v01 + v11);
            let sy = s.y * (r0 + r1);
            let (c0, c1) = if r0 <= 0.0 || (r1 > 0.0 && sy > r0) {
                oy += 1;
                s.y = (sy - r0) / r1;
                (v01, v11)
            } else {
                s.y = sy / r0;
                (v00, v10)
            };
            let sx = s.x * (c0 + c1);
            if c0 <= 0.0 || (c1 > 0.0 && sx > c0) {
                ox += 1;
                s.x = (sx - c0) / c1;
            } else {
                s.x = sx / c0;
            }
            s = s.clamp(Vec2::ZERO, Vec2::ONE);
        }
        let (px, py) = (self.width - 1, self.height - 1);
        let (ox, oy) = (ox.min(px - 1), oy.min(py - 1));
        let [v00, v10, v01, v11] = self.corners(ox, oy);
        let y = linear_to_interval(v00 + v10, v01 + v11, s.y);
        let (c0, c1) = (lerp(v00, v01, y), lerp(v10, v11, y));
        let x = linear_to_interval(c0, c1, s.x);
        let pdf = lerp(c0, c1, x);
        let p = Vec2::new((ox as f32 + x) / px as f32, (oy as f32 + y) / py as f32).min(Vec2::ONE);
        (pdf > 0.0 && pdf.is_finite()).then_some((p, pdf))
    }

    /// Density at `p` (clamped into the square): the bilinear interpolant of the normalised
    /// values.
    pub fn pdf(&self, p: Vec2) -> f32 {
        let (x, y, t) = self.locate(p);
        let [v00, v10, v01, v11] = self.corners(x, y);
        lerp(lerp(v00, v10, t.x), lerp(v01, v11, t.x), t.y)
    }

    /// The uniform sample that [`Bilinear2D::sample`] maps to `p` (for points of positive
    /// density: the map is a bijection there).
    pub fn invert(&self, p: Vec2) -> Vec2 {
        let (mut ox, mut oy, t) = self.locate(p);
        let [v00, v10, v01, v11] = self.corners(ox, oy);
        let (c0, c1) = (lerp(v00, v01, t.y), lerp(v10, v11, t.y));
        let mut s = Vec2::new(interval_to_linear(c0, c1, t.x), interval_to_linear(v00 + v10, v01 + v11, t.y));
        for level in &self.levels {
            let [v00, v10, v01, v11] = level.quad(ox & !1, oy & !1);
            let (r0, r1) = (v00 + v10, v01 + v11);
            let (odd_x, odd_y) = (ox & 1 == 1, oy & 1 == 1);
            let (c0, c1) = if odd_y { (v01, v11) } else { (v00, v10) };
            let (dy, dx) = (r0 + r1, c0 + c1);
            s.y = if dy > 0.0 { (if odd_y { r0 + s.y * r1 } else { s.y * r0 }) / dy } else { s.y };
            s.x = if dx > 0.0 { (if odd_x { c0 + s.x * c1 } else { s.x * c0 }) / dx } else { s.x };
            s = s.clamp(Vec2::ZERO, Vec2::ONE);
            (ox, oy) = (ox / 2, oy / 2);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;

    fn u2(i: u64) -> Vec2 {
        Vec2::new(uniform(1, i, 0), uniform(1, i, 1))
    }

    #[test]
    fn warps_land_where_they_should() {
        for i in 0..10_000 {
            let d = cosine_hemisphere(u2(i));
            assert!((d.length() - 1.0).abs() < 1e-4 && d.z >= 0.0);
            assert!((uniform_sphere(u2(i)).length() - 1.0).abs() < 1e-4);
            let (a, b) = uniform_triangle(u2(i));
            assert!(a >= 0.0 && b >= 0.0 && a + b <= 1.0 + 1e-6);
        }
    }

    #[test]
    fn cosine_hemisphere_mean_cosine_is_two_thirds() {
        let n = 200_000;
        let mean: f64 = (0..n).map(|i| cosine_hemisphere(u2(i)).z as f64).sum::<f64>() / n as f64;
        assert!((mean - 2.0 / 3.0).abs() < 0.003, "{mean}");
    }

    #[test]
    fn distributions_sample_in_proportion_and_skip_zero_cells() {
        let d = Distribution1D::new(&[0.0, 1.0, 3.0, 0.0]);
        let mut counts = [0usize; 4];
        let n = 100_000;
        for i in 0..n {
            let (x, pdf, cell) = d.sample_continuous(uniform(3, i, 0));
            assert!((cell as f32 / 4.0..(cell + 1) as f32 / 4.0).contains(&x));
            assert!(pdf > 0.0);
            counts[cell] += 1;
        }
        assert_eq!((counts[0], counts[3]), (0, 0));
        assert!((counts[2] as f64 / n as f64 - 0.75).abs() < 0.01);
        assert!((d.pdf_cell(2) - 3.0).abs() < 1e-6, "density integrates to 1 over [0,1)");
        let zero = Distribution1D::new(&[0.0, 0.0]);
        assert_eq!(zero.pdf_cell(1), 1.0);
    }

    /// Kensler's permutation as the paper writes it around its hash round: the walk, then
    /// `(i + p) mod len` with a division.
    fn permute_as_written(mut i: u32, len: u32, p: u32) -> u32 {
        let round = Permutation::new(len).numbered(p);
        loop {
            i = round.hash(i);
            if i < len.max(1) {
                return (i.wrapping_add(p)) % len.max(1);
            }
        }
    }

    fn cmj_as_written(s: u32, n: u32, pattern: u32, jitter: Vec2) -> Vec2 {
        let n = n.max(1);
        let m = ((n as f32).sqrt() as u32).max(1);
        let rows = n.div_ceil(m);
        let s = permute_as_written(s % n, n, pattern.wrapping_mul(0x51633e2d));
        let sx = permute_as_written(s % m, m, pattern.wrapping_mul(0x68bc21eb));
        let sy = permute_as_written(s / m, rows, pattern.wrapping_mul(0x02e5be93));
        let x = (sx as f32 + (sy as f32 + jitter.x) / rows as f32) / m as f32;
        let y = (s as f32 + jitter.y) / n as f32;
        Vec2::new(x.min(1.0 - f32::EPSILON), y.min(1.0 - f32::EPSILON))
    }

    #[test]
    fn the_precomputed_cmj_gives_the_papers_points_bit_for_bit() {
        // Patterns whose sums with i wrap past 2³² included (0xffff_fff0 and up).
        let patterns = [0u32, 1, 77, 0x5bd1_e995, 0xdead_beef, 0xffff_fff0, 0xffff_ffff];
        for n in (1u32..=70).chain([96, 100, 255, 256, 1000, 1024, 4097, 65536]) {
            for &pattern in &patterns {
                let set = Cmj::new(n).pattern(pattern);
                for s in (0..n.min(300)).chain([n, n + 3, 2 * n + 1]) {
                    let j = u2(s as u64 * 31 + n as u64);
                    assert_eq!(set.sample(s, j), cmj_as_written(s, n, pattern, j), "n {n}, pattern {pattern:#x}, s {s}");
                    assert_eq!(permute(s % n, n, pattern), permute_as_written(s % n, n, pattern));
                }
            }
        }
        // Lengths not a power of two near 2³², where the mask and the wrap matter most.
        for len in [3u32, 1 << 20, (1 << 31) + 5, u32::MAX] {
            for &pattern in &patterns {
                for i in [0u32, 1, 2] {
                    assert_eq!(permute(i, len, pattern), permute_as_written(i, len, pattern), "len {len}");
                }
            }
        }
    }

    #[test]
    fn permutations_are_bijections_and_cmj_points_are_stratified() {
        for len in [1u32, 2, 7, 16, 33, 100] {
            for pattern in [0u32, 1, 0xdead_beef] {
                let mut seen: Vec<u32> = (0..len).map(|i| permute(i, len, pattern)).collect();
                seen.sort_unstable();
                assert_eq!(seen, (0..len).collect::<Vec<_>>(), "len {len}");
            }
        }
        for n in [1u32, 5, 16, 64, 90] {
            for pattern in [3u32, 77] {
                let pts: Vec<Vec2> = (0..n).map(|s| cmj(s, n, pattern, u2(s as u64 + 1000 * n as u64))).collect();
                assert!(pts.iter().all(|p| (0.0..1.0).contains(&p.x) && (0.0..1.0).contains(&p.y)));
                // One point per 1/n strip along y, per cell of the m × ⌈n/m⌉ grid (when it has n cells)
                // and per fine strip along x.
                let mut rows: Vec<u32> = pts.iter().map(|p| (p.y * n as f32) as u32).collect();
                rows.sort_unstable();
                assert_eq!(rows, (0..n).collect::<Vec<_>>());
                let m = (n as f32).sqrt() as u32;
                let cols = n.div_ceil(m);
                let mut cells: Vec<(u32, u32)> = pts.iter().map(|p| ((p.x * m as f32) as u32, (p.y * cols as f32) as u32)).collect();
                cells.sort_unstable();
                cells.dedup();
                if m * cols == n {
                    assert_eq!(cells.len() as u32, n, "n = {n}");
                }
                let mut strips: Vec<u32> = pts.iter().map(|p| (p.x * (m * cols) as f32) as u32).collect();
                strips.sort_unstable();
                strips.dedup();
                assert_eq!(strips.len() as u32, n, "one point per fine strip along x, n = {n}");
            }
        }
    }

    #[test]
    fn reused_discrete_samples_rescale_within_their_cell() {
        let d = Distribution1D::new(&[1.0, 3.0]);
        let (i, p, du) = d.sample_discrete_reuse(0.25 + 0.75 * 0.5);
        assert_eq!(i, 1);
        assert!((p - 0.75).abs() < 1e-6 && (du - 0.5).abs() < 1e-6, "{p} {du}");
        let (i, _, du) = d.sample_discrete_reuse(0.125);
        assert!(i == 0 && (du - 0.5).abs() < 1e-6);
    }

    #[test]
    fn bilinear_density_of_a_ramp_is_sampled_by_its_inverse_cdf() {
        // Values 0 on the left, 1 on the right: density 2x, x = √u, y uniform.
        let d = Bilinear2D::new(&[0.0, 1.0, 0.0, 1.0], 2, 2);
        assert_eq!(d.integral, 0.5);
        let (p, pdf) = d.sample(Vec2::new(0.25, 0.7)).unwrap();
        assert!((p - Vec2::new(0.5, 0.7)).length() < 1e-6 && (pdf - 1.0).abs() < 1e-6, "{p} {pdf}");
        assert!((d.pdf(Vec2::new(0.75, 0.1)) - 1.5).abs() < 1e-6);
        assert!((d.invert(p) - Vec2::new(0.25, 0.7)).length() < 1e-6);
        // An all-zero grid samples nothing.
        let zero = Bilinear2D::new(&[0.0; 6], 3, 2);
        assert!(zero.sample(Vec2::splat(0.5)).is_none() && zero.integral == 0.0);
    }

    /// A random grid: `w` × `h` nodes, about a third of them zero, one spike.
    fn random_grid(w: usize, h: usize, seed: u64) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let r = uniform(seed, i as u64, 0);
                if i == (seed as usize) % (w * h) {
                    1e4
                } else if r < 0.3 {
                    0.0
                } else {
                    r * 10.0
                }
            })
            .collect()
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(if cfg!(debug_assertions) { 16 } else { 128 }))]

        #[test]
        fn bilinear_density_integrates_to_one_and_its_warp_inverts(w in 2usize..40, h in 2usize..24, seed in 0u64..1_000_000) {
            let d = Bilinear2D::new(&random_grid(w, h, seed), w, h);
            // The centre value of a bilinear patch times its area is its exact integral.
            let (px, py) = ((w - 1) as f32, (h - 1) as f32);
            let mut integral = 0.0f64;
            for y in 0..h - 1 {
                for x in 0..w - 1 {
                    integral += d.pdf(Vec2::new((x as f32 + 0.5) / px, (y as f32 + 0.5) / py)) as f64 / (px * py) as f64;
                }
            }
            proptest::prop_assert!((integral - 1.0).abs() < 1e-4, "{}", integral);
            for i in 0..200 {
                let u = Vec2::new(uniform(seed, i, 1), uniform(seed, i, 2));
                let Some((p, pdf)) = d.sample(u) else { continue };
                proptest::prop_assert!((0.0..=1.0).contains(&p.x) && (0.0..=1.0).contains(&p.y));
                proptest::prop_assert!((d.pdf(p) - pdf).abs() <= 1e-3 * pdf, "pdf {} vs sampled {}", d.pdf(p), pdf);
                // The warp is a bijection where the density is not vanishing.
                if pdf > 1e-2 {
                    let back = d.invert(p);
                    proptest::prop_assert!((back - u).abs().max_element() < 2e-3, "{} → {} → {}", u, p, back);
                }
            }
        }
    }

    #[test]
    fn bilinear_samples_fall_in_proportion_to_the_density() {
        // 5 × 4 nodes with zeros, histogrammed on a 7 × 6 grid not aligned with the patches.
        let values = [0.0, 1.0, 4.0, 0.0, 2.0, 3.0, 0.0, 0.5, 8.0, 1.0, 0.0, 0.0, 2.0, 6.0, 1.0, 5.0, 1.0, 0.0, 0.0, 3.0];
        let d = Bilinear2D::new(&values, 5, 4);
        let (bx, by, n) = (7usize, 6usize, 400_000u64);
        let mut counts = vec![0u64; bx * by];
        for i in 0..n {
            let (p, _) = d.sample(u2(i + 77)).unwrap();
            counts[((p.y * by as f32) as usize).min(by - 1) * bx + ((p.x * bx as f32) as usize).min(bx - 1)] += 1;
        }
        let k = 64;
        for j in 0..by {
            for i in 0..bx {
                let mut expect = 0.0f64;
                for b in 0..k {
                    for a in 0..k {
                        let q = Vec2::new(
                            (i as f32 + (a as f32 + 0.5) / k as f32) / bx as f32,
                            (j as f32 + (b as f32 + 0.5) / k as f32) / by as f32,
                        );
                        expect += d.pdf(q) as f64;
                    }
                }
                expect /= (k * k * bx * by) as f64;
                let got = counts[j * bx + i] as f64 / n as f64;
                let sigma = (expect * (1.0 - expect) / n as f64).sqrt();
                assert!((got - expect).abs() < 5.0 * sigma + 2e-4, "bin ({i}, {j}): {got} vs {expect}");
            }
        }
    }
}
