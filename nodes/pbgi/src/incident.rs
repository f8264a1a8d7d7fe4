//! The direct light arriving at a surface point, as samples: what `ShadeDirect` sums into
//! irradiance and `SurfelWavelets` weighs by the BRDF in every outgoing direction, drawn
//! once here so that both see the same light.

use glam::{Vec2, Vec3};
use relume_base::math::rng::uniform;
use relume_base::render::lights::{delta_sample, LightSampler};
use relume_base::types::accel::Accel;
use relume_base::types::Scene;

/// One point's incident light: per sample the world direction toward the light and its weight.
#[derive(Clone, Debug, Default)]
pub struct Incident {
    /// Point, spot and directional lights: radiance × cos θi (one exact sample each).
    pub delta: Vec<(Vec3, Vec3)>,
    /// Area lights and the environment: radiance × cos θi / pdf, to be divided by `samples`.
    pub extended: Vec<(Vec3, Vec3)>,
    /// Samples drawn for the extended lights (0 when the scene has none); occluded ones and
    /// those below the horizon are drawn but not listed.
    pub samples: u32,
}

impl Incident {
    /// The irradiance E: the delta lights' sum plus the extended lights' mean.
    pub fn irradiance(&self) -> Vec3 {
        let mut e = Vec3::ZERO;
        for &(_, w) in &self.delta {
            e += w;
        }
        if self.samples > 0 {
            let mut acc = Vec3::ZERO;
            for &(_, w) in &self.extended {
                acc += w;
            }
            e += acc / self.samples as f32;
        }
        e
    }

    /// Every sample with its final weight (extended ones divided by the sample count).
    pub fn weighted(&self) -> Vec<(Vec3, Vec3)> {
        let per = 1.0 / self.samples.max(1) as f32;
        self.delta.iter().copied().chain(self.extended.iter().map(|&(wi, w)| (wi, w * per))).collect()
    }
}

/// Draws the incident samples of surface points (seeded per point index and sample).
pub struct DirectSampler<'a> {
    scene: &'a Scene,
    accel: &'a Accel,
    lights: LightSampler,
    eps: f32,
    samples: u32,
    seed: u64,
}

impl<'a> DirectSampler<'a> {
    /// `samples` light samples per point for the extended lights, from `seed`.
    pub fn new(scene: &'a Scene, accel: &'a Accel, samples: u32, seed: u64) -> Self {
        DirectSampler { scene, accel, lights: LightSampler::new(scene), eps: 1e-6 * scene.extent(), samples, seed }
    }

    /// Whether any light can reach a point at `x` with normal `n`: an extended light, or a
    /// delta light in front of it.
    pub fn reachable(&self, x: Vec3, n: Vec3) -> bool {
        self.lights.has_extended() || self.scene.lights.iter().any(|l| delta_sample(l, x).is_some_and(|(wi, _, _)| wi.dot(n) > 0.0))
    }

    /// Point `i`'s incident light at `x` with normal `n`, into `out` (cleared first): one
    /// shadow ray per delta light in front and per extended sample above the horizon.
    pub fn incident(&self, i: usize, x: Vec3, n: Vec3, out: &mut Incident) {
        out.delta.clear();
        out.extended.clear();
        let origin = x + n * self.eps * (1.0 + x.abs().max_element());
        let visible = |wi: Vec3, dist: f32| {
            let tmax = if dist.is_finite() { dist * (1.0 - 1e-4) } else { f32::INFINITY };
            !self.accel.occluded(origin, wi, 0.0, tmax)
        };
        for l in &self.scene.lights {
            if let Some((wi, dist, li)) = delta_sample(l, x) {
                let cos = wi.dot(n);
                if cos > 0.0 && visible(wi, dist) {
                    out.delta.push((wi, li * cos));
                }
            }
        }
        out.samples = 0;
        if self.lights.has_extended() {
            out.samples = self.samples;
            for s in 0..self.samples {
                let id = (i as u64) << 20 | s as u64;
                let u = |d| uniform(self.seed, id, d);
                if let Some(ls) = self.lights.sample_extended(self.scene, x, u(0), Vec2::new(u(1), u(2))) {
                    let cos = ls.wi.dot(n);
                    if cos > 0.0 && ls.pdf > 0.0 && visible(ls.wi, ls.dist) {
                        out.extended.push((ls.wi, ls.li * (cos / ls.pdf)));
                    }
                }
            }
        }
    }
}
