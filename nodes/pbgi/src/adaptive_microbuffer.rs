//! The importance-driven adaptive microbuffer of wavelet PBGI ([P] 4.6): the uniform
//! microbuffer's hemisphere (Nusselt mapping, `microbuffer`) as a quadtree of pixels. It
//! starts as an N × N buffer; each pixel may split 2 × 2 down to `max_level` levels (a pixel
//! at level l is one of the uniform (N 2^l)² buffer's).
//!
//! - **BRDF importance F_ρ** sets the levels before the traversal: a pixel's share of the
//!   receiver's convolution, f(ωo, ωk) × its projected solid angle, is compared with the
//!   mean share over the disk, and the pixel splits until its share is at most the mean
//!   (each split quarters it). Micro-rendering warps the buffer toward the BRDF ([P] cites
//!   Ritschel et al.); the thesis subdivides instead, as here. A Lambert receiver keeps the
//!   uniform N × N buffer.
//! - **Lighting importance F_l** splits a pixel during the traversal: when a node lands in a
//!   pixel with radiance L (its largest channel) and L / 2^Δk > γ, Δk being the levels the
//!   light has already added to that pixel ([P]: L_i / d^Δk > γ with d "the dimension of the
//!   subdivision", read here as 2), the pixel splits and every node it held is visited again,
//!   against the finer pixels (some now open into their children). The thesis gives no γ:
//!   it is an absolute radiance, the gather's parameter.
//!
//! The traversal only records which node lands where (per pixel, as the thesis keeps node
//! lists rather than the nearest node); `finish` rasterises the records in the order they
//! were made, with the uniform buffer's splat rules (depth layers, coverage, bilinear spread
//! of sub-pixel nodes, cones of larger ones, exact disks of near leaves) over the pixels
//! of mixed levels. With every pixel at one level and no split during the traversal, the
//! result is that level's uniform buffer, write for write.

use super::microbuffer::{DiskBounds, DiskLight, Flat, Microbuffer, SplatRule, OCCLUDE_REACH};
use super::traversal::{radiance_along, GatherBuffer, GatherCounts, NodeRadiance, Raster, Traversal};
use glam::Vec3;
use relume_base::brdf;
use relume_base::math::frame::Frame;
use relume_base::types::Material;

/// A pixel's BRDF share counts as above the mean only beyond this relative margin (the
/// rounding of the shares' f32 values; a real lobe's shares differ by far more).
const SHARE_ROUNDING: f64 = 1e-5;

/// One rasterisation to replay: a splat or a near leaf's exact disk.
#[derive(Clone, Copy, Debug)]
enum Record {
    Splat {
        node: u32,
        d: Vec3,
        dist: f32,
        omega: f32,
        l: Vec3,
        flat: Option<Flat>,
    },
    /// `l`: the light its centre sends toward the receiver (`finish_lit` may read each
    /// pixel's own).
    Disk {
        node: u32,
        c: Vec3,
        nrm: Vec3,
        r: f32,
        l: Vec3,
        eps: f32,
    },
}

/// A pixel of some level: (level, x, y) at that level's grid of side N 2^level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Pixel {
    level: u32,
    x: usize,
    y: usize,
}

#[derive(Clone)]
pub struct AdaptiveMicrobuffer {
    n: usize,
    max_level: u32,
    /// Lighting importance threshold γ (infinite: no splits by light).
    gamma: f32,
    /// Per pixel of the finest grid (side N 2^max_level): the level of the pixel holding it,
    /// and the levels the light added there.
    level: Vec<u8>,
    light_levels: Vec<u8>,
    /// Per level, the uniform buffer of that side holding the pixels at that level.
    buffers: Vec<Microbuffer>,
    /// Per level, a box (x0, y0, x1, y1 of that level's grid) holding every pixel that has
    /// been at that level since `start`: what `convolve` reads and the next `start` clears.
    extent: Vec<Option<(usize, usize, usize, usize)>>,
    /// Records in the order they were made, with the pixel each landed in (`None` once
    /// handed back for another visit).
    records: Vec<(Option<Pixel>, Record)>,
    /// Whether nodes are chosen against the base pixels' solid angle (finer pixels then take
    /// larger nodes, spread as cones) rather than against the pixel each lands in.
    coarse_cut: bool,
    /// While every pixel is at the base level, records are also rasterised as they are made
    /// (the uniform buffer's writes, in its order), so that a receiver nothing refines costs
    /// no replay; the first split clears the base buffer and `finish` replays them all.
    direct: bool,
    /// Whether `finish` has run since `start`.
    finished: bool,
    /// Splits by light during the traversal (for the report).
    pub light_splits: u64,
    /// Scratch: one splat's writes.
    writes: Vec<(usize, f32)>,
}

