//! The port types of pixel relighting: the stored transfer images and their sparse
//! spatially varying form.

mod sv_transfer;
mod transfer;

pub use sv_transfer::{SparsePlane, SvBlock, SvTransfer};
pub use transfer::{floats_and_stride, kd_map_digest, PathCounts, Transfer, TransferRows, MAX_TRANSFER_BYTES};
