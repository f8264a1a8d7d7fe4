//! The reference renderers, `PathTrace`, `BidirPathTrace` and `DirectLight`: nodes only, built on the shared
//! `render` library. No other module of the crate imports from here; tests and benchmarks call
//! the nodes' `render` functions.

pub mod bidir_path_trace;
pub mod direct_light;
pub mod path_trace;

/// A renderer's work for the engine's order of ready runs (`Node::work`): the samples it
/// traces, the camera's pixels (the scene's port size) times `spp`; a path's depth is not
/// counted.
fn samples_traced(scene: Option<relume_core::PortSize>, spp: u32) -> Option<f64> {
    scene.and_then(|s| s.pixels()).map(|p| p as f64 * spp as f64)
}