impl AdaptiveMicrobuffer {
    /// An N × N buffer whose pixels may split `max_level` times, by light above `gamma`.
    pub fn new(n: usize, max_level: u32, gamma: f32) -> Self {
        assert!(n >= 2 && max_level <= 6, "an adaptive microbuffer needs N ≥ 2 and at most 6 levels ({n}, {max_level})");
        let fine = n << max_level;
        AdaptiveMicrobuffer {
            n,
            max_level,
            gamma,
            level: vec![0; fine * fine],
            light_levels: vec![0; fine * fine],
            buffers: (0..=max_level).map(|l| Microbuffer::new(n << l)).collect(),
            extent: vec![None; max_level as usize + 1],
            records: vec![],
            coarse_cut: false,
            direct: false,
            finished: false,
            light_splits: 0,
            writes: vec![],
        }
    }

    /// Chooses the nodes against the base pixels (`true`) or the pixel each lands in (`false`,
    /// the thesis' and the default of `new`).
    pub fn with_coarse_cut(mut self, on: bool) -> Self {
        self.coarse_cut = on;
        self
    }

    /// Every level's buffer with nodes smaller than its pixels landing by `rule`.
    pub fn with_rule(mut self, rule: SplatRule) -> Self {
        self.buffers = self.buffers.into_iter().map(|b| b.with_rule(rule)).collect();
        self
    }

    fn fine(&self) -> usize {
        self.n << self.max_level
    }

    /// Resets the buffer for a receiver and sets each base pixel's level from the BRDF
    /// importance of `m` seen from `wo` (local); `forced` puts every pixel at that level.
    pub fn start(&mut self, m: &Material, wo: Vec3, forced: Option<u32>) {
        for (b, e) in self.buffers.iter_mut().zip(&mut self.extent) {
            if let Some(e) = e.take() {
                b.clear_rect(e);
            }
        }
        self.records.clear();
        self.finished = false;
        self.light_levels.fill(0);
        self.light_splits = 0;
        let n = self.n;
        let base = &self.buffers[0];
        let share: Vec<f32> = (0..n * n).map(|i| base.dir(i).map_or(0.0, |d| brdf::eval(m, wo, d).max_element())).collect();
        let inside = share.iter().zip(0..n * n).filter(|(_, i)| base.dir(*i).is_some()).count().max(1);
        // The mean in f64, and a pixel above it only beyond rounding: a Lambert receiver's
        // shares are all one value, and an f32 mean of them lands a hair under it for some
        // albedos (0.5 or 0.7 at 8², most at 16²), which split every pixel of such receivers.
        let mean = share.iter().map(|&w| w as f64).sum::<f64>() / inside as f64;
        for (i, &w) in share.iter().enumerate() {
            let l = match forced {
                Some(l) => l.min(self.max_level),
                None if mean > 0.0 && w as f64 > mean * (1.0 + SHARE_ROUNDING) => {
                    ((w as f64 / mean).log2() / 2.0).ceil().clamp(0.0, self.max_level as f64) as u32
                }
                None => 0,
            };
            self.set_block(Pixel { level: 0, x: i % n, y: i / n }, l);
        }
        self.direct = self.extent[1..].iter().all(Option::is_none);
    }

    /// Sets the level of every finest pixel under `p` to `l`.
    fn set_block(&mut self, p: Pixel, l: u32) {
        let (fine, s) = (self.fine(), 1usize << (self.max_level - p.level));
        for y in p.y * s..(p.y + 1) * s {
            self.level[y * fine + p.x * s..y * fine + (p.x + 1) * s].fill(l as u8);
        }
        self.grow_extent(p, l);
    }

