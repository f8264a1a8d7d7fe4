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

use super::microbuffer::{layer_write, Microbuffer};
use super::traversal::Raster;
use crate::brdf;
use crate::types::Material;
use glam::Vec3;

/// One rasterisation to replay: a splat or a near leaf's exact disk.
#[derive(Clone, Copy, Debug)]
enum Record {
    Splat { node: u32, d: Vec3, dist: f32, omega: f32, l: Vec3 },
    Disk { c: Vec3, nrm: Vec3, r: f32, l: Vec3, eps: f32 },
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
    /// Records in the order they were made, with the pixel each landed in (`None` once
    /// handed back for another visit).
    records: Vec<(Option<Pixel>, Record)>,
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
            records: vec![],
            light_splits: 0,
            writes: vec![],
        }
    }

    fn fine(&self) -> usize {
        self.n << self.max_level
    }

    /// Resets the buffer for a receiver and sets each base pixel's level from the BRDF
    /// importance of `m` seen from `wo` (local); `forced` puts every pixel at that level.
    pub fn start(&mut self, m: &Material, wo: Vec3, forced: Option<u32>) {
        for b in &mut self.buffers {
            b.clear();
        }
        self.records.clear();
        self.light_levels.fill(0);
        self.light_splits = 0;
        let n = self.n;
        let base = &self.buffers[0];
        let share: Vec<f32> = (0..n * n).map(|i| base.dir(i).map_or(0.0, |d| brdf::eval(m, wo, d).max_element())).collect();
        let inside = share.iter().zip(0..n * n).filter(|(_, i)| base.dir(*i).is_some()).count().max(1);
        let mean = share.iter().sum::<f32>() / inside as f32;
        for (i, &w) in share.iter().enumerate() {
            let l = match forced {
                Some(l) => l.min(self.max_level),
                None if mean > 0.0 && w > mean => ((w / mean).log2() / 2.0).ceil().clamp(0.0, self.max_level as f32) as u32,
                None => 0,
            };
            self.set_block(Pixel { level: 0, x: i % n, y: i / n }, l);
        }
    }

    /// Sets the level of every finest pixel under `p` to `l`.
    fn set_block(&mut self, p: Pixel, l: u32) {
        let (fine, s) = (self.fine(), 1usize << (self.max_level - p.level));
        for y in p.y * s..(p.y + 1) * s {
            self.level[y * fine + p.x * s..y * fine + (p.x + 1) * s].fill(l as u8);
        }
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
        let (fine, s) = (self.fine(), 1usize << (self.max_level - p.level));
        for y in p.y * s..(p.y + 1) * s {
            for k in y * fine + p.x * s..y * fine + (p.x + 1) * s {
                self.level[k] += 1;
                self.light_levels[k] += 1;
            }
        }
        self.light_splits += 1;
        for (at, r) in &mut self.records {
            if *at == Some(p) {
                if let Record::Splat { node, .. } = r {
                    *at = None;
                    stack.push(*node);
                }
            }
        }
    }

    /// Rasterises the records into the pixels of their final levels.
    pub fn finish(&mut self) {
        let records = std::mem::take(&mut self.records);
        for (at, r) in &records {
            if at.is_none() {
                continue;
            }
            match *r {
                Record::Splat { d, dist, omega, l, .. } => self.raster_splat(d, dist, omega, l),
                Record::Disk { c, nrm, r, l, eps } => {
                    // Each pixel of each level shows the disk where its centre ray meets it.
                    let fine = self.fine();
                    for level in 0..=self.max_level {
                        let (side, shift) = (self.n << level, self.max_level - level);
                        let levels = &self.level;
                        let at_level = |i: usize| levels[((i / side) << shift) * fine + ((i % side) << shift)] as u32 == level;
                        self.buffers[level as usize].disk_exact_where(c, nrm, r, l, eps, at_level);
                    }
                }
            }
        }
        self.records = records;
    }

    /// The uniform splat at the level of the pixel `d` lands in, its writes sent to the
    /// pixels that hold them (a tap on a pixel of another level goes to that pixel, with its
    /// coverage measured against that pixel's own solid angle).
    fn raster_splat(&mut self, d: Vec3, dist: f32, omega: f32, l: Vec3) {
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
                let b = &mut self.buffers[level as usize];
                layer_write(&mut b.depth[i], &mut b.radiance[i], &mut b.coverage[i], dist, l, cov);
            } else {
                // The tap's solid angle at this level, as a share of pixel q's.
                let from = &self.buffers[level as usize];
                let to = &self.buffers[q.level as usize];
                let qi = q.y * (self.n << q.level) + q.x;
                let (Some(dp), Some(dq)) = (from.dir(i), to.dir(qi)) else { continue };
                let scale = (from.pixel_weight() / dp.z.max(1e-3)) / (to.pixel_weight() / dq.z.max(1e-3));
                let b = &mut self.buffers[q.level as usize];
                layer_write(&mut b.depth[qi], &mut b.radiance[qi], &mut b.coverage[qi], dist, l, cov * scale);
            }
        }
        self.writes = writes;
    }

    /// Outgoing radiance toward `wo` (local): Σ over the pixels of every level of f(wo, ωk)
    /// L_k × the pixel's projected solid angle.
    pub fn convolve(&self, m: &Material, wo: Vec3) -> Vec3 {
        let fine = self.fine();
        let mut sum = Vec3::ZERO;
        for (level, b) in self.buffers.iter().enumerate() {
            let side = self.n << level;
            let shift = self.max_level as usize - level;
            let mut part = Vec3::ZERO;
            for i in 0..side * side {
                let (x, y) = (i % side, i / side);
                if self.level[(y << shift) * fine + (x << shift)] as usize != level || b.radiance[i] == Vec3::ZERO {
                    continue;
                }
                if let Some(d) = b.dir(i) {
                    part += brdf::eval(m, wo, d) * b.radiance[i];
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

impl super::traversal::GatherBuffer for AdaptiveMicrobuffer {
    fn begin(&mut self, m: &Material, wo: Vec3) {
        self.start(m, wo, None);
    }
    fn end(&mut self, m: &Material, wo: Vec3) -> Vec3 {
        self.finish();
        self.convolve(m, wo)
    }
}

impl Raster for AdaptiveMicrobuffer {
    fn pixel_solid_angle(&self, d: Vec3) -> f32 {
        let p = self.pixel_of_fine(self.fine_index(d));
        self.buffers[p.level as usize].mean_pixel_solid_angle()
    }

    fn splat(&mut self, node: u32, d: Vec3, dist: f32, omega: f32, l: Vec3, stack: &mut Vec<u32>) {
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
        self.records.push((Some(p), Record::Splat { node, d, dist, omega, l }));
    }

    fn disk(&mut self, _: u32, c: Vec3, nrm: Vec3, r: f32, l: Vec3, eps: f32) {
        self.records.push((Some(Pixel { level: 0, x: 0, y: 0 }), Record::Disk { c, nrm, r, l, eps }));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::frame::Frame;
    use crate::pbgi::traversal::{GatherCounts, Traversal};
    use crate::testing::pbgi_setup;

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
                let want = uniform.convolve(&r.material[i], wo);
                let (got, c) = gather_adaptive(i, &mut adaptive, Some(level));
                assert_eq!(got, want, "receiver {i}, level {level}");
                assert_eq!((c.visited, c.rasterised, c.near_leaves), (counts.visited, counts.rasterised, counts.near_leaves));
                assert_eq!(adaptive.buffers[level as usize].radiance, uniform.radiance, "receiver {i}, level {level}");
            }
        }
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
