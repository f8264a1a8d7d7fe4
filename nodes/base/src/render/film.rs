//! Image assembly shared by the renderers: evaluating every pixel of an image with the rows in
//! parallel ([`per_pixel`]), and the [`Film`] that accumulates samples per pixel over
//! progressive passes into a mean and a variance of the mean. Both go through `RunCtx`
//! (progress per row, cancellation between rows) and give the same bytes on any thread count:
//! each pixel's samples are summed in sample order by one thread, and rows come back in order.

use crate::render::integrator::Counts;
use crate::types::Image;
use glam::Vec3;
use relume_core::{CancelToken, NodeError, RunCtx};
use std::ops::Range;

/// Runs `f` with `cx`, or with a context of its own (never cancelled, reporting to no one)
/// when there is none: callers outside a graph (tests, benchmarks) pass `None`.
pub fn with_ctx<R>(cx: Option<&RunCtx>, f: impl FnOnce(&RunCtx) -> R) -> R {
    match cx {
        Some(cx) => f(cx),
        None => {
            let cancel = CancelToken::new();
            f(&RunCtx::new("", &cancel, None))
        }
    }
}

/// A `width × height` image whose pixel (x, y) is `f(x, y, counts)`, rows in parallel; returns
/// it with the rays counted by all calls of `f`.
pub fn per_pixel(
    cx: &RunCtx,
    width: usize,
    height: usize,
    f: impl Fn(usize, usize, &mut Counts) -> [f32; 3] + Sync + Send,
) -> Result<(Image, u64), NodeError> {
    let ([img], rays) = per_pixel_layers(cx, width, height, |x, y, c| [f(x, y, c)])?;
    Ok((img, rays))
}

/// `per_pixel` for `L` images at once (a mean and its variance): `f` gives pixel (x, y) of each.
pub fn per_pixel_layers<const L: usize>(
    cx: &RunCtx,
    width: usize,
    height: usize,
    f: impl Fn(usize, usize, &mut Counts) -> [[f32; 3]; L] + Sync + Send,
) -> Result<([Image; L], u64), NodeError> {
    let mut imgs = Vec::with_capacity(L);
    for _ in 0..L {
        imgs.push(Image::try_new(width, height)?);
    }
    let rows = cx.par_map(height, |y| {
        let mut counts = Counts::default();
        let row: Vec<[[f32; 3]; L]> = (0..width).map(|x| f(x, y, &mut counts)).collect();
        (row, counts.rays)
    })?;
    let mut rays = 0;
    for (y, (row, r)) in rows.into_iter().enumerate() {
        for (l, img) in imgs.iter_mut().enumerate() {
            for (out, px) in img.pixels[y * width..(y + 1) * width].iter_mut().zip(&row) {
                *out = px[l];
            }
        }
        rays += r;
    }
    Ok((imgs.try_into().unwrap_or_else(|_| unreachable!("L images")), rays))
}

/// One row of a film: sums of the samples and of their squares per pixel (f64), and counts.
struct FilmRow {
    sum: Vec<[f64; 3]>,
    sum2: Vec<[f64; 3]>,
    rays: u64,
    nonfinite: u64,
}

/// Per-pixel sums of radiance samples, filled by passes over the whole image; finished into
/// the mean and the variance of the mean. NaN or infinite samples are dropped and counted.
pub struct Film {
    mean: Image,
    var: Image,
    rows: Vec<FilmRow>,
    samples: u32,
}

impl Film {
    /// An empty film; the output images are allocated now, so that a size over
    /// `MAX_IMAGE_BYTES` is refused before any work.
    pub fn try_new(width: usize, height: usize) -> Result<Film, NodeError> {
        let mean = Image::try_new(width, height)?;
        let var = Image::try_new(width, height)?;
        let row = || FilmRow { sum: vec![[0.0; 3]; width], sum2: vec![[0.0; 3]; width], rays: 0, nonfinite: 0 };
        Ok(Film { mean, var, rows: (0..height).map(|_| row()).collect(), samples: 0 })
    }

