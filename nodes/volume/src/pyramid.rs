//! The min/max pyramid of one channel of a volume ([S] 6.3.2, figure 6-4): level 0 holds each
//! voxel cell's range, level k + 1 the range over 2 × 2 × 2 cells of level k (odd sizes round
//! up: the last cell covers what is left). A cell's range at level 0 spans the voxel and its
//! neighbours on both sides along each axis (27 centres: trilinear sampling anywhere inside
//! the voxel's cube blends the centres from the previous voxel's to the next one's), so a
//! leaf whose range is below a threshold really holds a field flatter than that everywhere
//! inside it. (Counting only the upper neighbours left the lower half-voxel of every leaf
//! unbounded: measured on the glass sphere, long photon steps crossed the interface's edge
//! there.)

use crate::types::volume::Volume;
use rayon::prelude::*;

/// One level: its dimensions and (min, max) per cell, x fastest.
#[derive(Clone, Debug, PartialEq)]
pub struct Level {
    pub dims: [usize; 3],
    pub range: Vec<(f32, f32)>,
}

impl Level {
    #[inline]
    pub fn at(&self, x: usize, y: usize, z: usize) -> (f32, f32) {
        self.range[(z * self.dims[1] + y) * self.dims[0] + x]
    }
}

/// Levels from the voxels (0) up to a single cell.
#[derive(Clone, Debug, PartialEq)]
pub struct MinMaxPyramid {
    pub levels: Vec<Level>,
}

