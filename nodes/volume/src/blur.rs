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
    let ch = v.channels as usize;
    let live = live_channels(v);
    if live.len() < ch {
        return blur_live(v, &live, kernel, cx);
    }
    let d = v.dims.map(|x| x as usize);
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

/// The channels of `v` holding a value other than zero somewhere, ascending.
fn live_channels(v: &Volume) -> Vec<usize> {
    let ch = v.channels as usize;
    let mut live = vec![false; ch];
    for voxel in v.data.chunks_exact(ch) {
        for (l, &x) in live.iter_mut().zip(voxel) {
            *l |= x != 0.0;
        }
        if live.iter().all(|&l| l) {
            break;
        }
    }
    (0..ch).filter(|&c| live[c]).collect()
}

/// `blur` where only the channels `live` hold anything but zeros: each output of a zero
/// channel is a sum of w × 0 (+0 whatever the sign of the zeros), so only the live channels
/// are blurred, gathered into a volume of their own; every voxel's sum is the one the whole
/// volume's blur makes, in the same tap order (the same bytes, in a third of the time for an
/// index-only medium).
fn blur_live(v: &Volume, live: &[usize], kernel: &[f32], cx: &RunCtx) -> Result<Volume, NodeError> {
    let ch = v.channels as usize;
    let mut data = vec![0.0f32; v.data.len()];
    if !live.is_empty() {
        let k = live.len();
        let mut part = Volume {
            dims: v.dims,
            channels: k as u32,
            min: v.min,
            max: v.max,
            data: Vec::with_capacity(v.voxels() * k),
            derived: Default::default(),
        };
        part.data.extend(v.data.chunks_exact(ch).flat_map(|voxel| live.iter().map(|&c| voxel[c])));
        let part = blur(&part, kernel, cx)?;
        put_channels(&part, live, &mut data, ch);
    }
    Ok(Volume { dims: v.dims, channels: v.channels, min: v.min, max: v.max, data, derived: Default::default() })
}

/// Writes the channels of `part` (one per entry of `live`) into channels `live` of `data`, a
/// grid of the same voxels with `ch` channels each; the other channels are left as they are.
pub fn put_channels(part: &Volume, live: &[usize], data: &mut [f32], ch: usize) {
    for (out, voxel) in data.chunks_exact_mut(ch).zip(part.data.chunks_exact(live.len())) {
        for (&c, &x) in live.iter().zip(voxel) {
            out[c] = x;
        }
    }
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

    /// The blur of every channel, one sum per voxel and channel in tap order, faces
    /// replicated: what `blur` must give to the bit.
    fn plain(v: &Volume, k: &[f32]) -> Vec<f32> {
        let d = v.dims.map(|x| x as i64);
        let ch = v.channels as usize;
        let r = (k.len() / 2) as i64;
        let mut src = v.data.clone();
        for axis in 0..3 {
            let mut dst = vec![0.0f32; src.len()];
            for z in 0..d[2] {
                for y in 0..d[1] {
                    for x in 0..d[0] {
                        for c in 0..ch {
                            let mut acc = 0.0f32;
                            for (j, &w) in k.iter().enumerate() {
                                let mut p = [x, y, z];
                                p[axis] = (p[axis] + j as i64 - r).clamp(0, d[axis] - 1);
                                acc += w * src[((p[2] * d[1] + p[1]) * d[0] + p[0]) as usize * ch + c];
                            }
                            dst[((z * d[1] + y) * d[0] + x) as usize * ch + c] = acc;
                        }
                    }
                }
            }
            src = dst;
        }
        src
    }

    #[test]
    fn channels_of_zeros_are_left_out_and_the_rest_come_out_to_the_bit() {
        // Three channels as Voxelize writes them for glass without a medium (n, then κ = σ =
        // 0, some of them −0), one with a medium, and all zeros.
        let mut v = Volume::try_new([11, 9, 6], 3, Vec3::ZERO, Vec3::ONE, 0.0, u64::MAX).unwrap();
        for (i, voxel) in v.data.chunks_exact_mut(3).enumerate() {
            voxel[0] = 1.0 + 0.5 * ((i * 7919 % 13) as f32 / 13.0);
            voxel[1] = if i % 5 == 0 { -0.0 } else { 0.0 };
        }
        let k = kernel(3, 1.0);
        let want = plain(&v, &k);
        let got = run(&v, &k);
        assert_eq!(live_channels(&v), vec![0]);
        assert_eq!(got.data.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), want.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
        v.data.iter_mut().skip(2).step_by(3).enumerate().for_each(|(i, x)| *x = (i % 3) as f32 * 0.25);
        assert_eq!(live_channels(&v), vec![0, 2]);
        let (want, got) = (plain(&v, &k), run(&v, &k));
        assert_eq!(got.data.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), want.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
        v.data.iter_mut().for_each(|x| *x = -0.0);
        assert!(run(&v, &k).data.iter().all(|x| x.to_bits() == 0), "zeros blur to +0");
    }
}
