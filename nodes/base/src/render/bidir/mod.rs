//! The bidirectional path tracer (Veach 1997, ch. 10) behind `BidirPathTrace`: per camera
//! sample, a camera subpath and a light subpath, joined in every way their lengths allow, each
//! join weighted by multiple importance sampling (power heuristic) over all the strategies
//! that could have made the same path. It follows the unidirectional tracer's conventions
//! (one-sided opaque materials, Mitsuba 3's `max_depth`, Russian roulette from `rr_depth`),
//! so both estimate the same image, homogeneous media inside dielectrics included (scattering
//! points are vertices like any other, with the isotropic phase function for a BSDF).
//!
//! Light tracing (t = 1) lands on any pixel: those contributions come back as [`Splat`]s for
//! the caller to add to the image, divided by the samples per pixel.
//!
//! - `vertex`: what a vertex scatters or emits, and its densities.
//! - `walk`: the camera and light subpaths.
//! - `connect`: each strategy's unweighted contribution.
//! - `mis`: the strategies' weights.

mod connect;
mod mis;
mod vertex;
mod walk;

use crate::render::camera::CameraRays;
use crate::render::integrator::{Counts, Sampler};
use crate::render::lights::LightSampler;
use crate::types::accel::Accel;
use crate::types::Scene;
use glam::Vec3;

/// A light-tracing contribution to pixel `pixel` (row-major index) of one sample's light
/// subpath, its contributions to one pixel summed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat {
    pub pixel: u32,
    pub value: [f32; 3],
}

/// Settings of a bidirectional render.
#[derive(Clone, Copy, Debug)]
pub struct BidirSettings {
    /// Mitsuba's max_depth (path segments; −1 unbounded).
    pub max_depth: i32,
    /// The fewest path segments a counted path has (1: all light; 3: indirect light only).
    pub min_depth: u32,
    pub rr_depth: u32,
    pub seed: u64,
    /// Only this strategy (s light vertices, t camera vertices), unweighted: each strategy
    /// alone is an unbiased estimate of the paths it can make (for tests).
    pub only: Option<(usize, usize)>,
    /// Whether smooth dielectrics reflect (Fresnel); without, both subpaths refract at every
    /// dielectric except under total internal reflection (`PathTrace`'s switch, the same model).
    pub fresnel_reflection: bool,
}

/// Everything shared by the samples of one render.
pub struct Bidir<'a> {
    scene: &'a Scene,
    accel: &'a Accel,
    lights: LightSampler,
    cam: CameraRays,
    eps: f32,
    /// The scene's bounding sphere, and the area of the disk infinite lights' subpaths start
    /// from.
    centre: Vec3,
    radius: f32,
    disk: f32,
    max_camera: usize,
    max_light: usize,
    min_segments: usize,
    rr_depth: u32,
    seed: u64,
    only: Option<(usize, usize)>,
    fresnel_reflection: bool,
}

/// Stream of a sample's light subpath (its camera subpath uses the sample's own).
const LIGHT_STREAM: u64 = 0x4C49_4748_5450_4154;

impl<'a> Bidir<'a> {
    /// The tracer of `scene`.
    pub fn new(scene: &'a Scene, accel: &'a Accel, s: BidirSettings) -> Bidir<'a> {
        // Path segments at most; 0 shows emitters as 1 does, as the path tracer has it.
        let max_segments = if s.max_depth < 0 { usize::MAX - 1 } else { s.max_depth.max(1) as usize };
        let (lo, hi) = scene.bounds();
        let (centre, radius) = if lo.is_finite() && hi.is_finite() {
            ((lo + hi) * 0.5, ((hi - lo).length() * 0.5).max(1e-6) * 1.01)
        } else {
            (Vec3::ZERO, 1.0)
        };
        Bidir {
            scene,
            centre,
            radius,
            disk: std::f32::consts::PI * radius * radius,
            accel,
            lights: LightSampler::new(scene),
            cam: CameraRays::new(&scene.camera),
            eps: crate::render::surface::OFFSET_FRACTION * scene.extent(),
            max_camera: max_segments + 1,
            max_light: max_segments,
            min_segments: s.min_depth as usize,
            rr_depth: s.rr_depth,
            seed: s.seed,
            only: s.only,
            fresnel_reflection: s.fresnel_reflection,
        }
    }

    /// One sample of the camera ray (o, d) of sample `id`: the radiance it brings to its own
    /// pixel; the light subpath's contributions to pixels of a `width`-wide image are pushed
    /// to `splats`, each pixel once.
    pub fn sample(&self, o: Vec3, d: Vec3, id: u64, width: usize, counts: &mut Counts, splats: &mut Vec<Splat>) -> Vec3 {
        let mut rng = Sampler::new(self.seed, id, 0);
        let mut cam = Vec::with_capacity(8);
        self.camera_path(&mut cam, o, d, &mut rng, counts);
        let mut light_rng = Sampler::new(self.seed ^ LIGHT_STREAM, id, 0);
        let mut light = Vec::with_capacity(8);
        self.light_path(&mut light, &mut light_rng, counts);
        let first = splats.len();
        let mut l = Vec3::ZERO;
        for t in 1..=cam.len() {
            for s in 0..=light.len() {
                if s + t < 2 || s + t - 1 > self.max_light || s + t - 1 < self.min_segments || self.only.is_some_and(|o| o != (s, t)) {
                    continue;
                }
                let Some(c) = self.connect(&light, &cam, s, t, counts) else { continue };
                let w = if self.only.is_some() { 1.0 } else { self.mis_weight(&light, &cam, s, t) };
                let value = c.value * w;
                match c.pixel {
                    None => l += value,
                    Some((x, y)) => {
                        let pixel = (y as usize * width + x as usize) as u32;
                        match splats[first..].iter_mut().find(|sp| sp.pixel == pixel) {
                            Some(sp) => sp.value = (Vec3::from(sp.value) + value).to_array(),
                            None => splats.push(Splat { pixel, value: value.to_array() }),
                        }
                    }
                }
            }
        }
        l
    }
}
