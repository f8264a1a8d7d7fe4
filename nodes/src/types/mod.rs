//! Data types that flow along edges (port types).

mod image;
mod material;
mod metrics;

pub use self::image::{Image, MAX_IMAGE_BYTES};
pub use material::{Material, Medium};
pub use metrics::Metrics;
