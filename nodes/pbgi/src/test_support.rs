//! Small point-based GI set-ups for the unit tests of this folder, made by the pipeline's own
//! graph and nodes.

/// A small point-based GI set-up from the pipeline's own graph: `graphs/fpbgi_cornell.ron`
/// at 16 × 16 with 3,000 points, one shading sample, tiles of 8² pixels with k = 4 clusters.
pub mod pbgi_setup {
    use crate::types::{PointTree, Receivers};
    use relume_base::types::Clusters;
    use relume_core::graph::{Output, PortRef};
    use relume_core::{Engine, Graph, RunOptions};
    use std::sync::OnceLock;

    /// The point tree, receivers and clusters (computed once per test binary).
    pub fn tree_receivers_clusters() -> (PointTree, Receivers, Clusters) {
        static SETUP: OnceLock<(PointTree, Receivers, Clusters)> = OnceLock::new();
        SETUP
            .get_or_init(|| {
                let reg = crate::registry();
                let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../graphs/fpbgi_cornell.ron");
                let mut g = Graph::load(&path, &reg).unwrap_or_else(|e| panic!("{e}"));
                let sets = [
                    ("scene.width", "16"),
                    ("scene.height", "16"),
                    ("points.count", "3000"),
                    ("points.seed", "1"),
                    ("shade.samples", "1"),
                    ("clusters.tile", "8"),
                    ("clusters.k", "4"),
                    ("clusters.iterations", "5"),
                    ("clusters.seed", "1"),
                ];
                for (k, v) in sets {
                    g.set_param_text(&reg, k, v).unwrap();
                }
                for (name, port) in [("tree", "tree.tree"), ("receivers", "gbuffer.receivers"), ("clusters", "clusters.clusters")] {
                    g.outputs.push(Output { name: name.into(), port: PortRef::parse(port).unwrap(), pos: Default::default() });
                }
                let outputs = Some(["tree", "receivers", "clusters"].map(String::from).to_vec());
                let r = Engine::new(reg).run(&g, &RunOptions { outputs, ..Default::default() }).unwrap_or_else(|e| panic!("{e}"));
                let get = |n: &str| r.output(n).unwrap().clone();
                (
                    get("tree").get::<PointTree>().unwrap().clone(),
                    get("receivers").get::<Receivers>().unwrap().clone(),
                    get("clusters").get::<Clusters>().unwrap().clone(),
                )
            })
            .clone()
    }

    pub fn tree_and_receivers() -> (PointTree, Receivers) {
        let (t, r, _) = tree_receivers_clusters();
        (t, r)
    }

    /// `r` with its last receiver's pixel filled from the first two receivers' pixels
    /// (weights ¼ and ¾), and those three pixels.
    pub fn with_a_fill(r: &Receivers) -> (Receivers, [u32; 3]) {
        let mut r = r.clone();
        let (p, a, b) = (r.pixel[r.len() - 1], r.pixel[0], r.pixel[1]);
        assert!(p != a && p != b && a != b, "three pixels");
        r.fill = vec![crate::types::Fill { pixel: p, from: [a, b, 0, 0], weight: [0.25, 0.75, 0.0, 0.0] }];
        (r, [p, a, b])
    }

    /// Pixel p of `img` holds ¼ of pixel a's light and ¾ of b's (`with_a_fill`).
    pub fn assert_filled(img: &relume_base::types::Image, [p, a, b]: [u32; 3]) {
        let px = |q: u32| img.pixels[q as usize];
        let want: Vec<f32> = (0..3).map(|c| 0.25 * px(a)[c] + 0.75 * px(b)[c]).collect();
        assert_eq!(px(p).to_vec(), want, "the filled pixel reads the two it names");
        assert!(want.iter().any(|&v| v > 0.0), "and they are lit");
    }
}

/// A small wavelet-PBGI set-up: a floor and a back wall under a point light, 3,000 points,
/// 6 × 32² maps, seen from the front at 12 × 12.
pub mod wpbgi_setup {
    use crate::shade_direct::{shade_direct, ShadeDirect};
    use crate::surfel_wavelets::SurfelWavelets;
    use crate::types::{CodedWavelets, PointTree, PointWavelets, Receivers};
    use crate::wavelet_tree::WaveletTree;
    use glam::Vec3;
    use relume_base::scene::builder::SceneBuilder;
    use relume_base::testing::{first, i, run_on};
    use relume_base::types::accel::{Accel, BuildQuality};
    use relume_base::types::{Light, Material, Scene, SurfacePoints};
    use relume_core::{CancelToken, RunCtx, Value};

