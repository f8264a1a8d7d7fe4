use crate::render::camera::{camera_sample, CameraRays};
use crate::render::film::{with_ctx, Film};
use crate::render::integrator::{Settings, Tracer};
use crate::types::accel::Accel;
use crate::types::{gather_rows, row_spec, Image, ImageRows, Scene};
use relume_core::{inputs, node, outputs, params, NodeError, RunCtx, ShardSpec, Value};
use std::ops::Range;

params! {
    /// Reference path tracer (the ground truth every pipeline reports its error against):
    /// unbiased; next-event estimation with MIS (power heuristic) against BSDF sampling;
    /// importance-sampled environment maps; smooth dielectrics with homogeneous media;
    /// `max_depth` as in Mitsuba 3 (1: emitters only, 2: direct light, 3: one bounce, −1:
    /// unbounded with Russian roulette from `rr_depth`); `min_depth` leaves out the light of
    /// shorter paths (3: the indirect light alone); `fresnel_reflection: false` refracts every
    /// path at glass, leaving its reflection out; box pixel filter. Samples are taken
    /// in passes of doubling size (progress and cancellation between rows; after each pass the
    /// band so far goes to a watcher that asks, as the editor's viewer does); each pixel's
    /// random numbers depend only on (seed, pixel, sample), so the image has the same bytes on
    /// any thread count. Outputs the mean and the per-pixel variance of the mean. Sharded over
    /// image rows (chunks of about 4096 pixels): `relume shard`, `relume slurm` and
    /// `--processes` split it across processes and machines with the same bytes.
    pub struct PathTrace {
        /// samples per pixel
        pub spp: u32 = 16, range = 1..=(1 << 20), unit = "samples/pixel", test = 4;
        /// maximum path segments (Mitsuba's meaning); -1 = unbounded
        pub max_depth: i32 = -1, range = -1..=1024;
        /// fewest path segments counted: 1 = all light, 3 = indirect only (with max_depth 3,
        /// one bounce: what a point-based gather's indirect image estimates); the paths are
        /// the same at every value, so min_depth 3 is max_depth 3 minus max_depth 2 at one seed
        pub min_depth: u32 = 1, range = 1..=1024;
        /// depth at which Russian roulette starts
        pub rr_depth: u32 = 5, range = 1..=1024;
        /// random seed
        pub seed: u64 = 0, range = 0..=u32::MAX;
        /// reflect at smooth dielectrics by Fresnel; false: every path refracts (total internal
        /// reflection still reflects), the light model of the refraction pipeline, to measure
        /// what leaving the reflection out costs
        pub fresnel_reflection: bool = true;
    }
}

inputs!(pub PathTraceIn { scene: Scene, accel: Accel });
outputs!(pub PathTraceOut { image: Image, variance: Image });

/// Renders `p.spp` samples per pixel of the rows `rows`; returns them as a band with the
/// mean, the variance of the mean and the counters [rays, samples dropped as NaN or
/// infinite]. Each pixel depends only on (seed, pixel, sample): any split of the rows gives
/// the same bytes. `cx` reports progress and cancels; `None` outside a graph.
pub fn render_rows(scene: &Scene, accel: &Accel, p: &PathTrace, rows: Range<usize>, cx: Option<&RunCtx>) -> Result<ImageRows, NodeError> {
    let cam = &scene.camera;
    let w = cam.width;
    let mut film = Film::try_new(w, rows.len())?;
    if !scene.has_lights() {
        let (mean, var) = (Image::try_new(w, rows.len())?, Image::try_new(w, rows.len())?);
        return Ok(ImageRows::new(w, rows, vec![mean, var], vec![0, 0]));
    }
    let tracer = Tracer::new(
        scene,
        accel,
        Settings {
            max_depth: p.max_depth,
            min_depth: p.min_depth,
            rr_depth: p.rr_depth,
            seed: p.seed,
            fresnel_reflection: p.fresnel_reflection,
        },
    );
    let cam_rays = CameraRays::new(cam);
    let y0 = rows.start;
    with_ctx(cx, |cx| {
        let sample = |x, y, s, counts: &mut _| {
            let (o, d, id) = camera_sample(&cam_rays, p.seed, w, x, y + y0, s);
            tracer.radiance(o, d, id, counts)
        };
        // Each pass but the last, to a watcher that asks: the band as far as it got.
        let partial = |film: &Film| {
            if let Some((mean, var)) = cx.wants_partials().then(|| film.snapshot().ok()).flatten() {
                cx.partial(Value::new(ImageRows::new(w, rows.clone(), vec![mean, var], vec![film.rays(), film.nonfinite()])));
            }
        };
        film.add_passes(cx, p.spp, sample, partial)
    })?;
    let counters = vec![film.rays(), film.nonfinite()];
    let (mean, var) = film.finish();
    Ok(ImageRows::new(w, rows, vec![mean, var], counters))
}

