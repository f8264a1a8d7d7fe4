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

/// The widest and tallest image the rasteriser draws (pixel positions are kept in 16 bits).
pub const MAX_SIDE: usize = u16::MAX as usize;

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
/// (ox + x, oy + y), (ox, oy) = `origin` the first pixel of its bounding box, is a[k] x + b[k] y + c[k]
/// (set up in f64 about that corner, evaluated in f32); `inv_z` the corners' inverse camera
/// depths; `attr` the corners' (b1, b2) on the scene triangle `tri` (a clipped corner lies
/// inside it); the pixels whose samples can reach it are columns x0..x1, rows y0..y1.
struct ScreenTri {
    tri: u32,
    a: [f32; 3],
    b: [f32; 3],
    c: [f32; 3],
    inv_z: [f32; 3],
    attr: [[f32; 2]; 3],
    origin: [u16; 2],
    x0: u16,
    x1: u16,
    y0: u16,
    y1: u16,
}

impl ScreenTri {
    /// The three barycentrics at (x, y) pixels from the box's first pixel.
    fn beta(&self, x: f32, y: f32) -> [f32; 3] {
        [0, 1, 2].map(|k| self.a[k] * x + self.b[k] * y + self.c[k])
    }

    /// Whether no sample of the pixel whose corner has barycentrics `beta` can be inside:
    /// the samples lie in the box `ext` (x from, x to, y from, y to) of offsets from the
    /// corner, where each barycentric is largest at one of the box's corners.
    fn misses_pixel(&self, beta: &[f32; 3], ext: &[f32; 4]) -> bool {
        (0..3).any(|k| beta[k] + (self.a[k] * ext[0]).max(self.a[k] * ext[1]) + (self.b[k] * ext[2]).max(self.b[k] * ext[3]) < 0.0)
    }
}

/// How many of a band's triangles ahead their set-up is fetched.
const PREFETCH_AHEAD: usize = 8;

/// Samples tested together at most: a block of the pattern.
const LANES: usize = 16;

/// The samples tested together for `spp` samples a pixel: a power of two up to `LANES`.
fn lanes_for(spp: usize) -> usize {
    spp.next_power_of_two().min(LANES)
}

/// Z-buffer slots per pixel for `spp` samples: `spp` rounded up to whole blocks of
/// `lanes_for(spp)` (the slots past `spp` are never covered).
pub fn slots_per_pixel(spp: usize) -> usize {
    spp.div_ceil(lanes_for(spp)) * lanes_for(spp)
}

/// Bytes of z-buffer per slot (inverse depth, triangle, two barycentrics).
pub const SLOT_BYTES: usize = 16;

/// One band's z-buffer, its arrays reused from band to band: per pixel (row-major)
/// `slots_per_pixel(spp)` slots, the first `spp` of them its samples.
#[derive(Default)]
pub struct BandHits {
    spp: usize,
    stride: usize,
    inv_depth: Vec<f32>,
    tri: Vec<u32>,
    b1: Vec<f32>,
    b2: Vec<f32>,
}

impl BandHits {
    /// Sample `s` of pixel `p` of the band (pixels row-major from the band's first row).
    #[inline]
    pub fn hit(&self, p: usize, s: usize) -> SampleHit {
        let k = p * self.stride + s;
        SampleHit { tri: self.tri[k], b1: self.b1[k], b2: self.b2[k] }
    }

    /// Pixel `p`'s samples: their triangles and barycentrics (b1, b2).
    #[inline]
    pub fn pixel(&self, p: usize) -> (&[u32], &[f32], &[f32]) {
        let r = p * self.stride..p * self.stride + self.spp;
        (&self.tri[r.clone()], &self.b1[r.clone()], &self.b2[r])
    }

    /// With one sample a pixel: every pixel's triangle, barycentrics (b1, b2) and inverse
    /// depth, row-major.
    pub fn single(&self) -> (&[u32], &[f32], &[f32], &[f32]) {
        assert_eq!((self.spp, self.stride), (1, 1), "one sample a pixel");
        (&self.tri, &self.b1, &self.b2, &self.inv_depth)
    }

    /// Cleared for `pixels` pixels of `stride` slots: nothing hit, nothing near.
    fn reset(&mut self, pixels: usize, spp: usize, stride: usize) {
        let n = pixels * stride;
        (self.spp, self.stride) = (spp, stride);
        for v in [&mut self.inv_depth, &mut self.b1, &mut self.b2] {
            v.clear();
            v.resize(n, 0.0);
        }
        self.tri.clear();
        self.tri.resize(n, MISS);
    }
}

