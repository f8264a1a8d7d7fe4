//! Material texture maps: RGB images looked up at a surface's UV, multiplying the material's
//! own parameter (Kd, Ks or the exponent), so the scene's value is a tint and a white texel
//! leaves it unchanged.

use super::Material;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// An RGB texture, row 0 at the top (as image files store it): UV (0, 0) is the bottom-left
/// corner (OBJ's convention), looked up bilinearly and repeated outside [0, 1]².
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    /// Row-major, `width × height` texels, linear RGB.
    #[serde(with = "relume_core::codec::pod_vec")]
    pub texels: Vec<Vec3>,
}

impl Texture {
    /// A texture from an image's pixels; `None` when empty or the sizes disagree.
    pub fn new(width: usize, height: usize, texels: Vec<Vec3>) -> Option<Texture> {
        (width > 0 && height > 0 && texels.len() == width * height && width <= u32::MAX as usize && height <= u32::MAX as usize)
            .then_some(Texture { width: width as u32, height: height as u32, texels })
    }

    fn texel(&self, x: i64, y: i64) -> Vec3 {
        let (w, h) = (self.width as i64, self.height as i64);
        self.texels[(y.rem_euclid(h) * w + x.rem_euclid(w)) as usize]
    }

    /// The bilinear value at `uv` (texel centres at half-integers; repeated).
    pub fn lookup(&self, uv: Vec2) -> Vec3 {
        if !uv.is_finite() {
            return self.texels[0];
        }
        let x = uv.x as f64 * self.width as f64 - 0.5;
        let y = (1.0 - uv.y as f64) * self.height as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = self.texel(x0, y0).lerp(self.texel(x0 + 1, y0), fx);
        let bottom = self.texel(x0, y0 + 1).lerp(self.texel(x0 + 1, y0 + 1), fx);
        top.lerp(bottom, fy)
    }

    /// The mean of the texels over the UV rectangle `[u0, u1) × [v0, v1)` (texels whose centre
    /// lies in it; the nearest texel when none does): a texture down-sampled to a grid.
    pub fn mean_over(&self, u: (f32, f32), v: (f32, f32)) -> Vec3 {
        let (w, h) = (self.width as f64, self.height as f64);
        let xs = ((u.0 as f64 * w - 0.5).ceil().max(0.0) as i64)..((u.1 as f64 * w - 0.5).ceil().min(w) as i64);
        let ys = (((1.0 - v.1 as f64) * h - 0.5).ceil().max(0.0) as i64)..(((1.0 - v.0 as f64) * h - 0.5).ceil().min(h) as i64);
        let n = xs.clone().count() * ys.clone().count();
        if n == 0 {
            // The texel under the cell's centre.
            let (cu, cv) = ((u.0 + u.1) as f64 / 2.0, (v.0 + v.1) as f64 / 2.0);
            return self.texel((cu * w).floor() as i64, ((1.0 - cv) * h).floor() as i64);
        }
        let sum = ys.flat_map(|y| xs.clone().map(move |x| (x, y))).fold(glam::DVec3::ZERO, |s, (x, y)| s + self.texel(x, y).as_dvec3());
        (sum / n as f64).as_vec3()
    }
}

/// The texture maps of an object's material (none by default).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaterialMaps {
    /// Multiplies Kd (a Lambert material's albedo).
    pub kd: Option<Texture>,
    /// Multiplies Ks.
    pub ks: Option<Texture>,
    /// Its first channel multiplies the exponent (Blinn-Phong).
    pub exponent: Option<Texture>,
}

impl MaterialMaps {
    pub fn is_empty(&self) -> bool {
        self.kd.is_none() && self.ks.is_none() && self.exponent.is_none()
    }

    /// `m` with its parameters multiplied by the maps at `uv` (exponents kept ≥ 1).
    pub fn apply(&self, m: Material, uv: Vec2) -> Material {
        let scale = |t: &Option<Texture>| t.as_ref().map_or(Vec3::ONE, |t| t.lookup(uv));
        match m {
            Material::Lambert { albedo } => Material::Lambert { albedo: albedo * scale(&self.kd) },
            Material::BlinnPhong { kd, ks, exponent } => Material::BlinnPhong {
                kd: kd * scale(&self.kd),
                ks: ks * scale(&self.ks),
                exponent: (exponent * scale(&self.exponent).x).max(1.0),
            },
            Material::CookTorrance { kd, ks, roughness, f0 } => {
                Material::CookTorrance { kd: kd * scale(&self.kd), ks: ks * scale(&self.ks), roughness, f0 }
            }
            other => other,
        }
    }

