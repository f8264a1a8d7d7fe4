//! Point-based global illumination (docs/PIPELINES.md pipeline 4; [P] chapters 2–3).
//!
//! The crate's nodes join a registry beside relume-base's, which they build on:
//!
//! ```
//! let mut reg = relume_base::registry();
//! relume_pbgi::register(&mut reg);
//! for kind in ["PbgiGather", "FactorizedGather", "WaveletGather", "ViewTree"] {
//!     assert!(reg.node(kind).is_some(), "{kind}");
//! }
//! ```

pub mod adaptive_microbuffer;
pub mod brdf_wavelets;
pub mod build_point_tree;
pub mod cluster_receivers;
pub mod factorized_gather;
pub mod gather;
pub mod gbuffer;
pub mod incident;
pub mod microbuffer;
pub mod pbgi_gather;
pub mod preview_splat;
pub mod shade_direct;
pub mod spherical_microbuffer;
pub mod surfel_wavelets;
#[cfg(test)]
pub(crate) mod test_support;
pub mod texel_cache;
pub mod traversal;
pub mod twin_dielectrics;
pub mod types;
pub mod view_pairs;
pub mod view_tree;
pub mod view_walk;
pub mod wavelet_gather;
pub mod wavelet_radiance;
pub mod wavelet_tree;

// `pub fn register(reg)`: every node kind of the crate, found by build.rs.
include!(concat!(env!("OUT_DIR"), "/register.rs"));

/// A registry with the base's node kinds and this crate's (what the pipeline's own graphs
/// need, for its tests).
#[cfg(test)]
pub(crate) fn registry() -> relume_core::Registry {
    let mut r = relume_base::registry();
    register(&mut r);
    r
}
