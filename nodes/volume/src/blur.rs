//! Separable 3-D Gaussian blur of a volume ([S] 6.3.1: 7³ or 9³ after voxelisation; 3³ after
//! photon marching): one normalised 1-D kernel of 2r + 1 taps along x, y and z in turn, faces
//! replicated, so a constant volume stays constant and the sum is kept away from the faces.
//! Each output voxel is one fixed-order sum: the same bytes on any thread count.

use crate::types::volume::Volume;
use relume_core::{NodeError, RunCtx};

/// The normalised Gaussian of `2 · radius + 1` taps with standard deviation `sigma` voxels
/// (`sigma` ≤ 0: the identity).
pub fn kernel(radius: usize, sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 || radius == 0 {
        return vec![1.0];
    }
    let w: Vec<f64> =
        (0..=2 * radius).map(|i| (-((i as f64 - radius as f64).powi(2)) / (2.0 * sigma as f64 * sigma as f64)).exp()).collect();
    let s: f64 = w.iter().sum();
    w.iter().map(|v| (v / s) as f32).collect()
}

/// `v` blurred by `kernel` along each axis (all channels), slices in parallel. Each pass
/// works on whole rows: along y and z a tap is a whole x row (clamped at the faces), along x
/// a tap is the row shifted by whole voxels, clamped only in the `radius` voxels at either end;
/// every output is still 0 + w₀ s₀ + w₁ s₁ + … in tap order, so the loops vectorise and the
/// bytes stay those of one sum per voxel.
pub fn blur(v: &Volume, kernel: &[f32], cx: &RunCtx) -> Result<Volume, NodeError> {
    if kernel.len() / 2 == 0 {
        return Ok(v.clone());
    }
    let d = v.dims.map(|x| x as usize);
    let ch = v.channels as usize;
    let row = d[0] * ch;
    let slice = d[1] * row;
    let mut src = v.data.clone();
    let mut dst = vec![0.0f32; src.len()];
    for axis in 0..3 {
        let s = &src;
        cx.par_chunks_mut(&mut dst, slice, |z, out| {
            for (y, o) in out.chunks_exact_mut(row).enumerate() {
                match axis {
                    0 => blur_row(&s[z * slice + y * row..][..row], ch, kernel, o),
                    1 => blur_across(kernel, y, d[1], |q| &s[z * slice + q * row..][..row], o),
                    _ => blur_across(kernel, z, d[2], |q| &s[q * slice + y * row..][..row], o),
                }
            }
        })?;
        std::mem::swap(&mut src, &mut dst);
    }
    Ok(Volume { dims: v.dims, channels: v.channels, min: v.min, max: v.max, data: src, derived: Default::default() })
}

/// One output row blurred across rows: `row_at(q)` is the source row at position q of `n`
/// along the axis, `pos` the output's position.
fn blur_across<'a>(kernel: &[f32], pos: usize, n: usize, row_at: impl Fn(usize) -> &'a [f32], out: &mut [f32]) {
    let r = kernel.len() / 2;
    out.fill(0.0);
    for (k, &w) in kernel.iter().enumerate() {
        let q = (pos as i64 + k as i64 - r as i64).clamp(0, n as i64 - 1) as usize;
        for (o, &x) in out.iter_mut().zip(row_at(q)) {
            *o += w * x;
        }
    }
}

/// One x row of `ch`-channel voxels blurred along x, faces replicated.
fn blur_row(src: &[f32], ch: usize, kernel: &[f32], out: &mut [f32]) {
    let r = kernel.len() / 2;
    let n = src.len() / ch;
    let clamped = |x: usize, c: usize| {
        let mut acc = 0.0f32;
        for (k, w) in kernel.iter().enumerate() {
            let q = (x as i64 + k as i64 - r as i64).clamp(0, n as i64 - 1) as usize;
            acc += w * src[q * ch + c];
        }
        acc
    };
    if n <= 2 * r {
        for x in 0..n {
            for c in 0..ch {
                out[x * ch + c] = clamped(x, c);
            }
        }
        return;
    }
    // The voxels r .. n − r reach no face: tap k reads the row shifted by k − r voxels.
    let inner = &mut out[r * ch..(n - r) * ch];
    inner.fill(0.0);
    for (k, &w) in kernel.iter().enumerate() {
        for (o, &x) in inner.iter_mut().zip(&src[k * ch..]) {
            *o += w * x;
        }
    }
    for x in (0..r).chain(n - r..n) {
        for c in 0..ch {
            out[x * ch + c] = clamped(x, c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use relume_base::render::film::with_ctx;

    fn run(v: &Volume, k: &[f32]) -> Volume {
        with_ctx(None, |cx| blur(v, k, cx)).unwrap()
    }

    #[test]
    fn the_kernel_is_normalised_and_symmetric() {
        for (r, s) in [(1, 0.8), (3, 1.5), (4, 2.0)] {
            let k = kernel(r, s);
            assert_eq!(k.len(), 2 * r + 1);
            assert!((k.iter().sum::<f32>() - 1.0).abs() < 1e-6);
            assert!((0..k.len()).all(|i| k[i] == k[k.len() - 1 - i]));
        }
        assert_eq!(kernel(3, 0.0), vec![1.0]);
    }

    #[test]
    fn a_constant_stays_constant_a_point_spreads_and_keeps_its_sum_and_threads_agree() {
        let mut v = Volume::try_new([9, 8, 7], 2, Vec3::ZERO, Vec3::ONE, 0.5, u64::MAX).unwrap();
        let k = kernel(3, 1.2);
        let flat = run(&v, &k);
        assert!(flat.data.iter().all(|x| (x - 0.5).abs() < 1e-6));
        v.data.fill(0.0);
        let i = v.index(4, 4, 3);
        v.data[i + 1] = 1.0;
        let b = run(&v, &k);
        let sum: f32 = b.data.iter().skip(1).step_by(2).sum();
        assert!((sum - 1.0).abs() < 1e-5, "{sum}");
        assert!(b.data.iter().step_by(2).all(|x| *x == 0.0), "channels stay apart");
        assert!(b.get(4, 4, 3, 1) > b.get(5, 4, 3, 1) && b.get(5, 4, 3, 1) > 0.0);
        assert!((b.get(5, 4, 3, 1) - b.get(3, 4, 3, 1)).abs() < 1e-7 && (b.get(4, 5, 3, 1) - b.get(4, 3, 3, 1)).abs() < 1e-7);
        let on = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap().install(|| run(&v, &k));
        assert_eq!(on(1), on(3));
    }
}
