//! Real spherical harmonics (SH) to any number of bands.
//!
//! Normalisation: orthonormal real SH on the unit sphere, ∫ Y_k Y_j dω = δ_kj, without the
//! Condon–Shortley phase (Ramamoorthi & Hanrahan 2001, "An efficient representation for
//! irradiance environment maps", and Sloan's "Stupid SH tricks" up to that sign):
//!
//! - Y_l^0 = K_l^0 P_l^0(cos θ)
//! - Y_l^m = √2 K_l^m cos(mφ) P_l^m(cos θ) for m > 0
//! - Y_l^m = √2 K_l^|m| sin(|m|φ) P_l^|m|(cos θ) for m < 0
//!
//! with K_l^m = √((2l + 1)/(4π) · (l − m)!/(l + m)!), P_l^m the associated Legendre functions
//! without the (−1)^m phase, θ the angle from +z and φ the angle from +x toward +y. Coefficient
//! `k = l(l + 1) + m` (band `l` holds 2l + 1 of them; `bands` bands hold bands² coefficients).
//! The first three bands in Cartesian form (x, y, z of a unit direction):
//!
//! | k | l, m | Y |
//! |---|---|---|
//! | 0 | 0, 0 | 0.282095 = 1/(2√π) |
//! | 1, 2, 3 | 1, −1 / 0 / 1 | 0.488603 · y / z / x (= √(3/(4π))) |
//! | 4, 5 | 2, −2 / −1 | 1.092548 · xy / yz (= √(15/(4π))) |
//! | 6 | 2, 0 | 0.315392 · (3z² − 1) (= √(5/(16π))) |
//! | 7, 8 | 2, 1 / 2 | 1.092548 · xz, 0.546274 · (x² − y²) |
//!
//! The clamped cosine lobe max(0, n·ω) around a unit `n` has coefficients Â_l · Y_l^m(n)
//! (the addition theorem), with Â_0 = π, Â_1 = 2π/3, Â_2 = π/4, Â_l = 0 for odd l > 1 and
//! Â_l = 2π (−1)^(l/2 − 1) / ((l + 2)(l − 1)) · l! / (2^l ((l/2)!)²) for even l.

use glam::Vec3;
use std::f64::consts::PI;

/// Coefficients in `bands` bands: bands².
pub const fn sh_count(bands: usize) -> usize {
    bands * bands
}

/// Index of coefficient (l, m), −l ≤ m ≤ l.
pub const fn sh_index(l: usize, m: i32) -> usize {
    ((l * (l + 1)) as isize + m as isize) as usize
}

/// Y_0^0 = 1 / (2 √π).
pub const Y00: f32 = 0.282_094_8;
const Y1: f32 = 0.488_602_5; // √(3/(4π))
const Y2A: f32 = 1.092_548_4; // √(15/(4π))
const Y20: f32 = 0.315_391_57; // √(5/(16π))
const Y22: f32 = 0.546_274_2; // √(15/(16π))

/// The first three bands (9 coefficients) at unit `dir`; equal to `sh_basis(3, dir)`.
#[inline]
pub fn sh9(dir: Vec3) -> [f32; 9] {
    let Vec3 { x, y, z } = dir;
    [Y00, Y1 * y, Y1 * z, Y1 * x, Y2A * x * y, Y2A * y * z, Y20 * (3.0 * z * z - 1.0), Y2A * x * z, Y22 * (x * x - y * y)]
}

const Y30: f32 = 0.373_176_33; // √(7/(4π)) / 2
const Y31: f32 = 0.457_045_8; // √(21/(32π))
const Y32: f32 = 1.445_305_7; // √(105/(16π))
const Y33: f32 = 0.590_043_6; // √(35/(32π))

/// The first four bands (16 coefficients, pipeline 2's bounce light) at unit `dir`, in f32:
/// `sh_basis(4, dir)` within 2·10⁻⁶ (tested), a few times faster than the recurrences.
#[inline]
pub fn sh16(dir: Vec3) -> [f32; 16] {
    let Vec3 { x, y, z } = dir;
    let b = sh9(dir);
    let (x2, y2, z2) = (x * x, y * y, z * z);
    let s1 = Y31 * (5.0 * z2 - 1.0);
    [
        b[0],
        b[1],
        b[2],
        b[3],
        b[4],
        b[5],
        b[6],
        b[7],
        b[8],
        Y33 * (3.0 * x2 * y - y2 * y),
        Y32 * 2.0 * x * y * z,
        s1 * y,
        Y30 * z * (5.0 * z2 - 3.0),
        s1 * x,
        Y32 * z * (x2 - y2),
        Y33 * (x2 * x - 3.0 * x * y2),
    ]
}

