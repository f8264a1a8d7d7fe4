//! The unidirectional path tracer (`Tracer::radiance`) behind `PathTrace`, and behind the rays
//! `DirectLight` leaves to it: next-event estimation with multiple importance sampling (power
//! heuristic) against BSDF sampling, smooth dielectrics with homogeneous interior media,
//! Russian roulette, and Mitsuba 3's `max_depth` meaning (1: emitters seen directly; 2: direct
//! lighting; −1: unbounded). Also its `Settings` and the per-sample work `Counts`.

use crate::brdf;
use crate::math::frame::Frame;
use crate::math::rng::{stream, uniform_in};
use crate::math::sampling::{power_heuristic, uniform_sphere, UNIFORM_SPHERE_PDF};
use crate::render::lights::LightSampler;
use crate::render::surface::Surface;
use crate::types::accel::Accel;
use crate::types::{Material, Medium, Scene};
use glam::{Vec2, Vec3};

/// Integrator settings.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Mitsuba's max_depth: maximum number of path segments; −1 for no limit.
    pub max_depth: i32,
    /// Fewest path segments whose light is counted (1: all of it; 3 with `max_depth` 3: the
    /// one-bounce indirect light alone). The paths and their random numbers are the same at
    /// every value: only what shorter paths add is left out.
    pub min_depth: u32,
    /// Depth from which Russian roulette may end paths (Mitsuba's rr_depth, default 5).
    pub rr_depth: u32,
    pub seed: u64,
    /// Whether smooth dielectrics reflect (Fresnel); without, every path refracts except
    /// under total internal reflection, with the same random numbers.
    pub fresnel_reflection: bool,
}

/// Per-sample random numbers: (seed, sample id, running dimension) → uniform [0, 1), the
/// numbers `uniform(seed, id, dim)` gives; `draw` advances the dimension first. The seed and id
/// are hashed once, when the sampler is made.
pub struct Sampler {
    stream: u64,
    dim: u32,
}

impl Sampler {
    /// The sampler of sample `id` under `seed`, whose next draw is dimension `dim + 1`.
    pub fn new(seed: u64, id: u64, dim: u32) -> Sampler {
        Sampler { stream: stream(seed, id), dim }
    }
    pub fn draw(&mut self) -> f32 {
        self.dim += 1;
        uniform_in(self.stream, self.dim)
    }
    pub fn draw2(&mut self) -> Vec2 {
        Vec2::new(self.draw(), self.draw())
    }
}

/// Counts of one sample's work (rays traced).
#[derive(Clone, Copy, Debug, Default)]
pub struct Counts {
    pub rays: u64,
}

/// Everything shared by all samples of one render.
pub struct Tracer<'a> {
    pub scene: &'a Scene,
    pub accel: &'a Accel,
    pub lights: LightSampler,
    pub settings: Settings,
    eps: f32,
}

impl<'a> Tracer<'a> {
    pub fn new(scene: &'a Scene, accel: &'a Accel, settings: Settings) -> Self {
        let eps = crate::render::surface::OFFSET_FRACTION * scene.extent();
        Tracer { scene, accel, lights: LightSampler::new(scene), settings, eps }
    }

    /// How far off a surface secondary rays start: 10⁻⁶ of the scene's extent, computed once
    /// here (the extent walks every vertex).
    pub fn eps(&self) -> f32 {
        self.eps
    }

    fn environment(&self, d: Vec3) -> Vec3 {
        self.scene.environment_radiance(d)
    }

