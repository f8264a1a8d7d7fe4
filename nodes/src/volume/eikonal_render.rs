//! EikonalRender node.

use super::octree::{CLEAR, CLEARANCE, LEVEL, MAX_STEP};
use super::optics::{
    box_interval, leaf_exit, luminance, optical_depth, photon_lights, ray_step, voxel_of, Clearance, Integrator, PhotonLight, Ray,
};
use crate::brdf;
use crate::math::frame::Frame;
use crate::render::camera::CameraRays;
use crate::render::film::per_pixel;
use crate::render::integrator::Counts;
use crate::render::lights::delta_sample;
use crate::render::surface::Surface;
use crate::types::{Accel, Camera, CausticMap, Environment, Image, Material, Sampler, Scene, Volume};
use glam::Vec3;
use relume_core::{inputs, node, outputs, NodeError, Params, RunCtx};
use std::f32::consts::PI;

/// The picture of a medium and its surroundings ([S] 6.3.5): per pixel (`samples`² stratified
/// rays) the camera ray goes straight to the medium's box, then follows the ray equation
/// through it with a fixed step (`step`, 1 voxel) — Störmer–Verlet or the thesis' Euler step
/// x += Δs v / n, v += Δs ∇n (`integrator`, as `MarchPhotons`), |v| = n kept — or,
/// with `adaptive`, the octree's step (as `MarchPhotons` takes it, `step` the least) inside
/// clear leaves (κ = 0 all through: nothing to gather, the index flat within ε′) — where
/// nothing absorbs anywhere, straight on across uniform leaves to the first voxel that may bend
/// the ray, as `MarchPhotons` — and
/// gathers the in-scattered light σ × fluence × phase × transmittance (the fluence and mean
/// light direction `MarchPhotons` stored; phase Henyey–Greenstein of `g` about that direction,
/// blended toward isotropic as the stored light is less directed; `g` = 0 is isotropic), the
/// transmittance falling as e^{−κΔs}. Leaving the box it flies straight: a surface it meets
/// is shaded by its BSDF under each light (the pipeline's point lights, shadowed by the scene
/// and by the medium's transmittance along the straight shadow ray; a shadow ray crossing
/// voxels where rays bend gets nothing, that light arriving as photons), plus the caustic
/// map's irradiance × its diffuse albedo; with no surface, the environment. The camera is an input
/// of its own, so orbiting re-runs this node alone. Biases by construction: no reflection at
/// the object's interface (no Fresnel split), an interface blurred over the voxelisation's
/// Gaussian, single scattering only. Rows in parallel, the same bytes on any thread count.
#[derive(Params)]
pub struct EikonalRender {
    /// Henyey–Greenstein asymmetry of the medium (0: isotropic)
    #[param(default = 0.0, range = -0.99..=0.99)]
    pub g: f32,
    /// rays per pixel side (stratified): samples² rays per pixel
    #[param(default = 1, range = 1..=16)]
    pub samples: u32,
    /// the marching step through the medium
    #[param(default = 1.0, range = 0.05..=16.0, unit = "voxels")]
    pub step: f32,
    /// take the octree's longer steps through clear leaves ([S] 6.3.5 steps fixed everywhere)
    #[param(default = true)]
    pub adaptive: bool,
    /// how the ray equation is stepped
    #[param(default = Verlet)]
    pub integrator: Integrator,
}

inputs!(pub EikonalRenderIn { scene: Scene, accel: Accel, medium: Volume, octree: Volume, radiance: Volume, caustics: CausticMap, camera: Camera });
outputs!(pub EikonalRenderOut { image: Image });

/// The Henyey–Greenstein phase function at scattering cosine `cos`.
pub fn henyey_greenstein(g: f32, cos: f32) -> f32 {
    let d = 1.0 + g * g - 2.0 * g * cos;
    (1.0 - g * g) / (4.0 * PI * d * d.sqrt().max(1e-12))
}

/// Everything the pixels share.
struct Render<'a> {
    scene: &'a Scene,
    accel: &'a Accel,
    m: &'a Volume,
    oct: &'a Volume,
    /// Lookups of n and ∇n in `oct`.
    oct_s: Sampler<'a>,
    /// Its clearance, for straight runs and shadow rays.
    clearance: Clearance,
    radiance: &'a Volume,
    caustics: &'a CausticMap,
    lights: Vec<PhotonLight>,
    p: &'a EikonalRender,
    has_kappa: bool,
    eps: f32,
    obstacles: Option<(Vec3, Vec3)>,
}

