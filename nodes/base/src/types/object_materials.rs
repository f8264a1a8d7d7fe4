//! `ObjectMaterials`: the dynamic objects' materials and their coefficients on a BRDF basis,
//! what both relighting pipelines weigh their stored images with.

use super::texture::MaterialMaps;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// One dynamic object's material, Kd/π + Ks × (its `specular` lobe: Blinn-Phong
/// (s+2)/(8π) cos^s δ by default, or Cook-Torrance), and its coefficients on a BRDF basis per
/// colour channel: basis 0 (diffuse) Kd, basis k Ks · c_k (c(s) for Blinn-Phong).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectMaterial {
    pub name: String,
    pub kd: [f32; 3],
    pub ks: [f32; 3],
    /// The Blinn-Phong exponent (unused when `specular` is Cook-Torrance).
    pub s: f32,
    /// Empty until projected (`MaterialProject`); then one RGB triple per basis.
    pub coefficients: Vec<[f64; 3]>,
    /// Texture maps multiplying Kd, Ks and s over the object's UVs (the spatially varying
    /// extension, [S] 4.2; `PaintMaterial` edits them). None by default.
    #[serde(default)]
    pub maps: MaterialMaps,
    /// The specular model; absent in materials written before Cook-Torrance (Blinn-Phong).
    #[serde(default)]
    pub specular: Specular,
}

/// The specular lobe of an [`ObjectMaterial`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub enum Specular {
    /// Normalised Blinn-Phong with the material's exponent s.
    #[default]
    BlinnPhong,
    /// Cook-Torrance (`brdf/cook_torrance.rs`): Beckmann roughness m, Schlick F0.
    CookTorrance { m: f32, f0: f32 },
}

/// The materials of a scene's dynamic objects, in `Scene::dynamic_groups` order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ObjectMaterials(pub Vec<ObjectMaterial>);

/// Disk encoding: serde through postcard (a short list).
impl PortValue for ObjectMaterials {
    const NAME: &'static str = "ObjectMaterials";
    const COLOR: [u8; 3] = [230, 180, 250];
    const DOC: &'static str = "the dynamic objects' materials and their coefficients on a BRDF basis";
    fn byte_size(&self) -> usize {
        self.0.iter().map(|m| m.name.len() + 40 + m.coefficients.len() * 24 + m.maps.byte_size()).sum::<usize>() + 8
    }
    relume_core::serde_codec!();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn materials_round_trip() {
        let m = ObjectMaterials(vec![ObjectMaterial {
            name: "a".into(),
            kd: [0.1; 3],
            ks: [0.2; 3],
            s: 3.0,
            coefficients: vec![[1.0, -0.5, 0.0]],
            maps: Default::default(),
            specular: Specular::CookTorrance { m: 0.3, f0: 0.5 },
        }]);
        assert_eq!(ObjectMaterials::decode(&m.encode()).unwrap(), m);
    }
}
