//! Lat-long environment maps: lookup, importance sampling (luminance × sin θ) and the
//! procedural sky baked into a map. Lookups are piecewise constant per texel, matching the
//! sampling density exactly.

use crate::math::sampling::Distribution2D;
use crate::types::EnvMap;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Direction of lat-long coordinates (u, v) ∈ [0, 1]²: (sin θ sin φ, cos θ, −sin θ cos φ),
/// θ = π v, φ = 2π u (SCENES.md, Mitsuba 3's convention).
pub fn uv_to_dir(uv: Vec2) -> Vec3 {
    let (theta, phi) = (PI * uv.y, 2.0 * PI * uv.x);
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    Vec3::new(st * sp, ct, -st * cp)
}

/// Inverse of `uv_to_dir`.
pub fn dir_to_uv(d: Vec3) -> Vec2 {
    let theta = d.y.clamp(-1.0, 1.0).acos();
    let mut phi = d.x.atan2(-d.z);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    Vec2::new(phi / (2.0 * PI), theta / PI)
}

fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

impl EnvMap {
    /// Builds the sampling distribution. Non-finite or negative texels are an error.
    pub fn new(width: usize, height: usize, texels: Vec<Vec3>) -> Result<EnvMap, String> {
        if width == 0 || height == 0 || texels.len() != width * height {
            return Err(format!("environment map of {width} × {height} has {} texels", texels.len()));
        }
        if let Some(i) = texels.iter().position(|t| !t.is_finite() || t.min_element() < 0.0) {
            return Err(format!(
                "environment map texel ({}, {}) is {:?}: radiance must be finite and ≥ 0",
                i % width,
                i / width,
                texels[i]
            ));
        }
        let weights: Vec<f32> =
            texels.iter().enumerate().map(|(i, t)| luminance(*t) * (PI * ((i / width) as f32 + 0.5) / height as f32).sin()).collect();
        let distribution = Distribution2D::new(&weights, width, height);
        Ok(EnvMap { width, height, texels, distribution })
    }

    fn texel(&self, uv: Vec2) -> Vec3 {
        let x = ((uv.x * self.width as f32) as usize).min(self.width - 1);
        let y = ((uv.y * self.height as f32) as usize).min(self.height - 1);
        self.texels[y * self.width + x]
    }

    /// Radiance arriving from direction `d` (pointing away from the scene).
    pub fn eval(&self, d: Vec3) -> Vec3 {
        self.texel(dir_to_uv(d))
    }

    /// Samples a direction: (direction, radiance, solid-angle density). `None` for an all-black map.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        if self.distribution.marginal.integral <= 0.0 {
            return None;
        }
        let (uv, pdf_uv) = self.distribution.sample(u);
        let sin_theta = (PI * uv.y).sin();
        if pdf_uv <= 0.0 || sin_theta <= 0.0 {
            return None;
        }
        Some((uv_to_dir(uv), self.texel(uv), pdf_uv / (2.0 * PI * PI * sin_theta)))
    }

    /// Solid-angle density of `sample` for direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        if self.distribution.marginal.integral <= 0.0 {
            return 0.0;
        }
        let uv = dir_to_uv(d);
        let sin_theta = (PI * uv.y).sin();
        if sin_theta <= 0.0 {
            return 0.0;
        }
        self.distribution.pdf(uv) / (2.0 * PI * PI * sin_theta)
    }
}

/// A procedural sky: a vertical gradient from `horizon` to `zenith`, a flat `ground` below the
/// horizon and a sun disk of angular radius `sun_radius_deg` and radiance `sun_radiance`
/// around `sun_direction`, baked into a `width` × `width/2` lat-long map.
pub struct Sky {
    pub zenith: Vec3,
    pub horizon: Vec3,
    pub ground: Vec3,
    pub sun_direction: Vec3,
    pub sun_radiance: Vec3,
    pub sun_radius_deg: f32,
    pub width: usize,
}

