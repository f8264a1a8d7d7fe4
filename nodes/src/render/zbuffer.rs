//! A z-buffer rasteriser for the pinhole camera of `camera.rs`: for each sample of a fixed
//! in-pixel pattern, the nearest triangle and the barycentrics of the point it covers — the
//! primary hit a camera ray through that sample finds — found by projecting the triangles
//! instead of tracing rays. Triangles are clipped against a near plane in front of the eye,
//! projected, binned into bands of rows, and each band is rasterised on its own (in parallel
//! by the caller), its triangles in index order: a sample keeps the nearest triangle, the
//! lower index on a tie, so any split of the bands gives the same bytes. Barycentrics are
//! interpolated perspective-correctly, so they are the world-space triangle's. Both faces of
//! a triangle are drawn, as rays hit both.

use super::camera::CameraRays;
use crate::math::rng::uniform;
use crate::types::{Camera, Scene};
use glam::Vec3;
use rayon::prelude::*;
use std::ops::Range;

/// A sample that covers no triangle.
pub const MISS: u32 = u32::MAX;

/// Rows per band: the unit of parallel work.
pub const BAND_ROWS: usize = 8;

/// The primary hit of one sample: triangle `tri` (or `MISS`) at barycentrics (b1, b2), the
/// weights of its second and third corners, as `Accel::intersect` gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleHit {
    pub tri: u32,
    pub b1: f32,
    pub b2: f32,
}

const NO_HIT: SampleHit = SampleHit { tri: MISS, b1: 0.0, b2: 0.0 };

/// The in-pixel sample positions: `spp` points of a Hammersley set (x = (s + ½)/spp, y the
/// base-2 radical inverse of s) shifted by one seeded offset modulo the pixel
/// (Cranley–Patterson rotation), the same in every pixel: well spread for any count.
pub fn sample_pattern(spp: u32, seed: u64) -> Vec<(f32, f32)> {
    let (rx, ry) = (uniform(seed ^ 0x9A77_E2A5, 0, 0), uniform(seed ^ 0x9A77_E2A5, 0, 1));
    (0..spp)
        .map(|s| {
            let y = s.reverse_bits() as f64 / 4_294_967_296.0;
            let wrap = |v: f64| (v - v.floor()).min(1.0 - 1e-7) as f32;
            (wrap((s as f64 + 0.5) / spp as f64 + rx as f64), wrap(y + ry as f64))
        })
        .collect()
}

/// A clipped, projected triangle: the barycentric of corner k at pixel position
/// (x0 + x, y0 + y), (x0, y0) the first pixel of its bounding box, is a[k] x + b[k] y + c[k]
/// (set up in f64 about that corner, evaluated in f32); `inv_z` the corners' inverse camera
/// depths; `attr` the corners' (b1, b2) on the scene triangle `tri` (a clipped corner lies
/// inside it).
struct ScreenTri {
    tri: u32,
    a: [f32; 3],
    b: [f32; 3],
    c: [f32; 3],
    inv_z: [f32; 3],
    attr: [[f32; 2]; 3],
    x: Range<usize>,
    y: Range<usize>,
}

impl ScreenTri {
    /// The three barycentrics at (x, y) pixels from the box's first pixel.
    fn beta(&self, x: f32, y: f32) -> [f32; 3] {
        [0, 1, 2].map(|k| self.a[k] * x + self.b[k] * y + self.c[k])
    }

    /// Whether no point of the pixel square at (x, y) (from the box's first pixel) can be inside.
    fn misses_pixel(&self, x: f32, y: f32) -> bool {
        let beta = self.beta(x, y);
        (0..3).any(|k| beta[k] + self.a[k].max(0.0) + self.b[k].max(0.0) < 0.0)
    }
}

/// A scene's triangles set up for one camera and sample pattern; `band(i)` rasterises the
/// rows [i·BAND_ROWS, …).
pub struct Rasterizer {
    width: usize,
    height: usize,
    pattern: Vec<(f32, f32)>,
    tris: Vec<ScreenTri>,
    bins: Vec<Vec<u32>>,
}

/// A camera-space corner: (right, up, forward) coordinates and its (b1, b2) on the triangle.
type Corner = (Vec3, [f64; 2]);

