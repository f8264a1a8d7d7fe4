//! Cook-Torrance microfacet reflection with a diffuse base.
//!
//! Formula followed: [S] eq. 2-12, f = kd + ks F(β)/π · D G / (cos θi cos θo), which is Cook &
//! Torrance 1981 with D_CT(α) = exp(−tan²α/m²) / (m² cos⁴α). Written with the normalised
//! Beckmann density D = D_CT / π (∫ D cos θh dω = 1) this is ks F D G / (cos θi cos θo); we use
//! the microfacet form with the reflection Jacobian 1/(4 ωo·h) of Walter et al. 2007,
//!
//!   f = kd/π + ks · D(h) F(ωi·h) G / (4 cos θi cos θo),
//!
//! (as `Material::CookTorrance` documents), i.e. the thesis' specular term divided by 4 — the
//! same correction as Blinn-Phong's 8π — so that a white surface never reflects more than it
//! receives; the diffuse term is kd/π as for Lambert.
//!
//! - D(h) = exp(−tan²θh / m²) / (π m² cos⁴θh) (Beckmann, roughness m = RMS slope);
//! - F = f0 + (1 − f0)(1 − ωi·h)⁵ (Schlick, angle β between the light and the half vector, as in
//!   Cook & Torrance; [S] glosses β as the half-vector/normal angle, which would make F
//!   independent of the incidence angle);
//! - G = min(1, 2 cos θh cos θo / (ωo·h), 2 cos θh cos θi / (ωo·h)) (Torrance-Sparrow V-cavity).
//!
//! Sampling: with probability P_d = Y(kd)/(Y(kd)+Y(ks)) a cosine-weighted ωi, else h from
//! D(h) cos θh (tan²θh = −m² ln(1−u), φ = 2πu') mirrored to ωi = 2(ωo·h)h − ωo, density
//! D(h) cos θh / (4 ωo·h); [`pdf`] is the mixture. Computed in f64 with tan²θh taken from the
//! half vector's components, so m from 10⁻³ to 1 and grazing angles stay finite; m is clamped
//! to ≥ 10⁻⁴ and values saturate at f32::MAX instead of overflowing.

use super::fresnel::schlick;
use super::lobe::{diffuse_probability, half_vector, sample_mixture, spherical, to_f32_finite, BsdfSample, Half};
use glam::{Vec2, Vec3};
use std::f64::consts::PI;

/// Smallest roughness used (smaller or NaN values are raised to it).
pub const MIN_ROUGHNESS: f64 = 1e-4;

fn roughness(m: f32) -> f64 {
    if m > MIN_ROUGHNESS as f32 {
        m as f64
    } else {
        MIN_ROUGHNESS
    }
}

/// Beckmann D = exp(−tan²θh/m²) / (π m² cos⁴θh), written with 1/cos⁴ = (1 + tan²)².
pub fn beckmann_d(m: f32, tan2_h: f64) -> f64 {
    let m2 = roughness(m).powi(2);
    let e = (-tan2_h / m2).exp();
    if e == 0.0 {
        return 0.0;
    }
    let d = e * (1.0 + tan2_h).powi(2) / (PI * m2);
    if d.is_finite() {
        d
    } else {
        0.0
    }
}

/// The specular factor D F G / (4 cos θi cos θo), without ks, in f64 (0 below the horizon;
/// finite: see the module comment).
pub fn specular(m: f32, f0: f32, wo: Vec3, wi: Vec3) -> f64 {
    half_vector(wo, wi).map_or(0.0, |h| specular_at(&h, m, f0, wo.z as f64, wi.z as f64))
}

/// [`specular`] for the half vector `h` of directions at cos θo = `co`, cos θi = `ci`.
fn specular_at(h: &Half, m: f32, f0: f32, co: f64, ci: f64) -> f64 {
    let d = beckmann_d(m, h.tan2_h);
    if d > 0.0 && h.wo_h > 0.0 {
        let f = schlick((f0 as f64).clamp(0.0, 1.0), h.wo_h);
        let g = (2.0 * h.cos_h * co / h.wo_h).min(2.0 * h.cos_h * ci / h.wo_h).min(1.0);
        (d * f * g / (4.0 * ci * co)).min(f64::MAX)
    } else {
        0.0
    }
}

/// f = kd/π + ks D F G / (4 cos θi cos θo) for cos θo, cos θi > 0, else 0.
pub fn eval(kd: Vec3, ks: Vec3, m: f32, f0: f32, wo: Vec3, wi: Vec3) -> Vec3 {
    let Some(h) = half_vector(wo, wi) else { return Vec3::ZERO };
    let spec = specular_at(&h, m, f0, wo.z as f64, wi.z as f64);
    let (kd, ks) = (kd.max(Vec3::ZERO).as_dvec3(), ks.max(Vec3::ZERO).as_dvec3());
    let f = kd / PI + ks * spec;
    Vec3::new(to_f32_finite(f.x), to_f32_finite(f.y), to_f32_finite(f.z))
}

