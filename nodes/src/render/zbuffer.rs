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
/// inside it); the box is columns x0..x1, rows y0..y1.
struct ScreenTri {
    tri: u32,
    a: [f32; 3],
    b: [f32; 3],
    c: [f32; 3],
    inv_z: [f32; 3],
    attr: [[f32; 2]; 3],
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
}

impl ScreenTri {
    /// The three barycentrics at (x, y) pixels from the box's first pixel.
    fn beta(&self, x: f32, y: f32) -> [f32; 3] {
        [0, 1, 2].map(|k| self.a[k] * x + self.b[k] * y + self.c[k])
    }

    /// Whether no point of the pixel square whose corner has barycentrics `beta` can be inside.
    fn misses_pixel(&self, beta: &[f32; 3]) -> bool {
        (0..3).any(|k| beta[k] + self.a[k].max(0.0) + self.b[k].max(0.0) < 0.0)
    }
}

/// Samples tested together: a block of the pattern, one bit each in a mask.
const LANES: usize = 16;

/// A scene's triangles set up for one camera and sample pattern; `band(i)` rasterises the
/// rows [i·BAND_ROWS, …).
pub struct Rasterizer {
    width: usize,
    height: usize,
    pattern: Vec<(f32, f32)>,
    /// The pattern in blocks of `LANES` (x offsets, y offsets, the mask of real samples).
    blocks: Vec<([f32; LANES], [f32; LANES], u32)>,
    /// The set-up triangles in chunks of `SETUP_CHUNK` scene triangles.
    chunks: Vec<Vec<ScreenTri>>,
    /// Band i's triangles are `bin_tris[bin_start[i]..bin_start[i + 1]]`, in index order,
    /// each as (chunk << CHUNK_BITS) | place in the chunk.
    bin_start: Vec<u32>,
    bin_tris: Vec<u32>,
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

/// The corners' (b1, b2) on their own triangle.
const CORNER_ATTR: [[f64; 2]; 3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];

/// Triangles set up per parallel task.
const SETUP_CHUNK: usize = 4096;
/// Bits of a place in a chunk (clipping makes at most two triangles of one).
const CHUNK_BITS: usize = 13;

impl Rasterizer {
    /// Projects and bins `scene`'s triangles for `camera` with `spp` samples per pixel.
    pub fn new(scene: &Scene, camera: &Camera, spp: u32, seed: u64) -> Rasterizer {
        let (width, height) = (camera.width, camera.height);
        let rays = CameraRays::new(camera);
        // Nearer than this, geometry is cut: a hundred-thousandth of the distance to the target.
        let near = (camera.target - camera.origin).length() * 1e-5;
        // Every vertex projected once: camera coordinates, and pixel position when in front.
        let verts: Vec<(Vec3, [f64; 2])> = scene
            .positions
            .par_iter()
            .map(|&p| {
                let c = rays.to_camera(p);
                let (x, y) = if c.z >= near { rays.to_pixel(c) } else { (0.0, 0.0) };
                (c, [x, y])
            })
            .collect();
        let setup_one = |t: usize, out: &mut Vec<ScreenTri>| {
            let corners = scene.triangles[t].map(|i| verts[i as usize]);
            if corners.iter().all(|c| c.0.z >= near) {
                let xy = corners.map(|c| c.1);
                out.extend(Self::setup(t as u32, xy, corners.map(|c| c.0.z), CORNER_ATTR, width, height));
                return;
            }
            let poly = [0, 1, 2].map(|k| (corners[k].0, CORNER_ATTR[k]));
            let (clipped, n) = clip_near(&poly, near);
            // A fan over the clipped polygon: none, one or two triangles.
            for k in 1..n.max(2) - 1 {
                let c = [clipped[0], clipped[k], clipped[k + 1]];
                let xy = c.map(|(p, _)| {
                    let (x, y) = rays.to_pixel(p);
                    [x, y]
                });
                out.extend(Self::setup(t as u32, xy, c.map(|(p, _)| p.z), c.map(|(_, at)| at), width, height));
            }
        };
        // In chunks of triangles on rayon's threads, concatenated in triangle order.
        let chunks: Vec<Vec<ScreenTri>> = (0..scene.triangles.len().div_ceil(SETUP_CHUNK))
            .into_par_iter()
            .map(|c| {
                let mut out = Vec::with_capacity(SETUP_CHUNK);
                (c * SETUP_CHUNK..((c + 1) * SETUP_CHUNK).min(scene.triangles.len())).for_each(|t| setup_one(t, &mut out));
                out
            })
            .collect();
        // Bins as one array: counted, then filled in triangle order (chunk, then place in
        // it: `id` packs both; the chunks are never copied into one).
        let bands = height.div_ceil(BAND_ROWS);
        let span = |t: &ScreenTri| t.y0 as usize / BAND_ROWS..(t.y1 as usize).div_ceil(BAND_ROWS);
        let mut bin_start = vec![0u32; bands + 1];
        for t in chunks.iter().flatten() {
            span(t).for_each(|b| bin_start[b + 1] += 1);
        }
        for b in 0..bands {
            bin_start[b + 1] += bin_start[b];
        }
        let mut fill: Vec<u32> = bin_start[..bands].to_vec();
        let mut bin_tris = vec![0u32; bin_start[bands] as usize];
        for (c, chunk) in chunks.iter().enumerate() {
            for (k, t) in chunk.iter().enumerate() {
                for b in span(t) {
                    bin_tris[fill[b] as usize] = ((c << CHUNK_BITS) | k) as u32;
                    fill[b] += 1;
                }
            }
        }
        let pattern = sample_pattern(spp, seed);
        let blocks = pattern
            .chunks(LANES)
            .map(|c| {
                let (mut x, mut y) = ([0.0; LANES], [0.0; LANES]);
                for (s, &(ox, oy)) in c.iter().enumerate() {
                    (x[s], y[s]) = (ox, oy);
                }
                (x, y, if c.len() == LANES { u32::MAX >> (32 - LANES) } else { (1u32 << c.len()) - 1 })
            })
            .collect();
        Rasterizer { width, height, pattern, blocks, chunks, bin_start, bin_tris }
    }

