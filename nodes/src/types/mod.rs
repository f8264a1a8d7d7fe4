//! Data types that flow along edges (port types).

mod image;
mod metrics;

pub use self::image::{Image, MAX_IMAGE_BYTES};
pub use metrics::Metrics;
