//! Midpoint subdivision of a triangle mesh: each level splits every triangle into four at the
//! midpoints of its edges, one new vertex per edge shared by the triangles on both sides (a
//! closed mesh stays closed). The surface is the same flat facets, with four times the
//! triangles per level: the geometric load of a finer mesh for a ray tracer, without new
//! shape. Texture coordinates, where every vertex has one, are interpolated the same way.

use glam::{Vec2, Vec3};
use std::collections::HashMap;

/// The most levels a scene may ask for (4⁴ = 256 times the triangles).
pub const MAX_LEVELS: u32 = 4;

/// Triangles after `levels` of subdivision of `triangles` triangles, or `None` past `u64`.
pub fn subdivided_count(triangles: usize, levels: u32) -> Option<u64> {
    (triangles as u64).checked_mul(4u64.checked_pow(levels)?)
}

/// Subdivides the mesh (`uvs` empty or one per position) `levels` times in place. Triangles
/// keep their winding; the four children of a triangle follow each other in its place.
pub fn subdivide(positions: &mut Vec<Vec3>, uvs: &mut Vec<Vec2>, triangles: &mut Vec<[u32; 3]>, levels: u32) {
    let with_uvs = !uvs.is_empty() && uvs.len() == positions.len();
    for _ in 0..levels {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::with_capacity(triangles.len() * 3 / 2);
        let mut out = Vec::with_capacity(triangles.len() * 4);
        for &[a, b, c] in triangles.iter() {
            let mut at = |i: u32, j: u32| {
                *mid.entry((i.min(j), i.max(j))).or_insert_with(|| {
                    positions.push((positions[i as usize] + positions[j as usize]) * 0.5);
                    if with_uvs {
                        uvs.push((uvs[i as usize] + uvs[j as usize]) * 0.5);
                    }
                    (positions.len() - 1) as u32
                })
            };
            let (ab, bc, ca) = (at(a, b), at(b, c), at(c, a));
            out.extend_from_slice(&[[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        *triangles = out;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(p: &[Vec3], t: &[[u32; 3]]) -> f32 {
        t.iter().map(|&[a, b, c]| (p[b as usize] - p[a as usize]).cross(p[c as usize] - p[a as usize]).length() * 0.5).sum()
    }

    #[test]
    fn each_level_quadruples_the_triangles_and_keeps_the_surface() {
        // A tetrahedron: closed, 4 faces, 6 edges, 4 vertices.
        let mut p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let mut t = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let (a0, normal0) = (area(&p, &t), (p[2] - p[1]).cross(p[3] - p[1]).normalize());
        let mut uv = vec![];
        subdivide(&mut p, &mut uv, &mut t, 2);
        assert_eq!(t.len(), 64);
        assert_eq!(subdivided_count(4, 2), Some(64));
        // Euler: V − E + F = 2 for a closed mesh, every edge shared: no cracks.
        let mut edges = std::collections::HashSet::new();
        for &[a, b, c] in &t {
            for (i, j) in [(a, b), (b, c), (c, a)] {
                edges.insert((i.min(j), i.max(j)));
            }
        }
        assert_eq!(p.len() as i64 - edges.len() as i64 + t.len() as i64, 2);
        assert!((area(&p, &t) - a0).abs() < 1e-5 * a0, "the same surface");
        // Windings kept: the children of the slanted face face its way.
        let slanted = &t[48..64];
        for &[a, b, c] in slanted {
            let n = (p[b as usize] - p[a as usize]).cross(p[c as usize] - p[a as usize]).normalize();
            assert!(n.dot(normal0) > 0.999, "{n}");
        }
        assert!(uv.is_empty());
    }

    #[test]
    fn texture_coordinates_follow_the_midpoints() {
        let mut p = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
        let mut uv = vec![Vec2::ZERO, Vec2::X, Vec2::Y];
        let mut t = vec![[0, 1, 2]];
        subdivide(&mut p, &mut uv, &mut t, 1);
        assert_eq!((p.len(), uv.len(), t.len()), (6, 6, 4));
        for (x, u) in p.iter().zip(&uv) {
            assert_eq!(x.truncate(), *u, "the uv is the position here");
        }
    }

    #[test]
    fn counts_past_u64_are_none() {
        assert_eq!(subdivided_count(usize::MAX, 4), None);
        assert_eq!(subdivided_count(10, 0), Some(10));
    }
}