impl Render<'_> {
    fn environment(&self, d: Vec3) -> Vec3 {
        match &self.scene.environment {
            Some(Environment::Constant(c)) => *c,
            Some(Environment::Map(m)) => m.eval(d),
            None => Vec3::ZERO,
        }
    }

    /// Transmittance of the medium along the straight segment `o + t u`, t ∈ [0, len].
    fn transmittance(&self, o: Vec3, u: Vec3, len: f32) -> f32 {
        if !self.has_kappa {
            return 1.0;
        }
        match box_interval(o, u, self.m.min, self.m.max) {
            Some((t0, t1)) if t0 < len => (-optical_depth(self.m, o + u * t0, u, t1.min(len) - t0)).exp(),
            _ => 1.0,
        }
    }

    /// Light leaving surface point `s` toward `wo`.
    fn shade(&self, s: &Surface, wo: Vec3, counts: &mut Counts) -> Vec3 {
        let obj = &self.scene.objects[s.object as usize];
        if s.ng.dot(wo) <= 0.0 {
            return Vec3::ZERO;
        }
        let material = s.material(self.scene);
        let mut out = obj.emission;
        if matches!(material, Material::Dielectric { .. }) {
            return out;
        }
        let frame = Frame::from_normal(s.ns);
        let lwo = frame.to_local(wo);
        for l in &self.lights {
            let Some((wi, dist, li)) = delta_sample(&l.light, s.p) else { continue };
            if wi.dot(s.ng) <= 0.0 {
                continue;
            }
            let lwi = frame.to_local(wi);
            let f = brdf::eval(&material, lwo, lwi) * lwi.z.abs();
            if f == Vec3::ZERO {
                continue;
            }
            counts.rays += 1;
            // Off the surface by a size relative to the scene and to |p| (Surface::spawn's
            // offset grows with the square of the scene's size).
            let side = if wi.dot(s.ng) >= 0.0 { 1.0 } else { -1.0 };
            let origin = s.p + s.ng * (side * (self.eps + 1e-6 * s.p.abs().max_element()));
            let tmax = if dist.is_finite() { (dist - l.radius * 1.001) * (1.0 - 1e-4) } else { f32::INFINITY };
            // Light whose straight line crosses voxels where rays bend arrives as photons
            // (the caustic map), never here.
            if tmax > 0.0 && !self.accel.occluded(origin, wi, 0.0, tmax) && !self.clearance.crosses_bends(origin, wi, tmax) {
                out += f * li * self.transmittance(origin, wi, tmax);
            }
        }
        out + brdf::diffuse_albedo(&material) / PI * self.caustics.lookup(s.object, s.p)
    }

    /// Where `o + t u` first meets the scene for t ∈ (0, tmax), starting a hair behind `o`.
    fn hit(&self, o: Vec3, u: Vec3, tmax: f32) -> Option<Surface> {
        let start = o - u * self.eps;
        self.accel.intersect(start, u, 0.0, tmax + self.eps).map(|h| Surface::at(self.scene, &h, start, u))
    }

    /// Radiance arriving at `o` from direction −`d`.
    fn radiance(&self, o: Vec3, d: Vec3, counts: &mut Counts) -> Vec3 {
        counts.rays += 1;
        let m = self.m;
        let first = self.accel.intersect(o, d, 0.0, f32::INFINITY);
        let t_surface = first.map_or(f32::INFINITY, |h| h.t);
        let Some((t0, _)) = box_interval(o, d, m.min, m.max).filter(|(t0, _)| *t0 < t_surface) else {
            return match first {
                Some(h) => self.shade(&Surface::at(self.scene, &h, o, d), -d, counts),
                None => self.environment(d),
            };
        };
        let (mut l, mut tr) = (Vec3::ZERO, 1.0f32);
        let mut ray = Ray::new(&self.oct_s, o + d * t0, d);
        let ds0 = self.p.step * m.voxel().min_element();
        let ch = m.channels as usize;
        let max_steps = 64 * m.dims.iter().sum::<u32>() as usize * (1.0 / self.p.step).ceil().max(1.0) as usize;
        let h = m.voxel();
        for _ in 0..max_steps {
            let (x, u) = (ray.x, ray.dir());
            let mut ds = ds0;
            let mut straight = false;
            if self.p.adaptive {
                let q = self.oct_s.to_grid(x);
                let c = voxel_of(m, q);
                let oi = self.oct.index(c[0], c[1], c[2]);
                let smax = self.oct.data[oi + MAX_STEP];
                if !self.has_kappa && smax == f32::INFINITY && self.oct.data[oi + CLEARANCE] > 0.0 {
                    // Nothing to gather anywhere, and no ray bends here: straight on to the
                    // first voxel that may bend it, as MarchPhotons.
                    let run = self.clearance.straight_run(x, u, f32::INFINITY);
                    (ds, straight) = (run, run > 0.0);
                }
                if !straight && self.oct.data[oi + CLEAR] > 0.0 {
                    let hi = smax.max(self.p.step) * h.min_element();
                    ds = leaf_exit(q, u / h, c, self.oct.data[oi + LEVEL].max(0.0) as u32).max(ds0).min(hi);
                } else if !straight {
                    ds = ds0;
                }
            }
            let t_box = box_interval(x, u, m.min, m.max).map_or(0.0, |(_, t1)| t1);
            let leaving = ds >= t_box;
            if leaving {
                ds = t_box;
            }
            if !leaving {
                // A surface up to half a voxel past the step's end is taken now: the next step
                // would start too close to it to be found.
                let reach = ds + 0.5 * h.min_element();
                if let Some((lo, hi)) = self.obstacles {
                    let end = x + u * reach;
                    if x.min(end).cmple(hi + self.eps).all() && x.max(end).cmpge(lo - self.eps).all() {
                        if let Some(s) = self.hit(x, u, reach) {
                            return l + self.shade(&s, -u, counts) * tr;
                        }
                    }
                }
            }
            if ch > 2 && self.has_kappa {
                let mid = x + u * (ds / 2.0);
                let [_, kappa, sigma] = m.sample_n::<3>(mid, 0);
                let (kappa, sigma) = (kappa.max(0.0), sigma.max(0.0));
                let att = (-kappa * ds).exp();
                if sigma > 0.0 {
                    let [r, g, b, mx, my, mz] = self.radiance.sample_n::<6>(mid, 0);
                    let fluence = Vec3::new(r, g, b);
                    let md = Vec3::new(mx, my, mz);
                    let lum = luminance(fluence);
                    let phase = if self.p.g == 0.0 || lum <= 0.0 {
                        1.0 / (4.0 * PI)
                    } else {
                        let a = (md.length() / lum).clamp(0.0, 1.0);
                        let cos = md.try_normalize().map_or(0.0, |m| m.dot(-u));
                        (1.0 - a) / (4.0 * PI) + a * henyey_greenstein(self.p.g, cos)
                    };
                    let w = if kappa * ds > 1e-6 { (1.0 - att) / kappa } else { ds };
                    l += fluence * (sigma * phase * w * tr);
                }
                tr *= att;
            }
            if leaving {
                // Traced from the step's start: the exit point may lie in a floor's plane.
                return l + tr * self.hit(x, u, f32::INFINITY).map_or_else(|| self.environment(u), |s| self.shade(&s, -u, counts));
            }
            // Longer steps (through clear leaves) are midpoint steps, as in MarchPhotons.
            ray = if straight {
                Ray::new(&self.oct_s, x + u * ds, u)
            } else {
                let integrator = if ds > ds0 * 1.0001 { Integrator::Midpoint } else { self.p.integrator };
                ray_step(&self.oct_s, &ray, ds, integrator)
            };
        }
        l
    }
}

