//! Pipeline 3 on the glass scene at 128³ with about 68 K photons (EmitPhotons at 384²: the
//! thesis' table 6-1 setting, 35 K – 185 K photons at 128³): each stage alone, the photon
//! march with the octree's adaptive steps against fixed steps, each at 1, 3/4 and 1/2 voxel (so
//! that the time ratio is read at equal error), the render with
//! and without the octree's steps, and each kind of edit through the engine at 256² (the
//! image only: the reference is not asked for). Setup prints the photon steps and the error
//! of each march's caustic map against a fine one (fixed quarter-voxel steps).
//! `cargo bench -p relume-benches --bench refract`.

use relume_base::types::{Accel, Scene};
use relume_benches::{add_output, bench_graph, sized};
use relume_core::{shard::run_all, CancelToken, Engine, Graph, RunCtx, RunOptions};
use relume_volume::eikonal_paths::{trace, EikonalPaths, EikonalPathsIn};
use relume_volume::eikonal_render::{render, EikonalRender, EikonalRenderIn};
use relume_volume::emit_photons::{emit, EmitPhotons, Proxy};
use relume_volume::march_photons::{MarchPhotons, MarchPhotonsIn};
use relume_volume::octree::{build, Octree};
use relume_volume::optics::Integrator;
use relume_volume::types::{CausticMap, Photons, ViewPaths, Volume};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

fn main() {
    divan::main();
}

struct Stages {
    scene: Scene,
    /// The BVH without the sphere (a `Value`: an `Accel` is not `Clone`).
    accel_value: relume_core::Value,
    medium: Volume,
    octree: Volume,
    fixed: Volume,
    photons: Photons,
    radiance: Volume,
    caustics: CausticMap,
}

impl Stages {
    fn accel(&self) -> &Accel {
        self.accel_value.get::<Accel>().expect("an Accel")
    }
}

fn cx<R>(f: impl FnOnce(&RunCtx) -> R) -> R {
    let cancel = CancelToken::new();
    f(&RunCtx::new("bench", &cancel, None))
}

fn march_params() -> MarchPhotons {
    MarchPhotons {
        min_step: 1.0,
        integrator: Integrator::Verlet,
        cutoff: 0.001,
        stop_fraction: 0.001,
        max_steps: 20000,
        receiver: "floor".into(),
        map_resolution: 256,
        blur_sigma: 1.0,
        map_blur: 1,
        surface_radius: 4.0,
    }
}

fn march(s: &Stages, octree: &Volume, p: &MarchPhotons) -> (Volume, CausticMap) {
    let i = MarchPhotonsIn { scene: &s.scene, accel: s.accel(), medium: &s.medium, octree, photons: &s.photons };
    let out = cx(|c| run_all(p, &i, c)).unwrap();
    (out.radiance, out.caustics)
}

/// The march through the node (for its report): outputs and photon steps.
fn march_counted(s: &Stages, octree: &Volume, min_step: f64) -> (Volume, CausticMap, u64) {
    use relume_core::{ParamValue, Value};
    let inputs = [
        Value::new(s.scene.clone()),
        s.accel_value.clone(),
        Value::new(s.medium.clone()),
        Value::new(octree.clone()),
        Value::new(s.photons.clone()),
    ];
    let params = [("min_step", ParamValue::Float(min_step)), ("map_resolution", ParamValue::Int(256))];
    let e = relume_core::run_standalone::<MarchPhotons>(&params, std::path::Path::new("."), &inputs).unwrap();
    let steps = e.metrics.iter().find(|m| m.0 == "photon_steps").map_or(0, |m| m.1 as u64);
    (e.outputs[0].get::<Volume>().unwrap().clone(), e.outputs[1].get::<CausticMap>().unwrap().clone(), steps)
}

/// Relative L2 difference of two caustic maps.
fn map_error(a: &CausticMap, reference: &CausticMap) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (x, r) in a.texels.iter().zip(&reference.texels) {
        num += (*x - *r).length_squared() as f64;
        den += r.length_squared() as f64;
    }
    (num / den.max(f64::MIN_POSITIVE)).sqrt()
}

