use crate::types::brdf::{BrdfTensorTable, TuckerBrdf};
use relume_base::math::tucker::{tucker, Tensor3, Tucker};
use relume_base::types::Metrics;
use relume_core::{node, params, MemoryEstimate, NodeError, PortSize, RunCtx};

params! {
    /// Tucker-decomposes a BRDF tensor ([S] 5-3, 5-4): F ≈ D ×_h U^h ×_ωo U^ωo ×_ωi U^ωi, by HOOI
    /// started from the truncated HOSVD (`math/tucker.rs`, f64), into the `TuckerBrdf` a renderer
    /// shades with: u_h(material) (rows interpolated linearly in s, bilinearly on the
    /// Cook-Torrance (m, F0) grid), u_o(ωo) and u_i(ωi) (bilinear over the disk), core_for(u_h)
    /// = D ×_h u_h, and eval. Feed it `SpecularSeparation`'s residual f_r, as [S] does, or the
    /// raw tensor F.
    ///
    /// Ranks: n_h = 3 by default ([S] 5.3.3.1 uses 3 for Blinn-Phong and 4 for its Cook-Torrance
    /// space), n_ωo = n_ωi = 8. A rank above its mode's numerical rank is cut to it (a zero
    /// tensor gives rank 0 and an empty core: every lookup is 0), with a note. HOOI stops when a
    /// sweep gains less than `tolerance` × ‖F‖² or after `max_iterations` sweeps; not converging
    /// is a note and a metric, not an error. Only the sweep limit checks cancellation inside a
    /// decomposition; the node checks between its steps.
    ///
    /// Metrics: `rms_error` = √(Σ (F − F̂)² / (N_h N_ωo N_ωi)), the root mean square over the
    /// tensor entries, as [S] figure 5-5 plots it (from ‖F − F̂‖² = ‖F‖² − ‖D‖², exact for
    /// orthonormal factors); `relative_error` = ‖F − F̂‖ / ‖F‖; `iterations`, `converged` (1/0),
    /// the ranks kept. With `error_grid`, also the RMS error at n_ωi ∈ {4, 8, …, 32} × n_h ∈
    /// {1, …, 6} with n_ωo = n_ωi ([S] figure 5-5) as `grid_rms_nh{a}_nwi{b}` (48 decompositions:
    /// about 3 minutes on one core for the default 200 × 208 × 208 tensor). [S] reports 0.95
    /// without separation at n_h = 6, n_ωi = 32 for its measured Cook-Torrance fits, which calls
    /// it "squared error" without saying over what; relume's numbers are for its own tensors.
    pub struct TuckerDecompose {
        /// rank n_h of the material factor U^h ([S]: 3 Blinn-Phong, 4 Cook-Torrance)
        pub n_h: usize = 3, range = 1..=256;
        /// rank n_ωo of the outgoing-direction factor U^ωo
        pub n_wo: usize = 8, range = 1..=4096;
        /// rank n_ωi of the incoming-direction factor U^ωi
        pub n_wi: usize = 8, range = 1..=4096;
        /// most HOOI sweeps after the HOSVD start
        pub max_iterations: usize = 50, range = 0..=10000;
        /// stop when a sweep gains less than this share of ‖F‖²
        pub tolerance: f64 = 1e-10, range = 0.0..=1.0;
        /// also report the RMS error over n_ωi ∈ {4 … 32} × n_h ∈ {1 … 6} ([S] figure 5-5)
        pub error_grid: bool = false;
    }
}

/// √(mean squared error over the entries) of a decomposition of a tensor of squared norm
/// `norm2` and `entries` entries.
fn rms(d: &Tucker, norm2: f64, entries: usize) -> f64 {
    (d.relative_error * norm2 / entries.max(1) as f64).sqrt()
}

/// Factor rows as one row-major f32 table.
fn flat(rows: &[Vec<f64>]) -> Vec<f32> {
    rows.iter().flatten().map(|&v| v as f32).collect()
}

