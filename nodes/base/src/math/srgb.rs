//! The sRGB transfer function (IEC 61966-2-1): PNG files and the perceptual metrics use it.

/// sRGB transfer function (linear → encoded), input clamped to [0, 1].
pub fn srgb_encode(x: f32) -> f32 {
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Buckets of the byte encoding's table: narrow enough that the byte steps at most once in
/// each (the curve's steepest slope, 12.92 · 255 per unit near 0, is 0.8 bytes a bucket).
const BUCKETS: usize = 4096;

/// `srgb_encode(x)` as a byte, `(srgb_encode(x) · 255).round()`, with the same result for
/// every input but without a power: the byte at the start of `x`'s bucket, plus one where `x`
/// is past the value at which the byte steps up. The 255 step values are found once, by
/// bisection over the f32 bit patterns of the monotone encoding. Displays call it per pixel
/// and channel.
pub fn srgb_encode_u8(x: f32) -> u8 {
    struct Table {
        steps: [f32; 255],
        start: [u8; BUCKETS],
    }
    static TABLE: std::sync::OnceLock<Box<Table>> = std::sync::OnceLock::new();
    let t = TABLE.get_or_init(|| {
        let byte = |bits: u32| (srgb_encode(f32::from_bits(bits)) * 255.0).round() as u32;
        let steps: [f32; 255] = std::array::from_fn(|k| {
            // The smallest non-negative x whose byte is above k.
            let (mut lo, mut hi) = (0u32, 1f32.to_bits());
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if byte(mid) > k as u32 {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            f32::from_bits(lo)
        });
        let start = std::array::from_fn(|i| steps.partition_point(|&s| s <= i as f32 / BUCKETS as f32) as u8);
        Box::new(Table { steps, start })
    });
    if x.is_nan() || x <= 0.0 {
        return 0;
    }
    if x >= 1.0 {
        return 255;
    }
    let b = t.start[((x * BUCKETS as f32) as usize).min(BUCKETS - 1)];
    b + (b < 255 && x >= t.steps[b as usize]) as u8
}

/// sRGB decoding (encoded → linear).
pub fn srgb_decode(x: f32) -> f32 {
    if x <= 0.040_45 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_curves_invert() {
        for i in 0..=100 {
            let x = i as f32 / 100.0;
            assert!((srgb_decode(srgb_encode(x)) - x).abs() < 1e-5);
        }
        assert_eq!(srgb_encode(f32::NAN), 0.0);
    }

    #[test]
    fn the_byte_encoding_equals_the_rounded_curve_everywhere() {
        let exact = |x: f32| (srgb_encode(x) * 255.0).round() as u8;
        // Every f32 in [0, 1] with the low 6 mantissa bits dropped (about 16 million), and the
        // neighbours of each step.
        for bits in (0..=1f32.to_bits()).step_by(64) {
            let x = f32::from_bits(bits);
            assert_eq!(srgb_encode_u8(x), exact(x), "{x}");
        }
        for x in [-1.0, -0.0, 1.0, 1.5, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 0.003_130_8, 1e-30] {
            assert_eq!(srgb_encode_u8(x), exact(x), "{x}");
        }
    }
}
