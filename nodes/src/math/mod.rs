//! Shared math used by several nodes (one place for each piece).

pub mod atan;
pub mod cpca;
pub mod cta;
pub mod cube_haar;
pub mod cubemap;
pub mod frame;
pub mod haar;
pub mod kmeans;
pub mod morton;
pub mod pca;
pub mod rng;
pub mod sampling;
pub mod sh;
pub mod sh_rotation;
pub mod srgb;
pub mod ssim;
pub mod streamed_pca;
pub mod tree_coding;
pub mod tucker;

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

/// Asks the kernel to back `v`'s allocation with 2 MiB pages where it can (no effect on what
/// any code computes; nothing off Linux, or below 4 MiB): for arrays of hundreds of MiB read
/// a few bytes at a time far apart (a vertex's visibility), where every read would
/// otherwise miss the address-translation cache. Only pages not yet touched change, so call
/// it before filling a new allocation.
pub fn huge_pages<T>(v: &Vec<T>) {
    let bytes = v.capacity() * std::mem::size_of::<T>();
    if bytes < 4 << 20 {
        return;
    }
    #[cfg(target_os = "linux")]
    {
        const PAGE: usize = 4096;
        let start = (v.as_ptr() as usize).next_multiple_of(PAGE);
        let end = (v.as_ptr() as usize + bytes) & !(PAGE - 1);
        // SAFETY: the range lies inside `v`'s allocation and is page-aligned; the advice
        // changes how the kernel backs the pages, never their contents (a refusal is ignored).
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
        }
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

    /// The advice changes how pages are backed, never what they hold: an array filled after
    /// it (and one it reaches after filling) reads back the same.
    #[test]
    fn large_pages_keep_an_arrays_contents() {
        let mut v: Vec<u32> = Vec::with_capacity(3 << 20);
        huge_pages(&v);
        v.extend((0..3u32 << 20).map(|k| k.wrapping_mul(2_654_435_761)));
        huge_pages(&v);
        assert!(v.iter().enumerate().all(|(k, &x)| x == (k as u32).wrapping_mul(2_654_435_761)));
        huge_pages(&Vec::<u8>::new());
    }
}
