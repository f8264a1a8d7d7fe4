//! PathTrace node.

use crate::render::camera::CameraRays;
use crate::render::film::{with_ctx, Film};
use crate::render::integrator::{Settings, Tracer};
use crate::types::accel::Accel;
use crate::types::{Image, Scene};
use relume_core::{inputs, node, outputs, NodeError, Params, RunCtx};

/// Reference path tracer (the ground truth every pipeline reports its error against):
/// unbiased; next-event estimation with MIS (power heuristic) against BSDF sampling;
/// importance-sampled environment maps; smooth dielectrics with homogeneous media;
/// `max_depth` as in Mitsuba 3 (1: emitters only, 2: direct light, 3: one bounce, −1:
/// unbounded with Russian roulette from `rr_depth`); box pixel filter. Samples are taken
/// in passes of doubling size (progress and cancellation between rows); each pixel's
/// random numbers depend only on (seed, pixel, sample), so the image has the same bytes on
/// any thread count. Outputs the mean and the per-pixel variance of the mean.
#[derive(Params)]
pub struct PathTrace {
    /// samples per pixel
    #[param(default = 16, range = 1..=(1 << 20), unit = "samples/pixel")]
    pub spp: u32,
    /// maximum path segments (Mitsuba's meaning); -1 = unbounded
    #[param(default = -1, range = -1..=1024)]
    pub max_depth: i32,
    /// depth at which Russian roulette starts
    #[param(default = 5, range = 1..=1024)]
    pub rr_depth: u32,
    /// random seed
    #[param(default = 0, range = 0..=u32::MAX)]
    pub seed: u64,
}

inputs!(pub PathTraceIn { scene: Scene, accel: Accel });
outputs!(pub PathTraceOut { image: Image, variance: Image });

/// Renders `p.spp` samples per pixel; returns (mean, variance of the mean, rays, samples
/// dropped as NaN or infinite). `cx` reports progress and cancels; `None` outside a graph.
pub fn render(scene: &Scene, accel: &Accel, p: &PathTrace, cx: Option<&RunCtx>) -> Result<(Image, Image, u64, u64), NodeError> {
    let cam = &scene.camera;
    let mut film = Film::try_new(cam.width, cam.height)?;
    let tracer = Tracer::new(scene, accel, Settings { max_depth: p.max_depth, rr_depth: p.rr_depth, seed: p.seed });
    let rays = CameraRays::new(cam);
    let w = cam.width;
    with_ctx(cx, |cx| {
        film.add_passes(cx, p.spp, |x, y, s, counts| {
            let id = ((y * w + x) as u64) << 32 | s as u64;
            let jitter = (crate::math::rng::uniform(p.seed ^ 0x5EED, id, 0), crate::math::rng::uniform(p.seed ^ 0x5EED, id, 1));
            let (o, d) = rays.ray(x as f32 + jitter.0, y as f32 + jitter.1);
            tracer.radiance(o, d, id, counts)
        })
    })?;
    let (ray_count, nonfinite) = (film.rays(), film.nonfinite());
    let (mean, var) = film.finish();
    Ok((mean, var, ray_count, nonfinite))
}

#[node(category = "reference")]
impl PathTrace {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The film: a sum and a sum of squares (f64 RGB) per pixel.
        let image = inputs[0].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        relume_core::MemoryEstimate { outputs: vec![image, image], working: inputs[0].and_then(|s| s.pixels()).map_or(0, |p| p * 48) }
    }

    fn run(&self, i: PathTraceIn, cx: &RunCtx) -> Result<PathTraceOut, NodeError> {
        let (scene, accel) = (i.scene, i.accel);
        if !scene.has_lights() {
            cx.note("the scene has no light: the image is black (nothing was traced)");
            let (w, h) = (scene.camera.width, scene.camera.height);
            return Ok(PathTraceOut { image: Image::try_new(w, h)?, variance: Image::try_new(w, h)? });
        }
        let (mean, var, rays, nonfinite) = render(scene, accel, self, Some(cx))?;
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
        PathTrace { spp, max_depth, rr_depth: 5, seed: 1 }
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
