use crate::types::{Image, Metrics};
use relume_core::{node, params, CancelToken, NodeError, RunCtx};

params! {
    /// Per-pixel z-test of a noisy estimate against a reference, both given with the variance
    /// of their mean: per pixel and channel z = (x − r) / sqrt(var_x + var_r + tiny), tiny =
    /// the smallest normal f64 (negative variances, round-off of E[x²] − E[x]², count as 0).
    /// A pixel passes when all its channels have |z| ≤ `z`, so equal values with zero variance
    /// pass and unequal ones fail. A pixel with any value not finite fails and is counted in
    /// `nonfinite_pixels`. Metrics: `pass_fraction` (of all pixels), `max_abs_z` and signed
    /// `mean_z` (bias shows as mean_z away from 0; both over the finite pixels' channels with some
    /// variance: a difference without noise has no z worth averaging), `zero_variance_channels`
    /// (channels with no variance in either image; they pass only when equal), `pixels`; a note says whether pass_fraction ≥ `min_pass`. Under an unbiased Gaussian
    /// estimate with exact variances about 1 − 3 · P(|N| > z) of pixels pass (99.7 % at 3.29);
    /// variances estimated from few samples have heavier tails: use more samples or a larger
    /// `z`. Outputs the |z| map (f32::MAX where not finite or too large).
    pub struct ZTest {
        /// largest |z| a channel may have (3.29: two-sided 0.1 %)
        pub z: f64 = 3.29, range = 0.5..=10.0, unit = "σ";
        /// fraction of pixels that must pass for the note to say the test passes
        pub min_pass: f64 = 0.995, range = 0.0..=1.0;
    }
}

/// Result of `z_test`.
#[derive(Clone, Debug, PartialEq)]
pub struct ZTestOutcome {
    /// Passing pixels over all pixels (0 for an empty image).
    pub pass_fraction: f64,
    /// Largest |z| over the finite pixels' channels (0 if none).
    pub max_abs_z: f64,
    /// Mean signed z over the finite pixels' channels (0 if none).
    pub mean_z: f64,
    pub pixels: usize,
    /// Pixels with a value that is not finite in any of the four images (all fail).
    pub nonfinite_pixels: usize,
    /// Channels with zero variance in both images (outside max_abs_z and mean_z).
    pub zero_variance_channels: usize,
    /// |z| per channel, f32::MAX where not finite or beyond f32.
    pub z_map: Image,
}

impl ZTestOutcome {
    /// Whether at least `min_pass` of the pixels passed.
    pub fn passes(&self, min_pass: f64) -> bool {
        self.pass_fraction >= min_pass
    }

    /// The figures, in the order the report lists them.
    pub fn metrics(&self) -> Metrics {
        Metrics(vec![
            ("pass_fraction".into(), self.pass_fraction),
            ("max_abs_z".into(), self.max_abs_z),
            ("mean_z".into(), self.mean_z),
            ("pixels".into(), self.pixels as f64),
            ("nonfinite_pixels".into(), self.nonfinite_pixels as f64),
            ("zero_variance_channels".into(), self.zero_variance_channels as f64),
        ])
    }
}

/// The z-test statistic (see the node's doc): `image` with the per-pixel variance of its mean
/// against `reference` with its own, pixels passing at |z| ≤ `z` in every channel. Errors,
/// naming the port, unless all four have the same size. Outside a node run (never cancelled).
pub fn z_test(
    image: &Image,
    image_variance: &Image,
    reference: &Image,
    reference_variance: &Image,
    z: f64,
) -> Result<ZTestOutcome, NodeError> {
    let cancel = CancelToken::new();
    z_test_with(image, image_variance, reference, reference_variance, z, &RunCtx::new("z_test", &cancel, None))
}