/// The image of the medium seen by `camera` (see the node's doc).
pub fn render(i: &EikonalRenderIn, p: &EikonalRender, cx: &RunCtx) -> Result<(Image, u64), NodeError> {
    let m = i.medium;
    let o = i.octree;
    if o.dims != m.dims || o.channels != super::octree::CHANNELS || o.min != m.min || o.max != m.max {
        return Err(NodeError::failed(format!(
            "the octree ({:?}, {} channels) was not built on the medium's grid ({:?})",
            o.dims, o.channels, m.dims
        )));
    }
    if i.radiance.channels != 6 || (i.radiance.voxels() > 1 && i.radiance.dims != m.dims) {
        return Err(NodeError::failed(format!(
            "the radiance ({:?}, {} channels) is not MarchPhotons' on this medium's grid ({:?})",
            i.radiance.dims, i.radiance.channels, m.dims
        )));
    }
    let r = Render {
        scene: i.scene,
        accel: i.accel,
        m,
        oct: i.octree,
        oct_s: Sampler::new(i.octree),
        clearance: Clearance::of(i.octree),
        radiance: i.radiance,
        caustics: i.caustics,
        lights: photon_lights(i.scene),
        p,
        has_kappa: m.channels > 1 && m.data.chunks(m.channels as usize).any(|c| c[1] > 0.0),
        eps: 1e-5 * i.scene.extent().max((m.max - m.min).length()),
        obstacles: i.accel.bounds_within(m.min, m.max),
    };
    let cam = CameraRays::new(i.camera);
    let s = p.samples as usize;
    let inv = 1.0 / (s * s) as f32;
    per_pixel(cx, i.camera.width, i.camera.height, |x, y, counts| {
        let mut sum = Vec3::ZERO;
        for k in 0..s * s {
            let (fx, fy) = (x as f32 + ((k % s) as f32 + 0.5) / s as f32, y as f32 + ((k / s) as f32 + 0.5) / s as f32);
            let (o, d) = cam.ray(fx, fy);
            sum += r.radiance(o, d, counts);
        }
        (sum * inv).to_array()
    })
}

