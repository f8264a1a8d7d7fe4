//! The port types of point-based GI: the point tree, receivers and their gathered radiance,
//! and the points' wavelet-coded radiance.

mod point_tree;
mod receivers;
mod wavelets;

pub use point_tree::{faces_inside, PointTree, TreeNode, MIN_AREA_FRACTION};
pub use receivers::{Fill, PointRadiance, Receivers};
pub use wavelets::{CodedWavelets, PointWavelets, MAX_WAVELET_SIDE};
