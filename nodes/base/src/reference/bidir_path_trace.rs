use crate::render::bidir::{Bidir, BidirSettings, Splat};
use crate::render::camera::{camera_sample, CameraRays};
use crate::render::film::{with_ctx, Film};
use crate::types::accel::Accel;
use crate::types::{gather_rows, gather_splats, splat_spec, Image, ImageRows, Layer, Scene, SplatRows};
use relume_core::{inputs, node, outputs, params, NodeError, RunCtx, ShardSpec};
use std::ops::Range;

params! {
    /// Bidirectional path tracer (BDPT, Veach 1997): per camera sample, a camera subpath and
    /// a light subpath, joined in every way their lengths allow: the camera path reaching an
    /// emitter, each camera vertex joined to a point on a light, each light vertex seen by the
    /// camera (light tracing, landing on any pixel), and every vertex of one joined to every
    /// vertex of the other; weighted by MIS (power heuristic) over all the strategies that can
    /// make the same path. It finds caustics seen on diffuse surfaces, and light through glass,
    /// that a unidirectional path tracer reaches only by chance. Same scene conventions as
    /// `PathTrace` (`max_depth` as in Mitsuba 3, Russian roulette from `rr_depth`, one-sided
    /// opaque materials), so the two estimate the same image. Area, point, spot and
    /// directional lights, environment maps (light subpaths from infinitely far lights start
    /// on a disk over the scene's bounding sphere) and homogeneous media inside dielectrics
    /// (scattering points joined like surface points). Each sample's
    /// random numbers depend only on (seed, pixel, sample) and splats are added in a fixed
    /// order, so the image has the same bytes on any thread count. Outputs the mean and the
    /// variance of the mean (the light-traced part's from its per-pixel sums of squares).
    /// Sharded over image rows (at most 16 bands: each carries its splats on the whole image).
    pub struct BidirPathTrace {
        /// samples per pixel (each one camera and one light subpath)
        pub spp: u32 = 16, range = 1..=(1 << 20), unit = "samples/pixel", test = 4;
        /// maximum path segments (Mitsuba's meaning); -1 = unbounded
        pub max_depth: i32 = -1, range = -1..=1024;
        /// fewest path segments counted: 1 = all light, 3 = indirect only (with max_depth 3,
        /// one bounce: what a point-based gather's indirect image estimates)
        pub min_depth: u32 = 1, range = 1..=1024;
        /// bounces from which Russian roulette may end a subpath
        pub rr_depth: u32 = 5, range = 1..=1024;
        /// random seed
        pub seed: u64 = 0, range = 0..=u32::MAX;
        /// reflect at smooth dielectrics by Fresnel; false: every subpath refracts (total
        /// internal reflection still reflects), `PathTrace`'s switch: the refraction pipeline's
        /// light model, whose caustics this tracer finds sooner than the path tracer
        pub fresnel_reflection: bool = true;
    }
}

inputs!(pub BidirPathTraceIn { scene: Scene, accel: Accel });
outputs!(pub BidirPathTraceOut { image: Image, variance: Image });

/// Samples per pass at most: a pass's splats are held until it ends.
const MAX_PASS: u32 = 16;

impl BidirPathTrace {
    fn settings(&self) -> BidirSettings {
        BidirSettings {
            max_depth: self.max_depth,
            min_depth: self.min_depth,
            rr_depth: self.rr_depth,
            seed: self.seed,
            only: None,
            fresnel_reflection: self.fresnel_reflection,
        }
    }
}

