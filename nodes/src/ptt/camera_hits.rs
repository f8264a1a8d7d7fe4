//! CameraHits node.

use super::screen_hits::ScreenHits;
use crate::render::camera::CameraRays;
use crate::render::zbuffer::{slots_per_pixel, BandHits, Rasterizer, MAX_SIDE, MISS, SLOT_BYTES};
use crate::types::{Camera, Scene};
use glam::Vec3;
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, MemoryEstimate, NodeError, Params, PortSize, RunCtx};

/// What the camera sees of the scene's mesh, as weights on its vertices ([S] chapter 5
/// shades vertices and lets the rasteriser interpolate them): `spp` samples per pixel at
/// fixed positions (a rotated Hammersley set, the same in every pixel; `seed` rotates it),
/// each finding its nearest triangle by z-buffer rasterisation (`render::zbuffer`: near
/// clipping, perspective-correct barycentrics, both faces, the same hits as camera rays up
/// to ties on shared edges) and adding its triangle's corners, weighted by its barycentrics
/// over `spp`, to its pixel; for the samples that hit nothing it keeps their fraction and
/// the direction through their mean position, where `RasterizeVertexColors` reads the
/// environment once per pixel (the sky does not change across a pixel as geometry does).
/// Only the geometry and the camera reach it: wire the scene as loaded, not the turned
/// sky, and a sky edit leaves it alone. Runs when the camera or the geometry changes, not
/// when the colours do: `RasterizeVertexColors` then costs one weighted sum per pixel, and
/// `PttRelight` shades only the vertices listed as seen. The bytes are the same on any
/// thread count (bands of rows, triangles in index order, nearest then lowest index).
///
/// Metrics: samples per pixel, triangles drawn after clipping, the fraction of samples that
/// hit geometry, vertices seen, weights per pixel.
#[derive(Params)]
pub struct CameraHits {
    /// samples per pixel (box filter)
    #[param(default = 16, range = 1..=1024, unit = "samples/pixel")]
    pub spp: u32,
    /// rotates the in-pixel sample pattern
    #[param(default = 0, range = 0..=u32::MAX)]
    pub seed: u64,
}

inputs!(pub CameraHitsIn { scene: Scene, camera: Camera });
outputs!(pub CameraHitsOut { hits: ScreenHits });

/// One band's pixels, laid out as `ScreenHits`' arrays are (so that joining the bands
/// copies slices): entries per pixel, their vertices and weights, the missed fraction and
/// direction, and the samples that hit.
#[derive(Default)]
struct Band {
    counts: Vec<u32>,
    vertex: Vec<u32>,
    weight: Vec<f32>,
    miss: Vec<f32>,
    miss_dir: Vec<Vec3>,
    covered: u64,
}

