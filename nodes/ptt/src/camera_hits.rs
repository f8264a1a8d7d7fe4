use super::screen_hits::ScreenHits;
use glam::Vec3;
use rayon::prelude::*;
use relume_base::render::camera::CameraRays;
use relume_base::render::zbuffer::{slots_per_pixel, BandHits, Projection, Rasterizer, BAND_ROWS, MAX_SIDE, MISS, SKIP, SLOT_BYTES};
use relume_base::types::{Camera, Scene, TrianglePlanes};
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, MemoryEstimate, NodeError, PortSize, RunCtx};
use std::mem::MaybeUninit;
use std::ops::Range;

params! {
    /// What the camera sees of the scene's mesh, as weights on its vertices ([S] chapter 5
    /// shades vertices and lets the rasteriser interpolate them): `spp` samples per pixel at
    /// fixed positions (a rotated Hammersley set, the same in every pixel; `seed` rotates it),
    /// each finding its nearest triangle by z-buffer rasterisation (`render::zbuffer`: near
    /// clipping, perspective-correct barycentrics, both faces, the same hits as camera rays up
    /// to ties on shared edges) and adding its triangle's corners, weighted by its barycentrics
    /// over `spp`, to its pixel; for the samples that hit nothing it keeps their fraction and
    /// the direction through their mean position, where `RasterizeVertexColors` reads the
    /// environment once per pixel (the sky does not change across a pixel as geometry does).
    ///
    /// With `adaptive` on (as a GPU's antialiasing spends its samples), one sample at each
    /// pixel's centre is drawn first, and the `spp` samples only in the pixels at an edge:
    /// where the centre of the pixel or of one of its eight neighbours sees another object,
    /// nothing, or a depth more than `depth_step` (relative) away. Elsewhere the pixel is its
    /// centre sample: across one smooth surface the vertices' interpolated colour is nearly
    /// linear over a pixel, and its value at the centre is the pixel's mean. A feature thinner
    /// than a pixel that no centre sample meets is missed, as such schemes miss it.
    ///
    /// With `cull_back_faces` on, triangles whose corners turn clockwise on screen (the back
    /// faces of counter-clockwise meshes) are left out before they are set up: exact where every
    /// mesh is closed, or open only where the camera cannot look in (on envlit, 25,402 triangles
    /// drawn at the centres instead of 44,467). Those whose plane passes clearly behind the eye
    /// are turned away by the scene's triangle planes (found on the first run, kept with the
    /// scene) before their corners are read.
    ///
    /// Only the geometry and the camera reach it: wire the scene as loaded, not the turned
    /// sky, and a sky edit leaves it alone. Runs when the camera or the geometry changes, not
    /// when the colours do: `RasterizeVertexColors` then costs one weighted sum per pixel, and
    /// `PttRelight` shades only the vertices listed as seen. The bytes are the same on any
    /// thread count (bands of rows, triangles in index order, nearest then lowest index).
    ///
    /// Metrics: samples per pixel, triangles drawn with `spp` samples (after clipping; adaptive,
    /// those that reach an edge pixel) and, adaptive, at the centres, the fraction of the image
    /// that hits geometry, the fraction of pixels drawn with `spp` samples, vertices seen,
    /// weights per pixel.
    pub struct CameraHits {
        /// samples per pixel (box filter), in every pixel or, adaptive, at edges
        pub spp: u32 = 16, range = 1..=1024, unit = "samples/pixel", test = 2;
        /// rotates the in-pixel sample pattern
        pub seed: u64 = 0, range = 0..=u32::MAX;
        /// `spp` samples only where the pixels' centres see an edge; one sample elsewhere
        pub adaptive: bool = false;
        /// adaptive: the relative step in depth between neighbouring centres that is an edge
        pub depth_step: f64 = 0.02, range = 0.0..=1.0;
        /// leave out the triangles facing away (exact for closed meshes seen from outside)
        pub cull_back_faces: bool = false;
    }
}

/// One band's pixels, laid out as `ScreenHits`' arrays are (so that joining the bands
/// copies slices): where each pixel's entries end, their vertices and weights, the missed
/// fraction and direction, the summed fraction of each pixel that hit, the pixels
/// supersampled, and the vertices seen.
#[derive(Default)]
struct Band {
    /// Per pixel, the end of its entries among the band's.
    ends: Vec<u32>,
    vertex: Vec<u32>,
    weight: Vec<f32>,
    miss: Vec<f32>,
    miss_dir: Vec<Vec3>,
    covered: f64,
    supersampled: usize,
    /// The vertices with a weight, as bits (64 a word).
    seen: Vec<u64>,
}

/// What each pixel's centre sample sees, over the whole image (adaptive sampling): its
/// triangle, barycentrics and inverse depth.
struct Centres {
    tri: Vec<u32>,
    b1: Vec<f32>,
    b2: Vec<f32>,
    inv_depth: Vec<f32>,
}

