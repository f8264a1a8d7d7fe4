//! Shared math used by several nodes (one place for each piece).

pub mod atan;
pub mod cpca;
pub mod cta;
pub mod cube_haar;
pub mod cubemap;
pub mod frame;
pub mod haar;
pub mod kmeans;
pub mod latlong;
pub mod morton;
pub mod pca;
pub mod rng;
pub mod sampling;
pub mod sh;
pub mod sh_rotation;
pub mod srgb;
pub mod streamed_pca;
pub mod tree_coding;
pub mod tucker;

/// `count` values spread linearly over [lo, hi] (`lo` alone for one).
pub fn spread(count: usize, lo: f32, hi: f32) -> Vec<f64> {
    let (lo, hi) = (lo as f64, hi as f64);
    (0..count).map(|j| if count > 1 { lo + (hi - lo) * j as f64 / (count - 1) as f64 } else { lo }).collect()
}

/// ⌊v⌋ without the library call that baseline x86-64 makes of `f32::floor` (it has no
/// rounding instruction): the same value for every finite v (a zero keeps no sign).
#[inline]
pub fn floor_f32(v: f32) -> f32 {
    // From 2²³ on every f32 is a whole number (and NaN stays NaN).
    if v.is_nan() || v.abs() >= 8_388_608.0 {
        return v;
    }
    let t = v as i32 as f32;
    if t > v {
        t - 1.0
    } else {
        t
    }
}

/// Hints the processor to bring the cache line holding `x` into the cache (no effect on
/// what any code computes; nothing off x86-64): for reads far apart in memory whose
/// addresses are known a little before they are needed.
#[inline(always)]
pub fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch only hints the cache; it reads nothing and cannot fault, and `x` is a
    // valid reference in any case.
    unsafe {
        std::arch::x86_64::_mm_prefetch(x as *const T as *const i8, std::arch::x86_64::_MM_HINT_T0);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_f32_is_the_library_floor() {
        let cases = [
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            2.999_999_8,
            -2.999_999_8,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            1e20,
            -1e20,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
        ];
        for v in cases.into_iter().chain((0..10_000).map(|k| (k as f32 - 5000.0) * 0.013_7)) {
            assert_eq!(floor_f32(v), v.floor(), "{v}");
        }
        assert!(floor_f32(f32::NAN).is_nan() && floor_f32(f32::INFINITY) == f32::INFINITY);
    }
}
