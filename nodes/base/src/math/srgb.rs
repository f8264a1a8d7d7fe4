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
}
