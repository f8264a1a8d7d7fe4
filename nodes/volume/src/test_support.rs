//! Fixtures for pipeline 3's unit tests: the `glass` scene and the stages between it and a
//! picture, called directly (no engine), small enough for debug builds.

use super::eikonal_paths::{self, EikonalPaths, EikonalPathsIn};
use super::eikonal_render::{self, EikonalRender, EikonalRenderIn};
use super::emit_photons::{emit, EmitPhotons, Proxy};
use super::march_photons::MarchPhotons;
use super::octree::{self, Octree};
use super::voxelize::Voxelize;
use crate::types::{CausticMap, Photons, ViewPaths, Volume};
use relume_base::testing::{i, run_on, t};
use relume_base::types::accel::BuildQuality;
use relume_base::types::{Accel, Camera, Image, Scene};
use relume_core::{CancelToken, RunCtx, Value};

/// The canonical `glass` scene (graphs/scenes/glass.ron).
pub fn glass() -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../graphs/scenes/glass.ron");
    relume_base::scene::format::load_scene_file(&path).expect("the glass scene").scene
}

/// Runs `f` with a run context of its own.
pub fn with_cx<R>(f: impl FnOnce(&RunCtx) -> R) -> R {
    let cancel = CancelToken::new();
    f(&RunCtx::new("test", &cancel, None))
}

/// The object `name` voxelised at `resolution` (blur 7³, σ 1).
pub fn voxelize(scene: &Scene, name: &str, resolution: i64) -> Volume {
    let out = run_on::<Voxelize>(&[("object", t(name)), ("resolution", i(resolution))], vec![Value::new(scene.clone())]).unwrap();
    out[0].get::<Volume>().unwrap().clone()
}

/// The octree of `m` at the default thresholds.
pub fn octree_of(m: &Volume) -> Volume {
    octree::build(m, &Octree { uniform: 0.005, flat: 0.02, step: 8.0 }, u64::MAX).unwrap().0
}

/// The scene's BVH without object `name`.
pub fn accel_without(scene: &Scene, name: &str) -> Accel {
    let o = scene.objects.iter().position(|o| o.name == name).map_or(u32::MAX, |o| o as u32);
    Accel::build_filtered(scene, BuildQuality::Fast, |tri| scene.tri_object[tri] != o)
}

/// Photons at `resolution`² from every light of `scene` into `m`.
pub fn photons(scene: &Scene, accel: &Accel, m: &Volume, resolution: u32, proxy: Proxy) -> Photons {
    with_cx(|cx| emit(scene, accel, m, &EmitPhotons { resolution, proxy, seed: 1 }, cx)).unwrap()
}

/// The glass scene with its sphere voxelised at `resolution`, the octree, the BVH without the
/// sphere and photons at `photon_resolution`² into the active box.
pub fn glass_stages(resolution: i64, photon_resolution: u32) -> (Scene, Volume, Volume, Accel, Photons) {
    let s = glass();
    let m = voxelize(&s, "glass", resolution);
    let oct = octree_of(&m);
    let a = accel_without(&s, "glass");
    let ph = photons(&s, &a, &m, photon_resolution, Proxy::Active);
    (s, m, oct, a, ph)
}

/// MarchPhotons' defaults, with the receiver `floor` at `map` texels.
pub fn march_params(map: u32) -> MarchPhotons {
    MarchPhotons {
        min_step: 1.0,
        integrator: super::optics::Integrator::Verlet,
        cutoff: 0.001,
        stop_fraction: 0.001,
        max_steps: 20000,
        receiver: "floor".into(),
        map_resolution: map,
        blur_sigma: 1.0,
        map_blur: 1,
        surface_radius: 4.0,
    }
}

/// The photons marched: radiance and caustic map.
pub fn march(scene: &Scene, accel: &Accel, m: &Volume, oct: &Volume, ph: &Photons, p: &MarchPhotons) -> (Volume, CausticMap) {
    let i = super::march_photons::MarchPhotonsIn { scene, accel, medium: m, octree: oct, photons: ph };
    let out = with_cx(|cx| relume_core::shard::run_all(p, &i, cx)).unwrap();
    (out.radiance, out.caustics)
}

/// The camera's paths through `m` (EikonalPaths).
pub fn view_paths(accel: &Accel, m: &Volume, oct: &Volume, camera: &Camera, p: &EikonalPaths) -> ViewPaths {
    let i = EikonalPathsIn { accel, medium: m, octree: oct, camera };
    with_cx(|cx| eikonal_paths::trace(&i, p, cx)).unwrap()
}

/// The eikonal render of everything above through `camera` (isotropic phase).
#[allow(clippy::too_many_arguments)]
pub fn render_image(
    scene: &Scene,
    accel: &Accel,
    m: &Volume,
    oct: &Volume,
    radiance: &Volume,
    caustics: &CausticMap,
    camera: &Camera,
    p: &EikonalPaths,
) -> Image {
    let paths = view_paths(accel, m, oct, camera, p);
    let i = EikonalRenderIn { scene, accel, medium: m, octree: oct, radiance, caustics, paths: &paths };
    with_cx(|cx| eikonal_render::render(&i, &EikonalRender { g: 0.0, lamp_samples: 4 }, cx)).unwrap().0
}

/// EikonalPaths' defaults.
pub fn paths_params() -> EikonalPaths {
    EikonalPaths { samples: 1, step: 1.0, adaptive: true, integrator: super::optics::Integrator::Verlet }
}

/// A procedural medium (VolumeSource) of `kind` over the cube of side `size` at `centre`.
pub fn source(kind: &str, res: i64, centre: glam::Vec3, size: f64, extra: &[(&str, relume_core::ParamValue)]) -> Volume {
    use relume_base::testing::{f, id};
    let mut p = vec![
        ("kind", id(kind)),
        ("resolution", i(res)),
        ("centre", relume_core::ParamValue::Tuple(centre.to_array().iter().map(|c| f(*c as f64)).collect())),
        ("size", f(size)),
    ];
    p.extend(extra.iter().cloned());
    run_on::<super::volume_source::VolumeSource>(&p, vec![]).unwrap()[0].get::<Volume>().unwrap().clone()
}