/// Bytes of z-buffer per pixel for the centre samples.
const CENTRE_BYTES: u64 = 16;

impl Band {
    /// Adds `wt` to vertex `v`'s weight in the pixel whose entries start at `start`.
    #[inline]
    fn add_weight(&mut self, start: usize, v: u32, wt: f32) {
        match self.vertex[start..].iter().position(|&e| e == v) {
            Some(e) => self.weight[start + e] += wt,
            None => {
                self.vertex.push(v);
                self.weight.push(wt);
            }
        }
    }

    /// Adds the pixels `at` (row-major indices into the image, `w` wide, the first at
    /// (x, y)), each from its one sample at the centre (`c`): a triangle's three corners
    /// weighted by its barycentrics, or, where the sample hit nothing, the whole pixel
    /// missed along the ray through its centre. Written in place, the band's arrays grown
    /// once for the run.
    fn add_centres(&mut self, c: &Centres, at: Range<usize>, (mut x, mut y): (usize, usize), w: usize, scene: &Scene, rays: &CameraRays) {
        let (v0, e0, n) = (self.vertex.len(), self.ends.len(), at.len());
        self.vertex.resize(v0 + 3 * n, 0);
        self.weight.resize(v0 + 3 * n, 0.0);
        self.ends.resize(e0 + n, 0);
        self.miss.resize(e0 + n, 0.0);
        self.miss_dir.resize(e0 + n, Vec3::ZERO);
        let (mut cursor, mut covered) = (v0, self.covered);
        for (k, a) in at.enumerate() {
            let tri = c.tri[a];
            if tri == MISS {
                self.miss[e0 + k] = 1.0;
                self.miss_dir[e0 + k] = rays.ray(x as f32 + 0.5, y as f32 + 0.5).1;
            } else {
                covered += 1.0;
                // Three vertices, each once: a triangle with a corner repeated has no area,
                // and the z-buffer never keeps it.
                let corners = scene.triangles[tri as usize];
                self.vertex[cursor..cursor + 3].copy_from_slice(&corners);
                self.weight[cursor..cursor + 3].copy_from_slice(&[1.0 - c.b1[a] - c.b2[a], c.b1[a], c.b2[a]]);
                cursor += 3;
            }
            self.ends[e0 + k] = cursor as u32;
            x += 1;
            if x == w {
                (x, y) = (0, y + 1);
            }
        }
        self.vertex.truncate(cursor);
        self.weight.truncate(cursor);
        self.covered = covered;
    }

    /// Adds pixel (x, y) from its samples' triangles and barycentrics (b1, b2) at `pattern`'s
    /// positions: each triangle's corners weighted by its summed barycentrics over the
    /// samples, each vertex once; `tris` is scratch.
    #[allow(clippy::too_many_arguments)]
    fn add_pixel(
        &mut self,
        (tri, b1, b2): (&[u32], &[f32], &[f32]),
        pattern: &[(f32, f32)],
        (x, y): (usize, usize),
        scene: &Scene,
        rays: &CameraRays,
        tris: &mut Vec<(u32, Vec3)>,
    ) {
        let n = tri.len();
        let inv = 1.0 / n as f32;
        let start = self.vertex.len();
        let (mut missed, mut ox, mut oy) = (0u32, 0.0f32, 0.0f32);
        // The pixel's triangles with their summed barycentrics, in order of first hit.
        tris.clear();
        let corners = |s: usize| Vec3::new(1.0 - b1[s] - b2[s], b1[s], b2[s]);
        if tri[0] != MISS && tri.iter().all(|&t| t == tri[0]) {
            // The common pixel: all its samples on one triangle.
            self.covered += 1.0;
            tris.push((tri[0], (0..n).fold(Vec3::ZERO, |sum, s| sum + corners(s))));
        } else {
            for (s, &t) in tri.iter().enumerate() {
                if t == MISS {
                    let (sx, sy) = pattern[s];
                    (ox, oy, missed) = (ox + sx, oy + sy, missed + 1);
                    continue;
                }
                match tris.iter_mut().find(|e: &&mut (u32, Vec3)| e.0 == t) {
                    Some(e) => e.1 += corners(s),
                    None => tris.push((t, corners(s))),
                }
            }
            self.covered += (n as u32 - missed) as f64 * inv as f64;
        }
        for &(t, b) in tris.iter() {
            for (v, wt) in scene.triangles[t as usize].into_iter().zip(b.to_array()) {
                self.add_weight(start, v, wt * inv);
            }
        }
        self.ends.push(self.vertex.len() as u32);
        let (m, d) = if missed > 0 {
            // The ray through the missed samples' mean position.
            let m = missed as f32;
            (m * inv, rays.ray(x as f32 + ox / m, y as f32 + oy / m).1)
        } else {
            (0.0, Vec3::ZERO)
        };
        self.miss.push(m);
        self.miss_dir.push(d);
    }
}

