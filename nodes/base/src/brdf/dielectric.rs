//! Smooth dielectric interface (delta reflection and refraction).
//!
//! `ior` is the relative index n_inside / n_outside; ωo.z > 0 means the viewer is outside.
//! Let η = n(side of ωi after refraction) / n(side of ωo): η = ior from outside, 1/ior from
//! inside. With the exact Fresnel reflectance F(cos θo, η) ([`fresnel_dielectric`]):
//!
//! - reflection ωi = (−ωo.x, −ωo.y, ωo.z) is chosen with probability F: pdf = F,
//!   f = F / |cos θi|, throughput weight f |cos θi| / pdf = 1;
//! - refraction ωi = (−ωo.x/η, −ωo.y/η, ∓cos θt) (Snell: sin θt = sin θo / η, on the other
//!   side) with probability 1 − F: pdf = 1 − F, f = (1 − F) / (η² |cos θi|), weight 1/η².
//!   The 1/η² is the radiance scaling across the boundary (radiance / n² is invariant), as
//!   Mitsuba 3's `dielectric` in radiance transport mode;
//! - past the critical angle (total internal reflection) F = 1: always reflection, weight 1.
//!
//! ior = 1 gives exactly ωi = −ωo with weight 1. `eval` and `pdf` of a delta BSDF are 0.
//! The optional medium is ignored here (the path tracer handles it).

use super::fresnel::fresnel_dielectric;
use super::lobe::BsdfSample;
use glam::Vec3;

/// Chooses reflection (uc < F) or refraction as described in the module comment. `None` for
/// an invalid `ior` (≤ 0 or not finite), a non-finite ωo or ωo exactly in the surface plane.
pub fn sample(ior: f32, wo: Vec3, uc: f32) -> Option<BsdfSample> {
    if !(ior > 0.0 && ior.is_finite() && wo.is_finite()) || wo.z == 0.0 {
        return None;
    }
    let outside = wo.z > 0.0;
    let eta = if outside { ior } else { 1.0 / ior };
    let cos_o = wo.z.abs();
    let (fr, cos_t) = fresnel_dielectric(cos_o, eta);
    let s = if uc < fr || fr >= 1.0 {
        let wi = Vec3::new(-wo.x, -wo.y, wo.z);
        BsdfSample { wi, f: Vec3::splat(fr / cos_o), pdf: fr, delta: true }
    } else {
        let pt = 1.0 - fr;
        let wi = Vec3::new(-wo.x / eta, -wo.y / eta, if outside { -cos_t } else { cos_t });
        BsdfSample { wi, f: Vec3::splat(pt / cos_t / (eta * eta)), pdf: pt, delta: true }
    };
    (s.f.is_finite() && s.pdf > 0.0 && s.wi.is_finite()).then_some(s)
}

/// Probability that [`sample`] reflects (F, or 1 under total internal reflection) for ωo.
pub fn reflect_probability(ior: f32, wo: Vec3) -> f32 {
    let eta = if wo.z > 0.0 { ior } else { 1.0 / ior };
    fresnel_dielectric(wo.z.abs(), eta).0
}

/// Both Dirac lobes for ωo, as (ωi, weight) with weight the factor on the radiance arriving
/// from ωi: reflection (F) and refraction ((1 − F)/η², weight 0 under total internal
/// reflection), the two outcomes of [`sample`] with their probabilities folded in, so that
/// Σ weight · L(ωi) is the outgoing radiance. ωo must not lie in the surface plane (both
/// weights are 0 there, as for an invalid `ior`).
pub fn lobes(ior: f32, wo: Vec3) -> [(Vec3, f32); 2] {
    let reflected = Vec3::new(-wo.x, -wo.y, wo.z);
    if !(ior > 0.0 && ior.is_finite() && wo.is_finite()) || wo.z == 0.0 {
        return [(reflected, 0.0), (-wo, 0.0)];
    }
    let outside = wo.z > 0.0;
    let eta = if outside { ior } else { 1.0 / ior };
    let (fr, cos_t) = fresnel_dielectric(wo.z.abs(), eta);
    if fr >= 1.0 {
        return [(reflected, 1.0), (-wo, 0.0)];
    }
    let refracted = Vec3::new(-wo.x / eta, -wo.y / eta, if outside { -cos_t } else { cos_t });
    [(reflected, fr), (refracted, (1.0 - fr) / (eta * eta))]
}