    /// Widens level `l`'s extent over the pixels of `l` that tile `p` (p.level ≤ l).
    fn grow_extent(&mut self, p: Pixel, l: u32) {
        let s = 1usize << (l - p.level);
        let (x0, y0, x1, y1) = (p.x * s, p.y * s, p.x * s + s - 1, p.y * s + s - 1);
        let e = &mut self.extent[l as usize];
        *e = Some(match *e {
            None => (x0, y0, x1, y1),
            Some((a, b, c, d)) => (a.min(x0), b.min(y0), c.max(x1), d.max(y1)),
        });
    }

    /// The finest-grid index of local direction `d` on the disk.
    fn fine_index(&self, d: Vec3) -> usize {
        let f = self.fine();
        let t = |c: f32| (((c + 1.0) * 0.5 * f as f32) as usize).min(f - 1);
        t(d.y) * f + t(d.x)
    }

    /// The pixel holding finest pixel `k`.
    fn pixel_of_fine(&self, k: usize) -> Pixel {
        let f = self.fine();
        let level = self.level[k] as u32;
        let shift = self.max_level - level;
        Pixel { level, x: (k % f) >> shift, y: (k / f) >> shift }
    }

    /// Splits `p` by light: its records are handed back (their nodes pushed on `stack`).
    fn split(&mut self, p: Pixel, stack: &mut Vec<u32>) {
        if self.direct {
            self.direct = false;
            if let Some(e) = self.extent[0] {
                self.buffers[0].clear_rect(e);
            }
        }
        let (fine, s) = (self.fine(), 1usize << (self.max_level - p.level));
        for y in p.y * s..(p.y + 1) * s {
            for k in y * fine + p.x * s..y * fine + (p.x + 1) * s {
                self.level[k] += 1;
                self.light_levels[k] += 1;
            }
        }
        self.light_splits += 1;
        self.grow_extent(p, p.level + 1);
        for (at, r) in &mut self.records {
            if *at == Some(p) {
                if let Record::Splat { node, .. } = r {
                    *at = None;
                    stack.push(*node);
                }
            }
        }
    }

    /// Rasterises the records into the pixels of their final levels (nothing to do where
    /// nothing refined: they went into the base buffer as they were made), each near disk
    /// with the light its centre sends.
    pub fn finish(&mut self) {
        self.finish_lit(None)
    }

    /// `finish`, a near disk's pixels reading `along(node, w)` along their own rays (local
    /// direction w from the receiver) where given. Once per `start`: later calls do nothing.
    pub fn finish_lit(&mut self, along: Option<&dyn Fn(u32, Vec3) -> Vec3>) {
        if std::mem::replace(&mut self.finished, true) {
            return;
        }
        if !self.direct {
            let records = std::mem::take(&mut self.records);
            for (at, r) in &records {
                if at.is_none() {
                    continue;
                }
                match *r {
                    Record::Splat { d, dist, omega, l, flat, .. } => self.raster_splat(d, dist, omega, l, flat),
                    Record::Disk { node, c, nrm, r, l, eps } => match along {
                        Some(f) => self.raster_disk(c, nrm, r, &DiskLight::Along(&|w| f(node, w)), eps),
                        None => self.raster_disk(c, nrm, r, &DiskLight::Uniform(l), eps),
                    },
                }
            }
            self.records = records;
        }
        for (b, e) in self.buffers.iter_mut().zip(&self.extent) {
            if let Some(e) = *e {
                b.resolve_rect(e);
            }
        }
    }