    /// Bytes held by the textures.
    pub fn byte_size(&self) -> usize {
        [&self.kd, &self.ks, &self.exponent].iter().map(|t| t.as_ref().map_or(0, |t| t.texels.len() * 12)).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tex(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> Texture {
        Texture::new(w, h, (0..w * h).map(|i| Vec3::splat(f(i % w, i / w))).collect()).unwrap()
    }

    #[test]
    fn lookups_hit_texel_centres_flip_v_and_repeat() {
        // 4 × 2: row 0 (top) is 0..3, row 1 (bottom) 10..13.
        let t = tex(4, 2, |x, y| (x + 10 * y) as f32);
        assert_eq!(t.lookup(Vec2::new(0.125, 0.25)).x, 10.0, "bottom-left texel centre");
        assert_eq!(t.lookup(Vec2::new(0.875, 0.75)).x, 3.0, "top-right texel centre");
        assert_eq!(t.lookup(Vec2::new(0.25, 0.75)).x, 0.5, "between two texels");
        assert_eq!(t.lookup(Vec2::new(1.125, 1.25)), t.lookup(Vec2::new(0.125, 0.25)), "repeats");
        assert_eq!(t.lookup(Vec2::new(-0.875, 0.25)), t.lookup(Vec2::new(0.125, 0.25)));
        assert!(t.lookup(Vec2::new(f32::NAN, 0.0)).is_finite());
        assert!(Texture::new(2, 2, vec![Vec3::ONE; 3]).is_none() && Texture::new(0, 0, vec![]).is_none());
    }

    #[test]
    fn a_non_power_of_two_texture_averages_over_a_grid_cell() {
        // 6 × 3, value x: the left half of the UV square holds texels x = 0, 1, 2.
        let t = tex(6, 3, |x, _| x as f32);
        assert_eq!(t.mean_over((0.0, 0.5), (0.0, 1.0)).x, 1.0);
        assert_eq!(t.mean_over((0.5, 1.0), (0.0, 1.0)).x, 4.0);
        // A cell smaller than a texel takes the texel under its centre.
        assert_eq!(t.mean_over((0.0, 0.01), (0.0, 0.01)).x, 0.0);
        // The cells of a grid together average to the whole texture.
        let n = 5;
        let mut sum = 0.0;
        for i in 0..n {
            sum += t.mean_over((i as f32 / n as f32, (i + 1) as f32 / n as f32), (0.0, 1.0)).x;
        }
        assert!((sum / n as f32 - 2.5).abs() < 0.25, "{}", sum / n as f32);
    }

    #[test]
    fn maps_multiply_the_parameters_and_white_changes_nothing() {
        let m = Material::BlinnPhong { kd: Vec3::splat(0.5), ks: Vec3::splat(0.4), exponent: 40.0 };
        assert_eq!(MaterialMaps::default().apply(m, Vec2::ZERO), m);
        let white = MaterialMaps { kd: Some(tex(2, 2, |_, _| 1.0)), ks: None, exponent: Some(tex(1, 1, |_, _| 1.0)) };
        assert_eq!(white.apply(m, Vec2::new(0.3, 0.6)), m);
        let half = MaterialMaps { kd: Some(tex(1, 1, |_, _| 0.5)), ks: Some(tex(1, 1, |_, _| 0.0)), exponent: Some(tex(1, 1, |_, _| 0.0)) };
        assert_eq!(half.apply(m, Vec2::ZERO), Material::BlinnPhong { kd: Vec3::splat(0.25), ks: Vec3::ZERO, exponent: 1.0 });
        let lambert = Material::Lambert { albedo: Vec3::ONE };
        assert_eq!(half.apply(lambert, Vec2::ZERO), Material::Lambert { albedo: Vec3::splat(0.5) });
    }
}
