//! The reference path tracer against analytic answers, and on the stiff cases of
//! docs/QUALITY.md §2 (geometry, transport, lighting rows): finite output, no energy created.

use glam::Vec3;
use relume_base::reference::path_trace::{render, PathTrace};
use relume_base::render::camera::CameraRays;
use relume_base::scene::builder::SceneBuilder;
use relume_base::types::accel::{Accel, BuildQuality};
use relume_base::types::{EnvMap, Environment, Image, Light, Material, Scene};

fn trace(scene: &Scene, spp: u32, max_depth: i32) -> (Image, Image) {
    let accel = Accel::build(scene, BuildQuality::Medium);
    let (m, v, _, nonfinite) =
        render(scene, &accel, &PathTrace { spp, max_depth, min_depth: 1, rr_depth: 5, seed: 3, fresnel_reflection: true }, None).unwrap();
    assert_eq!(nonfinite, 0, "no NaN or infinite samples");
    assert!(m.as_floats().iter().chain(v.as_floats()).all(|x| x.is_finite() && *x >= 0.0), "finite, non-negative output");
    (m, v)
}

/// Mean over pixels of the red channel, and its standard error from the per-pixel variances
/// (one channel: in a grey scene the channels are the same samples, not independent ones).
fn mean_and_sigma(m: &Image, v: &Image) -> (f64, f64) {
    let n = m.pixels.len() as f64;
    let mean = m.pixels.iter().map(|p| p[0] as f64).sum::<f64>() / n;
    let var: f64 = v.pixels.iter().map(|p| p[0] as f64).sum::<f64>() / (n * n);
    (mean, var.sqrt())
}

fn lambert(a: f32) -> Material {
    Material::Lambert { albedo: Vec3::splat(a) }
}

#[test]
fn a_furnace_converges_to_emission_over_one_minus_albedo_within_its_variance() {
    // Inside a closed sphere of albedo a emitting e everywhere: L = e / (1 − a). Flat
    // shading: interpolated normals on a tessellated sphere do not conserve energy exactly.
    for (a, e) in [(0.5f32, 1.0f32), (0.8, 0.25)] {
        let scene = SceneBuilder::new(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0), 60.0, 8, 8)
            .sphere("room", Vec3::ZERO, 2.0, lambert(a), Vec3::splat(e), true)
            .flat_shading()
            .build();
        let (m, v) = trace(&scene, 512, -1);
        let (mean, sigma) = mean_and_sigma(&m, &v);
        let exact = (e / (1.0 - a)) as f64;
        assert!((mean - exact).abs() < 4.0 * sigma + 1e-3 * exact, "a = {a}: {mean} vs {exact} ± {sigma}");
        assert!(sigma > 0.0 && sigma < 0.02 * exact);
    }
}

#[test]
fn a_glossy_furnace_never_exceeds_the_analytic_bound() {
    // Blinn-Phong with kd + ks = 0.9: every bounce keeps at most 0.9, so L ≤ e / (1 − 0.9).
    let m = Material::BlinnPhong { kd: Vec3::splat(0.45), ks: Vec3::splat(0.45), exponent: 20.0 };
    let scene = SceneBuilder::new(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0), 60.0, 8, 8)
        .sphere("room", Vec3::ZERO, 2.0, m, Vec3::ONE, true)
        .flat_shading()
        .build();
    let (img, var) = trace(&scene, 256, -1);
    let (mean, sigma) = mean_and_sigma(&img, &var);
    assert!(mean <= 10.0 + 4.0 * sigma && mean >= 1.0, "{mean} ± {sigma}");
}