    /// A near leaf's exact disk: each pixel, at its own level, shows the disk where its centre
    /// ray meets it. The pixels are found down the quadtree from the base pixels in the disk's
    /// box, so a level costs only its own pixels (a pixel outside its level's box has no
    /// children inside theirs: the boxes shrink with the level).
    fn raster_disk(&mut self, c: Vec3, nrm: Vec3, r: f32, l: &DiskLight, eps: f32) {
        let bounds: Vec<DiskBounds> = self.buffers.iter().map(|b| b.disk_bounds(c, OCCLUDE_REACH * r)).collect();
        let fine = self.fine();
        let mut stack: Vec<Pixel> = vec![];
        let b0 = bounds[0];
        for y in (b0.lo.1..=b0.hi.1).rev() {
            for x in (b0.lo.0..=b0.hi.0).rev() {
                stack.push(Pixel { level: 0, x, y });
            }
        }
        while let Some(p) = stack.pop() {
            let b = &bounds[p.level as usize];
            if !b.contains(p.x, p.y) {
                continue;
            }
            let shift = self.max_level - p.level;
            if self.level[(p.y << shift) * fine + (p.x << shift)] as u32 == p.level {
                let side = self.n << p.level;
                self.buffers[p.level as usize].disk_pixel(p.y * side + p.x, b, c, nrm, r, l, eps);
            } else {
                for (dx, dy) in [(1, 1), (0, 1), (1, 0), (0, 0)] {
                    stack.push(Pixel { level: p.level + 1, x: 2 * p.x + dx, y: 2 * p.y + dy });
                }
            }
        }
    }

    /// The uniform splat at the level of the pixel `d` lands in, its writes sent to the
    /// pixels that hold them (a tap on a pixel of another level goes to that pixel, with its
    /// coverage measured against that pixel's own solid angle).
    fn raster_splat(&mut self, d: Vec3, dist: f32, omega: f32, l: Vec3, flat: Option<Flat>) {
        let p = self.pixel_of_fine(self.fine_index(d));
        let level = p.level;
        let mut writes = std::mem::take(&mut self.writes);
        writes.clear();
        self.buffers[level as usize].splat_writes(d, omega, &mut |i, cov| writes.push((i, cov)));
        let side = self.n << level;
        let shift = self.max_level - level;
        let fine = self.fine();
        for &(i, cov) in &writes {
            let (x, y) = (i % side, i / side);
            let k = (y << shift) * fine + (x << shift);
            let q = self.pixel_of_fine(k);
            if q.level == level {
                self.buffers[level as usize].write(i, dist, l, cov, cov, flat);
            } else {
                // The tap's solid angle at this level, as a share of pixel q's.
                let from = &self.buffers[level as usize];
                let to = &self.buffers[q.level as usize];
                let qi = q.y * (self.n << q.level) + q.x;
                let (Some(dp), Some(dq)) = (from.dir(i), to.dir(qi)) else { continue };
                let scale = (from.pixel_weight() / dp.z.max(1e-3)) / (to.pixel_weight() / dq.z.max(1e-3));
                self.buffers[q.level as usize].write(qi, dist, l, cov * scale, cov * scale, flat);
            }
        }
        self.writes = writes;
    }

    /// Outgoing radiance toward `wo` (local): Σ over the pixels of every level of f(wo, ωk)
    /// L_k × the pixel's projected solid angle.
    pub fn convolve(&self, m: &Material, wo: Vec3) -> Vec3 {
        let fine = self.fine();
        let mut sum = Vec3::ZERO;
        for (level, (b, e)) in self.buffers.iter().zip(&self.extent).enumerate() {
            let Some((x0, y0, x1, y1)) = *e else { continue };
            let side = self.n << level;
            let shift = self.max_level as usize - level;
            let (mut part, radiance) = (Vec3::ZERO, b.radiance());
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let i = y * side + x;
                    if self.level[(y << shift) * fine + (x << shift)] as usize != level || radiance[i] == Vec3::ZERO {
                        continue;
                    }
                    if let Some(d) = b.dir(i) {
                        part += brdf::eval(m, wo, d) * radiance[i];
                    }
                }
            }
            sum += part * b.pixel_weight();
        }
        sum
    }

    /// Pixels per level (for the report and tests).
    pub fn pixels_per_level(&self) -> Vec<usize> {
        let fine = self.fine();
        let mut count = vec![0; self.max_level as usize + 1];
        for (k, &l) in self.level.iter().enumerate() {
            let shift = self.max_level - l as u32;
            let (x, y) = (k % fine, k / fine);
            if x.is_multiple_of(1 << shift) && y.is_multiple_of(1 << shift) {
                count[l as usize] += 1;
            }
        }
        count
    }
}