/// All `bands`² basis functions at unit `dir`, in coefficient order.
pub fn sh_basis(bands: usize, dir: Vec3) -> Vec<f32> {
    let mut out = vec![0.0; sh_count(bands)];
    sh_basis_into(dir, &mut out);
    out
}

/// The basis at unit `dir` into `out`, whose length (a square) gives the band count.
/// Computed in f64 through the Legendre recurrences in Cartesian form (no trigonometry):
/// sinθ^m cos(mφ) and sinθ^m sin(mφ) are the real and imaginary parts of (x + iy)^m.
pub fn sh_basis_into(dir: Vec3, out: &mut [f32]) {
    if out.len() == 16 {
        out.copy_from_slice(&sh16(dir));
        return;
    }
    sh_recurrence_into(dir, out);
}

/// `sh_basis_into` through the recurrences, at any band count.
fn sh_recurrence_into(dir: Vec3, out: &mut [f32]) {
    let bands = bands_of(out.len());
    let (x, y, z) = (dir.x as f64, dir.y as f64, dir.z as f64);
    // (x + iy)^m, m = 0, 1, ...
    let (mut re, mut im) = (1.0f64, 0.0f64);
    // Q_m^m = (2m − 1)!!: P_l^m(z) = sinθ^m Q_l^m(z).
    let mut qmm = 1.0f64;
    for m in 0..bands {
        if m > 0 {
            let (r, i) = (re * x - im * y, re * y + im * x);
            re = r;
            im = i;
            qmm *= (2 * m - 1) as f64;
        }
        // Walk l = m, m + 1, ... with Q_l^m.
        let mut q_prev = 0.0f64; // Q_{l−2}^m
        let mut q = qmm; // Q_l^m
        for l in m..bands {
            if l == m + 1 {
                q_prev = q;
                q = z * (2 * m + 1) as f64 * qmm;
            } else if l > m + 1 {
                let next = ((2 * l - 1) as f64 * z * q - (l + m - 1) as f64 * q_prev) / (l - m) as f64;
                q_prev = q;
                q = next;
            }
            let k = norm_cached(l, m);
            if m == 0 {
                out[sh_index(l, 0)] = (k * q) as f32;
            } else {
                let s = std::f64::consts::SQRT_2 * k * q;
                out[sh_index(l, m as i32)] = (s * re) as f32;
                out[sh_index(l, -(m as i32))] = (s * im) as f32;
            }
        }
    }
}

/// Bands whose K_l^m are tabled (computed once by `norm`, the same bits).
const TABLED: usize = 8;

/// K_l^m from the table below `TABLED` bands, else computed.
fn norm_cached(l: usize, m: usize) -> f64 {
    static TABLE: std::sync::OnceLock<[[f64; TABLED]; TABLED]> = std::sync::OnceLock::new();
    if l < TABLED {
        TABLE.get_or_init(|| std::array::from_fn(|l| std::array::from_fn(|m| if m <= l { norm(l, m) } else { 0.0 })))[l][m]
    } else {
        norm(l, m)
    }
}

/// K_l^m = √((2l + 1)/(4π) · (l − m)!/(l + m)!).
fn norm(l: usize, m: usize) -> f64 {
    let mut ratio = 1.0f64; // (l − m)! / (l + m)!
    for i in (l - m + 1)..=(l + m) {
        ratio /= i as f64;
    }
    ((2 * l + 1) as f64 / (4.0 * PI) * ratio).sqrt()
}

/// Bands held by `n` coefficients; panics unless `n` is a square.
fn bands_of(n: usize) -> usize {
    let b = (n as f64).sqrt().round() as usize;
    assert_eq!(b * b, n, "an SH coefficient vector has a square length, not {n}");
    b
}

/// Â_l: the clamped cosine max(0, cos θ)'s zonal coefficient scaled by √(4π/(2l + 1)), so
/// that max(0, n·ω) = Σ_l Â_l Σ_m Y_l^m(n) Y_l^m(ω).
pub fn clamped_cosine_zonal(l: usize) -> f32 {
    match l {
        0 => std::f32::consts::PI,
        1 => 2.0 * std::f32::consts::PI / 3.0,
        _ if l % 2 == 1 => 0.0,
        _ => {
            let h = l / 2;
            // l! / (2^l (h!)²) = C(l, h) / 2^l
            let mut binom = 1.0f64;
            for i in 0..h {
                binom = binom * (l - i) as f64 / (i + 1) as f64;
            }
            let sign = if h % 2 == 1 { 1.0 } else { -1.0 };
            (2.0 * PI * sign / ((l + 2) * (l - 1)) as f64 * binom / 2f64.powi(l as i32)) as f32
        }
    }
}

