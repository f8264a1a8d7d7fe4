//! Analytic shapes tessellated into triangles, and per-vertex normals for meshes without them.

use glam::Vec3;

/// A UV sphere: `rings` × `segments` quads, outward normals, counter-clockwise seen from
/// outside. Returns (positions, normals, triangles).
pub fn sphere(center: Vec3, radius: f32, rings: usize, segments: usize) -> (Vec<Vec3>, Vec<Vec3>, Vec<[u32; 3]>) {
    let (rings, segments) = (rings.max(2), segments.max(3));
    let mut pos = Vec::new();
    let mut nrm = Vec::new();
    for r in 0..=rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..=segments {
            let phi = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
            let n = Vec3::new(theta.sin() * phi.cos(), theta.cos(), -theta.sin() * phi.sin());
            pos.push(center + radius * n);
            nrm.push(n);
        }
    }
    let row = segments as u32 + 1;
    let mut tris = Vec::new();
    for r in 0..rings as u32 {
        for s in 0..segments as u32 {
            let (a, b, c, d) = (r * row + s, r * row + s + 1, (r + 1) * row + s, (r + 1) * row + s + 1);
            if r > 0 {
                tris.push([a, c, b]);
            }
            if r + 1 < rings as u32 {
                tris.push([b, c, d]);
            }
        }
    }
    (pos, nrm, tris)
}

/// Angle-weighted vertex normals (as Mitsuba computes them for meshes without normals).
/// Vertices of degenerate triangles only get a normal from their other triangles; a vertex
/// that has none gets +y.
pub fn vertex_normals(pos: &[Vec3], tris: &[[u32; 3]]) -> Vec<Vec3> {
    let mut acc = vec![Vec3::ZERO; pos.len()];
    for t in tris {
        let p = t.map(|i| pos[i as usize]);
        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        if n == Vec3::ZERO {
            continue;
        }
        for k in 0..3 {
            let e1 = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
            let e2 = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
            let angle = e1.dot(e2).clamp(-1.0, 1.0).acos();
            acc[t[k] as usize] += n * angle;
        }
    }
    acc.into_iter().map(|n| n.try_normalize().unwrap_or(Vec3::Y)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_faces_outward_and_its_area_converges() {
        let (pos, nrm, tris) = sphere(Vec3::new(1.0, 2.0, 3.0), 0.5, 64, 128);
        let mut area = 0.0;
        for t in &tris {
            let p = t.map(|i| pos[i as usize]);
            let cr = (p[1] - p[0]).cross(p[2] - p[0]);
            area += 0.5 * cr.length();
            let centroid = (p[0] + p[1] + p[2]) / 3.0;
            assert!(cr.dot(centroid - Vec3::new(1.0, 2.0, 3.0)) > 0.0, "counter-clockwise from outside");
        }
        let exact = 4.0 * std::f32::consts::PI * 0.25;
        assert!((area - exact).abs() / exact < 0.002, "{area} vs {exact}");
        assert!(nrm.iter().all(|n| (n.length() - 1.0).abs() < 1e-5));
    }

    #[test]
    fn vertex_normals_of_a_flat_quad_and_a_degenerate_triangle() {
        let pos = [Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::new(1.0, 0.0, 1.0), Vec3::new(5.0, 5.0, 5.0)];
        let tris = [[0, 2, 1], [1, 2, 3], [4, 4, 4]];
        let n = vertex_normals(&pos, &tris);
        for v in &n[..4] {
            assert!((*v - Vec3::Y).length() < 1e-6, "{v}");
        }
        assert_eq!(n[4], Vec3::Y, "degenerate-only vertex gets a finite default");
    }
}
