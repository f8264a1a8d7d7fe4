//! Pipeline 3, dynamic refractive and scattering objects ([S] chapter 6; docs/PIPELINES.md
//! "Pipeline 3"): the shared volume code — the min/max pyramid the octree reads
//! (`pyramid`), the separable 3-D Gaussian blur (`blur`), inside fractions of closed meshes
//! by scanlines (`scanline`), the caustic map's blur that keeps to its side of a shadow's
//! edge (`caustic_blur`) — with the `Volume` port type in
//! `types::volume`. The optics photon marching and
//! rendering share are in `optics`. The stage nodes, one file each: `Voxelize`,
//! `VolumeSource`, `VolumePaint`, `Octree`, `EmitPhotons`, `MarchPhotons`, `EikonalPaths`,
//! `EikonalRender`,
//! and `VolumeSlice` to look inside a volume.
//!
//! The crate's nodes join a registry beside relume-base's, which they build on:
//!
//! ```
//! let mut reg = relume_base::registry();
//! relume_volume::register(&mut reg);
//! for kind in ["Voxelize", "MarchPhotons", "EikonalPaths", "EikonalRender"] {
//!     assert!(reg.node(kind).is_some(), "{kind}");
//! }
//! ```

pub mod blur;
pub mod caustic_blur;
pub mod eikonal_paths;
pub mod eikonal_render;
pub mod emit_photons;
pub mod march_photons;
pub mod octree;
pub mod octree_layout;
pub mod optics;
pub mod pyramid;
pub mod scanline;
#[cfg(test)]
pub(crate) mod test_support;
pub mod types;
pub mod volume_paint;
pub mod volume_slice;
pub mod volume_source;
pub mod voxelize;

// `pub fn register(reg)`: every node kind of the crate, found by build.rs.
include!(concat!(env!("OUT_DIR"), "/register.rs"));
