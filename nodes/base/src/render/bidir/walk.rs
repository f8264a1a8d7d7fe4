//! The two subpaths: the camera's and a light's, each a random walk that records at every
//! vertex its weight and the densities of reaching it from either end.

use super::vertex::{cone_pdf, shading_correction, to_area, toward, Kind, Mode, Vertex};
use super::Bidir;
use crate::brdf;
use crate::math::frame::Frame;
use crate::math::sampling::{concentric_disk, cosine_hemisphere, uniform_sphere, uniform_triangle, UNIFORM_SPHERE_PDF};
use crate::render::integrator::{medium_after, sample_medium, Counts, MediumEvent, Sampler};
use crate::render::lights::Emitter;
use crate::render::surface::Surface;
use crate::types::{Environment, Light, Material, Medium};
use glam::Vec3;
use std::f32::consts::PI;

impl Bidir<'_> {
    /// The camera subpath of the ray (o, d): the pinhole and up to `max - 1` surface vertices,
    /// ended by the environment where the path leaves the scene.
    pub(super) fn camera_path(&self, path: &mut Vec<Vertex>, o: Vec3, d: Vec3, rng: &mut Sampler, counts: &mut Counts) {
        path.push(Vertex::camera(o));
        let pdf = self.cam.direction_pdf(d);
        self.walk(path, o, d, Vec3::ONE, pdf, self.max_camera, Mode::Radiance, rng, counts);
    }

    /// A light subpath: a light picked by power, a point on it, a direction from it, then up
    /// to `max - 1` surface vertices (from an infinite light, a direction and a point where
    /// its beam enters the scene). Empty when nothing emits.
    pub(super) fn light_path(&self, path: &mut Vec<Vertex>, rng: &mut Sampler, counts: &mut Counts) {
        if self.max_light == 0 {
            return;
        }
        let Some((emitter, choice)) = self.lights.choose(rng.draw()) else { return };
        let (u_pos, u_dir) = (rng.draw2(), rng.draw2());
        let (y0, w, pdf_dir) = match emitter {
            Emitter::Triangle { tri, corners: [a, b, c], n, area, .. } => {
                let (b0, b1) = uniform_triangle(u_pos);
                let p = a * b0 + b * b1 + c * (1.0 - b0 - b1);
                let object = self.scene.tri_object[tri as usize];
                let surf = Surface { p, ng: n, ns: n, object, tri, area, uv: glam::Vec2::ZERO };
                let pdf = choice / area;
                let local = cosine_hemisphere(u_dir);
                (Vertex::area_light(surf, Vec3::splat(1.0 / pdf), pdf), Frame::from_normal(n).to_world(local), local.z / PI)
            }
            Emitter::Delta(k) => {
                let (p, w, pdf_dir) = match self.scene.lights[k] {
                    Light::Point { position, .. } => (position, uniform_sphere(u_dir), UNIFORM_SPHERE_PDF),
                    Light::Spot { position, direction, cos_outer, .. } => {
                        let cos = 1.0 - u_dir.x * (1.0 - cos_outer.max(-1.0));
                        let sin = (1.0 - cos * cos).max(0.0).sqrt();
                        let phi = 2.0 * PI * u_dir.y;
                        let local = Vec3::new(sin * phi.cos(), sin * phi.sin(), cos);
                        (position, Frame::from_normal(direction).to_world(local), cone_pdf(cos_outer))
                    }
                    Light::Directional { direction, .. } => {
                        let dir = -direction.normalize();
                        let y0 = Vertex::infinite(Some(k), dir, self.far(dir), self.disk, Vec3::splat(1.0 / choice), choice);
                        return self.beam(path, y0, u_pos, rng, counts);
                    }
                };
                (Vertex::delta_light(k, p, Vec3::splat(1.0 / choice), choice), w, pdf_dir)
            }
            Emitter::Environment => {
                let Some((dir, pdf_dir)) = self.environment_direction(u_dir) else { return };
                let pdf = choice * pdf_dir;
                return self.beam(
                    path,
                    Vertex::infinite(None, dir, self.far(dir), self.disk, Vec3::splat(1.0 / pdf), pdf),
                    u_pos,
                    rng,
                    counts,
                );
            }
        };
        path.push(y0);
        if !(pdf_dir > 0.0) {
            return;
        }
        let beta = y0.beta * y0.emit(self.scene, w) * (y0.cos_g(w) / pdf_dir);
        if beta == Vec3::ZERO || !beta.is_finite() {
            return;
        }
        let o = if y0.on_surface() { y0.surf.spawn(w, self.eps) } else { y0.p() };
        self.walk(path, o, w, beta, pdf_dir, self.max_light, Mode::Importance, rng, counts);
    }

    /// A light subpath from an infinite light `y0`: a beam along −`y0.wo` over a disk that
    /// covers the scene, entered at a point uniform on it (`u`).
    fn beam(&self, path: &mut Vec<Vertex>, y0: Vertex, u: glam::Vec2, rng: &mut Sampler, counts: &mut Counts) {
        path.push(y0);
        let (dir, frame) = (y0.wo, Frame::from_normal(y0.wo));
        let d = concentric_disk(u) * self.radius;
        let o = self.centre + dir * self.radius + frame.s * d.x + frame.t * d.y;
        let beta = y0.beta * y0.emit(self.scene, -dir) * self.disk;
        if beta != Vec3::ZERO && beta.is_finite() {
            self.walk(path, o, -dir, beta, 1.0 / self.disk, self.max_light, Mode::Importance, rng, counts);
        }
    }

    /// A direction toward the environment, drawn as the path tracer draws it for light
    /// sampling, and its solid-angle density.
    fn environment_direction(&self, u: glam::Vec2) -> Option<(Vec3, f32)> {
        match self.scene.environment.as_ref()? {
            Environment::Constant(_) => Some((uniform_sphere(u), UNIFORM_SPHERE_PDF)),
            Environment::Map(m) => m.sample(u).map(|(wi, _, pdf)| (wi, pdf)).filter(|&(_, pdf)| pdf > 0.0),
        }
    }

    /// A point far out along `dir`, outside the scene.
    pub(super) fn far(&self, dir: Vec3) -> Vec3 {
        self.centre + dir * (4.0 * self.radius)
    }

    /// Extends `path` from its last vertex along the ray (o, d) with weight `beta`, the ray's
    /// solid-angle density `pdf` (per unit area across the beam after an infinite light),
    /// until it has `max` vertices, leaves the scene, meets the back of an opaque surface, its
    /// BSDF sample fails or Russian roulette ends it (from `rr_depth` bounces on, continuing
    /// with probability min(β / β₁, 0.95)). Inside a dielectric's medium a scattering point
    /// may come before the next surface, drawn as the path tracer draws it; the subpath starts
    /// outside media and enters or leaves one where it crosses the boundary.
    #[allow(clippy::too_many_arguments)]
    fn walk(
        &self,
        path: &mut Vec<Vertex>,
        mut o: Vec3,
        mut d: Vec3,
        mut beta: Vec3,
        mut pdf: f32,
        max: usize,
        mode: Mode,
        rng: &mut Sampler,
        counts: &mut Counts,
    ) {
        let beta1 = beta.max_element();
        let mut medium: Option<Medium> = None;
        while path.len() < max {
            counts.rays += 1;
            let hit = self.accel.intersect(o, d, 0.0, f32::INFINITY);
            let mut scatter_at = None;
            if let Some(m) = &medium {
                match sample_medium(m, hit.map_or(f32::INFINITY, |h| h.t), rng) {
                    MediumEvent::Scatter(t, weight) => {
                        beta *= weight;
                        scatter_at = Some(o + d * t);
                    }
                    MediumEvent::Pass(weight) => beta *= weight,
                }
                if beta == Vec3::ZERO || !beta.is_finite() {
                    break;
                }
            }
            let mut v = match (scatter_at, medium, hit) {
                (Some(p), Some(m), _) => Vertex::in_medium(p, m, -d, beta),
                (_, _, None) => {
                    if mode == Mode::Radiance && self.scene.environment.is_some() {
                        path.push(Vertex::infinite(None, d, self.far(d), self.disk, beta, pdf));
                    }
                    break;
                }
                (_, _, Some(hit)) => {
                    let surf = Surface::at(self.scene, &hit, o, d);
                    let material = surf.material(self.scene);
                    if !brdf::is_delta(&material) && d.dot(surf.ng) >= 0.0 {
                        break;
                    }
                    Vertex { medium, ..Vertex::surface(surf, material, -d, beta) }
                }
            };
            let prev = &path[path.len() - 1];
            v.pdf_fwd = if prev.is_infinite() {
                pdf * v.cos_area(d)
            } else {
                let (w, dist2) = toward(prev.p(), v.p());
                to_area(pdf, &v, w, dist2)
            };
            path.push(v);
            if path.len() >= max {
                break;
            }
            let Some(step) = self.scatter(&v, mode, rng) else { break };
            let here = path.len() - 1;
            path[here].delta = step.delta;
            let (back, back2) = toward(v.p(), path[here - 1].p());
            path[here - 1].pdf_rev = to_area(step.pdf_rev, &path[here - 1], back, back2);
            medium = medium_after(&v.material, v.surf.ng, v.wo, step.wi, medium);
            pdf = step.pdf;
            beta *= step.weight;
            if beta == Vec3::ZERO || !beta.is_finite() {
                break;
            }
            if here as u32 >= self.rr_depth {
                let q = (beta.max_element() / beta1).min(0.95);
                if !(q > 0.0) || rng.draw() >= q {
                    break;
                }
                beta /= q;
            }
            o = if v.on_surface() { v.surf.spawn(step.wi, self.eps) } else { v.p() };
            d = step.wi;
        }
    }

    /// The direction a subpath leaves vertex `v` in (the BSDF's sample on surfaces, uniform
    /// over the sphere in a medium), its weight f |cos| / pdf as the subpath carries it, and
    /// the solid-angle densities of that direction forward and backward; `None` where the
    /// sample fails or leaves an opaque surface through its back.
    fn scatter(&self, v: &Vertex, mode: Mode, rng: &mut Sampler) -> Option<Step> {
        if v.kind == Kind::Medium {
            // Isotropic phase: f = pdf = 1/4π, weight 1.
            let wi = uniform_sphere(rng.draw2());
            return Some(Step { wi, weight: Vec3::ONE, pdf: UNIFORM_SPHERE_PDF, pdf_rev: UNIFORM_SPHERE_PDF, delta: false });
        }
        let (surf, material) = (&v.surf, v.material);
        let wo = v.frame.to_local(v.wo);
        let (u2, uc) = (rng.draw2(), rng.draw());
        // Without Fresnel reflection a dielectric always draws refraction (uc ≥ F), which total
        // internal reflection (F = 1) still overrules; the numbers drawn stay the same.
        let uc = if self.fresnel_reflection || !matches!(material, Material::Dielectric { .. }) { uc } else { 1.0 };
        let bs = brdf::sample(&material, wo, u2, uc)?;
        if !(bs.pdf > 0.0 && bs.pdf.is_finite()) {
            return None;
        }
        let wi = v.frame.to_world(bs.wi);
        if !bs.delta && wi.dot(surf.ng) <= 0.0 {
            return None;
        }
        let mut weight = bs.f * (bs.wi.z.abs() / bs.pdf);
        if mode == Mode::Importance {
            weight *= shading_correction(surf, v.wo, wi);
            if let Material::Dielectric { ior, .. } = material {
                // Importance does not scale by 1/η² across a boundary, radiance does.
                if bs.wi.z * wo.z < 0.0 {
                    let eta = if wo.z > 0.0 { ior } else { 1.0 / ior };
                    weight *= eta * eta;
                }
            }
        }
        let (pdf, pdf_rev) = if bs.delta { (0.0, 0.0) } else { (bs.pdf, brdf::pdf(&material, bs.wi, wo)) };
        Some(Step { wi, weight, pdf, pdf_rev, delta: bs.delta })
    }
}

/// One scattering step of a subpath (see [`Bidir::scatter`]); Dirac lobes have densities 0.
struct Step {
    wi: Vec3,
    weight: Vec3,
    pdf: f32,
    pdf_rev: f32,
    delta: bool,
}