/// `z_test` with `cx`'s progress and cancellation. The pixels are visited in order (one row
/// per tick), so `mean_z` is the same bits on any thread count.
pub fn z_test_with(
    image: &Image,
    image_variance: &Image,
    reference: &Image,
    reference_variance: &Image,
    z: f64,
    cx: &RunCtx,
) -> Result<ZTestOutcome, NodeError> {
    image.check_same_size(image_variance, "image", "image_variance")?;
    image.check_same_size(reference, "image", "reference")?;
    image.check_same_size(reference_variance, "image", "reference_variance")?;
    let tiny = f64::MIN_POSITIVE;
    let (mut passed, mut bad, mut channels, mut flat) = (0usize, 0usize, 0usize, 0usize);
    let (mut max_abs, mut sum) = (0.0f64, 0.0f64);
    let mut map = Vec::with_capacity(image.pixels.len());
    let (n, w) = (image.pixels.len(), image.width.max(1));
    let rows = n.div_ceil(w);
    for y in 0..rows {
        cx.tick(y as u64, rows as u64)?;
        for i in y * w..((y + 1) * w).min(n) {
            let (x, vx, r, vr) = (image.pixels[i], image_variance.pixels[i], reference.pixels[i], reference_variance.pixels[i]);
            if [x, vx, r, vr].iter().flatten().any(|c| !c.is_finite()) {
                bad += 1;
                map.push([f32::MAX; 3]);
                continue;
            }
            let mut px = [0.0f32; 3];
            let mut ok = true;
            for c in 0..3 {
                let v = (vx[c] as f64).max(0.0) + (vr[c] as f64).max(0.0);
                let zc = (x[c] as f64 - r[c] as f64) / (v + tiny).sqrt();
                ok &= zc.abs() <= z;
                px[c] = zc.abs().min(f32::MAX as f64) as f32;
                if v == 0.0 {
                    flat += 1;
                    continue;
                }
                max_abs = max_abs.max(zc.abs());
                sum += zc;
                channels += 1;
            }
            passed += ok as usize;
            map.push(px);
        }
    }
    let pixels = image.pixels.len();
    Ok(ZTestOutcome {
        pass_fraction: if pixels == 0 { 0.0 } else { passed as f64 / pixels as f64 },
        max_abs_z: max_abs,
        mean_z: if channels == 0 { 0.0 } else { sum / channels as f64 },
        pixels,
        nonfinite_pixels: bad,
        zero_variance_channels: flat,
        z_map: Image { width: image.width, height: image.height, pixels: map },
    })
}

