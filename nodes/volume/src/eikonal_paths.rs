use super::octree_layout::{CLEAR, CLEARANCE, LEVEL, MAX_STEP};
use super::optics::{box_interval, leaf_exit, ray_step, voxel_of, Clearance, Integrator, Ray};
use crate::types::view_paths::{Gather, PathEnd};
use crate::types::{Sampler, ViewPaths, Volume};
use glam::Vec3;
use relume_base::render::camera::CameraRays;
use relume_base::types::{Accel, Camera};
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, params, NodeError, RunCtx};
use std::sync::atomic::{AtomicU64, Ordering};

params! {
    /// The camera's curved rays through a medium ([S] 6.3.5, the half of the eikonal render that
    /// does not depend on the light): per pixel `samples`² stratified rays go straight to the
    /// medium's box, then follow the ray equation through it with a fixed step (`step`, 1 voxel)
    /// — Störmer–Verlet or the thesis' Euler step x += Δs v / n, v += Δs ∇n (`integrator`, as
    /// `MarchPhotons`), |v| = n kept — or, with `adaptive`, the octree's step (`step` the least)
    /// inside clear leaves (κ = 0 all through: nothing to gather, the index flat within ε′) and,
    /// where nothing absorbs anywhere, straight on across uniform leaves to the first voxel that
    /// may bend the ray. Each step through scattering medium (σ > 0) keeps an in-scattering
    /// sample: its midpoint, direction and weight σ × ∫ transmittance (e^{−κΔs} falling along the
    /// path). The path ends on the straight segment it leaves the box along, or at a surface inside
    /// the box (from `accel`: wire a BVH of what does not move with the light, so that a light
    /// edit leaves the paths as they are; `EikonalRender` checks it sees the same surfaces
    /// there). The camera is an input of its own: orbiting re-runs this node and the shading.
    /// Rows in parallel, the same bytes on any thread count; the paths' bytes are counted as they
    /// grow and a trace that would pass the memory budget stops with the estimate.
    pub struct EikonalPaths {
        /// rays per pixel side (stratified): samples² rays per pixel
        pub samples: u32 = 1, range = 1..=16;
        /// the marching step through the medium
        pub step: f32 = 1.0, range = 0.05..=16.0, unit = "voxels";
        /// take the octree's longer steps through clear leaves ([S] 6.3.5 steps fixed everywhere)
        pub adaptive: bool = true;
        /// how the ray equation is stepped
        pub integrator: Integrator = Verlet;
    }
}

inputs!(pub EikonalPathsIn { accel: Accel, medium: Volume, octree: Volume, camera: Camera });
outputs!(pub EikonalPathsOut { paths: ViewPaths });

/// One camera sample's path: the camera ray, where it enters the box, its gathers and end.
struct Path {
    o: Vec3,
    d: Vec3,
    entry: f32,
    gathers: Vec<Gather>,
    end: PathEnd,
}

/// Everything the pixels share.
struct Tracer<'a> {
    accel: &'a Accel,
    m: &'a Volume,
    oct: &'a Volume,
    /// Lookups of n and ∇n in `oct`.
    oct_s: Sampler<'a>,
    clearance: std::sync::Arc<Clearance>,
    p: &'a EikonalPaths,
    has_kappa: bool,
    eps: f32,
    obstacles: Option<(Vec3, Vec3)>,
    /// Steps after which a walk ends where it is (a ray caught in the medium).
    max_steps: usize,
    /// The voxel's sides and the marching step (world units).
    h: Vec3,
    ds0: f32,
}

