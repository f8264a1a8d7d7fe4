//! ShadeDirect node.

use crate::brdf::diffuse_albedo;
use crate::geometry::accel::Accel;
use crate::math::rng::uniform;
use crate::reference::lights::{delta_sample, LightSampler};
use crate::types::{PointRadiance, Scene, SurfacePoints};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};
use std::f32::consts::FRAC_1_PI;
use std::sync::atomic::{AtomicU64, Ordering};

node_doc! {
    /// Direct lighting of every surface point, as outgoing diffuse radiance B = kd/π · E:
    /// point, spot and directional lights exactly (one shadow ray each), area lights and the
    /// environment with `samples` light samples per point (seeded). Points that no light can
    /// reach (facing away from every delta light, and no area light or environment) and
    /// points with kd = 0 get B = 0 without tracing; the report counts them.
    pub struct ShadeDirect;
}

pub struct ShadeDirectParams {
    pub samples: u32,
    pub seed: u64,
}

impl Params for ShadeDirectParams {
    fn schema() -> Schema {
        Schema::new()
            .int("samples", 16, 1, 4096)
            .unit("samples/point")
            .help("light samples per point for area lights and the environment")
            .int("seed", 0, 0, i64::from(u32::MAX))
            .help("random seed")
    }
    fn from_values(v: &ParamValues) -> Self {
        ShadeDirectParams { samples: v.int("samples") as u32, seed: v.int("seed") as u64 }
    }
}

/// Outgoing diffuse radiance of each point; also returns how many points were skipped.
pub fn shade_direct(scene: &Scene, accel: &Accel, pts: &SurfacePoints, p: &ShadeDirectParams) -> (Vec<Vec3>, u64) {
    let lights = LightSampler::new(scene);
    let eps = 1e-6 * scene.extent();
    let skipped = AtomicU64::new(0);
    let out = (0..pts.len())
        .into_par_iter()
        .map(|i| {
            let kd = diffuse_albedo(&pts.material[i]);
            let (x, n) = (pts.position[i], pts.normal[i]);
            let reachable =
                lights.has_extended() || scene.lights.iter().any(|l| delta_sample(l, x).is_some_and(|(wi, _, _)| wi.dot(n) > 0.0));
            if kd == Vec3::ZERO || !reachable {
                skipped.fetch_add(1, Ordering::Relaxed);
                return Vec3::ZERO;
            }
            let origin = x + n * eps * (1.0 + x.abs().max_element());
            let visible = |wi: Vec3, dist: f32| {
                let tmax = if dist.is_finite() { dist * (1.0 - 1e-4) } else { f32::INFINITY };
                !accel.occluded(origin, wi, 0.0, tmax)
            };
            let mut e = Vec3::ZERO;
            for l in &scene.lights {
                if let Some((wi, dist, li)) = delta_sample(l, x) {
                    let cos = wi.dot(n);
                    if cos > 0.0 && visible(wi, dist) {
                        e += li * cos;
                    }
                }
            }
            if lights.has_extended() {
                let mut acc = Vec3::ZERO;
                for s in 0..p.samples {
                    let id = (i as u64) << 20 | s as u64;
                    let u = |d| uniform(p.seed, id, d);
                    if let Some(ls) = lights.sample_extended(scene, x, u(0), Vec2::new(u(1), u(2))) {
                        let cos = ls.wi.dot(n);
                        if cos > 0.0 && ls.pdf > 0.0 && visible(ls.wi, ls.dist) {
                            acc += ls.li * (cos / ls.pdf);
                        }
                    }
                }
                e += acc / p.samples as f32;
            }
            kd * FRAC_1_PI * e
        })
        .collect();
    (out, skipped.into_inner())
}

impl Node for ShadeDirect {
    const KIND: &'static str = "ShadeDirect";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "pbgi";
    const CACHING: Caching = Caching::Memory;
    type Params = ShadeDirectParams;

    fn ports() -> Ports {
        Ports::new().input::<Scene>("scene").input::<Accel>("accel").input::<SurfacePoints>("points").output::<PointRadiance>("radiance")
    }

