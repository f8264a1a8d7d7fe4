use crate::types::Image;
use relume_core::{node, params, CancelToken, NodeError, RunCtx};

params! {
    /// Separable Gaussian blur with clamp-to-edge borders. The kernel reaches
    /// ceil(truncate · σ) pixels each way and is normalised to sum 1, so a constant image stays
    /// constant; σ = 0 returns the input unchanged.
    pub struct GaussianBlur {
        /// standard deviation of the Gaussian
        pub sigma: f64 = 1.0, range = 0.0..=256.0, unit = "px";
        /// kernel radius in standard deviations
        pub truncate: f64 = 3.0, range = 1.0..=8.0, unit = "σ";
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

/// Blurs an image (shared with later pipeline stages), outside a node run: never cancelled.
pub fn gaussian_blur(img: &Image, sigma: f64, truncate: f64) -> Image {
    let cancel = CancelToken::new();
    gaussian_blur_with(img, sigma, truncate, &RunCtx::new("gaussian_blur", &cancel, None)).expect("never cancelled")
}

/// Blurs an image row by row in parallel, with `cx`'s progress and cancellation: the rows
/// horizontally, then each output row from the blurred rows around it. Every output channel
/// sums its taps in kernel order starting from 0, so the result is the same on any thread
/// count.
pub fn gaussian_blur_with(img: &Image, sigma: f64, truncate: f64, cx: &RunCtx) -> Result<Image, NodeError> {
    let k = gaussian_kernel(sigma, truncate);
    if k.len() == 1 {
        return Ok(img.clone());
    }
    let (w, h) = (img.width, img.height);
    let r = (k.len() / 2) as i64;
    let src = &img.pixels;
    let mut horizontal = vec![[0.0f32; 3]; src.len()];
    cx.phase(0.0, 0.5);
    cx.par_chunks_mut(&mut horizontal, w, |y, o| {
        let row = &src[y * w..(y + 1) * w];
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
    })?;
    let mut out = vec![[0.0f32; 3]; src.len()];
    cx.phase(0.5, 1.0);
    cx.par_chunks_mut(&mut out, w, |y, o| {
        for (j, &kw) in k.iter().enumerate() {
            let sy = (y as i64 + j as i64 - r).clamp(0, h as i64 - 1) as usize;
            let row = &horizontal[sy * w..(sy + 1) * w];
            for (px, s) in o.iter_mut().zip(row) {
                for c in 0..3 {
                    px[c] += kw * s[c];
                }
            }
        }
    })?;
    Ok(Image { width: w, height: h, pixels: out })
}

#[node(category = "image", outputs = [image])]
impl GaussianBlur {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The horizontal pass's image besides the output.
        relume_core::MemoryEstimate { outputs: vec![inputs[0]], working: inputs[0].map_or(0, |s| s.bytes) }
    }

    fn run(&self, image: &Image, cx: &RunCtx) -> Result<Image, NodeError> {
        gaussian_blur_with(image, self.sigma, self.truncate, cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{cancels_midway, f, first, run_on};
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
        let out: Image = first(&run_on::<GaussianBlur>(&[("sigma", f(1.5))], vec![Value::new(c.clone())]).unwrap());
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

    /// The blur of the old implementation (rows, transpose, rows, transpose), kept to show
    /// the row-wise vertical pass gives the same bits.
    fn blur_by_transposes(img: &Image, sigma: f64, truncate: f64) -> Image {
        fn blur_rows(src: &[[f32; 3]], w: usize, k: &[f32]) -> Vec<[f32; 3]> {
            let r = (k.len() / 2) as i64;
            let mut out = vec![[0.0; 3]; src.len()];
            for (o, row) in out.chunks_mut(w).zip(src.chunks(w)) {
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
            }
            out
        }
        fn transpose(src: &[[f32; 3]], w: usize, h: usize) -> Vec<[f32; 3]> {
            (0..w * h).map(|i| src[(i % h) * w + i / h]).collect()
        }
        let k = gaussian_kernel(sigma, truncate);
        let (w, h) = (img.width, img.height);
        let horizontal = blur_rows(&img.pixels, w, &k);
        let vertical_t = blur_rows(&transpose(&horizontal, w, h), h, &k);
        Image { width: w, height: h, pixels: transpose(&vertical_t, h, w) }
    }

    #[test]
    fn matches_the_transposing_implementation_bit_for_bit() {
        let img = crate::testing::images::with_noise(&crate::testing::images::scene(), 0.3, 7);
        for (sigma, truncate) in [(0.7, 3.0), (2.5, 3.0), (40.0, 1.0)] {
            let a = gaussian_blur(&img, sigma, truncate);
            let b = blur_by_transposes(&img, sigma, truncate);
            assert!(a.as_floats().iter().zip(b.as_floats()).all(|(x, y)| x.to_bits() == y.to_bits()), "σ = {sigma}");
        }
    }

    #[test]
    fn cancels_midway_through_a_large_image() {
        let img = Image::from_fn(512, 512, |x, y| [x as f32, y as f32, 1.0]);
        cancels_midway::<GaussianBlur>(&[("sigma", f(4.0))], vec![Value::new(img)]);
    }
}