    /// A projected triangle with corners at pixel positions `xy`, camera depths `z` and
    /// scene-triangle barycentrics `attr`; none when degenerate or off the image.
    fn setup(tri: u32, xy: [[f64; 2]; 3], z: [f32; 3], attr: [[f64; 2]; 3], width: usize, height: usize) -> Option<ScreenTri> {
        let area = (xy[1][0] - xy[0][0]) * (xy[2][1] - xy[0][1]) - (xy[1][1] - xy[0][1]) * (xy[2][0] - xy[0][0]);
        if !area.is_finite() || area.abs() < 1e-12 {
            return None;
        }
        let lo = |d: usize| xy[0][d].min(xy[1][d]).min(xy[2][d]);
        let hi = |d: usize| xy[0][d].max(xy[1][d]).max(xy[2][d]);
        let span = |l: f64, h: f64, n: usize| (l.floor().clamp(0.0, n as f64) as u32, h.ceil().clamp(0.0, n as f64) as u32);
        let ((x0, x1), (y0, y1)) = (span(lo(0), hi(0), width), span(lo(1), hi(1), height));
        if x0 >= x1 || y0 >= y1 {
            return None;
        }
        let (fx0, fy0) = (x0 as f64, y0 as f64);
        let inv_area = 1.0 / area;
        let (mut a, mut b, mut cc) = ([0.0; 3], [0.0; 3], [0.0; 3]);
        for k in 0..3 {
            // The barycentric of corner k: the edge function of the opposite edge over the area.
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let (ak, bk) = (-(xy[j][1] - xy[i][1]) * inv_area, (xy[j][0] - xy[i][0]) * inv_area);
            (a[k], b[k], cc[k]) = (ak as f32, bk as f32, (ak * (fx0 - xy[i][0]) + bk * (fy0 - xy[i][1])) as f32);
        }
        let attr = attr.map(|at| [at[0] as f32, at[1] as f32]);
        Some(ScreenTri { tri, a, b, c: cc, inv_z: z.map(|z| 1.0 / z), attr, x0, x1, y0, y1 })
    }

    /// Bands of `BAND_ROWS` rows in the image.
    pub fn bands(&self) -> usize {
        self.bin_start.len() - 1
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
        self.chunks.iter().map(Vec::len).sum()
    }

    /// The hits of band `i`: row-major over its pixels, `spp` samples each.
    pub fn band(&self, i: usize) -> Vec<SampleHit> {
        let (mut hits, mut depth) = (vec![], vec![]);
        self.band_into(i, &mut hits, &mut depth);
        hits
    }

    /// As `band`, into `hits`, with `inv_depth` as the z-buffer: both overwritten, their
    /// allocations reused from band to band.
    pub fn band_into(&self, i: usize, hits: &mut Vec<SampleHit>, inv_depth: &mut Vec<f32>) {
        let rows = self.band_rows(i);
        let spp = self.pattern.len();
        let n = rows.len() * self.width * spp;
        hits.clear();
        hits.resize(n, NO_HIT);
        // Inverse depths: the nearest sample has the largest; 0 is nothing yet.
        inv_depth.clear();
        inv_depth.resize(n, 0.0);
        let bin = &self.bin_tris[self.bin_start[i] as usize..self.bin_start[i + 1] as usize];
        for &t in bin {
            let t = &self.chunks[t as usize >> CHUNK_BITS][t as usize & ((1 << CHUNK_BITS) - 1)];
            for py in (t.y0 as usize).max(rows.start)..(t.y1 as usize).min(rows.end) {
                let fy = (py - t.y0 as usize) as f32;
                for px in t.x0 as usize..t.x1 as usize {
                    let corner = t.beta((px - t.x0 as usize) as f32, fy);
                    if t.misses_pixel(&corner) {
                        continue;
                    }
                    let base = ((py - rows.start) * self.width + px) * spp;
                    for (block, (ox, oy, valid)) in self.blocks.iter().enumerate() {
                        // The barycentrics at each sample, offsets from the pixel's corner.
                        let at = |s: usize, k: usize| corner[k] + t.a[k] * ox[s] + t.b[k] * oy[s];
                        // Branch-free over the block, so that it vectorises.
                        let mut inside = [0u32; LANES];
                        for (s, v) in inside.iter_mut().enumerate() {
                            *v = ((at(s, 0) >= 0.0) & (at(s, 1) >= 0.0) & (at(s, 2) >= 0.0)) as u32;
                        }
                        let mut mask = inside.iter().enumerate().fold(0u32, |m, (s, &v)| m | v << s) & valid;
                        while mask != 0 {
                            let s = mask.trailing_zeros() as usize;
                            mask &= mask - 1;
                            let w = [0, 1, 2].map(|k| at(s, k) * t.inv_z[k]);
                            let iz = w[0] + w[1] + w[2];
                            let slot = base + block * LANES + s;
                            if iz > inv_depth[slot] {
                                inv_depth[slot] = iz;
                                let attr = |d: usize| (w[0] * t.attr[0][d] + w[1] * t.attr[1][d] + w[2] * t.attr[2][d]) / iz;
                                hits[slot] = SampleHit { tri: t.tri, b1: attr(0), b2: attr(1) };
                            }
                        }
                    }
                }
            }
        }
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
