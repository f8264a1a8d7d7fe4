//! Precomputed transfer tensors (docs/PIPELINES.md pipeline 2; [S] chapter 5): fixed geometry lit by
//! an environment, with the view, the environment and the dynamic objects' BRDFs edited
//! together. Per vertex: direct light from the environment's Haar coefficients against the
//! vertex's visibility times the BRDF tensor's incoming factor (T0), one bounce in 4-band SH
//! (T1) and two bounces as a scalar (T2); shading with the Tucker-decomposed BRDF tensor plus
//! the separated specular lobes; then rasterised.
//!
//! The crate's nodes join a registry beside relume-base's, which they build on:
//!
//! ```
//! let mut reg = relume_base::registry();
//! relume_ptt::register(&mut reg);
//! for kind in ["TransferT0", "PttRelight"] {
//!     assert!(reg.node(kind).is_some(), "{kind}");
//! }
//! ```

pub mod bounce;
pub mod brdf_factors;
pub mod camera_hits;
pub mod channels;
pub mod compress_t2;
pub mod cta_compress;
pub mod env_lighting;
pub mod glossy_as_dynamic;
pub mod incident_projection;
pub mod ptt_bounce_light;
pub mod ptt_direct;
pub mod ptt_incident;
pub mod ptt_relight;
pub mod rasterize_vertex_colors;
pub mod screen_hits;
pub mod transfer_t0;
pub mod transfer_t1;
pub mod transfer_t2;
pub mod types;
pub mod vertex_path_trace;
pub mod vertex_visibility;
pub mod vertices;

// `pub fn register(reg)`: every node kind of the crate, found by build.rs.
include!(concat!(env!("OUT_DIR"), "/register.rs"));

#[cfg(test)]
pub(crate) mod test_support;
