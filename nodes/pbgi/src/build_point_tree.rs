//! PointTree node: builds the `PointTree` (types/point_tree.rs) over shaded surface points.

use crate::types::{PointRadiance, PointTree};
use glam::Vec3;
use relume_base::types::SurfacePoints;
use relume_core::{node, NodeError, Params, RunCtx};

/// Builds the point hierarchy of PBGI ([P] 2.1.2): a binary bounding-sphere tree with one
/// point per leaf (2N − 1 nodes). Top-down, each set of points is split at the median of
/// its longest bounding-box axis (ties by point index, so the tree is deterministic); then,
/// bottom-up, every node gets a bounding sphere holding its children's (a leaf: the point's
/// disk of radius r, a sphere of radius r at the point), a normal cone holding its children's,
/// its area A = Σ π r_i², and in 3-band real SH (9 coefficients, orthonormal) the projected
/// area A(ω) = Σ A_i max(0, n_i·ω) and the power Σ B_i A_i max(0, n_i·ω) (RGB, B_i the
/// point's outgoing radiance), each point's clamped cosine projected as Â_l Y_l^m(n_i) with
/// Â = π, 2π/3, π/4; a parent's area and SH are the sums of its children's. Seen from ω, an
/// inner node's projected area is the SH estimate clamped to what its normal cone allows,
/// and its radiance is power / area; leaves are exact. Points facing the inside of glass
/// (`TwinDielectrics`' inner twins) are split off first, into the root's second subtree: what
/// they send travels inside the glass only, and the gathers traverse each side apart.
/// The tree is told apart from others by its inputs, not by hashing its hundreds of
/// megabytes.
#[derive(Params)]
pub struct BuildPointTree;

#[node(category = "pbgi", kind = "PointTree", version = 3, caching = Keyed, metrics = ["nodes", "depth"], outputs = [tree])]
impl BuildPointTree {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // 2N − 1 nodes and the points' radiance.
        let n = inputs[0].map(|s| s.bytes / relume_base::types::SurfacePoints::BYTES_PER_POINT as u64);
        let node = std::mem::size_of::<crate::types::TreeNode>() as u64;
        // The build moves a 32-byte copy of each point (position, normal, radius, index).
        relume_core::MemoryEstimate {
            outputs: vec![n.map(|n| relume_core::PortSize::bytes(2 * n * node + 12 * n))],
            working: n.map_or(0, |n| 32 * n),
        }
    }

    fn run(&self, points: &SurfacePoints, radiance: &PointRadiance, cx: &RunCtx) -> Result<PointTree, NodeError> {
        let (points, radiance) = (points, &radiance.0);
        check_inputs(points, radiance)?;
        let tree = PointTree::build_with(points, radiance, cx)?;
        cx.metric("nodes", tree.len() as f64);
        cx.metric("depth", tree.depth() as f64);
        Ok(tree)
    }
}

