//! Choosing and sampling lights for next-event estimation: emissive triangles (front face
//! only), point, spot and directional lights and the environment, picked in proportion to an
//! estimate of their power.

use crate::math::sampling::{uniform_triangle, Distribution1D};
use crate::types::{Environment, Light, Scene};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// What can be picked. An emitting triangle carries its corners, geometric normal and area
/// (as `Scene::corners` and `Scene::normal_area` give them) and its object's emission, read
/// at every sample; a delta light is the scene's light of that index.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Emitter {
    Triangle { tri: u32, corners: [Vec3; 3], n: Vec3, area: f32, emission: Vec3 },
    Delta(usize),
    Environment,
}

/// A light sample as seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point toward the light.
    pub wi: Vec3,
    /// Distance to the light (infinite for directional and environment light).
    pub dist: f32,
    /// Incident radiance (for delta lights: intensity / dist², already including falloff).
    pub li: Vec3,
    /// Density in solid angle including the choice of this light; for delta lights the
    /// probability of choosing it.
    pub pdf: f32,
    pub delta: bool,
}

pub struct LightSampler {
    items: Vec<Emitter>,
    choice: Distribution1D,
    /// Choice among area lights and the environment only (for callers that handle delta
    /// lights exactly), with the item index of each choice.
    extended: Option<(Distribution1D, Vec<usize>)>,
    /// Item index of every scene triangle (u32::MAX for triangles that do not emit).
    tri_item: Vec<u32>,
    env_item: Option<usize>,
    /// Item index of the scene's first delta light (they follow in scene order).
    first_delta: usize,
}

fn lum(c: Vec3) -> f32 {
    (0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z).max(0.0)
}

impl LightSampler {
    pub fn new(scene: &Scene) -> Self {
        let mut items = Vec::new();
        let mut weights = Vec::new();
        let mut tri_item = vec![u32::MAX; scene.triangles.len()];
        for o in &scene.objects {
            if lum(o.emission) <= 0.0 {
                continue;
            }
            for t in o.triangles.clone() {
                let (n, area) = scene.normal_area(t as usize);
                if area > 0.0 {
                    tri_item[t as usize] = items.len() as u32;
                    items.push(Emitter::Triangle { tri: t, corners: scene.corners(t as usize), n, area, emission: o.emission });
                    weights.push(PI * area * lum(o.emission));
                }
            }
        }
        let r = 0.5 * scene.extent();
        let first_delta = items.len();
        for (i, l) in scene.lights.iter().enumerate() {
            let w = match l {
                Light::Point { intensity, .. } => 4.0 * PI * lum(*intensity),
                Light::Spot { intensity, cos_inner, cos_outer, .. } => 2.0 * PI * (1.0 - 0.5 * (cos_inner + cos_outer)) * lum(*intensity),
                Light::Directional { irradiance, .. } => PI * r * r * lum(*irradiance),
            };
            items.push(Emitter::Delta(i));
            weights.push(w);
        }
        let mut env_item = None;
        let env_lum = match &scene.environment {
            Some(Environment::Constant(c)) => lum(*c),
            Some(Environment::Map(m)) => m.distribution.integral,
            None => 0.0,
        };
        if env_lum > 0.0 {
            env_item = Some(items.len());
            items.push(Emitter::Environment);
            weights.push(4.0 * PI * PI * r * r * env_lum);
        }
        let choice = Distribution1D::new(&weights);
        let ext: Vec<usize> = (0..items.len()).filter(|&i| !matches!(items[i], Emitter::Delta(_))).collect();
        let extended = (!ext.is_empty() && ext.iter().any(|&i| weights[i] > 0.0))
            .then(|| (Distribution1D::new(&ext.iter().map(|&i| weights[i]).collect::<Vec<_>>()), ext));
        LightSampler { items, choice, tri_item, env_item, extended, first_delta }
    }

    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Whether the scene has area lights or an environment (lights with extent).
    pub fn has_extended(&self) -> bool {
        self.extended.is_some()
    }

    /// Samples a light as seen from point `p`. `u` picks the light, `u2` the point on it.
    pub fn sample(&self, scene: &Scene, p: Vec3, u: f32, u2: Vec2) -> Option<LightSample> {
        if self.items.is_empty() {
            return None;
        }
        let (i, p_choice) = self.choice.sample_discrete(u);
        self.sample_item(scene, p, i, p_choice, u2)
    }

    /// As `sample` from one 2-D sample: u.x picks the light and, rescaled within that light's
    /// share, places the point together with u.y, so stratified u stay stratified on each light.
    pub fn sample_2d(&self, scene: &Scene, p: Vec3, u: Vec2) -> Option<LightSample> {
        if self.items.is_empty() {
            return None;
        }
        let (i, p_choice, ux) = self.choice.sample_discrete_reuse(u.x);
        self.sample_item(scene, p, i, p_choice, Vec2::new(ux, u.y))
    }

    /// As `sample`, choosing only among area lights and the environment (densities are
    /// relative to that choice). Delta lights are left to the caller.
    pub fn sample_extended(&self, scene: &Scene, p: Vec3, u: f32, u2: Vec2) -> Option<LightSample> {
        let (dist, idx) = self.extended.as_ref()?;
        let (k, p_choice) = dist.sample_discrete(u);
        self.sample_item(scene, p, idx[k], p_choice, u2)
    }

