//! Materials as the scene describes them; `crate::brdf` evaluates and samples them.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A homogeneous participating medium (per unit length), isotropic phase function.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Medium {
    pub sigma_a: Vec3,
    pub sigma_s: Vec3,
}

/// Surface scattering models. All opaque models are one-sided: black seen from the back.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Material {
    /// ρ = albedo / π.
    Lambert { albedo: Vec3 },
    /// Normalised Blinn-Phong: ρ = kd/π + ks (s+2)/(8π) cos^s δ, δ the half-vector angle
    /// (docs/PIPELINES.md: 8π, not the thesis' 2π). Energy-conserving for kd + ks ≤ 1.
    BlinnPhong { kd: Vec3, ks: Vec3, exponent: f32 },
    /// Cook-Torrance ([S] 2-12): kd/π + ks · D F G / (4 cos θi cos θo) with Beckmann D of
    /// roughness m, Schlick F with normal-incidence reflectance f0, Torrance-Sparrow G.
    CookTorrance { kd: Vec3, ks: Vec3, roughness: f32, f0: f32 },
    /// Smooth dielectric interface of relative index `ior` (inside / outside; below 1 for an
    /// object nested in a denser one), optionally filled with a homogeneous medium.
    Dielectric { ior: f32, medium: Option<Medium> },
}
