//! Inside fractions of a closed triangle mesh on a voxel grid by scanlines ([S] 6.3.1): a line
//! along x at a (y, z) position crosses a closed mesh an even number of times, and between
//! crossings 2k and 2k + 1 it is inside; a voxel's fraction along such a line is exact in x.
//! Crossings are found in the (y, z) projection with edge functions in f64 and a top-left rule,
//! so a line through a shared edge or vertex counts it once. Parity holds only on a closed mesh:
//! `geometry::closed_mesh::open_edges` tells one it cannot be trusted on.

use glam::{DVec3, Vec3};

/// A triangle prepared for scanlines: its corners in f64, oriented so its (y, z) projection
/// has positive area (triangles seen edge-on are dropped).
#[derive(Clone, Copy, Debug)]
pub struct Projected {
    p: [DVec3; 3],
    area: f64,
}

impl Projected {
    pub fn new(t: &[Vec3; 3]) -> Option<Projected> {
        let mut p = t.map(|v| v.as_dvec3());
        let area = edge(p[0], p[1], p[2].y, p[2].z);
        if area == 0.0 {
            return None;
        }
        if area < 0.0 {
            p.swap(1, 2);
        }
        Some(Projected { p, area: area.abs() })
    }

    /// The (y, z) bounds of the projection.
    pub fn yz_bounds(&self) -> ([f64; 2], [f64; 2]) {
        let ys = self.p.map(|v| v.y);
        let zs = self.p.map(|v| v.z);
        let lo = |a: [f64; 3]| a.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = |a: [f64; 3]| a.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        ([lo(ys), hi(ys)], [lo(zs), hi(zs)])
    }

    /// Where the line through (y, z) along x crosses the triangle, if it does (top-left rule).
    pub fn crossing(&self, y: f64, z: f64) -> Option<f64> {
        let mut w = [0.0f64; 3];
        for (k, wk) in w.iter_mut().enumerate() {
            let (a, b) = (self.p[(k + 1) % 3], self.p[(k + 2) % 3]);
            let e = edge(a, b, y, z);
            if e < 0.0 || (e == 0.0 && !top_left(a, b)) {
                return None;
            }
            *wk = e;
        }
        Some((w[0] * self.p[0].x + w[1] * self.p[1].x + w[2] * self.p[2].x) / self.area)
    }
}

/// Twice the signed area of (a, b, (y, z)) in the (y, z) plane.
fn edge(a: DVec3, b: DVec3, y: f64, z: f64) -> f64 {
    (b.y - a.y) * (z - a.z) - (b.z - a.z) * (y - a.y)
}

/// The top-left rule for a positively oriented projection: an edge owns the points on it
/// when it is a "left" edge (z falling along it) or a horizontal "top" edge.
fn top_left(a: DVec3, b: DVec3) -> bool {
    let (dy, dz) = (b.y - a.y, b.z - a.z);
    dz < 0.0 || (dz == 0.0 && dy > 0.0)
}

/// Adds to `cover[i]` the length of voxel i (x from `x0 + i·h` to `x0 + (i+1)·h`) that lies
/// inside, given the line's crossings (sorted in place; an odd last one is dropped), times
/// `weight`.
pub fn add_coverage(crossings: &mut [f64], x0: f64, h: f64, weight: f64, cover: &mut [f64]) {
    add_coverage_where(crossings, x0, h, weight, None, cover);
}

/// As `add_coverage`, to the voxels `only` (ascending) where given, the others left as they
/// are: each of those gets the same additions in the same order, so the same value.
pub fn add_coverage_where(crossings: &mut [f64], x0: f64, h: f64, weight: f64, only: Option<&[usize]>, cover: &mut [f64]) {
    crossings.sort_by(f64::total_cmp);
    let n = cover.len();
    let mut add = |i: usize, a: f64, b: f64| {
        let lo = a.max(i as f64);
        let hi = b.min(i as f64 + 1.0);
        if hi > lo {
            cover[i] += (hi - lo) * weight;
        }
    };
    for pair in crossings.chunks_exact(2) {
        let (a, b) = ((pair[0] - x0) / h, (pair[1] - x0) / h);
        let (a, b) = (a.clamp(0.0, n as f64), b.clamp(0.0, n as f64));
        if b <= a {
            continue;
        }
        let (i0, i1) = (a.floor() as usize, (b.ceil() as usize).min(n));
        match only {
            None => (i0..i1).for_each(|i| add(i, a, b)),
            Some(only) => only[only.partition_point(|&i| i < i0)..].iter().take_while(|&&i| i < i1).for_each(|&i| add(i, a, b)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::scene::shapes::sphere;

    fn mesh(pos: &[Vec3], tris: &[[u32; 3]]) -> Vec<[Vec3; 3]> {
        tris.iter().map(|t| t.map(|i| pos[i as usize])).collect()
    }

    #[test]
    fn a_line_through_a_sphere_crosses_it_twice_even_through_shared_edges_and_vertices() {
        let (pos, _, tris) = sphere(Vec3::ZERO, 1.0, 8, 16);
        let proj: Vec<Projected> = mesh(&pos, &tris).iter().filter_map(Projected::new).collect();
        // Through the centre (a pole-to-pole line runs through vertices), and off-centre.
        for (y, z) in [(0.0, 0.0), (0.3, -0.2), (0.0, 0.5), (pos[20].y as f64, pos[20].z as f64)] {
            let mut xs: Vec<f64> = proj.iter().filter_map(|t| t.crossing(y, z)).collect();
            assert_eq!(xs.len(), 2, "({y}, {z}): {xs:?}");
            xs.sort_by(f64::total_cmp);
            assert!(xs[0] < 0.0 && xs[1] > 0.0 && (xs[0] + xs[1]).abs() < 1e-6);
        }
        let outside: Vec<f64> = proj.iter().filter_map(|t| t.crossing(1.2, 0.0)).collect();
        assert!(outside.is_empty());
    }

    #[test]
    fn coverage_is_the_inside_length_per_voxel() {
        let mut cover = vec![0.0; 4];
        add_coverage(&mut [2.5, 0.25], 0.0, 1.0, 1.0, &mut cover);
        assert_eq!(cover, [0.75, 1.0, 0.5, 0.0]);
        add_coverage(&mut [-3.0, 9.0, 3.5], 0.0, 1.0, 0.5, &mut cover);
        assert_eq!(cover, [1.25, 1.5, 1.0, 0.25], "clamped to the grid; the odd crossing dropped");
    }

    #[test]
    fn coverage_of_some_voxels_is_theirs_to_the_bit_and_leaves_the_rest() {
        let lines: [&[f64]; 3] = [&[0.3, 7.7], &[1.1, 2.9, 4.05, 6.2], &[9.5, -1.0]];
        let (mut all, mut some) = (vec![0.0; 8], vec![-1.0; 8]);
        some.iter_mut().step_by(3).for_each(|c| *c = 0.0);
        let only = [0, 3, 6];
        for xs in lines {
            add_coverage(&mut xs.to_vec(), 0.1, 0.9, 1.0 / 3.0, &mut all);
            add_coverage_where(&mut xs.to_vec(), 0.1, 0.9, 1.0 / 3.0, Some(&only), &mut some);
        }
        for i in 0..8 {
            if only.contains(&i) {
                assert_eq!(some[i].to_bits(), all[i].to_bits(), "voxel {i}");
            } else {
                assert_eq!(some[i], -1.0, "voxel {i} untouched");
            }
        }
        assert!(all.iter().all(|&c| c > 0.0));
    }
}
