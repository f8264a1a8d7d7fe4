//! Triangle planes: each triangle's unit normal and offset, derived from a scene's geometry
//! once and kept with it (`Scene::triangle_planes`), so that a rasteriser that culls back
//! faces for many cameras can turn most of them away by their plane alone.

use glam::Vec3;
use rayon::prelude::*;
use std::sync::OnceLock;

/// Per triangle its plane (n, n·p0), n the unit normal (p1 − p0) × (p2 − p0) of its corners
/// in order (zero for a degenerate triangle), and `radius`, the largest distance of a vertex
/// from the origin.
#[derive(Debug)]
pub struct TrianglePlanes {
    pub planes: Vec<[f32; 4]>,
    pub radius: f32,
}

impl TrianglePlanes {
    /// The planes of a mesh's triangles (in parallel; each triangle alone, so the same bytes
    /// on any thread count).
    pub fn of(positions: &[Vec3], triangles: &[[u32; 3]]) -> TrianglePlanes {
        let planes = triangles
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| positions[i as usize]);
                let n = (b - a).cross(c - a).normalize_or_zero();
                [n.x, n.y, n.z, n.dot(a)]
            })
            .collect();
        let radius = positions.iter().map(|p| p.length()).fold(0.0f32, f32::max);
        TrianglePlanes { planes, radius }
    }

    /// Whether triangle `t` faces away from a point at `eye` by more than `margin` (its plane
    /// passes that far on the point's side of its back): n·eye − n·p0 < −margin.
    #[inline]
    pub fn faces_away(&self, t: usize, eye: Vec3, margin: f32) -> bool {
        let [x, y, z, d] = self.planes[t];
        x * eye.x + y * eye.y + z * eye.z - d < -margin
    }

    /// Bytes held for `triangles`.
    pub fn bytes_for(triangles: usize) -> usize {
        triangles * 16
    }
}

/// What is derived from a scene's geometry on first use and kept with it: not serialised,
/// and not cloned (a clone, which its owner may change, derives its own). A scene changed in
/// place after its planes were asked for keeps the old ones: change a clone.
#[derive(Default)]
pub struct SceneDerived {
    planes: OnceLock<TrianglePlanes>,
}

impl SceneDerived {
    /// The planes of the scene's mesh (whose derived data this is), found on the first call.
    ///
    /// Found outside the lock: two nodes that ask at once may both compute them (the same
    /// bytes; the first kept). `get_or_init` would make the second wait for the first while
    /// the first's parallel loop waits on rayon's workers — and when the waiting thread is
    /// one of those workers, holding work the loop needs, neither ever finishes.
    pub(super) fn planes(&self, positions: &[Vec3], triangles: &[[u32; 3]]) -> &TrianglePlanes {
        if let Some(p) = self.planes.get() {
            return p;
        }
        let _ = self.planes.set(TrianglePlanes::of(positions, triangles));
        self.planes.get().expect("set above or by another thread")
    }
}

impl Clone for SceneDerived {
    fn clone(&self) -> Self {
        SceneDerived::default()
    }
}

impl std::fmt::Debug for SceneDerived {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.debug_struct("SceneDerived").field("planes", &self.planes.get().map(|p| p.planes.len())).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builder::SceneBuilder;
    use crate::types::Material;

    const GREY: Material = Material::Lambert { albedo: Vec3::splat(0.5) };

    #[test]
    fn a_floor_faces_up_and_away_from_below_and_a_clone_derives_its_own() {
        let s = SceneBuilder::new(Vec3::new(0.0, 2.0, 3.0), Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.5, 1.0), Vec3::X * 2.0, Vec3::NEG_Z * 2.0, GREY, Vec3::ZERO)
            .build();
        let p = s.triangle_planes();
        assert_eq!(p.planes.len(), s.triangles.len());
        for (t, pl) in p.planes.iter().enumerate() {
            // Wound counter-clockwise seen from above: the normal is +y, the plane y = 0.5.
            assert!((Vec3::new(pl[0], pl[1], pl[2]) - Vec3::Y).length() < 1e-6 && (pl[3] - 0.5).abs() < 1e-6, "{pl:?}");
            assert!(!p.faces_away(t, Vec3::new(0.3, 2.0, 0.0), 0.01));
            assert!(p.faces_away(t, Vec3::new(0.3, -2.0, 0.0), 0.01));
            // Within the margin of the plane: not certain, not turned away.
            assert!(!p.faces_away(t, Vec3::new(0.3, 0.495, 0.0), 0.01));
        }
        assert!((p.radius - Vec3::new(1.0, 0.5, 1.0).length()).abs() < 1e-6);
        // The same planes asked again; a clone moved starts with none and finds its own.
        assert!(std::ptr::eq(p, s.triangle_planes()));
        let mut moved = s.clone();
        // Turned half a turn about z: the floor faces down, below the eye.
        moved.positions.iter_mut().for_each(|v| (v.x, v.y) = (-v.x, -v.y));
        assert!(moved.triangle_planes().faces_away(0, Vec3::new(0.3, 2.0, 0.0), 0.01));
    }

    #[test]
    fn a_degenerate_triangle_has_no_plane_and_never_faces_away() {
        let mut s = SceneBuilder::new(Vec3::new(0.0, 2.0, 3.0), Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.5, 1.0), Vec3::X * 2.0, Vec3::NEG_Z * 2.0, GREY, Vec3::ZERO)
            .build();
        let t = s.triangles[0];
        s.triangles[0] = [t[0], t[0], t[1]];
        let p = s.triangle_planes();
        assert_eq!(p.planes[0], [0.0; 4]);
        assert!([Vec3::Y * 5.0, Vec3::NEG_Y * 5.0].iter().all(|&e| !p.faces_away(0, e, 0.0)));
    }
}
