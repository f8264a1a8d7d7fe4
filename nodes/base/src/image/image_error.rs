use crate::image::ssim::ssim_with;
use crate::math::srgb::srgb_encode;
use crate::types::{Image, Metrics};
use relume_core::{node, params, CancelToken, NodeError, RunCtx};

params! {
    /// Error of an image against a reference of the same size, into the run report:
    /// MSE (mean over pixels and channels of (x − r)²), relative MSE (mean of
    /// (x − r)² / (r² + ε)), PSNR = 10 log10(peak² / MSE) in dB, the theses' L2 % =
    /// 100 · ‖x − r‖₂ / ‖r‖₂, and two perceptual figures of the images as a display shows them
    /// (linear / `peak` clamped to [0, 1], sRGB-encoded, as in a PNG): `flip`, the mean of
    /// NVIDIA's LDR-ꟻLIP error map (Andersson et al. 2020, `nv-flip` crate, 67 pixels per degree,
    /// 8-bit input; 0 = identical, 1 = maximal; the crate has no HDR-ꟻLIP, so differences above
    /// `peak` are not seen), which models what a viewer sees flipping between the two, so it
    /// punishes a brightness shift as much as blotches and forgives pixel-scale noise; and
    /// `ssim`, mean SSIM (Wang et al. 2004; 11 × 11 Gaussian window, σ = 1.5, K1 = 0.01,
    /// K2 = 0.03, L = 1) of the Rec. 709 luma, 1 = identical, which punishes lost structure
    /// more than a brightness shift. Pixels where either image is not finite are left out of
    /// every figure and counted in `nonfinite_pixels` (ꟻLIP gets the same finite value in
    /// both images there; SSIM's windows skip them). Also outputs the per-pixel squared-error
    /// map.
    pub struct ImageError {
        /// signal peak: PSNR's peak, and the linear value ꟻLIP shows as display white
        pub peak: f64 = 1.0, range = 1e-6..=1e6;
        /// ε in relative MSE's denominator (r² + ε), keeps dark pixels from dominating
        pub epsilon: f64 = 1e-2, range = 1e-8..=1.0;
    }
}

/// Error figures of `x` against `r` (same size), in the order the report lists them; outside
/// a node run (never cancelled).
pub fn error_metrics(x: &Image, r: &Image, peak: f64, epsilon: f64) -> Metrics {
    let cancel = CancelToken::new();
    error_metrics_with(x, r, peak, epsilon, &RunCtx::new("error_metrics", &cancel, None)).expect("never cancelled")
}

/// `error_metrics` with `cx`'s progress and cancellation. The sums run over the pixels in
/// order (one row per tick), so the figures are the same bits on any thread count.
pub fn error_metrics_with(x: &Image, r: &Image, peak: f64, epsilon: f64, cx: &RunCtx) -> Result<Metrics, NodeError> {
    let (mut se, mut rel, mut ref2, mut n, mut bad) = (0.0f64, 0.0f64, 0.0f64, 0usize, 0usize);
    let w = x.width.max(1);
    let rows = x.pixels.len().div_ceil(w) as u64;
    for (y, (xrow, rrow)) in x.pixels.chunks(w).zip(r.pixels.chunks(w)).enumerate() {
        cx.tick(y as u64, rows)?;
        for (a, b) in xrow.iter().zip(rrow) {
            if a.iter().chain(b).any(|c| !c.is_finite()) {
                bad += 1;
                continue;
            }
            for c in 0..3 {
                let (a, b) = (a[c] as f64, b[c] as f64);
                let d2 = (a - b) * (a - b);
                se += d2;
                rel += d2 / (b * b + epsilon);
                ref2 += b * b;
            }
            n += 3;
        }
    }
    let count = n.max(1) as f64;
    let mse = se / count;
    let psnr = if mse > 0.0 { 10.0 * (peak * peak / mse).log10() } else { f64::INFINITY };
    let l2 = if ref2 > 0.0 {
        100.0 * (se / ref2).sqrt()
    } else if se == 0.0 {
        0.0
    } else {
        f64::INFINITY
    };
    let flip = flip_mean_with(x, r, peak, cx)?;
    cx.check()?;
    let ssim = ssim_with(x, r, peak, cx)?;
    Ok(Metrics(vec![
        ("mse".into(), mse),
        ("rel_mse".into(), rel / count),
        ("psnr_db".into(), psnr),
        ("l2_percent".into(), l2),
        ("flip".into(), flip),
        ("ssim".into(), ssim),
        ("nonfinite_pixels".into(), bad as f64),
    ]))
}