#[node(category = "volume", version = 4)]
impl EikonalRender {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let image = inputs[6].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        // The octree's clearance as a byte a voxel (its 8 channels hold 32).
        relume_core::MemoryEstimate { outputs: vec![image], working: inputs[3].map_or(0, |s| s.bytes / 32) }
    }

    fn run(&self, i: EikonalRenderIn, cx: &RunCtx) -> Result<EikonalRenderOut, NodeError> {
        let (image, rays) = render(&i, self, cx)?;
        cx.metric("rays", rays as f64);
        Ok(EikonalRenderOut { image })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::emit_photons::Proxy;
    use crate::volume::test_support::*;

    /// The glass scene at `size`² seen through `medium` (photons marched at 48²).
    fn picture(s: &Scene, m: &Volume, size: usize, p: &EikonalRender) -> Image {
        let oct = octree_of(m);
        let a = accel_without(s, "glass");
        let ph = photons(s, &a, m, 48, Proxy::Active);
        let (rad, map) = march(s, &a, m, &oct, &ph, &march_params(64));
        let mut cam = s.camera.clone();
        (cam.width, cam.height) = (size, size);
        render_image(s, &a, m, &oct, &rad, &map, &cam, p)
    }

    #[test]
    fn index_one_gives_the_unrefracted_image() {
        // The glass scene's box reaches down to the floor's plane: camera rays leaving the box
        // there must still find the floor (they did not when traced from the exit point), and
        // an index of 1 everywhere must give the picture of the scene without the object.
        let s = glass();
        let mut m = voxelize(&s, "glass", 24);
        m.data.chunks_mut(3).for_each(|c| c.copy_from_slice(&[1.0, 0.0, 0.0]));
        let through = picture(&s, &m, 40, &render_params());
        // The same box far away: no ray meets it.
        let (lo, hi) = (m.min, m.max);
        (m.min, m.max) = (lo + Vec3::splat(100.0), hi + Vec3::splat(100.0));
        let without = picture(&s, &m, 40, &render_params());
        let worst = through.pixels.iter().zip(&without.pixels).map(|(a, b)| (a[0] - b[0]).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{worst}");
        let lit = (20 * 40..40 * 40).filter(|&k| through.pixels[k][0] > 0.0).count();
        assert_eq!(lit, 20 * 40, "the floor, lit everywhere");
    }

    #[test]
    fn a_scattering_slab_under_a_directional_light_matches_single_scattering() {
        // A cube of homogeneous medium (n = 1, κ = 1, σ = 0.5 per unit, side 1) lit straight
        // down with irradiance E, seen from above at angle θ: single scattering gives
        // L = σ E / 4π · (1 − e^{−κ d (1 + μ) / μ}) / (κ (1 + μ)), μ = cos θ, for a view ray
        // leaving through the bottom face.
        use crate::scene::builder::SceneBuilder;
        use crate::testing::f;
        use crate::types::Light;
        let (e, kappa, sigma) = (3.0f32, 1.0f32, 0.5f32);
        let m =
            source("Constant", 32, Vec3::ZERO, 1.0, &[("index", f(1.0)), ("extinction", f(kappa as f64)), ("scattering", f(sigma as f64))]);
        let theta = 20f32.to_radians();
        let eye = Vec3::new(0.0, 3.0 * theta.cos(), 3.0 * theta.sin());
        let s = SceneBuilder::new(eye, Vec3::ZERO, 8.0, 21, 21)
            .light(Light::Directional { direction: -Vec3::Y, irradiance: Vec3::splat(e) })
            .build();
        let a = accel_without(&s, "");
        let oct = octree_of(&m);
        let ph = photons(&s, &a, &m, 128, Proxy::Active);
        let p = crate::volume::march_photons::MarchPhotons { receiver: "".into(), ..march_params(8) };
        let (rad, map) = march(&s, &a, &m, &oct, &ph, &p);
        let img = render_image(&s, &a, &m, &oct, &rad, &map, &s.camera, &EikonalRender { step: 0.5, ..render_params() });
        let cam = CameraRays::new(&s.camera);
        let (mut got, mut want) = (0.0f64, 0.0f64);
        for y in 8..13 {
            for x in 8..13 {
                let (o, d) = cam.ray(x as f32 + 0.5, y as f32 + 0.5);
                let (t0, t1) = box_interval(o, d, m.min, m.max).unwrap();
                assert!((o + d * t1).y < -0.4999, "the view ray leaves through the bottom");
                let mu = -d.y;
                let depth = 1.0f32;
                let l = sigma * e / (4.0 * PI) * (1.0 - (-kappa * depth * (1.0 + mu) / mu).exp()) / (kappa * (1.0 + mu));
                assert!(t1 > t0);
                want += l as f64;
                got += img.pixels[y * 21 + x][0] as f64;
            }
        }
        assert!((got / want - 1.0).abs() < 0.03, "rendered {got} against single scattering {want}");
    }
}
