//! Point-based GI against the path tracer, its stiff cases, and which nodes an edit re-runs.

use glam::Vec3;
use relume_core::Graph;
use relume_nodes::geometry::accel::{Accel, BuildQuality};
use relume_nodes::geometry::sample_surface::{sample_surface, Method, SampleSurfaceParams};
use relume_nodes::pbgi::gbuffer::gbuffer;
use relume_nodes::pbgi::pbgi_gather::{gather, PbgiGatherParams};
use relume_nodes::pbgi::point_tree::PointTree;
use relume_nodes::pbgi::shade_direct::{shade_direct, ShadeDirectParams};
use relume_nodes::reference::path_trace::{render, PathTraceParams};
use relume_nodes::scene::builder::SceneBuilder;
use relume_nodes::types::{Image, Light, Material, Scene};
use relume_tests::{engine, graphs_dir, ran, run};

/// Two parallel diffuse planes with a point light between them; the camera looks down at
/// the lower one from inside the gap.
fn two_planes() -> Scene {
    let lam = Material::Lambert { albedo: Vec3::splat(0.5) };
    SceneBuilder::new(Vec3::new(0.0, 0.9, 0.0), Vec3::new(0.0, 0.0, -0.01), 70.0, 24, 24)
        .quad("lower", Vec3::new(-2.0, 0.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), lam, Vec3::ZERO)
        .quad("upper", Vec3::new(-2.0, 1.0, -2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 4.0), lam, Vec3::ZERO)
        .light(Light::Point { position: Vec3::new(0.0, 0.5, 0.0), intensity: Vec3::splat(1.0) })
        .build()
}

fn pbgi_indirect(scene: &Scene, count: usize, resolution: usize) -> (Image, f64) {
    let accel = Accel::build(scene, BuildQuality::Medium);
    let pts = sample_surface(scene, &SampleSurfaceParams { method: Method::AreaCdf, count, seed: 3, emitters: false }).unwrap();
    let (b, _) = shade_direct(scene, &accel, &pts, &ShadeDirectParams { samples: 4, seed: 1 });
    let tree = PointTree::build(&pts, &b);
    let r = gbuffer(scene, &accel);
    let (img, counts) = gather(&tree, &r, &PbgiGatherParams { resolution, threshold: 1.0 }, scene.extent());
    (img, counts.rasterised as f64 / r.len().max(1) as f64)
}

fn mean(img: &Image) -> f64 {
    img.pixels.iter().map(|p| p[0] as f64).sum::<f64>() / img.pixels.len() as f64
}

#[test]
fn the_indirect_light_between_two_planes_matches_the_path_tracer_within_five_percent() {
    let scene = two_planes();
    let accel = Accel::build(&scene, BuildQuality::Medium);
    let pt = |max_depth| render(&scene, &accel, &PathTraceParams { spp: 512, max_depth, rr_depth: 5, seed: 4 }, None).unwrap().0;
    let (three, two) = (pt(3), pt(2));
    let reference: Vec<f64> = three.pixels.iter().zip(&two.pixels).map(|(a, b)| (a[0] - b[0]) as f64).collect();
    let ref_mean = reference.iter().sum::<f64>() / reference.len() as f64;
    let (pbgi, _) = pbgi_indirect(&scene, 60_000, 32);
    let m = mean(&pbgi);
    assert!(ref_mean > 0.0);
    assert!(((m - ref_mean) / ref_mean).abs() < 0.05, "PBGI {m} vs path tracer {ref_mean}");
}

#[test]
fn stiff_pbgi_cases_stay_finite_and_bounded() {
    // All points coplanar: a single plane under a light has no indirect light at all.
    let lam = Material::Lambert { albedo: Vec3::splat(0.5) };
    let flat = SceneBuilder::new(Vec3::new(0.0, 1.0, 0.5), Vec3::ZERO, 60.0, 12, 12)
        .quad("plane", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), lam, Vec3::ZERO)
        .light(Light::Point { position: Vec3::new(0.0, 1.0, 0.0), intensity: Vec3::ONE })
        .build();
    let (img, _) = pbgi_indirect(&flat, 5_000, 16);
    assert!(img.as_floats().iter().all(|x| x.is_finite() && x.abs() < 1e-6), "coplanar: no indirect light");
    // Microbuffers of 1 × 1 and 256 × 256, and a handful of points (receivers inside node
    // spheres everywhere): finite, and never more than the albedo times the brightest point.
    let scene = two_planes();
    for (res, count) in [(1, 2_000), (256, 2_000), (16, 3)] {
        let (img, _) = pbgi_indirect(&scene, count, res);
        assert!(img.as_floats().iter().all(|x| x.is_finite() && *x >= 0.0), "res {res}, {count} points");
    }
}

