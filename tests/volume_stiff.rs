//! Pipeline 3 on stiff and extreme cases (docs/QUALITY.md §2, "refraction" and "geometry"; issue
//! 15): a jump of the index from 1 to 2.4 across one voxel, total internal reflection in a
//! dense sphere, extinction 0 and 10⁴ per unit through MarchPhotons and EikonalRender, and
//! the glass scene 10⁻³ and 10³ units across. Every stage is called directly (no engine), on
//! grids of at most 48³ and at most 64² photons: counts and statistics, never time.

use glam::Vec3;
use relume_base::scene::builder::SceneBuilder;
use relume_base::types::accel::BuildQuality;
use relume_base::types::{Accel, Image, Light, Material, Scene};
use relume_core::{run_standalone, CancelToken, ParamValue, RunCtx, Value};
use relume_volume::eikonal_paths;
use relume_volume::eikonal_paths::{EikonalPaths, EikonalPathsIn};
use relume_volume::eikonal_render;
use relume_volume::eikonal_render::{EikonalRender, EikonalRenderIn};
use relume_volume::emit_photons::{emit, EmitPhotons, Proxy};
use relume_volume::march_photons::MarchPhotons;
use relume_volume::octree;
use relume_volume::octree::Octree;
use relume_volume::optics::{ray_step, Integrator, Ray};
use relume_volume::types::{CausticMap, Photons, Sampler, Volume};
use relume_volume::volume_source::VolumeSource;
use relume_volume::voxelize::Voxelize;
use std::path::Path;

// ---------------------------------------------------------------------------------------
// The stages, called as the crate's own test fixtures call them (volume/test_support.rs).
// ---------------------------------------------------------------------------------------

fn f(x: f64) -> ParamValue {
    ParamValue::Float(x)
}

fn i(x: i64) -> ParamValue {
    ParamValue::Int(x)
}

fn t(s: &str) -> ParamValue {
    ParamValue::Text(s.into())
}

fn with_cx<R>(run: impl FnOnce(&RunCtx) -> R) -> R {
    let cancel = CancelToken::new();
    run(&RunCtx::new("test", &cancel, None))
}

/// The octree at the node's default thresholds.
fn octree_of(m: &Volume) -> Volume {
    octree::build(m, &Octree { uniform: 0.005, flat: 0.02, step: 8.0 }, u64::MAX).unwrap().0
}

/// The scene's BVH without object `name` (what BuildBvh's filter gives the pipeline).
fn accel_without(scene: &Scene, name: &str) -> Accel {
    let o = scene.objects.iter().position(|o| o.name == name).map_or(u32::MAX, |o| o as u32);
    Accel::build_filtered(scene, BuildQuality::Fast, |tri| scene.tri_object[tri] != o)
}

fn photons(scene: &Scene, accel: &Accel, m: &Volume, resolution: u32) -> Photons {
    with_cx(|cx| emit(scene, accel, m, &EmitPhotons { resolution, proxy: Proxy::Active, seed: 1 }, cx)).unwrap()
}

/// MarchPhotons run as a node (its defaults, the receiver `floor` at `map` texels) with the
/// scene's BVH less object `without` (the BVH is not `Clone`: built again for the node): the
/// radiance, the caustic map and the node's metrics.
fn march(scene: &Scene, without: &str, m: &Volume, oct: &Volume, ph: &Photons, map: i64) -> (Volume, CausticMap, Vec<(String, f64)>) {
    march_onto(scene, without, m, oct, ph, map, "floor")
}

/// `march` with the caustic map on `receiver` ("": none, every landed photon kept as a point).
fn march_onto(
    scene: &Scene,
    without: &str,
    m: &Volume,
    oct: &Volume,
    ph: &Photons,
    map: i64,
    receiver: &str,
) -> (Volume, CausticMap, Vec<(String, f64)>) {
    let inputs = [
        Value::new(scene.clone()),
        Value::new(accel_without(scene, without)),
        Value::new(m.clone()),
        Value::new(oct.clone()),
        Value::new(ph.clone()),
    ];
    let e = run_standalone::<MarchPhotons>(&[("receiver", t(receiver)), ("map_resolution", i(map))], Path::new("."), &inputs).unwrap();
    let radiance = e.outputs[0].get::<Volume>().unwrap().clone();
    let caustics = e.outputs[1].get::<CausticMap>().unwrap().clone();
    (radiance, caustics, e.metrics)
}

