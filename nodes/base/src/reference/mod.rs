//! The reference renderers, `PathTrace`, `BidirPathTrace` and `DirectLight`: nodes only, built on the shared
//! `render` library. No other module of the crate imports from here; tests and benchmarks call
//! the nodes' `render` functions.

pub mod bidir_path_trace;
pub mod direct_light;
pub mod path_trace;