/// Mean LDR-ꟻLIP error of `x` against `r` (same size) over the pixels where both are finite,
/// each shown as a PNG would show it (`x / peak` clamped to [0, 1], sRGB, 8 bits); 0 when no
/// pixel is left to compare. Outside a node run (never cancelled).
pub fn flip_mean(x: &Image, r: &Image, peak: f64) -> f64 {
    let cancel = CancelToken::new();
    flip_mean_with(x, r, peak, &RunCtx::new("flip_mean", &cancel, None)).expect("never cancelled")
}

/// `flip_mean` with `cx`'s progress and cancellation (the 8-bit images are made row by row
/// in parallel; the ꟻLIP call itself cannot be interrupted).
pub fn flip_mean_with(x: &Image, r: &Image, peak: f64, cx: &RunCtx) -> Result<f64, NodeError> {
    let (Ok(w), Ok(h)) = (u32::try_from(x.width), u32::try_from(x.height)) else { return Ok(f64::NAN) };
    if x.pixels.is_empty() {
        return Ok(0.0);
    }
    let scale = (1.0 / peak) as f32;
    let to8 = |p: [f32; 3]| p.map(|c| (srgb_encode(c * scale) * 255.0 + 0.5) as u8);
    type Row<'a> = &'a [[f32; 3]];
    let rows: Vec<(Row, Row)> = x.pixels.chunks(x.width.max(1)).zip(r.pixels.chunks(x.width.max(1))).collect();
    let rows = cx.par_map(rows.len(), |y| {
        let (xrow, rrow) = rows[y];
        let (mut xb, mut rb, mut ok) =
            (Vec::with_capacity(xrow.len() * 3), Vec::with_capacity(xrow.len() * 3), Vec::with_capacity(xrow.len()));
        for (a, b) in xrow.iter().zip(rrow) {
            let finite = |p: &[f32; 3]| p.iter().all(|c| c.is_finite());
            let good = finite(a) && finite(b);
            // Where one side is not finite, both get the other side's value (or black) so that
            // ꟻLIP's spatial filters see no difference there.
            let (a, b) = if good {
                (*a, *b)
            } else {
                let fill = if finite(b) {
                    *b
                } else if finite(a) {
                    *a
                } else {
                    [0.0; 3]
                };
                (fill, fill)
            };
            xb.extend(to8(a));
            rb.extend(to8(b));
            ok.push(good);
        }
        (xb, rb, ok)
    })?;
    let (mut xb, mut rb, mut ok) = (Vec::with_capacity(x.pixels.len() * 3), Vec::with_capacity(x.pixels.len() * 3), Vec::new());
    for (xr, rr, okr) in rows {
        xb.extend(xr);
        rb.extend(rr);
        ok.extend(okr);
    }
    cx.check()?;
    let map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, &rb),
        nv_flip::FlipImageRgb8::with_data(w, h, &xb),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    )
    .to_vec();
    let (sum, n) = map.iter().zip(&ok).filter(|(_, &g)| g).fold((0.0f64, 0usize), |(s, n), (&e, _)| (s + e as f64, n + 1));
    Ok(if n == 0 { 0.0 } else { sum / n as f64 })
}

