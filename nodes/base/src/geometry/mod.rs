//! Geometry nodes: acceleration structures and surface sampling; measures of closed meshes.

pub mod build_bvh;
pub mod closed_mesh;
pub mod sample_surface;

use relume_core::Registry;

pub fn register(reg: &mut Registry) {
    reg.add::<build_bvh::BuildBvh>();
    reg.add::<sample_surface::SampleSurface>();
}
