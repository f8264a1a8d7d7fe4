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
mod lobe;
mod model;
#[cfg(test)]
mod tests;

pub use lobe::BsdfSample;
pub use model::BrdfModel;

use crate::types::Material;
use glam::{Vec2, Vec3};

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

/// The diffuse reflectance kd of a material (what point-based GI carries between surfaces);
/// zero for dielectrics.
pub fn diffuse_albedo(m: &Material) -> Vec3 {
    match *m {
        Material::Lambert { albedo } => albedo,
        Material::BlinnPhong { kd, .. } | Material::CookTorrance { kd, .. } => kd,
        Material::Dielectric { .. } => Vec3::ZERO,
    }
}