impl Tracer<'_> {
    /// Whether a surface lies on `o + t u` for t ∈ (0, tmax), starting a hair behind `o`.
    fn blocked(&self, o: Vec3, u: Vec3, tmax: f32) -> bool {
        self.accel.intersect(o - u * self.eps, u, 0.0, tmax + self.eps).is_some()
    }

    /// A walk along the camera ray `o + t d`: to the box, then (if it enters) through it.
    fn start(&self, o: Vec3, d: Vec3) -> Walk {
        let m = self.m;
        match box_interval(o, d, m.min, m.max) {
            None => {
                Walk { o, d, entry: f32::INFINITY, ray: None, tr: 1.0, steps: 0, end: Some(PathEnd { o, d, tmax: f32::INFINITY, tr: 1.0 }) }
            }
            Some((t0, _)) => Walk { o, d, entry: t0, ray: Some(Ray::new(&self.oct_s, o + d * t0, d)), tr: 1.0, steps: 0, end: None },
        }
    }

    /// One step of a walk that has not ended (its in-scattering samples go to `gathers`); at
    /// its end, or after `max_steps` steps, `walk.end` is set.
    fn step(&self, walk: &mut Walk, gathers: &mut Vec<Gather>) {
        let m = self.m;
        let Some(ray) = walk.ray else { return };
        if walk.steps >= self.max_steps {
            walk.end = Some(PathEnd { o: walk.o, d: walk.d, tmax: 0.0, tr: 0.0 });
            return;
        }
        walk.steps += 1;
        let (ds0, h) = (self.ds0, self.h);
        let (x, u) = (ray.x, ray.dir());
        let mut ds = ds0;
        let mut straight = false;
        if self.p.adaptive {
            let q = self.oct_s.to_grid(x);
            let c = voxel_of(m, q);
            let oi = self.oct.index(c[0], c[1], c[2]);
            let smax = self.oct.data[oi + MAX_STEP];
            if !self.has_kappa && smax == f32::INFINITY && self.oct.data[oi + CLEARANCE] > 0.0 {
                // Nothing to gather anywhere, and no ray bends here: straight on to the
                // first voxel that may bend it, as MarchPhotons.
                let run = self.clearance.straight_run(x, u, f32::INFINITY);
                if run > 0.0 {
                    (ds, straight) = (run, true);
                }
            }
            // A leaf's step is clamped to [ds0, max(Δs_max, step) × voxel]: where Δs_max is no
            // more than the step (the shell of a glass, most steps), that is ds0 whatever the
            // leaf's boundary, which is then not worked out.
            if !straight && self.oct.data[oi + CLEAR] > 0.0 && smax > self.p.step {
                let hi = smax.max(self.p.step) * h.min_element();
                ds = leaf_exit(q, u / h, c, self.oct.data[oi + LEVEL].max(0.0) as u32).max(ds0).min(hi);
            }
        }
        // Farther than the step from every face (with a margin for rounding), the step stays in
        // the box and its exit is not worked out.
        let inside = (x - m.min).min(m.max - x).cmpgt(Vec3::splat(ds * 1.001)).all();
        let t_box = if inside { f32::INFINITY } else { box_interval(x, u, m.min, m.max).map_or(0.0, |(_, t1)| t1) };
        let leaving = ds >= t_box;
        if leaving {
            ds = t_box;
        } else if let Some((lo, hi)) = self.obstacles {
            // A surface up to half a voxel past the step's end is taken now: the next step
            // would start too close to it to be found.
            let reach = ds + 0.5 * h.min_element();
            let far = x + u * reach;
            if x.min(far).cmple(hi + self.eps).all() && x.max(far).cmpge(lo - self.eps).all() && self.blocked(x, u, reach) {
                walk.end = Some(PathEnd { o: x, d: u, tmax: reach, tr: walk.tr });
                return;
            }
        }
        if m.channels > 2 && self.has_kappa {
            let mid = x + u * (ds / 2.0);
            let [_, kappa, sigma] = m.sample_n::<3>(mid, 0);
            let (kappa, sigma) = (kappa.max(0.0), sigma.max(0.0));
            let att = (-kappa * ds).exp();
            if sigma > 0.0 {
                let w = if kappa * ds > 1e-6 { (1.0 - att) / kappa } else { ds };
                gathers.push(Gather { p: mid, u, w: sigma * w * walk.tr });
            }
            walk.tr *= att;
        }
        if leaving {
            // Traced on from the step's start: the exit point may lie in a floor's plane.
            walk.end = Some(PathEnd { o: x, d: u, tmax: f32::INFINITY, tr: walk.tr });
            return;
        }
        // Longer steps (through clear leaves) are midpoint steps, as in MarchPhotons.
        walk.ray = Some(if straight {
            Ray::new(&self.oct_s, x + u * ds, u)
        } else {
            let integrator = if ds > ds0 * 1.0001 { Integrator::Midpoint } else { self.p.integrator };
            ray_step(&self.oct_s, &ray, ds, integrator)
        });
    }
}

/// A camera sample's path in the making: the camera ray, where it enters the box (∞: never),
/// the ray in the medium, its transmittance so far, and its end once it has one.
struct Walk {
    o: Vec3,
    d: Vec3,
    entry: f32,
    ray: Option<Ray>,
    tr: f32,
    steps: usize,
    end: Option<PathEnd>,
}

