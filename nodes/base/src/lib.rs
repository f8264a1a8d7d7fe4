//! relume-base: what every pipeline stands on. The shared math and BRDFs, the port types more
//! than one pipeline carries (images, scenes, materials, point sets, BRDF spaces), the render
//! library (camera, lights, surface interaction, the integrator core), and the nodes every
//! pipeline uses: scene loading and edits, geometry, images and their error figures, the BRDF
//! space and basis, and the reference renderers.
//!
//! A graph of two of its nodes, run twice through one engine: the second run takes everything
//! from the memory cache.
//!
//! ```
//! use relume_base::types::Image;
//! use relume_core::{Engine, Graph, RunOptions};
//!
//! let g = Graph::parse(
//!     r#"(version: 1,
//!         nodes: { "pattern": (kind: "TestPattern", params: (width: 32, height: 16)),
//!                  "blur": (kind: "GaussianBlur", params: (sigma: 1.5)) },
//!         edges: [("pattern.image", "blur.image")],
//!         outputs: { "image": "blur.image" })"#,
//!     None,
//! )
//! .unwrap();
//! let engine = Engine::new(relume_base::registry());
//! let run = engine.run(&g, &RunOptions::default()).unwrap();
//! let image = run.output("image").unwrap().get::<Image>().unwrap();
//! assert_eq!((image.width, image.height), (32, 16));
//! assert_eq!(run.report.ran, 2);
//! assert_eq!(engine.run(&g, &RunOptions::default()).unwrap().report.ran, 0);
//! ```

pub mod brdf;
pub mod brdf_space;
pub mod geometry;
pub mod image;
pub mod math;
pub mod reference;
pub mod render;
pub mod scene;
// The helpers of the nodes' unit tests, here and in the pipeline crates. Always built (a
// few small functions), not behind a feature: a feature that only the tests turn on would
// give the tests and the binaries two builds of every crate above this one.
#[doc(hidden)]
pub mod testing;
pub mod types;

use relume_core::Registry;

// `pub fn register(reg)`: every node kind of the crate, found by build.rs.
include!(concat!(env!("OUT_DIR"), "/register.rs"));

/// A registry with the node kinds of this crate only (a pipeline's tests add their own).
pub fn registry() -> Registry {
    let mut r = Registry::new();
    register(&mut r);
    r
}
