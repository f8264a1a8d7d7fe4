//! Rotating real spherical-harmonic coefficients (`math::sh`'s basis): pipeline 2's transfer
//! lives in each vertex's frame ([S] 5.3.3), and light expressed in SH moves between frames.
//!
//! A rotation maps each band onto itself, so it is one (2l + 1)² block per band. Each block is
//! found by least squares on 64 directions spread over the sphere (a Fibonacci lattice): the
//! rotated coefficients g of f satisfy Σ g_m Y_lm(d) = Σ c_m Y_lm(Rᵀ d) at every d, so the block
//! is M = (AᵀA)⁻¹ AᵀB with A = Y_l(d_i) and B = Y_l(Rᵀ d_i), in f64 (exact up to rounding: a
//! band's functions are determined by their values at more points than it has functions).

use super::sh::{sh_basis, sh_count};
use glam::{Mat3, Vec3};

/// Directions the blocks are fitted on.
const FIT_DIRECTIONS: usize = 64;

/// The rotation of `bands`-band coefficients by a rotation matrix.
#[derive(Clone, Debug)]
pub struct ShRotation {
    bands: usize,
    /// Per band l, the (2l + 1)² block, row-major.
    blocks: Vec<Vec<f64>>,
}

/// A Fibonacci lattice of `n` unit directions.
fn spread(n: usize) -> Vec<Vec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (2 * i + 1) as f64 / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
        })
        .collect()
}

/// Solves `a` x = `b` (n × n, n × k, row-major) by Gaussian elimination with partial pivoting
/// (a zero pivot gives 0 in its row).
pub fn solve(mut a: Vec<f64>, mut b: Vec<f64>, n: usize, k: usize) -> Vec<f64> {
    for col in 0..n {
        let p = (col..n).max_by(|&x, &y| a[x * n + col].abs().total_cmp(&a[y * n + col].abs())).unwrap_or(col);
        for c in 0..n {
            a.swap(col * n + c, p * n + c);
        }
        for c in 0..k {
            b.swap(col * k + c, p * k + c);
        }
        let d = a[col * n + col];
        for row in 0..n {
            if row != col && d != 0.0 {
                let f = a[row * n + col] / d;
                for c in 0..n {
                    a[row * n + c] -= f * a[col * n + c];
                }
                for c in 0..k {
                    b[row * k + c] -= f * b[col * k + c];
                }
            }
        }
    }
    for row in 0..n {
        let d = a[row * n + row];
        for c in 0..k {
            b[row * k + c] = if d != 0.0 { b[row * k + c] / d } else { 0.0 };
        }
    }
    b
}

impl ShRotation {
    /// The rotation of `bands`-band coefficients that turns a function by `r` (g(ω) = f(Rᵀω)).
    pub fn new(bands: usize, r: Mat3) -> ShRotation {
        let dirs = spread(FIT_DIRECTIONS);
        let a_all: Vec<Vec<f32>> = dirs.iter().map(|&d| sh_basis(bands, d)).collect();
        let b_all: Vec<Vec<f32>> = dirs.iter().map(|&d| sh_basis(bands, (r.transpose() * d).normalize())).collect();
        let blocks = (0..bands)
            .map(|l| {
                let (lo, w) = (l * l, 2 * l + 1);
                // Normal equations: (AᵀA) M = AᵀB over the band's columns.
                let mut ata = vec![0.0f64; w * w];
                let mut atb = vec![0.0f64; w * w];
                for (ya, yb) in a_all.iter().zip(&b_all) {
                    for p in 0..w {
                        for q in 0..w {
                            ata[p * w + q] += ya[lo + p] as f64 * ya[lo + q] as f64;
                            atb[p * w + q] += ya[lo + p] as f64 * yb[lo + q] as f64;
                        }
                    }
                }
                solve(ata, atb, w, w)
            })
            .collect();
        ShRotation { bands, blocks }
    }

    /// The rotated coefficients of `c` (`bands`² of them).
    pub fn apply(&self, c: &[f32]) -> Vec<f32> {
        assert_eq!(c.len(), sh_count(self.bands), "{} coefficients for {} bands", c.len(), self.bands);
        let mut out = vec![0.0f32; c.len()];
        for (l, m) in self.blocks.iter().enumerate() {
            let (lo, w) = (l * l, 2 * l + 1);
            for p in 0..w {
                out[lo + p] = (0..w).map(|q| m[p * w + q] * c[lo + q] as f64).sum::<f64>() as f32;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;
    use crate::math::sh::sh_eval;

    fn rotation(seed: u64) -> Mat3 {
        let u = |d| uniform(seed, 0, d);
        let axis = crate::math::sampling::uniform_sphere(glam::Vec2::new(u(0), u(1)));
        Mat3::from_axis_angle(axis, u(2) * std::f32::consts::TAU)
    }

    fn coefficients(bands: usize, seed: u64) -> Vec<f32> {
        (0..sh_count(bands)).map(|k| uniform(seed, k as u64, 3) * 2.0 - 1.0).collect()
    }

    #[test]
    fn a_rotated_function_is_the_function_turned() {
        for seed in 0..8 {
            let (r, c) = (rotation(seed), coefficients(4, 100 + seed));
            let g = ShRotation::new(4, r).apply(&c);
            for k in 0..100 {
                let d = crate::math::sampling::uniform_sphere(glam::Vec2::new(uniform(5, k, 0), uniform(5, k, 1)));
                let (a, b) = (sh_eval(&g, d), sh_eval(&c, r.transpose() * d));
                assert!((a - b).abs() < 1e-4, "rotation {seed}, {d}: {a} vs {b}");
            }
            // Each band keeps its energy (the blocks are orthogonal).
            for l in 0..4 {
                let e = |v: &[f32]| v[l * l..(l + 1) * (l + 1)].iter().map(|x| x * x).sum::<f32>();
                assert!((e(&g) - e(&c)).abs() < 1e-4 * (1.0 + e(&c)), "band {l}");
            }
        }
    }

    #[test]
    fn the_identity_changes_nothing_and_rotations_compose() {
        let c = coefficients(4, 9);
        let same = ShRotation::new(4, Mat3::IDENTITY).apply(&c);
        assert!(same.iter().zip(&c).all(|(a, b)| (a - b).abs() < 1e-5));
        let (r1, r2) = (rotation(1), rotation(2));
        let twice = ShRotation::new(4, r2).apply(&ShRotation::new(4, r1).apply(&c));
        let once = ShRotation::new(4, r2 * r1).apply(&c);
        assert!(twice.iter().zip(&once).all(|(a, b)| (a - b).abs() < 1e-4), "{twice:?} vs {once:?}");
        // About z, band 0 and the zonal terms (m = 0) stay.
        let z = ShRotation::new(4, Mat3::from_rotation_z(0.7)).apply(&c);
        for k in [0, 2, 6, 12] {
            assert!((z[k] - c[k]).abs() < 1e-5, "k {k}");
        }
    }
}
