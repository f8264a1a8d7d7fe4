use super::incident::{DirectSampler, Incident};
use super::wavelet_radiance::{interface_intensity, outgoing_intensity};
use crate::types::PointWavelets;
use glam::Vec3;
use relume_base::brdf;
use relume_base::math::cube_haar::{CubeHaar, SparseCubeHaar};
use relume_base::types::accel::Accel;
use relume_base::types::{Material, Scene, SurfacePoints};
use relume_core::{node, params, MemoryEstimate, NodeError, PortSize, RunCtx};

params! {
    /// Each surface point's outgoing radiance as wavelets (wavelet PBGI, [P] 4.4): the direct
    /// light reaching the point, drawn exactly as `ShadeDirect` draws it (same samples for the
    /// same `samples` and `seed`), weighed by the point's BRDF toward every texel of a cube map
    /// of side `resolution` and by the cosine to its normal (the intensity per unit area that
    /// the point tree averages: see `wavelet_radiance::outgoing_intensity`), then the
    /// non-standard Haar transform per face. Coefficients with every channel below `threshold`
    /// are dropped ([P]: 0.002), and at most `max_terms` kept per point (the largest; the
    /// report counts the points capped). Points no light reaches and black points keep no
    /// terms. A point on a smooth dielectric sends toward its front the light reflected from
    /// its front and refracted through from behind, each Dirac lobe into one texel
    /// (`wavelet_radiance::interface_intensity`; `TwinDielectrics` gives it a twin for the other
    /// side). Lobes narrower than
    /// the map resolves are widened to it, and a map that would send out more than the point
    /// receives is scaled down (`wavelet_radiance::band_limited`, `outgoing_intensity`: narrow
    /// lobes and grazing light, docs/QUALITY.md §2). The output holds at
    /// most points × max_terms × 16 B: over the memory budget it is refused before anything is
    /// drawn.
    pub struct SurfelWavelets {
        /// cube-map side per face (a power of two; [P]: 32, 128 for the ring's caustic)
        pub resolution: usize = 32, range = 2..=128, unit = "texels", test = 16;
        /// light samples per point for area lights and the environment
        pub samples: u32 = 16, range = 1..=4096, unit = "samples/point";
        /// random seed (the same as `ShadeDirect`'s draws the same light)
        pub seed: u64 = 0, range = 0..=u32::MAX;
        /// drop coefficients whose every channel is below this
        pub threshold: f32 = 0.002, range = 0.0..=10.0;
        /// most coefficients kept per point (bounds the output's memory)
        pub max_terms: usize = 4096, range = 1..=98304, unit = "terms/point";
    }
}

/// What one point came to, for the report.
enum Outcome {
    Skipped,
    Kept,
    Capped,
}

impl SurfelWavelets {
    /// Terms a point can keep at most.
    fn cap(&self) -> usize {
        self.max_terms.min(6 * self.resolution * self.resolution)
    }

    /// Point `i`'s kept coefficients.
    fn point(&self, sampler: &DirectSampler, pts: &SurfacePoints, i: usize, inc: &mut Incident) -> (SparseCubeHaar, Outcome) {
        let n = self.resolution;
        let (m, x, nrm) = (&pts.material[i], pts.position[i], pts.normal[i]);
        let empty = SparseCubeHaar { n, index: vec![], value: vec![] };
        let map = if let Material::Dielectric { ior, .. } = *m {
            // Both sides of the interface: light from the front is reflected, light from
            // behind is refracted through (`interface_intensity`).
            let mut side = |s: Vec3| {
                if !sampler.reachable(x, s) {
                    return vec![];
                }
                sampler.incident(i, x, s, inc);
                inc.weighted()
            };
            let (front, back) = (side(nrm), side(-nrm));
            if front.is_empty() && back.is_empty() {
                return (empty, Outcome::Kept);
            }
            interface_intensity(ior, nrm, &front, &back, n)
        } else {
            if brdf::albedo_hint(m) == Vec3::ZERO || !sampler.reachable(x, nrm) {
                return (empty, Outcome::Skipped);
            }
            sampler.incident(i, x, nrm, inc);
            if inc.delta.is_empty() && inc.extended.is_empty() {
                return (empty, Outcome::Kept);
            }
            outgoing_intensity(m, nrm, &inc.weighted(), n)
        };
        let w = CubeHaar::forward(&map).keep_above(self.threshold);
        match w.limit(self.cap()) {
            (w, false) => (w, Outcome::Kept),
            (w, true) => (w, Outcome::Capped),
        }
    }
}