    /// Radiance along the camera ray (o, d) for sample `id`.
    pub fn radiance(&self, o: Vec3, d: Vec3, id: u64, counts: &mut Counts) -> Vec3 {
        let s = self.settings;
        let max_depth = if s.max_depth < 0 { u32::MAX } else { s.max_depth as u32 };
        let mut rng = Sampler::new(s.seed, id, 0);
        let (mut o, mut d) = (o, d);
        let mut throughput = Vec3::ONE;
        let mut result = Vec3::ZERO;
        // Density of the BSDF sample that produced the current ray; `delta` when it came from
        // a delta lobe or the camera (then emitters hit are counted with weight 1).
        let mut prev_pdf = 0.0f32;
        let mut prev_delta = true;
        let mut medium: Option<Medium> = None;
        let mut depth = 0u32;
        loop {
            counts.rays += 1;
            let hit = self.accel.intersect(o, d, 0.0, f32::INFINITY);
            // Travel through a medium: a scattering event may come before the surface.
            if let Some(m) = medium {
                let dist = hit.map_or(f32::INFINITY, |h| h.t);
                match sample_medium(&m, dist, &mut rng) {
                    MediumEvent::Scatter(t, weight) => {
                        throughput *= weight;
                        if depth + 1 >= max_depth {
                            break;
                        }
                        o += d * t;
                        d = uniform_sphere(rng.draw2());
                        // Isotropic phase: f = 1/4π, pdf = 1/4π, weight 1.
                        prev_pdf = UNIFORM_SPHERE_PDF;
                        prev_delta = false;
                        depth += 1;
                        if !self.roulette(&mut throughput, depth, &mut rng) {
                            break;
                        }
                        continue;
                    }
                    MediumEvent::Pass(weight) => throughput *= weight,
                }
            }
            let Some(hit) = hit else {
                let le = self.environment(d);
                if le != Vec3::ZERO && depth + 1 >= s.min_depth {
                    let w = if prev_delta { 1.0 } else { power_heuristic(prev_pdf, self.lights.pdf_environment(self.scene, d)) };
                    result += throughput * le * w;
                }
                break;
            };
            let surf = Surface::at(self.scene, &hit, o, d);
            let obj = &self.scene.objects[surf.object as usize];
            let front = d.dot(surf.ng) < 0.0;
            if front && obj.emission != Vec3::ZERO && depth + 1 >= s.min_depth {
                let w = if prev_delta {
                    1.0
                } else {
                    let cos_l = -d.dot(surf.ng);
                    power_heuristic(prev_pdf, self.lights.pdf_triangle(surf.tri, hit.t, cos_l))
                };
                result += throughput * obj.emission * w;
            }
            if depth + 1 >= max_depth {
                break;
            }
            let material = surf.material(self.scene);
            // Shading frame on the side the ray arrives from for dielectrics; opaque models
            // are one-sided (black from the back).
            let (ns, two_sided) = match material {
                Material::Dielectric { .. } => (surf.ns, true),
                _ => (surf.ns, false),
            };
            if !two_sided && !front {
                break;
            }
            let frame = Frame::from_normal(ns);
            let wo = frame.to_local(-d);

            // Next-event estimation (a path of depth + 2 segments).
            if !brdf::is_delta(&material) {
                if let Some(ls) = self.lights.sample(self.scene, surf.p, rng.draw(), rng.draw2()) {
                    let wi = frame.to_local(ls.wi);
                    let f = brdf::eval(&material, wo, wi) * wi.z.abs();
                    // The light sample's numbers are drawn either way, so that `min_depth` leaves
                    // the paths as they are; the shadow ray is traced only when counted.
                    if depth + 2 >= s.min_depth && f != Vec3::ZERO && ls.li != Vec3::ZERO && ls.wi.dot(surf.ng) > 0.0 {
                        counts.rays += 1;
                        let origin = surf.spawn(ls.wi, self.eps);
                        let tmax = if ls.dist.is_finite() { ls.dist * (1.0 - 1e-4) - self.eps } else { f32::INFINITY };
                        if !self.accel.occluded(origin, ls.wi, 0.0, tmax) {
                            let w = if ls.delta { 1.0 } else { power_heuristic(ls.pdf, brdf::pdf(&material, wo, wi)) };
                            result += throughput * f * ls.li * (w / ls.pdf);
                        }
                    }
                }
            }

            // BSDF sampling.
            let (u2, uc) = (rng.draw2(), rng.draw());
            // Without Fresnel reflection a dielectric always draws refraction (uc ≥ F), which
            // total internal reflection (F = 1) still overrules.
            let uc = if s.fresnel_reflection || !matches!(material, Material::Dielectric { .. }) { uc } else { 1.0 };
            let Some(bs) = brdf::sample(&material, wo, u2, uc) else { break };
            if bs.pdf <= 0.0 || !bs.pdf.is_finite() {
                break;
            }
            let wi = frame.to_world(bs.wi);
            // Reject samples that leave through the wrong side of the geometric surface
            // (shading-normal artefacts) for opaque materials.
            if !two_sided && wi.dot(surf.ng) <= 0.0 {
                break;
            }
            throughput *= bs.f * (bs.wi.z.abs() / bs.pdf);
            if !throughput.is_finite() || throughput == Vec3::ZERO {
                break;
            }
            medium = medium_after(&material, surf.ng, -d, wi, medium);
            prev_pdf = bs.pdf;
            prev_delta = bs.delta;
            o = surf.spawn(wi, self.eps);
            d = wi;
            depth += 1;
            if !self.roulette(&mut throughput, depth, &mut rng) {
                break;
            }
        }
        result
    }