#[node(category = "quality", version = 2, metrics = ["pass_fraction", "max_abs_z", "mean_z", "pixels", "nonfinite_pixels", "zero_variance_channels"], outputs = [metrics, z_map])]
impl ZTest {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let outputs = (0..2).map(|k| if k == 1 { inputs[0] } else { Some(relume_core::PortSize::bytes(256)) }).collect();
        relume_core::MemoryEstimate { outputs, working: 0 }
    }

    fn run(
        &self,
        image: &Image,
        image_variance: &Image,
        reference: &Image,
        reference_variance: &Image,
        cx: &RunCtx,
    ) -> Result<(Metrics, Image), NodeError> {
        let t = z_test_with(image, image_variance, reference, reference_variance, self.z, cx)?;
        let m = t.metrics();
        for (k, v) in &m.0 {
            cx.metric(k, *v);
        }
        let verdict = if t.passes(self.min_pass) { "passes" } else { "fails" };
        cx.note(format!(
            "z-test {verdict}: {:.2} % of {} pixels within |z| ≤ {} (needed {:.2} %)",
            100.0 * t.pass_fraction,
            t.pixels,
            self.z,
            100.0 * self.min_pass
        ));
        if t.nonfinite_pixels > 0 {
            cx.note(format!("{} pixels with NaN or infinity counted as failures", t.nonfinite_pixels));
        }
        Ok((m, t.z_map))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;
    use crate::testing::{cancels_midway, f, run_full};
    use relume_core::Value;
    use std::path::Path;

    /// The per-pixel truth of the tests: a smooth colourful ramp.
    fn truth(w: usize, h: usize) -> Image {
        Image::from_fn(w, h, |x, y| [0.1 + x as f32 / w as f32, 0.5 + 0.3 * (y as f32 / h as f32), 2.0])
    }

    /// Standard normal from Box–Muller on two seeded uniforms.
    fn normal(seed: u64, i: u64, dim: u32) -> f64 {
        let (u1, u2) = (1.0 - uniform(seed, i, 2 * dim) as f64, uniform(seed, i, 2 * dim + 1) as f64);
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// An unbiased estimate of `t` whose mean has per-channel standard deviation `sd`
    /// (Gaussian), shifted by `bias` standard deviations; returns (estimate, variance).
    fn estimate(t: &Image, sd: [f32; 3], bias: f64, seed: u64) -> (Image, Image) {
        let mut x = t.clone();
        for (i, p) in x.pixels.iter_mut().enumerate() {
            for c in 0..3 {
                p[c] += ((normal(seed, i as u64, c as u32) + bias) * sd[c] as f64) as f32;
            }
        }
        let var = Image::from_fn(t.width, t.height, |_, _| sd.map(|s| s * s));
        (x, var)
    }

    /// An estimate as a renderer makes one: the mean of `n` samples, each uniform on
    /// t ± spread, with the known variance of that mean, spread² / (3n).
    fn sample_mean(t: &Image, n: u32, spread: f32, seed: u64) -> (Image, Image) {
        let mut x = t.clone();
        for (i, p) in x.pixels.iter_mut().enumerate() {
            for (c, v) in p.iter_mut().enumerate() {
                let s: f32 = (0..n).map(|k| 2.0 * uniform(seed, i as u64, c as u32 * n + k) - 1.0).sum();
                *v += spread * s / n as f32;
            }
        }
        (x, Image::from_fn(t.width, t.height, |_, _| [spread * spread / (3.0 * n as f32); 3]))
    }

    #[test]
    fn unbiased_estimates_with_known_variance_pass() {
        let t = truth(64, 64);
        let (x, vx) = estimate(&t, [0.05, 0.2, 0.01], 0.0, 1);
        let (r, vr) = estimate(&t, [0.01, 0.04, 0.002], 0.0, 2);
        let o = z_test(&x, &vx, &r, &vr, 3.29).unwrap();
        assert!(o.passes(0.995), "{o:?}");
        assert!(o.pass_fraction < 1.0, "some pixels are expected beyond 3.29 σ: {}", o.pass_fraction);
        assert!(o.mean_z.abs() < 0.05, "no bias: {}", o.mean_z);
        assert!(o.max_abs_z > 3.0 && o.max_abs_z < 6.0, "{}", o.max_abs_z);
        assert_eq!(o.pixels, 4096);
        // Sample means of uniforms against an exact reference (zero variance).
        let (x, vx) = sample_mean(&t, 8, 0.3, 3);
        let zero = Image::from_fn(64, 64, |_, _| [0.0; 3]);
        assert!(z_test(&x, &vx, &t, &zero, 3.29).unwrap().passes(0.995));
    }

    #[test]
    fn an_estimate_biased_by_five_sigma_fails() {
        let t = truth(64, 64);
        let (x, vx) = estimate(&t, [0.05, 0.2, 0.01], 5.0, 1);
        let (r, vr) = estimate(&t, [0.0, 0.0, 0.0], 0.0, 2);
        let o = z_test(&x, &vx, &r, &vr, 3.29).unwrap();
        assert!(!o.passes(0.995), "{}", o.pass_fraction);
        assert!(o.pass_fraction < 0.01, "{}", o.pass_fraction);
        assert!((o.mean_z - 5.0).abs() < 0.1, "the bias shows in mean_z: {}", o.mean_z);
        // Bias in a single channel is enough to fail a pixel: P(N(5, 1) ≤ 3.29) ≈ 4.4 %.
        let (mut x, vx) = estimate(&t, [0.05, 0.2, 0.01], 0.0, 1);
        for p in &mut x.pixels {
            p[2] += 0.05;
        }
        let f = z_test(&x, &vx, &r, &vr, 3.29).unwrap().pass_fraction;
        assert!(f > 0.02 && f < 0.07, "{f}");
    }

    #[test]
    fn zero_variances_pass_equal_images_and_fail_unequal_ones() {
        let t = truth(8, 8);
        let zero = Image::from_fn(8, 8, |_, _| [0.0; 3]);
        let o = z_test(&t, &zero, &t, &zero, 3.29).unwrap();
        assert_eq!((o.pass_fraction, o.max_abs_z, o.mean_z), (1.0, 0.0, 0.0));
        let mut x = t.clone();
        x.pixels[9][1] = f32::from_bits(x.pixels[9][1].to_bits() + 1); // one ulp
        x.pixels[10] = [0.0, 0.0, 1e-30];
        let o = z_test(&x, &zero, &t, &zero, 3.29).unwrap();
        assert_eq!(o.pass_fraction, 62.0 / 64.0);
        assert!(o.max_abs_z.is_finite() && o.mean_z.is_finite(), "{o:?}");
        assert!(o.z_map.as_floats().iter().all(|v| v.is_finite()));
        assert!(o.z_map.get(1, 1)[1] > 1e30 && o.z_map.get(1, 1)[0] == 0.0);
        // Round-off negative variances count as zero, not NaN.
        let neg = Image::from_fn(8, 8, |_, _| [-1e-12; 3]);
        assert_eq!(z_test(&t, &neg, &t, &neg, 3.29).unwrap().pass_fraction, 1.0);
    }

    #[test]
    fn mismatched_sizes_are_an_error_naming_the_port() {
        let (a, b) = (truth(8, 8), truth(8, 7));
        let e = z_test(&a, &a, &a, &b, 3.29).unwrap_err().to_string();
        assert!(e.contains("reference_variance") && e.contains("8 × 7"), "{e}");
        let e = z_test(&a, &b, &a, &a, 3.29).unwrap_err().to_string();
        assert!(e.starts_with("input `image_variance`"), "{e}");
        let e = run_full::<ZTest>(&[], Path::new("."), vec![Value::new(a.clone()), Value::new(a.clone()), Value::new(b), Value::new(a)])
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("input `reference`"), "{e}");
    }

    #[test]
    fn nonfinite_values_fail_and_are_counted() {
        let t = truth(10, 10);
        let (x, vx) = estimate(&t, [0.1; 3], 0.0, 7);
        let mut x2 = x.clone();
        x2.pixels[0][0] = f32::NAN;
        let mut vr = Image::from_fn(10, 10, |_, _| [0.0; 3]);
        vr.pixels[1][2] = f32::INFINITY;
        let mut r = t.clone();
        r.pixels[2][1] = f32::NEG_INFINITY;
        let o = z_test(&x2, &vx, &r, &vr, 10.0).unwrap();
        assert_eq!(o.nonfinite_pixels, 3);
        assert_eq!(o.pass_fraction, 0.97, "the other 97 are within 10 σ");
        assert!(o.max_abs_z.is_finite() && o.mean_z.is_finite());
        assert_eq!(o.z_map.pixels[0], [f32::MAX; 3]);
    }

    #[test]
    fn channels_without_variance_pass_only_when_equal_and_stay_out_of_the_statistics() {
        // A light pixel: every sample saw it, so neither image has variance there; a float
        // apart it fails, but its z (difference / 1e-154) must not swamp max_abs_z and mean_z.
        let t = truth(4, 4);
        let zero = Image::from_fn(4, 4, |_, _| [0.0; 3]);
        let noisy = Image::from_fn(4, 4, |_, _| [0.01; 3]);
        let mut x = t.clone();
        x.pixels[5][0] += 1e-3;
        let mut vx = noisy.clone();
        vx.pixels[5] = [0.0; 3];
        let mut vr = zero.clone();
        vr.pixels[6] = [0.0; 3];
        let o = z_test(&x, &vx, &t, &vr, 3.29).unwrap();
        assert_eq!(o.zero_variance_channels, 3);
        assert_eq!(o.pass_fraction, 15.0 / 16.0, "the unequal pixel without variance fails");
        assert_eq!((o.max_abs_z, o.mean_z), (0.0, 0.0), "the noisy pixels agree exactly");
        assert!(o.z_map.pixels[5][0] > 1e30);
    }

    #[test]
    fn the_node_reports_metrics_and_says_whether_the_test_passed() {
        let t = truth(32, 32);
        let (x, vx) = estimate(&t, [0.1; 3], 0.0, 4);
        let zero = Image::from_fn(32, 32, |_, _| [0.0; 3]);
        let inputs = || vec![Value::new(x.clone()), Value::new(vx.clone()), Value::new(t.clone()), Value::new(zero.clone())];
        let e = run_full::<ZTest>(&[], Path::new("."), inputs()).unwrap();
        let m: Metrics = e.outputs[0].get::<Metrics>().unwrap().clone();
        let names: Vec<_> = e.metrics.iter().map(|(k, _)| k.as_str()).collect();
        assert_eq!(names, ["pass_fraction", "max_abs_z", "mean_z", "pixels", "nonfinite_pixels", "zero_variance_channels"]);
        assert_eq!(m.get("pixels"), Some(1024.0));
        assert!(e.notes[0].starts_with("z-test passes"), "{:?}", e.notes);
        let zmap: Image = e.outputs[1].get::<Image>().unwrap().clone();
        assert_eq!((zmap.width, zmap.height), (32, 32));
        let e = run_full::<ZTest>(&[("z", f(0.5))], Path::new("."), inputs()).unwrap();
        assert!(e.notes[0].starts_with("z-test fails"), "{:?}", e.notes);
        let e = run_full::<ZTest>(&[("min_pass", f(0.0)), ("z", f(0.5))], Path::new("."), inputs()).unwrap();
        assert!(e.notes[0].starts_with("z-test passes"), "{:?}", e.notes);
    }

    #[test]
    fn cancels_midway_through_a_large_image() {
        let t = truth(512, 512);
        let (x, vx) = estimate(&t, [0.1; 3], 0.0, 5);
        let zero = Image::from_fn(512, 512, |_, _| [0.0; 3]);
        cancels_midway::<ZTest>(&[], vec![Value::new(x), Value::new(vx), Value::new(t), Value::new(zero)]);
    }
}
