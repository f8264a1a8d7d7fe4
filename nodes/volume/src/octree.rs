use super::octree_layout::{CHANNELS, CLEARANCE, CLEARANCE_CAP, GRADIENT};
use super::pyramid::MinMaxPyramid;
use crate::types::Volume;
use glam::Vec3;
use rayon::prelude::*;
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// The adaptive step of photon marching ([S] 6.3.2, 6.4.3, figure 6-4), per voxel of the
    /// refractive index (channel 0 of `medium`): from the min/max pyramid (a cell spans its
    /// voxels and their upper neighbours, what trilinear sampling blends), the voxel's leaf is the
    /// largest aligned cell whose index range is below ε′ (`flat`, 0.02); the largest step
    /// Δs_max is unbounded where the leaf's range is below ε (`uniform`, 0.005), `step` voxels (8)
    /// where it is between, and 0 — the marcher's minimum step — where even the voxel's own cell
    /// spans ε′ or more. This is the reading docs/PIPELINES.md gives: read literally (leaves built with
    /// ε, then "8 voxels below ε′") the ε′ rule never fires. Extinction does not shape the leaves ([S] 6.3.2 found it mattered little: the
    /// marcher integrates it exactly voxel by voxel); instead each voxel records whether its
    /// leaf is clear (κ = 0 all through it), where the eikonal render may take the leaf's steps
    /// too, having nothing to gather there. Output, 8 channels on the same grid: the leaf level
    /// (cell side 2^level voxels, aligned to multiples of it), Δs_max in voxels (+∞ for
    /// unbounded), clear (1 or 0), the clearance (0 where the voxel or a neighbour has
    /// |∇n| × voxel > 10⁻⁶: where a ray's trilinear gradient can be non-zero, "bends"; elsewhere
    /// the L∞ distance in voxels to the nearest such voxel, at most 16), then n (the
    /// medium's own) and ∇n (central differences one voxel apart, replicated at the faces:
    /// trilinear sampling of these is the central difference of the trilinear index, what
    /// `Volume::gradient` computes) side by side, so that a ray step reads both in one lookup. A
    /// straight line that crosses no voxel that bends is a ray the medium leaves exactly straight:
    /// the photons and the render's shadow rays split the light by it, and a ray in a voxel of
    /// clearance c may fly c − 1 voxels (along the axis it moves fastest along) straight on
    /// without a lookup (`optics::straight_run`).
    pub struct Octree {
        /// ε: an index range below this is uniform (unbounded steps)
        pub uniform: f32 = 0.005, range = 0.0..=1.0;
        /// ε′: an index range below this is flat enough for a leaf
        pub flat: f32 = 0.02, range = 0.0..=1.0;
        /// Δs_max inside leaves that are flat but not uniform
        pub step: f32 = 8.0, range = 1.0..=1024.0, unit = "voxels";
    }
}