fn metric(metrics: &[(String, f64)], name: &str) -> f64 {
    metrics.iter().find(|(n, _)| n == name).unwrap_or_else(|| panic!("no metric {name} in {metrics:?}")).1
}

/// EikonalPaths and EikonalRender at their defaults through the scene's camera at `size`².
fn render(scene: &Scene, accel: &Accel, m: &Volume, oct: &Volume, radiance: &Volume, caustics: &CausticMap, size: usize) -> Image {
    let mut camera = scene.camera.clone();
    (camera.width, camera.height) = (size, size);
    let p = EikonalPaths { samples: 1, step: 1.0, adaptive: true, integrator: Integrator::Verlet };
    let paths = with_cx(|cx| eikonal_paths::trace(&EikonalPathsIn { accel, medium: m, octree: oct, camera: &camera }, &p, cx)).unwrap();
    let i = EikonalRenderIn { scene, accel, medium: m, octree: oct, radiance, caustics, paths: &paths };
    with_cx(|cx| eikonal_render::render(&i, &EikonalRender { g: 0.0, lamp_samples: 4 }, cx)).unwrap().0
}

/// A 3-channel medium (n, κ = 0, σ = 0) of `d`³ voxels over `lo … hi`, n given at each
/// voxel centre.
fn medium(d: u32, lo: Vec3, hi: Vec3, n: impl Fn(Vec3, [usize; 3]) -> f32) -> Volume {
    let mut v = Volume::try_new([d; 3], 3, lo, hi, 0.0, u64::MAX).unwrap();
    let d = d as usize;
    for z in 0..d {
        for y in 0..d {
            for x in 0..d {
                let k = v.index(x, y, z);
                let c = v.centre(x, y, z);
                v.data[k] = n(c, [x, y, z]);
            }
        }
    }
    v
}

/// Single-precision values that are neither NaN, infinite nor denormal.
fn clean(values: impl IntoIterator<Item = f32>) -> Result<(), f32> {
    values.into_iter().try_for_each(|v| if v.is_finite() && (v == 0.0 || v.abs() >= f32::MIN_POSITIVE) { Ok(()) } else { Err(v) })
}

/// The ray from `x` along unit `d` marched by `ray_step` with step `ds` (world units) until
/// `stop(x)` or `max_steps`, checking at every step that x and v are finite and that
/// |v| = n(x) within 10⁻⁴ relative. `each(x, v)` sees every point. Returns (x, v, steps).
#[allow(clippy::too_many_arguments)]
fn march_ray(
    m: &Volume,
    oct: &Volume,
    x: Vec3,
    d: Vec3,
    ds: f32,
    max_steps: usize,
    stop: impl Fn(Vec3) -> bool,
    mut each: impl FnMut(Vec3, Vec3),
) -> (Vec3, Vec3, usize) {
    let oct = &Sampler::new(oct);
    let mut r = Ray::new(oct, x, d);
    let (mut x, mut v) = (r.x, r.v);
    for k in 0..max_steps {
        r = ray_step(oct, &r, ds, Integrator::Verlet);
        (x, v) = (r.x, r.v);
        assert!(x.is_finite() && v.is_finite(), "step {k}: x = {x}, v = {v}");
        let n = m.sample(x, 0);
        assert!((v.length() - n).abs() <= 1e-4 * n, "step {k}: |v| = {} where n = {n} (x = {x})", v.length());
        each(x, v);
        if stop(x) {
            return (x, v, k + 1);
        }
    }
    (x, v, max_steps)
}

