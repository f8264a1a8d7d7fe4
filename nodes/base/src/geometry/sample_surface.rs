use crate::math::rng::uniform;
use crate::math::sampling::{uniform_triangle, Distribution1D};
use crate::types::{Material, Scene, SurfacePoints, MAX_IMAGE_BYTES};
use glam::{Vec2, Vec3};
use relume_core::{node, params, CancelToken, NodeError, ParamEnum, RunCtx};
use std::collections::HashMap;

params! {
    /// Samples points on every surface of a scene. `AreaCdf`: exactly `count` points, each
    /// triangle chosen in proportion to its area, uniform inside it (seeded). `PoissonDisk`:
    /// dart throwing over area-CDF candidates (8 per requested point) with a grid, keeping a
    /// point only if no kept point lies within r = sqrt(A / (count π)) · 0.75; it keeps fewer
    /// than `count` points and says how many. Each point carries position, shading normal, the
    /// radius of the disk of area A / n it stands for, object and material. Emissive objects
    /// are left out unless `emitters` is set.
    pub struct SampleSurface {
        /// area-proportional random points, or a Poisson-disk subset of them
        pub method: Method = AreaCdf;
        /// points requested
        pub count: usize = 100_000, range = 1..=100_000_000, unit = "points", test = 2000;
        /// random seed
        pub seed: u64 = 0, range = 0..=u32::MAX;
        /// also sample emissive objects (lights); off for PBGI, whose direct pass handles them
        pub emitters: bool = false;
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum Method {
    AreaCdf,
    PoissonDisk,
}

/// Points generated per parallel work item.
const CHUNK: usize = 4096;

/// Samples points; errors name the parameter.
pub fn sample_surface(scene: &Scene, p: &SampleSurface) -> Result<SurfacePoints, NodeError> {
    let cancel = CancelToken::new();
    sample_surface_with(scene, p, &RunCtx::new("sample_surface", &cancel, None))
}

/// As `sample_surface`, reporting progress to `cx` and stopping once it is cancelled.
pub fn sample_surface_with(scene: &Scene, p: &SampleSurface, cx: &RunCtx) -> Result<SurfacePoints, NodeError> {
    let candidates = if p.method == Method::PoissonDisk { p.count.saturating_mul(8) } else { p.count };
    let bytes = candidates.saturating_mul(SurfacePoints::BYTES_PER_POINT);
    if bytes > MAX_IMAGE_BYTES {
        return Err(NodeError::over_limit_param(
            "count",
            format!("{candidates} points need {:.1} GiB, over the {} GiB limit", bytes as f64 / (1u64 << 30) as f64, MAX_IMAGE_BYTES >> 30),
        ));
    }
    let included = |t: usize| p.emitters || scene.objects[scene.tri_object[t] as usize].emission == Vec3::ZERO;
    let areas: Vec<f32> = (0..scene.triangles.len()).map(|t| if included(t) { scene.normal_area(t).1 } else { 0.0 }).collect();
    let dist = Distribution1D::new(&areas);
    let total: f64 = areas.iter().map(|&a| a as f64).sum();
    if total <= 0.0 {
        return Err(NodeError::input("scene", "the scene's surfaces have no area"));
    }
    // Point i: (position, normal, object, material), a function of i and the seed alone.
    let point = |i: usize| -> (Vec3, Vec3, u32, Material) {
        let (t, _) = dist.sample_discrete(uniform(p.seed, i as u64, 0));
        let (b0, b1) = uniform_triangle(Vec2::new(uniform(p.seed, i as u64, 1), uniform(p.seed, i as u64, 2)));
        let [a, b, c] = scene.corners(t);
        let pos = a * b0 + b * b1 + c * (1.0 - b0 - b1);
        let (ng, _) = scene.normal_area(t);
        let n = if scene.normals.is_empty() {
            ng
        } else {
            let [i0, i1, i2] = scene.triangles[t].map(|i| i as usize);
            (scene.normals[i0] * b0 + scene.normals[i1] * b1 + scene.normals[i2] * (1.0 - b0 - b1)).try_normalize().unwrap_or(ng)
        };
        let obj = scene.tri_object[t];
        let material = scene.material_on(t, [b0, b1, 1.0 - b0 - b1]);
        (pos, if n.dot(ng) < 0.0 { -n } else { n }, obj, material)
    };
    // The first `n` points, in order, generated in parallel chunks.
    let generate = |n: usize| -> Result<SurfacePoints, NodeError> {
        let chunks = cx.par_map(n.div_ceil(CHUNK), |c| (c * CHUNK..((c + 1) * CHUNK).min(n)).map(point).collect::<Vec<_>>())?;
        let mut pts = SurfacePoints::default();
        pts.position.reserve_exact(n);
        pts.normal.reserve_exact(n);
        pts.object.reserve_exact(n);
        pts.material.reserve_exact(n);
        // Each chunk is freed once copied.
        for (pos, nrm, obj, mat) in chunks.into_iter().flatten() {
            pts.position.push(pos);
            pts.normal.push(nrm);
            pts.object.push(obj);
            pts.material.push(mat);
        }
        Ok(pts)
    };
    let mut pts = match p.method {
        Method::AreaCdf => generate(p.count)?,
        Method::PoissonDisk => {
            let r = (total / (p.count as f64 * std::f64::consts::PI)).sqrt() as f32 * 0.75;
            let all = generate(candidates)?;
            let mut pts = SurfacePoints::default();
            let cell = |q: Vec3| ((q / r).floor().as_ivec3()).to_array();
            // Only looked up, never iterated: the result does not depend on its order.
            let mut grid: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
            for i in 0..all.len() {
                if i % CHUNK == 0 {
                    cx.tick(i as u64, all.len() as u64)?;
                }
                let q = all.position[i];
                let c = cell(q);
                let near = (-1..=1).flat_map(|dx| (-1..=1).flat_map(move |dy| (-1..=1).map(move |dz| [c[0] + dx, c[1] + dy, c[2] + dz])));
                let blocked = near
                    .into_iter()
                    .any(|k| grid.get(&k).is_some_and(|v| v.iter().any(|&j| pts.position[j as usize].distance_squared(q) < r * r)));
                if !blocked {
                    grid.entry(c).or_default().push(pts.len() as u32);
                    pts.position.push(q);
                    pts.normal.push(all.normal[i]);
                    pts.object.push(all.object[i]);
                    pts.material.push(all.material[i]);
                }
            }
            pts
        }
    };
    let radius = (total / (pts.len() as f64 * std::f64::consts::PI)).sqrt() as f32;
    pts.radius = vec![radius; pts.len()];
    Ok(pts)
}

#[node(category = "geometry", metrics = ["points"], outputs = [points])]
impl SampleSurface {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let _ = inputs;
        let bytes = (self.count * crate::types::SurfacePoints::BYTES_PER_POINT) as u64;
        relume_core::MemoryEstimate { outputs: vec![Some(relume_core::PortSize::bytes(bytes))], working: 0 }
    }

    fn run(&self, scene: &Scene, cx: &RunCtx) -> Result<SurfacePoints, NodeError> {
        let pts = sample_surface_with(scene, self, cx)?;
        cx.metric("points", pts.len() as f64);
        if self.method == Method::PoissonDisk {
            cx.note(format!("Poisson-disk sampling kept {} of {} requested points", pts.len(), self.count));
        }
        Ok(pts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::test_scene;

    fn params(method: Method, count: usize, seed: u64) -> SampleSurface {
        SampleSurface { method, count, seed, emitters: true }
    }

    #[test]
    fn area_cdf_points_lie_on_the_surface_in_proportion_to_area() {
        let scene = test_scene::spheres();
        let pts = sample_surface(&scene, &params(Method::AreaCdf, 20_000, 1)).unwrap();
        assert_eq!(pts.len(), 20_000);
        let area = |o: usize| scene.objects[o].triangles.clone().map(|t| scene.normal_area(t as usize).1 as f64).sum::<f64>();
        let total: f64 = (0..scene.objects.len()).map(area).sum();
        for o in 0..scene.objects.len() {
            let share = pts.object.iter().filter(|&&x| x == o as u32).count() as f64 / 20_000.0;
            let want = area(o) / total;
            // Binomial standard deviation; 5σ.
            assert!((share - want).abs() < 5.0 * (want * (1.0 - want) / 20_000.0).sqrt(), "object {o}: {share} vs {want}");
        }
        // The sphere "a" (centre (−0.8, 0, 0), radius 0.5): its points are on it, normals outward.
        for i in (0..pts.len()).filter(|&i| pts.object[i] == 0) {
            let d = pts.position[i] - Vec3::new(-0.8, 0.0, 0.0);
            assert!((d.length() - 0.5).abs() < 2e-3 && pts.normal[i].dot(d.normalize()) > 0.99);
        }
        let r = pts.radius[0] as f64;
        assert!((std::f64::consts::PI * r * r * 20_000.0 - total).abs() < 1e-3 * total, "disks add up to the area");
    }

    #[test]
    fn poisson_disk_points_keep_their_distance_and_are_deterministic() {
        let scene = test_scene::spheres();
        let a = sample_surface(&scene, &params(Method::PoissonDisk, 1500, 4)).unwrap();
        let b = sample_surface(&scene, &params(Method::PoissonDisk, 1500, 4)).unwrap();
        assert_eq!(a.position, b.position);
        assert!(a.len() > 900 && a.len() <= 1500 * 8, "{}", a.len());
        let total: f64 = (0..scene.triangles.len()).map(|t| scene.normal_area(t).1 as f64).sum();
        let r = (total / (1500.0 * std::f64::consts::PI)).sqrt() as f32 * 0.75;
        for i in 0..a.len() {
            for j in 0..i {
                assert!(a.position[i].distance(a.position[j]) >= r * 0.9999, "{i} and {j} too close");
            }
        }
    }

    #[test]
    fn oversized_requests_are_refused_before_allocating() {
        let scene = test_scene::spheres();
        let e = sample_surface(&scene, &params(Method::PoissonDisk, 100_000_000, 0)).unwrap_err();
        assert!(e.to_string().contains("GiB"), "{e}");
    }

    #[test]
    fn the_node_matches_the_kernel_and_cancels_midway() {
        use crate::testing::{cancels_midway, first, i, id, run_on};
        use relume_core::Value;
        let scene = test_scene::spheres();
        let pts: SurfacePoints = first(
            &run_on::<SampleSurface>(&[("count", i(5000)), ("seed", i(3)), ("method", id("PoissonDisk"))], vec![Value::new(scene.clone())])
                .unwrap(),
        );
        let want = sample_surface(&scene, &SampleSurface { method: Method::PoissonDisk, count: 5000, seed: 3, emitters: false }).unwrap();
        assert_eq!((pts.position, pts.radius), (want.position, want.radius));
        for method in Method::VARIANTS {
            cancels_midway::<SampleSurface>(&[("count", i(400_000)), ("method", id(method))], vec![Value::new(scene.clone())]);
        }
    }
}
