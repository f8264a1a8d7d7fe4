//! Shared math used by several nodes (one place for each piece).

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
