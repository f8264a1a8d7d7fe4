//! The orthonormal 2-D Haar transform of square power-of-two images, in the *non-standard*
//! order (one level = a pass over the rows and a pass over the columns of the current
//! low-pass block, then recurse on its top-left quarter): the variant of the relighting and
//! wavelet-lighting literature (Ng et al. 2003; [S] 4.2), whose basis functions are square and
//! so keep local detail local. Orthonormal: energy is preserved (Parseval), so keeping the
//! largest coefficients is the best k-term approximation in L2.
//!
//! Images of other sizes are padded explicitly to the next power-of-two square by repeating
//! their edge texels (no artificial edge for the wavelets to pay for) and cropped back after
//! the inverse. Non-linear approximation keeps the k largest coefficients by magnitude, ties
//! broken by index, so the result does not depend on anything but the values.

use std::f32::consts::FRAC_1_SQRT_2;

/// One level over the `s × s` top-left block of an `n`-wide image: rows, then columns.
fn forward_level(d: &mut [f32], n: usize, s: usize, tmp: &mut [f32]) {
    let h = s / 2;
    for y in 0..s {
        let row = &mut d[y * n..y * n + s];
        for i in 0..h {
            let (a, b) = (row[2 * i], row[2 * i + 1]);
            tmp[i] = (a + b) * FRAC_1_SQRT_2;
            tmp[h + i] = (a - b) * FRAC_1_SQRT_2;
        }
        row.copy_from_slice(&tmp[..s]);
    }
    for x in 0..s {
        for i in 0..h {
            let (a, b) = (d[2 * i * n + x], d[(2 * i + 1) * n + x]);
            tmp[i] = (a + b) * FRAC_1_SQRT_2;
            tmp[h + i] = (a - b) * FRAC_1_SQRT_2;
        }
        for (y, v) in tmp[..s].iter().enumerate() {
            d[y * n + x] = *v;
        }
    }
}

/// The inverse of `forward_level`: columns, then rows.
fn inverse_level(d: &mut [f32], n: usize, s: usize, tmp: &mut [f32]) {
    let h = s / 2;
    for x in 0..s {
        for i in 0..h {
            let (a, b) = (d[i * n + x], d[(h + i) * n + x]);
            tmp[2 * i] = (a + b) * FRAC_1_SQRT_2;
            tmp[2 * i + 1] = (a - b) * FRAC_1_SQRT_2;
        }
        for (y, v) in tmp[..s].iter().enumerate() {
            d[y * n + x] = *v;
        }
    }
    for y in 0..s {
        let row = &mut d[y * n..y * n + s];
        for i in 0..h {
            let (a, b) = (row[i], row[h + i]);
            tmp[2 * i] = (a + b) * FRAC_1_SQRT_2;
            tmp[2 * i + 1] = (a - b) * FRAC_1_SQRT_2;
        }
        row.copy_from_slice(&tmp[..s]);
    }
}

fn check(d: &[f32], n: usize) {
    assert!(n.is_power_of_two() && d.len() == n * n, "a Haar image is n × n with n a power of two ({} values, n = {n})", d.len());
}

/// The forward transform of the `n × n` image `d` (row-major), in place.
pub fn forward(d: &mut [f32], n: usize) {
    check(d, n);
    let mut tmp = vec![0.0f32; n];
    let mut s = n;
    while s > 1 {
        forward_level(d, n, s, &mut tmp);
        s /= 2;
    }
}

/// The inverse of `forward`, in place.
pub fn inverse(d: &mut [f32], n: usize) {
    check(d, n);
    let mut tmp = vec![0.0f32; n];
    let mut s = 2;
    while s <= n {
        inverse_level(d, n, s, &mut tmp);
        s *= 2;
    }
}

/// The side of the square a `w × h` image is padded to: the next power of two of the larger.
pub fn padded_side(w: usize, h: usize) -> usize {
    w.max(h).max(1).next_power_of_two()
}

/// `src` (`w × h`, row-major) padded to `padded_side(w, h)` squared by repeating its last
/// column and row.
pub fn pad(src: &[f32], w: usize, h: usize) -> (Vec<f32>, usize) {
    assert_eq!(src.len(), w * h);
    let n = padded_side(w, h);
    let mut out = vec![0.0f32; n * n];
    if w == 0 || h == 0 {
        return (out, n);
    }
    for y in 0..n {
        let sy = y.min(h - 1);
        for x in 0..n {
            out[y * n + x] = src[sy * w + x.min(w - 1)];
        }
    }
    (out, n)
}

/// The top-left `w × h` of an `n`-wide padded image.
pub fn crop(padded: &[f32], n: usize, w: usize, h: usize) -> Vec<f32> {
    (0..h).flat_map(|y| padded[y * n..y * n + w].iter().copied()).collect()
}

/// A k-term approximation: the kept coefficients' indices (ascending) and values.
#[derive(Clone, Debug, PartialEq)]
pub struct Sparse {
    pub n: usize,
    pub index: Vec<u32>,
    pub value: Vec<f32>,
}

impl Sparse {
    /// The `n × n` coefficient image with only the kept terms.
    pub fn dense(&self) -> Vec<f32> {
        let mut d = vec![0.0f32; self.n * self.n];
        for (i, v) in self.index.iter().zip(&self.value) {
            d[*i as usize] = *v;
        }
        d
    }
}