/// An in-pixel sample pattern laid out for the lanes.
struct Pattern {
    points: Vec<(f32, f32)>,
    /// The box the pattern spans in a pixel: x from, x to, y from, y to.
    extent: [f32; 4],
    /// The pattern's x and y offsets over a pixel's slots; NaN in the slots past the
    /// pattern, so that no triangle covers them.
    slot_x: Vec<f32>,
    slot_y: Vec<f32>,
}

impl Pattern {
    fn new(points: Vec<(f32, f32)>) -> Pattern {
        let extent = pattern_extent(&points);
        let slots = slots_per_pixel(points.len());
        let slot = |s: usize, f: fn(&(f32, f32)) -> f32| points.get(s).map_or(f32::NAN, f);
        let slot_x = (0..slots).map(|s| slot(s, |p| p.0)).collect();
        let slot_y = (0..slots).map(|s| slot(s, |p| p.1)).collect();
        Pattern { points, extent, slot_x, slot_y }
    }
}

/// The pixels of a band to draw: per pixel of the band (row-major), its place in the
/// band's z-buffer, or `SKIP`.
pub const SKIP: u32 = u32::MAX;

/// A scene's triangles set up for one camera and sample pattern; `band(i)` rasterises
/// the rows [i·BAND_ROWS, …).
pub struct Rasterizer {
    width: usize,
    height: usize,
    pattern: Pattern,
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

/// Pixels of slack around a triangle's bounds when choosing the pixels that may reach it.
const SPAN_MARGIN: f64 = 1e-3;

/// ⌊v⌋ clamped to 0 ..= n (by integer conversion: baseline x86-64 has no rounding
/// instruction, and `f64::floor` is a library call there).
fn floor_in(v: f64, n: usize) -> u32 {
    v.clamp(0.0, n as f64) as u32
}

/// ⌈v⌉ clamped to 0 ..= n.
fn ceil_in(v: f64, n: usize) -> u32 {
    let c = v.clamp(0.0, n as f64);
    let t = c as u32;
    t + ((t as f64) < c) as u32
}

/// The box a sample pattern spans inside the pixel: x from, x to, y from, y to.
fn pattern_extent(pattern: &[(f32, f32)]) -> [f32; 4] {
    let fold =
        |f: fn(&(f32, f32)) -> f32| pattern.iter().map(f).fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let ((x0, x1), (y0, y1)) = (fold(|p| p.0), fold(|p| p.1));
    [x0, x1, y0, y1]
}

/// The corners' (b1, b2) on their own triangle.
const CORNER_ATTR: [[f64; 2]; 3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];

/// Relative to the eye's and the scene's distances from the origin, how far behind the eye a
/// triangle's plane must pass for `build` to cull it by its plane alone.
const FACING_MARGIN: f32 = 1e-3;

/// Triangles set up per parallel task (a multiple of 64).
const SETUP_CHUNK: usize = 4096;
/// Bits of a place in a chunk (clipping makes at most two triangles of one).
const CHUNK_BITS: usize = 13;

/// Pixel p has samples from p + `from` to p + `to` along an axis of `n` pixels: it can reach
/// coordinates ≥ l when p ≥ l − to, and ≤ h when p ≤ h − from (with a margin for the
/// rounding of the f32 inside test). The first pixel that can reach l, and one past the
/// last that can reach h, clamped to the image: both are monotone in their coordinate, so
/// a triangle's span is the least of its corners' firsts to the largest of their lasts.
fn span_first(l: f64, to: f64, n: usize) -> u32 {
    ceil_in(l - to - SPAN_MARGIN, n)
}

fn span_end(h: f64, from: f64, n: usize) -> u32 {
    let last = h - from + SPAN_MARGIN;
    if last < 0.0 {
        0
    } else {
        (floor_in(last, n) + 1).min(n as u32)
    }
}

/// A scene's vertices projected for one camera: camera coordinates and, in front of the
/// near plane, pixel position; what every pattern's rasteriser starts from.
pub struct Projection {
    width: usize,
    height: usize,
    rays: CameraRays,
    /// Nearer than this, geometry is cut.
    near: f32,
    /// Per vertex, camera coordinates and (in front of the near plane) pixel position, apart:
    /// the triangles' set-up gathers the positions of all it looks at and the depths of only
    /// those it keeps, and the positions alone stay in the second-level cache.
    cam: Vec<Vec3>,
    xy: Vec<[f64; 2]>,
    /// Leave out the triangles that face away from the camera.
    cull: bool,
    /// The eye, in world space.
    eye: Vec3,
    /// Culling, turn away by their planes first the triangles clearly facing away (`build`).
    planes_first: bool,
}

impl Projection {
    /// Projects `scene`'s vertices for `camera`; the image's sides must be at most `MAX_SIDE`.
    pub fn new(scene: &Scene, camera: &Camera) -> Projection {
        let (width, height) = (camera.width, camera.height);
        assert!(width <= MAX_SIDE && height <= MAX_SIDE, "{width} × {height} pixels: the z-buffer draws at most {MAX_SIDE} a side");
        let rays = CameraRays::new(camera);
        // A hundred-thousandth of the distance to the target.
        let near = (camera.target - camera.origin).length() * 1e-5;
        let (cam, xy) = scene
            .positions
            .par_iter()
            .map(|&p| {
                let c = rays.to_camera(p);
                let (x, y) = if c.z >= near { rays.to_pixel(c) } else { (0.0, 0.0) };
                (c, [x, y])
            })
            .unzip();
        Projection { width, height, rays, near, cam, xy, cull: false, eye: camera.origin, planes_first: true }
    }