impl CameraHits {
    /// Every pixel's centre sample, band by band.
    fn centres(&self, raster: &Rasterizer, cx: &RunCtx) -> Result<Centres, NodeError> {
        // Each band drawn and copied into its place in the image's arrays by one task.
        let lens: Vec<usize> = (0..raster.bands()).map(|b| raster.band_rows(b).len() * raster.width()).collect();
        let (mut tri, mut b1, mut b2, mut inv_depth) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        places(&mut tri, &lens)
            .into_par_iter()
            .zip(places(&mut b1, &lens))
            .zip(places(&mut b2, &lens))
            .zip(places(&mut inv_depth, &lens))
            .enumerate()
            .for_each_init(BandHits::default, |hits, (b, (((t, u), v), z))| {
                raster.band_into(b, hits);
                let (ht, hu, hv, hz) = hits.single();
                fill(t, ht, |x| x);
                fill(u, hu, |x| x);
                fill(v, hv, |x| x);
                fill(z, hz, |x| x);
            });
        let n = lens.iter().sum();
        // SAFETY: each array's places split the first `n` of its spare capacity without gaps,
        // one per band of that band's pixels, and `fill` wrote them all.
        unsafe {
            tri.set_len(n);
            b1.set_len(n);
            b2.set_len(n);
            inv_depth.set_len(n);
        }
        cx.check()?;
        Ok(Centres { tri, b1, b2, inv_depth })
    }

    /// The pixels at an edge: those whose centre, or a neighbour's, sees another object,
    /// nothing where the other sees something, or a depth `depth_step` away.
    fn edges(&self, c: &Centres, object: &[u32], (w, h): (usize, usize)) -> EdgePixels {
        let step = self.depth_step as f32;
        let mut place = vec![SKIP; w * h];
        let mut before = vec![0u32; (w + 1) * h];
        if w == 0 {
            return EdgePixels { w, place, before };
        }
        // Bands of rows in parallel. Each pair of neighbours is compared once, at the pair's
        // upper-left end, for the band's rows and the row above it: with the right
        // neighbour, the one below, the one below-right, and the right neighbour with the one
        // below (`anti`). A pixel is at an edge when any of the eight pairs it is in differs.
        let bands = place.par_chunks_mut(w * BAND_ROWS).zip(before.par_chunks_mut((w + 1) * BAND_ROWS));
        bands.enumerate().for_each(|(b, (place, before))| {
            let first = b * BAND_ROWS;
            let (y0, y1) = (first.saturating_sub(1), first + place.len() / w);
            // The rows' objects (`MISS` where nothing is seen) and inverse depths, with the
            // row below the band.
            let rows = y0 * w..(y1 + 1).min(h) * w;
            let key: Vec<u32> = c.tri[rows.clone()].iter().map(|&t| if t == MISS { MISS } else { object[t as usize] }).collect();
            let z = &c.inv_depth[rows];
            let n = (y1 - y0) * w;
            let (mut right, mut down, mut diag, mut anti) = (vec![0u8; n], vec![0u8; n], vec![0u8; n], vec![0u8; n]);
            for r in 0..y1 - y0 {
                let (k, zr, at) = (&key[r * w..][..w], &z[r * w..][..w], r * w);
                pair_differs(step, (&k[..w - 1], &zr[..w - 1]), (&k[1..], &zr[1..]), &mut right[at..at + w - 1]);
                if y0 + r + 1 < h {
                    let (kd, zd) = (&key[(r + 1) * w..][..w], &z[(r + 1) * w..][..w]);
                    pair_differs(step, (k, zr), (kd, zd), &mut down[at..at + w]);
                    pair_differs(step, (&k[..w - 1], &zr[..w - 1]), (&kd[1..], &zd[1..]), &mut diag[at..at + w - 1]);
                    pair_differs(step, (&k[1..], &zr[1..]), (&kd[..w - 1], &zd[..w - 1]), &mut anti[at..at + w - 1]);
                }
            }
            let none = vec![0u8; w];
            let mut edge = vec![0u8; w];
            let mut count = 0;
            for (r, (place, before)) in place.chunks_mut(w).zip(before.chunks_mut(w + 1)).enumerate() {
                let at = (first + r - y0) * w;
                let (rr, dd, gg, aa) = (&right[at..][..w], &down[at..][..w], &diag[at..][..w], &anti[at..][..w]);
                let (du, gu, au) = match first + r {
                    0 => (&none[..], &none[..], &none[..]),
                    _ => (&down[at - w..at], &diag[at - w..at], &anti[at - w..at]),
                };
                edge[0] = rr[0] | dd[0] | du[0] | gg[0] | au[0];
                for x in 1..w {
                    edge[x] = rr[x] | rr[x - 1] | dd[x] | du[x] | gg[x] | gu[x - 1] | aa[x - 1] | au[x];
                }
                for x in 0..w {
                    before[x] = count;
                    if edge[x] != 0 {
                        place[x] = count;
                        count += 1;
                    }
                }
                before[w] = count;
            }
        });
        EdgePixels { w, place, before }
    }
}

