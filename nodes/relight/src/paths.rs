//! The paths of pixel relighting ([S] 4.1.1, 4.1.3), shared by the precompute (which weighs
//! each path with every basis BRDF) and the same-seed reference (which weighs the same paths
//! with one material): ONE set of paths per pixel fills every accumulator, so that
//! recombining the stored images does not amplify independent noise.
//!
//! Per pixel: `spp` camera rays jittered over the pixel find the first hits x′. The pixel's
//! class (fixed/none, or dynamic object g) is the class most of them hit (ties to the lower
//! class); their reflected light is dropped (counted), because a pixel has one object's
//! coefficients in `Relight`, and the kept samples' mean stands for the pixel. Emission seen
//! directly (fixed emitters, the environment on a miss) needs no coefficient: every sample's
//! goes, averaged over all of them, to the `emitted` accumulator, so a light's edge is
//! antialiased. Per kept sample: direct light at
//! x′ from `light_samples` light samples → Direct(f) for each slot f at x′; `bounce_rays`
//! uniform hemisphere rays x′ → x″ (no importance sampling: the basis BRDFs are signed), and at
//! each x″ `bounce_light_samples` light samples → Bounce(f, x) for each slot f at x′ and x at
//! x″. Hemisphere rays that hit an emitter add nothing (its light at x′ is counted by the light
//! samples), so nothing is counted twice. Nothing is clamped or rouletted.
//!
//! Random numbers depend only on (seed, pixel, sample, dimension) and are drawn in an order
//! that depends only on geometry, never on BRDF values: two `Shade`s see the same paths.

use crate::types::PathCounts;
use glam::Vec3;
use relume_base::math::frame::Frame;
use relume_base::math::rng::uniform;
use relume_base::render::camera::CameraRays;
use relume_base::render::integrator::Sampler;
use relume_base::render::lights::LightSampler;
use relume_base::render::surface::Surface;
use relume_base::types::accel::{Accel, Hit};
use relume_base::types::Scene;
use std::f32::consts::PI;

/// Most BRDF slots at one point (bases, or one material).
pub const MAX_SLOTS: usize = 64;

/// What a surface point contributes with on a path, for one pair of local directions (+z the
/// shading normal; `wi` toward the light, `wo` toward the viewer).
pub trait Shade: Sync {
    /// The slot values at a first hit x′ (`at`); returns how many were written.
    fn first(&self, at: &Surface, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> usize;
    /// The slot values at a second hit x″ on `obj`; returns (the index of the first among all
    /// second slots, how many were written).
    fn second(&self, at: &Surface, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> (usize, usize);
}

/// Where slot values accumulate: `direct[f]` for Direct(f), `bounce[f * n_second + x]` for
/// Bounce(f, x), `emitted` for the light seen directly (`None`: the scene has none).
#[derive(Clone, Debug)]
pub struct Slots {
    pub direct: Vec<u32>,
    pub bounce: Vec<u32>,
    pub n_second: usize,
    pub emitted: Option<u32>,
    pub accumulators: usize,
}

impl Slots {
    /// One accumulator for everything (a renderer of one material).
    pub fn single() -> Slots {
        Slots { direct: vec![0], bounce: vec![0], n_second: 1, emitted: Some(0), accumulators: 1 }
    }
}

/// What one pixel's paths did.
#[derive(Clone, Copy, Debug, Default)]
pub struct PixelStats {
    pub class: u32,
    /// Camera samples dropped because they hit another class than the pixel's.
    pub dropped: u32,
    pub rays: u64,
    /// The UV of x′ for the kept camera sample nearest the pixel's centre (the texel a
    /// spatially varying material is read at; zero when no kept sample hit a front face).
    pub uv: [f32; 2],
    /// The scene object (index + 1; 0: none) under that sample: the object-id image.
    pub object: u32,
}

/// Everything the paths of one render share.
pub struct Paths<'a, S: Shade> {
    scene: &'a Scene,
    accel: &'a Accel,
    lights: LightSampler,
    cam: CameraRays,
    counts: PathCounts,
    shade: &'a S,
    slots: &'a Slots,
    /// Class of each scene object (0: fixed, g + 1: dynamic object g).
    class: Vec<u32>,
    classes: usize,
    eps: f32,
}

/// The class of every scene object: 0 for fixed objects, g + 1 for the members of dynamic
/// object g (`Scene::dynamic_groups`).
pub fn object_classes(scene: &Scene) -> Vec<u32> {
    let mut class = vec![0u32; scene.objects.len()];
    for (g, (_, members)) in scene.dynamic_groups().iter().enumerate() {
        for &m in members {
            class[m as usize] = g as u32 + 1;
        }
    }
    class
}

impl<'a, S: Shade> Paths<'a, S> {
    pub fn new(scene: &'a Scene, accel: &'a Accel, counts: PathCounts, shade: &'a S, slots: &'a Slots) -> Self {
        let class = object_classes(scene);
        let classes = class.iter().copied().max().unwrap_or(0) as usize + 1;
        Paths {
            scene,
            accel,
            lights: LightSampler::new(scene),
            cam: CameraRays::new(&scene.camera),
            counts,
            shade,
            slots,
            class,
            classes,
            eps: relume_base::render::surface::OFFSET_FRACTION * scene.extent(),
        }
    }