    /// The corner's point light.
    const LIGHT: Vec3 = Vec3::new(0.3, 1.2, 0.6);
    const INTENSITY: f32 = 3.0;
    /// The floor's albedo (and the wall's in `exact_one_bounce`).
    const ALBEDO: f32 = 0.6;

    /// The scene (a grey Lambert floor, the back wall of material `wall`) and its points.
    pub fn corner(wall: Material) -> (Scene, SurfacePoints) {
        let grey = Material::Lambert { albedo: Vec3::splat(ALBEDO) };
        let scene = SceneBuilder::new(Vec3::new(0.0, 1.2, 2.5), Vec3::new(0.0, 0.4, 0.0), 50.0, 12, 12)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), grey, Vec3::ZERO)
            .quad("wall", Vec3::new(-1.0, 0.0, -1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 1.5, 0.0), wall, Vec3::ZERO)
            .light(Light::Point { position: LIGHT, intensity: Vec3::splat(INTENSITY) })
            .build();
        let pts = relume_base::geometry::sample_surface::sample_surface(
            &scene,
            &relume_base::geometry::sample_surface::SampleSurface {
                method: relume_base::geometry::sample_surface::Method::AreaCdf,
                count: 3000,
                seed: 2,
                emitters: true,
            },
        )
        .unwrap();
        (scene, pts)
    }

    /// The light a point of the grey corner (`corner` with a grey Lambert wall) reflects toward
    /// any direction after one bounce: (ρ/π) ∫ L(y) cos θx cos θy / r² dA over the other
    /// surface (the floor gathers from the wall, the wall from the floor), with L(y) the
    /// surface's directly lit radiance ρ I cos θ / (π d²). Nothing in the corner shadows, so
    /// this is the path tracer's expectation; the integral is a midpoint rule on a `cells`²
    /// grid, in f64.
    pub fn exact_one_bounce(x: Vec3, normal: Vec3, cells: usize) -> f64 {
        let rho = ALBEDO as f64 / std::f64::consts::PI;
        let on_wall = normal.z > 0.5;
        // The other surface: its corner, two edges and normal.
        let (o, u, v, ny) = if on_wall {
            (Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), Vec3::Y)
        } else {
            (Vec3::new(-1.0, 0.0, -1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 1.5, 0.0), Vec3::Z)
        };
        let cell_area = u.cross(v).length() as f64 / (cells * cells) as f64;
        let mut sum = 0.0f64;
        for a in 0..cells {
            for b in 0..cells {
                let y = o + u * ((a as f32 + 0.5) / cells as f32) + v * ((b as f32 + 0.5) / cells as f32);
                let to_light = LIGHT - y;
                let radiance = rho * INTENSITY as f64 * ny.dot(to_light.normalize()).max(0.0) as f64 / to_light.length_squared() as f64;
                let d = y - x;
                let w = d.normalize();
                let geometry = normal.dot(w).max(0.0) as f64 * (-ny.dot(w)).max(0.0) as f64 / d.length_squared() as f64;
                sum += radiance * geometry * cell_area;
            }
        }
        rho * sum
    }

    /// Everything a wavelet gather or a view tree reads.
    pub struct Setup {
        pub points: SurfacePoints,
        /// The diffuse tree (`ShadeDirect`'s radiance).
        pub tree: PointTree,
        pub wavelets: PointWavelets,
        /// `wavelets` coded at the default split (20) and threshold (0.002).
        pub coded: CodedWavelets,
        pub receivers: Receivers,
    }

    pub fn setup(wall: Material) -> Setup {
        let (scene, points) = corner(wall);
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let cancel = CancelToken::new();
        let (b, _) = shade_direct(&scene, &accel, &points, &ShadeDirect { samples: 1, seed: 0 }, &RunCtx::new("t", &cancel, None)).unwrap();
        let tree = PointTree::build(&points, &b);
        let acc = || Value::new(Accel::build(&scene, BuildQuality::Fast));
        let wavelets: PointWavelets = first(
            &run_on::<SurfelWavelets>(&[("resolution", i(32))], vec![Value::new(scene.clone()), acc(), Value::new(points.clone())])
                .unwrap(),
        );
        let coded: CodedWavelets = first(
            &run_on::<WaveletTree>(
                &[("report_uncoded", relume_core::ParamValue::Bool(false))],
                vec![Value::new(tree.clone()), Value::new(wavelets.clone())],
            )
            .unwrap(),
        );
        let receivers: Receivers = first(&run_on::<crate::gbuffer::GBuffer>(&[], vec![Value::new(scene.clone()), acc()]).unwrap());
        Setup { points, tree, wavelets, coded, receivers }
    }
}
