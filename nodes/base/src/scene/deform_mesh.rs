use crate::types::Scene;
use glam::{Mat3, Vec3};
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

params! {
    /// Deforms one object of a scene ([S] 6.5, geometry deformation of a refractive object: the
    /// edit that re-runs voxelisation onward). With d = p − `centre`, w = d's coordinate along
    /// `axis` and κ = `amount` in radians:
    /// - Twist turns each vertex about the axis line through `centre` by the angle κ·w
    ///   (right-handed about the +axis direction); distances to that line and w are kept.
    /// - Bend is Barr's bend (1984) with an unbounded bend region: the axis line is bent into a
    ///   circle of radius R = 1/κ through `centre`, toward +x for axis y and toward +y for axes x
    ///   and z (negative amounts bend the other way). With u = d's coordinate along that direction
    ///   and θ = κ·w, u′ = R − (R − u) cos θ and w′ = (R − u) sin θ; the third coordinate is kept.
    ///   A vertex at u ≥ R would fold the object inside out and is refused.
    /// - Scale multiplies w by `amount` (0 keeps it: 0.01 … 100 otherwise) and the two
    ///   coordinates across the axis by `across`, about `centre`.
    ///
    /// Triangles, their winding and closedness stay; per-vertex normals (when the scene has them)
    /// are carried by the inverse transpose of the deformation's Jacobian, so crease splits and
    /// analytic normals stay as they were. Only the object's own vertices move: a vertex it shares
    /// with another object is duplicated first. `amount` 0 (Scale: with `across` 1) returns the
    /// scene unchanged.
    pub struct DeformMesh {
        /// name of the object to deform
        pub object: String = "glass";
        /// the deformation
        pub kind: Deformation = Twist;
        /// the point it acts about (scene units)
        pub centre: Vec3 = (0.0, 0.6, 0.0);
        /// the axis it acts along
        pub axis: Axis = Y;
        /// Twist, Bend: degrees per scene unit along the axis; Scale: the factor along the axis (0 keeps it)
        pub amount: f32 = 0.0, range = -720.0..=720.0;
        /// Scale: the factor across the axis
        pub across: f32 = 1.0, range = 0.01..=100.0;
    }
}

/// A deformation of DeformMesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum Deformation {
    /// turn about the axis, proportionally to the distance along it
    Twist,
    /// bend the axis into a circular arc (Barr)
    Bend,
    /// scale along and across the axis
    Scale,
}

/// A world axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum Axis {
    /// x (bends toward +y)
    X,
    /// y (bends toward +x)
    Y,
    /// z (bends toward +y)
    Z,
}

impl Axis {
    fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }

    /// The direction Bend curves the axis toward.
    fn bend_toward(self) -> usize {
        match self {
            Axis::X | Axis::Z => 1,
            Axis::Y => 0,
        }
    }
}

/// A deformation with its parameters resolved.
#[derive(Clone, Copy, Debug)]
enum Map {
    /// κ (radians per unit), the axis and the two coordinates across it, (axis, j, k) cyclic.
    Twist { kappa: f32, a: usize, j: usize, k: usize },
    /// κ (radians per unit), the axis and the bend direction.
    Bend { kappa: f32, a: usize, b: usize },
    /// Factors along each world coordinate.
    Scale(Vec3),
}

