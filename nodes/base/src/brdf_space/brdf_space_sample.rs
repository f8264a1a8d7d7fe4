use crate::brdf::BrdfModel;
use crate::math::spread;
use crate::types::{cos_half, BrdfGrid, BrdfSample, BrdfSpace, MAX_BRDF_SPACE_BYTES};
use relume_core::{memory::fmt_bytes, node, params, MemoryEstimate, NodeError, ParamEnum, PortSize, RunCtx};

/// How the Blinn-Phong exponents of the specular samples are spread over [s_min, s_max].
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum Spacing {
    /// equal steps in s, as [S] 4.1.2 samples them
    Linear,
    /// equal ratios from one exponent to the next, so broad lobes (small s) get as many samples
    /// per doubling of s as narrow ones
    Geometric,
}

params! {
    /// Tabulates BRDFs on a (θi, θo, φ) grid, the BRDF space of pipeline 1 ([S] 4.1.2, 4-17,
    /// 4-18). Sample 1 is diffuse (kd = 1, ks = 0); the other samples − 1 are specular (kd = 0,
    /// ks = 1) of the chosen `model`:
    ///
    /// - Blinn-Phong: exponents spaced linearly over [s_min, s_max] ([S]: "s 在选定的范围内均匀
    ///   采样", uniformly over the chosen range; one specular sample takes s_min), or
    ///   geometrically (`s_spacing`), which gives broad lobes more of the samples. The BRDF is the
    ///   project's normalised Blinn-Phong, (s+2)/(8π) cos^s δ (`brdf/blinn_phong.rs`), not the
    ///   thesis' printed (s+2)/(2π).
    /// - Cook-Torrance (`brdf/cook_torrance.rs`, D F G / (4 cos θi cos θo)): `f0_count` Schlick F0
    ///   values over [f0_min, f0_max] times (samples − 1) / f0_count Beckmann roughnesses over
    ///   [m_min, m_max], roughness-major. The lobe is linear in F0, so the two ends (the default
    ///   f0_count = 2) span every F0 between them; the defaults are `BrdfTensor`'s ranges, which
    ///   `PttRelight` holds a material to. This is the space for the transfer tensors' bounce
    ///   channels when the dynamic object is Cook-Torrance: a Blinn-Phong space cannot hold the
    ///   microfacet lobe's growth toward grazing (see `MaterialProject`).
    ///
    /// Values are taken at cell centres, φ the relative azimuth folded into [0, π] with the mirror
    /// direction at φ = π (see `BrdfSpace`). Sizes over 2 GiB of table are refused before
    /// allocating.
    pub struct BrdfSpaceSample {
        /// cells over the incident polar angle θi ∈ [0, π/2]
        pub n_theta_i: usize = 30, range = 1..=1024, test = 8;
        /// cells over the outgoing polar angle θo ∈ [0, π/2]
        pub n_theta_o: usize = 30, range = 1..=1024, test = 8;
        /// cells over the relative azimuth φ ∈ [0, π] (mirror direction at π)
        pub n_phi: usize = 60, range = 1..=2048, test = 16;
        /// BRDF samples N_s: one diffuse, N_s − 1 specular
        pub samples: usize = 201, range = 2..=2048, test = 21;
        /// Blinn-Phong: smallest exponent of the specular samples
        pub s_min: f32 = 1.0, range = 0.0..=1e5;
        /// Blinn-Phong: largest exponent of the specular samples
        pub s_max: f32 = 200.0, range = 0.0..=1e5;
        /// Blinn-Phong: how the exponents are spread (Geometric needs s_min > 0)
        pub s_spacing: Spacing = Linear;
        /// specular model of the samples: Blinn-Phong (s) or Cook-Torrance (m, F0)
        pub model: BrdfModel = BlinnPhong;
        /// Cook-Torrance: smallest Beckmann roughness m
        pub m_min: f32 = 0.05, range = 0.001..=1.0;
        /// Cook-Torrance: largest Beckmann roughness m
        pub m_max: f32 = 0.6, range = 0.001..=1.0;
        /// Cook-Torrance: smallest Schlick F0
        pub f0_min: f32 = 0.02, range = 0.0..=1.0;
        /// Cook-Torrance: largest Schlick F0
        pub f0_max: f32 = 1.0, range = 0.0..=1.0;
        /// Cook-Torrance: F0 values per roughness (2: the ends, which span every F0 between)
        pub f0_count: usize = 2, range = 1..=64;
    }
}

