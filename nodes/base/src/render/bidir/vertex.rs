//! The vertices of the bidirectional path tracer's subpaths: what each scatters or emits
//! toward a direction, and the densities (per unit area at the next vertex, per unit volume
//! at a point in a medium) with which its subpath, or the other subpath run backwards,
//! reaches a neighbour.

use crate::brdf;
use crate::math::frame::Frame;
use crate::math::sampling::UNIFORM_SPHERE_PDF;
use crate::render::camera::CameraRays;
use crate::render::lights::{spot_falloff, LightSampler};
use crate::render::surface::Surface;
use crate::types::{Light, Material, Medium, Scene};
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// What a subpath carries: radiance (from the camera) or importance (from a light). They
/// differ where a BSDF is not symmetric: refraction's 1/η² and shading normals.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Radiance,
    Importance,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// The pinhole.
    Camera,
    /// A light subpath's start on an emitting triangle.
    AreaLight,
    /// A light subpath's start at the scene's point or spot light of this index.
    DeltaLight(usize),
    /// Light from infinitely far along `wo`: the environment (`None`) or the scene's
    /// directional light of this index. A camera subpath leaving the scene ends at one.
    Infinite(Option<usize>),
    /// A scattering point on a surface.
    Surface,
    /// A scattering point inside a homogeneous medium (isotropic phase function).
    Medium,
}

#[derive(Clone, Copy, Debug)]
pub struct Vertex {
    pub kind: Kind,
    /// The point; normals, triangle and object on surfaces and area lights.
    pub surf: Surface,
    pub material: Material,
    /// Shading frame (surfaces).
    pub frame: Frame,
    /// Unit direction toward the previous vertex of its subpath (surfaces); toward the light
    /// (infinite lights).
    pub wo: Vec3,
    /// The subpath's weight on arrival (before this vertex scatters).
    pub beta: Vec3,
    /// Scattered by a Dirac lobe: cannot be connected to.
    pub delta: bool,
    /// Density per unit area (per choice at delta lights) of this vertex as its own subpath
    /// sampled it, and as the other subpath would have, run backwards.
    pub pdf_fwd: f32,
    pub pdf_rev: f32,
    /// The medium the vertex lies in (on a surface, on the side its subpath arrived from);
    /// `None` outside media, where the camera and the lights are.
    pub medium: Option<Medium>,
}

/// A point with no surface (the pinhole, a delta light).
fn bare(p: Vec3) -> Surface {
    Surface { p, ng: Vec3::ZERO, ns: Vec3::ZERO, object: 0, tri: u32::MAX, area: 0.0, uv: Vec2::ZERO }
}

/// Veach's correction for shading normals in importance transport: |wo·ns| |wi·ng| / (|wo·ng| |wi·ns|),
/// `wo` toward the previous vertex of the light subpath, `wi` toward the next.
pub fn shading_correction(s: &Surface, wo: Vec3, wi: Vec3) -> f32 {
    let den = wo.dot(s.ng).abs() * wi.dot(s.ns).abs();
    if den == 0.0 {
        0.0
    } else {
        wo.dot(s.ns).abs() * wi.dot(s.ng).abs() / den
    }
}

impl Vertex {
    fn new(kind: Kind, surf: Surface, beta: Vec3, pdf_fwd: f32) -> Vertex {
        let material = Material::Lambert { albedo: Vec3::ZERO };
        let frame = Frame { s: Vec3::X, t: Vec3::Y, n: Vec3::Z };
        Vertex { kind, surf, material, frame, wo: Vec3::ZERO, beta, delta: false, pdf_fwd, pdf_rev: 0.0, medium: None }
    }

    pub fn camera(p: Vec3) -> Vertex {
        Vertex::new(Kind::Camera, bare(p), Vec3::ONE, 0.0)
    }

    pub fn delta_light(k: usize, p: Vec3, beta: Vec3, pdf: f32) -> Vertex {
        Vertex::new(Kind::DeltaLight(k), bare(p), beta, pdf)
    }

    /// Light from direction `dir` (unit, from the scene toward the light). `disk` is the area
    /// of the disk over the scene's bounds that its light subpaths start from (their density
    /// per unit area across the beam is 1 / `disk`); `p` a point far out along `dir`.
    pub fn infinite(light: Option<usize>, dir: Vec3, p: Vec3, disk: f32, beta: Vec3, pdf: f32) -> Vertex {
        let surf = Surface { area: disk, ..bare(p) };
        Vertex { wo: dir, ..Vertex::new(Kind::Infinite(light), surf, beta, pdf) }
    }