/// Clips a triangle to z ≥ `near` (one plane of Sutherland–Hodgman): at most 4 corners,
/// the first `n` of the array.
fn clip_near(poly: &[Corner; 3], near: f32) -> ([Corner; 4], usize) {
    let mut out = [poly[0]; 4];
    let mut n = 0;
    for k in 0..3 {
        let (p, q) = (poly[k], poly[(k + 1) % 3]);
        let (pin, qin) = (p.0.z >= near, q.0.z >= near);
        if pin {
            out[n] = p;
            n += 1;
        }
        if pin != qin {
            let t = (near - p.0.z) / (q.0.z - p.0.z);
            let at = |i: usize| p.1[i] + (q.1[i] - p.1[i]) * t as f64;
            let mut x = p.0 + (q.0 - p.0) * t;
            x.z = near;
            out[n] = (x, [at(0), at(1)]);
            n += 1;
        }
    }
    (out, n)
}

impl Rasterizer {
    /// Projects and bins `scene`'s triangles for `camera` with `spp` samples per pixel.
    pub fn new(scene: &Scene, camera: &Camera, spp: u32, seed: u64) -> Rasterizer {
        let (width, height) = (camera.width, camera.height);
        let rays = CameraRays::new(camera);
        // Nearer than this, geometry is cut: a hundred-thousandth of the distance to the target.
        let near = (camera.target - camera.origin).length() * 1e-5;
        let setup_one = |t: usize| {
            let corners = scene.triangles[t];
            let p = corners.map(|i| rays.to_camera(scene.positions[i as usize]));
            let poly = [(p[0], [0.0, 0.0]), (p[1], [1.0, 0.0]), (p[2], [0.0, 1.0])];
            let (clipped, n) = clip_near(&poly, near);
            // A fan over the clipped polygon: none, one or two triangles.
            (1..n.max(2) - 1).filter_map(move |k| Self::setup(&rays, t as u32, [clipped[0], clipped[k], clipped[k + 1]], width, height))
        };
        // In chunks of triangles on rayon's threads, concatenated in triangle order.
        let chunks: Vec<Vec<ScreenTri>> = (0..scene.triangles.len().div_ceil(4096))
            .into_par_iter()
            .map(|c| (c * 4096..((c + 1) * 4096).min(scene.triangles.len())).flat_map(setup_one).collect())
            .collect();
        let tris: Vec<ScreenTri> = chunks.into_iter().flatten().collect();
        let mut bins = vec![vec![]; height.div_ceil(BAND_ROWS)];
        for (i, t) in tris.iter().enumerate() {
            for bin in &mut bins[t.y.start / BAND_ROWS..t.y.end.div_ceil(BAND_ROWS)] {
                bin.push(i as u32);
            }
        }
        Rasterizer { width, height, pattern: sample_pattern(spp, seed), tris, bins }
    }

    fn setup(rays: &CameraRays, tri: u32, c: [Corner; 3], width: usize, height: usize) -> Option<ScreenTri> {
        let xy = c.map(|(p, _)| {
            let (x, y) = rays.to_pixel(p);
            [x, y]
        });
        let area = (xy[1][0] - xy[0][0]) * (xy[2][1] - xy[0][1]) - (xy[1][1] - xy[0][1]) * (xy[2][0] - xy[0][0]);
        if !area.is_finite() || area.abs() < 1e-12 {
            return None;
        }
        let lo = |d: usize| xy.iter().map(|p| p[d]).fold(f64::INFINITY, f64::min);
        let hi = |d: usize| xy.iter().map(|p| p[d]).fold(f64::NEG_INFINITY, f64::max);
        let span = |l: f64, h: f64, n: usize| (l.floor().clamp(0.0, n as f64) as usize)..(h.ceil().clamp(0.0, n as f64) as usize);
        let (x, y) = (span(lo(0), hi(0), width), span(lo(1), hi(1), height));
        if x.is_empty() || y.is_empty() {
            return None;
        }
        let (x0, y0) = (x.start as f64, y.start as f64);
        let (mut a, mut b, mut cc) = ([0.0; 3], [0.0; 3], [0.0; 3]);
        for k in 0..3 {
            // The barycentric of corner k: the edge function of the opposite edge over the area.
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let (ak, bk) = (-(xy[j][1] - xy[i][1]) / area, (xy[j][0] - xy[i][0]) / area);
            (a[k], b[k], cc[k]) = (ak as f32, bk as f32, (ak * (x0 - xy[i][0]) + bk * (y0 - xy[i][1])) as f32);
        }
        let attr = c.map(|(_, at)| [at[0] as f32, at[1] as f32]);
        Some(ScreenTri { tri, a, b, c: cc, inv_z: c.map(|(p, _)| 1.0 / p.z), attr, x, y })
    }