fn stages() -> &'static Stages {
    static S: OnceLock<Stages> = OnceLock::new();
    S.get_or_init(|| {
        let reg = relume_cli::registry();
        let mut g = bench_graph("refract_glass.ron");
        add_output(&mut g, "scene", "light.scene");
        add_output(&mut g, "accel", "bvh.accel");
        add_output(&mut g, "medium", "paint.medium");
        add_output(&mut g, "octree", "octree.octree");
        let outputs = ["scene", "accel", "medium", "octree"].map(String::from).to_vec();
        let r = Engine::new(reg).run(&g, &RunOptions { outputs: Some(outputs), ..Default::default() }).unwrap();
        let get = |n: &str| r.output(n).unwrap();
        let scene = get("scene").get::<Scene>().unwrap().clone();
        let accel_value = get("accel").clone();
        let accel = accel_value.get::<Accel>().unwrap();
        let medium = get("medium").get::<Volume>().unwrap().clone();
        let octree = get("octree").get::<Volume>().unwrap().clone();
        // ε = ε′ = 0: every voxel takes the minimum step.
        let fixed = build(&medium, &Octree { uniform: 0.0, flat: 0.0, step: 8.0 }, u64::MAX).unwrap().0;
        let photons =
            cx(|c| emit(&scene, accel, &medium, &EmitPhotons { resolution: sized(384, 64), proxy: Proxy::Active, seed: 1 }, c)).unwrap();
        let mut s = Stages {
            scene,
            accel_value,
            medium,
            octree,
            fixed,
            photons,
            radiance: Volume::try_new([1; 3], 6, glam::Vec3::ZERO, glam::Vec3::ONE, 0.0, u64::MAX).unwrap(),
            caustics: CausticMap::none(),
        };
        let (radiance, caustics, _) = march_counted(&s, &s.octree, 1.0);
        let (_, fine, fine_steps) = march_counted(&s, &s.fixed, 0.25);
        let mut line = format!("{} photons; caustic-map error against a fixed 1/4-voxel march ({fine_steps} steps):", s.photons.len());
        for (name, octree) in [("adaptive", &s.octree), ("fixed", &s.fixed)] {
            for step in MIN_STEPS {
                let (_, map, n) = march_counted(&s, octree, *step);
                line += &format!(" {name} {step} voxel {:.2} % in {n} steps;", 100.0 * map_error(&map, &fine));
            }
        }
        eprintln!("{line}");
        (s.radiance, s.caustics) = (radiance, caustics);
        s
    })
}

#[divan::bench(sample_count = 10)]
fn emit_photons_384(bencher: divan::Bencher) {
    let s = stages();
    bencher.bench(|| {
        cx(|c| emit(&s.scene, s.accel(), &s.medium, &EmitPhotons { resolution: sized(384, 64), proxy: Proxy::Active, seed: 1 }, c)).unwrap()
    });
}

/// Minimum (adaptive) or only (fixed) steps in voxels, so that the two are compared at equal
/// error.
const MIN_STEPS: &[f64] = &[1.0, 0.75, 0.5];

#[divan::bench(args = MIN_STEPS, sample_count = 10)]
fn march_adaptive(bencher: divan::Bencher, step: f64) {
    let s = stages();
    let p = MarchPhotons { min_step: step as f32, ..march_params() };
    bencher.bench(|| march(s, &s.octree, &p));
}

#[divan::bench(args = MIN_STEPS, sample_count = 5)]
fn march_fixed(bencher: divan::Bencher, step: f64) {
    let s = stages();
    let p = MarchPhotons { min_step: step as f32, ..march_params() };
    bencher.bench(|| march(s, &s.fixed, &p));
}

fn camera_256(s: &Stages) -> relume_base::types::Camera {
    let mut camera = s.scene.camera.clone();
    (camera.width, camera.height) = (sized(256, 32), sized(256, 32));
    camera
}

fn paths_256(s: &Stages, octree: &Volume, adaptive: bool) -> ViewPaths {
    let camera = camera_256(s);
    let i = EikonalPathsIn { accel: s.accel(), medium: &s.medium, octree, camera: &camera };
    cx(|c| trace(&i, &EikonalPaths { samples: 1, step: 1.0, adaptive, integrator: Integrator::Verlet }, c)).unwrap()
}

