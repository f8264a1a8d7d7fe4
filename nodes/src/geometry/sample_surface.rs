//! SampleSurface node.

use crate::math::rng::uniform;
use crate::math::sampling::{uniform_triangle, Distribution1D};
use crate::types::{Scene, SurfacePoints, MAX_IMAGE_BYTES};
use glam::{Vec2, Vec3};
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};
use std::collections::HashMap;

node_doc! {
    /// Samples points on every surface of a scene. `AreaCdf`: exactly `count` points, each
    /// triangle chosen in proportion to its area, uniform inside it (seeded). `PoissonDisk`:
    /// dart throwing over area-CDF candidates (8 per requested point) with a grid, keeping a
    /// point only if no kept point lies within r = sqrt(A / (count π)) · 0.75; it keeps fewer
    /// than `count` points and says how many. Each point carries position, shading normal, the
    /// radius of the disk of area A / n it stands for, object and material. Emissive objects
    /// are left out unless `emitters` is set.
    pub struct SampleSurface;
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    AreaCdf,
    PoissonDisk,
}

pub struct SampleSurfaceParams {
    pub method: Method,
    pub count: usize,
    pub seed: u64,
    /// Sample emissive objects too (PBGI leaves them out: direct lighting handles them).
    pub emitters: bool,
}

impl Params for SampleSurfaceParams {
    fn schema() -> Schema {
        Schema::new()
            .enumeration("method", &["AreaCdf", "PoissonDisk"], "AreaCdf")
            .help("area-proportional random points, or a Poisson-disk subset of them")
            .int("count", 100_000, 1, 100_000_000)
            .unit("points")
            .help("points requested")
            .int("seed", 0, 0, i64::from(u32::MAX))
            .help("random seed")
            .bool("emitters", false)
            .help("also sample emissive objects (lights); off for PBGI, whose direct pass handles them")
    }
    fn from_values(v: &ParamValues) -> Self {
        let method = if v.variant("method") == "PoissonDisk" { Method::PoissonDisk } else { Method::AreaCdf };
        SampleSurfaceParams { method, count: v.int("count") as usize, seed: v.int("seed") as u64, emitters: v.bool("emitters") }
    }
}

/// Samples points; errors name the parameter.
pub fn sample_surface(scene: &Scene, p: &SampleSurfaceParams) -> Result<SurfacePoints, NodeError> {
    let candidates = if p.method == Method::PoissonDisk { p.count.saturating_mul(8) } else { p.count };
    let bytes = candidates.saturating_mul(SurfacePoints::BYTES_PER_POINT);
    if bytes > MAX_IMAGE_BYTES {
        return Err(NodeError::param(
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
    let mut pts = SurfacePoints::default();
    let push = |pts: &mut SurfacePoints, i: usize| {
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
        pts.position.push(pos);
        pts.normal.push(if n.dot(ng) < 0.0 { -n } else { n });
        pts.object.push(obj);
        pts.material.push(scene.objects[obj as usize].material);
    };
    match p.method {
        Method::AreaCdf => {
            for i in 0..p.count {
                push(&mut pts, i);
            }
        }
        Method::PoissonDisk => {
            let r = (total / (p.count as f64 * std::f64::consts::PI)).sqrt() as f32 * 0.75;
            let mut all = SurfacePoints::default();
            for i in 0..candidates {
                push(&mut all, i);
            }
            let cell = |q: Vec3| ((q / r).floor().as_ivec3()).to_array();
            let mut grid: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
            for i in 0..all.len() {
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
        }
    }
    let radius = (total / (pts.len() as f64 * std::f64::consts::PI)).sqrt() as f32;
    pts.radius = vec![radius; pts.len()];
    Ok(pts)
}

impl Node for SampleSurface {
    const KIND: &'static str = "SampleSurface";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "geometry";
    const CACHING: Caching = Caching::Memory;
    type Params = SampleSurfaceParams;

    fn ports() -> Ports {
        Ports::new().input::<Scene>("scene").output::<SurfacePoints>("points")
    }

    fn run(&self, p: &SampleSurfaceParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        let pts = sample_surface(io.input::<Scene>("scene")?, p)?;
        cx.metric("points", pts.len() as f64);
        if p.method == Method::PoissonDisk {
            cx.note(format!("Poisson-disk sampling kept {} of {} requested points", pts.len(), p.count));
        }
        io.set("points", pts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::test_scene;

    fn params(method: Method, count: usize, seed: u64) -> SampleSurfaceParams {
        SampleSurfaceParams { method, count, seed, emitters: true }
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
}