impl GatherBuffer for AdaptiveMicrobuffer {
    fn begin(&mut self, m: &Material, wo: Vec3) {
        self.start(m, wo, None);
    }
    /// The traversal, then the records rastered at their final levels, a near disk of a
    /// source whose leaves send a lobe read along each pixel's ray.
    fn gather<R: NodeRadiance>(
        &mut self,
        t: &Traversal<R>,
        _: &Material,
        p: Vec3,
        frame: &Frame,
        stack: &mut Vec<u32>,
        counts: &mut GatherCounts,
    ) {
        t.run(&[t.tree.outer_root()], p, frame, self, stack, counts, |_, _| false);
        if t.source.directional_leaves() {
            self.finish_lit(Some(&|node, w| radiance_along(t.source, node, frame, w)));
        }
    }
    fn end(&mut self, m: &Material, wo: Vec3) -> Vec3 {
        self.finish();
        self.convolve(m, wo)
    }
}

impl Raster for AdaptiveMicrobuffer {
    fn pixel_solid_angle(&self, d: Vec3) -> f32 {
        if self.coarse_cut {
            return self.buffers[0].mean_pixel_solid_angle();
        }
        let p = self.pixel_of_fine(self.fine_index(d));
        self.buffers[p.level as usize].mean_pixel_solid_angle()
    }

    fn splat(&mut self, node: u32, d: Vec3, dist: f32, omega: f32, l: Vec3, flat: Option<Flat>, stack: &mut Vec<u32>) {
        if d.z <= 0.0 || omega <= 0.0 {
            return;
        }
        let k = self.fine_index(d);
        let p = self.pixel_of_fine(k);
        if p.level < self.max_level && l.max_element() / 2f32.powi(self.light_levels[k] as i32) > self.gamma {
            self.split(p, stack);
            stack.push(node);
            return;
        }
        if self.direct {
            self.buffers[0].splat(d, dist, omega, l, flat);
        }
        self.records.push((Some(p), Record::Splat { node, d, dist, omega, l, flat }));
    }