    fn environment(&self, d: Vec3) -> Vec3 {
        self.scene.environment_radiance(d)
    }

    /// Direct light at surface `s` (shading frame `frame`) from `n` light samples: calls
    /// `add(wi local, Li cos θi / (pdf n))` for each unoccluded sample.
    fn direct(&self, s: &Surface, frame: &Frame, n: u32, rng: &mut Sampler, rays: &mut u64, mut add: impl FnMut(Vec3, Vec3)) {
        for _ in 0..n {
            let (u, u2) = (rng.draw(), rng.draw2());
            let Some(ls) = self.lights.sample(self.scene, s.p, u, u2) else { continue };
            if ls.li == Vec3::ZERO || ls.wi.dot(s.ng) <= 0.0 || ls.pdf.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            let wi = frame.to_local(ls.wi);
            if wi.z <= 0.0 {
                continue;
            }
            *rays += 1;
            let tmax = if ls.dist.is_finite() { ls.dist * (1.0 - 1e-4) - self.eps } else { f32::INFINITY };
            if self.accel.occluded(s.spawn(ls.wi, self.eps), ls.wi, 0.0, tmax) {
                continue;
            }
            add(wi, ls.li * (wi.z / (ls.pdf * n as f32)));
        }
    }

    /// Traces pixel (x, y) of the camera: adds its paths into `acc` (`slots.accumulators` RGB
    /// sums, zeroed by the caller) as the mean over its kept camera samples (the light seen
    /// directly over all of them), calling `on_sample(acc)` after each camera sample (for
    /// per-sample statistics; nothing is called when no sample is kept).
    pub fn pixel(&self, x: usize, y: usize, acc: &mut [[f64; 3]], on_sample: &mut dyn FnMut(&[[f64; 3]])) -> PixelStats {
        let c = self.counts;
        let w = self.scene.camera.width;
        let pixel = (y * w + x) as u64;
        let mut stats = PixelStats::default();
        // First hits of every camera sample, and the pixel's class by majority.
        let mut firsts: Vec<(Vec3, Vec3, Option<Hit>, f32)> = Vec::with_capacity(c.spp as usize);
        let mut votes = vec![0u32; self.classes];
        for s in 0..c.spp {
            let id = pixel << 32 | s as u64;
            let (jx, jy) = (uniform(c.seed ^ 0x5EED, id, 0), uniform(c.seed ^ 0x5EED, id, 1));
            let (o, d) = self.cam.ray(x as f32 + jx, y as f32 + jy);
            let hit = self.accel.intersect(o, d, 0.0, f32::INFINITY);
            stats.rays += 1;
            votes[hit.map_or(0, |h| self.class[self.scene.tri_object[h.tri as usize] as usize]) as usize] += 1;
            firsts.push((o, d, hit, (jx - 0.5).powi(2) + (jy - 0.5).powi(2)));
        }
        let class = (0..self.classes).max_by_key(|&k| (votes[k], std::cmp::Reverse(k))).unwrap_or(0) as u32;
        stats.class = class;
        let kept = votes[class as usize];
        stats.dropped = c.spp - kept;
        if kept == 0 {
            return stats;
        }
        let weight = 1.0 / kept as f64;
        let add_weighted = |acc: &mut [[f64; 3]], i: u32, v: Vec3, weight: f64| {
            let a = &mut acc[i as usize];
            for k in 0..3 {
                a[k] += v[k] as f64 * weight;
            }
        };
        let add = |acc: &mut [[f64; 3]], i: u32, v: Vec3| add_weighted(acc, i, v, weight);
        let mut fv = [Vec3::ZERO; MAX_SLOTS];
        let mut xv = [Vec3::ZERO; MAX_SLOTS];
        let mut nearest = f32::INFINITY;
        for (s, (o, d, hit, centre_dist)) in firsts.into_iter().enumerate() {
            'sample: {
                // The light seen directly, from every sample.
                let seen = match hit {
                    None => self.environment(d),
                    Some(h) => {
                        let e = self.scene.objects[self.scene.tri_object[h.tri as usize] as usize].emission;
                        if e != Vec3::ZERO && d.dot(Surface::at(self.scene, &h, o, d).ng) < 0.0 {
                            e
                        } else {
                            Vec3::ZERO
                        }
                    }
                };
                if let (Some(slot), true) = (self.slots.emitted, seen != Vec3::ZERO) {
                    add_weighted(acc, slot, seen, 1.0 / c.spp as f64);
                }
                let object_class = hit.map_or(0, |h| self.class[self.scene.tri_object[h.tri as usize] as usize]);
                if object_class != class {
                    break 'sample;
                }
                let mut rng = Sampler::new(c.seed, pixel << 32 | s as u64, 1);
                let Some(hit) = hit else { break 'sample };
                let surf = Surface::at(self.scene, &hit, o, d);
                if d.dot(surf.ng) >= 0.0 {
                    break 'sample; // one-sided: black from the back
                }
                if centre_dist < nearest {
                    (nearest, stats.uv, stats.object) = (centre_dist, surf.uv.to_array(), surf.object + 1);
                }
                let frame = Frame::from_normal(surf.ns);
                let wo = frame.to_local(-d);
                // Direct light at x′.
                self.direct(&surf, &frame, c.light_samples, &mut rng, &mut stats.rays, |wi, g| {
                    let n = self.shade.first(&surf, wi, wo, &mut fv);
                    for (f, v) in fv[..n].iter().enumerate() {
                        add(acc, self.slots.direct[f], *v * g);
                    }
                });
                // One bounce: uniform hemisphere rays to x″, direct light there.
                for _ in 0..c.bounce_rays {
                    let u = rng.draw2();
                    let z = u.x;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    let (sin, cos) = (2.0 * PI * u.y).sin_cos();
                    let local = Vec3::new(r * cos, r * sin, z);
                    let dir = frame.to_world(local);
                    if dir.dot(surf.ng) <= 0.0 || local.z <= 0.0 {
                        continue;
                    }
                    stats.rays += 1;
                    let Some(h2) = self.accel.intersect(surf.spawn(dir, self.eps), dir, 0.0, f32::INFINITY) else { continue };
                    let s2 = Surface::at(self.scene, &h2, surf.spawn(dir, self.eps), dir);
                    if dir.dot(s2.ng) >= 0.0 {
                        continue;
                    }
                    // x′'s slots for this direction: f cos θ′ / pdf, pdf = 1 / 2π, over the rays.
                    let n1 = self.shade.first(&surf, local, wo, &mut fv);
                    let scale = local.z * 2.0 * PI / c.bounce_rays as f32;
                    fv[..n1].iter_mut().for_each(|v| *v *= scale);
                    let frame2 = Frame::from_normal(s2.ns);
                    let wo2 = frame2.to_local(-dir);
                    self.direct(&s2, &frame2, c.bounce_light_samples, &mut rng, &mut stats.rays, |wi2, g2| {
                        let (base, n2) = self.shade.second(&s2, wi2, wo2, &mut xv);
                        for (f, fv) in fv[..n1].iter().enumerate() {
                            let row = f * self.slots.n_second + base;
                            for (x, xv) in xv[..n2].iter().enumerate() {
                                add(acc, self.slots.bounce[row + x], *fv * *xv * g2);
                            }
                        }
                    });
                }
            }
            on_sample(acc);
        }
        stats
    }
}