    /// The same projection, leaving out (`on`) the triangles whose corners turn clockwise
    /// as the camera sees them: the back faces of meshes wound counter-clockwise seen from
    /// outside, which a closed mesh always hides behind its front. Those whose plane passes
    /// clearly behind the eye are turned away by the scene's `triangle_planes` before their
    /// corners are read.
    pub fn cull_back_faces(mut self, on: bool) -> Projection {
        self.cull = on;
        self
    }

    /// Per vertex, the ends of the spans its position gives for samples in the box `ext`
    /// (`span_first` and `span_end` along x, then y; at most `MAX_SIDE`, so 16 bits each:
    /// half the bytes the triangles gather them from), or `BEHIND` when the vertex lies
    /// nearer than the near plane (it has no position).
    fn vertex_spans(&self, ext: [f64; 4]) -> Vec<[u16; 4]> {
        let (w, h, near) = (self.width, self.height, self.near);
        let at = |(c, xy): (&Vec3, &[f64; 2])| {
            if c.z < near {
                return BEHIND;
            }
            [span_first(xy[0], ext[1], w), span_end(xy[0], ext[0], w), span_first(xy[1], ext[3], h), span_end(xy[1], ext[2], h)]
                .map(|v| v as u16)
        };
        self.cam.par_iter().zip(&self.xy).map(at).collect()
    }
}

impl Projection {
    /// Scene triangle `t` set up for samples in the box `ext` (`spans` its vertices'
    /// `vertex_spans` for it), clipped to the near plane (none, one or two screen
    /// triangles), each handed to `out` when its pixel box is not empty and `keep` takes it.
    fn screen_tris(
        &self,
        scene: &Scene,
        t: usize,
        ext: [f64; 4],
        spans: &[[u16; 4]],
        keep: &impl Fn([u32; 4]) -> bool,
        mut out: impl FnMut(ScreenTri),
    ) {
        let (width, height) = (self.width, self.height);
        let ids = scene.triangles[t];
        let s = ids.map(|i| spans[i as usize]);
        if (s[0][0] <= s[0][1]) & (s[1][0] <= s[1][1]) & (s[2][0] <= s[2][1]) {
            // The span from the corners' (most triangles reach no pixel of a sparse
            // pattern, and stop here).
            let box_ = [
                s[0][0].min(s[1][0]).min(s[2][0]),
                s[0][1].max(s[1][1]).max(s[2][1]),
                s[0][2].min(s[1][2]).min(s[2][2]),
                s[0][3].max(s[1][3]).max(s[2][3]),
            ]
            .map(u32::from);
            if box_[0] >= box_[1] || box_[2] >= box_[3] || !keep(box_) {
                return;
            }
            let xy = ids.map(|i| self.xy[i as usize]);
            let z = || ids.map(|i| self.cam[i as usize].z);
            if let Some(st) = Rasterizer::setup(t as u32, xy, z, CORNER_ATTR, box_, (width, height), self.cull) {
                out(st);
            }
            return;
        }
        let poly = [0, 1, 2].map(|k| (self.cam[ids[k] as usize], CORNER_ATTR[k]));
        let (clipped, n) = clip_near(&poly, self.near);
        // A fan over the clipped polygon: none, one or two triangles.
        for k in 1..n.max(2) - 1 {
            let c = [clipped[0], clipped[k], clipped[k + 1]];
            let xy = c.map(|(p, _)| {
                let (x, y) = self.rays.to_pixel(p);
                [x, y]
            });
            let lo = |d: usize| xy[0][d].min(xy[1][d]).min(xy[2][d]);
            let hi = |d: usize| xy[0][d].max(xy[1][d]).max(xy[2][d]);
            let box_ = [
                span_first(lo(0), ext[1], width),
                span_end(hi(0), ext[0], width),
                span_first(lo(1), ext[3], height),
                span_end(hi(1), ext[2], height),
            ];
            if box_[0] >= box_[1] || box_[2] >= box_[3] || !keep(box_) {
                continue;
            }
            if let Some(st) = Rasterizer::setup(t as u32, xy, || c.map(|(p, _)| p.z), c.map(|(_, at)| at), box_, (width, height), self.cull)
            {
                out(st);
            }
        }
    }
}

/// A vertex behind the near plane in `vertex_spans`: its x span's first past its end, which
/// no position gives (`span_first` ≤ `span_end` for one coordinate, clamped or not).
const BEHIND: [u16; 4] = [1, 0, 0, 0];

impl Rasterizer {
    /// Projects and bins `scene`'s triangles for `camera` with `spp` samples per pixel; the
    /// image's sides must be at most `MAX_SIDE`.
    pub fn new(scene: &Scene, camera: &Camera, spp: u32, seed: u64) -> Rasterizer {
        Self::with_projection(scene, &Projection::new(scene, camera), spp, seed)
    }

