//! GaussianBlur node.

use crate::types::Image;
use rayon::prelude::*;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};

node_doc! {
    /// Separable Gaussian blur with clamp-to-edge borders. The kernel reaches
    /// ceil(truncate · σ) pixels each way and is normalised to sum 1, so a constant image stays
    /// constant; σ = 0 returns the input unchanged.
    pub struct GaussianBlur;
}

pub struct GaussianBlurParams {
    pub sigma: f64,
    pub truncate: f64,
}

impl Params for GaussianBlurParams {
    fn schema() -> Schema {
        Schema::new()
            .float("sigma", 1.0, 0.0, 256.0)
            .unit("px")
            .help("standard deviation of the Gaussian")
            .float("truncate", 3.0, 1.0, 8.0)
            .unit("σ")
            .help("kernel radius in standard deviations")
    }
    fn from_values(v: &ParamValues) -> Self {
        GaussianBlurParams { sigma: v.float("sigma"), truncate: v.float("truncate") }
    }
}

/// Normalised 1-D Gaussian weights for offsets −r..=r.
pub fn gaussian_kernel(sigma: f64, truncate: f64) -> Vec<f32> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let r = (truncate * sigma).ceil() as i64;
    let w: Vec<f64> = (-r..=r).map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp()).collect();
    let sum: f64 = w.iter().sum();
    w.iter().map(|x| (x / sum) as f32).collect()
}

/// Convolves rows (horizontal) of `src` with `k`, clamping at the borders.
fn blur_rows(src: &[[f32; 3]], w: usize, k: &[f32]) -> Vec<[f32; 3]> {
    let r = (k.len() / 2) as i64;
    let mut out = vec![[0.0; 3]; src.len()];
    out.par_chunks_mut(w).zip(src.par_chunks(w)).for_each(|(o, row)| {
        for (x, px) in o.iter_mut().enumerate() {
            let mut acc = [0.0f32; 3];
            for (j, &kw) in k.iter().enumerate() {
                let sx = (x as i64 + j as i64 - r).clamp(0, w as i64 - 1) as usize;
                for c in 0..3 {
                    acc[c] += kw * row[sx][c];
                }
            }
            *px = acc;
        }
    });
    out
}

fn transpose(src: &[[f32; 3]], w: usize, h: usize) -> Vec<[f32; 3]> {
    (0..w * h).map(|i| src[(i % h) * w + i / h]).collect()
}

/// Blurs an image (shared with later pipeline stages).
pub fn gaussian_blur(img: &Image, sigma: f64, truncate: f64) -> Image {
    let k = gaussian_kernel(sigma, truncate);
    if k.len() == 1 {
        return img.clone();
    }
    let (w, h) = (img.width, img.height);
    let horizontal = blur_rows(&img.pixels, w, &k);
    let vertical_t = blur_rows(&transpose(&horizontal, w, h), h, &k);
    Image { width: w, height: h, pixels: transpose(&vertical_t, h, w) }
}

impl Node for GaussianBlur {
    const KIND: &'static str = "GaussianBlur";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "image";
    const CACHING: Caching = Caching::Disk;
    type Params = GaussianBlurParams;

    fn ports() -> Ports {
        Ports::new().input::<Image>("image").output::<Image>("image")
    }

    fn run(&self, p: &GaussianBlurParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        cx.check()?;
        let out = gaussian_blur(io.input::<Image>("image")?, p.sigma, p.truncate);
        cx.progress(1, 1);
        io.set("image", out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{f, first, run_on};
    use relume_core::Value;

    #[test]
    fn kernel_is_normalised_and_symmetric() {
        let k = gaussian_kernel(2.0, 3.0);
        assert_eq!(k.len(), 13);
        assert!((k.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert_eq!(k[0], k[12]);
        assert_eq!(gaussian_kernel(0.0, 3.0), vec![1.0]);
    }

    #[test]
    fn preserves_constants_and_total_energy_of_an_impulse() {
        let c = Image::from_fn(9, 7, |_, _| [0.25, 1.0, 3.0]);
        let out: Image = first(&run_on(GaussianBlur, &[("sigma", f(1.5))], vec![Value::new(c.clone())]).unwrap());
        for (a, b) in out.as_floats().iter().zip(c.as_floats()) {
            assert!((a - b).abs() < 1e-5);
        }
        let imp = Image::from_fn(31, 31, |x, y| [if (x, y) == (15, 15) { 1.0 } else { 0.0 }; 3]);
        let out = gaussian_blur(&imp, 2.0, 3.0);
        let total: f32 = out.pixels.iter().map(|p| p[0]).sum();
        assert!((total - 1.0).abs() < 1e-5, "{total}");
        assert!(out.get(15, 15)[0] > out.get(16, 15)[0]);
        assert_eq!(out.get(14, 15), out.get(16, 15));
    }

    #[test]
    fn extreme_sizes_stay_finite() {
        let one = Image::from_fn(1, 1, |_, _| [2.0; 3]);
        let big = gaussian_blur(&one, 256.0, 8.0);
        assert!((big.get(0, 0)[0] - 2.0).abs() < 1e-4, "{:?}", big.pixels);
        let strip = Image::from_fn(1, 50, |_, y| [y as f32; 3]);
        let out = gaussian_blur(&strip, 100.0, 3.0);
        assert!(out.as_floats().iter().all(|x| x.is_finite() && (0.0..=49.0).contains(x)));
        assert_eq!(gaussian_blur(&strip, 0.0, 3.0), strip);
    }
}
