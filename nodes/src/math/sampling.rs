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
pub fn permute(mut i: u32, len: u32, pattern: u32) -> u32 {
    let p = pattern;
    let mut w = len.max(1) - 1;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    loop {
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
        if i < len.max(1) {
            return (i.wrapping_add(p)) % len.max(1);
        }
    }
}

/// Sample `s` of `n` correlated multi-jittered points in [0, 1)² (Kensler 2013): the n points
/// of one `pattern` fall one per cell of an m × ⌈n/m⌉ grid (m = ⌊√n⌋) and one per 1/n strip
/// along each axis. `jitter` (two uniforms in [0, 1)) places the point within its cell.
pub fn cmj(s: u32, n: u32, pattern: u32, jitter: Vec2) -> Vec2 {
    let n = n.max(1);
    let m = ((n as f32).sqrt() as u32).max(1);
    let rows = n.div_ceil(m);
    let s = permute(s % n, n, pattern.wrapping_mul(0x51633e2d));
    let sx = permute(s % m, m, pattern.wrapping_mul(0x68bc21eb));
    let sy = permute(s / m, rows, pattern.wrapping_mul(0x02e5be93));
    let x = (sx as f32 + (sy as f32 + jitter.x) / rows as f32) / m as f32;
    let y = (s as f32 + jitter.y) / n as f32;
    Vec2::new(x.min(1.0 - f32::EPSILON), y.min(1.0 - f32::EPSILON))
}

/// A piecewise-constant 2-D distribution over [0, 1)²: a marginal over rows (v) and a
/// conditional per row (u). Used for environment-map importance sampling.
#[derive(Clone, Debug)]
pub struct Distribution2D {
    pub rows: Vec<Distribution1D>,
    pub marginal: Distribution1D,
}

impl Distribution2D {
    /// `func` is row-major, `width` × `height`.
    pub fn new(func: &[f32], width: usize, height: usize) -> Self {
        let rows: Vec<Distribution1D> = (0..height).map(|y| Distribution1D::new(&func[y * width..(y + 1) * width])).collect();
        let marginal = Distribution1D::new(&rows.iter().map(|r| r.integral).collect::<Vec<_>>());
        Distribution2D { rows, marginal }
    }

    /// Returns ((u, v), density over [0, 1)²).
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (v, pdf_v, row) = self.marginal.sample_continuous(u.y);
        let (x, pdf_u, _) = self.rows[row].sample_continuous(u.x);
        (Vec2::new(x, v), pdf_u * pdf_v)
    }

    /// Density at (u, v).
    pub fn pdf(&self, uv: Vec2) -> f32 {
        let h = self.marginal.len();
        let row = ((uv.y * h as f32) as usize).min(h - 1);
        let w = self.rows[row].len();
        let col = ((uv.x * w as f32) as usize).min(w - 1);
        self.rows[row].pdf_cell(col) * self.marginal.pdf_cell(row)
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
    fn two_d_density_integrates_to_one() {
        let f: Vec<f32> = (0..32).map(|i| (i % 7) as f32 + if i == 9 { 100.0 } else { 0.0 }).collect();
        let d = Distribution2D::new(&f, 8, 4);
        let mut integral = 0.0;
        for y in 0..4 {
            for x in 0..8 {
                integral += d.pdf(Vec2::new((x as f32 + 0.5) / 8.0, (y as f32 + 0.5) / 4.0)) / 32.0;
            }
        }
        assert!((integral - 1.0).abs() < 1e-4, "{integral}");
        for i in 0..1000 {
            let (uv, pdf) = d.sample(u2(i));
            assert!((pdf - d.pdf(uv)).abs() < 1e-3 * pdf.max(1.0), "{pdf} vs {}", d.pdf(uv));
        }
    }
}