    /// As `new`, from a projection made once for several rasterisers.
    pub fn with_projection(scene: &Scene, projection: &Projection, spp: u32, seed: u64) -> Rasterizer {
        Self::build(scene, projection, Pattern::new(sample_pattern(spp, seed)), |_| true)
    }

    /// One sample at each pixel's centre, from a projection made once for several
    /// rasterisers.
    pub fn centres(scene: &Scene, projection: &Projection) -> Rasterizer {
        Self::build(scene, projection, Pattern::new(vec![(0.5, 0.5)]), |_| true)
    }

    /// `spp` samples per pixel, keeping only the triangles whose pixel box (columns x0..x1,
    /// rows y0..y1 as `[x0, x1, y0, y1]`) `keep` takes: for drawing some pixels
    /// (`band_pixels_into`) without setting up the triangles that reach none of them.
    pub fn for_pixels(scene: &Scene, projection: &Projection, spp: u32, seed: u64, keep: impl Fn([u32; 4]) -> bool + Sync) -> Rasterizer {
        Self::build(scene, projection, Pattern::new(sample_pattern(spp, seed)), keep)
    }

    fn build(scene: &Scene, proj: &Projection, pattern: Pattern, keep: impl Fn([u32; 4]) -> bool + Sync) -> Rasterizer {
        let (width, height) = (proj.width, proj.height);
        let ext = pattern.extent.map(f64::from);
        let spans = proj.vertex_spans(ext);
        // Culling, a triangle whose plane passes clearly behind the eye is turned away by its
        // plane alone, before its corners are read: the set-up would find its corners turning
        // clockwise and drop it (the margin, a thousandth of the eye's and the scene's reach,
        // stands far above the rounding of either test; within it the set-up decides).
        let away = (proj.cull && proj.planes_first).then(|| {
            let planes = scene.triangle_planes();
            (planes, FACING_MARGIN * (proj.eye.length() + planes.radius))
        });
        let setup_one = |t: usize, out: &mut Vec<ScreenTri>| proj.screen_tris(scene, t, ext, &spans, &keep, |st| out.push(st));
        // In chunks of triangles on rayon's threads, concatenated in triangle order.
        let chunks: Vec<Vec<ScreenTri>> = (0..scene.triangles.len().div_ceil(SETUP_CHUNK))
            .into_par_iter()
            .map(|c| {
                let mut out = Vec::new();
                let tris = c * SETUP_CHUNK..((c + 1) * SETUP_CHUNK).min(scene.triangles.len());
                match away {
                    Some((planes, margin)) => {
                        // The chunk's triangles not turned away, as bits found without a
                        // branch a triangle (which way one faces follows no order a branch
                        // predictor learns), then those of the set bits in order.
                        let mut set = [0u64; SETUP_CHUNK / 64];
                        for (k, t) in tris.clone().enumerate() {
                            set[k / 64] |= (!planes.faces_away(t, proj.eye, margin) as u64) << (k % 64);
                        }
                        for (i, &word) in set.iter().enumerate() {
                            let mut word = word;
                            while word != 0 {
                                setup_one(tris.start + i * 64 + word.trailing_zeros() as usize, &mut out);
                                word &= word - 1;
                            }
                        }
                    }
                    None => tris.for_each(|t| setup_one(t, &mut out)),
                }
                out
            })
            .collect();
        // Bins as one array, in triangle order (chunk, then place in it: `id` packs both; the
        // chunks are never copied into one): each chunk's triangles counted per band and
        // filled into their runs of the bands' bins on rayon's threads, a chunk per task.
        let bands = height.div_ceil(BAND_ROWS);
        let span = |t: &ScreenTri| t.y0 as usize / BAND_ROWS..(t.y1 as usize).div_ceil(BAND_ROWS);
        let counts: Vec<Vec<u32>> = chunks
            .par_iter()
            .map(|chunk| {
                let mut n = vec![0u32; bands];
                chunk.iter().for_each(|t| span(t).for_each(|b| n[b] += 1));
                n
            })
            .collect();
        let mut bin_start = vec![0u32; bands + 1];
        for b in 0..bands {
            bin_start[b + 1] = bin_start[b] + counts.iter().map(|n| n[b]).sum::<u32>();
        }
        let mut bin_tris = vec![0u32; bin_start[bands] as usize];
        // Each chunk's run in each band's bin: the bins split band by band, chunk by chunk.
        let mut runs: Vec<Vec<&mut [u32]>> = chunks.iter().map(|_| Vec::with_capacity(bands)).collect();
        let mut rest = &mut bin_tris[..];
        for b in 0..bands {
            for (c, n) in counts.iter().enumerate() {
                let (run, tail) = rest.split_at_mut(n[b] as usize);
                runs[c].push(run);
                rest = tail;
            }
        }
        runs.into_par_iter().zip(&chunks).enumerate().for_each(|(c, (mut runs, chunk))| {
            let mut at = vec![0usize; bands];
            for (k, t) in chunk.iter().enumerate() {
                for b in span(t) {
                    runs[b][at[b]] = ((c << CHUNK_BITS) | k) as u32;
                    at[b] += 1;
                }
            }
        });
        Rasterizer { width, height, pattern, chunks, bin_start, bin_tris }
    }

