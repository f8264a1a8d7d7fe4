//! The channels of the octree volume the `Octree` node writes and the marchers read (the
//! eikonal paths and render, photon marching, the ray stepping of `optics`).

/// Channels of the octree volume: level, Δs_max, clear, clearance, n, ∇n (3).
pub const CHANNELS: u32 = 8;
/// The channel of the leaf level.
pub const LEVEL: usize = 0;
/// The channel of Δs_max (voxels).
pub const MAX_STEP: usize = 1;
/// The channel saying the voxel's leaf is clear (κ = 0 all through it).
pub const CLEAR: usize = 2;
/// The channel of the voxel's clearance: the L∞ distance in voxels to the nearest voxel where
/// a ray may bend (0: it may bend here), at most `CLEARANCE_CAP`.
pub const CLEARANCE: usize = 3;
/// The channel of the index n, followed by ∇n's three components.
pub const INDEX: usize = 4;
/// The channel of ∇n's x component.
pub const GRADIENT: usize = 5;

/// The largest clearance stored (voxels): a straight run jumps at most this far at once.
pub const CLEARANCE_CAP: u8 = 16;
