//! Pipeline 3, dynamic refractive and scattering objects ([S] chapter 6; PIPELINES.md
//! "Pipeline 3"): the shared volume code — the min/max pyramid the octree reads
//! (`pyramid`), the separable 3-D Gaussian blur (`blur`) — with the `Volume` port type in
//! `types::volume`. The stage nodes (`Voxelize`, `Octree`, `EmitPhotons`, `MarchPhotons`,
//! `EikonalRender`, …) come next, one file each.

pub mod blur;
pub mod pyramid;