// ---------------------------------------------------------------------------------------
// 1. A jump of the index from 1 to 2.4 across one voxel.
// ---------------------------------------------------------------------------------------

/// Voxels of the jump test: n = 1 for voxel x < 24, 2.4 from 24 on (48³ over the unit cube).
/// Trilinear n ramps between the voxel centres 23.5 and 24.5 (grid units); the octree's
/// central differences are non-zero in voxels 23 and 24, so the trilinear ∇n rays see is
/// non-zero for grid x in (22.5, 25.5) and zero outside.
const JUMP_D: u32 = 48;
const JUMP_AT: usize = 24;

fn jump() -> (Volume, Volume) {
    let m = medium(JUMP_D, Vec3::ZERO, Vec3::ONE, |_, [x, _, _]| if x < JUMP_AT { 1.0 } else { 2.4 });
    let o = octree_of(&m);
    (m, o)
}

#[test]
fn a_jump_from_one_to_two_point_four_across_one_voxel_keeps_v_equal_to_n_and_refracts_by_snell() {
    let (m, oct) = jump();
    let h = m.voxel().x;
    let grid_x = |x: Vec3| x.x / h;
    // The index seen by the ray: 1 before the gradient's reach, 2.4 past it.
    assert_eq!(m.sample(Vec3::new(22.4 * h, 0.5, 0.5), 0), 1.0);
    assert_eq!(m.sample(Vec3::new(25.6 * h, 0.5, 0.5), 0), 2.4);
    // From n = 1 into n = 2.4, from grid x = 21 (1.5 voxels before ∇n starts) until past
    // 26.5 (a voxel beyond where ∇n ends), tangential along z from z = 2 voxels: at 85° the
    // ray needs about 20 voxels of z before it crosses (the medium is z-invariant anyway).
    for ds_vox in [1.0f32, 0.25] {
        for deg in [0.0f32, 30.0, 60.0, 85.0] {
            let (s, c) = deg.to_radians().sin_cos();
            let d = Vec3::new(c, 0.0, s);
            let x0 = Vec3::new(21.0 * h, 0.5, 2.0 * h);
            let mut min_vx = f32::INFINITY;
            let mut min_x = f32::INFINITY;
            let (x, v, steps) = march_ray(
                &m,
                &oct,
                x0,
                d,
                ds_vox * h,
                4000,
                |x| grid_x(x) > 26.5,
                |x, v| {
                    min_vx = min_vx.min(v.x);
                    min_x = min_x.min(grid_x(x));
                    assert_eq!(x.y, 0.5, "the ray stays in its plane");
                    assert!(m.contains(x), "the ray left the box at {x} ({deg}°, {ds_vox} voxel)");
                },
            );
            let what = format!("{deg}° incidence, step {ds_vox} voxel: {steps} steps, ends at grid x {} with v = {v}", grid_x(x));
            assert!(grid_x(x) > 26.5, "did not cross: {what}");
            // Light going into the denser side bends toward the normal: never turns back.
            assert!(min_vx > 0.0 && min_x >= 21.0, "turned back (v_x down to {min_vx}, x down to {min_x}): {what}");
            let sin_t = v.z / v.length();
            let sin_i = s;
            if deg == 0.0 {
                assert_eq!(v.z, 0.0, "normal incidence stays normal: {what}");
                assert!((v.x - 2.4).abs() < 1e-5, "{what}");
            } else {
                // Toward the normal, but not past it.
                assert!(sin_t > 0.0 && sin_t < sin_i, "sin θt = {sin_t} (sin θi = {sin_i}): {what}");
            }
            if deg == 30.0 {
                // Snell: sin θt = sin 30° / 2.4 = 0.2083. The ray sees ∇n (central
                // differences, trilinear) over three voxels while n itself ramps over one,
                // and |v| is reset to n(x) at every step: where ∇n is non-zero but n is still
                // 1 the reset takes tangential momentum away. That bias and the step's error
                // (measured with Verlet steps: 0.187 at one-voxel steps, 0.195 at quarter-voxel;
                // −0.03 … −0.02 at 60° and −0.08 … −0.03 at 85°, not asserted) stay under 0.05
                // in sin at 30°, which still tells Snell (0.208) from no refraction (0.5) or
                // a wrong ratio such as 1/1.5 (0.333).
                let snell = sin_i / 2.4;
                assert!((sin_t - snell).abs() < 0.05, "sin θt = {sin_t}, Snell {snell}: {what}");
            }
            eprintln!("jump 1 → 2.4: {what}; sin θt = {sin_t:.4} vs Snell {:.4}", sin_i / 2.4);
        }
        // From n = 2.4 out into n = 1, from grid x = 27 heading −x: at 0° and 20° it crosses
        // (sin θt = 2.4 sin 20° = 0.82 < 1) and never turns back.
        for deg in [0.0f32, 20.0] {
            let (s, c) = deg.to_radians().sin_cos();
            let d = Vec3::new(-c, 0.0, s);
            let x0 = Vec3::new(27.0 * h, 0.5, 2.0 * h);
            let mut max_vx = f32::NEG_INFINITY;
            let (x, v, steps) = march_ray(
                &m,
                &oct,
                x0,
                d,
                ds_vox * h,
                4000,
                |x| grid_x(x) < 21.5,
                |x, v| {
                    max_vx = max_vx.max(v.x);
                    assert!(m.contains(x), "the ray left the box at {x}");
                },
            );
            let what = format!("2.4 → 1 at {deg}°, step {ds_vox} voxel: {steps} steps, ends at grid x {} with v = {v}", grid_x(x));
            assert!(grid_x(x) < 21.5 && max_vx < 0.0, "did not cross or turned back (v_x up to {max_vx}): {what}");
            if deg == 0.0 {
                assert_eq!(v.z, 0.0, "{what}");
                assert!((v.x + 1.0).abs() < 1e-5, "{what}");
            }
            eprintln!("jump 2.4 → 1: {what}; sin θt = {:.4} vs Snell {:.4}", v.z / v.length(), (2.4 * s).min(1.0));
        }
        // At 60° from the dense side (beyond the critical angle 24.6°) it comes back: it
        // ends on the dense side heading away from the interface.
        let (s, c) = 60f32.to_radians().sin_cos();
        let x0 = Vec3::new(27.0 * h, 0.5, 2.0 * h);
        let mut min_x = f32::INFINITY;
        let (x, v, steps) = march_ray(
            &m,
            &oct,
            x0,
            Vec3::new(-c, 0.0, s),
            ds_vox * h,
            4000,
            |x| grid_x(x) > 27.5 || grid_x(x) < 21.5,
            |x, _| {
                min_x = min_x.min(grid_x(x));
                assert!(m.contains(x), "the ray left the box at {x}");
            },
        );
        let what = format!("2.4 → 1 at 60°, step {ds_vox} voxel: {steps} steps, ends at grid x {} with v = {v}", grid_x(x));
        eprintln!("{what}; deepest grid x {min_x}");
        assert!(grid_x(x) > 27.5 && v.x > 0.0, "not reflected: {what}");
    }
}

