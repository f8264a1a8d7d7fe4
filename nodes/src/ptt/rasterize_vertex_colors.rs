//! RasterizeVertexColors node.

use super::types::VertexColors;
use crate::reference::path_trace::camera_sample;
use crate::render::camera::CameraRays;
use crate::types::{Accel, Camera, Image, Scene};
use glam::Vec3;
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, MemoryEstimate, NodeError, Params, PortSize, RunCtx};
use std::sync::atomic::{AtomicU64, Ordering};

/// Renders per-vertex radiance to an image ([S] chapter 5: the transfer tensors relight the
/// vertices, and each pixel interpolates them): `spp` camera samples per pixel, placed as the
/// reference path tracer places them (box filter, the same jitter from (`seed`, pixel,
/// sample): with the reference's seed, antialiased edges match its image); each sample's
/// primary hit takes its triangle's three vertex colours weighted by the hit's barycentrics,
/// and a sample that hits nothing sees the environment as the reference does (black with
/// `background` off). The pixel is the mean of its samples, summed in sample order: the same
/// bytes on any thread count. Shading per vertex is the thesis' choice; what interpolation
/// loses across shadow edges on coarse meshes is part of the method's error, measured against
/// a vertex-sampled reference elsewhere. The image's bytes are checked against the budget
/// before it is allocated.
///
/// Metrics: samples per pixel, primary rays traced, the fraction of samples that hit geometry.
#[derive(Params)]
pub struct RasterizeVertexColors {
    /// camera samples per pixel (box filter, as the reference)
    #[param(default = 16, range = 1..=4096, unit = "samples/pixel")]
    pub spp: u32,
    /// random seed of the sample positions (the reference's seed gives its positions)
    #[param(default = 0, range = 0..=u32::MAX)]
    pub seed: u64,
    /// samples that miss the geometry see the environment (else black)
    #[param(default = true)]
    pub background: bool,
}

inputs!(pub RasterizeVertexColorsIn { scene: Scene, accel: Accel, camera: Camera, colors: VertexColors });
outputs!(pub RasterizeVertexColorsOut { image: Image });