    /// Samples taken per pixel so far.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Rays counted by all samples so far.
    pub fn rays(&self) -> u64 {
        self.rows.iter().map(|r| r.rays).sum()
    }

    /// Samples that were NaN or infinite (dropped).
    pub fn nonfinite(&self) -> u64 {
        self.rows.iter().map(|r| r.nonfinite).sum()
    }

    /// One pass: adds the samples `samples` of every pixel, rows in parallel, each pixel's in
    /// sample order; `f(x, y, s, counts)` is sample `s` of pixel (x, y). The film must take
    /// its samples in order (`samples.start` = `self.samples()`).
    pub fn add_pass(
        &mut self,
        cx: &RunCtx,
        samples: Range<u32>,
        f: impl Fn(usize, usize, u32, &mut Counts) -> Vec3 + Sync + Send,
    ) -> Result<(), NodeError> {
        self.add_pass_with(cx, samples, |x, y, s, counts, _: &mut Vec<()>| f(x, y, s, counts)).map(drop)
    }

    /// As [`Film::add_pass`], where a sample may also leave records elsewhere (a light path's
    /// contributions to other pixels): `f` pushes them to the row's list, and the lists come
    /// back in row order, each in the order its row's samples pushed them, so the same bytes
    /// on any thread count.
    pub fn add_pass_with<T: Send>(
        &mut self,
        cx: &RunCtx,
        samples: Range<u32>,
        f: impl Fn(usize, usize, u32, &mut Counts, &mut Vec<T>) -> Vec3 + Sync + Send,
    ) -> Result<Vec<Vec<T>>, NodeError> {
        debug_assert_eq!(samples.start, self.samples, "samples are added in order");
        let taken = samples.len() as u32;
        let mut work: Vec<(&mut FilmRow, Vec<T>)> = self.rows.iter_mut().map(|r| (r, Vec::new())).collect();
        cx.par_chunks_mut(&mut work, 1, |y, rows| {
            let (row, records) = &mut rows[0];
            let mut counts = Counts::default();
            for (x, (sum, sum2)) in row.sum.iter_mut().zip(&mut row.sum2).enumerate() {
                for s in samples.clone() {
                    let l = f(x, y, s, &mut counts, records);
                    if !l.is_finite() {
                        row.nonfinite += 1;
                        continue;
                    }
                    for c in 0..3 {
                        sum[c] += l[c] as f64;
                        sum2[c] += (l[c] as f64) * (l[c] as f64);
                    }
                }
            }
            row.rays += counts.rays;
        })?;
        self.samples += taken;
        Ok(work.into_iter().map(|(_, r)| r).collect())
    }

    /// Takes `spp` samples per pixel in progressive passes of doubling size (1, 2, 4, …
    /// samples, the last pass what remains), with `f` as in [`Film::add_pass`]; `after_pass`
    /// sees the film after each pass but the last (a partial result for display).
    pub fn add_passes(
        &mut self,
        cx: &RunCtx,
        spp: u32,
        f: impl Fn(usize, usize, u32, &mut Counts) -> Vec3 + Sync + Send,
        mut after_pass: impl FnMut(&Film),
    ) -> Result<(), NodeError> {
        let mut pass = 1u32;
        while self.samples < spp {
            let first = self.samples;
            let n = pass.min(spp - first);
            cx.phase(first as f64 / spp as f64, (first + n) as f64 / spp as f64);
            self.add_pass(cx, first..first + n, &f)?;
            if self.samples < spp {
                after_pass(self);
            }
            pass = pass.saturating_mul(2);
        }
        Ok(())
    }

    /// The mean of the samples so far, and the (unbiased) variance of the mean per pixel
    /// channel (0 with fewer than 2 samples). Dropped samples count in the sample number `n`.
    pub fn snapshot(&self) -> Result<(Image, Image), NodeError> {
        let w = self.mean.width;
        let (mut mean, mut var) = (Image::try_new(w, self.rows.len())?, Image::try_new(w, self.rows.len())?);
        fill(&self.rows, self.samples, &mut mean, &mut var);
        Ok((mean, var))
    }