// ---------------------------------------------------------------------------------------
// 2. Total internal reflection inside a dense sphere.
// ---------------------------------------------------------------------------------------

/// n = 2.4 inside a sphere of radius 0.7 at the centre of a 48³ grid over [−1, 1]³, falling
/// linearly to 1 over two voxels centred on the surface (n = 1 + 1.4 · clamp((R + h − r) /
/// 2h, 0, 1)).
const SPHERE_R: f32 = 0.7;

fn dense_sphere() -> (Volume, Volume) {
    let h = 2.0 / 48.0;
    let m = medium(48, Vec3::splat(-1.0), Vec3::ONE, |c, _| 1.0 + 1.4 * ((SPHERE_R + h - c.length()) / (2.0 * h)).clamp(0.0, 1.0));
    let o = octree_of(&m);
    (m, o)
}

/// A ray started inside at distance R − 3 voxels from the centre (where n = 2.4 and ∇n = 0)
/// heading outward at `deg` to the local normal, marched `steps` steps of `ds_vox` voxels (or
/// until it is 1.5 from the centre): the largest distance from the centre, in voxels past R,
/// and the ray's angular momentum |x × v| (conserved by the ray equation in a spherically
/// symmetric index) at the start and the end.
fn tir_ray(m: &Volume, oct: &Volume, deg: f32, ds_vox: f32, steps: usize) -> (f32, f32, f32, usize) {
    let h = m.voxel().x;
    // z = 0 lies between two voxel planes symmetric about it: the ray stays in it.
    let x0 = Vec3::new(0.0, SPHERE_R - 3.0 * h, 0.0);
    let (s, c) = deg.to_radians().sin_cos();
    let d = Vec3::new(s, c, 0.0);
    let l0 = x0.cross(d * m.sample(x0, 0)).length();
    let mut far = 0.0f32;
    let (x, v, n) = march_ray(m, oct, x0, d, ds_vox * h, steps, |x| x.length() > 1.5, |x, _| far = far.max(x.length()));
    (((far - SPHERE_R) / h), l0, x.cross(v).length(), n)
}

