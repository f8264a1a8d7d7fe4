use crate::brdf;
use crate::math::frame::Frame;
use crate::math::rng::{mix64, stream, uniform_in};
use crate::math::sampling::{Cmj, CmjPattern};
use crate::render::camera::CameraRays;
use crate::render::film::{per_pixel, with_ctx};
use crate::render::integrator::{Counts, Settings, Tracer};
use crate::render::surface::Surface;
use crate::types::accel::Accel;
use crate::types::{gather_rows, row_spec, Image, ImageRows, Material, Scene};
use glam::{Vec2, Vec3};
use relume_core::{inputs, node, outputs, params, NodeError, RunCtx, ShardSpec};
use std::ops::Range;

params! {
    /// Direct light only, what `PathTrace` with `max_depth` 2 estimates (emitters seen plus
    /// light arriving straight from the lights), at less cost and noise: each pixel takes
    /// `pixel_samples` camera rays jittered over the pixel (box filter, correlated
    /// multi-jittered) and each opaque hit `light_samples` shadow rays toward points chosen by
    /// the light sampler, stratified over all of the pixel's light samples together. Light
    /// sampling only (no BSDF sampling): unbiased, but noisier than `PathTrace` on sharp
    /// highlights of large lights. Hits on delta surfaces (dielectrics) and misses are left to
    /// the path tracer with `max_depth` 2. Each pixel's random numbers depend only on (seed,
    /// pixel), so the image has the same bytes on any thread count. Sharded over image rows,
    /// like `PathTrace`.
    pub struct DirectLight {
        /// camera rays per pixel, jittered over the pixel (antialiasing)
        pub pixel_samples: u32 = 16, range = 1..=(1 << 16), unit = "rays/pixel", test = 4;
        /// shadow rays toward the lights per camera hit
        pub light_samples: u32 = 4, range = 1..=1024, unit = "rays/hit";
        /// random seed
        pub seed: u64 = 0, range = 0..=u32::MAX;
    }
}

inputs!(pub DirectLightIn { scene: Scene, accel: Accel });
outputs!(pub DirectLightOut { image: Image });

/// Direct light arriving at an opaque front-facing hit and leaving toward `-d`, from the
/// `count` light samples `first..` of the pixel's set `lights`, their jitter drawn from the
/// camera sample's random `stream`.
#[allow(clippy::too_many_arguments)]
fn shade(
    t: &Tracer,
    surf: &Surface,
    m: &Material,
    d: Vec3,
    (first, count): (u32, u32),
    lights: &CmjPattern,
    stream: u64,
    counts: &mut Counts,
) -> Vec3 {
    let frame = Frame::from_normal(surf.ns);
    let wo = frame.to_local(-d);
    let eps = t.eps();
    let mut sum = Vec3::ZERO;
    for k in first..first + count {
        let jitter = Vec2::new(uniform_in(stream, 2 * k + 2), uniform_in(stream, 2 * k + 3));
        let Some(ls) = t.lights.sample_2d(t.scene, surf.p, lights.sample(k, jitter)) else { continue };
        let wi = frame.to_local(ls.wi);
        let f = brdf::eval(m, wo, wi) * wi.z.abs();
        if f == Vec3::ZERO || ls.li == Vec3::ZERO || ls.wi.dot(surf.ng) <= 0.0 || ls.pdf <= 0.0 {
            continue;
        }
        counts.rays += 1;
        let origin = surf.spawn(ls.wi, eps);
        let tmax = if ls.dist.is_finite() { ls.dist * (1.0 - 1e-4) - eps } else { f32::INFINITY };
        if !t.accel.occluded(origin, ls.wi, 0.0, tmax) {
            sum += f * ls.li / ls.pdf;
        }
    }
    sum / count as f32
}

