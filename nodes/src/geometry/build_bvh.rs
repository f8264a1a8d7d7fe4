//! BuildBvh node.

use super::accel::{Accel, BuildQuality};
use crate::types::Scene;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};

node_doc! {
    /// Builds a compressed-wide BVH (obvhs, PLOC) over every triangle of a scene, for
    /// closest-hit rays and shadow rays that stop at the first blocker. Its fingerprint is
    /// that of the scene plus the build quality (it is rebuilt, not stored on disk).
    pub struct BuildBvh;
}

pub struct BuildBvhParams {
    pub quality: BuildQuality,
}

impl Params for BuildBvhParams {
    fn schema() -> Schema {
        Schema::new()
            .enumeration("quality", &["Fast", "Medium", "Slow"], "Medium")
            .help("build effort against traversal speed (obvhs presets)")
    }
    fn from_values(v: &ParamValues) -> Self {
        let quality = match v.variant("quality") {
            "Fast" => BuildQuality::Fast,
            "Slow" => BuildQuality::Slow,
            _ => BuildQuality::Medium,
        };
        BuildBvhParams { quality }
    }
}

impl Node for BuildBvh {
    const KIND: &'static str = "BuildBvh";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "geometry";
    const CACHING: Caching = Caching::Memory;
    type Params = BuildBvhParams;

    fn ports() -> Ports {
        Ports::new().input::<Scene>("scene").output::<Accel>("accel")
    }

    fn run(&self, p: &BuildBvhParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        let accel = Accel::build(io.input::<Scene>("scene")?, p.quality);
        cx.metric("triangles", accel.triangle_count() as f64);
        cx.metric("bvh_nodes", accel.node_count() as f64);
        io.set("accel", accel)
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
                let tri = super::super::accel::brute(a, b, c, o, d);
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
}