/// Shared by the two step sizes: the ray at 70° (beyond the critical angle asin(1/2.4) =
/// 24.6°: it meets the surface at about 50°) stays within R + 3 voxels — the ramp is two voxels
/// wide and ∇n reaches a voxel and a half beyond R, so a reflected ray turns within R + 2.5 —
/// over 600 steps (several bounces), and the ray at 10° (meeting the surface at 8°) leaves.
fn total_internal_reflection(ds_vox: f32) {
    let (m, oct) = dense_sphere();
    let (past, l0, l1, steps) = tir_ray(&m, &oct, 70.0, ds_vox, 600);
    eprintln!(
        "TIR, step {ds_vox} voxel, 70°: reaches R + {past:.2} voxels in {steps} steps; angular momentum |x × v| {l0:.3} → {l1:.3} (R · 1 = {SPHERE_R}: below it the ray can leave)"
    );
    assert!(past <= 3.0, "the ray at 70° got out to R + {past} voxels (|x × v| {l0} → {l1}, {steps} steps)");
    let (past, l0, l1, steps) = tir_ray(&m, &oct, 10.0, ds_vox, 600);
    eprintln!("TIR, step {ds_vox} voxel, 10°: reaches R + {past:.2} voxels in {steps} steps; |x × v| {l0:.3} → {l1:.3}");
    assert!(past > 6.0, "the ray at 10° should leave the sphere: R + {past} voxels");
}

#[test]
fn total_internal_reflection_keeps_a_ray_inside_a_dense_sphere_at_quarter_voxel_steps() {
    total_internal_reflection(0.25);
}

#[test]
fn total_internal_reflection_keeps_a_ray_inside_a_dense_sphere_at_one_voxel_steps() {
    // One voxel is MarchPhotons' default `min_step`: the step photons take at the interface.
    // Fails (pipeline 3 as landed): the ray at 70° reaches R + 19 voxels (it left) after
    // 110 steps, its angular momentum |x × v| falling 1.297 → 0.715 (per bounce 1.85 R →
    // 1.40 R → 1.10 R → 0.85 R; below R · n_outside = R it can leave). Where ∇n (central
    // differences, wider than the ramp of n) is non-zero but n(x′) is already small, the
    // reset |v′| = n(x′) shrinks the tangential part of v, which the ray equation keeps. At
    // quarter-voxel steps the same ray escapes after 914 steps, at 0.1 voxel a 50° ray after
    // 4676: finer steps delay the leak, they do not remove it.
    total_internal_reflection(1.0);
}

// ---------------------------------------------------------------------------------------
// 3. Extinction 0 and 10⁴ per unit through MarchPhotons and EikonalRender.
// ---------------------------------------------------------------------------------------