/// Mixture density P_d cos θi/π + (1−P_d) D(h) cos θh / (4 ωo·h); 0 below the horizon.
pub fn pdf(kd: Vec3, ks: Vec3, m: f32, wo: Vec3, wi: Vec3) -> f32 {
    let Some(pd) = diffuse_probability(kd, ks) else { return 0.0 };
    let Some(h) = half_vector(wo, wi) else { return 0.0 };
    let diffuse = wi.z as f64 / PI;
    let spec = if h.wo_h > 0.0 { beckmann_d(m, h.tan2_h) * h.cos_h / (4.0 * h.wo_h) } else { 0.0 };
    to_f32_finite(pd * diffuse + (1.0 - pd) * spec)
}

/// Draws from the diffuse / Beckmann mixture described in the module comment.
pub fn sample(kd: Vec3, ks: Vec3, m: f32, f0: f32, wo: Vec3, u: Vec2, uc: f32) -> Option<BsdfSample> {
    let pd = diffuse_probability(kd, ks)?;
    sample_mixture(
        |wo, wi| pdf(kd, ks, m, wo, wi),
        |wo, wi| eval(kd, ks, m, f0, wo, wi),
        wo,
        u,
        uc,
        pd,
        |u| {
            // P(tan²θh ≤ t) = 1 − exp(−t/m²) for the density D cos θh.
            let tan2 = -roughness(m).powi(2) * (-(u.x as f64)).ln_1p();
            let cos_h = 1.0 / (1.0 + tan2).sqrt();
            let sin_h = (tan2 / (1.0 + tan2)).sqrt();
            spherical(cos_h, sin_h, 2.0 * PI * u.y as f64)
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beckmann_distribution_is_normalised_over_projected_area() {
        for m in [0.001f32, 0.05, 0.3, 1.0] {
            // ∫ D cos θh dω = ∫₀^∞ D(t) 2π cos θ sin θ dθ; substitute t = tan²θ:
            // cos θ sin θ dθ = dt / (2 (1+t)²). Integrate in x = t/m² on [0, 60].
            let m2 = (m as f64).powi(2);
            let n = 60_000;
            let dx = 60.0 / n as f64;
            let integral: f64 = (0..n)
                .map(|k| {
                    let t = (k as f64 + 0.5) * dx * m2;
                    beckmann_d(m, t) * PI / (1.0 + t).powi(2) * m2 * dx
                })
                .sum();
            assert!((integral - 1.0).abs() < 1e-4, "m {m}: {integral}");
        }
    }

    #[test]
    fn cook_torrance_matches_beckmann_schlick_and_v_cavity_terms() {
        let (kd, ks, m, f0) = (Vec3::new(0.1, 0.2, 0.3), Vec3::new(0.6, 0.5, 0.4), 0.35f32, 0.2f32);
        // ωo at ~78°: the V-cavity masking is active (G < 1) and the test exercises it.
        let wo = Vec3::new(0.95, 0.1, 0.2).normalize();
        let wi = Vec3::new(-0.3, 0.2, 0.7).normalize();
        let h = (wo + wi).normalize();
        let tan2 = (1.0 - h.z * h.z) / (h.z * h.z);
        let d = (-tan2 / (m * m)).exp() / (std::f32::consts::PI * m * m * h.z.powi(4));
        let f = f0 + (1.0 - f0) * (1.0 - wi.dot(h)).powi(5);
        let g = (2.0 * h.z * wo.z / wo.dot(h)).min(2.0 * h.z * wi.z / wo.dot(h)).min(1.0);
        let expect = kd / std::f32::consts::PI + ks * d * f * g / (4.0 * wi.z * wo.z);
        let got = eval(kd, ks, m, f0, wo, wi);
        assert!((got - expect).abs().max_element() < 1e-4 * expect.max_element(), "{got} vs {expect}");
        assert!(g < 0.9, "G = {g}");
    }

    #[test]
    fn near_mirror_cook_torrance_keeps_its_peak_finite() {
        // m = 10⁻³ exactly at the mirror direction: D = 1/(π m²) ≈ 3·10⁵, f huge but finite.
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let wi = Vec3::new(-0.6, 0.0, 0.8);
        let f = eval(Vec3::ZERO, Vec3::ONE, 0.001, 1.0, wo, wi);
        let expect = 1.0 / (std::f64::consts::PI * 1e-6) / (4.0 * 0.64);
        assert!(f.is_finite() && ((f.x as f64) - expect).abs() < 1e-3 * expect, "{f} vs {expect}");
        // Two degrees off the mirror the lobe has vanished (D ~ e^-300) without producing NaN.
        let t = 0.6435f32 + 0.035;
        let wi2 = Vec3::new(-t.sin(), 0.0, t.cos());
        let f2 = eval(Vec3::ZERO, Vec3::ONE, 0.001, 1.0, wo, wi2);
        assert!(f2.is_finite() && f2.max_element() < 1e-30, "{f2}");
    }
}