    /// A projected triangle with corners at pixel positions `xy`, camera depths `z()` and
    /// scene-triangle barycentrics `attr`, drawn in the pixels of `box_` (columns x0..x1,
    /// rows y0..y1: those whose samples can reach its bounds, non-empty); none when
    /// degenerate, or facing away from the camera when `cull`. With one sample a pixel, a triangle smaller than a pixel usually has
    /// no such pixel and is not set up at all.
    fn setup(
        tri: u32,
        xy: [[f64; 2]; 3],
        z: impl FnOnce() -> [f32; 3],
        attr: [[f64; 2]; 3],
        box_: [u32; 4],
        (width, height): (usize, usize),
        cull: bool,
    ) -> Option<ScreenTri> {
        let area = (xy[1][0] - xy[0][0]) * (xy[2][1] - xy[0][1]) - (xy[1][1] - xy[0][1]) * (xy[2][0] - xy[0][0]);
        // Pixel rows grow downwards: a counter-clockwise triangle has a negative area.
        if !area.is_finite() || area.abs() < 1e-12 || (cull && area > 0.0) {
            return None;
        }
        let lo = |d: usize| xy[0][d].min(xy[1][d]).min(xy[2][d]);
        // The barycentrics are set up about the first pixel of the triangle's bounding box.
        let origin = [floor_in(lo(0), width), floor_in(lo(1), height)];
        let (fx0, fy0) = (origin[0] as f64, origin[1] as f64);
        let inv_area = 1.0 / area;
        let (mut a, mut b, mut cc) = ([0.0; 3], [0.0; 3], [0.0; 3]);
        for k in 0..3 {
            // The barycentric of corner k: the edge function of the opposite edge over the area.
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let (ak, bk) = (-(xy[j][1] - xy[i][1]) * inv_area, (xy[j][0] - xy[i][0]) * inv_area);
            (a[k], b[k], cc[k]) = (ak as f32, bk as f32, (ak * (fx0 - xy[i][0]) + bk * (fy0 - xy[i][1])) as f32);
        }
        let attr = attr.map(|at| [at[0] as f32, at[1] as f32]);
        let [x0, x1, y0, y1] = box_.map(|v| v as u16);
        Some(ScreenTri { tri, a, b, c: cc, inv_z: z().map(|z| 1.0 / z), attr, origin: origin.map(|o| o as u16), x0, x1, y0, y1 })
    }

    /// The image's width in pixels.
    pub fn width(&self) -> usize {
        self.width
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
        &self.pattern.points
    }

    /// Triangles (after clipping) that reach the image.
    pub fn triangles(&self) -> usize {
        self.chunks.iter().map(Vec::len).sum()
    }

    /// The hits of band `i`: row-major over its pixels, `spp` samples each.
    pub fn band(&self, i: usize) -> Vec<SampleHit> {
        let mut buf = BandHits::default();
        self.band_into(i, &mut buf);
        let pixels = self.band_rows(i).len() * self.width;
        (0..pixels).flat_map(|p| (0..self.pattern.points.len()).map(move |s| (p, s))).map(|(p, s)| buf.hit(p, s)).collect()
    }