#[test]
fn extinction_zero_and_ten_thousand_give_clean_numbers_through_marching_and_rendering() {
    let grey = Material::Lambert { albedo: Vec3::splat(0.5) };
    let irradiance = 1.0;
    let s = SceneBuilder::new(Vec3::new(0.0, 1.5, 3.0), Vec3::new(0.0, -0.3, 0.0), 40.0, 24, 24)
        .quad("floor", Vec3::new(-2.0, -1.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), grey, Vec3::ZERO)
        .light(Light::Directional { direction: Vec3::new(0.0, -1.0, 0.0), irradiance: Vec3::splat(irradiance) })
        .build();
    let a = accel_without(&s, "");
    let (radius, size, res) = (0.5f32, 2.0f32, 24i64);
    for kappa in [0.0, 1e4] {
        let params = [
            ("kind", ParamValue::Ident("GrinSphere".into())),
            ("resolution", i(res)),
            ("centre", ParamValue::Tuple(vec![f(0.0), f(0.0), f(0.0)])),
            ("size", f(size as f64)),
            ("radius", f(radius as f64)),
            ("index", f(1.5)),
            ("extinction", f(kappa)),
            ("scattering", f(kappa / 2.0)),
        ];
        let m = run_standalone::<VolumeSource>(&params, Path::new("."), &[]).unwrap().outputs[0].get::<Volume>().unwrap().clone();
        let oct = octree_of(&m);
        let ph = photons(&s, &a, &m, 64);
        // A directional light covers the active box's bounding sphere with 64² texels: a third of
        // them meet the box.
        assert!(ph.len() > 1000, "{} photons", ph.len());
        let (r, map, metrics) = march(&s, "", &m, &oct, &ph, 32);
        let img = render(&s, &a, &m, &oct, &r, &map, 24);
        let what = format!("κ = {kappa}");
        clean(r.data.iter().copied()).unwrap_or_else(|v| panic!("radiance holds {v:e} ({what})"));
        clean(map.texels.iter().flat_map(|t| t.to_array())).unwrap_or_else(|v| panic!("caustic map holds {v:e} ({what})"));
        clean(img.pixels.iter().flatten().copied()).unwrap_or_else(|v| panic!("image holds {v:e} ({what})"));
        assert!(metrics.iter().all(|(_, v)| v.is_finite()), "{metrics:?}");
        // The floor, lit (directly or as caustics) in most of the picture's lower half.
        let lit = img.pixels[12 * 24..].iter().filter(|p| p[0] > 0.0).count();
        assert!(lit > 6 * 24, "{lit} lit pixels in the lower half ({what})");
        let emitted = ph.total_power().x as f64;
        // The power the caustic map holds (W/unit² × texel area): some of what was emitted.
        let landed: f64 = map.texels.iter().map(|t| t.x as f64).sum::<f64>() * map.texel_area() as f64;
        if kappa == 0.0 {
            assert_eq!(r.dims, [1; 3], "nothing scatters: one empty voxel");
            assert!(landed > 0.5 * emitted && landed <= 1.001 * emitted, "caustic power {landed} of {emitted} emitted");
            eprintln!("κ = 0: caustic power {landed:.4} of {emitted:.4} emitted; metrics {metrics:?}");
            continue;
        }
        assert_eq!(r.dims, m.dims);
        // 7/κ = 0.0007 units (0.008 voxel) takes a photon below the 1/1000 cutoff, and e^−κΔs
        // over one voxel is e^−833 = 0 in f32: nothing reaches 3 voxels in, even after the
        // 3³ blur.
        let h = m.voxel().x;
        let mut deep = 0;
        for z in 0..res as usize {
            for y in 0..res as usize {
                for x in 0..res as usize {
                    if m.centre(x, y, z).length() < radius - 3.0 * h {
                        deep += 1;
                        let k = r.index(x, y, z);
                        assert_eq!(&r.data[k..k + 6], &[0.0; 6], "voxel ({x}, {y}, {z}), deep inside");
                    }
                }
            }
        }
        assert!(deep >= 20, "{deep} deep voxels");
        // Energy: the power absorbed is κ × fluence × voxel volume summed (each deposit is
        // power × (1 − e^−κl) / κ; the blur keeps sums away from the faces). It never exceeds
        // what was emitted, and is at least what the photons counted absorbed lost (each of
        // them ≥ 99.9 % of its power, all photons of a directional light carrying the same).
        let voxel_volume = (h as f64).powi(3);
        let absorbed = kappa * voxel_volume * r.data.chunks(6).map(|c| c[0] as f64).sum::<f64>();
        let counted = metric(&metrics, "absorbed_pct") / 100.0 * emitted;
        eprintln!(
            "κ = 10⁴: absorbed {absorbed:.5} and landed {landed:.5} of {emitted:.5} emitted, photons counted absorbed carried {counted:.5}; metrics {metrics:?}"
        );
        assert!(absorbed + landed <= 1.001 * emitted, "absorbed {absorbed} + landed {landed} > emitted {emitted}");
        assert!(absorbed >= 0.998 * counted && counted > 0.3 * emitted, "absorbed {absorbed}, counted {counted}, emitted {emitted}");
    }
}