#[node(category = "quality", version = 2, metrics = ["mse", "rel_mse", "psnr_db", "l2_percent", "flip", "ssim", "nonfinite_pixels"], outputs = [metrics, error_map])]
impl ImageError {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // SSIM holds two luma planes (f64) and three planes of six f64 moments per pixel
        // (moments, row-filtered, column-filtered): 160 bytes a pixel, more than ꟻLIP's
        // 8-bit copies and map after it.
        let pixels = inputs[0].and_then(|s| s.pixels());
        relume_core::MemoryEstimate {
            outputs: vec![Some(relume_core::PortSize::bytes(256)), inputs[0]],
            working: pixels.map_or(0, |p| p * 160),
        }
    }

    fn run(&self, image: &Image, reference: &Image, cx: &RunCtx) -> Result<(Metrics, Image), NodeError> {
        let (x, r) = (image, reference);
        r.check_same_size(x, "reference", "image")?;
        cx.phase(0.0, 0.9);
        let m = error_metrics_with(x, r, self.peak, self.epsilon, cx)?;
        for (k, v) in &m.0 {
            cx.metric(k, *v);
        }
        if m.get("nonfinite_pixels").unwrap_or(0.0) > 0.0 {
            cx.note(format!("{} pixels with NaN or infinity were left out of the error", m.get("nonfinite_pixels").unwrap()));
        }
        let mut map = vec![[0.0f32; 3]; x.pixels.len()];
        cx.phase(0.9, 1.0);
        cx.par_chunks_mut(&mut map, x.width, |y, o| {
            let (xrow, rrow) = (&x.pixels[y * x.width..], &r.pixels[y * x.width..]);
            for ((m, a), b) in o.iter_mut().zip(xrow).zip(rrow) {
                *m = std::array::from_fn(|c| (a[c] - b[c]) * (a[c] - b[c]));
            }
        })?;
        Ok((m, Image { width: x.width, height: x.height, pixels: map }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;
    use crate::testing::{cancels_midway, run_full};
    use relume_core::Value;
    use std::path::Path;

    #[test]
    fn figures_match_hand_computed_values() {
        let r = Image::from_fn(2, 1, |_, _| [1.0; 3]);
        let x = Image::from_fn(2, 1, |i, _| [if i == 0 { 1.5 } else { 1.0 }; 3]);
        let m = error_metrics(&x, &r, 1.0, 0.0);
        assert!((m.get("mse").unwrap() - 0.125).abs() < 1e-12);
        assert!((m.get("rel_mse").unwrap() - 0.125).abs() < 1e-12);
        assert!((m.get("psnr_db").unwrap() - 10.0 * 8f64.log10()).abs() < 1e-9);
        assert!((m.get("l2_percent").unwrap() - 100.0 * (0.75f64 / 6.0).sqrt()).abs() < 1e-9);
        assert_eq!(error_metrics(&r, &r, 1.0, 0.01).get("psnr_db"), Some(f64::INFINITY));
    }

    #[test]
    fn nonfinite_pixels_are_counted_not_propagated() {
        let r = Image::from_fn(3, 1, |_, _| [0.0; 3]);
        let x = Image::from_fn(3, 1, |i, _| [[f32::NAN, f32::INFINITY, 0.5][i]; 3]);
        let e = run_full::<ImageError>(&[], Path::new("."), vec![Value::new(x), Value::new(r)]).unwrap();
        let m: Metrics = e.outputs[0].get::<Metrics>().unwrap().clone();
        assert_eq!(m.get("nonfinite_pixels"), Some(2.0));
        assert!((m.get("mse").unwrap() - 0.25).abs() < 1e-12);
        assert_eq!(m.get("l2_percent"), Some(f64::INFINITY), "zero reference: L2 % is unbounded");
        assert_eq!(e.metrics.len(), 7);
        assert_eq!(e.notes.len(), 1);
    }

    use crate::testing::images::{scene, with_noise};

    #[test]
    fn identical_images_have_zero_flip() {
        let a = scene();
        assert_eq!(flip_mean(&a, &a, 1.0), 0.0);
        assert_eq!(error_metrics(&a, &a, 1.0, 0.01).get("flip"), Some(0.0));
    }

    #[test]
    fn flip_grows_with_the_noise_level() {
        let r = scene();
        let f: Vec<f64> = [0.01, 0.03, 0.1].iter().map(|&sd| flip_mean(&with_noise(&r, sd, 5), &r, 1.0)).collect();
        assert!(f[0] > 0.0 && f[0] < f[1] && f[1] < f[2], "{f:?}");
        assert!(f[2] < 1.0, "{f:?}");
    }

    #[test]
    fn flip_forgives_pixel_noise_more_than_blotches_of_equal_mse() {
        let r = scene();
        let fine = with_noise(&r, 0.05, 9);
        let a = error_metrics(&fine, &r, 1.0, 0.01).get("mse").unwrap().sqrt() as f32;
        // ±a in 8 × 8 cells: the same MSE, at a scale the eye resolves.
        let blotchy = Image::from_fn(r.width, r.height, |x, y| {
            let s = if uniform(3, (x / 8 + 100 * (y / 8)) as u64, 0) < 0.5 { a } else { -a };
            r.get(x, y).map(|c| c + s)
        });
        let mse_blotchy = error_metrics(&blotchy, &r, 1.0, 0.01).get("mse").unwrap();
        assert!((mse_blotchy / (a * a) as f64 - 1.0).abs() < 1e-3, "equal MSE");
        let (f_fine, f_blotchy) = (flip_mean(&fine, &r, 1.0), flip_mean(&blotchy, &r, 1.0));
        assert!(f_fine < 0.75 * f_blotchy, "fine {f_fine} vs blotchy {f_blotchy}");
    }

    #[test]
    fn a_constant_shift_hurts_less_than_noise_of_equal_mse_in_ssim_but_not_in_flip() {
        let r = scene();
        let noisy = with_noise(&r, 0.05, 9);
        let m_noise = error_metrics(&noisy, &r, 1.0, 0.01);
        let shift = m_noise.get("mse").unwrap().sqrt() as f32;
        let shifted = Image::from_fn(r.width, r.height, |x, y| r.get(x, y).map(|c| c + shift));
        let m_shift = error_metrics(&shifted, &r, 1.0, 0.01);
        assert!((m_shift.get("mse").unwrap() / m_noise.get("mse").unwrap() - 1.0).abs() < 1e-3, "equal MSE");
        let (s_noise, s_shift) = (m_noise.get("ssim").unwrap(), m_shift.get("ssim").unwrap());
        assert!(1.0 - s_shift < 0.25 * (1.0 - s_noise), "ssim: shift {s_shift} vs noise {s_noise}");
        // ꟻLIP shows what flipping between the images reveals: the shift, more than the noise.
        let (f_noise, f_shift) = (m_noise.get("flip").unwrap(), m_shift.get("flip").unwrap());
        assert!(f_shift > f_noise, "flip: shift {f_shift} vs noise {f_noise}");
    }

    #[test]
    fn one_pixel_and_three_by_three_images_give_finite_flip() {
        for (w, h) in [(1, 1), (3, 3), (1, 5)] {
            let r = Image::from_fn(w, h, |x, y| [0.2 + 0.1 * x as f32, 0.3 + 0.05 * y as f32, 0.5]);
            let x = Image::from_fn(w, h, |x, y| r.get(x, y).map(|c| c * 1.5));
            let f = flip_mean(&x, &r, 1.0);
            assert!(f.is_finite() && f > 0.0 && f <= 1.0, "{w}×{h}: {f}");
            assert_eq!(flip_mean(&r, &r, 1.0), 0.0);
        }
    }

    #[test]
    fn nonfinite_pixels_are_left_out_of_flip() {
        let r = scene();
        let mut x = r.clone();
        x.pixels[100] = [f32::NAN, 0.5, 0.5];
        let mut r2 = r.clone();
        r2.pixels[200] = [f32::INFINITY; 3];
        let m = error_metrics(&x, &r2, 1.0, 0.01);
        assert_eq!(m.get("flip"), Some(0.0), "the two bad pixels are excluded and leave no trace on their neighbours");
        assert!((m.get("ssim").unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(m.get("nonfinite_pixels"), Some(2.0));
        let all_nan = Image::from_fn(3, 3, |_, _| [f32::NAN; 3]);
        assert_eq!(flip_mean(&all_nan, &all_nan, 1.0), 0.0, "nothing left to compare");
    }

    #[test]
    fn cancels_midway_through_a_large_image() {
        let r = Image::from_fn(512, 512, |x, y| [x as f32 / 512.0, y as f32 / 512.0, 0.5]);
        let x = with_noise(&r, 0.05, 1);
        cancels_midway::<ImageError>(&[], vec![Value::new(x), Value::new(r)]);
    }

    #[test]
    fn the_node_outputs_the_squared_error_map() {
        let r = scene();
        let x = with_noise(&r, 0.05, 2);
        let e = run_full::<ImageError>(&[], Path::new("."), vec![Value::new(x.clone()), Value::new(r.clone())]).unwrap();
        let map = e.outputs[1].get::<Image>().unwrap();
        assert_eq!((map.width, map.height), (r.width, r.height));
        for ((m, a), b) in map.pixels.iter().zip(&x.pixels).zip(&r.pixels) {
            assert_eq!(*m, std::array::from_fn(|c| (a[c] - b[c]) * (a[c] - b[c])));
        }
        assert_eq!(e.outputs[0].get::<Metrics>().unwrap(), &error_metrics(&x, &r, 1.0, 0.01));
    }
}