impl BrdfSpaceSample {
    fn grid(&self) -> BrdfGrid {
        BrdfGrid { n_theta_i: self.n_theta_i as u32, n_theta_o: self.n_theta_o as u32, n_phi: self.n_phi as u32 }
    }

    /// The sample list: the diffuse sample, then the specular ones (in increasing s, or
    /// roughness-major in increasing m and F0), or the parameter that makes it impossible.
    pub fn sample_list(&self) -> Result<Vec<BrdfSample>, NodeError> {
        let n = self.samples - 1;
        let order = |lo: f32, hi: f32, a: &str, b: &str| {
            if lo > hi {
                Err(NodeError::param(a, format!("{a} = {lo} is above {b} = {hi}; make {a} ≤ {b}")))
            } else {
                Ok(())
            }
        };
        let specular: Vec<BrdfSample> = match self.model {
            BrdfModel::BlinnPhong => {
                order(self.s_min, self.s_max, "s_min", "s_max")?;
                let exponents = match self.s_spacing {
                    Spacing::Linear => spread(n, self.s_min, self.s_max),
                    Spacing::Geometric if self.s_min > 0.0 => {
                        spread(n, self.s_min.ln(), self.s_max.ln()).into_iter().map(f64::exp).collect()
                    }
                    Spacing::Geometric => {
                        return Err(NodeError::param(
                            "s_min",
                            "s_min = 0 cannot start a geometric spacing; make it positive or use s_spacing: Linear",
                        ))
                    }
                };
                exponents.into_iter().map(|s| BrdfSample::blinn_phong(0.0, 1.0, s as f32)).collect()
            }
            BrdfModel::CookTorrance => {
                order(self.m_min, self.m_max, "m_min", "m_max")?;
                order(self.f0_min, self.f0_max, "f0_min", "f0_max")?;
                if !n.is_multiple_of(self.f0_count) {
                    return Err(NodeError::param(
                        "samples",
                        format!(
                            "a Cook-Torrance space takes samples − 1 = {n} specular samples as roughnesses × {} F0 values; make samples − 1 a multiple of f0_count",
                            self.f0_count
                        ),
                    ));
                }
                let f0 = spread(self.f0_count, self.f0_min, self.f0_max);
                spread(n / self.f0_count, self.m_min, self.m_max)
                    .into_iter()
                    .flat_map(|m| f0.iter().map(move |&f| BrdfSample::cook_torrance(1.0, m as f32, f as f32)))
                    .collect()
            }
        };
        Ok(std::iter::once(BrdfSample::diffuse(1.0)).chain(specular).collect())
    }
}

#[node(category = "relight", version = 2, outputs = [space])]
impl BrdfSpaceSample {
    fn memory(&self, _inputs: &[Option<PortSize>]) -> MemoryEstimate {
        // The table, and one f64 cos δ per cell besides it.
        let g = self.grid();
        MemoryEstimate {
            outputs: vec![Some(PortSize::bytes(BrdfSpace::bytes_for(&g, self.samples as u64)))],
            working: g.cells_u64().saturating_mul(8),
        }
    }