/// The paths of `camera`'s rays through the medium (see the node's doc).
pub fn trace(i: &EikonalPathsIn, p: &EikonalPaths, cx: &RunCtx) -> Result<ViewPaths, NodeError> {
    let (m, o) = (i.medium, i.octree);
    if o.dims != m.dims || o.channels != super::octree_layout::CHANNELS || o.min != m.min || o.max != m.max {
        return Err(NodeError::failed(format!(
            "the octree ({:?}, {} channels) was not built on the medium's grid ({:?})",
            o.dims, o.channels, m.dims
        )));
    }
    let (lo, hi) = i.accel.bounds();
    let extent = if lo.cmple(hi).all() { (hi - lo).length() } else { 0.0 };
    let t = Tracer {
        accel: i.accel,
        m,
        oct: o,
        oct_s: Sampler::new(o),
        clearance: Clearance::shared(o),
        p,
        has_kappa: m.absorbs(),
        eps: 1e-5 * extent.max((m.max - m.min).length()),
        obstacles: i.accel.bounds_within(m.min, m.max),
        max_steps: 64 * m.dims.iter().sum::<u32>() as usize * (1.0 / p.step).ceil().max(1.0) as usize,
        h: m.voxel(),
        ds0: p.step * m.voxel().min_element(),
    };
    let cam = CameraRays::new(i.camera);
    let (w, h, s) = (i.camera.width, i.camera.height, p.samples as usize);
    let budget = cx.memory_budget();
    let fixed = (w * h * s * s) as u64 * ViewPaths::SAMPLE_BYTES;
    if fixed > budget {
        return Err(NodeError::OverLimit {
            param: Some("samples".into()),
            msg: format!("{} camera samples need {}, over the {} budget", w * h * s * s, fmt_bytes(fixed), fmt_bytes(budget)),
        });
    }
    let held = AtomicU64::new(fixed);
    // A row's samples walk together, one step of each in turn: independent lookups of
    // neighbouring voxels the processor overlaps (each walk's steps are its own, so the bytes
    // do not depend on the order).
    let rows = cx.par_map(h, |y| {
        let mut walks: Vec<Walk> = Vec::with_capacity(w * s * s);
        for x in 0..w {
            for k in 0..s * s {
                let (fx, fy) = (x as f32 + ((k % s) as f32 + 0.5) / s as f32, y as f32 + ((k / s) as f32 + 0.5) / s as f32);
                let (o, d) = cam.ray(fx, fy);
                walks.push(t.start(o, d));
            }
        }
        let mut gathers: Vec<Vec<Gather>> = vec![Vec::new(); walks.len()];
        let mut live: Vec<usize> = (0..walks.len()).filter(|&k| walks[k].end.is_none()).collect();
        while !live.is_empty() {
            for &k in &live {
                t.step(&mut walks[k], &mut gathers[k]);
                if walks[k].end.is_some() {
                    let bytes = gathers[k].len() as u64 * ViewPaths::GATHER_BYTES;
                    if bytes > 0 && held.fetch_add(bytes, Ordering::Relaxed) + bytes > budget {
                        return None;
                    }
                }
            }
            live.retain(|&k| walks[k].end.is_none());
        }
        let paths = walks.into_iter().zip(gathers).map(|(w, gathers)| Path {
            o: w.o,
            d: w.d,
            entry: w.entry,
            gathers,
            end: w.end.expect("every walk ends"),
        });
        Some(paths.collect::<Vec<Path>>())
    })?;
    let mut out = ViewPaths {
        width: w as u32,
        height: h as u32,
        samples: p.samples,
        min: m.min,
        max: m.max,
        obstacles: t.obstacles,
        offsets: vec![0],
        ..Default::default()
    };
    for row in rows {
        let Some(row) = row else {
            return Err(NodeError::OverLimit {
                param: Some("samples".into()),
                msg: format!(
                    "the paths' in-scattering samples passed the {} budget (already {} held): fewer samples or a coarser step",
                    fmt_bytes(budget),
                    fmt_bytes(held.load(Ordering::Relaxed))
                ),
            });
        };
        for path in row {
            out.origin.push(path.o);
            out.dir.push(path.d);
            out.entry.push(path.entry);
            out.gathers.extend_from_slice(&path.gathers);
            out.offsets.push(out.gathers.len() as u32);
            out.ends.push(path.end);
        }
    }
    Ok(out)
}

