//! Pipeline 3, dynamic refractive and scattering objects ([S] chapter 6; PIPELINES.md
//! "Pipeline 3"): the shared volume code — the min/max pyramid the octree reads
//! (`pyramid`), the separable 3-D Gaussian blur (`blur`), inside fractions of closed meshes
//! by scanlines (`scanline`) — with the `Volume` port type in
//! `types::volume`. The stage nodes: `Voxelize`, `VolumeSource`, `VolumePaint`, `Octree`, and `VolumeSlice` to look inside a volume; to come `EmitPhotons`, `MarchPhotons`,
//! `EikonalRender`, …, one file each.

pub mod blur;
pub mod octree;
pub mod pyramid;
pub mod scanline;
pub mod volume_paint;
pub mod volume_slice;
pub mod volume_source;
pub mod voxelize;

use relume_core::Registry;

/// Registers the volume nodes.
pub fn register(reg: &mut Registry) {
    reg.add::<voxelize::Voxelize>();
    reg.add::<volume_slice::VolumeSlice>();
    reg.add::<octree::Octree>();
    reg.add::<volume_source::VolumeSource>();
    reg.add::<volume_paint::VolumePaint>();
}
