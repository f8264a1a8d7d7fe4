//! Data types that flow along edges (port types).

mod image;
mod material;
mod metrics;
mod points;
mod receivers;
mod scene;

pub use self::image::{Image, MAX_IMAGE_BYTES};
pub use material::{Material, Medium};
pub use metrics::Metrics;
pub use points::SurfacePoints;
pub use receivers::{PointRadiance, Receivers};
pub use scene::{Camera, EnvMap, Environment, Light, Object, Scene};
