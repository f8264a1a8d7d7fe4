//! The port types of refraction and scattering: the voxel volume, the view paths through it,
//! photons and their deposits.

mod derived;
mod photons;
pub mod view_paths;
pub mod volume;

pub use derived::Derived;
pub use photons::{CausticMap, PhotonDeposits, Photons};
pub use view_paths::ViewPaths;
pub use volume::{Sampler, Volume, MAX_VOLUME_BYTES};