#[test]
fn a_convex_object_under_a_constant_environment_reflects_albedo_times_radiance() {
    // No occlusion: a sphere of albedo 0.8 under radiance 1 shows 0.8; the sky shows 1.
    for env in [Environment::Constant(Vec3::ONE), Environment::Map(EnvMap::new(16, 8, vec![Vec3::ONE; 128]).unwrap())] {
        let scene = SceneBuilder::new(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, 30.0, 16, 16)
            .sphere("ball", Vec3::ZERO, 1.0, lambert(0.8), Vec3::ZERO, false)
            .environment(env)
            .build();
        let (m, v) = trace(&scene, 256, -1);
        let (centre, corner) = (m.get(8, 8), m.get(0, 0));
        let sd = v.get(8, 8)[0].sqrt();
        assert!((centre[0] - 0.8).abs() < 4.0 * sd + 2e-3, "{centre:?} ± {sd}");
        assert_eq!(corner, [1.0; 3], "the environment seen directly");
    }
}

#[test]
fn direct_lighting_of_a_diffuse_quad_matches_the_analytic_irradiance() {
    // max_depth 2: L = ρ/π · I cos θ / r², per pixel, at the pixel centre (the box filter's
    // jitter changes the value only to second order).
    let (rho, i, light) = (0.6f32, 10.0f32, Vec3::new(0.3, 1.5, 0.2));
    let scene = SceneBuilder::new(Vec3::new(0.0, 3.0, 0.01), Vec3::ZERO, 40.0, 24, 24)
        .quad("floor", Vec3::new(-2.0, 0.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), lambert(rho), Vec3::ZERO)
        .light(Light::Point { position: light, intensity: Vec3::splat(i) })
        .build();
    let (m, _) = trace(&scene, 64, 2);
    let rays = CameraRays::new(&scene.camera);
    let mut worst = 0.0f32;
    for y in 0..24 {
        for x in 0..24 {
            let (o, d) = rays.ray(x as f32 + 0.5, y as f32 + 0.5);
            let p = o + d * (-o.y / d.y);
            let to = light - p;
            let exact = rho / std::f32::consts::PI * i * (to.y / to.length()) / to.length_squared();
            worst = worst.max((m.get(x, y)[0] - exact).abs() / exact);
        }
    }
    assert!(worst < 0.01, "largest relative error {worst}");
}

#[test]
fn one_and_two_threads_give_the_same_bytes() {
    let scene = relume_tests::small_cornell();
    let accel = Accel::build(&scene, BuildQuality::Medium);
    let p = PathTrace { spp: 8, max_depth: -1, min_depth: 1, rr_depth: 5, seed: 9, fresnel_reflection: true };
    let run = |threads| {
        rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| render(&scene, &accel, &p, None).unwrap())
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.0, b.0);
    assert_eq!(a.1, b.1);
}

#[test]
fn the_scene_scale_does_not_change_the_image_from_a_thousandth_to_a_thousand() {
    // A box, a ball and a point light scaled together (intensity by scale², so irradiance is
    // unchanged): the same picture, and the self-intersection epsilon follows the scale.
    let build = |s: f32| {
        SceneBuilder::new(Vec3::new(0.0, 0.5, 3.0) * s, Vec3::ZERO, 40.0, 16, 16)
            .quad(
                "floor",
                Vec3::new(-1.0, -1.0, 1.0) * s,
                Vec3::new(2.0, 0.0, 0.0) * s,
                Vec3::new(0.0, 0.0, -2.0) * s,
                lambert(0.7),
                Vec3::ZERO,
            )
            .sphere("ball", Vec3::new(0.0, -0.5, 0.0) * s, 0.5 * s, lambert(0.5), Vec3::ZERO, false)
            .light(Light::Point { position: Vec3::new(0.5, 1.5, 0.5) * s, intensity: Vec3::splat(4.0 * s * s) })
            .build()
    };
    same_picture_at_scales(build, &[1e-3, 1e3]);
}

/// Renders `build(s)` at scale 1 and at each of `scales` and asserts the pictures agree
/// (relative L1 difference under 2 %).
fn same_picture_at_scales(build: impl Fn(f32) -> Scene, scales: &[f32]) {
    let (unit, _) = trace(&build(1.0), 16, 3);
    assert!(unit.as_floats().iter().any(|x| *x > 0.0));
    for &s in scales {
        let diff = relume_tests::relative_l1(&trace(&build(s), 16, 3).0, &unit);
        assert!(diff < 0.02, "scale {s}: relative L1 difference {diff}");
    }
}