fn shade_256(s: &Stages, paths: &ViewPaths) -> relume_base::types::Image {
    let i = EikonalRenderIn {
        scene: &s.scene,
        accel: s.accel(),
        medium: &s.medium,
        octree: &s.octree,
        radiance: &s.radiance,
        caustics: &s.caustics,
        paths,
    };
    cx(|c| render(&i, &EikonalRender { g: 0.0, lamp_samples: 4 }, c)).unwrap().0
}

fn render_256(s: &Stages, octree: &Volume, adaptive: bool) -> relume_base::types::Image {
    shade_256(s, &paths_256(s, octree, adaptive))
}

/// The shading alone (what a light edit re-runs of the render).
#[divan::bench(sample_count = 10)]
fn shade_256_only(bencher: divan::Bencher) {
    let s = stages();
    let paths = paths_256(s, &s.octree, true);
    bencher.bench(|| shade_256(s, &paths));
}

#[divan::bench(sample_count = 10)]
fn render_256_adaptive(bencher: divan::Bencher) {
    let s = stages();
    bencher.bench(|| render_256(s, &s.octree, true));
}

#[divan::bench(sample_count = 5)]
fn render_256_fixed(bencher: divan::Bencher) {
    let s = stages();
    bencher.bench(|| render_256(s, &s.octree, false));
}

/// refract_glass.ron at 256², one ray a pixel, asking for the image only.
fn edit_graph() -> Graph {
    edit_graph_of("refract_glass.ron")
}

/// `name` at 256², one camera ray a pixel.
fn edit_graph_of(name: &str) -> Graph {
    let reg = relume_cli::registry();
    let mut g = bench_graph(name);
    for (k, v) in [("scene.width", sized("256", "32")), ("scene.height", sized("256", "32")), ("paths.samples", "1")] {
        g.set_param_text(&reg, k, v).unwrap();
    }
    g
}

const EDITS: &[&str] = &["light.translation", "paint.weight", "camera.azimuth"];

/// Untimed edits of a kind before its timed ones: until the memory cache holds its latest
/// results of each node (`RESULTS_PER_NODE`), an edit's outputs land on fresh pages, which
/// the kernel zeroes (a deformation edit's first eight ran up to 1.5× the steady state).
const WARM_EDITS: u64 = 12;

#[divan::bench(args = EDITS, sample_count = 10, sample_size = 1)]
fn edit_256(bencher: divan::Bencher, param: &str) {
    let mut g = edit_graph();
    let e = Engine::new(relume_cli::registry());
    let opts = RunOptions { outputs: Some(vec!["image".into()]), ..Default::default() };
    e.run(&g, &opts).unwrap();
    let k = AtomicU64::new(1);
    let value = |x: f64| match param {
        "light.translation" => format!("({x}, 0, 0)"),
        "paint.weight" => format!("{}", 0.01 + x),
        _ => format!("{}", x * 100.0),
    };
    for i in 0..WARM_EDITS {
        g.set_param_text(e.registry(), param, &value(-1e-4 * (i + 1) as f64)).unwrap();
        e.run(&g, &opts).unwrap();
    }
    bencher.bench_local(|| {
        let x = k.fetch_add(1, Ordering::Relaxed) as f64 * 1e-4;
        g.set_param_text(e.registry(), param, &value(x)).unwrap();
        e.run(&g, &opts).unwrap().report.ran
    });
}

/// The deformation edit ([S] table 6-1's geometry edit): `refract_deform.ron`'s bend changed,
/// which re-runs everything from the deformed mesh on (the image only).
#[divan::bench(sample_count = 10, sample_size = 1)]
fn edit_256_deform(bencher: divan::Bencher) {
    let mut g = edit_graph_of("refract_deform.ron");
    let e = Engine::new(relume_cli::registry());
    let opts = RunOptions { outputs: Some(vec!["image".into()]), ..Default::default() };
    e.run(&g, &opts).unwrap();
    for i in 0..WARM_EDITS {
        g.set_param_text(e.registry(), "deform.amount", &format!("{}", 40.0 - (i + 1) as f64 * 1e-3)).unwrap();
        e.run(&g, &opts).unwrap();
    }
    let k = AtomicU64::new(1);
    bencher.bench_local(|| {
        let v = format!("{}", 40.0 + k.fetch_add(1, Ordering::Relaxed) as f64 * 1e-3);
        g.set_param_text(e.registry(), "deform.amount", &v).unwrap();
        e.run(&g, &opts).unwrap().report.ran
    });
}
