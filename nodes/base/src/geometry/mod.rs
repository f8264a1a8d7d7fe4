//! Geometry nodes: acceleration structures and surface sampling; measures of closed meshes.

pub mod build_bvh;
pub mod closed_mesh;
pub mod sample_surface;
