//! Helpers for the nodes' own unit tests.

use relume_core::{
    cache::CacheEntry, run_standalone, run_standalone_with, CancelToken, Event, Node, NodeError, Observer, ParamValue, PortValue, Value,
};
use std::path::Path;

/// Runs a node with the given explicit parameters and inputs; returns its outputs.
pub fn run_node<N: Node>(params: &[(&str, ParamValue)], base_dir: &Path, inputs: Vec<Value>) -> Result<Vec<Value>, NodeError> {
    run_full::<N>(params, base_dir, inputs).map(|e| e.outputs)
}

/// As `run_node`, keeping metrics and notes.
pub fn run_full<N: Node>(params: &[(&str, ParamValue)], base_dir: &Path, inputs: Vec<Value>) -> Result<CacheEntry, NodeError> {
    run_standalone::<N>(params, base_dir, &inputs)
}

/// Runs a node without file parameters on one or more values.
pub fn run_on<N: Node>(params: &[(&str, ParamValue)], inputs: Vec<Value>) -> Result<Vec<Value>, NodeError> {
    run_node::<N>(params, Path::new("."), inputs)
}

/// Runs a node and cancels the run at its first progress report: asserts that it stops with
/// `Cancelled` (not a result, not another error) and returns how many progress reports it
/// made after the cancellation (a node that honours cancellation makes few).
pub fn cancels_midway<N: Node>(params: &[(&str, ParamValue)], inputs: Vec<Value>) -> usize {
    struct CancelOnProgress(CancelToken, std::sync::atomic::AtomicUsize);
    impl Observer for CancelOnProgress {
        fn event(&self, e: &Event<'_>) {
            if let Event::Progress { .. } = e {
                if self.0.is_cancelled() {
                    self.1.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                self.0.cancel();
            }
        }
    }
    let obs = CancelOnProgress(CancelToken::new(), Default::default());
    let r = run_standalone_with::<N>(&obs.0, Some(&obs), params, Path::new("."), &inputs);
    assert!(obs.0.is_cancelled(), "{} reported no progress before finishing", N::KIND);
    assert!(matches!(r, Err(NodeError::Cancelled)), "{} did not stop when cancelled: {:?}", N::KIND, r.map(|e| e.outputs.len()));
    obs.1.load(std::sync::atomic::Ordering::Relaxed)
}

/// The first output as type T.
pub fn first<T: PortValue + Clone>(out: &[Value]) -> T {
    out[0].get::<T>().expect("output type").clone()
}

pub fn f(x: f64) -> ParamValue {
    ParamValue::Float(x)
}

pub fn i(x: i64) -> ParamValue {
    ParamValue::Int(x)
}

pub fn id(s: &str) -> ParamValue {
    ParamValue::Ident(s.into())
}

pub fn t(s: &str) -> ParamValue {
    ParamValue::Text(s.into())
}

/// An RGB parameter value.
pub fn rgb(c: [f64; 3]) -> ParamValue {
    ParamValue::Tuple(c.iter().map(|&x| ParamValue::Float(x)).collect())
}

/// Small scenes built in code for unit tests.
pub mod test_scene {
    use crate::scene::builder::SceneBuilder;
    use crate::types::{Light, Material, Scene};
    use glam::Vec3;

    /// A 2 × 2 floor of material `floor` at y = 0 under a 0.4 × 0.4 lamp of radiance 10 at
    /// y = 1, seen from above at 8 × 8: add lights and build.
    pub fn floor_and_lamp(floor: Material) -> SceneBuilder {
        SceneBuilder::new(Vec3::new(0.0, 3.0, 0.1), Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), floor, Vec3::ZERO)
            .quad(
                "lamp",
                Vec3::new(-0.2, 1.0, -0.2),
                Vec3::new(0.4, 0.0, 0.0),
                Vec3::new(0.0, 0.0, 0.4),
                Material::Lambert { albedo: Vec3::ZERO },
                Vec3::splat(10.0),
            )
    }

    /// Three spheres over a floor quad under a point light.
    pub fn spheres() -> Scene {
        let grey = Material::Lambert { albedo: Vec3::splat(0.5) };
        SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, 16, 16)
            .sphere("a", Vec3::new(-0.8, 0.0, 0.0), 0.5, grey, Vec3::ZERO, false)
            .sphere("b", Vec3::new(0.7, 0.3, -0.5), 0.6, grey, Vec3::ZERO, false)
            .sphere("c", Vec3::new(0.0, -0.6, 0.8), 0.3, grey, Vec3::ZERO, false)
            .quad("floor", Vec3::new(-2.0, -1.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), grey, Vec3::ZERO)
            .light(Light::Point { position: Vec3::new(0.0, 2.0, 1.0), intensity: Vec3::splat(5.0) })
            .build()
    }
}

/// Test images shared by the image-quality tests.
pub mod images {
    use crate::math::rng::uniform;
    use crate::types::Image;

    /// A smooth, unclipped scene (values in [0.15, 0.75]) with an edge through it.
    pub fn scene() -> Image {
        Image::from_fn(64, 48, |x, y| {
            let (t, s) = (x as f32 / 63.0, y as f32 / 47.0);
            let edge = if x + y > 56 { 0.15 } else { 0.0 };
            [0.15 + 0.4 * t + edge, 0.2 + 0.3 * s + edge, 0.35 + 0.2 * t * s]
        })
    }

    /// `img` plus zero-mean uniform noise of standard deviation `sd` in every channel.
    pub fn with_noise(img: &Image, sd: f32, seed: u64) -> Image {
        let mut out = img.clone();
        for (i, p) in out.pixels.iter_mut().enumerate() {
            for (c, v) in p.iter_mut().enumerate() {
                *v += sd * 12f32.sqrt() * (uniform(seed, i as u64, c as u32) - 0.5);
            }
        }
        out
    }
}