/// Â_0, Â_1, Â_2 = π, 2π/3, π/4 spread over the 9 coefficients.
const A9: [f32; 9] = {
    let (a0, a1, a2) = (std::f32::consts::PI, 2.0 * std::f32::consts::PI / 3.0, std::f32::consts::PI / 4.0);
    [a0, a1, a1, a1, a2, a2, a2, a2, a2]
};

/// The clamped cosine max(0, n·ω) around unit `n` in 3 bands: Â_l Y_l^m(n).
#[inline]
pub fn sh9_clamped_cosine(n: Vec3) -> [f32; 9] {
    let y = sh9(n);
    std::array::from_fn(|k| A9[k] * y[k])
}

/// The clamped cosine max(0, n·ω) around unit `n` in `bands` bands.
pub fn sh_clamped_cosine(bands: usize, n: Vec3) -> Vec<f32> {
    let mut c = sh_basis(bands, n);
    for l in 0..bands {
        let a = clamped_cosine_zonal(l);
        for v in &mut c[l * l..(l + 1) * (l + 1)] {
            *v *= a;
        }
    }
    c
}

/// Σ_k c_k Y_k(dir) for unit `dir`; the band count follows from the length (a square).
pub fn sh_eval(coeffs: &[f32], dir: Vec3) -> f32 {
    if coeffs.len() == 9 {
        return sh9_eval(coeffs.try_into().expect("9"), dir);
    }
    let y = sh_basis(bands_of(coeffs.len()), dir);
    coeffs.iter().zip(&y).map(|(c, y)| c * y).sum()
}

/// Σ_k c_k Y_k(dir) in 3 bands.
#[inline]
pub fn sh9_eval(coeffs: &[f32; 9], dir: Vec3) -> f32 {
    sh9_dot(coeffs, &sh9(dir))
}

/// Σ_k c_k y_k for a basis `y` = `sh9(dir)` already evaluated (several functions, one
/// direction).
#[inline]
pub fn sh9_dot(coeffs: &[f32; 9], y: &[f32; 9]) -> f32 {
    coeffs.iter().zip(y).map(|(c, y)| c * y).sum()
}

/// `sh9_dot` per RGB channel.
#[inline]
pub fn sh9_dot_rgb(coeffs: &[Vec3; 9], y: &[f32; 9]) -> Vec3 {
    coeffs.iter().zip(y).fold(Vec3::ZERO, |acc, (c, y)| acc + *c * *y)
}

/// Σ_k c_k Y_k(dir) in 3 bands, per RGB channel.
#[inline]
pub fn sh9_eval_rgb(coeffs: &[Vec3; 9], dir: Vec3) -> Vec3 {
    sh9_dot_rgb(coeffs, &sh9(dir))
}