    fn run(&self, p: &ShadeDirectParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        let (scene, accel, pts) = (io.input::<Scene>("scene")?, io.input::<Accel>("accel")?, io.input::<SurfacePoints>("points")?);
        cx.check()?;
        let (b, skipped) = shade_direct(scene, accel, pts, p);
        cx.metric("points", pts.len() as f64);
        cx.metric("points_skipped", skipped as f64);
        if skipped > 0 {
            cx.note(format!("{skipped} points no light can reach or with no diffuse reflectance were set to 0 without tracing"));
        }
        io.set("radiance", PointRadiance(b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::accel::BuildQuality;
    use crate::scene::builder::SceneBuilder;
    use crate::types::{Light, Material};

    fn plane_points(scene: &Scene) -> SurfacePoints {
        crate::geometry::sample_surface::sample_surface(
            scene,
            &crate::geometry::sample_surface::SampleSurfaceParams {
                method: crate::geometry::sample_surface::Method::AreaCdf,
                count: 400,
                seed: 1,
                emitters: true,
            },
        )
        .unwrap()
    }

    #[test]
    fn a_point_light_gives_the_analytic_radiance_and_shadows_block_it() {
        let lam = Material::Lambert { albedo: Vec3::splat(0.5) };
        let scene = SceneBuilder::new(Vec3::new(0.0, 3.0, 0.1), Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), lam, Vec3::ZERO)
            .light(Light::Point { position: Vec3::new(0.0, 1.0, 0.0), intensity: Vec3::splat(2.0) })
            .build();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let pts = plane_points(&scene);
        let (b, skipped) = shade_direct(&scene, &accel, &pts, &ShadeDirectParams { samples: 4, seed: 0 });
        assert_eq!(skipped, 0);
        for (x, bi) in pts.position.iter().zip(&b) {
            let to = Vec3::new(0.0, 1.0, 0.0) - *x;
            let exact = 0.5 * FRAC_1_PI * 2.0 * (to.y / to.length()) / to.length_squared();
            assert!((bi.x - exact).abs() < 1e-4 * exact.max(1.0), "{} vs {exact}", bi.x);
        }
    }

    #[test]
    fn points_facing_away_from_the_only_light_are_skipped_without_tracing() {
        let lam = Material::Lambert { albedo: Vec3::splat(0.5) };
        let scene = SceneBuilder::new(Vec3::new(0.0, 3.0, 0.1), Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), lam, Vec3::ZERO)
            .light(Light::Point { position: Vec3::new(0.0, -1.0, 0.0), intensity: Vec3::splat(2.0) })
            .build();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let pts = plane_points(&scene);
        let (b, skipped) = shade_direct(&scene, &accel, &pts, &ShadeDirectParams { samples: 4, seed: 0 });
        assert_eq!(skipped as usize, pts.len());
        assert!(b.iter().all(|x| *x == Vec3::ZERO));
    }

    #[test]
    fn an_area_light_estimate_converges_to_the_same_value_for_two_seeds() {
        let lam = Material::Lambert { albedo: Vec3::splat(0.8) };
        let scene = SceneBuilder::new(Vec3::new(0.0, 3.0, 0.1), Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), lam, Vec3::ZERO)
            .quad(
                "lamp",
                Vec3::new(-0.2, 1.0, -0.2),
                Vec3::new(0.4, 0.0, 0.0),
                Vec3::new(0.0, 0.0, 0.4),
                Material::Lambert { albedo: Vec3::ZERO },
                Vec3::splat(10.0),
            )
            .build();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let pts = plane_points(&scene);
        let mean =
            |seed| shade_direct(&scene, &accel, &pts, &ShadeDirectParams { samples: 256, seed }).0.iter().map(|v| v.x as f64).sum::<f64>();
        let (a, b) = (mean(1), mean(2));
        assert!(a > 0.0 && ((a - b) / a).abs() < 0.01, "{a} {b}");
    }
}