#[test]
fn coincident_points_build_a_tree_and_gather_finitely() {
    use relume_nodes::types::SurfacePoints;
    let pts = SurfacePoints {
        position: vec![Vec3::new(0.0, 1.0, 0.0); 50],
        normal: vec![-Vec3::Y; 50],
        radius: vec![0.05; 50],
        object: vec![1; 50],
        material: vec![Material::Lambert { albedo: Vec3::splat(0.5) }; 50],
    };
    let tree = PointTree::build(&pts, &vec![Vec3::ONE; 50]);
    let scene = two_planes();
    let accel = Accel::build(&scene, BuildQuality::Fast);
    let r = gbuffer(&scene, &accel);
    let (img, _) = gather(&tree, &r, &PbgiGatherParams { resolution: 16, threshold: 1.0 }, 4.0);
    assert!(img.as_floats().iter().all(|x| x.is_finite() && *x >= 0.0));
    assert!(img.as_floats().iter().any(|x| *x > 0.0), "the stacked disks are seen from below");
}

#[test]
fn moving_the_light_reruns_shading_onward_but_not_the_surface_points() {
    let reg = relume_nodes::registry();
    let mut g = Graph::load(&graphs_dir().join("pbgi_cornell.ron"), &reg).unwrap();
    for (k, v) in
        [("scene.width", "16"), ("scene.height", "16"), ("points.count", "3000"), ("direct.pixel_samples", "2"), ("shade.samples", "2")]
    {
        g.set_param_text(&reg, k, v).unwrap();
    }
    let e = engine();
    run(&e, &g);
    g.set_param_text(&reg, "move.translation", "(0.1, 0, 0)").unwrap();
    let r = run(&e, &g);
    assert_eq!(ran(&r), ["bvh", "combine", "direct", "gather", "gbuffer", "move", "shade", "tree"]);
    assert!(r.node("points").is_some_and(|n| n.status == "cached"));
}

#[test]
fn the_factorized_gather_rasterises_far_fewer_nodes_per_receiver_and_agrees_with_the_plain_one() {
    use relume_nodes::image::image_error::error_metrics;
    use relume_nodes::pbgi::cluster_receivers::{cluster_receivers, ClusterReceiversParams};
    use relume_nodes::pbgi::factorized_gather::{factorized_gather, FactorizedGatherParams};
    for name in ["cornell", "cornell-bunny"] {
        let mut scene = relume_nodes::scene::format::load_scene_file(&graphs_dir().join(format!("scenes/{name}.ron"))).unwrap().scene;
        scene.camera.width = 64;
        scene.camera.height = 64;
        let accel = Accel::build(&scene, BuildQuality::Medium);
        let pts =
            sample_surface(&scene, &SampleSurfaceParams { method: Method::AreaCdf, count: 20_000, seed: 7, emitters: false }).unwrap();
        let (b, _) = shade_direct(&scene, &accel, &pts, &ShadeDirectParams { samples: 8, seed: 1 });
        let tree = PointTree::build(&pts, &b);
        let r = gbuffer(&scene, &accel);
        let clusters = cluster_receivers(&r, &ClusterReceiversParams { tile: 32, k: 100, iterations: 10, seed: 3 }, None).unwrap().0;
        let (plain, cp) = gather(&tree, &r, &PbgiGatherParams { resolution: 16, threshold: 1.0 }, scene.extent());
        let (fact, cf) = factorized_gather(
            &tree,
            &r,
            &clusters,
            &FactorizedGatherParams { resolution: 16, threshold: 1.0, epsilon: 1.0 },
            scene.extent(),
        );
        let (np, nf) = (cp.rasterised as f64 / r.len() as f64, cf.rasterised as f64 / r.len() as f64);
        assert!(nf < 0.5 * np, "{name}: nodes rasterised per receiver {nf} (factorised) vs {np} (plain)");
        let mse = error_metrics(&fact, &plain, 1.0, 0.01).get("mse").unwrap();
        assert!(mse <= 1e-4, "{name}: MSE between the two {mse}");
    }
}

#[test]
fn changing_k_reruns_only_the_clustering_and_the_factorized_gather() {
    let reg = relume_nodes::registry();
    let mut g = Graph::load(&graphs_dir().join("fpbgi_cornell.ron"), &reg).unwrap();
    for (k, v) in
        [("scene.width", "16"), ("scene.height", "16"), ("points.count", "3000"), ("direct.pixel_samples", "2"), ("shade.samples", "2")]
    {
        g.set_param_text(&reg, k, v).unwrap();
    }
    let e = engine();
    run(&e, &g);
    g.set_param_text(&reg, "clusters.k", "20").unwrap();
    assert_eq!(ran(&run(&e, &g)), ["clusters", "combine", "gather"]);
}

#[test]
fn asking_only_for_the_direct_image_builds_no_points_tree_or_gather() {
    let reg = relume_nodes::registry();
    let mut g = Graph::load(&graphs_dir().join("pbgi_cornell.ron"), &reg).unwrap();
    for (k, v) in [("scene.width", "16"), ("scene.height", "16"), ("direct.pixel_samples", "2")] {
        g.set_param_text(&reg, k, v).unwrap();
    }
    let opts = relume_core::RunOptions { outputs: Some(vec!["direct".into()]), ..Default::default() };
    let r = engine().run(&g, &opts).unwrap().report;
    assert_eq!(ran(&r), ["bvh", "direct", "move", "scene"]);
}