#[test]
fn an_area_light_under_a_ceiling_lights_the_same_from_a_thousandth_to_a_thousand() {
    // A floor, a ceiling and an emitting quad a little under it, scaled together (an emitter's
    // radiance does not change with size): the same picture. Ray origins were once lifted off
    // surfaces by the scene's size times (1 + |p|), which grows with the square of the size:
    // from a hundred units across, shadow rays started far enough off the floor to miss part
    // of the light, and `cornell` at 100 and 1,000 units came out 16 % and 19 % dark.
    let build = |s: f32| {
        SceneBuilder::new(Vec3::new(0.0, 0.4, 3.0) * s, Vec3::ZERO, 40.0, 16, 16)
            .quad(
                "floor",
                Vec3::new(-1.0, -1.0, 1.0) * s,
                Vec3::new(2.0, 0.0, 0.0) * s,
                Vec3::new(0.0, 0.0, -2.0) * s,
                lambert(0.7),
                Vec3::ZERO,
            )
            .quad(
                "ceiling",
                Vec3::new(-1.0, 1.0, -1.0) * s,
                Vec3::new(2.0, 0.0, 0.0) * s,
                Vec3::new(0.0, 0.0, 2.0) * s,
                lambert(0.7),
                Vec3::ZERO,
            )
            .quad(
                "lamp",
                Vec3::new(-0.25, 0.99, -0.25) * s,
                Vec3::new(0.5, 0.0, 0.0) * s,
                Vec3::new(0.0, 0.0, 0.5) * s,
                lambert(0.0),
                Vec3::splat(8.0),
            )
            .build()
    };
    same_picture_at_scales(build, &[1e-3, 1e2, 1e3]);
}

#[test]
fn stiff_lighting_cases_give_finite_images() {
    let base = || {
        SceneBuilder::new(Vec3::new(0.0, 0.5, 3.0), Vec3::ZERO, 40.0, 12, 12).quad(
            "floor",
            Vec3::new(-1.0, -1.0, 1.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -2.0),
            lambert(0.7),
            Vec3::ZERO,
        )
    };
    // A sun 10⁴ × brighter than the sky.
    let mut texels = vec![Vec3::splat(0.2); 64 * 32];
    texels[10 * 64 + 20] = Vec3::splat(2000.0);
    let (m, _) = trace(&base().environment(Environment::Map(EnvMap::new(64, 32, texels).unwrap())).build(), 16, -1);
    assert!(m.as_floats().iter().any(|&x| x > 0.0));
    // A zero-radiance environment: black, not NaN.
    let (m, _) = trace(&base().environment(Environment::Constant(Vec3::ZERO)).build(), 4, -1);
    assert!(m.as_floats().iter().all(|&x| x == 0.0));
    // A point light inside a closed object: nothing outside is lit.
    let inside = base()
        .sphere("shell", Vec3::ZERO, 0.4, lambert(0.5), Vec3::ZERO, false)
        .light(Light::Point { position: Vec3::ZERO, intensity: Vec3::splat(100.0) })
        .build();
    let (m, _) = trace(&inside, 8, -1);
    assert!(m.as_floats().iter().all(|&x| x == 0.0), "light cannot escape a closed sphere");
    // A light exactly on a surface.
    let on = base().light(Light::Point { position: Vec3::new(0.0, -1.0, 0.0), intensity: Vec3::splat(5.0) }).build();
    trace(&on, 8, -1);
}

#[test]
fn degenerate_and_duplicated_geometry_gives_finite_images() {
    // Two coincident quads (duplicated vertices and faces) and a zero-area sliver.
    let p = vec![
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
    ];
    let tris = vec![[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 3], [4, 5, 6]];
    let scene = SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, 12, 12)
        .mesh("twice", p, None, tris, lambert(0.5), Vec3::ZERO)
        .light(Light::Point { position: Vec3::new(0.0, 0.0, 2.0), intensity: Vec3::ONE })
        .build();
    let (m, _) = trace(&scene, 8, -1);
    assert!(m.get(6, 6)[0] > 0.0);
}

