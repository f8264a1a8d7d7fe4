//! What the BSDF models share: the sample they return and the pieces of their sampling
//! (half vectors, mixture of a diffuse and a specular lobe, spherical directions).

use crate::math::sampling::cosine_hemisphere;
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
/// `p_diffuse`, else the mirror of ωo about `sample_h(u)`), then evaluates the mixture density
/// and f through the model's own `pdf` / `eval`, so that they agree exactly.
pub(crate) fn sample_mixture(
    pdf: impl FnOnce(Vec3, Vec3) -> f32,
    eval: impl FnOnce(Vec3, Vec3) -> Vec3,
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
    let p = pdf(wo, wi);
    let f = eval(wo, wi);
    if !(p > 0.0 && p.is_finite() && f.is_finite()) || f.min_element() < 0.0 {
        return None;
    }
    Some(BsdfSample { wi, f, pdf: p, delta: false })
}