/// Keeps the `k` coefficients of largest magnitude (ties to the lower index; zeros are never
/// kept, so a constant image keeps one term whatever `k`).
pub fn keep_largest(c: &[f32], n: usize, k: usize) -> Sparse {
    let mut order: Vec<u32> = (0..c.len() as u32).filter(|&i| c[i as usize] != 0.0).collect();
    let k = k.min(order.len());
    if k < order.len() {
        let key = |i: &u32| (std::cmp::Reverse(ordered(c[*i as usize].abs())), *i);
        order.select_nth_unstable_by_key(k, key);
        order.truncate(k);
    }
    order.sort_unstable();
    let value = order.iter().map(|&i| c[i as usize]).collect();
    Sparse { n, index: order, value }
}

/// A total order on non-negative finite floats (NaN last).
fn ordered(x: f32) -> u32 {
    if x.is_nan() {
        0
    } else {
        x.to_bits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn energy(d: &[f32]) -> f64 {
        d.iter().map(|v| (*v as f64).powi(2)).sum()
    }

    #[test]
    fn a_constant_image_is_one_coefficient() {
        for n in [1usize, 2, 8, 64] {
            let mut d = vec![0.75f32; n * n];
            forward(&mut d, n);
            let nz: Vec<usize> = (0..n * n).filter(|&i| d[i] != 0.0).collect();
            assert_eq!(nz, [0], "n = {n}");
            assert!((d[0] - 0.75 * n as f32).abs() < 1e-5 * n as f32, "the average times n: {}", d[0]);
            assert_eq!(keep_largest(&d, n, 50).index, [0]);
        }
    }

    #[test]
    fn a_single_bright_texel_survives_with_three_terms_a_level_and_the_average() {
        let n = 32;
        let mut d = vec![0.0f32; n * n];
        d[13 * n + 22] = 1.0e4;
        let orig = d.clone();
        forward(&mut d, n);
        let levels = n.trailing_zeros() as usize;
        let nz = d.iter().filter(|v| **v != 0.0).count();
        assert_eq!(nz, 3 * levels + 1);
        let kept = keep_largest(&d, n, 3 * levels + 1);
        let mut back = kept.dense();
        inverse(&mut back, n);
        for (a, b) in back.iter().zip(&orig) {
            assert!((a - b).abs() < 1e-3, "{a} vs {b}");
        }
        // Fewer terms keep less of it, never more.
        let mut fewer = keep_largest(&d, n, 4).dense();
        inverse(&mut fewer, n);
        assert!(fewer[13 * n + 22] > 0.0 && fewer[13 * n + 22] < 1.0e4);
    }

    #[test]
    fn a_non_power_of_two_image_pads_by_its_edges_and_crops_back() {
        let (w, h) = (6, 3);
        let src: Vec<f32> = (0..w * h).map(|i| (i * 7 % 5) as f32).collect();
        let (mut p, n) = pad(&src, w, h);
        assert_eq!(n, 8);
        assert_eq!(p[7 * n + 7], src[2 * w + 5], "the corner repeats the last texel");
        forward(&mut p, n);
        inverse(&mut p, n);
        let back = crop(&p, n, w, h);
        for (a, b) in back.iter().zip(&src) {
            assert!((a - b).abs() < 1e-5);
        }
        // A constant non-power-of-two image stays one coefficient after padding.
        let (mut c, n) = pad(&[2.0; 15], 5, 3);
        forward(&mut c, n);
        assert_eq!(c.iter().filter(|v| **v != 0.0).count(), 1);
    }

    #[test]
    fn ties_keep_the_lower_index_and_zeros_are_never_kept() {
        let c = [0.0, 1.0, -1.0, 0.5, 1.0];
        assert_eq!(keep_largest(&c, 1, 2).index, [1, 2]);
        assert_eq!(keep_largest(&c, 1, 10).index, [1, 2, 3, 4]);
        assert_eq!(keep_largest(&c, 1, 0).index, Vec::<u32>::new());
    }

    proptest! {
        #[test]
        fn round_trip_and_parseval(log_n in 0u32..6, seed in any::<u64>()) {
            let n = 1usize << log_n;
            let src: Vec<f32> = (0..n * n).map(|i| crate::math::rng::uniform(seed, i as u64, 0) * 4.0 - 2.0).collect();
            let mut d = src.clone();
            forward(&mut d, n);
            prop_assert!((energy(&d) - energy(&src)).abs() <= 1e-4 * energy(&src).max(1e-9));
            inverse(&mut d, n);
            for (a, b) in d.iter().zip(&src) {
                prop_assert!((a - b).abs() < 1e-4);
            }
        }

        #[test]
        fn keeping_more_terms_never_raises_the_error(seed in any::<u64>(), k in 1usize..64) {
            let n = 16;
            let src: Vec<f32> = (0..n * n).map(|i| crate::math::rng::uniform(seed, i as u64, 1)).collect();
            let mut c = src.clone();
            forward(&mut c, n);
            let err = |k: usize| {
                let mut d = keep_largest(&c, n, k).dense();
                inverse(&mut d, n);
                d.iter().zip(&src).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>()
            };
            prop_assert!(err(k + 1) <= err(k) + 1e-6);
            // The error is the energy of the dropped coefficients (orthonormal).
            let kept = keep_largest(&c, n, k);
            let dropped = energy(&c) - energy(&kept.value);
            prop_assert!((err(k) - dropped).abs() < 1e-3 * energy(&c));
        }
    }
}
