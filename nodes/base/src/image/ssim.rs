//! Structural similarity (SSIM, Wang, Bovik, Sheikh and Simoncelli 2004) on display luma.
//!
//! Per pixel, over a Gaussian window (11 × 11, σ = 1.5):
//! SSIM = (2 μx μy + C1)(2 σxy + C2) / ((μx² + μy² + C1)(σx² + σy² + C2)),
//! C1 = (K1 L)², C2 = (K2 L)², K1 = 0.01, K2 = 0.03, on values of dynamic range L = 1.
//! The image figure is the mean over pixels whose whole window lies inside the image (as in the
//! paper's reference code), or over all pixels when the image is smaller than the window.
//! Windows leave out what lies outside the image and pixels that are not finite in either
//! image, and are renormalised over what is left, so borders, tiny images and NaN need no
//! special case; non-finite pixels are also left out of the mean.

use crate::math::srgb::srgb_encode;
use crate::types::Image;
use relume_core::{CancelToken, NodeError, RunCtx};

pub const K1: f64 = 0.01;
pub const K2: f64 = 0.03;
pub const SIGMA: f64 = 1.5;
/// Window half-width: 11 × 11 taps.
pub const RADIUS: usize = 5;

/// Rec. 709 luma of the sRGB-encoded display values of `img / peak` (clamped to [0, 1]), in
/// [0, 1]; NaN where a channel is not finite.
pub fn display_luma(img: &Image, peak: f64) -> Vec<f64> {
    let s = (1.0 / peak) as f32;
    img.pixels
        .iter()
        .map(|p| {
            if p.iter().all(|c| c.is_finite()) {
                let e = p.map(|c| srgb_encode(c * s) as f64);
                0.2126 * e[0] + 0.7152 * e[1] + 0.0722 * e[2]
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// Mean SSIM of two images as shown on a display whose white is the linear value `peak`
/// (see `display_luma`); 1 for identical images. Returns 1 when no pixel is finite in both.
pub fn ssim(x: &Image, r: &Image, peak: f64) -> f64 {
    let cancel = CancelToken::new();
    ssim_with(x, r, peak, &RunCtx::new("ssim", &cancel, None)).expect("never cancelled")
}

/// `ssim` inside a node's run: its passes go row by row through `cx`, so a cancelled run
/// stops within a row.
pub fn ssim_with(x: &Image, r: &Image, peak: f64, cx: &RunCtx) -> Result<f64, NodeError> {
    assert_eq!((x.width, x.height), (r.width, r.height), "ssim needs images of the same size");
    ssim_plane_with(&display_luma(x, peak), &display_luma(r, peak), x.width, x.height, 1.0, cx)
}

/// Mean SSIM of two row-major planes of `w` × `h` values with dynamic range `l`; entries that
/// are not finite in either plane are left out (see the module comment).
pub fn ssim_plane(a: &[f64], b: &[f64], w: usize, h: usize, l: f64) -> f64 {
    let cancel = CancelToken::new();
    ssim_plane_with(a, b, w, h, l, &RunCtx::new("ssim", &cancel, None)).expect("never cancelled")
}

/// `ssim_plane` with `cx`'s cancellation (and progress).
pub fn ssim_plane_with(a: &[f64], b: &[f64], w: usize, h: usize, l: f64, cx: &RunCtx) -> Result<f64, NodeError> {
    assert!(a.len() == w * h && b.len() == w * h, "planes must hold w × h values");
    let (c1, c2) = ((K1 * l).powi(2), (K2 * l).powi(2));
    let k: Vec<f64> = {
        let r = RADIUS as i64;
        let g: Vec<f64> = (-r..=r).map(|i| (-((i * i) as f64) / (2.0 * SIGMA * SIGMA)).exp()).collect();
        let s: f64 = g.iter().sum();
        g.iter().map(|v| v / s).collect()
    };
    // Per pixel: mask, a, b, a², b², ab (all zero where masked).
    let moments: Vec<[f64; 6]> =
        a.iter().zip(b).map(|(&x, &y)| if x.is_finite() && y.is_finite() { [1.0, x, y, x * x, y * y, x * y] } else { [0.0; 6] }).collect();
    let filtered = filter_cols(&filter_rows(&moments, w, &k, cx)?, w, h, &k, cx)?;
    let interior = |i: usize| {
        let (x, y) = (i % w, i / w);
        x >= RADIUS && y >= RADIUS && x + RADIUS < w && y + RADIUS < h
    };
    let any_interior = w > 2 * RADIUS && h > 2 * RADIUS;
    // Per-row partial sums in parallel, then the rows in order: the same bits on any
    // thread count (an unordered parallel reduce is not).
    let ssim_at = |m: &[f64; 6]| {
        let inv = 1.0 / m[0];
        let (mx, my) = (m[1] * inv, m[2] * inv);
        let (vx, vy, cxy) = (m[3] * inv - mx * mx, m[4] * inv - my * my, m[5] * inv - mx * my);
        (2.0 * mx * my + c1) * (2.0 * cxy + c2) / ((mx * mx + my * my + c1) * (vx.max(0.0) + vy.max(0.0) + c2))
    };
    let rows: Vec<(f64, usize)> = cx.par_map(h, |y| {
        let row = &filtered[y * w..(y + 1) * w];
        {
            row.iter()
                .enumerate()
                .map(|(x, m)| (y * w + x, m))
                .filter(|&(i, _)| moments[i][0] > 0.0 && (!any_interior || interior(i)))
                .fold((0.0, 0), |(s, n), (_, m)| (s + ssim_at(m), n + 1))
        }
    })?;
    let (sum, n) = rows.iter().fold((0.0, 0usize), |(s, n), &(rs, rn)| (s + rs, n + rn));
    Ok(if n == 0 { 1.0 } else { sum / n as f64 })
}

/// Horizontal pass with zero outside the image.
fn filter_rows(src: &[[f64; 6]], w: usize, k: &[f64], cx: &RunCtx) -> Result<Vec<[f64; 6]>, NodeError> {
    let mut out = vec![[0.0; 6]; src.len()];
    cx.par_chunks_mut(&mut out, w, |y, o| {
        let row = &src[y * w..(y + 1) * w];
        for (x, px) in o.iter_mut().enumerate() {
            for (j, &kw) in k.iter().enumerate() {
                let Some(sx) = (x + j).checked_sub(RADIUS).filter(|&s| s < w) else { continue };
                for c in 0..6 {
                    px[c] += kw * row[sx][c];
                }
            }
        }
    })?;
    Ok(out)
}

/// Vertical pass with zero outside the image.
fn filter_cols(src: &[[f64; 6]], w: usize, h: usize, k: &[f64], cx: &RunCtx) -> Result<Vec<[f64; 6]>, NodeError> {
    let mut out = vec![[0.0; 6]; src.len()];
    cx.par_chunks_mut(&mut out, w, |y, o| {
        for (j, &kw) in k.iter().enumerate() {
            let Some(sy) = (y + j).checked_sub(RADIUS).filter(|&s| s < h) else { continue };
            for (px, s) in o.iter_mut().zip(&src[sy * w..(sy + 1) * w]) {
                for c in 0..6 {
                    px[c] += kw * s[c];
                }
            }
        }
    })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;

    use crate::testing::images::{scene, with_noise};

    fn mse(a: &Image, b: &Image) -> f64 {
        let d = a.as_floats().iter().zip(b.as_floats()).map(|(x, y)| ((x - y) as f64).powi(2));
        d.sum::<f64>() / a.as_floats().len() as f64
    }

    #[test]
    fn the_same_bits_on_one_thread_and_on_four() {
        let (a, b) = (scene(), with_noise(&scene(), 0.05, 3));
        let on = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap().install(|| ssim(&a, &b, 1.0));
        let one = on(1);
        for _ in 0..8 {
            assert_eq!(on(4).to_bits(), one.to_bits());
        }
    }

    #[test]
    fn identical_images_have_ssim_one() {
        let a = scene();
        assert!((ssim(&a, &a, 1.0) - 1.0).abs() < 1e-12, "{}", ssim(&a, &a, 1.0));
        let flat = Image::from_fn(20, 20, |_, _| [0.3; 3]);
        assert!((ssim(&flat, &flat, 1.0) - 1.0).abs() < 1e-12, "flat images: C1 and C2 keep 0/0 away");
    }

    #[test]
    fn more_noise_gives_lower_ssim() {
        let r = scene();
        let s: Vec<f64> = [0.01, 0.03, 0.1].iter().map(|&sd| ssim(&with_noise(&r, sd, 5), &r, 1.0)).collect();
        assert!(1.0 > s[0] && s[0] > s[1] && s[1] > s[2], "{s:?}");
        assert!(s[2] > -1.0, "{s:?}");
    }

    #[test]
    fn a_constant_shift_hurts_less_than_structure_noise_of_equal_mse() {
        let r = scene();
        let noisy = with_noise(&r, 0.05, 9);
        let e = mse(&noisy, &r);
        let shift = e.sqrt() as f32;
        let shifted = Image::from_fn(r.width, r.height, |x, y| r.get(x, y).map(|c| c + shift));
        assert!((mse(&shifted, &r) / e - 1.0).abs() < 1e-3, "equal MSE");
        let (s_noise, s_shift) = (ssim(&noisy, &r, 1.0), ssim(&shifted, &r, 1.0));
        assert!(s_shift > 0.95, "a shift keeps the structure: {s_shift}");
        assert!(1.0 - s_shift < 0.25 * (1.0 - s_noise), "shift {s_shift} vs noise {s_noise}");
    }

    #[test]
    fn images_smaller_than_the_window_give_finite_values() {
        for (w, h) in [(1, 1), (3, 3), (1, 7), (11, 2)] {
            let r = Image::from_fn(w, h, |x, y| [0.2 + 0.1 * x as f32, 0.3 + 0.05 * y as f32, 0.5]);
            let x = Image::from_fn(w, h, |x, y| r.get(x, y).map(|c| c * 1.5));
            let s = ssim(&x, &r, 1.0);
            assert!(s.is_finite() && s < 1.0 && s > -1.0, "{w}×{h}: {s}");
            assert!((ssim(&r, &r, 1.0) - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn interior_mean_matches_a_direct_window_sum() {
        // 13 × 12: interior pixels are x in 5..8, y in 5..7; compute one directly.
        let a: Vec<f64> = (0..13 * 12).map(|i| uniform(1, i, 0) as f64).collect();
        let b: Vec<f64> = (0..13 * 12).map(|i| 0.5 * a[i as usize] + 0.5 * uniform(2, i, 0) as f64).collect();
        let g = |d: i64| (-((d * d) as f64) / (2.0 * SIGMA * SIGMA)).exp();
        let norm: f64 = (-5..=5).map(g).sum::<f64>().powi(2);
        let direct = |cx: i64, cy: i64| {
            let mut m = [0.0f64; 5];
            for dy in -5..=5 {
                for dx in -5..=5 {
                    let i = ((cy + dy) * 13 + cx + dx) as usize;
                    let wgt = g(dx) * g(dy) / norm;
                    let (x, y) = (a[i], b[i]);
                    for (acc, v) in m.iter_mut().zip([x, y, x * x, y * y, x * y]) {
                        *acc += wgt * v;
                    }
                }
            }
            let (mx, my) = (m[0], m[1]);
            let (vx, vy, c) = (m[2] - mx * mx, m[3] - my * my, m[4] - mx * my);
            let (c1, c2) = (K1 * K1, K2 * K2);
            (2.0 * mx * my + c1) * (2.0 * c + c2) / ((mx * mx + my * my + c1) * (vx + vy + c2))
        };
        let mut want = 0.0;
        for y in 5..7 {
            for x in 5..8 {
                want += direct(x, y);
            }
        }
        want /= 6.0;
        let got = ssim_plane(&a, &b, 13, 12, 1.0);
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    }

    #[test]
    fn nonfinite_pixels_are_left_out() {
        let r = scene();
        let mut x = r.clone();
        x.pixels[100] = [f32::NAN, 0.5, 0.5];
        x.pixels[500] = [f32::INFINITY; 3];
        let s = ssim(&x, &r, 1.0);
        assert!((s - 1.0).abs() < 1e-12, "the rest is identical: {s}");
        let noisy = with_noise(&r, 0.03, 4);
        let mut noisy_nan = noisy.clone();
        noisy_nan.pixels[700] = [f32::NAN; 3];
        let (s0, s1) = (ssim(&noisy, &r, 1.0), ssim(&noisy_nan, &r, 1.0));
        assert!(s1.is_finite() && (s1 - s0).abs() < 0.01, "{s0} vs {s1}");
        let all_nan = Image::from_fn(3, 3, |_, _| [f32::NAN; 3]);
        assert_eq!(ssim(&all_nan, &r_small(), 1.0), 1.0, "nothing left to compare");
    }

    fn r_small() -> Image {
        Image::from_fn(3, 3, |_, _| [0.5; 3])
    }
}
