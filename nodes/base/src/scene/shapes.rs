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

/// Vertex normals that stay sharp across creases: each triangle corner averages (angle
/// weighted) only the faces around its vertex whose normals lie within `crease_deg` of the
/// triangle's own. Vertices are split where corners end up with different normals. Returns
/// (positions, normals, triangles, original vertex of each new vertex).
pub fn crease_normals(pos: &[Vec3], tris: &[[u32; 3]], crease_deg: f32) -> (Vec<Vec3>, Vec<Vec3>, Vec<[u32; 3]>, Vec<u32>) {
    let cos_crease = crease_deg.to_radians().cos();
    let face: Vec<Vec3> = tris
        .iter()
        .map(|t| (pos[t[1] as usize] - pos[t[0] as usize]).cross(pos[t[2] as usize] - pos[t[0] as usize]).normalize_or_zero())
        .collect();
    // Each corner's angle, once (a vertex's corners are weighed against each other).
    let angle: Vec<f32> = tris
        .iter()
        .flat_map(|t| {
            let p = t.map(|i| pos[i as usize]);
            (0..3).map(move |k| {
                let e1 = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
                let e2 = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
                e1.dot(e2).clamp(-1.0, 1.0).acos()
            })
        })
        .collect();
    // The corners at each vertex, grouped by vertex (counting sort, faces in order).
    let mut start = vec![0u32; pos.len() + 1];
    for t in tris {
        for &v in t {
            start[v as usize + 1] += 1;
        }
    }
    for v in 0..pos.len() {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut corners = vec![(0u32, 0u8); 3 * tris.len()];
    for (f, t) in tris.iter().enumerate() {
        for (k, &v) in t.iter().enumerate() {
            corners[fill[v as usize] as usize] = (f as u32, k as u8);
            fill[v as usize] += 1;
        }
    }
    let incident = (0..pos.len()).map(|v| &corners[start[v] as usize..start[v + 1] as usize]);
    let mut out_pos = Vec::with_capacity(pos.len());
    let mut out_nrm: Vec<Vec3> = Vec::with_capacity(pos.len());
    let mut origin = Vec::with_capacity(pos.len());
    let mut out_tris = tris.to_vec();
    for (v, inc) in incident.enumerate() {
        // Distinct corner normals at this vertex, each becoming one output vertex.
        let mut made: Vec<(Vec3, u32)> = Vec::new();
        for &(f, k) in inc {
            let nf = face[f as usize];
            let mut n = Vec3::ZERO;
            for &(g, kg) in inc {
                let ng = face[g as usize];
                if nf != Vec3::ZERO && ng.dot(nf) >= cos_crease {
                    n += ng * angle[3 * g as usize + kg as usize];
                }
            }
            let n = n.try_normalize().unwrap_or(if nf != Vec3::ZERO { nf } else { Vec3::Y });
            let idx = match made.iter().find(|(m, _)| m.dot(n) > 1.0 - 1e-6) {
                Some(&(_, i)) => i,
                None => {
                    let i = out_pos.len() as u32;
                    out_pos.push(pos[v]);
                    out_nrm.push(n);
                    origin.push(v as u32);
                    made.push((n, i));
                    i
                }
            };
            out_tris[f as usize][k as usize] = idx;
        }
        if inc.is_empty() {
            out_pos.push(pos[v]);
            out_nrm.push(Vec3::Y);
            origin.push(v as u32);
        }
    }
    (out_pos, out_nrm, out_tris, origin)
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
    fn crease_normals_keep_a_cube_flat_and_a_sphere_smooth() {
        // A unit cube with 8 shared corners: every face must get its own flat normal.
        let p: Vec<Vec3> = (0..8).map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32)).collect();
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let tris: Vec<[u32; 3]> = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        let (pos, nrm, t2, origin) = crease_normals(&p, &tris, 30.0);
        assert_eq!(pos.len(), 24, "each corner is split into its three faces");
        for t in &t2 {
            let fp = t.map(|i| pos[i as usize]);
            let f = (fp[1] - fp[0]).cross(fp[2] - fp[0]).normalize();
            for &i in t {
                assert!((nrm[i as usize] - f).length() < 1e-6);
                assert_eq!(pos[i as usize], p[origin[i as usize] as usize]);
            }
        }
        let (sp, _, st) = sphere(Vec3::ZERO, 1.0, 32, 64);
        let (pos, nrm, _, _) = crease_normals(&sp, &st, 30.0);
        assert!(pos.len() <= sp.len(), "a smooth sphere is not split");
        // Away from the poles and the seam (whose corners see faces on one side only) the
        // normals are
        // close to the radial direction.
        for (p, n) in pos.iter().zip(&nrm).filter(|(p, _)| p.y.abs() < 0.99) {
            assert!(p.normalize().dot(*n) > 0.998, "{p} {n}");
        }
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