    /// As `band`, into `buf` (overwritten, its arrays reused from band to band). The
    /// samples of a pixel are tested in blocks of `lanes_for(spp)` without branches, so
    /// that they vectorise; on a processor with AVX2 the same code runs compiled for it
    /// (eight lanes wide instead of four; no fused multiply-adds, so the bytes are the same).
    pub fn band_into(&self, i: usize, buf: &mut BandHits) {
        self.draw(i, buf, &self.pattern, None)
    }

    /// As `band_into` for some of the band's pixels: `place[p]` is pixel p's place in `buf`
    /// (pixels row-major from the band's first row; `SKIP` draws nothing there), the places
    /// 0..`count`.
    pub fn band_pixels_into(&self, i: usize, place: &[u32], count: usize, buf: &mut BandHits) {
        assert_eq!(place.len(), self.band_rows(i).len() * self.width, "one place per pixel of the band");
        self.draw(i, buf, &self.pattern, Some((place, count)))
    }

    fn draw(&self, i: usize, buf: &mut BandHits, pattern: &Pattern, place: Option<(&[u32], usize)>) {
        match lanes_for(pattern.points.len()) {
            1 => self.band_lanes::<1>(i, buf, pattern, place),
            2 => self.band_lanes::<2>(i, buf, pattern, place),
            4 => self.band_lanes::<4>(i, buf, pattern, place),
            8 => self.band_lanes::<8>(i, buf, pattern, place),
            _ => self.band_lanes::<LANES>(i, buf, pattern, place),
        }
    }