/// The pixels at an edge (adaptive sampling), numbered band by band: `place` per pixel
/// (row-major) its number among its band's edge pixels in row-major order, or `SKIP`;
/// `before`, `w` + 1 per row, the band's edge pixels before column x of the row (x = `w`:
/// up to the row's end).
struct EdgePixels {
    w: usize,
    place: Vec<u32>,
    before: Vec<u32>,
}

impl EdgePixels {
    /// Whether a pixel of the box columns x0..x1, rows y0..y1 is at an edge.
    fn any_in(&self, [x0, x1, y0, y1]: [u32; 4]) -> bool {
        (y0 as usize..y1 as usize).any(|y| {
            let row = &self.before[y * (self.w + 1)..];
            row[x1 as usize] != row[x0 as usize]
        })
    }

    /// The edge pixels of band `rows`: how many.
    fn count(&self, rows: &Range<usize>) -> usize {
        self.before[rows.end * (self.w + 1) - 1] as usize
    }
}

/// The first `lens.iter().sum()` places of `out`'s spare capacity, split one after another
/// into parts of `lens`: where parallel tasks write parts of one array (`fill`; the caller
/// sets the length once all are written).
fn places<'a, U>(out: &'a mut Vec<U>, lens: &[usize]) -> Vec<&'a mut [MaybeUninit<U>]> {
    let total = lens.iter().sum();
    out.reserve(total);
    let mut rest = &mut out.spare_capacity_mut()[..total];
    let mut parts = Vec::with_capacity(lens.len());
    for &len in lens {
        let (place, tail) = rest.split_at_mut(len);
        parts.push(place);
        rest = tail;
    }
    parts
}

/// Writes `part`, each element mapped by `f`, into `place` (of the same length).
fn fill<T: Copy, U>(place: &mut [MaybeUninit<U>], part: &[T], f: impl Fn(T) -> U) {
    assert_eq!(place.len(), part.len(), "a place per element");
    place.iter_mut().zip(part).for_each(|(o, &x)| {
        o.write(f(x));
    });
}

/// The bands' arrays joined end to end, all of a band's by one task: the pixels' ends (from
/// 0, after the bands before), vertices, weights, missed fractions and directions.
#[allow(clippy::type_complexity)]
fn join_bands(bands: &[Band]) -> (Vec<u32>, Vec<u32>, Vec<f32>, Vec<f32>, Vec<Vec3>) {
    let entries: Vec<usize> = bands.iter().map(|b| b.vertex.len()).collect();
    let pixels: Vec<usize> = bands.iter().map(|b| b.ends.len()).collect();
    let first: Vec<u32> = entries.iter().scan(0, |at, &n| Some(std::mem::replace(at, *at + n as u32))).collect();
    let (mut ends, mut vertex, mut weight, mut miss, mut miss_dir) = (vec![0u32], Vec::new(), Vec::new(), Vec::new(), Vec::new());
    places(&mut ends, &pixels)
        .into_par_iter()
        .zip(places(&mut vertex, &entries))
        .zip(places(&mut weight, &entries))
        .zip(places(&mut miss, &pixels))
        .zip(places(&mut miss_dir, &pixels))
        .zip(bands)
        .zip(first)
        .for_each(|((((((e, v), w), m), d), band), first)| {
            fill(e, &band.ends, |end| first + end);
            fill(v, &band.vertex, |x| x);
            fill(w, &band.weight, |x| x);
            fill(m, &band.miss, |x| x);
            fill(d, &band.miss_dir, |x| x);
        });
    let (p, n) = (pixels.iter().sum::<usize>(), entries.iter().sum::<usize>());
    // SAFETY: each array's places split the first `p` (pixels) or `n` (entries) of its spare
    // capacity without gaps, one per band of that band's length, and `fill` wrote them all.
    unsafe {
        ends.set_len(1 + p);
        vertex.set_len(n);
        weight.set_len(n);
        miss.set_len(p);
        miss_dir.set_len(p);
    }
    (ends, vertex, weight, miss, miss_dir)
}

/// The vertices whose bit is set in `bits` (64 a word), ascending.
fn seen_list(bits: &[u64]) -> Vec<u32> {
    let mut out = Vec::with_capacity(bits.iter().map(|w| w.count_ones() as usize).sum());
    for (k, &w) in bits.iter().enumerate() {
        let mut w = w;
        while w != 0 {
            out.push(k as u32 * 64 + w.trailing_zeros());
            w &= w - 1;
        }
    }
    out
}

/// Per place, 1 where the centres `a` and `b` (objects, inverse depths) differ: another
/// object, nothing where the other sees something, or depths more than `step` apart
/// (relative to the nearer); 0 elsewhere. Symmetric in `a` and `b`; without branches, so
/// that it vectorises.
fn pair_differs(step: f32, a: (&[u32], &[f32]), b: (&[u32], &[f32]), out: &mut [u8]) {
    for ((((o, ka), za), kb), zb) in out.iter_mut().zip(a.0).zip(a.1).zip(b.0).zip(b.1) {
        *o = ((ka != kb) | ((*ka != MISS) & ((za - zb).abs() > step * za.max(*zb)))) as u8;
    }
}