#[node(category = "ptt", metrics = ["rms_error", "relative_error", "iterations", "converged", "rank_h", "rank_wo", "rank_wi"], outputs = [brdf, metrics])]
impl TuckerDecompose {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        // The f64 copy of the tensor and HOOI's projections and Gram rows (each at most as
        // big again); the output is small beside them.
        let b = inputs[0].map_or(0, |s| s.bytes);
        MemoryEstimate { outputs: vec![Some(PortSize::bytes(b / 16 + 4096)), Some(PortSize::bytes(4096))], working: b.saturating_mul(6) }
    }

    fn run(&self, tensor: &BrdfTensorTable, cx: &RunCtx) -> Result<(TuckerBrdf, Metrics), NodeError> {
        let t = tensor;
        let dims = t.dims();
        if let Some(k) = t.values.iter().position(|v| !v.is_finite()) {
            return Err(NodeError::input("tensor", format!("entry {k} is not finite")));
        }
        let working = (t.values.len() as u64).saturating_mul(48);
        if working > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "decomposing a {dims:?} tensor needs about {}, over the run's memory budget of {}",
                relume_core::memory::fmt_bytes(working),
                relume_core::memory::fmt_bytes(cx.memory_budget())
            )));
        }
        cx.phase(0.0, 0.05);
        let row = dims[1] * dims[2];
        let parts = cx.par_map(dims[0], |h| t.values[h * row..(h + 1) * row].iter().map(|&v| v as f64).collect::<Vec<f64>>())?;
        let tensor = Tensor3 { dims, data: parts.concat() };
        let norm2 = tensor.norm2();
        let entries = tensor.data.len();

        cx.phase(0.05, if self.error_grid { 0.2 } else { 1.0 });
        cx.tick(0, 1)?;
        let asked = [self.n_h, self.n_wo, self.n_wi];
        let d = tucker(&tensor, asked, self.max_iterations, self.tolerance)?;
        cx.tick(1, 1)?;
        let ranks = d.core.dims;
        let brdf = TuckerBrdf {
            family: t.family.clone(),
            disk: t.disk.clone(),
            ranks: ranks.map(|r| r as u32),
            core: d.core.data.iter().map(|&v| v as f32).collect(),
            factor_h: flat(&d.factors[0]),
            factor_o: flat(&d.factors[1]),
            factor_i: flat(&d.factors[2]),
        };

        let mut m = vec![
            ("rms_error".to_string(), rms(&d, norm2, entries)),
            ("relative_error".into(), d.relative_error.sqrt()),
            ("iterations".into(), d.iterations as f64),
            ("converged".into(), if d.converged { 1.0 } else { 0.0 }),
            ("rank_h".into(), ranks[0] as f64),
            ("rank_wo".into(), ranks[1] as f64),
            ("rank_wi".into(), ranks[2] as f64),
        ];
        if !d.converged {
            cx.note(format!(
                "HOOI did not converge in {} sweeps (last gain above {:e} × ‖F‖²); the decomposition is the last sweep's",
                d.iterations, self.tolerance
            ));
        }
        if norm2 == 0.0 {
            cx.note("the tensor is zero: an empty decomposition (rank 0), every lookup gives 0");
        } else if ranks != asked {
            cx.note(format!("ranks {asked:?} cut to {ranks:?}: the tensor's numerical rank (or size) per mode is lower"));
        }

        if self.error_grid {
            cx.phase(0.2, 1.0);
            let grid: Vec<(usize, usize)> = (1..=8).flat_map(|b| (1..=6).map(move |a| (a, 4 * b))).collect();
            let errors = cx.par_try_map(grid.len(), |g| {
                let (a, b) = grid[g];
                tucker(&tensor, [a, b, b], self.max_iterations, self.tolerance).map(|d| rms(&d, norm2, entries))
            })?;
            for ((a, b), e) in grid.into_iter().zip(errors) {
                m.push((format!("grid_rms_nh{a}_nwi{b}"), e));
            }
        }
        for (k, v) in &m {
            cx.metric(k, *v);
        }
        Ok((brdf, Metrics(m)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf_factors::test_support::{decompose, tensor};
    use crate::types::brdf::{BrdfFamily, DiskGrid, MaterialParam};
    use glam::{Quat, Vec3};
    use relume_base::testing::{cancels_midway, f, i, run_on};
    use relume_core::{PortValue, Value};

    #[test]
    fn full_ranks_reproduce_the_tensor() {
        let t = tensor(&[("disk", i(6)), ("samples", i(5)), ("s_max", f(30.0))]);
        let [nh, n, _] = t.dims();
        let (b, m) = decompose(&t, &[("n_h", i(nh as i64)), ("n_wo", i(n as i64)), ("n_wi", i(n as i64))]);
        assert!(m.get("relative_error").unwrap() < 1e-6 && m.get("converged") == Some(1.0), "{m:?}");
        let peak = t.values.iter().fold(0.0f32, |a, &v| a.max(v)) as f64;
        let mut worst = 0.0f64;
        for h in 0..nh {
            for o in 0..n {
                for k in 0..n {
                    worst = worst.max((b.at(h, o, k) - t.at(h, o, k) as f64).abs());
                }
            }
        }
        assert!(worst < 1e-5 * peak, "worst {worst} of peak {peak}");
        // The renderer's path (interpolated rows at a sample's own parameter and directions)
        // gives the same values.
        for (h, o, k) in [(0, 3, 7), (4, 10, t.disk.mirror(10)), (2, n - 1, 0)] {
            let (wo, wi) = (t.disk.direction(o).as_vec3(), t.disk.direction(k).as_vec3());
            let got = b.eval(t.family.param(h), wo, wi).unwrap() as f64;
            assert!((got - t.at(h, o, k) as f64).abs() < 1e-5 * peak, "({h}, {o}, {k}): {got} vs {}", t.at(h, o, k));
        }
        assert_eq!(TuckerBrdf::decode(&b.encode()).unwrap(), b);
    }

    #[test]
    fn u_h_at_an_integer_exponent_is_that_samples_row() {
        let t = tensor(&[("disk", i(8)), ("samples", i(20)), ("s_max", f(20.0))]);
        let (b, _) = decompose(&t, &[]);
        assert_eq!(b.ranks, [3, 8, 8]);
        for s in 1..=20 {
            let row = b.u_h(MaterialParam::BlinnPhong { s: s as f64 }).unwrap();
            assert_eq!(row, b.factor_h[(s - 1) * 3..s * 3].to_vec(), "s = {s}");
        }
        // Halfway between two exponents: the mean of their rows.
        let mid = b.u_h(MaterialParam::BlinnPhong { s: 4.5 }).unwrap();
        for (a, v) in mid.iter().enumerate() {
            let want = 0.5 * (b.factor_h[9 + a] as f64 + b.factor_h[12 + a] as f64);
            assert!((*v as f64 - want).abs() < 1e-6 * want.abs().max(1e-3), "{v} vs {want}");
        }
        assert!(b.u_h(MaterialParam::BlinnPhong { s: 20.5 }).unwrap_err().contains("[1, 20]"));
        // core_for then contract is eval.
        let (wo, wi) = (Vec3::new(0.3, -0.2, 0.9).normalize(), Vec3::new(-0.25, 0.1, 0.95).normalize());
        let u = b.u_h(MaterialParam::BlinnPhong { s: 7.3 }).unwrap();
        let by_hand = b.contract(&b.core_for(&u), &b.u_o(wo), &b.u_i(wi));
        assert_eq!(by_hand as f32, b.eval(MaterialParam::BlinnPhong { s: 7.3 }, wo, wi).unwrap());
        assert_eq!(b.eval(MaterialParam::BlinnPhong { s: 7.3 }, wo, -wi).unwrap(), 0.0, "below the horizon");
    }

    #[test]
    fn turning_both_directions_about_the_normal_leaves_the_value_nearly_unchanged() {
        // Blinn-Phong is isotropic. A quarter turn maps the disk grid onto itself (exact up
        // to f32 rounding); other angles move the directions off the samples and measure the
        // bilinear lookup's error. Measured at n = 16, s 1 … 50, default ranks, s = 10, 2000
        // random pairs (θ up to 78°): 4.6 % relative RMS at random angles, 3.8·10⁻⁷ of the
        // RMS value at most for quarter turns.
        let t = tensor(&[("disk", i(16)), ("samples", i(50)), ("s_max", f(50.0))]);
        let (b, _) = decompose(&t, &[]);
        let p = MaterialParam::BlinnPhong { s: 10.0 };
        let m = b.core_for(&b.u_h(p).unwrap());
        let f = |wo: Vec3, wi: Vec3| b.contract(&m, &b.u_o(wo), &b.u_i(wi));
        let dir = |k: u64, c: u32| {
            let u = relume_base::math::rng::uniform(5, k, c) as f64;
            let v = relume_base::math::rng::uniform(5, k, c + 1) as f64;
            let (z, a) = (0.2 + 0.8 * u, 2.0 * std::f64::consts::PI * v);
            let r = (1.0 - z * z).sqrt();
            Vec3::new((r * a.cos()) as f32, (r * a.sin()) as f32, z as f32)
        };
        let (mut quarter, mut turned, mut norm) = (0.0f64, 0.0f64, 0.0f64);
        for k in 0..2000 {
            let (wo, wi) = (dir(k, 0), dir(k, 2));
            let base = f(wo, wi);
            let q = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
            quarter = quarter.max((f(q * wo, q * wi) - base).abs());
            let r = Quat::from_rotation_z(std::f32::consts::TAU * relume_base::math::rng::uniform(6, k, 0));
            turned += (f(r * wo, r * wi) - base).powi(2);
            norm += base * base;
        }
        let rel = (turned / norm).sqrt();
        let scale = (norm / 2000.0).sqrt();
        assert!(quarter < 1e-5 * scale, "quarter turn: {quarter} of {scale}");
        assert!(rel < 0.06, "any turn: relative RMS {rel}");
    }

    #[test]
    fn the_error_grid_reports_every_rank_pair_and_falls_with_rank() {
        let t = tensor(&[("disk", i(10)), ("samples", i(12)), ("s_max", f(60.0))]);
        let (_, m) = decompose(&t, &[("error_grid", relume_core::ParamValue::Bool(true))]);
        for a in 1..=6 {
            for b in (4..=32).step_by(4) {
                assert!(m.get(&format!("grid_rms_nh{a}_nwi{b}")).is_some(), "nh {a} nwi {b}");
            }
        }
        let g = |a: usize, b: usize| m.get(&format!("grid_rms_nh{a}_nwi{b}")).unwrap();
        assert!(g(1, 4) > g(3, 8) && g(3, 8) > g(6, 32), "{} {} {}", g(1, 4), g(3, 8), g(6, 32));
        assert!((g(3, 8) - m.get("rms_error").unwrap()).abs() < 1e-9 * g(3, 8));
    }

    #[test]
    fn a_zero_tensor_decomposes_to_rank_zero_and_looks_up_zero() {
        let t = BrdfTensorTable {
            family: BrdfFamily::BlinnPhong { s: vec![1.0, 2.0] },
            disk: DiskGrid::new(4),
            values: vec![0.0; 2 * 12 * 12],
        };
        let (b, m) = decompose(&t, &[]);
        assert_eq!(b.ranks, [0, 0, 0]);
        assert_eq!(m.get("rms_error"), Some(0.0));
        assert_eq!(b.eval(MaterialParam::BlinnPhong { s: 1.5 }, Vec3::Z, Vec3::Z), Ok(0.0));
        assert!(b.u_h(MaterialParam::BlinnPhong { s: 1.5 }).unwrap().is_empty());
        let mut nan = t.clone();
        nan.values[5] = f32::NAN;
        let e = run_on::<TuckerDecompose>(&[], vec![Value::new(nan)]).unwrap_err();
        assert!(e.to_string().contains("entry 5"), "{e}");
    }

    #[test]
    fn the_sweep_limit_is_reported_not_refused() {
        let t = tensor(&[("disk", i(8)), ("samples", i(20)), ("s_max", f(100.0))]);
        let (_, m) = decompose(&t, &[("max_iterations", i(1)), ("tolerance", f(0.0))]);
        assert_eq!((m.get("converged"), m.get("iterations")), (Some(0.0), Some(1.0)));
    }

    #[test]
    fn stops_when_cancelled() {
        let t = tensor(&[("disk", i(6)), ("samples", i(40))]);
        cancels_midway::<TuckerDecompose>(&[], vec![Value::new(t)]);
    }
}