#[node(category = "pbgi", version = 2, metrics = ["points", "points_skipped", "points_capped", "terms_per_point", "terms_of_full_map"], outputs = [wavelets])]
impl SurfelWavelets {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        let points = inputs[2].map(|s| s.bytes / SurfacePoints::BYTES_PER_POINT as u64);
        let out = points.map(|p| p * self.cap() as u64 * PointWavelets::BYTES_PER_TERM as u64 + (p + 1) * 4);
        // The per-point results wait in a list before they are packed: once more the output;
        // each thread's cube map and coefficients besides.
        let per_thread = 6 * (self.resolution * self.resolution) as u64 * 12 * 3;
        MemoryEstimate {
            outputs: vec![out.map(PortSize::bytes)],
            working: out.unwrap_or(0) + per_thread * rayon::current_num_threads() as u64,
        }
    }

    fn run(&self, scene: &Scene, accel: &Accel, points: &SurfacePoints, cx: &RunCtx) -> Result<PointWavelets, NodeError> {
        if !self.resolution.is_power_of_two() {
            return Err(NodeError::param(
                "resolution",
                format!("{} is not a power of two (the Haar transform halves each face)", self.resolution),
            ));
        }
        let pts = points;
        let sampler = DirectSampler::new(scene, accel, self.samples, self.seed);
        let per_point = cx.par_map_init(pts.len(), Incident::default, |inc, k| self.point(&sampler, pts, k, inc))?;
        let (mut skipped, mut capped) = (0u64, 0u64);
        let mut points = Vec::with_capacity(per_point.len());
        for (w, outcome) in per_point {
            match outcome {
                Outcome::Skipped => skipped += 1,
                Outcome::Capped => capped += 1,
                Outcome::Kept => {}
            }
            points.push(w);
        }
        let w = PointWavelets::from_points(self.resolution, &points);
        cx.metric("points", pts.len() as f64);
        cx.metric("points_skipped", skipped as f64);
        cx.metric("points_capped", capped as f64);
        cx.metric("terms_per_point", w.index.len() as f64 / pts.len().max(1) as f64);
        cx.metric("terms_of_full_map", (6 * self.resolution * self.resolution) as f64);
        if capped > 0 {
            cx.note(format!("{capped} points had more than {} terms above the threshold and kept the largest {0}", self.cap()));
        }
        Ok(w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shade_direct::{shade_direct, ShadeDirect};
    use relume_base::testing::{cancels_midway, f, first, i, run_on};
    use relume_base::types::accel::BuildQuality;
    use relume_base::types::{Light, Material};
    use relume_core::{CancelToken, Value};
    use std::f32::consts::PI;

    fn floor_under_a_lamp(m: Material) -> (Scene, Accel, SurfacePoints) {
        let scene = relume_base::testing::test_scene::floor_and_lamp(m)
            .light(Light::Point { position: Vec3::new(0.5, 1.5, 0.0), intensity: Vec3::splat(2.0) })
            .build();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let pts = relume_base::geometry::sample_surface::sample_surface(
            &scene,
            &relume_base::geometry::sample_surface::SampleSurface {
                method: relume_base::geometry::sample_surface::Method::AreaCdf,
                count: 60,
                seed: 1,
                emitters: true,
            },
        )
        .unwrap();
        (scene, accel, pts)
    }

    fn inputs(scene: &Scene, pts: &SurfacePoints) -> Vec<Value> {
        vec![Value::new(scene.clone()), Value::new(Accel::build(scene, BuildQuality::Fast)), Value::new(pts.clone())]
    }

    fn run(scene: &Scene, _accel: &Accel, pts: &SurfacePoints, params: &[(&str, relume_core::ParamValue)]) -> PointWavelets {
        first(&run_on::<SurfelWavelets>(params, inputs(scene, pts)).unwrap())
    }

    #[test]
    fn a_lambert_points_exitance_is_its_shaded_radiance_times_pi() {
        // ∫ J dω = ∫ L cos dω = π B for a diffuse surfel: the wavelets carry the same light as
        // `ShadeDirect`'s radiance B (same samples), up to the threshold's loss.
        let (scene, accel, pts) = floor_under_a_lamp(Material::Lambert { albedo: Vec3::new(0.7, 0.5, 0.3) });
        let w = run(
            &scene,
            &accel,
            &pts,
            &[("resolution", i(16)), ("samples", i(4)), ("seed", i(3)), ("threshold", relume_base::testing::f(0.0))],
        );
        let cancel = CancelToken::new();
        let (b, _) = shade_direct(&scene, &accel, &pts, &ShadeDirect { samples: 4, seed: 3 }, &RunCtx::new("t", &cancel, None)).unwrap();
        let mut lit = 0;
        for (k, bk) in b.iter().enumerate() {
            let exitance = w.sparse(k).dense().inverse().integral();
            let want = *bk * PI;
            // The texels straddling the horizon are counted whole or not at all: 16² is coarse.
            assert!((exitance - want).abs().max_element() <= 0.02 * want.max_element() + 1e-6, "point {k}: {exitance} vs {want}");
            lit += (want.x > 0.0) as usize;
        }
        assert!(lit > pts.len() / 2, "{lit} lit points");
    }

    #[test]
    fn the_term_cap_keeps_the_largest_and_black_points_keep_none() {
        let (scene, accel, pts) = floor_under_a_lamp(Material::BlinnPhong { kd: Vec3::splat(0.2), ks: Vec3::splat(0.6), exponent: 80.0 });
        let full = run(&scene, &accel, &pts, &[("resolution", i(16)), ("samples", i(2))]);
        let capped = run(&scene, &accel, &pts, &[("resolution", i(16)), ("samples", i(2)), ("max_terms", i(20))]);
        for k in 0..pts.len() {
            let (fi, fv) = full.point(k);
            let (ci, cv) = capped.point(k);
            assert!(ci.len() <= 20 && ci.len() == fi.len().min(20));
            // What the cap dropped is never larger than what it kept.
            let kept_min = cv.iter().map(|v| v.abs().max_element()).fold(f32::INFINITY, f32::min);
            for (idx, v) in fi.iter().zip(fv) {
                if !ci.contains(idx) {
                    assert!(v.abs().max_element() <= kept_min, "point {k}");
                }
            }
        }
        let (scene, accel, pts) = floor_under_a_lamp(Material::Lambert { albedo: Vec3::ZERO });
        let w = run(&scene, &accel, &pts, &[("resolution", i(8))]);
        assert!(w.index.is_empty() && w.len() == pts.len());
    }

    #[test]
    fn a_glass_floor_and_its_twins_send_out_exactly_what_arrives_split_by_fresnel() {
        // A glass floor under the lamp, each point with its twin facing down: the lit side
        // reflects F of the light up, the twin sends 1 − F of it down through the glass, and
        // together they send out exactly the irradiance (every sample split, none lost).
        // A point light only, so that a point and its twin see the same light.
        let glass = Material::Dielectric { ior: 1.5, medium: None };
        let scene = relume_base::scene::builder::SceneBuilder::new(Vec3::new(0.0, 3.0, 0.1), Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), glass, Vec3::ZERO)
            .light(Light::Point { position: Vec3::new(0.5, 1.5, 0.0), intensity: Vec3::splat(2.0) })
            .build();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let sample = relume_base::geometry::sample_surface::SampleSurface {
            method: relume_base::geometry::sample_surface::Method::AreaCdf,
            count: 60,
            seed: 1,
            emitters: false,
        };
        let pts = relume_base::geometry::sample_surface::sample_surface(&scene, &sample).unwrap();
        let pts = crate::twin_dielectrics::twin_dielectrics(&pts);
        let half = pts.len() / 2;
        let w = run(&scene, &accel, &pts, &[("resolution", i(16)), ("samples", i(4)), ("threshold", f(0.0))]);
        let sampler = DirectSampler::new(&scene, &accel, 4, 0);
        let mut inc = Incident::default();
        let exitance = |k: usize| w.sparse(k).dense().inverse().integral();
        let mut lit = 0;
        for k in 0..half {
            sampler.incident(k, pts.position[k], pts.normal[k], &mut inc);
            let e: Vec3 = inc.weighted().iter().map(|s| s.1).sum();
            let (up, down) = (exitance(k), exitance(half + k));
            assert!((up + down - e).abs().max_element() <= 1e-4 * e.max_element() + 1e-6, "point {k}: {up} + {down} vs {e}");
            // Reflectance 0.04 at normal incidence, more toward grazing.
            assert!(up.x >= 0.039 * e.x && up.x <= 0.2 * e.x + 1e-6, "point {k}: {up} of {e}");
            lit += (e.x > 0.0) as usize;
            // What each sends lies on its own side.
            let map = w.sparse(half + k).dense().inverse();
            for (t, d) in map.texels.iter().zip(relume_base::math::cubemap::texel_directions(16).iter()) {
                assert!(d.dot(pts.normal[half + k]) > -0.1 || t.abs().max_element() < 1e-3, "point {k}: sent behind");
            }
        }
        assert!(lit > half / 2, "{lit} of {half} lit");
    }

    #[test]
    fn a_side_that_is_not_a_power_of_two_is_refused_and_a_run_can_be_cancelled() {
        let (scene, _, pts) = floor_under_a_lamp(Material::Lambert { albedo: Vec3::ONE });
        let inputs = inputs(&scene, &pts);
        let err = run_on::<SurfelWavelets>(&[("resolution", i(24))], inputs.clone()).unwrap_err();
        assert!(err.to_string().contains("power of two"), "{err}");
        cancels_midway::<SurfelWavelets>(&[("resolution", i(8))], inputs);
    }

    #[test]
    fn the_memory_estimate_bounds_the_output() {
        let (scene, accel, pts) = floor_under_a_lamp(Material::BlinnPhong { kd: Vec3::splat(0.3), ks: Vec3::splat(0.5), exponent: 30.0 });
        let node = SurfelWavelets { resolution: 8, samples: 2, seed: 0, threshold: 0.0, max_terms: 50 };
        let est =
            relume_core::Node::memory(&node, &[None, None, Some(PortSize::bytes((pts.len() * SurfacePoints::BYTES_PER_POINT) as u64))]);
        let w = run(
            &scene,
            &accel,
            &pts,
            &[("resolution", i(8)), ("samples", i(2)), ("threshold", relume_base::testing::f(0.0)), ("max_terms", i(50))],
        );
        use relume_core::PortValue;
        assert!(w.byte_size() as u64 <= est.outputs[0].unwrap().bytes, "{} > {:?}", w.byte_size(), est.outputs[0]);
        assert!(w.index.len() > pts.len() * 25, "a threshold of 0 keeps many terms: {}", w.index.len());
    }
}