#[node(category = "ptt", version = 4, caching = Keyed, metrics = ["spp", "triangles", "centre_triangles", "covered_fraction", "supersampled_fraction", "seen", "weights_per_pixel"], outputs = [hits])]
impl CameraHits {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        let hits = inputs[1].and_then(|s| s.dims).map(|[w, h]| {
            let px = (w * h) as u64;
            PortSize::bytes(ScreenHits::bytes(px, px * 3 * self.spp.min(4) as u64, px * 3))
        });
        MemoryEstimate { outputs: vec![hits], working: 0 }
    }

    fn run(&self, scene: &Scene, camera: &Camera, cx: &RunCtx) -> Result<ScreenHits, NodeError> {
        let cam = camera;
        let (w, h) = (cam.width, cam.height);
        let pixels = (w * h) as u64;
        let spp = self.spp as usize;
        // The projected triangles and every band's z-buffer, as if all were held at once,
        // and the centre samples when adaptive.
        if w > MAX_SIDE || h > MAX_SIDE {
            return Err(NodeError::input("camera", format!("{w} × {h} pixels: the z-buffer draws at most {MAX_SIDE} pixels a side")));
        }
        // (Culling, the scene's triangle planes are kept with it once found.)
        let planes = if self.cull_back_faces { TrianglePlanes::bytes_for(scene.triangles.len()) as u64 } else { 0 };
        let need = scene.triangles.len() as u64 * 2 * 200
            + planes
            + pixels * (slots_per_pixel(spp) * SLOT_BYTES) as u64
            + if self.adaptive { pixels * CENTRE_BYTES } else { 0 }
            + ScreenHits::bytes(pixels, pixels * 3, 0);
        if need > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "rasterising {w} × {h} pixels at {spp} samples each needs about {}, over the {} budget",
                fmt_bytes(need),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let projection = Projection::new(scene, cam).cull_back_faces(self.cull_back_faces);
        // Adaptive: the centres first, then the spp samples in the pixels at an edge, from
        // only the triangles that reach one.
        let mut centre_triangles = 0;
        let (raster, centres) = if self.adaptive {
            let cr = Rasterizer::centres(scene, &projection);
            centre_triangles = cr.triangles();
            let centres = self.centres(&cr, cx)?;
            let edge = self.edges(&centres, &scene.tri_object, (w, h));
            let r = Rasterizer::for_pixels(scene, &projection, self.spp, self.seed, |b| edge.any_in(b));
            (r, Some((centres, edge)))
        } else {
            (Rasterizer::with_projection(scene, &projection, self.spp, self.seed), None)
        };
        cx.check()?;
        let rays = CameraRays::new(cam);
        // Per thread: the band's hits and z-buffer, and a pixel's triangles, reused.
        let scratch = || (BandHits::default(), Vec::<(u32, Vec3)>::with_capacity(spp));
        let bands: Vec<Band> = cx.par_map_init(raster.bands(), scratch, |(hits, tris), b| {
            let rows = raster.band_rows(b);
            let pixels = rows.len() * w;
            let places = match &centres {
                Some((_, edge)) => {
                    let places = &edge.place[rows.start * w..rows.end * w];
                    raster.band_pixels_into(b, places, edge.count(&rows), hits);
                    Some(places)
                }
                None => {
                    raster.band_into(b, hits);
                    None
                }
            };
            // Room for three corners a pixel (a centre sample on a triangle; edge pixels,
            // a few in a band, may grow it).
            let mut out = Band {
                ends: Vec::with_capacity(pixels),
                vertex: Vec::with_capacity(3 * pixels),
                weight: Vec::with_capacity(3 * pixels),
                miss: Vec::with_capacity(pixels),
                miss_dir: Vec::with_capacity(pixels),
                ..Band::default()
            };
            let xy = |p: usize| (p % w, rows.start + p / w);
            match (&places, &centres) {
                (Some(places), Some((c, _))) => {
                    // Runs of pixels drawn from their centres, each up to an edge pixel.
                    let mut p = 0;
                    while p < pixels {
                        let edge = places[p..].iter().position(|&k| k != SKIP).map_or(pixels, |e| p + e);
                        if edge > p {
                            let first = rows.start * w;
                            out.add_centres(c, first + p..first + edge, xy(p), w, scene, &rays);
                        }
                        if edge < pixels {
                            out.supersampled += 1;
                            out.add_pixel(hits.pixel(places[edge] as usize), raster.pattern(), xy(edge), scene, &rays, tris);
                        }
                        p = edge + 1;
                    }
                }
                _ => {
                    for p in 0..pixels {
                        out.supersampled += 1;
                        out.add_pixel(hits.pixel(p), raster.pattern(), xy(p), scene, &rays, tris);
                    }
                }
            }
            out.seen = vec![0u64; scene.positions.len().div_ceil(64)];
            out.vertex.iter().for_each(|&v| out.seen[v as usize / 64] |= 1 << (v % 64));
            out
        })?;
        // The bands joined on both threads (each band's slices copied into their place), and
        // the vertices seen by any band.
        let (offsets, vertex, weight, miss, miss_dir) = join_bands(&bands);
        let mut seen = vec![0u64; scene.positions.len().div_ceil(64)];
        for band in &bands {
            seen.iter_mut().zip(&band.seen).for_each(|(s, b)| *s |= b);
        }
        let out = ScreenHits {
            width: w as u32,
            height: h as u32,
            vertices: scene.positions.len() as u32,
            offsets,
            vertex,
            weight,
            miss,
            miss_dir,
            seen: seen_list(&seen),
        };
        let covered = bands.iter().fold(0.0, |sum, b| sum + b.covered);
        let supersampled: usize = bands.iter().map(|b| b.supersampled).sum();
        cx.metric("spp", spp as f64);
        cx.metric("triangles", raster.triangles() as f64);
        if self.adaptive {
            cx.metric("centre_triangles", centre_triangles as f64);
        }
        cx.metric("covered_fraction", covered / pixels as f64);
        cx.metric("supersampled_fraction", supersampled as f64 / pixels as f64);
        cx.metric("seen", out.seen.len() as f64);
        cx.metric("weights_per_pixel", out.vertex.len() as f64 / pixels as f64);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::scene::builder::SceneBuilder;
    use relume_base::testing::{cancels_midway, first, i, run_on};
    use relume_base::types::{Environment, Material};
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
    fn a_run_of_centre_pixels_wraps_its_rows_and_gives_each_its_corners_or_its_ray() {
        let s = ball();
        let rays = CameraRays::new(&s.camera);
        // Pixels 1..6 of an image 3 wide: (1, 0), (2, 0), (0, 1), (1, 1), (2, 1).
        let c = Centres {
            tri: vec![0, 4, MISS, 7, MISS, 4],
            b1: vec![0.0, 0.25, 0.0, 0.5, 0.0, 0.125],
            b2: vec![0.0, 0.5, 0.0, 0.25, 0.0, 0.375],
            inv_depth: vec![0.0; 6],
        };
        let mut band = Band { covered: 2.0, ..Band::default() };
        band.add_centres(&c, 1..6, (1, 0), 3, &s, &rays);
        assert_eq!(band.ends, [3, 3, 6, 6, 9]);
        let corners: Vec<u32> = [4, 7, 4].iter().flat_map(|&t| s.triangles[t]).collect();
        assert_eq!(band.vertex, corners);
        assert_eq!(band.weight, [0.25, 0.25, 0.5, 0.25, 0.5, 0.25, 0.5, 0.125, 0.375]);
        assert_eq!(band.miss, [0.0, 1.0, 0.0, 1.0, 0.0]);
        assert_eq!(band.miss_dir, [Vec3::ZERO, rays.ray(2.5, 0.5).1, Vec3::ZERO, rays.ray(1.5, 1.5).1, Vec3::ZERO]);
        assert_eq!(band.covered, 5.0);
    }

    #[test]
    fn the_bands_join_end_to_end_and_the_seen_bits_list_ascending() {
        // Bands of 2, 0, 1 and 2 pixels with 3, 0, 0 and 4 entries.
        let band = |ends: &[u32], vertex: &[u32], miss: &[f32]| Band {
            ends: ends.to_vec(),
            vertex: vertex.to_vec(),
            weight: vertex.iter().map(|&v| v as f32 / 8.0).collect(),
            miss: miss.to_vec(),
            miss_dir: miss.iter().map(|&m| Vec3::splat(m)).collect(),
            ..Band::default()
        };
        let bands = [
            band(&[3, 3], &[1, 2, 3], &[0.0, 1.0]),
            band(&[], &[], &[]),
            band(&[0], &[], &[1.0]),
            band(&[1, 4], &[4, 5, 6, 7], &[0.5, 0.0]),
        ];
        let (ends, vertex, weight, miss, miss_dir) = join_bands(&bands);
        assert_eq!(ends, [0, 3, 3, 3, 4, 7]);
        assert_eq!(vertex, [1, 2, 3, 4, 5, 6, 7]);
        assert_eq!(weight, vertex.iter().map(|&v| v as f32 / 8.0).collect::<Vec<_>>());
        assert_eq!(miss, [0.0, 1.0, 1.0, 0.5, 0.0]);
        assert_eq!(miss_dir, miss.iter().map(|&m| Vec3::splat(m)).collect::<Vec<_>>());
        assert_eq!(join_bands(&[]), (vec![0], vec![], vec![], vec![], vec![]));
        let mut bits = vec![0u64; 3];
        for v in [0u32, 63, 64, 130, 5] {
            bits[v as usize / 64] |= 1 << (v % 64);
        }
        assert_eq!(seen_list(&bits), vec![0, 5, 63, 64, 130]);
        assert!(seen_list(&[0, 0]).is_empty());
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

    /// Pixel p's entries, sorted by vertex.
    fn entries(h: &ScreenHits, p: usize) -> Vec<(u32, f32)> {
        let r = h.offsets[p] as usize..h.offsets[p + 1] as usize;
        let mut e: Vec<(u32, f32)> = h.vertex[r.clone()].iter().copied().zip(h.weight[r].iter().copied()).collect();
        e.sort_by_key(|x| x.0);
        e
    }

    fn metric(s: &Scene, params: &[(&str, ParamValue)], name: &str) -> f64 {
        let run = relume_base::testing::run_full::<CameraHits>(
            params,
            std::path::Path::new("."),
            vec![Value::new(s.clone()), Value::new(s.camera.clone())],
        );
        run.expect("runs").metrics.iter().find(|m| m.0 == name).expect("the metric").1
    }

    #[test]
    fn adaptive_hits_are_the_uniform_ones_at_edges_and_the_centre_ray_elsewhere() {
        let s = ball();
        let (n, w) = (32 * 24, 32);
        let uniform = hits(&s, &[("spp", i(8)), ("seed", i(2))]);
        let adaptive = hits(&s, &[("spp", i(8)), ("seed", i(2)), ("adaptive", ParamValue::Bool(true))]);
        let accel = relume_base::types::Accel::build(&s, relume_base::types::accel::BuildQuality::Fast);
        let rays = CameraRays::new(&s.camera);
        let object = |v: u32| s.tri_object[s.triangles.iter().position(|t| t.contains(&v)).unwrap()];
        let (mut edges, mut inside, mut off) = (0, 0, 0);
        for p in 0..n {
            let (u, a) = (entries(&uniform, p), entries(&adaptive, p));
            let objects: std::collections::BTreeSet<u32> = u.iter().map(|e| object(e.0)).collect();
            let at_edge = objects.len() > 1 || (uniform.miss[p] > 0.0 && uniform.miss[p] < 1.0);
            if a == u && uniform.miss[p] == adaptive.miss[p] && (uniform.miss_dir[p] - adaptive.miss_dir[p]).length() < 1e-6 {
                edges += at_edge as usize;
                continue;
            }
            // Every pixel where the samples see two objects, or some see nothing, is drawn
            // with all its samples: a straight edge through a pixel always parts its centre
            // from one of its eight neighbours'.
            assert!(!at_edge, "pixel {p}: an edge drawn with one sample");
            // Else the pixel is the ray through its centre.
            let (x, y) = ((p % w) as f32 + 0.5, (p / w) as f32 + 0.5);
            let (o, d) = rays.ray(x, y);
            match accel.intersect(o, d, 0.0, f32::INFINITY) {
                None => assert!(a.is_empty() && adaptive.miss[p] == 1.0 && (adaptive.miss_dir[p] - d).length() < 1e-6, "pixel {p}"),
                Some(hit) => {
                    let corners = s.triangles[hit.tri as usize];
                    let want = [1.0 - hit.b1 - hit.b2, hit.b1, hit.b2];
                    for (v, wt) in corners.iter().zip(want) {
                        let got = a.iter().find(|e| e.0 == *v).map_or(0.0, |e| e.1);
                        if (got - wt).abs() > 1e-3 {
                            off += 1;
                        }
                    }
                    assert_eq!(adaptive.miss[p], 0.0);
                }
            }
            inside += 1;
        }
        assert!(edges > 40 && inside > 300, "{edges} edge pixels, {inside} drawn from their centre");
        // Rays and the rasteriser may part on shared edges: rarely.
        assert!(off * 100 < inside, "{off} weights of {inside} pixels differ from the centre ray's");
        let ad = [("spp", i(8)), ("seed", i(2)), ("adaptive", ParamValue::Bool(true))];
        let fraction = metric(&s, &ad, "supersampled_fraction");
        assert!(fraction > 0.05 && fraction < 0.4, "{fraction}");
        // The same bytes on one thread.
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        assert_eq!(one.install(|| hits(&s, &ad)).encode(), adaptive.encode());
    }

    #[test]
    fn the_depth_step_chooses_how_much_of_one_surface_is_supersampled() {
        // On the ball, the depth changes between any two centres: with no step allowed
        // every pixel of it is an edge; with a whole depth's step only its outline is.
        let s = ball();
        let with = |step: f64| {
            metric(
                &s,
                &[("spp", i(4)), ("adaptive", ParamValue::Bool(true)), ("depth_step", ParamValue::Float(step))],
                "supersampled_fraction",
            )
        };
        let (none, all, default) = (with(0.0), with(1.0), with(0.02));
        let covered = metric(&s, &[("spp", i(4))], "covered_fraction");
        assert!(none >= covered - 0.01, "step 0: {none} of the pixels supersampled, {covered} covered");
        assert!(all < none * 0.75 && default > all && default < none, "{all} {default} {none}");
        assert_eq!(metric(&s, &[("spp", i(4))], "supersampled_fraction"), 1.0, "not adaptive: every pixel");
    }

    #[test]
    fn culling_back_faces_keeps_a_closed_mesh_and_drops_a_quad_seen_from_behind() {
        // The ball is closed: its back faces are hidden, and leaving them out changes no hit.
        let s = ball();
        for adaptive in [false, true] {
            let on = |cull: bool| [("spp", i(4)), ("adaptive", ParamValue::Bool(adaptive)), ("cull_back_faces", ParamValue::Bool(cull))];
            let (kept, culled) = (hits(&s, &on(false)), hits(&s, &on(true)));
            assert_eq!(kept.vertex, culled.vertex, "adaptive {adaptive}");
            assert_eq!(kept.miss, culled.miss);
            let close = kept.weight.iter().zip(&culled.weight).all(|(a, b)| (a - b).abs() < 1e-6);
            assert!(close, "adaptive {adaptive}: the weights move");
            let (all, fewer) = (metric(&s, &on(false), "triangles"), metric(&s, &on(true), "triangles"));
            assert!(fewer < all * 0.7, "adaptive {adaptive}: {fewer} of {all} triangles drawn");
        }
        // A quad wound to face away from the camera is a back face: culled, the sky shows.
        let away = SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, 8, 8)
            .environment(Environment::Constant(SKY))
            .quad("wall", Vec3::new(-2.0, -2.0, 0.0), Vec3::new(0.0, 4.0, 0.0), Vec3::new(4.0, 0.0, 0.0), GREY, Vec3::ZERO)
            .build();
        let facing = |cull: bool| hits(&away, &[("spp", i(2)), ("cull_back_faces", ParamValue::Bool(cull))]);
        assert!(facing(false).miss.iter().all(|&m| m == 0.0), "drawn from both sides by default");
        assert!(facing(true).miss.iter().all(|&m| m == 1.0), "culled");
    }

    #[test]
    fn cancels() {
        let s = ball();
        cancels_midway::<CameraHits>(&[("spp", i(64))], vec![Value::new(s.clone()), Value::new(s.camera.clone())]);
    }

    /// The edges of centres drawn at random (objects, misses, depths near one another or
    /// not), on an image of several bands with a short last one, against the definition:
    /// a pixel is at an edge when a centre of its 3 × 3 neighbourhood differs from its own.
    #[test]
    fn edge_pixels_are_those_with_a_differing_centre_among_their_eight_neighbours() {
        let (w, h) = (37, 29);
        let object = [0, 0, 1, 1, 2, 2];
        let node = CameraHits { spp: 4, seed: 0, adaptive: true, depth_step: 0.02, cull_back_faces: false };
        for trial in 0..50u64 {
            let r = |p: usize, d: u32| relume_base::math::rng::uniform(trial, p as u64, d);
            let tri: Vec<u32> = (0..w * h).map(|p| if r(p, 0) < 0.15 { MISS } else { (r(p, 1) * 6.0) as u32 % 6 }).collect();
            // Depth steps of 0 to 3 %, against the 2 % that makes an edge.
            let spread = 0.03 * (trial % 3) as f32;
            let inv_depth: Vec<f32> = (0..w * h).map(|p| if tri[p] == MISS { 0.0 } else { 1.0 + spread * r(p, 2) }).collect();
            let n = w * h;
            let c = Centres { tri: tri.clone(), b1: vec![0.0; n], b2: vec![0.0; n], inv_depth: inv_depth.clone() };
            let got = node.edges(&c, &object, (w, h));
            let key = |p: usize| if tri[p] == MISS { MISS } else { object[tri[p] as usize] };
            let differ = |p: usize, q: usize| {
                let (zp, zq) = (inv_depth[p], inv_depth[q]);
                key(p) != key(q) || (key(p) != MISS && (zp - zq).abs() > 0.02 * zp.max(zq))
            };
            let mut count = 0;
            for y in 0..h {
                if y % BAND_ROWS == 0 {
                    count = 0;
                }
                for x in 0..w {
                    let p = y * w + x;
                    let near = |a: usize, n: usize| a.saturating_sub(1)..(a + 2).min(n);
                    let e = near(y, h).any(|qy| near(x, w).any(|qx| differ(p, qy * w + qx)));
                    assert_eq!(got.place[p], if e { count } else { SKIP }, "trial {trial}, pixel ({x}, {y})");
                    assert_eq!(got.any_in([x as u32, x as u32 + 1, y as u32, y as u32 + 1]), e);
                    count += e as u32;
                }
            }
            assert!(got.any_in([0, w as u32, 0, h as u32]));
        }
    }
}