    fn disk(&mut self, node: u32, c: Vec3, nrm: Vec3, r: f32, l: &DiskLight, eps: f32) {
        if self.direct {
            self.buffers[0].disk_lit(c, nrm, r, l, eps);
        }
        let l = l.along(c.normalize_or(Vec3::Z));
        self.records.push((Some(Pixel { level: 0, x: 0, y: 0 }), Record::Disk { node, c, nrm, r, l, eps }));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::pbgi_setup;

    /// Gathers receiver `i` of the Cornell set-up into `mb` (adaptive) and returns the
    /// outgoing radiance and the counts.
    fn gather_adaptive(i: usize, mb: &mut AdaptiveMicrobuffer, forced: Option<u32>) -> (Vec3, GatherCounts) {
        let (tree, r) = pbgi_setup::tree_and_receivers();
        let t = Traversal::new(&tree, 1.0, 1e-5 * 4.0);
        let frame = Frame::from_normal(r.normal[i]);
        let wo = frame.to_local(r.wo[i]);
        mb.start(&r.material[i], wo, forced);
        let (mut stack, mut counts) = (vec![], GatherCounts::default());
        t.run(&[tree.root], r.position[i], &frame, mb, &mut stack, &mut counts, |_, _| false);
        mb.finish();
        (mb.convolve(&r.material[i], wo), counts)
    }

    #[test]
    fn a_lambert_receiver_keeps_the_base_buffer_whatever_its_albedo() {
        // An f32 mean of equal shares rounds under them for some albedos and sizes (0.5 and
        // 0.7 at 8², 0.2, 0.4, 0.7, 0.8 at 16²): every pixel was split by rounding.
        for n in [8, 16] {
            let mut mb = AdaptiveMicrobuffer::new(n, 2, f32::INFINITY);
            for albedo in [0.2, 0.4, 0.5, 0.6, 0.7, 0.73, 0.8] {
                mb.start(&Material::Lambert { albedo: Vec3::splat(albedo) }, Vec3::new(0.3, 0.1, 0.9).normalize(), None);
                let levels = mb.pixels_per_level();
                assert!(mb.direct && levels[1..].iter().all(|&c| c == 0), "{n}², albedo {albedo}: {levels:?}");
            }
            // A glossy lobe still splits the pixels under it.
            mb.start(&Material::BlinnPhong { kd: Vec3::ZERO, ks: Vec3::ONE, exponent: 180.0 }, Vec3::new(0.3, 0.1, 0.9).normalize(), None);
            assert!(!mb.direct, "{n}²: {:?}", mb.pixels_per_level());
        }
    }

    #[test]
    fn refinement_forced_everywhere_equals_the_uniform_buffer_of_that_level() {
        let (tree, r) = pbgi_setup::tree_and_receivers();
        let t = Traversal::new(&tree, 1.0, 1e-5 * 4.0);
        let mut adaptive = AdaptiveMicrobuffer::new(8, 2, f32::INFINITY);
        for level in [0, 1, 2] {
            let mut uniform = Microbuffer::new(8 << level);
            for i in (0..r.len()).step_by(7) {
                let frame = Frame::from_normal(r.normal[i]);
                let wo = frame.to_local(r.wo[i]);
                uniform.clear();
                let (mut stack, mut counts) = (vec![], GatherCounts::default());
                t.run(&[tree.root], r.position[i], &frame, &mut uniform, &mut stack, &mut counts, |_, _| false);
                uniform.resolve();
                let want = uniform.convolve(&r.material[i], wo);
                let (got, c) = gather_adaptive(i, &mut adaptive, Some(level));
                assert_eq!(got, want, "receiver {i}, level {level}");
                assert_eq!((c.visited, c.rasterised, c.near_leaves), (counts.visited, counts.rasterised, counts.near_leaves));
                assert_eq!(adaptive.buffers[level as usize].radiance(), uniform.radiance(), "receiver {i}, level {level}");
            }
        }
    }

    #[test]
    fn refined_pixels_read_a_near_disks_lobe_along_their_own_rays() {
        // A disk whose light grows with the ray's x, kept and rastered again at level 1
        // everywhere: with the lobe handed to `finish_lit`, the pixels are the uniform 16²
        // buffer's; `finish` alone paints the light toward the centre over the whole disk.
        let lambert = Material::Lambert { albedo: Vec3::ONE };
        let (c, nrm, r) = (Vec3::new(0.1, 0.0, 0.5), Vec3::new(0.0, 0.0, -1.0), 0.3);
        let lobe = |w: Vec3| Vec3::splat(1.0 + w.x);
        let mut uniform = Microbuffer::new(16);
        uniform.disk_lit(c, nrm, r, &DiskLight::Along(&lobe), 1e-6);
        uniform.resolve();
        let fill = |with_lobe: bool| {
            let mut mb = AdaptiveMicrobuffer::new(8, 1, f32::INFINITY);
            mb.start(&lambert, Vec3::Z, Some(1));
            Raster::disk(&mut mb, 7, c, nrm, r, &DiskLight::Along(&lobe), 1e-6);
            if with_lobe {
                mb.finish_lit(Some(&|node, w| {
                    assert_eq!(node, 7);
                    lobe(w)
                }));
            } else {
                mb.finish();
            }
            mb.buffers[1].radiance().to_vec()
        };
        assert_eq!(fill(true), uniform.radiance());
        let centre = lobe(c.normalize());
        let painted = fill(false);
        assert!(painted.iter().zip(uniform.radiance()).any(|(a, b)| a != b));
        assert!(painted.iter().all(|l| l.x <= centre.x + 1e-6), "one light over the disk");
    }

    #[test]
    fn a_coarse_cut_opens_the_tree_as_the_base_buffer_does_and_rasterises_finer() {
        // Forced to level 2 with the cut chosen against the base 8² pixels: the traversal is
        // the uniform 8² buffer's, node for node; the pixels are the 32² buffer's.
        let (tree, r) = pbgi_setup::tree_and_receivers();
        let t = Traversal::new(&tree, 1.0, 1e-5 * 4.0);
        let mut coarse = AdaptiveMicrobuffer::new(8, 2, f32::INFINITY).with_coarse_cut(true);
        let (mut base_sum, mut coarse_sum, mut fine_sum) = (0.0, 0.0, 0.0);
        for i in (0..r.len()).step_by(7) {
            let frame = Frame::from_normal(r.normal[i]);
            let wo = frame.to_local(r.wo[i]);
            let uniform = |n: usize| {
                let mut mb = Microbuffer::new(n);
                let (mut stack, mut counts) = (vec![], GatherCounts::default());
                t.run(&[tree.root], r.position[i], &frame, &mut mb, &mut stack, &mut counts, |_, _| false);
                mb.resolve();
                (mb.convolve(&r.material[i], wo), counts)
            };
            let ((base, want), (fine, _)) = (uniform(8), uniform(32));
            let (got, c) = gather_adaptive(i, &mut coarse, Some(2));
            assert_eq!((c.visited, c.rasterised, c.near_leaves), (want.visited, want.rasterised, want.near_leaves), "receiver {i}");
            assert_eq!(coarse.pixels_per_level()[2], 32 * 32);
            assert!(got.is_finite() && got.min_element() >= 0.0, "receiver {i}: {got}");
            base_sum += base.x as f64;
            coarse_sum += got.x as f64;
            fine_sum += fine.x as f64;
        }
        // The same light, spread over finer pixels: the totals agree with both buffers'.
        // The finer pixels move the result toward the 32² buffer's (measured: 2.480 against
        // 2.337 at 8² and 2.478 at 32²).
        assert!(
            (coarse_sum - fine_sum).abs() < (base_sum - fine_sum).abs(),
            "coarse cut {coarse_sum}, uniform 8² {base_sum}, 32² {fine_sum}"
        );
    }

    #[test]
    fn a_lambert_receiver_keeps_the_base_buffer_and_a_glossy_one_refines_around_its_lobe() {
        let mut mb = AdaptiveMicrobuffer::new(16, 3, f32::INFINITY);
        mb.start(&Material::Lambert { albedo: Vec3::ONE }, Vec3::Z, None);
        assert_eq!(mb.pixels_per_level(), [256, 0, 0, 0]);
        let glossy = Material::BlinnPhong { kd: Vec3::splat(0.1), ks: Vec3::splat(0.5), exponent: 180.0 };
        let wo = Vec3::new(0.5, 0.0, 0.8).normalize();
        mb.start(&glossy, wo, None);
        let levels = mb.pixels_per_level();
        assert!(levels[3] > 0 && levels[0] > 200, "{levels:?}");
        // The finest pixels sit around the mirror direction (−0.5, 0, 0.8).
        let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
        let k = mb.fine_index(mirror);
        assert_eq!(mb.level[k], 3, "{levels:?}");
        assert_eq!(mb.level[mb.fine_index(Vec3::new(0.6, 0.6, 0.5).normalize())], 0);
    }

    #[test]
    fn bright_light_splits_its_pixels_and_the_result_stays_near_the_fine_uniform_buffer() {
        // γ below the Cornell light's bounce radiance: pixels seeing bright nodes split.
        let (_, r) = pbgi_setup::tree_and_receivers();
        let lambert = (0..r.len()).find(|&i| matches!(r.material[i], Material::Lambert { .. })).unwrap();
        let mut coarse = AdaptiveMicrobuffer::new(8, 2, f32::INFINITY);
        let (base, c0) = gather_adaptive(lambert, &mut coarse, None);
        let mut fine = AdaptiveMicrobuffer::new(8, 2, f32::INFINITY);
        let (want, _) = gather_adaptive(lambert, &mut fine, Some(2));
        let mut lit = AdaptiveMicrobuffer::new(8, 2, 0.02);
        let (got, c) = gather_adaptive(lambert, &mut lit, None);
        assert!(lit.light_splits > 0 && c.visited > c0.visited, "{} splits", lit.light_splits);
        let levels = lit.pixels_per_level();
        assert!(levels[1] + levels[2] > 0, "{levels:?}");
        // Splitting where the light is does not move the result farther from the fine buffer.
        let err = |x: Vec3| ((x - want).length() / want.length()) as f64;
        assert!(err(got) <= err(base) + 0.02, "adaptive {got}, coarse {base}, fine {want}");
    }
}