    /// Picks a light in proportion to its power (as `sample` does), to start a light subpath:
    /// the light and the probability of the pick. `None` without lights.
    pub fn choose(&self, u: f32) -> Option<(Emitter, f32)> {
        if self.items.is_empty() {
            return None;
        }
        let (i, p) = self.choice.sample_discrete(u);
        (p > 0.0).then_some((self.items[i], p))
    }

    /// Probability that `choose` (and `sample`) picks emitting triangle `tri`; 0 for a
    /// triangle that does not emit.
    pub fn triangle_choice(&self, tri: u32) -> f32 {
        match self.tri_item[tri as usize] {
            u32::MAX => 0.0,
            item => self.choice.discrete_pdf(item as usize),
        }
    }

    /// Probability that `choose` picks the scene's delta light `k`.
    pub fn delta_choice(&self, k: usize) -> f32 {
        self.choice.discrete_pdf(self.first_delta + k)
    }

    fn sample_item(&self, scene: &Scene, p: Vec3, i: usize, p_choice: f32, u2: Vec2) -> Option<LightSample> {
        if p_choice <= 0.0 {
            return None;
        }
        match self.items[i] {
            Emitter::Triangle { corners: [a, b, c], n, area, emission, .. } => {
                let (b0, b1) = uniform_triangle(u2);
                let q = a * b0 + b * b1 + c * (1.0 - b0 - b1);
                let d = q - p;
                let dist2 = d.length_squared();
                let dist = dist2.sqrt();
                if dist2 <= 0.0 || !dist.is_finite() {
                    return None;
                }
                let wi = d / dist;
                let cos_l = -wi.dot(n);
                if cos_l <= 0.0 {
                    return None;
                }
                Some(LightSample { wi, dist, li: emission, pdf: p_choice * dist2 / (cos_l * area), delta: false })
            }
            Emitter::Delta(k) => {
                delta_sample(&scene.lights[k], p).map(|(wi, dist, li)| LightSample { wi, dist, li, pdf: p_choice, delta: true })
            }
            Emitter::Environment => match scene.environment.as_ref()? {
                Environment::Constant(c) => {
                    let wi = crate::math::sampling::uniform_sphere(u2);
                    Some(LightSample {
                        wi,
                        dist: f32::INFINITY,
                        li: *c,
                        pdf: p_choice * crate::math::sampling::UNIFORM_SPHERE_PDF,
                        delta: false,
                    })
                }
                Environment::Map(m) => {
                    let (wi, li, pdf) = m.sample(u2)?;
                    Some(LightSample { wi, dist: f32::INFINITY, li, pdf: p_choice * pdf, delta: false })
                }
            },
        }
    }

    /// Solid-angle density with which `sample` would have produced a hit on emissive triangle
    /// `tri` at distance `dist` seen under cosine `cos_l` (for MIS of BSDF-sampled hits).
    pub fn pdf_triangle(&self, tri: u32, dist: f32, cos_l: f32) -> f32 {
        let item = self.tri_item[tri as usize];
        if item == u32::MAX || cos_l <= 0.0 {
            return 0.0;
        }
        let Emitter::Triangle { area, .. } = self.items[item as usize] else { return 0.0 };
        self.choice.discrete_pdf(item as usize) * dist * dist / (cos_l * area)
    }

    /// Solid-angle density of sampling the environment in direction `wi`.
    pub fn pdf_environment(&self, scene: &Scene, wi: Vec3) -> f32 {
        let Some(i) = self.env_item else { return 0.0 };
        let p = self.choice.discrete_pdf(i);
        match &scene.environment {
            Some(Environment::Constant(_)) => p * crate::math::sampling::UNIFORM_SPHERE_PDF,
            Some(Environment::Map(m)) => p * m.pdf(wi),
            None => 0.0,
        }
    }
}

/// Direction, distance and incident radiance of a delta light at point `p`. A light closer
/// than 1e-12 (a light exactly on the surface) contributes nothing rather than infinity.
pub fn delta_sample(l: &Light, p: Vec3) -> Option<(Vec3, f32, Vec3)> {
    match *l {
        Light::Point { position, intensity } => {
            let d = position - p;
            let dist2 = d.length_squared();
            (dist2 > 1e-24).then(|| (d / dist2.sqrt(), dist2.sqrt(), intensity / dist2))
        }
        Light::Spot { position, direction, intensity, cos_inner, cos_outer } => {
            let d = position - p;
            let dist2 = d.length_squared();
            if dist2 <= 1e-24 {
                return None;
            }
            let wi = d / dist2.sqrt();
            let falloff = spot_falloff((-wi).dot(direction), cos_inner, cos_outer);
            (falloff > 0.0).then(|| (wi, dist2.sqrt(), intensity * falloff / dist2))
        }
        Light::Directional { direction, irradiance } => Some((-direction, f32::INFINITY, irradiance)),
    }
}

/// A spot light's share of its intensity at cosine `cos` off its axis: 1 inside `cos_inner`,
/// 0 outside `cos_outer`, smoothstep between.
pub fn spot_falloff(cos: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    if cos >= cos_inner {
        1.0
    } else if cos <= cos_outer {
        0.0
    } else {
        let x = (cos - cos_outer) / (cos_inner - cos_outer);
        x * x * (3.0 - 2.0 * x)
    }
}
