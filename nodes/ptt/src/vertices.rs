//! The vertices the transfer tensors live on: the scene's vertices with their shading normals
//! (the scene's per-vertex normals, or area-weighted face normals for a flat-shaded mesh), a
//! frame around each, and the offset rays leave them at.

use glam::Vec3;
use relume_base::math::frame::Frame;
use relume_base::types::Scene;

/// Per vertex, its unit shading normal: the scene's, or for a flat-shaded scene the
/// angle-weighted mean of its faces' (`scene::shapes::vertex_normals`); zero for a vertex no
/// triangle uses (it gets no rays and no light).
pub fn vertex_normals(scene: &Scene) -> Vec<Vec3> {
    let normals = if scene.normals.len() == scene.positions.len() {
        scene.normals.clone()
    } else {
        relume_base::scene::shapes::vertex_normals(&scene.positions, &scene.triangles)
    };
    let mut used = vec![false; scene.positions.len()];
    scene.triangles.iter().flatten().for_each(|&v| used[v as usize] = true);
    normals.iter().zip(used).map(|(n, u)| if u && n.is_finite() { n.normalize_or_zero() } else { Vec3::ZERO }).collect()
}

/// The local frame of a vertex with normal `n` (z along the normal; the tangent from
/// `Frame::from_normal`, the same for every node of the pipeline).
pub fn vertex_frame(n: Vec3) -> Frame {
    Frame::from_normal(n)
}

/// How far along its normal a ray from a vertex starts, and its minimum distance: 10⁻⁴ of
/// the scene's extent (a vertex lies on its triangles; without the offset their own surface
/// would occlude grazing rays).
pub fn ray_offset(scene: &Scene) -> f32 {
    1e-4 * scene.extent()
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::scene::builder::SceneBuilder;
    use relume_base::types::Material;

    #[test]
    fn flat_meshes_get_their_faces_normals_and_unused_vertices_none() {
        let mut s = SceneBuilder::new(Vec3::Z, Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::X * 2.0, Vec3::NEG_Z * 2.0, Material::Lambert { albedo: Vec3::ONE }, Vec3::ZERO)
            .flat_shading()
            .build();
        s.positions.push(Vec3::splat(5.0));
        let n = vertex_normals(&s);
        assert_eq!(n.len(), 5);
        for v in &n[..4] {
            assert!((*v - Vec3::Y).length() < 1e-6, "{v:?}");
        }
        assert_eq!(n[4], Vec3::ZERO);
    }
}