/// Renders the rows `rows` of the direct-light image as a band with the counter [rays].
/// Each pixel depends only on (seed, pixel): any split of the rows gives the same bytes.
/// `cx` reports progress and cancels; `None` outside a graph.
pub fn render_rows(scene: &Scene, accel: &Accel, p: &DirectLight, rows: Range<usize>, cx: Option<&RunCtx>) -> Result<ImageRows, NodeError> {
    let w = scene.camera.width;
    let t = Tracer::new(
        scene,
        accel,
        Settings { max_depth: 2, min_depth: 1, rr_depth: 5, seed: p.seed ^ 0xD1EC_7000, fresnel_reflection: true },
    );
    let cam_rays = CameraRays::new(&scene.camera);
    let (spp, ls) = (p.pixel_samples.max(1), p.light_samples.max(1));
    let (camera_sets, light_sets) = (Cmj::new(spp), Cmj::new(spp * ls));
    let y0 = rows.start;
    let (img, rays) = with_ctx(cx, |cx| {
        per_pixel(cx, w, rows.len(), |x, y, counts| {
            let y = y + y0;
            let pixel = (y * w + x) as u64;
            let pattern = mix64(p.seed ^ pixel.wrapping_mul(0x9E37_79B9_7F4A_7C15)) as u32;
            let (camera, lights) = (camera_sets.pattern(pattern), light_sets.pattern(pattern ^ 0x5bd1_e995));
            let mut sum = Vec3::ZERO;
            for s in 0..spp {
                let id = pixel << 32 | s as u64;
                let random = stream(p.seed, id);
                let jitter = Vec2::new(uniform_in(random, 0), uniform_in(random, 1));
                let uv = camera.sample(s, jitter);
                let (o, d) = cam_rays.ray(x as f32 + uv.x, y as f32 + uv.y);
                counts.rays += 1;
                sum += match accel.intersect(o, d, 0.0, f32::INFINITY) {
                    Some(hit) => {
                        let surf = Surface::at(scene, &hit, o, d);
                        let obj = &scene.objects[surf.object as usize];
                        let front = d.dot(surf.ng) < 0.0;
                        if brdf::is_delta(&obj.material) {
                            t.radiance(o, d, id, counts)
                        } else if front {
                            obj.emission + shade(&t, &surf, &surf.material(scene), d, (s * ls, ls), &lights, random, counts)
                        } else {
                            Vec3::ZERO
                        }
                    }
                    None => t.radiance(o, d, id, counts),
                };
            }
            (sum / spp as f32).to_array()
        })
    })?;
    Ok(ImageRows::new(w, rows, vec![img], vec![rays]))
}

/// The whole direct-light image with the number of rays traced; the same bytes as the node's
/// sharded run.
pub fn render(scene: &Scene, accel: &Accel, p: &DirectLight, cx: Option<&RunCtx>) -> Result<(Image, u64), NodeError> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let band = render_rows(scene, accel, p, 0..h, cx)?;
    let (mut imgs, c) = gather_rows(w, h, 1, &[&band])?;
    Ok((imgs.pop().expect("one layer"), c[0]))
}