impl Sky {
    pub fn bake(&self) -> Result<EnvMap, String> {
        let (w, h) = (self.width, (self.width / 2).max(1));
        let sun = self.sun_direction.normalize_or_zero();
        let sun_radius = self.sun_radius_deg.to_radians();
        // A texel spans at most this angle from its centre (at the equator).
        let texel_reach = std::f32::consts::PI / h as f32 * 1.5;
        let texels = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let d = uv_to_dir(Vec2::new((x + 0.5) / w as f32, (y + 0.5) / h as f32));
                let base = if d.y < 0.0 { self.ground } else { self.horizon.lerp(self.zenith, d.y.sqrt()) };
                if sun == Vec3::ZERO || d.dot(sun).clamp(-1.0, 1.0).acos() > sun_radius + texel_reach {
                    return base;
                }
                // The sun may be smaller than a texel: weight it by the covered fraction of the
                // texel's solid angle (16 × 16 sub-samples, weighted by sin θ) so that its power
                // does not depend on the map's resolution.
                let (mut covered, mut total) = (0.0f32, 0.0f32);
                for k in 0..256 {
                    let uv = Vec2::new((x + ((k % 16) as f32 + 0.5) / 16.0) / w as f32, (y + ((k / 16) as f32 + 0.5) / 16.0) / h as f32);
                    let weight = (PI * uv.y).sin();
                    total += weight;
                    if uv_to_dir(uv).dot(sun) >= sun_radius.cos() {
                        covered += weight;
                    }
                }
                base + self.sun_radiance * (covered / total.max(f32::MIN_POSITIVE))
            })
            .collect();
        EnvMap::new(w, h, texels)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;

    #[test]
    fn lat_long_mapping_round_trips_and_follows_the_convention() {
        assert!((uv_to_dir(Vec2::new(0.0, 0.5)) - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        assert!((uv_to_dir(Vec2::new(0.25, 0.5)) - Vec3::new(1.0, 0.0, 0.0)).length() < 1e-6);
        assert!((uv_to_dir(Vec2::new(0.3, 0.0)) - Vec3::Y).length() < 1e-6, "v = 0 is the top row");
        for i in 0..1000 {
            let uv = Vec2::new(uniform(5, i, 0), 0.01 + 0.98 * uniform(5, i, 1));
            assert!((dir_to_uv(uv_to_dir(uv)) - uv).length() < 1e-4);
        }
    }

    #[test]
    fn sampling_density_matches_pdf_and_integrates_to_one() {
        let texels: Vec<Vec3> = (0..64 * 32).map(|i| Vec3::splat(if i == 700 { 1e4 } else { (i % 5) as f32 * 0.1 })).collect();
        let env = EnvMap::new(64, 32, texels).unwrap();
        // ∫ pdf dω over the sphere: texel centre density × texel solid angle.
        let mut integral = 0.0f64;
        for y in 0..32 {
            let (t0, t1) = (PI * y as f32 / 32.0, PI * (y + 1) as f32 / 32.0);
            let solid = 2.0 * PI / 64.0 * (t0.cos() - t1.cos());
            for x in 0..64 {
                let d = uv_to_dir(Vec2::new((x as f32 + 0.5) / 64.0, (y as f32 + 0.5) / 32.0));
                integral += (env.pdf(d) * solid) as f64;
            }
        }
        assert!((integral - 1.0).abs() < 0.01, "{integral}");
        for i in 0..2000 {
            let (d, l, pdf) = env.sample(Vec2::new(uniform(2, i, 0), uniform(2, i, 1))).unwrap();
            assert!((env.pdf(d) - pdf).abs() <= 1e-3 * pdf, "{} vs {pdf}", env.pdf(d));
            assert_eq!(env.eval(d), l);
        }
    }

    #[test]
    fn a_black_map_samples_nothing_and_bad_texels_are_refused() {
        let env = EnvMap::new(4, 2, vec![Vec3::ZERO; 8]).unwrap();
        assert!(env.sample(Vec2::splat(0.5)).is_none());
        assert_eq!(env.pdf(Vec3::Y), 0.0);
        assert!(EnvMap::new(2, 1, vec![Vec3::ONE, Vec3::splat(f32::NAN)]).unwrap_err().contains("(1, 0)"));
    }

    fn sky_like(s: &Sky) -> Sky {
        Sky {
            zenith: Vec3::ONE,
            horizon: Vec3::ONE,
            ground: Vec3::ONE,
            sun_direction: s.sun_direction,
            sun_radiance: s.sun_radiance,
            sun_radius_deg: s.sun_radius_deg,
            width: s.width,
        }
    }

    #[test]
    fn the_sky_has_its_sun_where_it_was_put() {
        let sky = Sky {
            zenith: Vec3::new(0.1, 0.2, 0.5),
            horizon: Vec3::ONE,
            ground: Vec3::splat(0.05),
            sun_direction: Vec3::new(0.0, 1.0, -1.0),
            sun_radiance: Vec3::splat(1000.0),
            sun_radius_deg: 3.0,
            width: 256,
        };
        let env = sky.bake().unwrap();
        assert!(env.eval(Vec3::new(0.0, 1.0, -1.0).normalize()).x > 999.0);
        assert_eq!(env.eval(-Vec3::Y), Vec3::splat(0.05));
        // The sun's power (radiance × solid angle) does not depend on the map's resolution,
        // even when the sun is smaller than a texel.
        let power = |width| {
            let m = Sky { width, ..sky_like(&sky) }.bake().unwrap();
            let (w, h) = (m.width, m.height);
            (0..w * h)
                .map(|i| {
                    let (t0, t1) = (PI * (i / w) as f32 / h as f32, PI * (i / w + 1) as f32 / h as f32);
                    (m.texels[i].x - 1.0).max(0.0) as f64 * (2.0 * PI / w as f32 * (t0.cos() - t1.cos())) as f64
                })
                .sum::<f64>()
        };
        let exact = 1000.0 * 2.0 * std::f64::consts::PI * (1.0 - 3f64.to_radians().cos());
        for width in [64, 256, 1024] {
            let p = power(width);
            assert!((p - exact).abs() < 0.03 * exact, "width {width}: {p} vs {exact}");
        }
    }
}
