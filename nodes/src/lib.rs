//! relume-nodes: the stage nodes of relume's pipelines and the `relume` command line.

pub mod brdf;
pub mod brdf_space;
pub mod cli;
pub mod geometry;
pub mod image;
pub mod math;
pub mod pbgi;
pub mod ptt;
pub mod reference;
pub mod relight;
pub mod render;
pub mod scene;
#[cfg(test)]
pub(crate) mod testing;
pub mod types;
pub mod volume;

use relume_core::Registry;

/// Registers every node kind of this crate.
pub fn register_all(reg: &mut Registry) {
    image::register(reg);
    scene::register(reg);
    brdf_space::register(reg);
    geometry::register(reg);
    reference::register(reg);
    pbgi::register(reg);
    ptt::register(reg);
    relight::register(reg);
    volume::register(reg);
}

/// A registry with every node of this crate.
pub fn registry() -> Registry {
    let mut r = Registry::new();
    register_all(&mut r);
    r
}
