//! Data types that flow along edges (port types).

pub mod accel;
mod brdf_space;
mod clusters;
mod image;
mod image_rows;
mod material;
mod metrics;
mod object_materials;
mod points;
mod scene;
mod splat_rows;
mod texture;
mod triangle_planes;

pub use self::image::{Image, MAX_IMAGE_BYTES};
pub use accel::Accel;
pub use brdf_space::{cos_half, BasisFamily, BrdfBasis, BrdfGrid, BrdfSample, BrdfSpace, Trilinear, MAX_BRDF_SPACE_BYTES};
pub use clusters::{Cluster, Clusters};
pub use image_rows::{gather_rows, row_spec, ImageRows, Layer};
pub use material::{Material, Medium};
pub use metrics::Metrics;
pub use object_materials::{ObjectMaterial, ObjectMaterials, Specular};
pub use points::SurfacePoints;
pub use scene::{Camera, EnvMap, Environment, Light, Object, Scene};
pub use splat_rows::{gather_splats, splat_spec, SplatRows};
pub use texture::{MaterialMaps, Texture};
pub use triangle_planes::{SceneDerived, TrianglePlanes};