    fn run(&self, cx: &RunCtx) -> Result<BrdfSpace, NodeError> {
        let samples = self.sample_list()?;
        let grid = self.grid();
        let bytes = BrdfSpace::bytes_for(&grid, self.samples as u64);
        if bytes > MAX_BRDF_SPACE_BYTES {
            return Err(NodeError::over_limit(format!(
                "a BRDF space of {} samples on {} × {} × {} cells needs {}, over the {} limit; lower samples, n_theta_i, n_theta_o or n_phi",
                self.samples,
                self.n_theta_i,
                self.n_theta_o,
                self.n_phi,
                fmt_bytes(bytes),
                fmt_bytes(MAX_BRDF_SPACE_BYTES)
            )));
        }
        let cells = grid.cells();
        let cos_h: Vec<f64> = (0..cells)
            .map(|c| {
                let [ti, to, phi] = grid.centre(c);
                cos_half(ti, to, phi)
            })
            .collect();
        let mut values = vec![0.0f32; samples.len() * cells];
        cx.par_chunks_mut(&mut values, cells, |i, table| {
            let p = &samples[i];
            for (c, v) in table.iter_mut().enumerate() {
                *v = if p.is_cook_torrance() { p.eval(grid.centre(c)) } else { p.eval_cos_h(cos_h[c]) } as f32;
            }
        })?;
        Ok(BrdfSpace { grid, samples, values })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::{blinn_phong, cook_torrance};
    use crate::brdf_space::test_support::{ct_space, space};
    use crate::testing::{cancels_midway, f, first, i, id, run_on};
    use glam::Vec3;
    use relume_core::PortValue;

    #[test]
    fn values_are_the_library_blinn_phong_at_cell_centres() {
        let sp = space(6, 5, 8, 11, 1.0, 50.0);
        assert_eq!(sp.samples.len(), 11);
        assert_eq!(sp.samples[0], BrdfSample::diffuse(1.0));
        let s: Vec<f32> = sp.samples[1..].iter().map(|x| x.s).collect();
        let expect: Vec<f32> = (0..10).map(|j| (1.0 + 49.0 * j as f64 / 9.0) as f32).collect();
        assert_eq!(s, expect, "linear in s");
        for (k, smp) in sp.samples.iter().enumerate() {
            for cell in [0, 17, 100, sp.grid.cells() - 1] {
                let [ti, to, phi] = sp.grid.centre(cell);
                let (wi, wo) = BrdfGrid::directions(ti, to, phi);
                let lib = blinn_phong::eval(Vec3::splat(smp.kd), Vec3::splat(smp.ks), smp.s, wo.as_vec3(), wi.as_vec3()).x;
                let got = sp.sample(k)[cell];
                assert!((got - lib).abs() <= 1e-5 * lib.abs().max(1e-3), "sample {k} cell {cell}: {got} vs {lib}");
            }
        }
        // The diffuse sample is 1/π everywhere.
        assert!(sp.sample(0).iter().all(|&v| (v - std::f32::consts::FRAC_1_PI).abs() < 1e-7));
    }

    #[test]
    fn geometric_spacing_keeps_the_ends_and_a_constant_ratio_and_needs_a_positive_start() {
        let exponents = |spacing: &str, s_min: f64| {
            let grid = [("n_theta_i", i(2)), ("n_theta_o", i(2)), ("n_phi", i(2)), ("samples", i(12))];
            let params = [&grid[..], &[("s_min", f(s_min)), ("s_max", f(2048.0)), ("s_spacing", id(spacing))]].concat();
            run_on::<BrdfSpaceSample>(&params, vec![])
                .map(|out| first::<BrdfSpace>(&out).samples[1..].iter().map(|x| x.s as f64).collect::<Vec<_>>())
        };
        let s = exponents("Geometric", 2.0).unwrap();
        assert_eq!((s[0], s[10]), (2.0, 2048.0));
        assert!(s.windows(2).all(|w| (w[1] / w[0] - 2.0).abs() < 1e-5), "each exponent twice the one before: {s:?}");
        assert!(exponents("Linear", 2.0).unwrap()[1] > 200.0, "linear steps leave the broad lobes one sample");
        let e = exponents("Geometric", 0.0).unwrap_err();
        assert!(e.to_string().contains("s_min") && e.to_string().contains("Linear"), "{e}");
    }

    #[test]
    fn the_mirror_peak_is_at_phi_pi() {
        let sp = space(10, 10, 20, 2, 100.0, 100.0);
        let g = sp.grid;
        // For θi = θo, the largest specular value over φ is in the last φ cell.
        for a in 0..10 {
            let row: Vec<f32> = (0..20).map(|c| sp.sample(1)[g.index(a, a, c)]).collect();
            let best = row.iter().enumerate().max_by(|x, y| x.1.total_cmp(y.1)).unwrap().0;
            assert_eq!(best, 19, "θ index {a}: {row:?}");
        }
    }

    #[test]
    fn reruns_and_thread_counts_give_identical_bytes() {
        let run = || space(5, 6, 7, 9, 1.0, 1e4).encode();
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(run);
        assert_eq!(run(), one);
        assert_eq!(run(), run());
    }

    #[test]
    fn extreme_exponents_stay_finite() {
        // docs/QUALITY.md §2: s = 1 and s = 10⁴ (near mirror); s = 0 (constant lobe).
        let sp = space(8, 8, 16, 4, 0.0, 1e4);
        assert!(sp.values.iter().all(|v| v.is_finite() && *v >= 0.0));
        let peak = sp.sample(3).iter().fold(0.0f32, |m, v| m.max(*v));
        assert!(peak > 0.0 && peak <= (1e4 + 2.0) / (8.0 * std::f32::consts::PI) * 1.0001, "{peak}");
    }

    #[test]
    fn bad_ranges_and_oversized_grids_are_refused_before_allocating() {
        let e = run_on::<BrdfSpaceSample>(&[("s_min", f(10.0)), ("s_max", f(5.0))], vec![]).unwrap_err();
        assert!(e.to_string().contains("s_min") && e.to_string().contains("s_max"), "{e}");
        let big = [("n_theta_i", i(1024)), ("n_theta_o", i(1024)), ("n_phi", i(2048)), ("samples", i(2048))];
        let e = run_on::<BrdfSpaceSample>(&big, vec![]).unwrap_err();
        assert!(e.is_over_limit() && e.to_string().contains("16384.00 GiB"), "{e}");
    }

    #[test]
    fn cook_torrance_samples_are_the_library_lobe_roughness_major() {
        let sp = ct_space(6, 7, 2, 0.05, 0.6);
        assert_eq!(sp.samples[0], BrdfSample::diffuse(1.0));
        let want = [(0.05, 0.02), (0.05, 1.0), (0.325, 0.02), (0.325, 1.0), (0.6, 0.02), (0.6, 1.0)];
        for (p, (m, f0)) in sp.samples[1..].iter().zip(want) {
            assert!((p.m - m).abs() < 1e-7 && (p.f0 - f0).abs() < 1e-7, "{p:?} vs ({m}, {f0})");
        }
        for (k, p) in sp.samples.iter().enumerate().skip(1) {
            assert!(p.is_cook_torrance() && (p.kd, p.ks) == (0.0, 1.0));
            for cell in [0, 17, 100, sp.grid.cells() - 1] {
                let [ti, to, phi] = sp.grid.centre(cell);
                let (wi, wo) = BrdfGrid::directions(ti, to, phi);
                let lib = cook_torrance::eval(Vec3::ZERO, Vec3::ONE, p.m, p.f0, wo.as_vec3(), wi.as_vec3()).x;
                let got = sp.sample(k)[cell];
                assert!((got - lib).abs() <= 1e-5 * lib.abs().max(1e-3), "sample {k} cell {cell}: {got} vs {lib}");
            }
        }
    }

    #[test]
    fn the_cook_torrance_lobe_is_linear_in_f0_so_the_ends_span_the_range() {
        // Three F0 values: the middle one's table is the mean of the ends' (Schlick is linear
        // in F0), to f32 rounding.
        let sp = ct_space(6, 7, 3, 0.1, 0.5);
        for m in 0..2 {
            let (lo, mid, hi) = (sp.sample(1 + 3 * m), sp.sample(2 + 3 * m), sp.sample(3 + 3 * m));
            assert!((sp.samples[2 + 3 * m].f0 - 0.51).abs() < 1e-7);
            for c in 0..sp.grid.cells() {
                let mean = 0.5 * (lo[c] as f64 + hi[c] as f64);
                assert!((mid[c] as f64 - mean).abs() <= 1e-6 * mean.abs().max(1e-6), "m {m} cell {c}: {} vs {mean}", mid[c]);
            }
        }
    }

    #[test]
    fn extreme_roughness_and_grazing_cells_stay_finite() {
        // docs/QUALITY.md §2: Cook-Torrance roughness 0.001 and 1, and grazing θ (the outermost
        // cells of a 90-cell axis are at 89.5°).
        let sp = ct_space(90, 5, 2, 0.001, 1.0);
        assert!(sp.values.iter().all(|v| v.is_finite() && *v >= 0.0));
        assert!(sp.sample(1).iter().any(|v| *v > 0.0) && sp.sample(4).iter().any(|v| *v > 0.0));
    }

    #[test]
    fn a_sample_count_that_does_not_split_into_roughnesses_and_f0_values_is_refused() {
        let p = [("model", id("CookTorrance")), ("samples", i(8)), ("f0_count", i(2))];
        let e = run_on::<BrdfSpaceSample>(&p, vec![]).unwrap_err();
        assert!(matches!(&e, NodeError::Param { name, .. } if name == "samples"), "{e}");
        assert!(e.to_string().contains("f0_count"), "{e}");
        let e = run_on::<BrdfSpaceSample>(&[("model", id("CookTorrance")), ("m_min", f(0.7))], vec![]).unwrap_err();
        assert!(matches!(&e, NodeError::Param { name, .. } if name == "m_min"), "{e}");
    }

    #[test]
    fn stops_when_cancelled() {
        cancels_midway::<BrdfSpaceSample>(&[("n_theta_i", i(8)), ("n_theta_o", i(8)), ("n_phi", i(8)), ("samples", i(400))], vec![]);
    }
}
