//! Normalised Blinn-Phong.
//!
//! f(ωo, ωi) = kd/π + ks (s+2)/(8π) cos^s δ, δ the angle between the half vector
//! h = (ωo+ωi)/|ωo+ωi| and the normal (docs/PIPELINES.md "BRDFs"). The thesis' [S] 4-15 prints
//! (s+2)/(2π), which with the half-vector angle reflects up to 4× the incident energy; with 8π
//! the specular albedo stays ≤ 1 (→ 1 − O(1/s) at normal incidence for large s), so
//! kd + ks ≤ 1 conserves energy.
//!
//! Sampling: with probability P_d = Y(kd)/(Y(kd)+Y(ks)) (Y = luminance) a cosine-weighted ωi;
//! otherwise a half vector from p(h) = (s+1)/(2π) cos^s θh (cos θh = u^{1/(s+1)}, φ = 2πu')
//! mirrored into ωi = 2(ωo·h)h − ωo, whose density is p(h) / (4 ωo·h). [`pdf`] returns the
//! mixture P_d cos θi/π + (1−P_d) p(h)/(4 ωo·h). Everything is evaluated in f64, so s from 0
//! to 10⁴ and directions down to grazing stay finite.

use super::lobe::{diffuse_probability, half_vector, sample_mixture, spherical, to_f32_finite, BsdfSample};
use glam::{Vec2, Vec3};
use std::f64::consts::PI;

/// Exponents are clamped to [0, ∞) (NaN → 0).
fn exponent(s: f32) -> f64 {
    if s > 0.0 {
        s as f64
    } else {
        0.0
    }
}

/// The specular factor (s+2)/(8π) cos^s δ, without ks.
pub fn specular(s: f32, cos_h: f64) -> f64 {
    let s = exponent(s);
    (s + 2.0) / (8.0 * PI) * cos_h.max(0.0).powf(s)
}

/// p(h) = (s+1)/(2π) cos^s θh, the solid-angle density of the sampled half vector.
pub fn half_vector_pdf(s: f32, cos_h: f64) -> f64 {
    let s = exponent(s);
    (s + 1.0) / (2.0 * PI) * cos_h.max(0.0).powf(s)
}

/// f = kd/π + ks (s+2)/(8π) cos^s δ for cos θo, cos θi > 0, else 0.
pub fn eval(kd: Vec3, ks: Vec3, s: f32, wo: Vec3, wi: Vec3) -> Vec3 {
    let Some(h) = half_vector(wo, wi) else { return Vec3::ZERO };
    let spec = specular(s, h.cos_h);
    let (kd, ks) = (kd.max(Vec3::ZERO).as_dvec3(), ks.max(Vec3::ZERO).as_dvec3());
    let f = kd / PI + ks * spec;
    Vec3::new(to_f32_finite(f.x), to_f32_finite(f.y), to_f32_finite(f.z))
}

/// Mixture density P_d cos θi/π + (1−P_d) (s+1)/(2π) cos^s θh / (4 ωo·h); 0 below the horizon.
pub fn pdf(kd: Vec3, ks: Vec3, s: f32, wo: Vec3, wi: Vec3) -> f32 {
    let Some(pd) = diffuse_probability(kd, ks) else { return 0.0 };
    let Some(h) = half_vector(wo, wi) else { return 0.0 };
    let diffuse = wi.z as f64 / PI;
    let spec = if h.wo_h > 0.0 { half_vector_pdf(s, h.cos_h) / (4.0 * h.wo_h) } else { 0.0 };
    to_f32_finite(pd * diffuse + (1.0 - pd) * spec)
}

/// Draws from the diffuse / half-vector mixture described in the module comment.
pub fn sample(kd: Vec3, ks: Vec3, s: f32, wo: Vec3, u: Vec2, uc: f32) -> Option<BsdfSample> {
    let pd = diffuse_probability(kd, ks)?;
    sample_mixture(
        |wo, wi| pdf(kd, ks, s, wo, wi),
        |wo, wi| eval(kd, ks, s, wo, wi),
        wo,
        u,
        uc,
        pd,
        |u| {
            let cos_h = (u.x as f64).powf(1.0 / (exponent(s) + 1.0));
            let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
            spherical(cos_h, sin_h, 2.0 * PI * u.y as f64)
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blinn_phong_uses_the_eight_pi_normalisation_of_the_spec() {
        let (kd, ks, s) = (Vec3::new(0.2, 0.3, 0.1), Vec3::new(0.5, 0.4, 0.6), 37.0f32);
        let wo = Vec3::new(0.3, -0.2, 0.9).normalize();
        let wi = Vec3::new(-0.1, 0.4, 0.8).normalize();
        let h = (wo + wi).normalize();
        let expect = kd / std::f32::consts::PI + ks * (s + 2.0) / (8.0 * std::f32::consts::PI) * h.z.powf(s);
        let got = eval(kd, ks, s, wo, wi);
        assert!((got - expect).abs().max_element() < 1e-5 * expect.max_element(), "{got} vs {expect}");
    }

    #[test]
    fn half_vector_density_integrates_to_one_over_the_hemisphere() {
        for s in [0.0f32, 1.0, 20.0, 500.0] {
            // ∫ p(h) dω = 2π ∫₀¹ p(cos) dcos, midpoint rule in cos θh.
            let n = 20_000;
            let integral: f64 = (0..n).map(|k| half_vector_pdf(s, (k as f64 + 0.5) / n as f64)).sum::<f64>() * 2.0 * PI / n as f64;
            assert!((integral - 1.0).abs() < 1e-3, "s {s}: {integral}");
        }
    }
}