    /// The mean and the variance of the mean, as [`Film::snapshot`], into the images
    /// allocated when the film was made.
    pub fn finish(self) -> (Image, Image) {
        let Film { mut mean, mut var, rows, samples } = self;
        fill(&rows, samples, &mut mean, &mut var);
        (mean, var)
    }
}

/// The mean of the sums in `rows` over `samples` samples, and the variance of the mean.
fn fill(rows: &[FilmRow], samples: u32, mean: &mut Image, var: &mut Image) {
    let (n, w) = (samples as f64, mean.width);
    for (y, row) in rows.iter().enumerate() {
        for x in 0..w {
            let i = y * w + x;
            for c in 0..3 {
                let m = if samples > 0 { row.sum[x][c] / n } else { 0.0 };
                mean.pixels[i][c] = m as f32;
                var.pixels[i][c] = if samples > 1 { ((row.sum2[x][c] / n - m * m).max(0.0) / (n - 1.0)) as f32 } else { 0.0 };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_double_and_sum_in_sample_order() {
        let f = |x: usize, y: usize, s: u32, c: &mut Counts| {
            c.rays += 1;
            Vec3::splat((x + 10 * y) as f32 + 0.1 * s as f32)
        };
        let mut a = Film::try_new(3, 2).unwrap();
        // After each pass but the last (1, 2, 4 samples; then the last 4): the film so far.
        let mut seen = Vec::new();
        with_ctx(None, |cx| a.add_passes(cx, 11, f, |film| seen.push((film.samples(), film.snapshot().unwrap().0.get(2, 1)[0])))).unwrap();
        assert_eq!((a.samples(), a.rays(), a.nonfinite()), (11, 66, 0));
        assert_eq!(seen.iter().map(|s| s.0).collect::<Vec<_>>(), [1, 3, 7]);
        assert!((seen[1].1 - (12.0 + 0.1)).abs() < 1e-5, "the mean of samples 0, 1, 2: {:?}", seen[1]);
        // The same samples one at a time: the same sums, bit for bit.
        let mut b = Film::try_new(3, 2).unwrap();
        for s in 0..11 {
            with_ctx(None, |cx| b.add_pass(cx, s..s + 1, f)).unwrap();
        }
        let snapshot = a.snapshot().unwrap();
        let (ma, va) = a.finish();
        let (mb, vb) = b.finish();
        assert_eq!((ma.clone(), va.clone()), (mb, vb));
        assert_eq!(snapshot, (ma.clone(), va), "a snapshot at the end is the finished film");
        assert!((ma.get(2, 1)[0] - (12.0 + 0.5)).abs() < 1e-5, "{:?}", ma.get(2, 1));
    }

    #[test]
    fn nonfinite_samples_are_dropped_and_counted() {
        let mut film = Film::try_new(2, 1).unwrap();
        with_ctx(None, |cx| film.add_passes(cx, 4, |x, _, s, _| if x == 1 && s == 2 { Vec3::NAN } else { Vec3::ONE }, |_| {})).unwrap();
        assert_eq!(film.nonfinite(), 1);
        let (mean, var) = film.finish();
        assert_eq!(mean.pixels, vec![[1.0; 3], [0.75; 3]]);
        assert_eq!(var.get(0, 0), [0.0; 3]);
    }

    #[test]
    fn per_pixel_keeps_row_order_and_counts_rays() {
        let (img, rays) = with_ctx(None, |cx| {
            per_pixel(cx, 5, 4, |x, y, c| {
                c.rays += 2;
                [x as f32, y as f32, 0.0]
            })
        })
        .unwrap();
        assert_eq!(rays, 40);
        assert_eq!(img, Image::from_fn(5, 4, |x, y| [x as f32, y as f32, 0.0]));
    }

    #[test]
    fn a_too_large_film_is_refused_before_allocating() {
        assert!(Film::try_new(1 << 20, 1 << 20).is_err());
    }
}