#[test]
fn dielectrics_and_media_stay_finite_from_clear_glass_to_extinction_ten_thousand() {
    use relume_base::types::Medium;
    for (ior, medium) in [
        (1.0, None),
        (1.5, None),
        (2.4, None),
        (1.33, Some(Medium { sigma_a: Vec3::ZERO, sigma_s: Vec3::ZERO })),
        (1.5, Some(Medium { sigma_a: Vec3::new(0.5, 1.0, 2.0), sigma_s: Vec3::splat(2.0) })),
        (1.5, Some(Medium { sigma_a: Vec3::splat(1e4), sigma_s: Vec3::splat(1e4) })),
        (1.5, Some(Medium { sigma_a: Vec3::splat(1e4), sigma_s: Vec3::ZERO })),
    ] {
        let scene = SceneBuilder::new(Vec3::new(0.0, 0.5, 3.0), Vec3::ZERO, 40.0, 12, 12)
            .quad("floor", Vec3::new(-2.0, -1.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), lambert(0.8), Vec3::ZERO)
            .sphere("glass", Vec3::ZERO, 0.6, Material::Dielectric { ior, medium }, Vec3::ZERO, false)
            .sphere("lamp", Vec3::new(1.0, 2.0, 0.5), 0.2, lambert(0.0), Vec3::splat(50.0), false)
            .build();
        let (m, _) = trace(&scene, 16, 16);
        assert!(m.as_floats().iter().any(|&x| x > 0.0), "ior {ior}");
    }
}

#[test]
fn index_one_glass_is_invisible() {
    // A dielectric of index 1 refracts straight through: the picture equals the one without it
    // (up to the noise of the diffuse floor seen through it, same seed, same paths).
    let with = |glass: bool| {
        let mut b = SceneBuilder::new(Vec3::new(0.0, 0.5, 3.0), Vec3::ZERO, 40.0, 12, 12)
            .quad("floor", Vec3::new(-2.0, -1.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), lambert(0.8), Vec3::ZERO)
            .light(Light::Directional { direction: Vec3::new(0.3, -1.0, 0.2).normalize(), irradiance: Vec3::ONE });
        if glass {
            b = b.sphere("glass", Vec3::ZERO, 0.6, Material::Dielectric { ior: 1.0, medium: None }, Vec3::ZERO, false);
        }
        b.build()
    };
    // Direct light only through delta interfaces is not sampled by NEE (the glass blocks shadow
    // rays), so compare max_depth 1 (what the camera sees of emitters: nothing) and the
    // geometry: the floor behind the glass is still visible through it.
    let (a, _) = trace(&with(false), 4, 1);
    let (b, _) = trace(&with(true), 4, 1);
    assert_eq!(a, b);
}

#[test]
fn a_spot_light_lights_inside_its_cone_only() {
    let scene = SceneBuilder::new(Vec3::new(0.0, 3.0, 0.01), Vec3::ZERO, 60.0, 32, 32)
        .quad("floor", Vec3::new(-2.0, 0.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), lambert(0.5), Vec3::ZERO)
        .light(Light::Spot {
            position: Vec3::new(0.0, 1.0, 0.0),
            direction: -Vec3::Y,
            intensity: Vec3::splat(5.0),
            cos_inner: 20f32.to_radians().cos(),
            cos_outer: 25f32.to_radians().cos(),
        })
        .build();
    let (m, _) = trace(&scene, 4, 2);
    let rays = CameraRays::new(&scene.camera);
    for (x, y) in [(16, 16), (2, 2), (30, 16)] {
        let (o, d) = rays.ray(x as f32 + 0.5, y as f32 + 0.5);
        let p = o + d * (-o.y / d.y);
        let angle = (p.x * p.x + p.z * p.z).sqrt().atan2(1.0).to_degrees();
        let v = m.get(x, y)[0];
        if angle < 19.0 {
            assert!(v > 0.0, "inside the beam at {angle}°");
        } else if angle > 26.0 {
            assert_eq!(v, 0.0, "outside the cutoff at {angle}°");
        }
    }
}