/// The octree of channel 0 of `v` (see the node's doc) and the voxel counts per step class
/// [unbounded, `step`, minimum].
pub fn build(v: &Volume, o: &Octree, budget: u64) -> Result<(Volume, [u64; 3]), NodeError> {
    if o.uniform.partial_cmp(&o.flat) == Some(std::cmp::Ordering::Greater) || o.uniform.is_nan() || o.flat.is_nan() {
        return Err(NodeError::param("uniform", format!("ε = {} must not exceed ε′ = {}", o.uniform, o.flat)));
    }
    let mut out = Volume::try_new(v.dims, CHANNELS, v.min, v.max, 0.0, budget)?;
    let p = MinMaxPyramid::build(v, 0);
    // Where nothing absorbs anywhere every leaf is clear: no pyramid of κ needed.
    let absorbs = v.absorbs();
    let kappa = absorbs.then(|| MinMaxPyramid::build(v, 1));
    let h = v.voxel();
    let d = v.dims.map(|x| x as usize);
    let ch = CHANNELS as usize;
    let vc = v.channels as usize;
    let slab = d[0] * d[1] * ch;
    let flat = |r: (f32, f32)| r.1 - r.0 < o.flat;
    // The leaf level of the cells of level 1 (their voxels' leaf unless level 0 is flat only
    // alone): ranges only grow with the level, so the largest flat level over a cell is its
    // parent's when that is flat, else its own when flat, found from the top down.
    let above = leaf_levels(&p, 1, flat);
    let (d1x, d1y) = p.levels.get(1).map_or((0, 0), |l| (l.dims[0], l.dims[1]));
    let (gx, gy, gz) = (2.0 * h.x, 2.0 * h.y, 2.0 * h.z);
    // One z slab a task; each voxel is computed alone, so any thread count gives the same bytes.
    let counts = out
        .data
        .par_chunks_mut(slab)
        .enumerate()
        .map(|(z, slab)| {
            let mut counts = [0u64; 3];
            let (zm, zp) = (z.saturating_sub(1), (z + 1).min(d[2] - 1));
            for y in 0..d[1] {
                let (ym, yp) = (y.saturating_sub(1), (y + 1).min(d[1] - 1));
                let row = |yy: usize, zz: usize| &v.data[(zz * d[1] + yy) * d[0] * vc..][..d[0] * vc];
                let (here, down, up, back, front) = (row(y, z), row(ym, z), row(yp, z), row(y, zm), row(y, zp));
                for x in 0..d[0] {
                    let (xm, xp) = (x.saturating_sub(1), (x + 1).min(d[0] - 1));
                    let n = |r: &[f32], x: usize| r[x * vc];
                    let g = [(n(here, xp) - n(here, xm)) / gx, (n(up, x) - n(down, x)) / gy, (n(front, x) - n(back, x)) / gz];
                    let own = p.range_at(0, x, y, z);
                    let (level, step, class) = if !flat(own) {
                        (0, 0.0, 2)
                    } else {
                        let level = match above.get((((z >> 1) * d1y) + (y >> 1)) * d1x + (x >> 1)) {
                            Some(&l) if l != NOT_FLAT => l as usize,
                            _ => 0,
                        };
                        let (lo, hi) = if level == 0 { own } else { p.range_at(level, x, y, z) };
                        if hi - lo < o.uniform {
                            (level, f32::INFINITY, 0)
                        } else {
                            (level, o.step, 1)
                        }
                    };
                    let clear = kappa.as_ref().is_none_or(|kp| kp.range_at(level, x, y, z).1 <= 0.0);
                    let i = (y * d[0] + x) * ch;
                    slab[i..i + ch].copy_from_slice(&[level as f32, step, clear as u8 as f32, 0.0, n(here, x), g[0], g[1], g[2]]);
                    counts[class] += 1;
                }
            }
            counts
        })
        .reduce(|| [0u64; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
    mark_clearance(&mut out);
    Ok((out, counts))
}

/// A cell no level of which, from its own up, is flat.
const NOT_FLAT: u8 = u8::MAX;

/// Per cell of level `from` of `p`, the largest level ≥ `from` whose cell over it is `flat`,
/// or `NOT_FLAT`: from the top level down, a cell takes its parent's when that is flat (ranges
/// only grow with the level, so a flat parent has flat children), else its own level when its
/// own range is flat. The same as counting up from `from` while the cells stay flat.
fn leaf_levels(p: &MinMaxPyramid, from: usize, flat: impl Fn((f32, f32)) -> bool) -> Vec<u8> {
    let mut parent: Option<(Vec<u8>, [usize; 3])> = None;
    for k in (from..p.levels.len()).rev() {
        let l = &p.levels[k];
        let [nx, ny, _] = l.dims;
        let here: Vec<u8> = l
            .range
            .iter()
            .enumerate()
            .map(|(i, &r)| {
                let up = parent.as_ref().map_or(NOT_FLAT, |(pl, pd)| {
                    let (x, y, z) = (i % nx, i / nx % ny, i / (nx * ny));
                    pl[((z >> 1) * pd[1] + (y >> 1)) * pd[0] + (x >> 1)]
                });
                if up != NOT_FLAT {
                    up
                } else if flat(r) {
                    k as u8
                } else {
                    NOT_FLAT
                }
            })
            .collect();
        parent = Some((here, l.dims));
    }
    parent.map_or_else(Vec::new, |(v, _)| v)
}

/// Sets `CLEARANCE`: the L∞ distance in voxels to the nearest voxel whose own or a neighbour's
/// gradient is measurable (0 there: a ray may bend), at most `CLEARANCE_CAP`. The distance to
/// the measurable voxels themselves, one less: separable, exact along x by two sweeps, then
/// along y and z as min over k of max(|k|, d(i + k)) (what the L∞ norm makes of the
/// minimum over the plane's distances). Each voxel alone: the same bytes on any thread count.
fn mark_clearance(o: &mut Volume) {
    let d = o.dims.map(|x| x as usize);
    let h = o.voxel();
    let ch = CHANNELS as usize;
    let far = CLEARANCE_CAP + 1;
    let mut dist: Vec<u8> = o
        .data
        .par_chunks(ch)
        .map(|c| if (Vec3::new(c[GRADIENT], c[GRADIENT + 1], c[GRADIENT + 2]) * h).abs().max_element() > 1e-6 { 0 } else { far })
        .collect();
    dist.par_chunks_mut(d[0]).for_each(|row| {
        for x in 1..row.len() {
            row[x] = row[x].min(row[x - 1].saturating_add(1));
        }
        for x in (0..row.len() - 1).rev() {
            row[x] = row[x].min(row[x + 1].saturating_add(1));
        }
    });
    // Along axis `stride` (y: d[0], z: d[0] d[1]) of length `n`, a row of x at a time (the
    // rows k apart, min of max, vectorise).
    let along = |src: &[u8], stride: usize, n: usize| -> Vec<u8> {
        let mut out = src.to_vec();
        out.par_chunks_mut(d[0]).enumerate().for_each(|(r, row)| {
            let i = r * d[0];
            let pos = (i / stride) % n;
            for k in 1..far as usize {
                let kk = k as u8;
                let mut fold = |from: usize| {
                    for (a, &b) in row.iter_mut().zip(&src[from..from + d[0]]) {
                        *a = (*a).min(b.max(kk));
                    }
                };
                if pos >= k {
                    fold(i - k * stride);
                }
                if pos + k < n {
                    fold(i + k * stride);
                }
            }
        });
        out
    };
    let dist = along(&dist, d[0], d[1]);
    let dist = along(&dist, d[0] * d[1], d[2]);
    let clearance = |x: u8| x.saturating_sub(1).min(CLEARANCE_CAP);
    o.data.par_chunks_mut(ch).zip(dist.par_iter()).for_each(|(c, &x)| c[CLEARANCE] = clearance(x) as f32);
    // The straight runs' bricks, made here from the bytes rather than read back from the
    // channel by the first node that marches (the same bytes as `Clearance::of`).
    let bricks = crate::optics::Clearance::from_rows(o, |i| clearance(dist[i]));
    o.derived.get("clearance", || bricks);
}

#[node(category = "volume", version = 6, caching = Keyed, metrics = ["unbounded_pct", "stepped_pct", "minimum_step_pct"], outputs = [octree])]
impl Octree {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // Eight channels per voxel where the medium has three (its usual layout), with the
        // straight runs' clearance bricks it keeps (a byte a voxel, the grid padded to 4³
        // bricks: under twice the voxels from 12 voxels a side), and two pyramids (8 bytes a
        // voxel at level 0, an eighth more above).
        let out = inputs[0].map(|s| relume_core::PortSize::bytes(s.bytes / 3 * 8 + s.bytes / 6));
        relume_core::MemoryEstimate { outputs: vec![out], working: inputs[0].map_or(0, |s| s.bytes / 3 * 6) }
    }

    fn run(&self, medium: &Volume, cx: &RunCtx) -> Result<Volume, NodeError> {
        let (octree, [unbounded, stepped, minimum]) = build(medium, self, cx.memory_budget())?;
        let n = octree.voxels() as f64;
        cx.metric("unbounded_pct", 100.0 * unbounded as f64 / n);
        cx.metric("stepped_pct", 100.0 * stepped as f64 / n);
        cx.metric("minimum_step_pct", 100.0 * minimum as f64 / n);
        Ok(octree)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::octree_layout::{CLEAR, INDEX, LEVEL, MAX_STEP};
    use glam::Vec3;

    fn field(d: u32, f: impl Fn(usize, usize, usize) -> f32) -> Volume {
        let mut v = Volume::try_new([d; 3], 3, Vec3::ZERO, Vec3::ONE, 0.0, u64::MAX).unwrap();
        for z in 0..d as usize {
            for y in 0..d as usize {
                for x in 0..d as usize {
                    let i = v.index(x, y, z);
                    v.data[i] = f(x, y, z);
                }
            }
        }
        v
    }

    fn defaults() -> Octree {
        Octree { uniform: 0.005, flat: 0.02, step: 8.0 }
    }

    #[test]
    fn the_memory_estimate_covers_the_octree_and_the_bricks_it_keeps() {
        use relume_core::{Node, PortValue};
        // 13 voxels a side: the bricks pad the grid to 16³, 1.86 times its voxels.
        for d in [13, 16, 40] {
            let medium = field(d, |x, _, _| 1.0 + 0.01 * x as f32);
            let estimate = defaults().memory(&[Some(relume_core::PortSize::bytes(medium.byte_size() as u64))]);
            let (o, _) = build(&medium, &defaults(), u64::MAX).unwrap();
            let held = o.byte_size() as u64 + crate::optics::Clearance::shared(&o).bytes();
            let estimated = estimate.outputs[0].unwrap().bytes;
            assert!(estimated >= held && estimated < 2 * held, "{d}³: estimated {estimated} bytes, held {held}");
        }
    }

    #[test]
    fn a_constant_index_is_one_leaf_with_unbounded_steps() {
        let (o, c) = build(&field(16, |_, _, _| 1.5), &defaults(), u64::MAX).unwrap();
        assert_eq!(c, [4096, 0, 0]);
        assert!(
            o.data.chunks(8).all(|v| v == [4.0, f32::INFINITY, 1.0, CLEARANCE_CAP as f32, 1.5, 0.0, 0.0, 0.0]),
            "the 16³ cell is level 4, clear, flat, straight everywhere"
        );
    }

    #[test]
    fn a_jump_from_one_to_two_point_four_takes_the_minimum_step_only_at_the_interface() {
        // x < 8: n = 1; x ≥ 8: n = 2.4 (one voxel apart).
        let (o, c) = build(&field(16, |x, _, _| if x < 8 { 1.0 } else { 2.4 }), &defaults(), u64::MAX).unwrap();
        let at = |x: usize| [o.get(x, 3, 3, 0), o.get(x, 3, 3, 1)];
        assert_eq!(at(7), [0.0, 0.0], "the voxels whose trilinear index blends across the jump");
        assert_eq!(at(8), [0.0, 0.0]);
        // Rays bend in voxels 7 and 8 (their central differences span the jump) and may in
        // their neighbours 6 and 9 (trilinear sampling reaches them); not beyond, where the
        // clearance counts the voxels to them.
        let clearance: Vec<f32> = (0..16).map(|x| o.get(x, 3, 3, CLEARANCE)).collect();
        assert_eq!(clearance, [6., 5., 4., 3., 2., 1., 0., 0., 0., 0., 1., 2., 3., 4., 5., 6.]);
        assert_eq!(c[2], 2 * 256, "two slabs of voxels");
        // Away from it, leaves as large as the aligned cells that stay clear of voxels 7 and 8:
        // shrinking toward them on both sides (4, 2, 1 voxels).
        assert_eq!(at(12), [2.0, f32::INFINITY]);
        assert_eq!(at(10), [1.0, f32::INFINITY]);
        assert_eq!(at(9), [0.0, f32::INFINITY]);
        assert_eq!(at(2), [2.0, f32::INFINITY]);
        assert_eq!(at(5), [1.0, f32::INFINITY]);
        assert_eq!(at(6), [0.0, f32::INFINITY]);
    }

    #[test]
    fn a_gentle_gradient_gets_the_bounded_step_and_leaves_grow_as_it_flattens() {
        // 0.002 per voxel: a voxel's cell spans 0.002 (< ε), cells of 4 span 0.008 (ε … ε′),
        // cells of 8 span 0.016, of 16 span 0.03 (> ε′).
        let (o, c) = build(&field(32, |x, _, _| 1.0 + 0.002 * x as f32), &defaults(), u64::MAX).unwrap();
        assert_eq!(c[2], 0);
        assert!(o.data.chunks(8).all(|v| v[LEVEL] == 3.0 && v[MAX_STEP] == 8.0 && v[CLEARANCE] == 0.0), "{:?}", &o.data[..8]);
        assert_eq!(o.get(10, 5, 5, INDEX), 1.0 + 0.002 * 10.0, "the medium's own index, copied beside its gradient");
        // The gradient: 0.002 per voxel of 1/32 (central differences; one-sided halves at the faces).
        let g = o.get(10, 5, 5, GRADIENT);
        assert!((g - 0.064).abs() < 1e-4, "{g}");
        assert!((o.get(0, 5, 5, GRADIENT) - 0.032).abs() < 1e-4);
        let (_, c) = build(&field(32, |x, _, _| 1.0 + 0.0001 * x as f32), &defaults(), u64::MAX).unwrap();
        assert_eq!(c, [32768, 0, 0], "a total range of 0.0032 < ε everywhere");
    }

    #[test]
    fn leaves_are_clear_only_where_nothing_absorbs_all_through_them() {
        let mut v = field(16, |_, _, _| 1.0);
        for z in 0..16 {
            for y in 0..16 {
                let i = v.index(12, y, z);
                v.data[i + 1] = 0.5;
            }
        }
        let (o, _) = build(&v, &defaults(), u64::MAX).unwrap();
        assert_eq!(o.get(1, 1, 1, 0), 4.0, "κ does not shape the leaves");
        assert_eq!(o.get(1, 1, 1, CLEAR), 0.0, "but the 16³ leaf holds absorbing voxels");
        let (o, _) = build(&field(16, |_, _, _| 1.0), &defaults(), u64::MAX).unwrap();
        assert_eq!(o.get(1, 1, 1, CLEAR), 1.0);
    }

    #[test]
    fn the_clearance_is_the_l_infinity_distance_to_where_rays_bend() {
        // Three bumps of index: brute force over every pair of voxels.
        let bumps = [(3usize, 4usize, 5usize), (17, 20, 2), (30, 30, 30)];
        let v = field(32, |x, y, z| if bumps.contains(&(x, y, z)) { 1.2 } else { 1.0 });
        let (o, _) = build(&v, &defaults(), u64::MAX).unwrap();
        let steep: Vec<[usize; 3]> = (0..32usize.pow(3))
            .filter(|&i| (0..3).any(|k| o.data[i * 8 + GRADIENT + k] != 0.0))
            .map(|i| [i % 32, i / 32 % 32, i / 1024])
            .collect();
        assert_eq!(steep.len(), 3 * 6, "each bump's six neighbours along the axes");
        for z in 0..32 {
            for y in 0..32 {
                for x in 0..32 {
                    let dist = steep.iter().map(|s| (0..3).map(|k| s[k].abs_diff([x, y, z][k])).max().unwrap()).min().unwrap();
                    let want = dist.saturating_sub(1).min(CLEARANCE_CAP as usize) as f32;
                    assert_eq!(o.get(x, y, z, CLEARANCE), want, "({x}, {y}, {z})");
                }
            }
        }
    }

    #[test]
    fn the_octree_comes_with_the_straight_runs_bricks_read_back_from_its_channel() {
        let v = field(20, |x, y, z| if (x + 2 * y + 3 * z) % 17 == 0 { 1.3 } else { 1.0 });
        let (o, _) = build(&v, &defaults(), u64::MAX).unwrap();
        let kept = o.derived.get("clearance", || -> crate::optics::Clearance { panic!("made by the node") });
        assert_eq!(*kept, crate::optics::Clearance::of(&o));
    }

    #[test]
    fn thresholds_out_of_order_are_a_parameter_error() {
        let bad = Octree { uniform: 0.05, flat: 0.02, step: 8.0 };
        assert!(build(&field(4, |_, _, _| 1.0), &bad, u64::MAX).unwrap_err().to_string().contains("must not exceed"));
    }
}