    /// Bands of `BAND_ROWS` rows in the image.
    pub fn bands(&self) -> usize {
        self.bins.len()
    }

    /// Rows of band `i`.
    pub fn band_rows(&self, i: usize) -> Range<usize> {
        i * BAND_ROWS..((i + 1) * BAND_ROWS).min(self.height)
    }

    /// The sample positions inside a pixel.
    pub fn pattern(&self) -> &[(f32, f32)] {
        &self.pattern
    }

    /// Triangles (after clipping) that reach the image.
    pub fn triangles(&self) -> usize {
        self.tris.len()
    }

    /// The hits of band `i`: row-major over its pixels, `spp` samples each.
    pub fn band(&self, i: usize) -> Vec<SampleHit> {
        let rows = self.band_rows(i);
        let spp = self.pattern.len();
        let mut hits = vec![NO_HIT; rows.len() * self.width * spp];
        // Inverse depths: the nearest sample has the largest; 0 is nothing yet.
        let mut inv_depth = vec![0.0f32; hits.len()];
        for &t in &self.bins[i] {
            let t = &self.tris[t as usize];
            for py in t.y.start.max(rows.start)..t.y.end.min(rows.end) {
                let fy = (py - t.y.start) as f32;
                for px in t.x.clone() {
                    let fx = (px - t.x.start) as f32;
                    if t.misses_pixel(fx, fy) {
                        continue;
                    }
                    let base = ((py - rows.start) * self.width + px) * spp;
                    for (s, &(ox, oy)) in self.pattern.iter().enumerate() {
                        let beta = t.beta(fx + ox, fy + oy);
                        if beta[0] < 0.0 || beta[1] < 0.0 || beta[2] < 0.0 {
                            continue;
                        }
                        let w = [beta[0] * t.inv_z[0], beta[1] * t.inv_z[1], beta[2] * t.inv_z[2]];
                        let iz = w[0] + w[1] + w[2];
                        if iz > inv_depth[base + s] {
                            inv_depth[base + s] = iz;
                            let at = |d: usize| (w[0] * t.attr[0][d] + w[1] * t.attr[1][d] + w[2] * t.attr[2][d]) / iz;
                            hits[base + s] = SampleHit { tri: t.tri, b1: at(0), b2: at(1) };
                        }
                    }
                }
            }
        }
        hits
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builder::SceneBuilder;
    use crate::types::accel::BuildQuality;
    use crate::types::{Accel, Material};

    const GREY: Material = Material::Lambert { albedo: Vec3::splat(0.5) };

    /// Every sample's hit against a ray traced through the same position.
    fn agrees_with_rays(scene: &Scene, spp: u32) -> (usize, usize) {
        let r = Rasterizer::new(scene, &scene.camera, spp, 3);
        let accel = Accel::build(scene, BuildQuality::Fast);
        let rays = CameraRays::new(&scene.camera);
        let w = scene.camera.width;
        let (mut hits, mut differ) = (0, 0);
        for b in 0..r.bands() {
            let band = r.band(b);
            for (k, h) in band.iter().enumerate() {
                let (s, px) = (k % spp as usize, k / spp as usize);
                let (x, y) = (px % w, r.band_rows(b).start + px / w);
                let (ox, oy) = r.pattern()[s];
                let (o, d) = rays.ray(x as f32 + ox, y as f32 + oy);
                let traced = accel.intersect(o, d, 0.0, f32::INFINITY);
                match traced {
                    Some(t) if t.tri == h.tri => {
                        hits += 1;
                        assert!((t.b1 - h.b1).abs() < 1e-3 && (t.b2 - h.b2).abs() < 1e-3, "{t:?} {h:?}");
                    }
                    None if h.tri == MISS => {}
                    _ => differ += 1,
                }
            }
        }
        (hits, differ)
    }

    #[test]
    fn the_pattern_is_spread_and_inside_the_pixel() {
        for spp in [1, 2, 5, 16, 64] {
            let p = sample_pattern(spp, 7);
            assert_eq!(p.len(), spp as usize);
            assert!(p.iter().all(|&(x, y)| (0.0..1.0).contains(&x) && (0.0..1.0).contains(&y)));
            // One point in each of the spp columns of width 1/spp.
            let mut cols: Vec<usize> = p.iter().map(|&(x, _)| (x * spp as f32) as usize).collect();
            cols.sort();
            cols.dedup();
            assert_eq!(cols.len(), spp as usize);
        }
        assert_eq!(sample_pattern(16, 1), sample_pattern(16, 1));
        assert_ne!(sample_pattern(16, 1), sample_pattern(16, 2));
    }

    #[test]
    fn hits_match_traced_rays_on_a_sphere_over_a_floor() {
        let s = SceneBuilder::new(Vec3::new(0.3, 1.2, 3.0), Vec3::ZERO, 45.0, 48, 40)
            .sphere("ball", Vec3::new(0.0, 0.4, 0.0), 0.6, GREY, Vec3::ZERO, false)
            .quad("floor", Vec3::new(-3.0, -0.2, 3.0), Vec3::new(6.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -6.0), GREY, Vec3::ZERO)
            .build();
        let (hits, differ) = agrees_with_rays(&s, 4);
        // Samples exactly on shared edges may pick either neighbour (the same point): rare.
        assert!(hits > 3000, "{hits}");
        assert!(differ * 1000 < hits, "{differ} of {hits} samples disagree with the traced rays");
    }

    #[test]
    fn a_floor_reaching_behind_the_eye_is_clipped_not_lost() {
        // The floor passes under and behind the camera: clipping must keep what is in front.
        let s = SceneBuilder::new(Vec3::new(0.0, 0.5, 0.0), Vec3::new(0.0, 0.3, -2.0), 70.0, 32, 32)
            .quad("floor", Vec3::new(-50.0, 0.0, 50.0), Vec3::new(100.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -100.0), GREY, Vec3::ZERO)
            .build();
        let (hits, differ) = agrees_with_rays(&s, 2);
        assert!(hits > 400, "{hits}");
        assert!(differ * 200 < hits, "{differ} of {hits}");
    }

    #[test]
    fn geometry_behind_the_camera_or_off_screen_draws_nothing() {
        let s = SceneBuilder::new(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0), 40.0, 16, 16)
            .sphere("behind", Vec3::new(0.0, 0.0, 3.0), 0.5, GREY, Vec3::ZERO, false)
            .sphere("aside", Vec3::new(30.0, 0.0, -3.0), 0.5, GREY, Vec3::ZERO, false)
            .build();
        let r = Rasterizer::new(&s, &s.camera, 4, 0);
        assert_eq!(r.triangles(), 0);
        assert!((0..r.bands()).all(|b| r.band(b).iter().all(|h| h.tri == MISS)));
    }

    #[test]
    fn the_nearer_of_two_overlapping_quads_wins_whatever_their_order() {
        let quad = |b: SceneBuilder, name: &str, z: f32| {
            b.quad(name, Vec3::new(-1.0, -1.0, z), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0), GREY, Vec3::ZERO)
        };
        let cam = || SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 20.0, 8, 8);
        let near_first = quad(quad(cam(), "near", 0.5), "far", 0.0).build();
        let far_first = quad(quad(cam(), "far", 0.0), "near", 0.5).build();
        let centre = |s: &Scene| {
            let r = Rasterizer::new(s, &s.camera, 1, 0);
            let h = r.band(0)[4 * 8 + 4];
            s.objects[s.tri_object[h.tri as usize] as usize].name.clone()
        };
        assert_eq!(centre(&near_first), "near");
        assert_eq!(centre(&far_first), "near");
    }
}