// ---------------------------------------------------------------------------------------
// 4. The glass scene 10⁻³ and 10³ units across.
// ---------------------------------------------------------------------------------------

/// A glass sphere (ior 1.5) over a floor under a point light, all lengths × `s` and the
/// intensity × s² (irradiance unchanged), seen from a camera scaled likewise.
fn glass_scene(s: f32) -> Scene {
    let floor = Material::Lambert { albedo: Vec3::splat(0.8) };
    SceneBuilder::new(Vec3::new(0.0, 1.6, 2.6) * s, Vec3::new(0.0, 0.35, 0.0) * s, 40.0, 24, 24)
        .quad("floor", Vec3::new(-2.0, 0.0, 2.0) * s, Vec3::new(4.0, 0.0, 0.0) * s, Vec3::new(0.0, 0.0, -4.0) * s, floor, Vec3::ZERO)
        .sphere("glass", Vec3::new(0.0, 0.6, 0.0) * s, 0.5 * s, Material::Dielectric { ior: 1.5, medium: None }, Vec3::ZERO, false)
        .light(Light::Point { position: Vec3::new(1.5, 3.0, 0.5) * s, intensity: Vec3::splat(5.0 * s * s) })
        .build()
}

/// The glass scene at scale `s` through voxelisation (32), the octree, photons (512²),
/// marching onto `receiver`'s map (or, "", as landed points) and the render (24²): the image
/// and MarchPhotons' metrics.
fn glass_at_scale(s: f32, receiver: &str) -> (Image, Vec<(String, f64)>) {
    let scene = glass_scene(s);
    let out =
        run_standalone::<Voxelize>(&[("object", t("glass")), ("resolution", i(32))], Path::new("."), &[Value::new(scene.clone())]).unwrap();
    let m = out.outputs[0].get::<Volume>().unwrap().clone();
    let oct = octree_of(&m);
    let a = accel_without(&scene, "glass");
    let ph = photons(&scene, &a, &m, 512);
    let (r, map, metrics) = march_onto(&scene, "glass", &m, &oct, &ph, 64, receiver);
    let img = render(&scene, &a, &m, &oct, &r, &map, 24);
    (img, metrics)
}

#[test]
fn the_glass_scene_a_thousandth_and_a_thousand_units_across_gives_the_same_picture() {
    // This found two bugs, both fixed: obvhs skipped boxes ending within 10⁻⁴ (absolute) of
    // a ray's origin, so at s = 10⁻³ the marcher's look-ahead never found the floor (landed
    // 30.9 % of the photons against 71.5 %; `Accel` now scales coordinates by a power of
    // two); and shadow rays left surfaces by an offset growing as s² (`Surface::spawn`'s
    // offset × a scene-relative ε), lifting them about 3 voxels at s = 10³.
    for receiver in ["floor", ""] {
        same_glass_at_scales(receiver);
    }
}

