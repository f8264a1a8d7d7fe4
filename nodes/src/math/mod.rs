//! Shared math used by several nodes (one place for each piece).

pub mod cpca;
pub mod cta;
pub mod cube_haar;
pub mod cubemap;
pub mod frame;
pub mod haar;
pub mod kmeans;
pub mod pca;
pub mod rng;
pub mod sampling;
pub mod sh;
pub mod sh_rotation;
pub mod srgb;
pub mod ssim;
pub mod streamed_pca;
pub mod tucker;