    /// Russian roulette from `rr_depth` on: continue with probability min(max throughput,
    /// 0.95) and divide by it.
    fn roulette(&self, throughput: &mut Vec3, depth: u32, rng: &mut Sampler) -> bool {
        if depth < self.settings.rr_depth {
            return true;
        }
        let q = throughput.max_element().min(0.95);
        if q <= 0.0 || rng.draw() >= q {
            return false;
        }
        *throughput /= q;
        true
    }
}

/// The medium a path travels in after it scatters at a surface of `material` (geometric
/// normal `ng`) from `wo` (toward where it came from) into `wi`: a dielectric's own medium
/// where it enters the object (against its outward normal), none where it leaves it, and
/// `current` where it stays on its side.
pub(crate) fn medium_after(material: &Material, ng: Vec3, wo: Vec3, wi: Vec3, current: Option<Medium>) -> Option<Medium> {
    match material {
        Material::Dielectric { medium, .. } if (wi.dot(ng) < 0.0) != (wo.dot(ng) < 0.0) => {
            if wi.dot(ng) < 0.0 {
                *medium
            } else {
                None
            }
        }
        _ => current,
    }
}

pub(crate) enum MediumEvent {
    /// Scatter at distance t with this throughput weight.
    Scatter(f32, Vec3),
    /// Reach the surface with this throughput weight.
    Pass(Vec3),
}

/// Free-flight sampling in a homogeneous medium. A medium that only absorbs is handled
/// analytically (weight e^{−σa d}). Otherwise a colour channel is picked uniformly and the
/// distance sampled from its extinction; weights use the average density over channels
/// (one-sample MIS), which stays finite for σt = 0 and for σt = 10⁴ (underflow gives 0).
pub(crate) fn sample_medium(m: &Medium, dist: f32, rng: &mut Sampler) -> MediumEvent {
    let sigma_t = m.sigma_a + m.sigma_s;
    if m.sigma_s == Vec3::ZERO {
        let tr = if dist.is_finite() { (-sigma_t * dist).exp() } else { Vec3::select(sigma_t.cmpgt(Vec3::ZERO), Vec3::ZERO, Vec3::ONE) };
        return MediumEvent::Pass(tr);
    }
    let c = ((rng.draw() * 3.0) as usize).min(2);
    let st = sigma_t[c];
    let t = if st > 0.0 { -(1.0 - rng.draw()).ln() / st } else { f32::INFINITY };
    if t < dist {
        let tr = (-sigma_t * t).exp();
        let pdf = (sigma_t * tr).element_sum() / 3.0;
        if pdf <= 0.0 {
            return MediumEvent::Pass(Vec3::ZERO);
        }
        MediumEvent::Scatter(t, tr * m.sigma_s / pdf)
    } else {
        let tr = if dist.is_finite() { (-sigma_t * dist).exp() } else { Vec3::ZERO };
        let p_pass = tr.element_sum() / 3.0;
        if p_pass <= 0.0 {
            return MediumEvent::Pass(Vec3::ZERO);
        }
        MediumEvent::Pass(tr / p_pass)
    }
}
