use crate::types::accel::{Accel, BuildQuality};
use crate::types::Scene;
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// Builds an eight-wide BVH over every triangle of a scene (a binary PLOC build by obvhs,
    /// collapsed to eight children a node, boxes stored lane by lane for SIMD slab tests, one
    /// AVX register a node where the CPU has AVX2), for
    /// closest-hit rays that visit children nearest first and shadow rays that stop at the
    /// first blocker. The build is
    /// deterministic; a disk-cached BVH is stored whole (nodes and prepared triangles). `exclude`
    /// leaves one object out (pipeline 3: the refractive object, which the medium volume stands
    /// for); hits still name scene triangles.
    pub struct BuildBvh {
        /// build effort against traversal speed (obvhs presets)
        pub quality: BuildQuality = Medium;
        /// an object to leave out ("": none)
        pub exclude: String = "";
    }
}

#[node(category = "geometry", version = 4, metrics = ["triangles", "bvh_nodes"], outputs = [accel])]
impl BuildBvh {
    fn run(&self, scene: &Scene, cx: &RunCtx) -> Result<Accel, NodeError> {
        if scene.triangles.len() > Accel::MAX_TRIANGLES {
            return Err(NodeError::over_limit(format!(
                "{} triangles, over the {} one BVH holds",
                scene.triangles.len(),
                Accel::MAX_TRIANGLES
            )));
        }
        // One obvhs call: not cancellable inside.
        let accel = if self.exclude.is_empty() {
            Accel::build(scene, self.quality)
        } else {
            let Some(o) = scene.objects.iter().position(|o| o.name == self.exclude) else {
                let names: Vec<_> = scene.objects.iter().map(|o| o.name.as_str()).collect();
                return Err(NodeError::param("exclude", format!("no object \"{}\" (objects: {})", self.exclude, names.join(", "))));
            };
            Accel::build_filtered(scene, self.quality, |t| scene.tri_object[t] as usize != o)
        };
        cx.metric("triangles", accel.triangle_count() as f64);
        cx.metric("bvh_nodes", accel.node_count() as f64);
        Ok(accel)
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
                assert_eq!((h.ng, h.area), scene.normal_area(h.tri as usize), "the hit's normal and area are the scene's, bit for bit");
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

    #[test]
    fn an_excluded_object_is_never_hit_and_hits_name_scene_triangles() {
        use crate::testing::{run_on, t};
        use relume_core::Value;
        let scene = test_scene::spheres();
        let b = scene.objects.iter().position(|o| o.name == "b").unwrap();
        let out = run_on::<BuildBvh>(&[("exclude", t("b"))], vec![Value::new(scene.clone())]).unwrap();
        let a = out[0].get::<Accel>().unwrap();
        let full = Accel::build(&scene, BuildQuality::Medium);
        assert_eq!(a.triangle_count(), scene.triangles.len() - scene.objects[b].triangles.len());
        let (mut kept, mut through) = (0, 0);
        for i in 0..400u64 {
            let u = |d| crate::math::rng::uniform(5, i, d);
            let o = Vec3::new(u(0) * 4.0 - 2.0, u(1) * 4.0 - 2.0, 3.0);
            let d = (Vec3::new(u(2) - 0.5, u(3) - 0.5, -1.0)).normalize();
            let (h, hf) = (a.intersect(o, d, 0.0, f32::INFINITY), full.intersect(o, d, 0.0, f32::INFINITY));
            assert!(h.is_none_or(|h| scene.tri_object[h.tri as usize] as usize != b));
            match hf {
                Some(hf) if scene.tri_object[hf.tri as usize] as usize == b => through += 1,
                _ => {
                    assert_eq!(h, hf, "ray {i}: away from b the hits agree");
                    kept += 1;
                }
            }
        }
        assert!(kept > 50 && through > 10, "{kept} {through}");
        let (lo, hi) = a.bounds();
        assert!(lo.cmple(hi).all());
        let (flo, fhi) = a.bounds_within(Vec3::new(-9.0, -9.0, -9.0), Vec3::new(9.0, lo.y + 1e-3, 9.0)).unwrap();
        assert!(flo.y == lo.y && fhi.y <= lo.y + 1e-3, "clipped to the slab");
        assert!(a.bounds_within(Vec3::splat(100.0), Vec3::splat(101.0)).is_none());
        let e = run_on::<BuildBvh>(&[("exclude", t("zz"))], vec![Value::new(scene.clone())]).unwrap_err().to_string();
        assert!(e.contains("objects: a, b, c, floor"), "{e}");
        let none = Accel::build_filtered(&scene, BuildQuality::Fast, |_| false);
        assert_eq!(none.triangle_count(), 0);
        assert!(none.intersect(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY).is_none());
        assert!(!none.occluded(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY));
    }

    #[test]
    fn rays_straight_down_onto_a_floor_hit_it() {
        // −n is (−0, −1, −0): obvhs took the −0 components' signs two ways and missed; and it
        // skipped boxes ending within 10⁻⁴ of a ray's origin, in any units.
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let floor = scene.objects.iter().position(|o| o.name == "floor").unwrap() as u32;
        let t0 = scene.objects[floor as usize].triangles.start as usize;
        let [a, b, c] = scene.corners(t0);
        let (n, _) = scene.normal_area(t0);
        let p = (a + b + c) / 3.0;
        for h in [1e-6f32, 3e-5, 1e-3, 1.0] {
            for d in [-n, (-n + Vec3::new(0.3, 0.0, 0.2)).normalize()] {
                let hit = accel.intersect(p + n * h, d, 0.0, f32::INFINITY);
                assert_eq!(hit.map(|h| scene.tri_object[h.tri as usize]), Some(floor), "h {h} d {d}");
            }
        }
    }

    #[test]
    fn a_scene_a_thousandth_across_gets_the_same_hits_scaled() {
        // Every coordinate × 2⁻¹⁰: hits at distances × 2⁻¹⁰, bit for bit (a power of two scales
        // every rounding exactly), including those closer than obvhs' 10⁻⁴.
        let scene = test_scene::spheres();
        let mut small = scene.clone();
        small.positions.iter_mut().for_each(|p| *p *= 1.0 / 1024.0);
        let (a, b) = (Accel::build(&scene, BuildQuality::Fast), Accel::build(&small, BuildQuality::Fast));
        let mut hits = 0;
        for i in 0..200u64 {
            let u = |d| crate::math::rng::uniform(9, i, d);
            let o = Vec3::new(u(0) * 4.0 - 2.0, u(1) * 4.0 - 2.0, 3.0);
            let d = (Vec3::new(u(2) - 0.5, u(3) - 0.5, -1.0)).normalize();
            let (h, hs) = (a.intersect(o, d, 0.0, f32::INFINITY), b.intersect(o / 1024.0, d, 0.0, f32::INFINITY));
            assert_eq!(h.map(|h| (h.tri, h.t / 1024.0, h.b1, h.b2)), hs.map(|h| (h.tri, h.t, h.b1, h.b2)), "ray {i}");
            hits += h.is_some() as u32;
        }
        assert!(hits > 50);
        use relume_core::PortValue;
        assert_eq!(Accel::decode(&b.encode()).unwrap().encode(), b.encode());
    }
}
