//! The choice of BRDF family a node samples, as a parameter.

use relume_core::ParamEnum;

/// The BRDF family a sampling node spans (`BrdfTensor`, `BrdfSpaceSample`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum BrdfModel {
    /// normalised Blinn-Phong over the exponent s
    BlinnPhong,
    /// Cook-Torrance over Beckmann roughness m × Schlick F0
    CookTorrance,
}
