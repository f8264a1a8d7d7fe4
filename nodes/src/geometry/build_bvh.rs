//! BuildBvh node.

use crate::types::accel::{Accel, BuildQuality};
use crate::types::Scene;
use relume_core::{inputs, node, outputs, NodeError, Params, RunCtx};

/// Builds a compressed-wide BVH (obvhs, PLOC) over every triangle of a scene, for
/// closest-hit rays and shadow rays that stop at the first blocker. The build is
/// deterministic; a disk-cached BVH is stored whole (nodes and prepared triangles).
#[derive(Params)]
pub struct BuildBvh {
    /// build effort against traversal speed (obvhs presets)
    #[param(default = Medium)]
    pub quality: BuildQuality,
}

inputs!(pub BuildBvhIn { scene: Scene });
outputs!(pub BuildBvhOut { accel: Accel });

#[node(category = "geometry")]
impl BuildBvh {
    fn run(&self, i: BuildBvhIn, cx: &RunCtx) -> Result<BuildBvhOut, NodeError> {
        // One obvhs call: not cancellable inside.
        let accel = Accel::build(i.scene, self.quality);
        cx.metric("triangles", accel.triangle_count() as f64);
        cx.metric("bvh_nodes", accel.node_count() as f64);
        Ok(BuildBvhOut { accel })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::test_scene;
    use glam::Vec3;

    #[test]
    fn closest_hits_match_brute_force_and_shadow_rays_agree() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Medium);
        let mut hits = 0;
        for i in 0..120u64 {
            let u = |d| crate::math::rng::uniform(4, i, d);
            let o = Vec3::new(u(0) * 4.0 - 2.0, u(1) * 4.0 - 2.0, 3.0);
            let d = (Vec3::new(u(2) - 0.5, u(3) - 0.5, -1.0)).normalize();
            // Brute force over every triangle.
            let mut best: Option<(f32, u32)> = None;
            for t in 0..scene.triangles.len() {
                let [a, b, c] = scene.corners(t);
                let tri = crate::types::accel::brute(a, b, c, o, d);
                if let Some(tt) = tri {
                    if best.is_none_or(|(bt, _)| tt < bt) {
                        best = Some((tt, t as u32));
                    }
                }
            }
            let hit = accel.intersect(o, d, 0.0, f32::INFINITY);
            assert_eq!(hit.map(|h| h.tri), best.map(|b| b.1), "ray {i}");
            if let (Some(h), Some(b)) = (hit, best) {
                hits += 1;
                assert!((h.t - b.0).abs() < 1e-4);
                let [a, bb, c] = scene.corners(h.tri as usize);
                let p = a * (1.0 - h.b1 - h.b2) + bb * h.b1 + c * h.b2;
                assert!((p - (o + d * h.t)).length() < 1e-4, "barycentrics give the hit point");
                assert!(accel.occluded(o, d, 0.0, h.t + 1e-3));
                assert!(!accel.occluded(o, d, 0.0, h.t * 0.999));
            } else {
                assert!(!accel.occluded(o, d, 0.0, f32::INFINITY));
            }
        }
        assert!(hits > 20, "the test rays hit something: {hits}");
    }

    #[test]
    fn the_node_builds_with_the_chosen_quality() {
        use crate::testing::{id, run_on};
        use relume_core::{PortValue, Value};
        let scene = test_scene::spheres();
        let out = run_on::<BuildBvh>(&[("quality", id("Fast"))], vec![Value::new(scene.clone())]).unwrap();
        let a = out[0].get::<Accel>().unwrap();
        assert_eq!(a.encode(), Accel::build(&scene, BuildQuality::Fast).encode());
        assert_eq!(a.triangle_count(), scene.triangles.len());
    }
}