impl MinMaxPyramid {
    /// The pyramid of channel `c` of `v`.
    pub fn build(v: &Volume, c: usize) -> MinMaxPyramid {
        let d = v.dims.map(|x| x as usize);
        // Separable, one z slab (or row) a task: the range over x ± 1, then y ± 1, then z ± 1
        // (clipped to the grid), least and largest apart, then paired.
        let (row, plane) = (d[0], d[0] * d[1]);
        let vc = v.channels as usize;
        let (mut lo, mut hi) = (vec![0f32; v.voxels()], vec![0f32; v.voxels()]);
        lo.par_chunks_mut(row).zip(hi.par_chunks_mut(row)).zip(v.data.par_chunks(row * vc)).for_each(|((lo, hi), r)| {
            let at = |x: usize| r[x * vc + c];
            for x in 0..row {
                let (o, a, b) = (at(x), at(x.saturating_sub(1)), at((x + 1).min(row - 1)));
                (lo[x], hi[x]) = (o.min(a).min(b), o.max(a).max(b));
            }
        });
        // Along y, each row from its own and its clipped neighbours' in `lo`, `hi`.
        let (mut l2, mut h2) = (vec![0f32; lo.len()], vec![0f32; lo.len()]);
        l2.par_chunks_mut(row).zip(h2.par_chunks_mut(row)).enumerate().for_each(|(i, (l, h))| {
            let (p, first) = (i % d[1], i / d[1] * plane);
            let at = |q: usize| first + q * row..first + (q + 1) * row;
            let [own, before, after] = [at(p), at(p.saturating_sub(1)), at((p + 1).min(d[1] - 1))];
            for (((l, &o), &b), &a) in l.iter_mut().zip(&lo[own.clone()]).zip(&lo[before.clone()]).zip(&lo[after.clone()]) {
                *l = o.min(b).min(a);
            }
            for (((h, &o), &b), &a) in h.iter_mut().zip(&hi[own]).zip(&hi[before]).zip(&hi[after]) {
                *h = o.max(b).max(a);
            }
        });
        // Along z, each plane straight into the level's (least, largest) pairs.
        let mut range = vec![(0f32, 0f32); lo.len()];
        range.par_chunks_mut(plane).enumerate().for_each(|(p, out)| {
            let at = |q: usize| q * plane..(q + 1) * plane;
            let [own, before, after] = [at(p), at(p.saturating_sub(1)), at((p + 1).min(d[2] - 1))];
            let (lo, hi) = ((&l2[own.clone()], &l2[before.clone()], &l2[after.clone()]), (&h2[own], &h2[before], &h2[after]));
            for (i, r) in out.iter_mut().enumerate() {
                *r = (lo.0[i].min(lo.1[i]).min(lo.2[i]), hi.0[i].max(hi.1[i]).max(hi.2[i]));
            }
        });
        let mut levels = vec![Level { dims: d, range }];
        while levels.last().is_some_and(|l| l.dims.iter().any(|&n| n > 1)) {
            let below = levels.last().expect("a level");
            let dims = below.dims.map(|n| n.div_ceil(2));
            // One z slab of the new level a task; each cell the same fold over its 8 children.
            let mut range = vec![(0f32, 0f32); dims.iter().product()];
            range.par_chunks_mut(dims[0] * dims[1]).enumerate().for_each(|(z, slab)| {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                        for (dx, dy, dz) in (0..8).map(|k| (k & 1, (k >> 1) & 1, k >> 2)) {
                            let (cx, cy, cz) = (2 * x + dx, 2 * y + dy, 2 * z + dz);
                            if cx < below.dims[0] && cy < below.dims[1] && cz < below.dims[2] {
                                let (a, b) = below.at(cx, cy, cz);
                                (lo, hi) = (lo.min(a), hi.max(b));
                            }
                        }
                        slab[y * dims[0] + x] = (lo, hi);
                    }
                }
            });
            levels.push(Level { dims, range });
        }
        MinMaxPyramid { levels }
    }

    /// The range of the level-`k` cell holding voxel (x, y, z).
    pub fn range_at(&self, k: usize, x: usize, y: usize, z: usize) -> (f32, f32) {
        self.levels[k].at(x >> k, y >> k, z >> k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn volume(dims: [u32; 3], f: impl Fn(usize, usize, usize) -> f32) -> Volume {
        let mut v = Volume::try_new(dims, 1, Vec3::ZERO, Vec3::ONE, 0.0, u64::MAX).unwrap();
        for z in 0..dims[2] as usize {
            for y in 0..dims[1] as usize {
                for x in 0..dims[0] as usize {
                    let i = v.index(x, y, z);
                    v.data[i] = f(x, y, z);
                }
            }
        }
        v
    }

    #[test]
    fn every_level_bounds_the_voxels_below_it_and_the_top_is_the_whole_range() {
        // Odd sizes: 5 × 3 × 7 → 3 × 2 × 4 → 2 × 1 × 2 → 1 × 1 × 1.
        let v = volume([5, 3, 7], |x, y, z| ((x * 7 + y * 13 + z * 5) % 11) as f32 * 0.1);
        let p = MinMaxPyramid::build(&v, 0);
        let dims: Vec<[usize; 3]> = p.levels.iter().map(|l| l.dims).collect();
        assert_eq!(dims, [[5, 3, 7], [3, 2, 4], [2, 1, 2], [1, 1, 1]]);
        let (lo, hi) = v.data.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        assert_eq!(p.levels[3].at(0, 0, 0), (lo, hi));
        for k in 0..4 {
            for z in 0..7 {
                for y in 0..3 {
                    for x in 0..5 {
                        let (a, b) = p.range_at(k, x, y, z);
                        assert!(a <= v.get(x, y, z, 0) && v.get(x, y, z, 0) <= b, "level {k} at {x} {y} {z}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_cell_sees_its_neighbours_on_both_sides_so_a_step_shows_in_the_voxels_that_blend_it() {
        // A jump between x = 3 and x = 4: trilinear sampling blends it anywhere in voxels 3 and
        // 4 (the upper half of 3, the lower half of 4), so both cells span it; 2 and 5 do not.
        let v = volume([8, 2, 2], |x, _, _| if x < 4 { 1.0 } else { 2.4 });
        let p = MinMaxPyramid::build(&v, 0);
        assert_eq!(p.range_at(0, 3, 0, 0), (1.0, 2.4));
        assert_eq!(p.range_at(0, 4, 0, 0), (1.0, 2.4));
        assert_eq!(p.range_at(0, 2, 0, 0), (1.0, 1.0));
        assert_eq!(p.range_at(0, 5, 0, 0), (2.4, 2.4));
        assert_eq!(p.range_at(1, 2, 0, 0), (1.0, 2.4));
        assert_eq!(p.range_at(1, 0, 0, 0), (1.0, 1.0));
        assert_eq!(p.range_at(1, 6, 0, 0), (2.4, 2.4));
        // The trilinear index inside a cell stays within its range.
        let s = crate::types::Sampler::new(&v);
        for k in 0..=80 {
            let x = k as f32 / 80.0;
            let n = s.sample_n::<1>(Vec3::new(x, 0.5, 0.5), 0)[0];
            let (lo, hi) = p.range_at(0, ((x * 8.0) as usize).min(7), 0, 0);
            assert!(lo <= n && n <= hi, "x = {x}: n = {n} outside {lo} … {hi}");
        }
    }
}
