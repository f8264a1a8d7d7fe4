//! ImageError node.

use crate::types::{Image, Metrics};
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};

node_doc! {
    /// Error of an image against a reference of the same size, into the run report:
    /// MSE (mean over pixels and channels of (x − r)²), relative MSE (mean of
    /// (x − r)² / (r² + ε)), PSNR = 10 log10(peak² / MSE) in dB, and the theses' L2 % =
    /// 100 · ‖x − r‖₂ / ‖r‖₂. Pixels where either image is not finite are left out of every
    /// figure and counted in `nonfinite_pixels`. Also outputs the per-pixel squared-error map.
    pub struct ImageError;
}

pub struct ImageErrorParams {
    pub peak: f64,
    pub epsilon: f64,
}

impl Params for ImageErrorParams {
    fn schema() -> Schema {
        Schema::new()
            .float("peak", 1.0, 1e-6, 1e6)
            .help("signal peak used by PSNR")
            .float("epsilon", 1e-2, 1e-8, 1.0)
            .help("ε in relative MSE's denominator (r² + ε), keeps dark pixels from dominating")
    }
    fn from_values(v: &ParamValues) -> Self {
        ImageErrorParams { peak: v.float("peak"), epsilon: v.float("epsilon") }
    }
}

/// Error figures of `x` against `r` (same size), in the order the report lists them.
pub fn error_metrics(x: &Image, r: &Image, peak: f64, epsilon: f64) -> Metrics {
    let (mut se, mut rel, mut ref2, mut n, mut bad) = (0.0f64, 0.0f64, 0.0f64, 0usize, 0usize);
    for (a, b) in x.pixels.iter().zip(&r.pixels) {
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
    Metrics(vec![
        ("mse".into(), mse),
        ("rel_mse".into(), rel / count),
        ("psnr_db".into(), psnr),
        ("l2_percent".into(), l2),
        ("nonfinite_pixels".into(), bad as f64),
    ])
}

impl Node for ImageError {
    const KIND: &'static str = "ImageError";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "quality";
    const CACHING: Caching = Caching::Disk;
    type Params = ImageErrorParams;

    fn ports() -> Ports {
        Ports::new().input::<Image>("image").input::<Image>("reference").output::<Metrics>("metrics").output::<Image>("error_map")
    }

    fn run(&self, p: &ImageErrorParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        let (x, r) = (io.input::<Image>("image")?, io.input::<Image>("reference")?);
        r.check_same_size(x, "reference", "image")?;
        let m = error_metrics(x, r, p.peak, p.epsilon);
        for (k, v) in &m.0 {
            cx.metric(k, *v);
        }
        if m.get("nonfinite_pixels").unwrap_or(0.0) > 0.0 {
            cx.note(format!("{} pixels with NaN or infinity were left out of the error", m.get("nonfinite_pixels").unwrap()));
        }
        let map = x.pixels.iter().zip(&r.pixels).map(|(a, b)| std::array::from_fn(|c| (a[c] - b[c]) * (a[c] - b[c]))).collect();
        io.set("error_map", Image { width: x.width, height: x.height, pixels: map })?;
        io.set("metrics", m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::run_full;
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
        let e = run_full(ImageError, &[], Path::new("."), vec![Value::new(x), Value::new(r)]).unwrap();
        let m: Metrics = e.outputs[0].get::<Metrics>().unwrap().clone();
        assert_eq!(m.get("nonfinite_pixels"), Some(2.0));
        assert!((m.get("mse").unwrap() - 0.25).abs() < 1e-12);
        assert_eq!(m.get("l2_percent"), Some(f64::INFINITY), "zero reference: L2 % is unbounded");
        assert_eq!(e.metrics.len(), 5);
        assert_eq!(e.notes.len(), 1);
    }
}
