//! The port types of refraction and scattering: the voxel volume, the view paths through it,
//! photons and their deposits, and the photons landed on surfaces.

mod derived;
mod photons;
pub mod surface_photons;
pub mod view_paths;
pub mod volume;

pub use derived::Derived;
pub use photons::{CausticMap, PhotonDeposits, Photons};
pub use surface_photons::{Landing, SurfacePhotons};
pub use view_paths::ViewPaths;
pub use volume::{Sampler, Volume, MAX_VOLUME_BYTES};