/// Renders the samples of the rows `rows` with `settings`: the band of those rows (mean and
/// variance of what the camera subpaths brought them; counters [rays, samples dropped as NaN
/// or infinite, splats dropped]) and the sums of the light subpaths' splats on the whole image.
pub fn render_part(
    scene: &Scene,
    accel: &Accel,
    settings: BidirSettings,
    spp: u32,
    rows: Range<usize>,
    cx: Option<&RunCtx>,
) -> Result<SplatRows, NodeError> {
    let cam = &scene.camera;
    let (w, h) = (cam.width, cam.height);
    let mut film = Film::try_new(w, rows.len())?;
    // The splat sums (two f64 RGB layers of the whole image) are refused with the image's
    // own limit before they are allocated.
    if (w * h).checked_mul(48).is_none_or(|b| b > crate::types::MAX_IMAGE_BYTES) {
        return Err(NodeError::over_limit(format!(
            "the splat sums of a {w} × {h} image would pass {} GiB",
            crate::types::MAX_IMAGE_BYTES >> 30
        )));
    }
    let (mut sum, mut sum2) = (vec![[0.0f64; 3]; w * h], vec![[0.0f64; 3]; w * h]);
    let mut dropped = 0u64;
    if scene.has_lights() {
        let tracer = Bidir::new(scene, accel, settings);
        let cam_rays = CameraRays::new(cam);
        let y0 = rows.start;
        with_ctx(cx, |cx| -> Result<(), NodeError> {
            let mut pass = 1u32;
            while film.samples() < spp {
                let first = film.samples();
                let n = pass.min(spp - first).min(MAX_PASS);
                cx.phase(first as f64 / spp as f64, (first + n) as f64 / spp as f64);
                let records = film.add_pass_with(cx, first..first + n, |x, y, s, counts, splats: &mut Vec<Splat>| {
                    let (o, d, id) = camera_sample(&cam_rays, settings.seed, w, x, y + y0, s);
                    tracer.sample(o, d, id, w, counts, splats)
                })?;
                for sp in records.iter().flatten() {
                    if !sp.value.iter().all(|v| v.is_finite()) {
                        dropped += 1;
                        continue;
                    }
                    let (a, b) = (&mut sum[sp.pixel as usize], &mut sum2[sp.pixel as usize]);
                    for c in 0..3 {
                        let v = sp.value[c] as f64;
                        a[c] += v;
                        b[c] += v * v;
                    }
                }
                pass = pass.saturating_mul(2);
            }
            Ok(())
        })?;
    }
    let counters = vec![film.rays(), film.nonfinite(), dropped];
    let (mean, var) = film.finish();
    let layer = |v: Vec<[f64; 3]>| Layer(v.into_iter().map(|p| p.map(|x| x as f32)).collect());
    Ok(SplatRows { band: ImageRows::new(w, rows, vec![mean, var], counters), sum: layer(sum), sum2: layer(sum2) })
}

/// The image from its parts (in row order): the camera subpaths' bands plus the splats over
/// all W × H × spp light subpaths; (mean, variance of the mean, counters).
pub fn assemble(scene: &Scene, spp: u32, parts: &[&SplatRows]) -> Result<(Image, Image, Vec<u64>), NodeError> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let bands: Vec<&ImageRows> = parts.iter().map(|p| &p.band).collect();
    let (mut imgs, counters) = gather_rows(w, h, 2, &bands)?;
    let (mut var, mut mean) = (imgs.pop().expect("two layers"), imgs.pop().expect("two layers"));
    let (splat_mean, splat_var) = gather_splats(w, h, parts, (w * h) as f64 * spp as f64, spp as f64)?;
    for (i, (m, v)) in mean.pixels.iter_mut().zip(&mut var.pixels).enumerate() {
        for c in 0..3 {
            m[c] += splat_mean.pixels[i][c];
            v[c] += splat_var.pixels[i][c];
        }
    }
    Ok((mean, var, counters))
}

/// The whole image, band by band as the node shards it (so the same bytes): (mean, variance
/// of the mean, counters [rays, dropped samples, dropped splats]). `settings.only` renders one
/// strategy alone.
pub fn render(
    scene: &Scene,
    accel: &Accel,
    settings: BidirSettings,
    spp: u32,
    cx: Option<&RunCtx>,
) -> Result<(Image, Image, Vec<u64>), NodeError> {
    let cam = &scene.camera;
    let spec = splat_spec(cam.width, cam.height);
    let parts = (0..spec.chunks())
        .map(|k| {
            let r = spec.chunk_items(k);
            render_part(scene, accel, settings, spp, r.start as usize..r.end as usize, cx)
        })
        .collect::<Result<Vec<_>, _>>()?;
    assemble(scene, spp, &parts.iter().collect::<Vec<_>>())
}