#[node(category = "ptt")]
impl RasterizeVertexColors {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        let image = inputs[2].and_then(|s| s.dims).map(|[w, h]| PortSize::image(w, h));
        MemoryEstimate { outputs: vec![image], working: 0 }
    }

    fn run(&self, i: RasterizeVertexColorsIn, cx: &RunCtx) -> Result<RasterizeVertexColorsOut, NodeError> {
        let (scene, accel, colors) = (i.scene, i.accel, &i.colors.colors);
        if colors.len() != scene.positions.len() {
            return Err(NodeError::input(
                "colors",
                format!("holds {} colours but the scene has {} vertices (one colour per vertex)", colors.len(), scene.positions.len()),
            ));
        }
        let (w, h) = (i.camera.width, i.camera.height);
        let bytes = PortSize::image(w, h).bytes;
        if bytes > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "the image of {w} × {h} pixels would hold {}, over the {} budget",
                fmt_bytes(bytes),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let mut image = Image::try_new(w, h)?;
        let cam = CameraRays::new(i.camera);
        let hits = AtomicU64::new(0);
        cx.par_chunks_mut(&mut image.pixels, w, |y, row| {
            let mut covered = 0;
            for (x, px) in row.iter_mut().enumerate() {
                let mut sum = [0.0f64; 3];
                for s in 0..self.spp {
                    let (o, d, _) = camera_sample(&cam, self.seed, w, x, y, s);
                    let l = match accel.intersect(o, d, 0.0, f32::INFINITY) {
                        Some(hit) => {
                            covered += 1;
                            let [a, b, c] = scene.triangles[hit.tri as usize].map(|v| colors[v as usize]);
                            a * (1.0 - hit.b1 - hit.b2) + b * hit.b1 + c * hit.b2
                        }
                        None if self.background => scene.environment_radiance(d),
                        None => Vec3::ZERO,
                    };
                    for (acc, v) in sum.iter_mut().zip(l.to_array()) {
                        *acc += v as f64;
                    }
                }
                *px = sum.map(|acc| (acc / self.spp as f64) as f32);
            }
            hits.fetch_add(covered, Ordering::Relaxed);
        })?;
        let rays = (w * h) as u64 * self.spp as u64;
        cx.metric("spp", self.spp as f64);
        cx.metric("rays", rays as f64);
        cx.metric("covered_fraction", hits.into_inner() as f64 / rays as f64);
        Ok(RasterizeVertexColorsOut { image })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::path_trace::{render, PathTrace};
    use crate::scene::builder::SceneBuilder;
    use crate::testing::{cancels_midway, first, i, run_full, run_on};
    use crate::types::accel::BuildQuality;
    use crate::types::{Environment, Material};
    use relume_core::{ParamValue, Value};

    const SKY: Vec3 = Vec3::new(0.2, 0.3, 0.4);
    const BLACK: Material = Material::Lambert { albedo: Vec3::ZERO };

    /// A 32² camera at z = 3 looking down −z (fov 40°) under a constant sky.
    fn camera() -> SceneBuilder {
        SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, 32, 32).environment(Environment::Constant(SKY))
    }

    /// A quad in the plane z = 0 facing the camera, from x = `x0` rightwards past the view.
    fn right_of(x0: f32) -> Scene {
        camera().quad("q", Vec3::new(x0, -5.0, 0.0), Vec3::new(10.0, 0.0, 0.0), Vec3::new(0.0, 10.0, 0.0), BLACK, Vec3::ZERO).build()
    }

    fn inputs(s: &Scene, colors: Vec<Vec3>) -> Vec<Value> {
        vec![
            Value::new(s.clone()),
            Value::new(Accel::build(s, BuildQuality::Fast)),
            Value::new(s.camera.clone()),
            Value::new(VertexColors { colors }),
        ]
    }

    fn raster(s: &Scene, colors: Vec<Vec3>, params: &[(&str, ParamValue)]) -> Image {
        first(&run_on::<RasterizeVertexColors>(params, inputs(s, colors)).expect("runs"))
    }

    fn close(a: [f32; 3], b: Vec3, tol: f32) -> bool {
        (Vec3::from_array(a) - b).abs().max_element() <= tol
    }

    #[test]
    fn constant_colours_fill_the_covered_pixels_and_the_sky_the_rest() {
        let s = camera().sphere("ball", Vec3::ZERO, 0.6, BLACK, Vec3::ZERO, false).build();
        let c = Vec3::new(1.0, 0.5, 0.25);
        let n = s.positions.len();
        let img = raster(&s, vec![c; n], &[("spp", i(1))]);
        let covered = img.pixels.iter().filter(|p| close(**p, c, 1e-6)).count();
        let sky = img.pixels.iter().filter(|p| **p == SKY.to_array()).count();
        assert_eq!(covered + sky, 32 * 32, "every pixel is the colour or the sky");
        assert!(covered > 100 && sky > 100, "{covered} {sky}");
        assert!(close(img.get(16, 16), c, 1e-6) && img.get(0, 0) == SKY.to_array());
        // Without the background the sky is black; with many samples each pixel mixes the two.
        let dark = raster(&s, vec![c; n], &[("spp", i(1)), ("background", ParamValue::Bool(false))]);
        assert!(dark.pixels.iter().all(|p| close(*p, c, 1e-6) || *p == [0.0; 3]));
        let aa = raster(&s, vec![c; n], &[("spp", i(16))]);
        for p in &aa.pixels {
            let a = (p[0] - SKY.x) / (c.x - SKY.x);
            assert!((-1e-6..=1.0 + 1e-6).contains(&a) && close(*p, SKY + (c - SKY) * a, 1e-5), "{p:?}");
        }
    }

    #[test]
    fn a_linear_function_at_the_vertices_comes_back_linear() {
        // A tilted, coarsely tessellated sheet (5 × 5 vertices) with f(p) = a + M p stored at
        // its vertices: every sample must see f at its own hit point, so every pixel is the
        // mean of f (or the sky) over the reference's sample positions.
        let mut pos = vec![];
        let mut tris = vec![];
        for j in 0..5u32 {
            for k in 0..5u32 {
                let (x, y) = (-1.0 + 0.5 * k as f32, -1.0 + 0.5 * j as f32);
                pos.push(Vec3::new(x, y, -0.6 * x + 0.3 * y));
                if j < 4 && k < 4 {
                    let a = j * 5 + k;
                    tris.push([a, a + 1, a + 6]);
                    tris.push([a, a + 6, a + 5]);
                }
            }
        }
        let s = camera().mesh("sheet", pos, None, tris, BLACK, Vec3::ZERO).build();
        let f = |p: Vec3| Vec3::new(0.5 + 0.3 * p.x, 0.4 + 0.2 * p.y - 0.1 * p.z, 0.6 - 0.15 * p.x + 0.25 * p.z);
        let colors: Vec<Vec3> = s.positions.iter().map(|p| f(*p)).collect();
        let (spp, seed) = (4, 9);
        let img = raster(&s, colors, &[("spp", i(spp)), ("seed", i(seed))]);
        let accel = Accel::build(&s, BuildQuality::Fast);
        let cam = CameraRays::new(&s.camera);
        let (mut worst, mut interior) = (0.0f32, 0);
        for y in 0..32 {
            for x in 0..32 {
                let mut want = Vec3::ZERO;
                let mut all_hit = true;
                for k in 0..spp as u32 {
                    let (o, d, _) = camera_sample(&cam, seed as u64, 32, x, y, k);
                    want += match accel.intersect(o, d, 0.0, f32::INFINITY) {
                        Some(hit) => f(o + d * hit.t),
                        None => {
                            all_hit = false;
                            SKY
                        }
                    };
                }
                want /= spp as f32;
                let err = (Vec3::from_array(img.get(x, y)) - want).abs().max_element();
                worst = worst.max(err);
                interior += all_hit as usize;
            }
        }
        eprintln!("linear: {interior} interior pixels, worst error {worst:e}");
        assert!(interior > 300, "{interior}");
        assert!(worst < 2e-6, "{worst}");
    }

    #[test]
    fn a_quad_over_half_the_view_covers_half_the_pixels() {
        // The quad's edge x = 0 projects onto the image's centre line: with one sample per
        // pixel, columns 16.. are covered and 0..16 not, for any jitter.
        let s = right_of(0.0);
        let c = Vec3::new(0.9, 0.1, 0.1);
        let out = run_full::<RasterizeVertexColors>(&[("spp", i(1))], std::path::Path::new("."), inputs(&s, vec![c; 4])).expect("runs");
        let img: Image = first(&out.outputs);
        for y in 0..32 {
            for x in 0..32 {
                let want = if x >= 16 { c } else { SKY };
                assert!(close(img.get(x, y), want, 1e-6), "({x}, {y}): {:?}", img.get(x, y));
            }
        }
        let m = |k: &str| out.metrics.iter().find(|(n, _)| n == k).map(|(_, v)| *v);
        assert_eq!((m("spp"), m("rays"), m("covered_fraction")), (Some(1.0), Some(1024.0), Some(0.5)));
    }

    #[test]
    fn antialiased_edges_match_the_reference_path_tracer() {
        // Edge at image x = 20.5: column 20 is half covered. An emitting quad seen by the path
        // tracer with emitters only (max_depth 1) is the constant colour E on the quad and the
        // sky elsewhere; the raster of E at its vertices, with the same spp and seed, takes
        // the same sample positions and gives the same pixels.
        let half = 3.0 * (20f32.to_radians()).tan();
        let x0 = half * (2.0 * 20.5 / 32.0 - 1.0);
        let e = Vec3::new(2.0, 1.0, 0.5);
        let s = camera().quad("q", Vec3::new(x0, -5.0, 0.0), Vec3::new(10.0, 0.0, 0.0), Vec3::new(0.0, 10.0, 0.0), BLACK, e).build();
        let (spp, seed) = (64, 3);
        let img = raster(&s, vec![e; 4], &[("spp", i(spp)), ("seed", i(seed))]);
        let accel = Accel::build(&s, BuildQuality::Fast);
        let (reference, ..) =
            render(&s, &accel, &PathTrace { spp: spp as u32, max_depth: 1, rr_depth: 5, seed: seed as u64 }, None).unwrap();
        let worst =
            img.pixels.iter().zip(&reference.pixels).map(|(a, b)| (Vec3::from_array(*a) - Vec3::from_array(*b)).abs().max_element());
        let worst = worst.fold(0.0f32, f32::max);
        // Column 20 lies strictly between sky and quad, near half-way.
        let cov: Vec<f32> = (0..32).map(|y| (img.get(20, y)[0] - SKY.x) / (e.x - SKY.x)).collect();
        eprintln!("edge: worst difference from the reference {worst:e}, column 20 coverage {:.3}..{:.3}", min(&cov), max(&cov));
        assert!(worst < 1e-6, "{worst}");
        assert!(min(&cov) > 0.2 && max(&cov) < 0.8, "{cov:?}");
        assert!(close(img.get(19, 7), SKY, 1e-6) && close(img.get(21, 7), e, 1e-6));
        // One sample per pixel leaves no intermediate value.
        let one = raster(&s, vec![e; 4], &[("spp", i(1)), ("seed", i(seed))]);
        assert!(one.pixels.iter().all(|p| close(*p, e, 1e-6) || close(*p, SKY, 0.0)));
    }

    fn min(v: &[f32]) -> f32 {
        v.iter().copied().fold(f32::INFINITY, f32::min)
    }

    fn max(v: &[f32]) -> f32 {
        v.iter().copied().fold(f32::NEG_INFINITY, f32::max)
    }

    #[test]
    fn the_same_bytes_on_one_and_two_threads() {
        let s = camera().sphere("ball", Vec3::new(0.2, 0.1, 0.0), 0.7, BLACK, Vec3::ZERO, false).build();
        let colors: Vec<Vec3> = s.positions.iter().map(|p| Vec3::new(p.x.abs(), p.y * p.y, 0.3 + 0.1 * p.z)).collect();
        let on = |t| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(t).build().expect("pool");
            pool.install(|| raster(&s, colors.clone(), &[("spp", i(8)), ("seed", i(5))]))
        };
        let (one, two) = (on(1), on(2));
        assert_eq!(bytemuck::cast_slice::<f32, u8>(one.as_floats()), bytemuck::cast_slice::<f32, u8>(two.as_floats()));
    }

    #[test]
    fn a_wrong_colour_count_and_an_oversized_image_are_refused() {
        let s = right_of(0.0);
        let e = run_on::<RasterizeVertexColors>(&[], inputs(&s, vec![Vec3::ONE; 3])).expect_err("refused");
        assert!(e.to_string().contains('3') && e.to_string().contains("4 vertices"), "{e}");
        let mut big = s.clone();
        (big.camera.width, big.camera.height) = (1 << 20, 1 << 20);
        let e = run_on::<RasterizeVertexColors>(&[], inputs(&big, vec![Vec3::ONE; 4])).expect_err("refused");
        assert!(e.is_over_limit() && e.to_string().contains("1048576 × 1048576"), "{e}");
    }

    #[test]
    fn the_node_stops_midway_when_cancelled() {
        let mut s = camera().sphere("ball", Vec3::ZERO, 0.6, BLACK, Vec3::ZERO, false).build();
        (s.camera.width, s.camera.height) = (128, 128);
        let n = s.positions.len();
        cancels_midway::<RasterizeVertexColors>(&[("spp", i(64))], inputs(&s, vec![Vec3::ONE; n]));
    }
}
