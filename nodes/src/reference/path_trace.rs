//! PathTrace node.

use super::camera::CameraRays;
use super::integrator::{Counts, Settings, Tracer};
use crate::geometry::accel::Accel;
use crate::types::{Image, Scene};
use rayon::prelude::*;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

node_doc! {
    /// Reference path tracer (the ground truth every pipeline reports its error against):
    /// unbiased; next-event estimation with MIS (power heuristic) against BSDF sampling;
    /// importance-sampled environment maps; smooth dielectrics with homogeneous media;
    /// `max_depth` as in Mitsuba 3 (1: emitters only, 2: direct light, 3: one bounce, −1:
    /// unbounded with Russian roulette from `rr_depth`); box pixel filter. Samples are taken
    /// in passes of doubling size (progress and cancellation between rows); each pixel's
    /// random numbers depend only on (seed, pixel, sample), so the image has the same bytes on
    /// any thread count. Outputs the mean and the per-pixel variance of the mean.
    pub struct PathTrace;
}

pub struct PathTraceParams {
    pub spp: u32,
    pub max_depth: i32,
    pub rr_depth: u32,
    pub seed: u64,
}

impl Params for PathTraceParams {
    fn schema() -> Schema {
        Schema::new()
            .int("spp", 16, 1, 1 << 20)
            .unit("samples/pixel")
            .help("samples per pixel")
            .int("max_depth", -1, -1, 1024)
            .help("maximum path segments (Mitsuba's meaning); -1 = unbounded")
            .int("rr_depth", 5, 1, 1024)
            .help("depth at which Russian roulette starts")
            .int("seed", 0, 0, i64::from(u32::MAX))
            .help("random seed")
    }
    fn from_values(v: &ParamValues) -> Self {
        PathTraceParams {
            spp: v.int("spp") as u32,
            max_depth: v.int("max_depth") as i32,
            rr_depth: v.int("rr_depth") as u32,
            seed: v.int("seed") as u64,
        }
    }
}

/// Renders `spp` samples per pixel; returns (mean, variance of the mean, counts).
pub fn render(scene: &Scene, accel: &Accel, p: &PathTraceParams, cx: Option<&RunCtx>) -> Result<(Image, Image, u64, u64), NodeError> {
    let cam = &scene.camera;
    let (w, h) = (cam.width, cam.height);
    let mut mean = Image::try_new(w, h)?;
    let mut var = Image::try_new(w, h)?;
    let tracer = Tracer::new(scene, accel, Settings { max_depth: p.max_depth, rr_depth: p.rr_depth, seed: p.seed });
    let rays = CameraRays::new(cam);
    let mut sum = vec![[0f64; 3]; w * h];
    let mut sum2 = vec![[0f64; 3]; w * h];
    let total = (w * h) as u64 * p.spp as u64;
    let done = AtomicU64::new(0);
    let ray_count = AtomicU64::new(0);
    let nonfinite = AtomicU64::new(0);
    let cancelled = AtomicBool::new(false);
    let mut first = 0u32;
    let mut pass = 1u32;
    while first < p.spp {
        let n = pass.min(p.spp - first);
        sum.par_chunks_mut(w).zip(sum2.par_chunks_mut(w)).enumerate().for_each(|(y, (srow, s2row))| {
            if cancelled.load(Ordering::Relaxed) || cx.is_some_and(|c| c.check().is_err()) {
                cancelled.store(true, Ordering::Relaxed);
                return;
            }
            let mut counts = Counts::default();
            for x in 0..w {
                let pixel = (y * w + x) as u64;
                for s in first..first + n {
                    let id = pixel << 32 | s as u64;
                    let jitter = (crate::math::rng::uniform(p.seed ^ 0x5EED, id, 0), crate::math::rng::uniform(p.seed ^ 0x5EED, id, 1));
                    let (o, d) = rays.ray(x as f32 + jitter.0, y as f32 + jitter.1);
                    let l = tracer.radiance(o, d, id, &mut counts);
                    if !l.is_finite() {
                        nonfinite.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                    for c in 0..3 {
                        srow[x][c] += l[c] as f64;
                        s2row[x][c] += (l[c] as f64) * (l[c] as f64);
                    }
                }
            }
            ray_count.fetch_add(counts.rays, Ordering::Relaxed);
            let d = done.fetch_add(w as u64 * n as u64, Ordering::Relaxed) + w as u64 * n as u64;
            if let Some(c) = cx {
                c.progress(d, total);
            }
        });
        if cancelled.load(Ordering::Relaxed) {
            return Err(NodeError::Cancelled);
        }
        first += n;
        pass *= 2;
    }
    let n = p.spp as f64;
    for i in 0..w * h {
        for c in 0..3 {
            let m = sum[i][c] / n;
            mean.pixels[i][c] = m as f32;
            var.pixels[i][c] = if p.spp > 1 { ((sum2[i][c] / n - m * m).max(0.0) / (n - 1.0)) as f32 } else { 0.0 };
        }
    }
    Ok((mean, var, ray_count.into_inner(), nonfinite.into_inner()))
}

impl Node for PathTrace {
    const KIND: &'static str = "PathTrace";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "reference";
    const CACHING: Caching = Caching::Disk;
    type Params = PathTraceParams;

    fn ports() -> Ports {
        Ports::new().input::<Scene>("scene").input::<Accel>("accel").output::<Image>("image").output::<Image>("variance")
    }

    fn run(&self, p: &PathTraceParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        let scene = io.input::<Scene>("scene")?;
        let accel = io.input::<Accel>("accel")?;
        if !scene.has_lights() {
            cx.note("the scene has no light: the image is black (nothing was traced)");
            let (w, h) = (scene.camera.width, scene.camera.height);
            io.set("image", Image::try_new(w, h)?)?;
            return io.set("variance", Image::try_new(w, h)?);
        }
        let (mean, var, rays, nonfinite) = render(scene, accel, p, Some(cx))?;
        cx.metric("spp", p.spp as f64);
        cx.metric("rays", rays as f64);
        cx.metric("nonfinite_samples", nonfinite as f64);
        if nonfinite > 0 {
            cx.note(format!("{nonfinite} samples were NaN or infinite and were dropped"));
        }
        if p.spp == 1 {
            cx.note("variance needs spp ≥ 2: it is written as 0");
        }
        io.set("image", mean)?;
        io.set("variance", var)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::accel::BuildQuality;
    use crate::testing::test_scene;

    fn params(spp: u32, max_depth: i32) -> PathTraceParams {
        PathTraceParams { spp, max_depth, rr_depth: 5, seed: 1 }
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
}