    fn band_lanes<const L: usize>(&self, i: usize, buf: &mut BandHits, pattern: &Pattern, place: Option<(&[u32], usize)>) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has just been found to have AVX2.
            return unsafe { self.band_avx2::<L>(i, buf, pattern, place) };
        }
        self.band_any::<L>(i, buf, pattern, place)
    }

    /// `band_any` compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn band_avx2<const L: usize>(&self, i: usize, buf: &mut BandHits, pattern: &Pattern, place: Option<(&[u32], usize)>) {
        self.band_any::<L>(i, buf, pattern, place)
    }

    /// `draw` with blocks of `L` samples, for any processor.
    #[inline(always)]
    fn band_any<const L: usize>(&self, i: usize, buf: &mut BandHits, pattern: &Pattern, place: Option<(&[u32], usize)>) {
        let rows = self.band_rows(i);
        let stride = pattern.slot_x.len();
        let Pattern { points, extent, slot_x, slot_y } = pattern;
        // Inverse depths: the nearest sample has the largest; 0 is nothing yet.
        buf.reset(place.map_or(rows.len() * self.width, |p| p.1), points.len(), stride);
        let BandHits { inv_depth, tri: hit_tri, b1: hit_b1, b2: hit_b2, .. } = buf;
        let bin = &self.bin_tris[self.bin_start[i] as usize..self.bin_start[i + 1] as usize];
        let screen_tri = |t: u32| &self.chunks[t as usize >> CHUNK_BITS][t as usize & ((1 << CHUNK_BITS) - 1)];
        for (k, &t) in bin.iter().enumerate() {
            // A band's triangles lie far apart in memory: fetch a few ahead (both of the
            // cache lines one may straddle) while drawing this one.
            if let Some(&ahead) = bin.get(k + PREFETCH_AHEAD) {
                let ahead = screen_tri(ahead);
                crate::math::prefetch(ahead);
                crate::math::prefetch(&ahead.y1);
            }
            let t = screen_tri(t);
            for py in (t.y0 as usize).max(rows.start)..(t.y1 as usize).min(rows.end) {
                let fy = (py as i32 - t.origin[1] as i32) as f32;
                for px in t.x0 as usize..t.x1 as usize {
                    let mut at_pixel = (py - rows.start) * self.width + px;
                    if let Some((place, _)) = place {
                        match place[at_pixel] {
                            SKIP => continue,
                            k => at_pixel = k as usize,
                        }
                    }
                    let corner = t.beta((px as i32 - t.origin[0] as i32) as f32, fy);
                    if t.misses_pixel(&corner, extent) {
                        continue;
                    }
                    let base = at_pixel * stride;
                    for block in (0..stride).step_by(L) {
                        let at = base + block;
                        let ox: &[f32; L] = slot_x[block..block + L].try_into().unwrap();
                        let oy: &[f32; L] = slot_y[block..block + L].try_into().unwrap();
                        let depth: &mut [f32; L] = (&mut inv_depth[at..at + L]).try_into().unwrap();
                        let tri: &mut [u32; L] = (&mut hit_tri[at..at + L]).try_into().unwrap();
                        let b1: &mut [f32; L] = (&mut hit_b1[at..at + L]).try_into().unwrap();
                        let b2: &mut [f32; L] = (&mut hit_b2[at..at + L]).try_into().unwrap();
                        let (c, a, b, z, at) = (corner, t.a, t.b, t.inv_z, t.attr);
                        // Lane by lane, each step its own loop, so that every one vectorises.
                        let (mut w0, mut w1, mut w2, mut inside) = ([0.0f32; L], [0.0f32; L], [0.0f32; L], [0u32; L]);
                        for s in 0..L {
                            // The barycentrics at the sample, offsets from the pixel's corner.
                            let l = [
                                c[0] + a[0] * ox[s] + b[0] * oy[s],
                                c[1] + a[1] * ox[s] + b[1] * oy[s],
                                c[2] + a[2] * ox[s] + b[2] * oy[s],
                            ];
                            inside[s] = ((l[0] >= 0.0) & (l[1] >= 0.0) & (l[2] >= 0.0)) as u32;
                            (w0[s], w1[s], w2[s]) = (l[0] * z[0], l[1] * z[1], l[2] * z[2]);
                        }
                        for s in 0..L {
                            let iz = w0[s] + w1[s] + w2[s];
                            // All ones where the sample is covered and nearer, as a bit mask
                            // (selects on bits vectorise where selects on bools branch).
                            let m = (inside[s] & (iz > depth[s]) as u32).wrapping_neg();
                            let pick = |new: u32, old: u32| (new & m) | (old & !m);
                            let pickf = |new: f32, old: f32| f32::from_bits(pick(new.to_bits(), old.to_bits()));
                            // Divided by the inverse depth once the band is drawn.
                            let n1 = w0[s] * at[0][0] + w1[s] * at[1][0] + w2[s] * at[2][0];
                            let n2 = w0[s] * at[0][1] + w1[s] * at[1][1] + w2[s] * at[2][1];
                            depth[s] = pickf(iz, depth[s]);
                            tri[s] = pick(t.tri, tri[s]);
                            b1[s] = pickf(n1, b1[s]);
                            b2[s] = pickf(n2, b2[s]);
                        }
                    }
                }
            }
        }
        // Perspective-correct barycentrics: the nearest triangle's sums over its inverse depth
        // (a miss keeps its zeros).
        for ((b1, b2), &iz) in hit_b1.iter_mut().zip(hit_b2.iter_mut()).zip(inv_depth.iter()) {
            let d = if iz > 0.0 { iz } else { 1.0 };
            (*b1, *b2) = (*b1 / d, *b2 / d);
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
        // One lane, four, four with one padded, sixteen, and two blocks of sixteen.
        for spp in [1, 4, 3, 16, 20] {
            let (hits, differ) = agrees_with_rays(&s, spp);
            // Samples exactly on shared edges may pick either neighbour (the same point): rare.
            assert!(hits > 800 * spp as usize, "{spp} spp: {hits}");
            assert!(differ * 1000 < hits, "{spp} spp: {differ} of {hits} samples disagree with the traced rays");
        }
    }

    #[test]
    fn culling_by_the_planes_first_gives_the_same_bytes_from_any_eye() {
        // A closed ball over a floor, and a floor tile seen nearly edge-on from some eyes.
        let mut checked = 0;
        for (k, eye) in [
            Vec3::new(0.3, 1.2, 3.0),
            Vec3::new(-2.5, 0.3, -1.0),
            Vec3::new(0.0, -1.5, 2.0),
            Vec3::new(1.0, -0.2, 2.5),
            Vec3::new(0.2, 0.4, 0.1),
            Vec3::new(0.0, -0.1999, 4.0),
        ]
        .into_iter()
        .enumerate()
        {
            let s = SceneBuilder::new(eye, Vec3::new(0.0, 0.3, 0.0), 50.0, 40, 32)
                .sphere("ball", Vec3::new(0.0, 0.4, 0.0), 0.6, GREY, Vec3::ZERO, false)
                .quad("floor", Vec3::new(-3.0, -0.2, 3.0), Vec3::new(6.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -6.0), GREY, Vec3::ZERO)
                .build();
            for spp in [1, 16] {
                let hits = |first: bool| {
                    let mut p = Projection::new(&s, &s.camera).cull_back_faces(true);
                    p.planes_first = first;
                    let r = Rasterizer::with_projection(&s, &p, spp, 1);
                    (
                        r.triangles(),
                        (0..r.bands()).flat_map(|b| r.band(b)).map(|h| (h.tri, h.b1.to_bits(), h.b2.to_bits())).collect::<Vec<_>>(),
                    )
                };
                let (with, without) = (hits(true), hits(false));
                assert_eq!(with, without, "eye {k}, {spp} spp");
                checked += with.1.iter().filter(|h| h.0 != MISS).count();
            }
            // From inside the ball every triangle of it faces away: the planes cull them all.
            let planes = s.triangle_planes();
            let away = (0..s.triangles.len()).filter(|&t| planes.faces_away(t, eye, 1e-3 * (eye.length() + planes.radius))).count();
            assert!(away > 0 || k == 4, "eye {k}: none faces away");
        }
        assert!(checked > 5000, "{checked} samples hit");
    }

    #[test]
    fn the_avx2_build_gives_the_same_bytes_as_the_plain_one() {
        let s = SceneBuilder::new(Vec3::new(0.3, 1.2, 3.0), Vec3::ZERO, 45.0, 40, 24)
            .sphere("ball", Vec3::new(0.0, 0.4, 0.0), 0.6, GREY, Vec3::ZERO, false)
            .build();
        for spp in [1, 3, 16, 20] {
            let r = Rasterizer::new(&s, &s.camera, spp, 2);
            for b in 0..r.bands() {
                let (mut plain, mut dispatched) = (BandHits::default(), BandHits::default());
                r.band_into(b, &mut dispatched);
                match lanes_for(spp as usize) {
                    1 => r.band_any::<1>(b, &mut plain, &r.pattern, None),
                    4 => r.band_any::<4>(b, &mut plain, &r.pattern, None),
                    _ => r.band_any::<LANES>(b, &mut plain, &r.pattern, None),
                }
                let bits =
                    |h: &BandHits| (h.tri.clone(), [&h.inv_depth, &h.b1, &h.b2].map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>()));
                assert_eq!(bits(&plain), bits(&dispatched), "{spp} spp, band {b}");
            }
        }
    }

    #[test]
    fn with_one_sample_a_pixel_a_triangle_between_samples_is_not_drawn() {
        // A sliver of a quad far away, narrower than a pixel: with one sample a pixel at
        // fixed offsets it lies between two samples, and no pixel's box keeps it.
        let r = |spp: u32, width: f32| {
            let s = SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, 16, 16)
                .quad("sliver", Vec3::new(0.0, -1.0, 0.0), Vec3::new(width, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0), GREY, Vec3::ZERO)
                .build();
            let r = Rasterizer::new(&s, &s.camera, spp, 0);
            let covered = (0..r.bands()).map(|b| r.band(b).iter().filter(|h| h.tri != MISS).count()).sum::<usize>();
            (r.triangles(), covered)
        };
        // The pixel is 2 tan 20° · 3 / 16 ≈ 0.137 wide at the quad; the sample sits where
        // seed 0 puts it. Slide a sliver of a hundredth of a pixel across a pixel: it is kept
        // exactly where it covers a sample.
        let (pattern, px) = (sample_pattern(1, 0)[0].0, 2.0 * 20f32.to_radians().tan() * 3.0 / 16.0);
        assert!(pattern > 0.02, "the test wants the sample clear of the pixel's left edge: {pattern}");
        assert_eq!(r(1, px * 0.01), (0, 0), "a sliver at the centre column's start is set aside");
        let (kept, covered) = r(1, px * (pattern + 0.01));
        assert!(kept > 0 && covered > 0, "a sliver reaching the sample is drawn");
        // With many samples the first sliver is drawn: some sample lies in it.
        assert!(r(64, px * 0.05).0 > 0);
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

    #[test]
    fn a_coordinates_span_never_starts_past_its_end_so_behind_marks_no_real_vertex() {
        // `BEHIND` is a span whose first lies past its end: `span_first` ≤ `span_end` for any
        // coordinate (inside, outside, not finite), pattern extent and side, both within the
        // 16 bits `vertex_spans` keeps.
        let u = |k: usize, dim: u32| crate::math::rng::uniform(11, k as u64, dim) as f64;
        let specials = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -0.0, 0.0, 1e300, -1e300];
        for k in 0..200_000 {
            let n = [1, 2, 3, 255, 256, MAX_SIDE][k % 6];
            let x = match k % 10 {
                0 => specials[k / 10 % specials.len()],
                1 => (u(k, 0) * 3.0 - 1.0) * n as f64 * 10.0,
                _ => u(k, 0) * (n as f64 + 2.0) - 1.0,
            };
            let (a, b) = (u(k, 1), u(k, 2));
            let (from, to) = (a.min(b), a.max(b));
            let (first, end) = (span_first(x, to, n), span_end(x, from, n));
            assert!(first <= end && end as usize <= n && n <= u16::MAX as usize, "x {x} from {from} to {to} n {n}: {first}..{end}");
        }
        assert!(BEHIND[0] > BEHIND[1]);
    }
}