#[node(category = "reference", sharded, metrics = ["spp", "rays", "nonfinite_samples"])]
impl BidirPathTrace {
    fn work(&self, inputs: &[Option<relume_core::PortSize>]) -> Option<f64> {
        super::samples_traced(inputs[0], self.spp)
    }

    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // A band's film (72 bytes a pixel of its rows), its splat sums (48 bytes a pixel of the
        // whole image, f64) and every band's two whole-image layers (24 bytes a pixel each).
        let dims = inputs[0].and_then(|s| s.dims);
        let image = dims.map(|[w, h]| relume_core::PortSize::image(w, h));
        let working = dims.map_or(0, |[w, h]| {
            let bands = splat_spec(w, h).chunks();
            (w * h) as u64 * (72 + 48 + 24 * bands)
        });
        relume_core::MemoryEstimate { outputs: vec![image, image], working }
    }

    fn shard(&self, i: &BidirPathTraceIn) -> Result<ShardSpec, NodeError> {
        Ok(splat_spec(i.scene.camera.width, i.scene.camera.height))
    }

    fn run_items(&self, i: &BidirPathTraceIn, rows: Range<u64>, cx: &RunCtx) -> Result<SplatRows, NodeError> {
        render_part(i.scene, i.accel, self.settings(), self.spp, rows.start as usize..rows.end as usize, Some(cx))
    }

    fn gather(&self, i: &BidirPathTraceIn, parts: &[&SplatRows], cx: &RunCtx) -> Result<BidirPathTraceOut, NodeError> {
        let (image, variance, c) = assemble(i.scene, self.spp, parts)?;
        if !i.scene.has_lights() {
            cx.note("the scene has no light: the image is black (nothing was traced)");
            return Ok(BidirPathTraceOut { image, variance });
        }
        cx.metric("spp", self.spp as f64);
        cx.metric("rays", c[0] as f64);
        cx.metric("nonfinite_samples", (c[1] + c[2]) as f64);
        if c[1] + c[2] > 0 {
            cx.note(format!("{} samples and {} light-traced splats were NaN or infinite and were dropped", c[1], c[2]));
        }
        if self.spp == 1 {
            cx.note("the camera subpaths' variance needs spp ≥ 2: it is written as 0");
        }
        Ok(BidirPathTraceOut { image, variance })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::path_trace::{self, PathTrace};
    use crate::scene::builder::SceneBuilder;
    use crate::types::accel::BuildQuality;
    use crate::types::{Light, Material, Medium};
    use glam::Vec3;

    fn lambert(a: f32) -> Material {
        Material::Lambert { albedo: Vec3::splat(a) }
    }

    /// A floor and a back wall under a small downward lamp: light reaches the camera directly,
    /// after one bounce and after more.
    fn corner(floor: Material, wall: Material) -> SceneBuilder {
        SceneBuilder::new(Vec3::new(0.0, 1.2, 2.5), Vec3::new(0.0, 0.4, 0.0), 50.0, 16, 16)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), floor, Vec3::ZERO)
            .quad("wall", Vec3::new(-1.0, 0.0, -1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0), wall, Vec3::ZERO)
            .quad("lamp", Vec3::new(-0.2, 1.0, -0.2), Vec3::new(0.4, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.4), lambert(0.0), Vec3::splat(10.0))
    }

    fn bidir(scene: &Scene, spp: u32, max_depth: i32, only: Option<(usize, usize)>) -> (Image, Image) {
        let accel = Accel::build(scene, BuildQuality::Fast);
        let (m, v, c) = render(
            scene,
            &accel,
            BidirSettings { max_depth, min_depth: 1, rr_depth: 5, seed: 7, only, fresnel_reflection: true },
            spp,
            None,
        )
        .unwrap();
        assert_eq!((c[1], c[2]), (0, 0), "no NaN or infinite samples");
        (m, v)
    }

    fn path(scene: &Scene, spp: u32, max_depth: i32) -> (Image, Image) {
        let accel = Accel::build(scene, BuildQuality::Fast);
        let (m, v, _, _) = path_trace::render(
            scene,
            &accel,
            &PathTrace { spp, max_depth, min_depth: 1, rr_depth: 5, seed: 11, fresnel_reflection: true },
            None,
        )
        .unwrap();
        (m, v)
    }

    /// Mean of the red channel over the pixels and its standard error (one channel: in grey
    /// scenes the channels are the same samples).
    fn mean(img: &(Image, Image)) -> (f64, f64) {
        let n = img.0.pixels.len() as f64;
        let m = img.0.pixels.iter().map(|p| p[0] as f64).sum::<f64>() / n;
        let v = img.1.pixels.iter().map(|p| p[0] as f64).sum::<f64>() / (n * n);
        (m, v.sqrt())
    }

    /// The two images' means agree within four standard errors, and per pixel within three
    /// in at least `pass` of the pixels.
    fn agree(a: &(Image, Image), b: &(Image, Image), pass: f64, what: &str) {
        let ((ma, sa), (mb, sb)) = (mean(a), mean(b));
        let sigma = (sa * sa + sb * sb).sqrt();
        assert!((ma - mb).abs() < 4.0 * sigma, "{what}: {ma} ± {sa} against {mb} ± {sb}");
        let within = |i: usize| {
            (a.0.pixels[i][0] - b.0.pixels[i][0]).abs() as f64 <= 3.0 * ((a.1.pixels[i][0] + b.1.pixels[i][0]) as f64).sqrt() + 1e-6
        };
        let frac = (0..a.0.pixels.len()).filter(|&i| within(i)).count() as f64 / a.0.pixels.len() as f64;
        assert!(frac >= pass, "{what}: {frac} of the pixels within 3σ");
    }

    fn seen_lamp() -> Scene {
        SceneBuilder::new(Vec3::new(0.0, 0.3, 1.5), Vec3::new(0.0, 1.0, 0.0), 60.0, 16, 16)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), lambert(0.5), Vec3::ZERO)
            .quad("lamp", Vec3::new(-0.2, 1.0, -0.2), Vec3::new(0.4, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.4), lambert(0.5), Vec3::splat(10.0))
            .build()
    }

    fn glass_ball() -> Scene {
        let glass = Material::Dielectric { ior: 1.5, medium: None };
        corner(lambert(0.6), lambert(0.6)).sphere("ball", Vec3::new(0.0, 0.35, 0.0), 0.3, glass, Vec3::ZERO, false).build()
    }

    /// A floor, a glass ball and a wall under a directional light and a dim constant sky.
    fn sun() -> Scene {
        let sun = Light::Directional { direction: Vec3::new(0.4, -1.0, -0.3).normalize(), irradiance: Vec3::splat(3.0) };
        let glass = Material::Dielectric { ior: 1.5, medium: None };
        corner(lambert(0.6), lambert(0.6))
            .sphere("ball", Vec3::new(0.0, 0.35, 0.0), 0.3, glass, Vec3::ZERO, false)
            .light(sun)
            .environment(crate::types::Environment::Constant(Vec3::splat(0.2)))
            .build()
    }

    /// A glossy ball and a floor under a sky map with a bright patch (importance sampling has
    /// something to find), seen in part directly.
    fn sky() -> Scene {
        let texels: Vec<Vec3> = (0..32 * 16)
            .map(|i| if (i % 32) / 4 == 2 && (i / 32) / 2 == 2 { Vec3::splat(40.0) } else { Vec3::new(0.3, 0.4, 0.6) })
            .collect();
        let map = crate::types::EnvMap::new(32, 16, texels).unwrap();
        SceneBuilder::new(Vec3::new(0.0, 0.8, 2.5), Vec3::new(0.0, 0.3, 0.0), 50.0, 16, 16)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), lambert(0.6), Vec3::ZERO)
            .sphere("ball", Vec3::new(0.0, 0.35, 0.0), 0.3, gloss(), Vec3::ZERO, false)
            .environment(crate::types::Environment::Map(map))
            .build()
    }

    fn gloss() -> Material {
        Material::BlinnPhong { kd: Vec3::splat(0.2), ks: Vec3::splat(0.6), exponent: 200.0 }
    }

    #[test]
    fn it_agrees_with_the_path_tracer_on_area_point_and_spot_lights_glossy_surfaces_and_glass() {
        let spot = Light::Spot {
            position: Vec3::new(0.5, 1.5, 0.5),
            direction: Vec3::new(-0.3, -1.0, -0.3).normalize(),
            intensity: Vec3::splat(4.0),
            cos_inner: 0.9,
            cos_outer: 0.8,
        };
        let scenes = [
            ("a lamp in view", seen_lamp(), 1),
            ("a lamp in view", seen_lamp(), -1),
            ("spheres under a point light (smooth normals)", crate::testing::test_scene::spheres(), -1),
            ("a glossy floor", corner(gloss(), lambert(0.6)).build(), 3),
            ("a glass ball", glass_ball(), -1),
            ("a spot light and a glossy wall", corner(lambert(0.6), gloss()).light(spot).build(), -1),
            ("a sun and a glass ball", sun(), -1),
            ("an environment map seen past a glossy ball", sky(), -1),
            ("an environment map", sky(), 2),
        ];
        for (what, scene, depth) in &scenes {
            agree(&bidir(scene, 128, *depth, None), &path(scene, 128, *depth), 0.9, &format!("{what}, max_depth {depth}"));
        }
    }

    #[test]
    fn each_strategy_alone_estimates_all_the_paths_of_its_length() {
        // One-bounce paths (three segments) made four ways: the camera path reaching the lamp,
        // joined to a point on it, joined to the light's first bounce, or the light path seen
        // by the camera. Each alone, unweighted, is the whole one-bounce image.
        let scene = corner(lambert(0.6), lambert(0.6)).build();
        let (p3, p2) = (mean(&path(&scene, 256, 3)), mean(&path(&scene, 256, 2)));
        let (bounce, sigma) = (p3.0 - p2.0, (p3.1 * p3.1 + p2.1 * p2.1).sqrt());
        assert!(bounce > 10.0 * sigma, "{bounce} ± {sigma}");
        for only in [(0, 4), (1, 3), (2, 2), (3, 1)] {
            let (m, s) = mean(&bidir(&scene, 128, 3, Some(only)));
            let tol = 4.0 * (s * s + sigma * sigma).sqrt();
            assert!((m - bounce).abs() < tol, "strategy {only:?}: {m} ± {s} against {bounce} ± {sigma}");
        }
        // All strategies, weighted, with `min_depth` 3: the same one-bounce image.
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let settings = BidirSettings { max_depth: 3, min_depth: 3, rr_depth: 5, seed: 7, only: None, fresnel_reflection: true };
        let (m, v, _) = render(&scene, &accel, settings, 128, None).unwrap();
        let (m, s) = mean(&(m, v));
        assert!((m - bounce).abs() < 4.0 * (s * s + sigma * sigma).sqrt(), "min_depth 3: {m} ± {s} against {bounce} ± {sigma}");
    }

    #[test]
    fn each_strategy_alone_estimates_the_light_of_infinitely_far_lights() {
        // Direct light from an environment map and from a sun with a sky: the camera path
        // leaving the scene (not for the sun), a shadow ray toward the light, or the light's
        // beam entering the scene over a disk and seen by the camera.
        for (scene, strategies) in [(sky(), &[(0, 3), (1, 2), (2, 1)][..]), (sun(), &[(1, 2), (2, 1)][..])] {
            let (p2, p1) = (mean(&path(&scene, 512, 2)), mean(&path(&scene, 512, 1)));
            let (direct, sigma) = (p2.0 - p1.0, (p2.1 * p2.1 + p1.1 * p1.1).sqrt());
            for &only in strategies {
                let (m, s) = mean(&bidir(&scene, 256, 2, Some(only)));
                let tol = 4.0 * (s * s + sigma * sigma).sqrt();
                assert!((m - direct).abs() < tol, "strategy {only:?}: {m} ± {s} against {direct} ± {sigma}");
            }
        }
    }

    #[test]
    fn a_furnace_converges_to_emission_over_one_minus_albedo() {
        // Inside a closed emitting sphere of albedo a: L = e / (1 − a), every strategy's light
        // spread over the whole sphere and every light path seen by the camera somewhere.
        for (a, e) in [(0.5f32, 1.0f32), (0.8, 0.25)] {
            let scene = SceneBuilder::new(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0), 60.0, 8, 8)
                .sphere("room", Vec3::ZERO, 2.0, lambert(a), Vec3::splat(e), true)
                .flat_shading()
                .build();
            let (m, s) = mean(&bidir(&scene, 256, -1, None));
            let exact = (e / (1.0 - a)) as f64;
            assert!((m - exact).abs() < 4.0 * s + 1e-3 * exact, "a = {a}: {m} ± {s} against {exact}");
            assert!(s > 0.0 && s < 0.02 * exact, "{s}");
        }
    }

    #[test]
    fn stiff_cases_stay_finite_and_within_the_energy_bound() {
        // A lamp almost touching the floor (the geometry term's 1/r² near its pole), glass of
        // index 10⁻³ and 10³ apart, a sliver triangle: finite, non-negative, and no more light
        // than a white furnace of the lamp's radiance would show.
        let near = SceneBuilder::new(Vec3::new(0.0, 1.0, 1.5), Vec3::ZERO, 50.0, 12, 12)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), lambert(0.9), Vec3::ZERO)
            .quad("lamp", Vec3::new(-0.2, 1e-4, -0.2), Vec3::new(0.4, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.4), lambert(0.0), Vec3::splat(10.0))
            .build();
        let glass = |ior| {
            corner(lambert(0.6), lambert(0.6))
                .sphere("ball", Vec3::new(0.0, 0.35, 0.0), 0.3, Material::Dielectric { ior, medium: None }, Vec3::ZERO, false)
                .build()
        };
        let sliver = corner(lambert(0.6), lambert(0.6))
            .quad("sliver", Vec3::new(-0.5, 0.3, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1e-7, 0.0), lambert(0.9), Vec3::ZERO)
            .build();
        for (what, scene) in
            [("a lamp 10⁻⁴ over the floor", near), ("ior 10⁻³", glass(1e-3)), ("ior 10³", glass(1e3)), ("a sliver", sliver)]
        {
            let (m, v) = bidir(&scene, 16, -1, None);
            assert!(m.as_floats().iter().chain(v.as_floats()).all(|x| x.is_finite() && *x >= 0.0), "{what}");
            let brightest = m.as_floats().iter().fold(0.0f32, |a, &b| a.max(b));
            assert!(brightest <= 10.0 / (1.0 - 0.9), "{what}: {brightest}");
            assert!(mean(&(m, v)).0 > 0.0, "{what}: lit");
        }
    }

    #[test]
    fn one_and_two_threads_and_any_split_of_the_rows_give_the_same_bytes() {
        let scene = glass_ball();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let settings = BidirSettings { max_depth: -1, min_depth: 1, rr_depth: 5, seed: 3, only: None, fresnel_reflection: true };
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| render(&scene, &accel, settings, 8, None).unwrap())
        };
        let (a, b) = (run(1), run(2));
        assert_eq!((&a.0, &a.1), (&b.0, &b.1));
        // The node's bands, run one by one through the engine's sharding, gather to the same.
        let out = crate::testing::run_on::<BidirPathTrace>(
            &[("spp", crate::testing::i(8)), ("seed", crate::testing::i(3))],
            vec![relume_core::Value::new(scene.clone()), relume_core::Value::new(Accel::build(&scene, BuildQuality::Fast))],
        )
        .unwrap();
        assert_eq!(crate::testing::first::<Image>(&out), a.0);
    }

    /// A glass ball filled with a scattering medium of scattering coefficient `sigma_s`, under
    /// the lamp and filling most of the view: the light inside reaches the camera through the
    /// glass, so the joins of two scattering points inside the ball carry much of it.
    fn fog(sigma_s: f32) -> Scene {
        let medium = Some(Medium { sigma_a: Vec3::new(0.1, 0.3, 0.6), sigma_s: Vec3::splat(sigma_s) });
        SceneBuilder::new(Vec3::new(0.0, 0.45, 1.0), Vec3::new(0.0, 0.35, 0.0), 40.0, 16, 16)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), lambert(0.6), Vec3::ZERO)
            .quad("lamp", Vec3::new(-0.2, 1.0, -0.2), Vec3::new(0.4, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.4), lambert(0.0), Vec3::splat(10.0))
            .sphere("fog", Vec3::new(0.0, 0.35, 0.0), 0.3, Material::Dielectric { ior: 1.3, medium }, Vec3::ZERO, false)
            .build()
    }

    #[test]
    fn it_agrees_with_the_path_tracer_through_media_inside_glass() {
        // σt r about 1 and 6 across the ball: single scattering, then many scatterings.
        // Measured at 4,096 samples, the mean comes out wrong without the transmittance along
        // the joins inside the ball (18 % too bright at σs 3, 6.5 times at 20), without the
        // phase function at the light subpath's scattering points (17 % too dark at 3), and
        // without importance's missing 1/η² on entering the ball (8 % too dark at 3, 7.7 of
        // its standard errors).
        for (sigma_s, spp) in [(3.0, 4096), (20.0, 512)] {
            let scene = fog(sigma_s);
            agree(&bidir(&scene, spp, -1, None), &path(&scene, spp, -1), 0.9, &format!("σs {sigma_s}"));
        }
    }

    #[test]
    fn without_fresnel_reflection_it_agrees_with_the_path_tracer_without_it() {
        // The glass ball lets all its light through (the refraction pipeline's light model):
        // both tracers switch it the same way, and the light through the ball changes.
        let scene = glass_ball();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let settings = BidirSettings { max_depth: -1, min_depth: 1, rr_depth: 5, seed: 7, only: None, fresnel_reflection: false };
        let (m, v, c) = render(&scene, &accel, settings, 1024, None).unwrap();
        assert_eq!((c[1], c[2]), (0, 0), "no NaN or infinite samples");
        let p = PathTrace { spp: 1024, max_depth: -1, min_depth: 1, rr_depth: 5, seed: 11, fresnel_reflection: false };
        let (pm, pv, _, _) = path_trace::render(&scene, &accel, &p, None).unwrap();
        let without = (m, v);
        agree(&without, &(pm, pv), 0.9, "no Fresnel reflection");
        let with = bidir(&scene, 1024, -1, None);
        let ((a, sa), (b, sb)) = (mean(&without), mean(&with));
        assert!((a - b).abs() > 4.0 * (sa * sa + sb * sb).sqrt(), "the switch changes the image: {a} ± {sa} against {b} ± {sb}");
    }

    #[test]
    fn the_node_stops_midway_when_cancelled() {
        let scene = glass_ball();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        crate::testing::cancels_midway::<BidirPathTrace>(
            &[("spp", crate::testing::i(64))],
            vec![relume_core::Value::new(scene), relume_core::Value::new(accel)],
        );
    }
}
