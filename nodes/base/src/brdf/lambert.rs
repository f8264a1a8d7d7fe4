//! Lambertian reflector.

use super::lobe::BsdfSample;
use crate::math::sampling::{cosine_hemisphere, cosine_hemisphere_pdf};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// f = albedo / π for cos θo > 0 and cos θi > 0, else 0.
pub fn eval(albedo: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return Vec3::ZERO;
    }
    albedo * FRAC_1_PI
}

/// p(ωi) = cos θi / π on the upper hemisphere (cosine sampling), 0 elsewhere or when ωo is below.
pub fn pdf(wo: Vec3, wi: Vec3) -> f32 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return 0.0;
    }
    cosine_hemisphere_pdf(wi.z)
}

/// Cosine-weighted ωi (Shirley–Chiu disk lifted to the hemisphere); weight f cos θi / p = albedo.
pub fn sample(albedo: Vec3, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
    if wo.z <= 0.0 {
        return None;
    }
    let wi = cosine_hemisphere(u);
    let p = pdf(wo, wi);
    if p <= 0.0 {
        return None;
    }
    Some(BsdfSample { wi, f: eval(albedo, wo, wi), pdf: p, delta: false })
}