    pub fn area_light(surf: Surface, beta: Vec3, pdf: f32) -> Vertex {
        Vertex::new(Kind::AreaLight, surf, beta, pdf)
    }

    /// A surface point reached along `-wo` with weight `beta`.
    pub fn surface(surf: Surface, material: Material, wo: Vec3, beta: Vec3) -> Vertex {
        Vertex { material, frame: Frame::from_normal(surf.ns), wo, ..Vertex::new(Kind::Surface, surf, beta, 0.0) }
    }

    /// A scattering point `p` inside `medium`, reached along `-wo` with weight `beta`.
    pub fn in_medium(p: Vec3, medium: Medium, wo: Vec3, beta: Vec3) -> Vertex {
        Vertex { wo, medium: Some(medium), ..Vertex::new(Kind::Medium, bare(p), beta, 0.0) }
    }

    pub fn p(&self) -> Vec3 {
        self.surf.p
    }

    /// Has an area (its density converts with a cosine).
    pub fn on_surface(&self) -> bool {
        matches!(self.kind, Kind::AreaLight | Kind::Surface)
    }

    /// Can be joined to the other subpath (not a Dirac BSDF).
    pub fn connectible(&self) -> bool {
        self.kind != Kind::Surface || !brdf::is_delta(&self.material)
    }

    pub fn is_delta_light(&self) -> bool {
        matches!(self.kind, Kind::DeltaLight(_) | Kind::Infinite(Some(_)))
    }

    pub fn is_infinite(&self) -> bool {
        matches!(self.kind, Kind::Infinite(_))
    }

    /// Unit direction from this vertex to `other` and the squared distance (infinite, and the
    /// light's own direction, where either is an infinite light).
    pub fn dir_to(&self, other: &Vertex) -> (Vec3, f32) {
        if other.is_infinite() {
            (other.wo, f32::INFINITY)
        } else if self.is_infinite() {
            (-self.wo, f32::INFINITY)
        } else {
            toward(self.p(), other.p())
        }
    }

    /// |cos| of `w` in a connection's geometry term: against the shading normal on surfaces,
    /// the geometric one on area lights, 1 at points.
    pub fn cos_g(&self, w: Vec3) -> f32 {
        match self.kind {
            Kind::Surface => w.dot(self.surf.ns).abs(),
            Kind::AreaLight => w.dot(self.surf.ng).abs(),
            Kind::Camera | Kind::DeltaLight(_) | Kind::Infinite(_) | Kind::Medium => 1.0,
        }
    }

    /// |cos| of `w` against the geometric normal (densities per unit area), 1 at points.
    pub fn cos_area(&self, w: Vec3) -> f32 {
        if self.on_surface() {
            w.dot(self.surf.ng).abs()
        } else {
            1.0
        }
    }

    /// The BSDF of a surface vertex from its previous vertex toward `w`, as its subpath
    /// carries it: opaque materials are one-sided, as in the path tracer (both directions on
    /// the front of the geometric surface); Dirac lobes give 0. In a medium, the isotropic
    /// phase function 1/4π (the same both ways).
    pub fn f(&self, w: Vec3, mode: Mode) -> Vec3 {
        if self.kind == Kind::Medium {
            return Vec3::splat(UNIFORM_SPHERE_PDF);
        }
        if self.kind != Kind::Surface || self.wo.dot(self.surf.ng) <= 0.0 || w.dot(self.surf.ng) <= 0.0 {
            return Vec3::ZERO;
        }
        let v = brdf::eval(&self.material, self.frame.to_local(self.wo), self.frame.to_local(w));
        match mode {
            Mode::Radiance => v,
            Mode::Importance => v * shading_correction(&self.surf, self.wo, w),
        }
    }

    /// What a light vertex sends toward `w`: an area light's radiance (front side only), a
    /// point or spot light's intensity, the environment's radiance or a directional light's
    /// irradiance along its own direction.
    pub fn emit(&self, scene: &Scene, w: Vec3) -> Vec3 {
        match self.kind {
            Kind::AreaLight if w.dot(self.surf.ng) > 0.0 => scene.objects[self.surf.object as usize].emission,
            Kind::DeltaLight(k) => match scene.lights[k] {
                Light::Point { intensity, .. } => intensity,
                Light::Spot { direction, intensity, cos_inner, cos_outer, .. } => {
                    intensity * spot_falloff(w.dot(direction), cos_inner, cos_outer)
                }
                Light::Directional { .. } => Vec3::ZERO,
            },
            Kind::Infinite(None) => scene.environment_radiance(self.wo),
            Kind::Infinite(Some(k)) => match scene.lights[k] {
                Light::Directional { irradiance, .. } => irradiance,
                _ => Vec3::ZERO,
            },
            _ => Vec3::ZERO,
        }
    }