/// The glass scene at 10⁻³ and 10³ against 1, its caustic on `receiver`'s map or ("") as
/// landed points.
fn same_glass_at_scales(receiver: &str) {
    let (reference, ref_metrics) = glass_at_scale(1.0, receiver);
    assert_eq!(reference.nonfinite_pixels(), 0);
    let lum = |p: &[f32; 3]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    let top = reference.pixels.iter().map(lum).fold(0.0f32, f32::max);
    assert!(top > 0.0, "a black reference");
    let landed = metric(&ref_metrics, "landed_pct");
    assert!(landed > 10.0, "{ref_metrics:?}");
    let mut failures = Vec::new();
    for s in [1e-3f32, 1e3] {
        let (img, metrics) = glass_at_scale(s, receiver);
        assert_eq!(img.nonfinite_pixels(), 0, "scale {s}");
        // Per pixel, on the pixels above 1 % of the brightest: the largest relative difference
        // of any channel.
        let (mut worst, mut at, mut compared) = (0.0f32, 0, 0);
        for (k, (a, b)) in reference.pixels.iter().zip(&img.pixels).enumerate() {
            if lum(a) < 0.01 * top {
                continue;
            }
            compared += 1;
            for c in 0..3 {
                let d = (a[c] - b[c]).abs() / a[c].max(0.01 * top);
                if d > worst {
                    (worst, at) = (d, k);
                }
            }
        }
        let over = |limit: f32| {
            reference
                .pixels
                .iter()
                .zip(&img.pixels)
                .filter(|(a, b)| lum(a) >= 0.01 * top && (lum(a) - lum(b)).abs() > limit * lum(a))
                .count()
        };
        let dark_gone_bright = reference.pixels.iter().zip(&img.pixels).filter(|(a, b)| lum(a) < 0.01 * top && lum(b) > 0.02 * top).count();
        let other = metric(&metrics, "landed_pct");
        let sum = |im: &Image| im.pixels.iter().map(lum).sum::<f32>();
        let (total, ref_total) = (sum(&img), sum(&reference));
        let line = format!(
            "receiver \"{receiver}\", scale {s}: sum {total} vs {ref_total}; {compared} pixels compared, max relative difference {worst:.4} at pixel {at} ({:?} vs {:?}), {} pixels off by > 3 %, {} by > 30 %; landed {other:.3} % vs {landed:.3} %; dark pixels gone bright {dark_gone_bright}; metrics {metrics:?}",
            reference.pixels[at],
            img.pixels[at],
            over(0.03),
            over(0.3)
        );
        eprintln!("{line}");
        assert!(compared > 200, "{compared}");
        // The scene is the same up to f32 rounding of positions × s, which can move a photon's
        // steps by an ulp and so, rarely, a photon into the next caustic texel; and a camera
        // ray caught by total internal reflection near the sphere's rim (pixel 149 here runs
        // 150 steps round the inside) is chaotic: an ulp at the start sends it out anywhere.
        // So a statistic, not every pixel — at most 2 % of the pixels off by more than 3 %, at
        // most one by 30 % and one dark pixel gone bright (that ray), the picture's sum within 1 %.
        let mut ok = over(0.03) * 50 <= compared
            && over(0.3) <= 1
            && dark_gone_bright <= 1
            && (other - landed).abs() < 0.5
            && (total - ref_total).abs() <= 0.01 * ref_total;
        for name in ["photons", "left_pct", "absorbed_pct", "straight_pct"] {
            let (x, y) = (metric(&metrics, name), metric(&ref_metrics, name));
            ok &= (x - y).abs() <= 0.01 * y.abs().max(1.0);
        }
        if !ok {
            failures.push(line);
        }
    }
    eprintln!("scale 1: metrics {ref_metrics:?}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
