//! Measures of a closed triangle mesh: its open edges (edges not shared by exactly two faces
//! after welding vertices that coincide within a tolerance) and the volume it encloses.

use glam::Vec3;
use rustc_hash::FxHashMap;

/// Edges not shared by exactly two faces after welding vertices within `tol` (degenerate faces
/// skipped): 0 for a closed (watertight, edge-manifold) mesh. A corner at a position already
/// welded (bit for bit: the corners an indexed mesh's triangles share) takes that weld's
/// vertex without searching again; hashing is Fx (keys are integers, not attacker-chosen).
pub fn open_edges(tris: &[[Vec3; 3]], tol: f32) -> usize {
    let mut cells: FxHashMap<[i64; 3], Vec<(Vec3, u32)>> = FxHashMap::default();
    let mut seen: FxHashMap<[u32; 3], u32> = FxHashMap::default();
    let mut next = 0u32;
    let mut weld = |p: Vec3| -> u32 {
        let bits = p.to_array().map(f32::to_bits);
        if let Some(&id) = seen.get(&bits) {
            return id;
        }
        let c = (p / tol).floor();
        let key = [c.x as i64, c.y as i64, c.z as i64];
        let found = (|| {
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        if let Some(list) = cells.get(&[key[0] + dx, key[1] + dy, key[2] + dz]) {
                            if let Some((_, id)) = list.iter().find(|(q, _)| q.distance(p) <= tol) {
                                return Some(*id);
                            }
                        }
                    }
                }
            }
            None
        })();
        let id = found.unwrap_or_else(|| {
            next += 1;
            cells.entry(key).or_default().push((p, next - 1));
            next - 1
        });
        seen.insert(bits, id);
        id
    };
    let mut edges: FxHashMap<(u32, u32), u32> = FxHashMap::default();
    for t in tris {
        let v = t.map(&mut weld);
        if v[0] == v[1] || v[1] == v[2] || v[0] == v[2] {
            continue;
        }
        for k in 0..3 {
            let (a, b) = (v[k], v[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    edges.values().filter(|&&n| n != 2).count()
}

/// The volume a closed mesh encloses (divergence theorem: signed tetrahedra from the origin,
/// in f64; positive for outward-facing winding, so the magnitude is returned).
pub fn enclosed_volume(tris: &[[Vec3; 3]]) -> f64 {
    tris.iter().map(|t| t[0].as_dvec3().dot(t[1].as_dvec3().cross(t[2].as_dvec3()))).sum::<f64>().abs() / 6.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::shapes::sphere;

    fn mesh(pos: &[Vec3], tris: &[[u32; 3]]) -> Vec<[Vec3; 3]> {
        tris.iter().map(|t| t.map(|i| pos[i as usize])).collect()
    }

    #[test]
    fn a_tessellated_sphere_is_closed_and_a_quad_or_a_cut_sphere_is_not() {
        let (pos, _, tris) = sphere(Vec3::new(0.0, 0.6, 0.0), 0.5, 12, 24);
        let t = mesh(&pos, &tris);
        assert_eq!(open_edges(&t, 1e-5), 0, "seam and pole vertices weld");
        assert!(open_edges(&t[..t.len() - 3], 1e-5) > 0);
        let quad = [[Vec3::ZERO, Vec3::X, Vec3::ONE], [Vec3::ZERO, Vec3::ONE, Vec3::Y]];
        assert_eq!(open_edges(&quad, 1e-5), 4);
    }

    #[test]
    fn the_enclosed_volume_of_a_sphere_mesh_is_near_four_thirds_pi_r_cubed() {
        let (pos, _, tris) = sphere(Vec3::new(3.0, -1.0, 2.0), 2.0, 48, 96);
        let v = enclosed_volume(&mesh(&pos, &tris));
        let want = 4.0 / 3.0 * std::f64::consts::PI * 8.0;
        assert!((v - want).abs() < 0.005 * want, "{v} vs {want}");
    }
}
