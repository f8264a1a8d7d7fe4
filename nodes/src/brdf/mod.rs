//! BSDFs of the scene materials ([`Material`]): evaluation, sampling densities and importance
//! sampling, all in the local shading frame.
//!
//! Conventions: +z is the shading normal; `wo` points away from the surface toward the viewer,
//! `wi` toward the light; values exclude the cosine factor, so the path throughput weight of a
//! sample is f |cos θi| / pdf. Opaque models (Lambert, Blinn-Phong, Cook-Torrance) are
//! one-sided: everything is zero (and `sample` gives `None`) when wo.z ≤ 0 or wi.z ≤ 0.
//!
//! - [`lambert`]: f = albedo / π, cosine sampling.
//! - [`blinn_phong`]: f = kd/π + ks (s+2)/(8π) cos^s δ, mixture of cosine and half-vector lobe
//!   sampling.
//! - [`cook_torrance`]: f = kd/π + ks D F G / (4 cos θi cos θo) with Beckmann D, Schlick F,
//!   V-cavity G; mixture of cosine and Beckmann D(h) cos θh sampling.
//! - [`dielectric`]: smooth interface, exact Fresnel, delta reflection / refraction.

pub mod blinn_phong;
pub mod cook_torrance;
pub mod dielectric;
pub mod fresnel;
pub mod lambert;
mod model;
#[cfg(test)]
mod tests;

pub use model::BrdfModel;

use crate::math::sampling::cosine_hemisphere;
use crate::types::Material;
use glam::{DVec3, Vec2, Vec3};

/// A direction drawn by [`sample`]. Directions are in the local shading frame: +z is the
/// shading normal; `wo` points away from the surface toward the viewer, `wi` toward the light.
/// Values exclude the cosine factor: the throughput weight is `f * |wi.z| / pdf`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    pub wi: Vec3,
    /// BSDF value for (wo, wi); for delta samples the value of the delta lobe's coefficient
    /// (divided by |cos θi|) so that f |cos θi| / pdf is the throughput weight.
    pub f: Vec3,
    /// Solid-angle density of `wi` (for delta samples: the discrete probability of the lobe).
    pub pdf: f32,
    /// True when `wi` came from a Dirac lobe (it cannot be reached by `eval` / `pdf`).
    pub delta: bool,
}

/// The BSDF f(wo, wi) without the cosine factor; 0 for delta materials (their lobes are only
/// reachable through [`sample`]).
pub fn eval(m: &Material, wo: Vec3, wi: Vec3) -> Vec3 {
    match *m {
        Material::Lambert { albedo } => lambert::eval(albedo, wo, wi),
        Material::BlinnPhong { kd, ks, exponent } => blinn_phong::eval(kd, ks, exponent, wo, wi),
        Material::CookTorrance { kd, ks, roughness, f0 } => cook_torrance::eval(kd, ks, roughness, f0, wo, wi),
        Material::Dielectric { .. } => Vec3::ZERO,
    }
}

/// Solid-angle density with which [`sample`] returns `wi` given `wo`; 0 for delta materials.
pub fn pdf(m: &Material, wo: Vec3, wi: Vec3) -> f32 {
    match *m {
        Material::Lambert { .. } => lambert::pdf(wo, wi),
        Material::BlinnPhong { kd, ks, exponent } => blinn_phong::pdf(kd, ks, exponent, wo, wi),
        Material::CookTorrance { kd, ks, roughness, .. } => cook_torrance::pdf(kd, ks, roughness, wo, wi),
        Material::Dielectric { .. } => 0.0,
    }
}

/// Importance-samples `wi` given `wo`; `u` and `uc` are uniform in [0, 1) (`uc` picks the lobe).
/// `None` when the sample carries no energy (back side, direction below the horizon, black
/// material). Every returned sample has finite f ≥ 0 and finite pdf > 0.
pub fn sample(m: &Material, wo: Vec3, u: Vec2, uc: f32) -> Option<BsdfSample> {
    match *m {
        Material::Lambert { albedo } => lambert::sample(albedo, wo, u),
        Material::BlinnPhong { kd, ks, exponent } => blinn_phong::sample(kd, ks, exponent, wo, u, uc),
        Material::CookTorrance { kd, ks, roughness, f0 } => cook_torrance::sample(kd, ks, roughness, f0, wo, u, uc),
        Material::Dielectric { ior, .. } => dielectric::sample(ior, wo, uc),
    }
}

/// True for materials made only of Dirac lobes (eval and pdf are always 0).
pub fn is_delta(m: &Material) -> bool {
    matches!(m, Material::Dielectric { .. })
}