    /// The radiance a camera subpath's last vertex brings back: a surface's emission toward
    /// its previous vertex (front side only), or the environment's where the path left.
    pub fn emitted(&self, scene: &Scene) -> Vec3 {
        match self.kind {
            Kind::Surface if self.wo.dot(self.surf.ng) > 0.0 => scene.objects[self.surf.object as usize].emission,
            Kind::Infinite(None) => scene.environment_radiance(self.wo),
            _ => Vec3::ZERO,
        }
    }

    /// Solid-angle density with which a light subpath starting here leaves toward `w`:
    /// cosine-weighted on area lights (and on emitting surfaces a camera subpath reached),
    /// uniform over the sphere or the cone at delta lights.
    pub fn emit_pdf(&self, scene: &Scene, w: Vec3) -> f32 {
        match self.kind {
            Kind::AreaLight | Kind::Surface => w.dot(self.surf.ng).max(0.0) * FRAC_1_PI,
            Kind::DeltaLight(k) => match scene.lights[k] {
                Light::Point { .. } => UNIFORM_SPHERE_PDF,
                Light::Spot { direction, cos_outer, .. } => {
                    if w.dot(direction) >= cos_outer {
                        cone_pdf(cos_outer)
                    } else {
                        0.0
                    }
                }
                Light::Directional { .. } => 0.0,
            },
            Kind::Camera | Kind::Infinite(_) | Kind::Medium => 0.0,
        }
    }

    /// Density of starting a light subpath at this point: the light's choice over its area on
    /// triangles, the choice alone at delta lights, the choice times the density of the
    /// direction for the environment.
    pub fn origin_pdf(&self, scene: &Scene, lights: &LightSampler) -> f32 {
        match self.kind {
            Kind::AreaLight | Kind::Surface if self.surf.area > 0.0 => lights.triangle_choice(self.surf.tri) / self.surf.area,
            Kind::DeltaLight(k) | Kind::Infinite(Some(k)) => lights.delta_choice(k),
            Kind::Infinite(None) => lights.pdf_environment(scene, self.wo),
            _ => 0.0,
        }
    }

    /// Density per unit area at `next` of a light subpath starting here and leaving toward it.
    pub fn light_pdf(&self, scene: &Scene, next: &Vertex) -> f32 {
        if self.is_infinite() {
            return next.cos_area(self.wo) / self.surf.area;
        }
        let (w, dist2) = self.dir_to(next);
        to_area(self.emit_pdf(scene, w), next, w, dist2)
    }

    /// Density per unit area at `next` with which this vertex's subpath, arriving from the
    /// direction `from` (unit, ignored at the camera and at lights), continues to `next`.
    /// From an infinite light: the beam's density across it, times the cosine at `next`.
    pub fn pdf(&self, scene: &Scene, cam: &CameraRays, from: Vec3, next: &Vertex) -> f32 {
        let (w, dist2) = self.dir_to(next);
        let solid = match self.kind {
            Kind::Infinite(_) => return self.light_pdf(scene, next),
            Kind::Camera => cam.direction_pdf(w),
            Kind::AreaLight | Kind::DeltaLight(_) => self.emit_pdf(scene, w),
            Kind::Medium => UNIFORM_SPHERE_PDF,
            Kind::Surface => {
                let ng = self.surf.ng;
                if brdf::is_delta(&self.material) || from.dot(ng) <= 0.0 || w.dot(ng) <= 0.0 {
                    0.0
                } else {
                    brdf::pdf(&self.material, self.frame.to_local(from), self.frame.to_local(w))
                }
            }
        };
        to_area(solid, next, w, dist2)
    }
}

/// Unit direction from `a` to `b` and the squared distance.
pub fn toward(a: Vec3, b: Vec3) -> (Vec3, f32) {
    let d = b - a;
    let dist2 = d.length_squared();
    (d / dist2.sqrt(), dist2)
}

/// A solid-angle density toward `next` along `w` at squared distance `dist2`, per unit area
/// (an infinite light's vertex keeps the solid angle: it is a direction).
pub fn to_area(solid: f32, next: &Vertex, w: Vec3, dist2: f32) -> f32 {
    if next.is_infinite() {
        solid
    } else if dist2 > 0.0 {
        solid * next.cos_area(w) / dist2
    } else {
        0.0
    }
}

/// Density of a direction uniform over the cone cos θ ≥ `cos_outer`.
pub fn cone_pdf(cos_outer: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_outer.max(-1.0)))
}