#[node(category = "ptt", version = 2, caching = Keyed)]
impl CameraHits {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        let hits = inputs[1].and_then(|s| s.dims).map(|[w, h]| {
            let px = (w * h) as u64;
            PortSize::bytes(ScreenHits::bytes(px, px * 3 * self.spp.min(4) as u64, px * 3))
        });
        MemoryEstimate { outputs: vec![hits], working: 0 }
    }

    fn run(&self, i: CameraHitsIn, cx: &RunCtx) -> Result<CameraHitsOut, NodeError> {
        let (scene, cam) = (i.scene, i.camera);
        let (w, h) = (cam.width, cam.height);
        let pixels = (w * h) as u64;
        let spp = self.spp as usize;
        // The projected triangles and every band's z-buffer, as if all were held at once.
        if w > MAX_SIDE || h > MAX_SIDE {
            return Err(NodeError::input("camera", format!("{w} × {h} pixels: the z-buffer draws at most {MAX_SIDE} pixels a side")));
        }
        let need = scene.triangles.len() as u64 * 2 * 200
            + pixels * (slots_per_pixel(spp) * SLOT_BYTES) as u64
            + ScreenHits::bytes(pixels, pixels * 3, 0);
        if need > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "rasterising {w} × {h} pixels at {spp} samples each needs about {}, over the {} budget",
                fmt_bytes(need),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let raster = Rasterizer::new(scene, cam, self.spp, self.seed);
        cx.check()?;
        let rays = CameraRays::new(cam);
        let inv = 1.0 / spp as f32;
        // Per thread: the band's hits and z-buffer, and a pixel's triangles, reused.
        let scratch = || (BandHits::default(), Vec::<(u32, Vec3)>::with_capacity(spp));
        let bands: Vec<Band> = cx.par_map_init(raster.bands(), scratch, |(hits, tris), b| {
            let rows = raster.band_rows(b);
            raster.band_into(b, hits);
            let pixels = rows.len() * w;
            let mut out = Band {
                counts: Vec::with_capacity(pixels),
                miss: Vec::with_capacity(pixels),
                miss_dir: Vec::with_capacity(pixels),
                ..Band::default()
            };
            for p in 0..pixels {
                let (x, y) = (p % w, rows.start + p / w);
                let start = out.vertex.len();
                let (mut missed, mut ox, mut oy) = (0u32, 0.0f32, 0.0f32);
                // The pixel's triangles with their summed barycentrics, in order of first hit.
                tris.clear();
                let (tri, b1, b2) = hits.pixel(p);
                let corners = |s: usize| Vec3::new(1.0 - b1[s] - b2[s], b1[s], b2[s]);
                if tri[0] != MISS && tri.iter().all(|&t| t == tri[0]) {
                    // The common pixel: all its samples on one triangle.
                    out.covered += spp as u64;
                    tris.push((tri[0], (0..spp).fold(Vec3::ZERO, |sum, s| sum + corners(s))));
                } else {
                    for (s, &t) in tri.iter().enumerate() {
                        if t == MISS {
                            let (sx, sy) = raster.pattern()[s];
                            (ox, oy, missed) = (ox + sx, oy + sy, missed + 1);
                            continue;
                        }
                        out.covered += 1;
                        match tris.iter_mut().find(|e: &&mut (u32, Vec3)| e.0 == t) {
                            Some(e) => e.1 += corners(s),
                            None => tris.push((t, corners(s))),
                        }
                    }
                }
                for &(t, b) in tris.iter() {
                    for (v, wt) in scene.triangles[t as usize].into_iter().zip(b.to_array()) {
                        match out.vertex[start..].iter().position(|&e| e == v) {
                            Some(e) => out.weight[start + e] += wt * inv,
                            None => {
                                out.vertex.push(v);
                                out.weight.push(wt * inv);
                            }
                        }
                    }
                }
                out.counts.push((out.vertex.len() - start) as u32);
                let (m, d) = if missed > 0 {
                    // The ray through the missed samples' mean position.
                    let m = missed as f32;
                    (m * inv, rays.ray(x as f32 + ox / m, y as f32 + oy / m).1)
                } else {
                    (0.0, Vec3::ZERO)
                };
                out.miss.push(m);
                out.miss_dir.push(d);
            }
            out
        })?;
        let total: usize = bands.iter().map(|b| b.vertex.len()).sum();
        let mut out = ScreenHits {
            width: w as u32,
            height: h as u32,
            vertices: scene.positions.len() as u32,
            offsets: Vec::with_capacity(w * h + 1),
            vertex: Vec::with_capacity(total),
            weight: Vec::with_capacity(total),
            miss: Vec::with_capacity(w * h),
            miss_dir: Vec::with_capacity(w * h),
            seen: vec![],
        };
        out.offsets.push(0);
        let mut covered = 0;
        let mut seen = vec![false; scene.positions.len()];
        for band in bands {
            let mut at = *out.offsets.last().unwrap();
            out.offsets.extend(band.counts.iter().map(|&n| {
                at += n;
                at
            }));
            band.vertex.iter().for_each(|&v| seen[v as usize] = true);
            out.vertex.extend_from_slice(&band.vertex);
            out.weight.extend_from_slice(&band.weight);
            out.miss.extend_from_slice(&band.miss);
            out.miss_dir.extend_from_slice(&band.miss_dir);
            covered += band.covered;
        }
        out.seen = (0..seen.len() as u32).filter(|&v| seen[v as usize]).collect();
        cx.metric("spp", spp as f64);
        cx.metric("triangles", raster.triangles() as f64);
        cx.metric("covered_fraction", covered as f64 / (pixels * spp as u64) as f64);
        cx.metric("seen", out.seen.len() as f64);
        cx.metric("weights_per_pixel", total as f64 / pixels as f64);
        Ok(CameraHitsOut { hits: out })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builder::SceneBuilder;
    use crate::testing::{cancels_midway, first, i, run_on};
    use crate::types::{Environment, Material};
    use relume_core::{ParamValue, PortValue, Value};

    const SKY: Vec3 = Vec3::new(0.2, 0.3, 0.4);
    const GREY: Material = Material::Lambert { albedo: Vec3::splat(0.5) };

    fn ball() -> Scene {
        SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, 32, 24)
            .environment(Environment::Constant(SKY))
            .sphere("ball", Vec3::ZERO, 0.6, GREY, Vec3::ZERO, false)
            .quad("far", Vec3::new(-9.0, -9.0, -20.0), Vec3::new(18.0, 0.0, 0.0), Vec3::new(0.0, 3.0, 0.0), GREY, Vec3::ZERO)
            .build()
    }

    fn hits(s: &Scene, params: &[(&str, ParamValue)]) -> ScreenHits {
        first(&run_on::<CameraHits>(params, vec![Value::new(s.clone()), Value::new(s.camera.clone())]).expect("runs"))
    }

    #[test]
    fn every_pixel_sums_to_one_over_its_hits_and_misses() {
        let s = ball();
        let h = hits(&s, &[("spp", i(8))]);
        assert_eq!(h.offsets.len(), 32 * 24 + 1);
        let (mut full, mut empty, mut mixed) = (0, 0, 0);
        for p in 0..32 * 24 {
            let r = h.offsets[p] as usize..h.offsets[p + 1] as usize;
            let w: f32 = h.weight[r.clone()].iter().sum();
            // The samples that missed and those that hit make the whole pixel; a miss looks
            // through the pixel.
            let miss = h.miss[p];
            assert!((w + miss - 1.0).abs() < 1e-5, "pixel {p}: hits {w} + misses {miss}");
            assert_eq!(miss > 0.0, h.miss_dir[p] != Vec3::ZERO, "pixel {p}");
            if miss > 0.0 {
                let (x, y) = ((p % 32) as f32, (p / 32) as f32);
                let rays = CameraRays::new(&s.camera);
                let corners = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)].map(|(dx, dy)| rays.ray(x + dx, y + dy).1);
                let inside = corners.iter().map(|c| c.dot(h.miss_dir[p])).fold(f32::INFINITY, f32::min);
                assert!(inside > 0.999, "pixel {p}: the miss looks outside the pixel");
            }
            match (w > 0.999, w < 1e-6) {
                (true, _) => full += 1,
                (_, true) => empty += 1,
                _ => mixed += 1,
            }
            // No vertex twice in a pixel.
            let mut vs: Vec<u32> = h.vertex[r].to_vec();
            vs.sort();
            assert!(vs.windows(2).all(|w| w[0] < w[1]));
        }
        assert!(full > 100 && empty > 100 && mixed > 10, "{full} {empty} {mixed}");
        // Seen: exactly the vertices with a weight, ascending, all on the ball or the far quad.
        let mut want: Vec<u32> = h.vertex.clone();
        want.sort();
        want.dedup();
        assert_eq!(h.seen, want);
        assert!(h.seen.len() < s.positions.len(), "the ball's back is not seen");
    }

    #[test]
    fn bytes_do_not_depend_on_threads_and_the_seed_moves_the_samples() {
        let s = ball();
        let a = hits(&s, &[("spp", i(4)), ("seed", i(3))]);
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let b = one.install(|| hits(&s, &[("spp", i(4)), ("seed", i(3))]));
        assert_eq!(a.encode(), b.encode());
        assert_ne!(hits(&s, &[("spp", i(4)), ("seed", i(4))]).weight, a.weight);
    }

    #[test]
    fn an_empty_scene_is_all_background_and_huge_images_are_refused() {
        let s = SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, 8, 8).environment(Environment::Constant(SKY)).build();
        let h = hits(&s, &[("spp", i(2))]);
        assert!(h.vertex.is_empty() && h.seen.is_empty());
        assert!(h.miss.iter().all(|m| *m == 1.0));
        let mut big = ball();
        big.camera.width = 16384;
        big.camera.height = 16384;
        let e = run_on::<CameraHits>(&[("spp", i(1024))], vec![Value::new(big.clone()), Value::new(big.camera.clone())]).unwrap_err();
        assert!(e.to_string().contains("budget"), "{e}");
        // A strip too wide for the z-buffer's 16-bit pixel positions, however few its bytes.
        (big.camera.width, big.camera.height) = (MAX_SIDE + 1, 1);
        let e = run_on::<CameraHits>(&[("spp", i(1))], vec![Value::new(big.clone()), Value::new(big.camera.clone())]).unwrap_err();
        assert!(e.to_string().contains("at most 65535"), "{e}");
    }

    #[test]
    fn cancels() {
        let s = ball();
        cancels_midway::<CameraHits>(&[("spp", i(64))], vec![Value::new(s.clone()), Value::new(s.camera.clone())]);
    }
}