#[node(category = "reference", version = 2, sharded, metrics = ["rays", "rays_per_pixel"])]
impl DirectLight {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The bands of the chunks and the gathered image.
        let image = inputs[0].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        relume_core::MemoryEstimate { outputs: vec![image], working: inputs[0].and_then(|s| s.pixels()).map_or(0, |p| p * 12) }
    }

    fn shard(&self, i: &DirectLightIn) -> Result<ShardSpec, NodeError> {
        Ok(row_spec(i.scene.camera.width, i.scene.camera.height))
    }

    fn run_items(&self, i: &DirectLightIn, rows: Range<u64>, cx: &RunCtx) -> Result<ImageRows, NodeError> {
        render_rows(i.scene, i.accel, self, rows.start as usize..rows.end as usize, Some(cx))
    }

    fn gather(&self, i: &DirectLightIn, parts: &[&ImageRows], cx: &RunCtx) -> Result<DirectLightOut, NodeError> {
        let cam = &i.scene.camera;
        let (mut imgs, c) = gather_rows(cam.width, cam.height, 1, parts)?;
        let img = imgs.pop().expect("one layer");
        let rays = c[0];
        let bad = img.as_floats().iter().filter(|v| !v.is_finite()).count();
        if bad > 0 {
            cx.note(format!("{bad} pixel channels are NaN or infinite"));
        }
        cx.metric("rays", rays as f64);
        cx.metric("rays_per_pixel", rays as f64 / (img.width * img.height) as f64);
        Ok(DirectLightOut { image: img })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::path_trace::{self, PathTrace};
    use crate::scene::builder::SceneBuilder;
    use crate::testing::{cancels_midway, i, run_on, test_scene};
    use crate::types::accel::BuildQuality;
    use crate::types::{Environment, Light};
    use relume_core::Value;

    /// Two spheres over a floor under a small square area light facing down.
    fn area_lit() -> Scene {
        let grey = Material::Lambert { albedo: Vec3::splat(0.6) };
        let black = Material::Lambert { albedo: Vec3::ZERO };
        SceneBuilder::new(Vec3::new(0.0, 0.5, 3.5), Vec3::new(0.0, -0.3, 0.0), 45.0, 16, 16)
            .sphere("a", Vec3::new(-0.5, -0.4, 0.0), 0.5, grey, Vec3::ZERO, false)
            .sphere("b", Vec3::new(0.6, -0.6, 0.4), 0.35, grey, Vec3::ZERO, false)
            .quad("floor", Vec3::new(-2.0, -1.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), grey, Vec3::ZERO)
            .quad("light", Vec3::new(-0.4, 1.2, 0.4), Vec3::new(0.0, 0.0, -0.8), Vec3::new(0.8, 0.0, 0.0), black, Vec3::splat(8.0))
            .build()
    }

    fn params(pixel_samples: u32, light_samples: u32, seed: u64) -> DirectLight {
        DirectLight { pixel_samples, light_samples, seed }
    }

    #[test]
    fn it_agrees_with_the_path_tracer_at_max_depth_two() {
        let scene = area_lit();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let (img, rays) = render(&scene, &accel, &params(64, 4, 1), None).unwrap();
        let pt = PathTrace { spp: 1024, max_depth: 2, min_depth: 1, rr_depth: 5, seed: 3, fresnel_reflection: true };
        let (mean, var, _, _) = path_trace::render(&scene, &accel, &pt, None).unwrap();
        assert!(rays >= 16 * 16 * 64, "{rays}");
        let (a, b) = (img.as_floats(), mean.as_floats());
        let (sa, sb) = (a.iter().map(|&x| x as f64).sum::<f64>(), b.iter().map(|&x| x as f64).sum::<f64>());
        assert!(sb > 0.0 && ((sa - sb) / sb).abs() < 0.01, "image sums {sa} vs {sb}");
        // Per pixel channel: within 4 σ of the path tracer's mean (its own variance of the mean,
        // doubled for this image's noise) or 2 % of it.
        let pass =
            a.iter().zip(b).zip(var.as_floats()).filter(|((x, y), v)| (*x - *y).abs() <= 4.0 * (2.0 * *v).sqrt() + 0.02 * *y).count();
        assert!(pass as f64 >= 0.995 * a.len() as f64, "{pass} of {}", a.len());
    }

    #[test]
    fn stratified_light_samples_are_less_noisy_than_independent_path_samples() {
        // The same number of light samples per pixel (64): the spread between two seeds is
        // smaller than the path tracer's.
        let scene = area_lit();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let spread =
            |imgs: [Image; 2]| imgs[0].as_floats().iter().zip(imgs[1].as_floats()).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>();
        let dl = spread([1, 2].map(|s| render(&scene, &accel, &params(16, 4, s), None).unwrap().0));
        let pt = spread([1, 2].map(|s| {
            path_trace::render(
                &scene,
                &accel,
                &PathTrace { spp: 64, max_depth: 2, min_depth: 1, rr_depth: 5, seed: s, fresnel_reflection: true },
                None,
            )
            .unwrap()
            .0
        }));
        assert!(dl < 0.5 * pt, "{dl} vs {pt}");
    }

    #[test]
    fn the_image_is_the_same_bytes_on_one_thread() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let a = render(&scene, &accel, &params(5, 3, 9), None).unwrap();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let b = pool.install(|| render(&scene, &accel, &params(5, 3, 9), None).unwrap());
        assert_eq!(a.0, b.0);
        assert_eq!(a.1, b.1);
    }

    #[test]
    fn a_light_on_a_surface_and_a_black_environment_stay_finite() {
        // docs/QUALITY.md §2 (transport, lighting): a point light exactly on the floor, and a zero-
        // radiance environment as the only other light.
        let grey = Material::Lambert { albedo: Vec3::splat(0.5) };
        let scene = SceneBuilder::new(Vec3::new(0.0, 1.0, 3.0), Vec3::new(0.0, -1.0, 0.0), 40.0, 12, 12)
            .quad("floor", Vec3::new(-2.0, -1.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), grey, Vec3::ZERO)
            .light(Light::Point { position: Vec3::new(0.0, -1.0, 0.0), intensity: Vec3::splat(5.0) })
            .environment(Environment::Constant(Vec3::ZERO))
            .build();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let (img, _) = render(&scene, &accel, &params(4, 2, 1), None).unwrap();
        assert!(img.as_floats().iter().all(|x| x.is_finite() && *x >= 0.0));
        // Furnace-style bound: no pixel brighter than the light could make a point at distance
        // ≥ one pixel's footprint; and the floor far from the light gets I cos / d² at most.
        let far = scene.camera.width / 2; // the top row sees the floor farthest from the light
        assert!(img.pixels[far].iter().all(|&c| c < 5.0 * 0.5 / std::f32::consts::PI), "{:?}", img.pixels[far]);
    }

    #[test]
    fn the_node_is_registered_and_reports_its_rays() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let out =
            run_on::<DirectLight>(&[("pixel_samples", i(4)), ("light_samples", i(2))], vec![Value::new(scene), Value::new(accel)]).unwrap();
        let img = out[0].get::<Image>().unwrap();
        assert!(img.as_floats().iter().any(|x| *x > 0.0));
        let reg = crate::registry();
        assert_eq!(reg.node("DirectLight").expect("registered").category(), "reference");
    }

    #[test]
    fn the_node_stops_midway_when_cancelled() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        cancels_midway::<DirectLight>(&[("pixel_samples", i(16))], vec![Value::new(scene), Value::new(accel)]);
    }
}