impl Map {
    /// The deformed offset from the centre and the Jacobian at `d` (offset from the centre).
    /// Coordinates the map keeps are copied, not recomputed.
    fn apply(self, d: Vec3) -> (Vec3, Mat3) {
        // m[col][row] = ∂ out[row] / ∂ d[col].
        let mut m = [[0.0f32; 3]; 3];
        let mut out = d;
        match self {
            Map::Twist { kappa, a, j, k } => {
                let (s, c) = (kappa * d[a]).sin_cos();
                out[j] = d[j] * c - d[k] * s;
                out[k] = d[j] * s + d[k] * c;
                m[a][a] = 1.0;
                (m[j][j], m[j][k]) = (c, s);
                (m[k][j], m[k][k]) = (-s, c);
                (m[a][j], m[a][k]) = (-kappa * out[k], kappa * out[j]);
            }
            Map::Bend { kappa, a, b } => {
                let (u, w) = (d[b], d[a]);
                let theta = kappa * w;
                let (s, c) = theta.sin_cos();
                let half = (0.5 * theta).sin();
                // u′ = R − (R − u) cos θ, w′ = (R − u) sin θ, written without R's cancellation.
                out[b] = u * c + 2.0 * half * half / kappa;
                out[a] = s / kappa - u * s;
                let stretch = 1.0 - kappa * u;
                let third = 3 - a - b;
                m[third][third] = 1.0;
                (m[b][b], m[b][a]) = (c, -s);
                (m[a][b], m[a][a]) = (stretch * s, stretch * c);
            }
            Map::Scale(f) => {
                out = d * f;
                (m[0][0], m[1][1], m[2][2]) = (f.x, f.y, f.z);
            }
        }
        (out, Mat3::from_cols_array_2d(&m))
    }
}

/// det(J) · J⁻ᵀ: carries normals (up to length) through a map of Jacobian J with det J > 0.
fn cofactor(j: Mat3) -> Mat3 {
    Mat3::from_cols(j.y_axis.cross(j.z_axis), j.z_axis.cross(j.x_axis), j.x_axis.cross(j.y_axis))
}

/// The scene with object `name` deformed (see the node's doc). Returns the scene and the
/// number of vertices duplicated because another object shared them.
pub fn deform_mesh(
    scene: &Scene,
    name: &str,
    kind: Deformation,
    centre: Vec3,
    axis: Axis,
    amount: f32,
    across: f32,
) -> Result<(Scene, usize), NodeError> {
    let Some(o) = scene.objects.iter().position(|o| o.name == name) else {
        let names: Vec<_> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        return Err(NodeError::param("object", format!("no object \"{name}\" (objects: {})", names.join(", "))));
    };
    for (what, v) in [("amount", amount), ("across", across)] {
        if !v.is_finite() {
            return Err(NodeError::param(what, format!("must be finite, not {v}")));
        }
    }
    if !centre.is_finite() {
        return Err(NodeError::param("centre", format!("must be finite, not {centre}")));
    }
    let a = axis.index();
    let map = match kind {
        Deformation::Twist | Deformation::Bend if amount == 0.0 => return Ok((scene.clone(), 0)),
        Deformation::Twist => Map::Twist { kappa: amount.to_radians(), a, j: (a + 1) % 3, k: (a + 2) % 3 },
        Deformation::Bend => Map::Bend { kappa: amount.to_radians(), a, b: axis.bend_toward() },
        Deformation::Scale => {
            let along = if amount == 0.0 { 1.0 } else { amount };
            if !(0.01..=100.0).contains(&along) {
                return Err(NodeError::param("amount", format!("Scale needs a factor in [0.01, 100] (0 keeps the length), not {amount}")));
            }
            if along == 1.0 && across == 1.0 {
                return Ok((scene.clone(), 0));
            }
            let mut f = Vec3::splat(across);
            f[a] = along;
            Map::Scale(f)
        }
    };

    let mut s = scene.clone();
    let range = s.objects[o].triangles.clone();
    let nv = s.positions.len();
    // Vertices reached by other objects' triangles.
    let mut shared = vec![false; nv];
    for (t, tri) in s.triangles.iter().enumerate() {
        if !range.contains(&(t as u32)) {
            tri.iter().for_each(|&v| shared[v as usize] = true);
        }
    }
    // Each vertex of the object once, as (source vertex, vertex it is written to).
    let mut target = vec![u32::MAX; nv];
    let mut moved: Vec<(u32, u32)> = Vec::new();
    let mut duplicated = 0;
    for t in range.clone() {
        for c in 0..3 {
            let v = s.triangles[t as usize][c] as usize;
            if target[v] == u32::MAX {
                target[v] = if shared[v] {
                    duplicated += 1;
                    s.positions.push(s.positions[v]);
                    if !s.normals.is_empty() {
                        s.normals.push(s.normals[v]);
                    }
                    if !s.uvs.is_empty() {
                        s.uvs.push(s.uvs[v]);
                    }
                    (s.positions.len() - 1) as u32
                } else {
                    v as u32
                };
                moved.push((v as u32, target[v]));
            }
            s.triangles[t as usize][c] = target[v];
        }
    }

    let has_normals = !s.normals.is_empty();
    for &(src, dst) in &moved {
        let p = scene.positions[src as usize];
        let d = p - centre;
        let (e, jac) = map.apply(d);
        if let Map::Bend { kappa, b, .. } = map {
            if kappa * d[b] >= 1.0 {
                let r = 1.0 / kappa;
                return Err(NodeError::param(
                    "amount",
                    format!(
                        "the bend's radius is {:.4} scene units and object \"{name}\" reaches {:.4} from the axis toward the bend's centre: it would fold inside out (lower the amount)",
                        r.abs(),
                        d[b].abs()
                    ),
                ));
            }
        }
        let mut q = p;
        for i in 0..3 {
            // Coordinates the map keeps stay bit for bit.
            if e[i] != d[i] {
                q[i] = centre[i] + e[i];
            }
        }
        let n = if has_normals { (cofactor(jac) * scene.normals[src as usize]).normalize_or_zero() } else { Vec3::ZERO };
        if !q.is_finite() || !n.is_finite() {
            return Err(NodeError::failed(format!("deforming object \"{name}\" gave a non-finite vertex ({q}) from {p}")));
        }
        s.positions[dst as usize] = q;
        if has_normals {
            s.normals[dst as usize] = n;
        }
    }
    Ok((s, duplicated))
}