/// Refuses what would make the tree meaningless; errors name the port and the first bad point.
fn check_inputs(points: &SurfacePoints, radiance: &[Vec3]) -> Result<(), NodeError> {
    let n = points.len();
    if n == 0 {
        return Err(NodeError::input("points", "no points: the tree needs at least one"));
    }
    if points.normal.len() != n || points.radius.len() != n {
        return Err(NodeError::input(
            "points",
            format!("{n} positions but {} normals and {} radii", points.normal.len(), points.radius.len()),
        ));
    }
    if radiance.len() != n {
        return Err(NodeError::input("radiance", format!("{} radiance values for {n} points", radiance.len())));
    }
    if n >= u32::MAX as usize / 2 {
        return Err(NodeError::input("points", format!("{n} points: more than a u32-indexed tree holds")));
    }
    let all = points.position.iter().zip(&points.normal).zip(&points.radius).zip(radiance);
    for (i, (((&p, &nr), &r), &b)) in all.enumerate() {
        if !p.is_finite() || !nr.is_finite() || !r.is_finite() {
            return Err(NodeError::input("points", format!("point {i} is not finite (position {p}, normal {nr}, radius {r})")));
        }
        if r < 0.0 {
            return Err(NodeError::input("points", format!("point {i} has a negative radius {r}")));
        }
        if nr.length_squared() == 0.0 {
            return Err(NodeError::input("points", format!("point {i} has a zero normal")));
        }
        if !b.is_finite() {
            return Err(NodeError::input("radiance", format!("point {i}'s radiance {b} is not finite")));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::geometry::sample_surface::{sample_surface, Method, SampleSurface};
    use relume_base::testing::{cancels_midway, first, run_full, run_on, test_scene};
    use relume_base::types::Material;
    use relume_core::Value;
    use std::path::Path;

    fn points_from(position: Vec<Vec3>, normal: Vec<Vec3>, radius: Vec<f32>) -> SurfacePoints {
        let n = position.len();
        SurfacePoints { position, normal, radius, object: vec![0; n], material: vec![Material::Lambert { albedo: Vec3::splat(0.5) }; n] }
    }

    #[test]
    fn the_node_builds_the_tree_and_reports_its_size() {
        let scene = test_scene::spheres();
        let pts = sample_surface(&scene, &SampleSurface { method: Method::AreaCdf, count: 3000, seed: 2, emitters: true }).unwrap();
        let rad = PointRadiance(vec![Vec3::splat(0.5); pts.len()]);
        let want = PointTree::build(&pts, &rad.0);
        let entry = run_full::<BuildPointTree>(&[], Path::new("."), vec![Value::new(pts.clone()), Value::new(rad.clone())]).unwrap();
        let tree: PointTree = first(&entry.outputs);
        assert_eq!(tree, want);
        assert_eq!(tree.len(), 2 * 3000 - 1);
        let metric = |k: &str| entry.metrics.iter().find(|(n, _)| n == k).map(|m| m.1);
        assert_eq!(metric("nodes"), Some(5999.0));
        assert_eq!(metric("depth"), Some(12.0));
    }

    #[test]
    fn the_node_names_the_input_it_cannot_use() {
        let run = |pts: SurfacePoints, rad: Vec<Vec3>| {
            run_on::<BuildPointTree>(&[], vec![Value::new(pts), Value::new(PointRadiance(rad))]).unwrap_err()
        };
        let e = run(SurfacePoints::default(), vec![]);
        assert!(matches!(&e, NodeError::Input { port, .. } if port == "points"), "{e}");
        let one = points_from(vec![Vec3::ZERO], vec![Vec3::Z], vec![0.1]);
        let e = run(one.clone(), vec![Vec3::ONE; 2]);
        assert!(matches!(&e, NodeError::Input { port, .. } if port == "radiance"), "{e}");
        assert!(e.to_string().contains("2 radiance values for 1 points"), "{e}");
        let e = run(one.clone(), vec![Vec3::new(f32::NAN, 0.0, 0.0)]);
        assert!(matches!(&e, NodeError::Input { port, .. } if port == "radiance"), "{e}");
        let e = run(points_from(vec![Vec3::ZERO], vec![Vec3::ZERO], vec![0.1]), vec![Vec3::ONE]);
        assert!(matches!(&e, NodeError::Input { port, .. } if port == "points") && e.to_string().contains("zero normal"), "{e}");
        let e = run(points_from(vec![Vec3::ZERO], vec![Vec3::Z], vec![-1.0]), vec![Vec3::ONE]);
        assert!(e.to_string().contains("negative radius"), "{e}");
        let e = run(points_from(vec![Vec3::INFINITY], vec![Vec3::Z], vec![0.1]), vec![Vec3::ONE]);
        assert!(e.to_string().contains("point 0 is not finite"), "{e}");
    }

    #[test]
    fn the_node_is_registered_as_point_tree_in_pbgi() {
        let reg = crate::registry();
        let node = reg.node("PointTree").expect("registered");
        assert_eq!(node.category(), "pbgi");
        assert!(reg.port_type("PointTree").is_some());
    }

    #[test]
    fn the_node_stops_when_cancelled() {
        let scene = test_scene::spheres();
        let pts = sample_surface(&scene, &SampleSurface { method: Method::AreaCdf, count: 20_000, seed: 3, emitters: true }).unwrap();
        let rad = PointRadiance(vec![Vec3::splat(0.5); pts.len()]);
        cancels_midway::<BuildPointTree>(&[], vec![Value::new(pts), Value::new(rad)]);
    }
}