/// The whole image: (mean, variance of the mean, rays, samples dropped as NaN or infinite);
/// the same bytes as the node's sharded run.
pub fn render(scene: &Scene, accel: &Accel, p: &PathTrace, cx: Option<&RunCtx>) -> Result<(Image, Image, u64, u64), NodeError> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let band = render_rows(scene, accel, p, 0..h, cx)?;
    let (mut imgs, c) = gather_rows(w, h, 2, &[&band])?;
    let var = imgs.pop().expect("two layers");
    Ok((imgs.pop().expect("two layers"), var, c[0], c[1]))
}

#[node(category = "reference", version = 2, sharded, metrics = ["spp", "rays", "nonfinite_samples"])]
impl PathTrace {
    fn work(&self, inputs: &[Option<relume_core::PortSize>]) -> Option<f64> {
        super::samples_traced(inputs[0], self.spp)
    }

    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The film of a band (a sum and a sum of squares, f64 RGB, per pixel), the bands of
        // the chunks (mean and variance) and the gathered images.
        let image = inputs[0].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        relume_core::MemoryEstimate { outputs: vec![image, image], working: inputs[0].and_then(|s| s.pixels()).map_or(0, |p| p * 72) }
    }

    fn shard(&self, i: &PathTraceIn) -> Result<ShardSpec, NodeError> {
        Ok(row_spec(i.scene.camera.width, i.scene.camera.height))
    }

    fn run_items(&self, i: &PathTraceIn, rows: Range<u64>, cx: &RunCtx) -> Result<ImageRows, NodeError> {
        render_rows(i.scene, i.accel, self, rows.start as usize..rows.end as usize, Some(cx))
    }

    fn gather(&self, i: &PathTraceIn, parts: &[&ImageRows], cx: &RunCtx) -> Result<PathTraceOut, NodeError> {
        let cam = &i.scene.camera;
        let (mut imgs, c) = gather_rows(cam.width, cam.height, 2, parts)?;
        let (var, mean) = (imgs.pop().expect("two layers"), imgs.pop().expect("two layers"));
        if !i.scene.has_lights() {
            cx.note("the scene has no light: the image is black (nothing was traced)");
            return Ok(PathTraceOut { image: mean, variance: var });
        }
        let (rays, nonfinite) = (c[0], c[1]);
        cx.metric("spp", self.spp as f64);
        cx.metric("rays", rays as f64);
        cx.metric("nonfinite_samples", nonfinite as f64);
        if nonfinite > 0 {
            cx.note(format!("{nonfinite} samples were NaN or infinite and were dropped"));
        }
        if self.spp == 1 {
            cx.note("variance needs spp ≥ 2: it is written as 0");
        }
        Ok(PathTraceOut { image: mean, variance: var })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{cancels_midway, i, test_scene};
    use crate::types::accel::BuildQuality;
    use relume_core::Value;

    fn params(spp: u32, max_depth: i32) -> PathTrace {
        PathTrace { spp, max_depth, min_depth: 1, rr_depth: 5, seed: 1, fresnel_reflection: true }
    }

    #[test]
    fn max_depth_one_sees_only_emitters_and_more_depth_adds_light() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let sum = |d| render(&scene, &accel, &params(4, d), None).unwrap().0.as_floats().iter().map(|&x| x as f64).sum::<f64>();
        let (one, two, three) = (sum(1), sum(2), sum(3));
        assert_eq!(one, 0.0, "no emitter is visible: a point light only");
        assert!(two > 0.0 && three > two, "{two} {three}");
    }

    #[test]
    fn without_fresnel_reflection_a_glass_sphere_passes_all_the_light_behind_it() {
        // A glass sphere (index 1.5) in front of a large emitter of radiance 1, seen through
        // its centre: refracting in and out, radiance × 1/η² × η² = 1 exactly when nothing
        // reflects; with Fresnel reflection about (1 − F)² / (1 − F²) = 0.923 (F = 0.04 at
        // each interface, the rest going back to the black sky).
        use crate::scene::builder::SceneBuilder;
        use crate::types::Material;
        use glam::Vec3;
        let glass = Material::Dielectric { ior: 1.5, medium: None };
        let black = Material::Lambert { albedo: Vec3::ZERO };
        let scene = SceneBuilder::new(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, 2.0, 3, 3)
            .sphere("glass", Vec3::ZERO, 1.0, glass, Vec3::ZERO, false)
            .quad("lamp", Vec3::new(-10.0, -10.0, -5.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 20.0, 0.0), black, Vec3::ONE)
            .build();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let centre = |fresnel_reflection| {
            let p = PathTrace { fresnel_reflection, ..params(256, -1) };
            render(&scene, &accel, &p, None).unwrap().0.pixels[4][0]
        };
        let (without, with) = (centre(false), centre(true));
        assert!((without - 1.0).abs() < 1e-4, "without reflection {without}");
        assert!((with - 0.923).abs() < 0.02, "with reflection {with}");
    }

    #[test]
    fn a_bubble_of_index_below_one_bends_light_as_the_inner_face_of_a_glass_shell() {
        // A glass ball holding a bubble of relative index 1 / 1.5 (air inside glass) is a
        // glass shell: the same picture as the ball with an inward-facing inner sphere of
        // index 1.5 (its inside the glass around it), up to rounding; a small lamp behind
        // makes the bending show, and without the bubble the picture differs.
        use crate::scene::builder::SceneBuilder;
        use crate::types::Material;
        use glam::Vec3;
        let glass = Material::Dielectric { ior: 1.5, medium: None };
        let black = Material::Lambert { albedo: Vec3::ZERO };
        let image = |inner: Option<(f32, bool)>| {
            let mut b = SceneBuilder::new(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, 30.0, 8, 8).sphere(
                "glass",
                Vec3::ZERO,
                1.0,
                glass,
                Vec3::ZERO,
                false,
            );
            if let Some((ior, inward)) = inner {
                b = b.sphere("inner", Vec3::ZERO, 0.5, Material::Dielectric { ior, medium: None }, Vec3::ZERO, inward);
            }
            let scene =
                b.quad("lamp", Vec3::new(-1.0, -1.0, -5.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0), black, Vec3::ONE).build();
            let accel = Accel::build(&scene, BuildQuality::Fast);
            let p = PathTrace { fresnel_reflection: false, ..params(16, -1) };
            render(&scene, &accel, &p, None).unwrap().0.as_floats().to_vec()
        };
        let (bubble, shell, ball) = (image(Some((1.0 / 1.5, false))), image(Some((1.5, true))), image(None));
        let diff = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
        assert!(diff(&bubble, &shell) < 1e-3, "bubble against shell: {}", diff(&bubble, &shell));
        assert!(diff(&bubble, &ball) > 0.1, "the bubble changes the picture: {}", diff(&bubble, &ball));
    }

    #[test]
    fn min_depth_three_is_the_one_bounce_light_of_the_same_paths() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let image = |max_depth, min_depth| {
            let p = PathTrace { min_depth, ..params(8, max_depth) };
            render(&scene, &accel, &p, None).unwrap().0.as_floats().to_vec()
        };
        let (three, two, bounce) = (image(3, 1), image(2, 1), image(3, 3));
        let mut sum = 0.0;
        for ((a, b), c) in three.iter().zip(&two).zip(&bounce) {
            assert!((a - b - c).abs() <= 1e-5 * a.abs().max(1.0), "{a} - {b} against {c}");
            sum += *c as f64;
        }
        assert!(sum > 0.0, "light bounces between the spheres");
        assert!(image(2, 3).iter().all(|&x| x == 0.0), "no path is both ≥ 3 and ≤ 2 segments long");
    }

    #[test]
    fn variance_shrinks_as_samples_grow_and_is_zero_for_one_sample() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let var = |spp| render(&scene, &accel, &params(spp, 3), None).unwrap().1.as_floats().iter().map(|&x| x as f64).sum::<f64>();
        assert_eq!(var(1), 0.0);
        let (v4, v64) = (var(4), var(64));
        assert!(v64 < v4 / 4.0, "variance of the mean falls like 1/n: {v4} → {v64}");
    }

    #[test]
    fn a_cancelled_render_stops_with_cancelled() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let cancel = relume_core::CancelToken::new();
        cancel.cancel();
        let cx = RunCtx::new("t", &cancel, None);
        assert_eq!(render(&scene, &accel, &params(4, 3), Some(&cx)).err(), Some(NodeError::Cancelled));
    }

    #[test]
    fn the_node_stops_midway_when_cancelled() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        cancels_midway::<PathTrace>(&[("spp", i(64)), ("max_depth", i(3))], vec![Value::new(scene), Value::new(accel)]);
    }
}