/// Rough hemispherical reflectance, e.g. for Russian roulette or debugging (not exact):
/// Lambert → albedo; Blinn-Phong → kd + ks; Cook-Torrance → kd + ks (f0 + (1 − f0)/21)
/// (the cosine-weighted hemispherical mean of Schlick's F); dielectric → 1 (lossless).
pub fn albedo_hint(m: &Material) -> Vec3 {
    match *m {
        Material::Lambert { albedo } => albedo,
        Material::BlinnPhong { kd, ks, .. } => kd + ks,
        Material::CookTorrance { kd, ks, f0, .. } => kd + ks * (f0 + (1.0 - f0) / 21.0),
        Material::Dielectric { .. } => Vec3::ONE,
    }
}

// ---- helpers shared by the two glossy (diffuse + specular lobe) models -----------------------

/// Rec. 709 luminance of the non-negative part of an RGB colour.
pub(crate) fn luminance(c: Vec3) -> f64 {
    let c = c.max(Vec3::ZERO).as_dvec3();
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// Probability of sampling the diffuse lobe of a kd/ks mixture: Y(kd) / (Y(kd) + Y(ks)), Y the
/// luminance. `None` when both are black (or not finite): such a material reflects nothing.
pub(crate) fn diffuse_probability(kd: Vec3, ks: Vec3) -> Option<f64> {
    let (d, s) = (luminance(kd), luminance(ks));
    let sum = d + s;
    if sum > 0.0 && sum.is_finite() {
        Some(d / sum)
    } else {
        None
    }
}

/// The half vector h = (ωo + ωi) / |ωo + ωi| of two upper-hemisphere directions, in f64.
pub(crate) struct Half {
    /// cos θh = h.z.
    pub cos_h: f64,
    /// tan² θh, computed from the components (accurate when θh is tiny).
    pub tan2_h: f64,
    /// ωo·h = ωi·h, taken as their mean so that swapping ωo and ωi gives bit-identical
    /// values (they differ only by rounding for unit inputs): eval is exactly reciprocal.
    pub wo_h: f64,
}

/// `None` unless both directions are strictly above the surface and the half vector exists.
pub(crate) fn half_vector(wo: Vec3, wi: Vec3) -> Option<Half> {
    if wo.z <= 0.0 || wi.z <= 0.0 || !wo.is_finite() || !wi.is_finite() {
        return None;
    }
    let (o, i) = (wo.as_dvec3(), wi.as_dvec3());
    let s = o + i;
    let len = s.length();
    if len <= 0.0 || s.z <= 0.0 {
        return None;
    }
    let h = s / len;
    let wo_h = (0.5 * (o.dot(h) + i.dot(h))).max(0.0);
    Some(Half { cos_h: h.z, tan2_h: (s.x * s.x + s.y * s.y) / (s.z * s.z), wo_h })
}

/// Unit vector from polar angle (given by its cosine and sine) and azimuth, in f64.
pub(crate) fn spherical(cos_t: f64, sin_t: f64, phi: f64) -> DVec3 {
    DVec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

/// Mirror of ωo about the unit normal h: ωi = 2 (ωo·h) h − ωo (computed in f64).
pub(crate) fn reflect(wo: Vec3, h: DVec3) -> Vec3 {
    let o = wo.as_dvec3();
    (2.0 * o.dot(h) * h - o).normalize_or_zero().as_vec3()
}

/// f64 → f32 that saturates at f32::MAX instead of overflowing to infinity (NaN → 0).
pub(crate) fn to_f32_finite(x: f64) -> f32 {
    if x.is_nan() {
        0.0
    } else {
        x.clamp(-(f32::MAX as f64), f32::MAX as f64) as f32
    }
}

/// Draws ωi from the two-lobe mixture of a glossy model (diffuse with probability
/// `p_diffuse`, else the mirror of ωo about `sample_h(u)`), then evaluates f and the mixture
/// density through `m`'s own [`eval`] / [`pdf`] so that they agree exactly.
pub(crate) fn sample_mixture(
    m: &Material,
    wo: Vec3,
    u: Vec2,
    uc: f32,
    p_diffuse: f64,
    sample_h: impl FnOnce(Vec2) -> DVec3,
) -> Option<BsdfSample> {
    if wo.z <= 0.0 || !wo.is_finite() {
        return None;
    }
    let wi = if (uc as f64) < p_diffuse { cosine_hemisphere(u) } else { reflect(wo, sample_h(u)) };
    if wi.z <= 0.0 || !wi.is_finite() {
        return None;
    }
    let p = pdf(m, wo, wi);
    let f = eval(m, wo, wi);
    if !(p > 0.0 && p.is_finite() && f.is_finite()) || f.min_element() < 0.0 {
        return None;
    }
    Some(BsdfSample { wi, f, pdf: p, delta: false })
}

/// The diffuse reflectance kd of a material (what point-based GI carries between surfaces);
/// zero for dielectrics.
pub fn diffuse_albedo(m: &Material) -> Vec3 {
    match *m {
        Material::Lambert { albedo } => albedo,
        Material::BlinnPhong { kd, .. } | Material::CookTorrance { kd, .. } => kd,
        Material::Dielectric { .. } => Vec3::ZERO,
    }
}