#[node(category = "scene", outputs = [scene])]
impl DeformMesh {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        relume_core::MemoryEstimate { outputs: vec![inputs[0]], working: 0 }
    }

    fn run(&self, scene: &Scene, cx: &RunCtx) -> Result<Scene, NodeError> {
        let (scene, duplicated) = deform_mesh(scene, &self.object, self.kind, self.centre, self.axis, self.amount, self.across)?;
        if duplicated > 0 {
            cx.note(format!("{duplicated} vertices of \"{}\" were shared with other objects and were duplicated", self.object));
        }
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::closed_mesh::{enclosed_volume, open_edges};
    use crate::scene::builder::SceneBuilder;
    use crate::testing::{first, id, run_on, t, test_scene};
    use crate::types::Material;
    use relume_core::{PortValue, Value};
    use std::collections::HashMap;

    /// The default layout of the refractive pipeline: a glass sphere at (0, 0.6, 0) over a floor.
    fn glass() -> Scene {
        let grey = Material::Lambert { albedo: Vec3::splat(0.5) };
        SceneBuilder::new(Vec3::new(0.0, 0.8, 3.0), Vec3::new(0.0, 0.5, 0.0), 40.0, 16, 16)
            .sphere("glass", Vec3::new(0.0, 0.6, 0.0), 0.5, Material::Dielectric { ior: 1.5, medium: None }, Vec3::ZERO, false)
            .quad("floor", Vec3::new(-2.0, 0.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), grey, Vec3::ZERO)
            .build()
    }

    fn object_tris(s: &Scene, name: &str) -> Vec<[Vec3; 3]> {
        let o = s.objects.iter().find(|o| o.name == name).unwrap();
        o.triangles.clone().map(|t| s.corners(t as usize)).collect()
    }

    fn object_vertices(s: &Scene, name: &str) -> Vec<u32> {
        let o = s.objects.iter().find(|o| o.name == name).unwrap();
        let mut v: Vec<u32> = o.triangles.clone().flat_map(|t| s.triangles[t as usize]).collect();
        v.sort_unstable();
        v.dedup();
        v
    }

    fn deform(s: &Scene, kind: Deformation, centre: Vec3, axis: Axis, amount: f32, across: f32) -> Scene {
        deform_mesh(s, "glass", kind, centre, axis, amount, across).unwrap().0
    }

    #[test]
    fn amount_zero_leaves_the_scene_byte_identical() {
        let s = glass();
        for kind in [Deformation::Twist, Deformation::Bend, Deformation::Scale] {
            let (d, dup) = deform_mesh(&s, "glass", kind, Vec3::new(0.3, 0.1, 0.0), Axis::X, 0.0, 1.0).unwrap();
            assert_eq!((d.encode(), dup), (s.encode(), 0), "{kind:?}");
        }
        let (d, _) = deform_mesh(&s, "glass", Deformation::Scale, Vec3::ZERO, Axis::Z, 1.0, 1.0).unwrap();
        assert_eq!(d.encode(), s.encode(), "a scale by 1 along and across");
        // Through the node with its defaults (object "glass", Twist, amount 0).
        let out: Scene = first(&run_on::<DeformMesh>(&[], vec![Value::new(s.clone())]).unwrap());
        assert_eq!(out.encode(), s.encode());
    }

    #[test]
    fn twist_keeps_each_vertex_distance_to_the_axis_and_its_coordinate_along_it() {
        let s = glass();
        let centre = Vec3::new(0.2, 0.6, -0.1);
        let d = deform(&s, Deformation::Twist, centre, Axis::Y, 90.0, 1.0);
        let mut turned = 0;
        for v in object_vertices(&s, "glass") {
            let (p, q) = (s.positions[v as usize], d.positions[v as usize]);
            assert_eq!(p.y, q.y, "the coordinate along the axis, bit for bit");
            let (rp, rq) = ((p - centre).with_y(0.0).length(), (q - centre).with_y(0.0).length());
            assert!((rp - rq).abs() < 1e-5, "distance to the axis {rp} → {rq}");
            // The turn is 90° per unit, right-handed about +y.
            let want = 90f32.to_radians() * (p.y - centre.y);
            if rp > 1e-3 {
                let (a, b) = ((p - centre).with_y(0.0) / rp, (q - centre).with_y(0.0) / rq);
                let turn = a.cross(b).y.atan2(a.dot(b));
                assert!((turn - want).abs() < 1e-3, "turned {turn}, not {want}");
                turned += (want.abs() > 0.1) as usize;
            }
            // Normals stay unit and outward-ish for a convex body (the twist is gentle here).
            let n = d.normals[v as usize];
            assert!((n.length() - 1.0).abs() < 1e-5);
        }
        assert!(turned > 100, "{turned}");
        assert_eq!(d.triangles, s.triangles);
        assert_eq!(open_edges(&object_tris(&d, "glass"), 1e-6), 0);
        // A twist keeps volume (its Jacobian has determinant 1).
        let (v0, v1) = (enclosed_volume(&object_tris(&s, "glass")), enclosed_volume(&object_tris(&d, "glass")));
        assert!((v1 / v0 - 1.0).abs() < 2e-3, "{v0} → {v1}");
    }

    #[test]
    fn normals_follow_the_inverse_transpose_of_the_jacobian() {
        // Compare with a finite-difference Jacobian at a few vertices of a twist and a bend.
        let s = glass();
        let centre = Vec3::new(0.1, 0.5, 0.0);
        for (kind, amount) in [(Deformation::Twist, 120.0), (Deformation::Bend, 40.0)] {
            let d = deform(&s, kind, centre, Axis::Y, amount, 1.0);
            let map = match kind {
                Deformation::Twist => Map::Twist { kappa: f32::to_radians(amount), a: 1, j: 2, k: 0 },
                _ => Map::Bend { kappa: f32::to_radians(amount), a: 1, b: 0 },
            };
            for v in object_vertices(&s, "glass").into_iter().step_by(97) {
                let p = (s.positions[v as usize] - centre).as_dvec3();
                let f = |q: glam::DVec3| map.apply(q.as_vec3()).0.as_dvec3();
                let h = 1e-3;
                let cols = [glam::DVec3::X, glam::DVec3::Y, glam::DVec3::Z].map(|e| (f(p + e * h) - f(p - e * h)) / (2.0 * h));
                let jac = glam::DMat3::from_cols(cols[0], cols[1], cols[2]);
                let n = (jac.inverse().transpose() * s.normals[v as usize].as_dvec3()).normalize();
                assert!((n - d.normals[v as usize].as_dvec3()).length() < 1e-3, "{kind:?} at {p}: {n} vs {}", d.normals[v as usize]);
            }
        }
    }

    #[test]
    fn scale_by_two_about_the_centre_multiplies_the_enclosed_volume_by_eight() {
        let s = glass();
        let centre = Vec3::new(0.0, 0.6, 0.0);
        let d = deform(&s, Deformation::Scale, centre, Axis::Y, 2.0, 2.0);
        let (v0, v1) = (enclosed_volume(&object_tris(&s, "glass")), enclosed_volume(&object_tris(&d, "glass")));
        assert!((v1 / v0 - 8.0).abs() < 1e-4, "{v0} → {v1}");
        for v in object_vertices(&s, "glass") {
            let (p, q) = (s.positions[v as usize], d.positions[v as usize]);
            assert!((q - centre - 2.0 * (p - centre)).length() < 1e-5);
            assert!((d.normals[v as usize] - s.normals[v as usize]).length() < 1e-5, "a uniform scale keeps normals");
        }
        // Stretched only along y (factor 3): volume × 3, the equator's radius kept.
        let d = deform(&s, Deformation::Scale, centre, Axis::Y, 3.0, 1.0);
        let v3 = enclosed_volume(&object_tris(&d, "glass"));
        assert!((v3 / v0 - 3.0).abs() < 1e-4, "{v0} → {v3}");
        let (lo, hi) =
            object_tris(&d, "glass").iter().flatten().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), p| (a.min(*p), b.max(*p)));
        assert!(((hi - lo).y - 3.0).abs() < 1e-4 && ((hi - lo).x - 1.0).abs() < 1e-3, "{lo} {hi}");
        // The normals of the stretched sphere are those of the ellipsoid: ∝ (x, y/9, z) about the centre.
        for v in object_vertices(&s, "glass") {
            let q = d.positions[v as usize] - centre;
            let want = (q * Vec3::new(1.0, 1.0 / 9.0, 1.0)).normalize();
            assert!((d.normals[v as usize] - want).length() < 1e-4, "{q}");
        }
    }

    #[test]
    fn bend_keeps_the_mesh_closed_and_moves_vertices_off_the_axis() {
        let s = glass();
        let centre = Vec3::new(0.0, 0.6, 0.0);
        let amount = 60.0f32;
        let d = deform(&s, Deformation::Bend, centre, Axis::Y, amount, 1.0);
        assert_eq!(d.triangles, s.triangles, "same triangles, same winding");
        assert_eq!(d.positions.len(), s.positions.len());
        assert_eq!(open_edges(&object_tris(&d, "glass"), 1e-6), 0, "still closed");
        // Vertices that coincided (the sphere's seam and poles) still coincide.
        let mut seen: HashMap<[u32; 3], Vec3> = HashMap::new();
        for v in object_vertices(&s, "glass") {
            let q = d.positions[v as usize];
            let prev = *seen.entry(s.positions[v as usize].to_array().map(f32::to_bits)).or_insert(q);
            assert_eq!(prev, q);
        }
        // The top pole (on the axis, 0.5 above the centre) moves toward +x by 2 sin²(θ/2)/κ,
        // and down to sin θ/κ above the centre; z is kept everywhere.
        let top = object_vertices(&s, "glass")
            .into_iter()
            .find(|&v| (s.positions[v as usize] - Vec3::new(0.0, 1.1, 0.0)).length() < 1e-6)
            .unwrap();
        let (kappa, theta) = (amount.to_radians(), amount.to_radians() * 0.5);
        let want = centre + Vec3::new(2.0 * (theta / 2.0).sin().powi(2) / kappa, theta.sin() / kappa, 0.0);
        assert!((d.positions[top as usize] - want).length() < 1e-5, "{} vs {want}", d.positions[top as usize]);
        assert!(d.positions[top as usize].x > 0.05);
        for v in object_vertices(&s, "glass") {
            assert_eq!(d.positions[v as usize].z, s.positions[v as usize].z);
        }
        // The sphere is symmetric about the bend plane's axis, so the volume stays (det J = 1 − κu).
        let (v0, v1) = (enclosed_volume(&object_tris(&s, "glass")), enclosed_volume(&object_tris(&d, "glass")));
        assert!((v1 / v0 - 1.0).abs() < 2e-3, "{v0} → {v1}");
        // Negative amounts bend the other way.
        let d = deform(&s, Deformation::Bend, centre, Axis::Y, -amount, 1.0);
        assert!((d.positions[top as usize].x + want.x).abs() < 1e-5);
        // Too strong a bend would fold the object over: refused, naming the radius.
        let e = deform_mesh(&s, "glass", Deformation::Bend, centre, Axis::Y, 180.0, 1.0).unwrap_err().to_string();
        assert!(e.contains("fold inside out") && e.contains("radius"), "{e}");
    }

    #[test]
    fn other_objects_are_untouched_and_shared_vertices_are_duplicated() {
        let s = test_scene::spheres();
        let (d, dup) = deform_mesh(&s, "b", Deformation::Twist, Vec3::new(0.5, 0.0, -0.5), Axis::Z, 45.0, 1.0).unwrap();
        assert_eq!(dup, 0);
        for name in ["a", "c", "floor"] {
            assert_eq!(object_tris(&d, name), object_tris(&s, name), "{name}");
            for v in object_vertices(&s, name) {
                assert_eq!(d.normals[v as usize], s.normals[v as usize]);
            }
        }
        assert_ne!(object_tris(&d, "b"), object_tris(&s, "b"));
        // A scene whose two objects share a vertex: the deformed one gets its own copy.
        let mut s = test_scene::spheres();
        s.uvs = (0..s.positions.len()).map(|i| glam::Vec2::new(i as f32, 0.0)).collect();
        let floor = s.objects[3].triangles.start as usize;
        let b0 = s.objects[1].triangles.start as usize;
        s.triangles[floor][0] = s.triangles[b0][0];
        let shared_v = s.triangles[b0][0];
        let (d, dup) = deform_mesh(&s, "b", Deformation::Scale, Vec3::new(0.7, 0.3, -0.5), Axis::Y, 2.0, 1.0).unwrap();
        assert_eq!(dup, 1);
        assert_eq!(d.positions.len(), s.positions.len() + 1);
        assert_eq!(d.positions[shared_v as usize], s.positions[shared_v as usize], "the floor's corner stays");
        assert_eq!(d.triangles[floor], s.triangles[floor]);
        let copy = d.triangles[b0][0] as usize;
        assert_eq!(copy, s.positions.len());
        assert_eq!(d.uvs[copy], s.uvs[shared_v as usize]);
        assert_ne!(d.positions[copy], s.positions[shared_v as usize]);
        assert!(Scene::decode(&d.encode()).is_some(), "consistent");
    }

    #[test]
    fn an_unknown_object_or_a_bad_amount_is_a_parameter_error() {
        let s = test_scene::spheres();
        let e = deform_mesh(&s, "teapot", Deformation::Twist, Vec3::ZERO, Axis::Y, 10.0, 1.0).unwrap_err().to_string();
        assert!(e.contains("no object \"teapot\"") && e.contains("objects: a, b, c, floor"), "{e}");
        let e = run_on::<DeformMesh>(&[("object", t("zz")), ("kind", id("Bend"))], vec![Value::new(s.clone())]).unwrap_err().to_string();
        assert!(e.contains("no object \"zz\""), "{e}");
        let e = deform_mesh(&s, "a", Deformation::Scale, Vec3::ZERO, Axis::Y, -2.0, 1.0).unwrap_err().to_string();
        assert!(e.contains("[0.01, 100]"), "{e}");
        let e = deform_mesh(&s, "a", Deformation::Twist, Vec3::new(f32::NAN, 0.0, 0.0), Axis::Y, 10.0, 1.0).unwrap_err().to_string();
        assert!(e.contains("finite"), "{e}");
    }
}