/// ∫ over the sphere of the function the coefficients stand for: c_0 · √(4π).
pub fn sh_integral(coeffs: &[f32]) -> f32 {
    coeffs.first().map_or(0.0, |c| c * (4.0 * std::f32::consts::PI).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;
    use glam::Quat;

    /// Gauss–Legendre nodes and weights on [−1, 1] (Newton on P_n).
    fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
        (0..n)
            .map(|i| {
                let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
                let mut dp = 1.0;
                for _ in 0..100 {
                    let (mut p0, mut p1) = (1.0f64, x);
                    for k in 2..=n {
                        let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                        p0 = p1;
                        p1 = p2;
                    }
                    dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                    let dx = p1 / dp;
                    x -= dx;
                    if dx.abs() < 1e-15 {
                        break;
                    }
                }
                (x, 2.0 / ((1.0 - x * x) * dp * dp))
            })
            .collect()
    }

    /// Directions and weights that integrate products of SH up to band 11 exactly
    /// (Gauss–Legendre in z, uniform in φ).
    fn sphere_quadrature() -> Vec<(Vec3, f64)> {
        let nphi = 24;
        gauss_legendre(12)
            .into_iter()
            .flat_map(|(z, w)| {
                (0..nphi).map(move |j| {
                    let phi = 2.0 * PI * (j as f64 + 0.5) / nphi as f64;
                    let s = (1.0 - z * z).sqrt();
                    (Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, z as f32), w * 2.0 * PI / nphi as f64)
                })
            })
            .collect()
    }

    fn random_dir(seed: u64, i: u64) -> Vec3 {
        let z = 1.0 - 2.0 * uniform(seed, i, 0);
        let phi = 2.0 * std::f32::consts::PI * uniform(seed, i, 1);
        let s = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(s * phi.cos(), s * phi.sin(), z)
    }

    #[test]
    fn the_basis_is_orthonormal_over_the_sphere_up_to_six_bands() {
        let q = sphere_quadrature();
        let bands = 6;
        let n = sh_count(bands);
        let ys: Vec<(Vec<f32>, f64)> = q.iter().map(|&(d, w)| (sh_basis(bands, d), w)).collect();
        for a in 0..n {
            for b in 0..n {
                let g: f64 = ys.iter().map(|(y, w)| y[a] as f64 * y[b] as f64 * w).sum();
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((g - want).abs() < 1e-5, "<Y{a}, Y{b}> = {g}");
            }
        }
    }

    #[test]
    fn the_nine_coefficient_fast_path_matches_the_general_basis_and_the_published_constants() {
        for i in 0..200 {
            let d = random_dir(3, i);
            let general = sh_basis(3, d);
            let fast = sh9(d);
            for k in 0..9 {
                assert!((general[k] - fast[k]).abs() < 2e-6, "dir {d}, k {k}: {} vs {}", general[k], fast[k]);
            }
            // The recurrences at 4 bands keep the first 9.
            let mut four = [0.0f32; 16];
            sh_recurrence_into(d, &mut four);
            assert!(four[..9].iter().zip(&general).all(|(a, b)| (a - b).abs() < 1e-7));
        }
        let d = Vec3::new(0.48, 0.6, 0.64);
        let want = [
            0.282095,
            0.488603 * 0.6,
            0.488603 * 0.64,
            0.488603 * 0.48,
            1.092548 * 0.48 * 0.6,
            1.092548 * 0.6 * 0.64,
            0.315392 * (3.0 * 0.64 * 0.64 - 1.0),
            1.092548 * 0.48 * 0.64,
            0.546274 * (0.48 * 0.48 - 0.6 * 0.6),
        ];
        for (k, (got, want)) in sh9(d).iter().zip(want).enumerate() {
            assert!((got - want).abs() < 2e-6, "k {k}");
        }
        // Band 3 at +z: only m = 0 is non-zero, Y_3^0(z) = √(7/(4π)).
        let y = sh_basis(4, Vec3::Z);
        assert!((y[sh_index(3, 0)] - (7.0 / (4.0 * std::f32::consts::PI)).sqrt()).abs() < 1e-6);
        assert!((9..16).filter(|&k| k != sh_index(3, 0)).all(|k| y[k].abs() < 1e-7));
    }

    #[test]
    fn the_sixteen_coefficient_fast_path_matches_the_recurrences() {
        for i in 0..500 {
            let d = random_dir(5, i);
            let mut want = [0.0f32; 16];
            sh_recurrence_into(d, &mut want);
            let got = sh16(d);
            for k in 0..16 {
                assert!((got[k] - want[k]).abs() < 2e-6, "dir {d}, k {k}: {} vs {}", got[k], want[k]);
            }
            assert_eq!(sh_basis(4, d), got.to_vec(), "four bands take the fast path");
        }
        // The constants against √((2l + 1)/(4π) · (l − m)!/(l + m)!) (× √2 for m ≠ 0) and
        // the leading factor of each Q_3^m: 1/2, 1/2 (of 15 z² − 3 = 3 (5 z² − 1)), 15, 15.
        let k = |m: usize| norm(3, m) * if m == 0 { 1.0 } else { std::f64::consts::SQRT_2 };
        for (c, want) in [(Y30, k(0) / 2.0), (Y31, k(1) * 1.5), (Y32, k(2) * 15.0), (Y33, k(3) * 15.0)] {
            assert!((c as f64 - want).abs() < 1e-7, "{c} vs {want}");
        }
    }

    #[test]
    fn the_zonal_clamped_cosine_coefficients_are_the_published_ones() {
        use std::f32::consts::PI;
        assert_eq!(clamped_cosine_zonal(0), PI);
        assert!((clamped_cosine_zonal(1) - 2.0 * PI / 3.0).abs() < 1e-6);
        assert!((clamped_cosine_zonal(2) - PI / 4.0).abs() < 1e-6);
        assert_eq!(clamped_cosine_zonal(3), 0.0);
        assert!((clamped_cosine_zonal(4) + PI / 24.0).abs() < 1e-6);
        assert!((clamped_cosine_zonal(6) - PI / 64.0).abs() < 1e-6);
    }

    #[test]
    fn the_clamped_cosine_projection_matches_numerical_projection_and_integrates_to_pi() {
        let q = sphere_quadrature();
        for i in 0..5 {
            let n = random_dir(11, i);
            // The lobe's kink limits the quadrature; a fine midpoint rule in z × φ instead.
            let bands = 4;
            let mut num = [0f64; 16];
            let (nz, nphi) = (300, 300);
            for a in 0..nz {
                let z = -1.0 + 2.0 * (a as f64 + 0.5) / nz as f64;
                let s = (1.0 - z * z).sqrt();
                for b in 0..nphi {
                    let phi = 2.0 * PI * (b as f64 + 0.5) / nphi as f64;
                    let w = Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, z as f32);
                    let f = n.dot(w).max(0.0) as f64;
                    if f > 0.0 {
                        let y = sh_basis(bands, w);
                        for k in 0..16 {
                            num[k] += f * y[k] as f64 * (2.0 / nz as f64) * (2.0 * PI / nphi as f64);
                        }
                    }
                }
            }
            let c = sh_clamped_cosine(bands, n);
            for k in 0..16 {
                assert!((c[k] as f64 - num[k]).abs() < 2e-3, "n {n}, k {k}: {} vs {}", c[k], num[k]);
            }
            let c9 = sh9_clamped_cosine(n);
            assert!(c9.iter().zip(&c).all(|(a, b)| (a - b).abs() < 1e-5));
            // ∫ max(0, n·ω) dω = π, exactly in the projection.
            assert!((sh_integral(&c9) - std::f32::consts::PI).abs() < 1e-5);
            let integral: f64 = q.iter().map(|&(d, w)| sh9_eval(&c9, d) as f64 * w).sum();
            assert!((integral - PI).abs() < 1e-5, "{integral}");
        }
    }

    #[test]
    fn three_bands_reproduce_the_clamped_cosine_within_the_known_error() {
        // In 3 bands max(0, cos θ) ≈ 1/4 + cos θ / 2 + 5/32 (3 cos² θ − 1): worst at the
        // horizon (3/32 = 0.09375 over), 1/16 at the pole and straight behind.
        let mut worst = 0f32;
        for i in 0..2000 {
            let (n, w) = (random_dir(5, i), random_dir(6, i));
            let c = sh9_clamped_cosine(n);
            let t = n.dot(w);
            let approx = sh9_eval(&c, w);
            let closed = 0.25 + 0.5 * t + 5.0 / 32.0 * (3.0 * t * t - 1.0);
            assert!((approx - closed).abs() < 1e-5, "{approx} vs {closed}");
            worst = worst.max((approx - t.max(0.0)).abs());
            assert!((sh_eval(&sh_clamped_cosine(3, n), w) - approx).abs() < 1e-5);
        }
        assert!(worst <= 0.09375 + 1e-5 && worst > 0.08, "{worst}");
        let c = sh9_clamped_cosine(Vec3::Z);
        assert!((sh9_eval(&c, Vec3::Z) - 1.0625).abs() < 1e-5);
        assert!((sh9_eval(&c, Vec3::X) - 0.09375).abs() < 1e-5);
        assert!((sh9_eval(&c, -Vec3::Z) - 0.0625).abs() < 1e-5);
    }

    #[test]
    fn projections_are_rotation_invariant_in_three_and_four_bands() {
        for i in 0..300 {
            let axis = random_dir(7, i);
            let angle = uniform(8, i, 0) * 2.0 * std::f32::consts::PI;
            let r = Quat::from_axis_angle(axis, angle);
            let (n, w) = (random_dir(9, i), random_dir(10, i));
            let a = sh9_eval(&sh9_clamped_cosine(n), w);
            let b = sh9_eval(&sh9_clamped_cosine(r * n), r * w);
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
            let a4 = sh_eval(&sh_clamped_cosine(4, n), w);
            let b4 = sh_eval(&sh_clamped_cosine(4, r * n), r * w);
            assert!((a4 - b4).abs() < 1e-5, "{a4} vs {b4}");
        }
    }

    #[test]
    fn rgb_evaluation_is_per_channel_evaluation() {
        let n = random_dir(1, 1);
        let c = sh9_clamped_cosine(n);
        let rgb: [Vec3; 9] = std::array::from_fn(|k| Vec3::new(1.0, 2.0, 0.5) * c[k]);
        let w = random_dir(2, 2);
        let v = sh9_eval_rgb(&rgb, w);
        let s = sh9_eval(&c, w);
        assert!((v - Vec3::new(1.0, 2.0, 0.5) * s).abs().max_element() < 1e-6);
    }
}
