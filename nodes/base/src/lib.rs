//! relume-base: what every pipeline stands on. The shared math and BRDFs, the port types more
//! than one pipeline carries (images, scenes, materials, point sets, BRDF spaces), the render
//! library (camera, lights, surface interaction, the integrator core), and the nodes every
//! pipeline uses: scene loading and edits, geometry, images and their error figures, the BRDF
//! space and basis, and the reference renderers.

pub mod brdf;
pub mod brdf_space;
pub mod geometry;
pub mod image;
pub mod math;
pub mod reference;
pub mod render;
pub mod scene;
#[cfg(any(test, feature = "testing"))]
pub mod testing;
pub mod types;

use relume_core::Registry;

/// Registers the node kinds of this crate.
pub fn register(reg: &mut Registry) {
    image::register(reg);
    scene::register(reg);
    brdf_space::register(reg);
    geometry::register(reg);
    reference::register(reg);
}

/// A registry with the node kinds of this crate only (a pipeline's tests add their own).
pub fn registry() -> Registry {
    let mut r = Registry::new();
    register(&mut r);
    r
}