#[node(category = "volume", version = 3, metrics = ["camera_samples", "gathers", "entered_pct"])]
impl EikonalPaths {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The samples' fixed part (the gathers are counted as they grow), the octree's
        // clearance as a byte a voxel.
        let paths = inputs[3]
            .and_then(|s| s.dims)
            .map(|[w, h]| relume_core::PortSize::bytes(w as u64 * h as u64 * (self.samples as u64).pow(2) * ViewPaths::SAMPLE_BYTES));
        relume_core::MemoryEstimate { outputs: vec![paths], working: inputs[2].map_or(0, |s| s.bytes / 32) }
    }

    fn run(&self, i: EikonalPathsIn, cx: &RunCtx) -> Result<EikonalPathsOut, NodeError> {
        let paths = trace(&i, self, cx)?;
        cx.metric("camera_samples", paths.len() as f64);
        cx.metric("gathers", paths.gathers.len() as f64);
        cx.metric("entered_pct", 100.0 * paths.entry.iter().filter(|e| e.is_finite()).count() as f64 / paths.len().max(1) as f64);
        Ok(EikonalPathsOut { paths })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::*;
    use relume_base::scene::builder::SceneBuilder;
    use relume_base::testing::f;
    use relume_base::types::Light;
    use relume_core::{CancelToken, PortValue};

    /// A unit cube of homogeneous medium (n = 1, κ = 1, σ = 0.5) at the origin seen from above,
    /// 9² pixels, and its paths.
    fn slab(p: &EikonalPaths) -> (Camera, Volume, ViewPaths) {
        let m = source("Constant", 16, Vec3::ZERO, 1.0, &[("index", f(1.0)), ("extinction", f(1.0)), ("scattering", f(0.5))]);
        let s = SceneBuilder::new(Vec3::new(0.0, 3.0, 0.3), Vec3::ZERO, 40.0, 9, 9)
            .light(Light::Directional { direction: -Vec3::Y, irradiance: Vec3::ONE })
            .build();
        let paths = view_paths(&accel_without(&s, ""), &m, &octree_of(&m), &s.camera, p);
        (s.camera, m, paths)
    }

    #[test]
    fn straight_paths_through_an_absorbing_cube_carry_its_transmittance_and_weights() {
        // n = 1: every path leaves along its camera ray; a ray crossing the cube over a length L
        // keeps e^{−κL}, and its gathers' weights sum to σ (1 − e^{−κL}) / κ.
        let (camera, m, paths) = slab(&paths_params());
        assert_eq!(paths.len(), 81);
        let cam = CameraRays::new(&camera);
        let mut entered = 0;
        for k in 0..paths.len() {
            let (o, d) = cam.ray((k % 9) as f32 + 0.5, (k / 9) as f32 + 0.5);
            assert_eq!((paths.origin[k], paths.dir[k]), (o, d));
            let e = paths.ends[k];
            assert!((e.d - d).length() < 1e-6, "straight on: {} vs {d}", e.d);
            assert_eq!(e.tmax, f32::INFINITY);
            let w: f32 = paths.gathers[paths.offsets[k] as usize..paths.offsets[k + 1] as usize].iter().map(|g| g.w).sum();
            match box_interval(o, d, m.min, m.max) {
                Some((t0, t1)) => {
                    entered += 1;
                    assert_eq!(paths.entry[k], t0);
                    let l = t1 - t0;
                    assert!((e.tr - (-l).exp()).abs() < 1e-3, "transmittance {} over {l}", e.tr);
                    assert!((w - 0.5 * (1.0 - (-l).exp())).abs() < 2e-3, "weights {w} over {l}");
                }
                None => {
                    assert_eq!(paths.entry[k], f32::INFINITY);
                    assert_eq!((e.o, e.tr, w), (o, 1.0, 0.0), "a ray past the box is the camera ray");
                }
            }
        }
        assert!(entered > 20 && entered < 81, "{entered} rays meet the cube");
    }

    #[test]
    fn the_same_bytes_on_one_thread_and_many_and_stratified_samples() {
        let run = || slab(&EikonalPaths { samples: 2, ..paths_params() }).2;
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(run);
        let many = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap().install(run);
        assert_eq!(one.encode(), many.encode());
        assert_eq!(one.len(), 81 * 4, "2² samples a pixel");
    }

    #[test]
    fn paths_over_the_memory_budget_are_refused_with_the_estimate() {
        let m = source("Constant", 16, Vec3::ZERO, 1.0, &[("index", f(1.0)), ("extinction", f(1.0)), ("scattering", f(0.5))]);
        let s = SceneBuilder::new(Vec3::new(0.0, 3.0, 0.3), Vec3::ZERO, 40.0, 64, 64).build();
        let (a, oct) = (accel_without(&s, ""), octree_of(&m));
        let i = EikonalPathsIn { accel: &a, medium: &m, octree: &oct, camera: &s.camera };
        let cancel = CancelToken::new();
        for budget in [64 << 10, 400 << 10] {
            // 64 KiB: not even the samples; 400 KiB: the samples, not their gathers.
            let cx = RunCtx::new("t", &cancel, None).with_memory_budget(budget);
            let e = trace(&i, &paths_params(), &cx).unwrap_err();
            assert!(matches!(e, NodeError::OverLimit { .. }), "{e}");
            assert!(e.to_string().contains("budget"), "{e}");
        }
    }
}
