use crate::math::pca::uncentred_pca_with;
use crate::types::{BasisFamily, BrdfBasis, BrdfSample, BrdfSpace, Metrics};
use relume_core::{node, params, MemoryEstimate, NodeError, ParamEnum, PortSize, RunCtx};

params! {
    /// N_b basis BRDFs from a BRDF space ([S] 4-19 … 4-22). Basis 1 is the diffuse sample itself
    /// (divided by its kd: the table 1/π, so a material's diffuse coefficient is its Kd); bases
    /// 2 … N_b are the leading N_b − 1 components of an uncentred PCA (no mean subtracted, [S]
    /// 4-20) of the specular samples, each divided by its ks (`math/pca.rs`: Gram route in f64,
    /// decreasing eigenvalue, largest entry positive, so re-runs give identical bytes). The
    /// specular samples get no diffuse coefficient ([S] 4-21); their coefficients on bases 2 …
    /// form the table c(s) that `MaterialProject` interpolates linearly in s ([S] 4-22). From a
    /// Cook-Torrance space (`BrdfSpaceSample`'s `model`) the basis keeps no table but the range of
    /// roughness and F0 it was sampled over: `MaterialProject` fits each material on it. A
    /// rank-deficient sample set (all exponents equal, duplicated samples) gives fewer bases,
    /// with a note.
    ///
    /// Weighting: by default every (θi, θo, φ) cell counts alike (`Uniform`), as [S] does by
    /// flattening its uniformly sampled tensor into a vector; `SolidAngle` counts each cell with
    /// its solid angle (dωi dωo), the measure a renderer integrates against. `normalise` scales
    /// each specular sample to unit norm (under the weighting) before the PCA, so that every
    /// exponent counts alike; without it the raw samples are used and the tall lobes of large s
    /// dominate (at the thesis' setting the s = 1 sample is then rebuilt with 22 % error).
    /// Measured at that setting (30 × 30 × 60, s = 1 … 200, N_b = 6): the defaults (`Uniform` +
    /// `normalise`) give a total error of 0.799 % and a max of 6.77 % (mean 0.89 %), against
    /// [S]'s "0.7979 %, the largest single sample 6.747 %": [S] most likely normalised its
    /// samples, weighted cells alike and quoted the total. `SolidAngle` gives mean 1.18 %, max
    /// 8.85 %, total 1.07 % in its own norm; in the relit images of ring and cornell-bunny the
    /// uniform basis is lower or equal at 7 and 8 bases in every exponent setting, and passes
    /// more pixels of the relighting z-test.
    ///
    /// Metrics: the relative L2 reconstruction error ‖f − f̂‖ / ‖f‖ of each specular sample, in %
    /// (f̂ rebuilt from the f32 tables as output): `l2_error_mean_pct` / `_max_pct` over the
    /// samples and `_total_pct` over all of them at once, under the chosen weighting, and the same
    /// mean and max under each weighting (`solid_angle_…`, `uniform_…`); the bases, the numerical
    /// rank of the specular set and the share of its energy (Σ eigenvalues, of the samples as the
    /// PCA saw them) the bases keep.
    pub struct BrdfPca {
        /// number of bases N_b, the diffuse one included
        pub bases: usize = 6, range = 2..=32;
        /// how grid cells count in the PCA and its error: all alike as in [S], or by solid angle
        pub weighting: Weighting = Uniform;
        /// scale each specular sample to unit norm before the PCA, so every exponent counts alike
        pub normalise: bool = true;
    }
}

/// How `BrdfPca` weighs the grid cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum Weighting {
    /// each cell's solid angle dωi dωo (see `BrdfGrid::weights`)
    SolidAngle,
    /// every (θi, θo, φ) cell alike, as [S] flattens its tensor
    Uniform,
}

/// Per specular sample: ‖f − f̂‖² and ‖f‖² under the solid-angle and the uniform weight.
#[derive(Clone, Copy, Default)]
struct SampleError {
    err_w: f64,
    norm_w: f64,
    err_u: f64,
    norm_u: f64,
}

/// ‖f − f̂‖ / ‖f‖ in % (0 for a zero sample, which the PCA rebuilds exactly).
fn pct(err: f64, norm: f64) -> f64 {
    if norm > 0.0 {
        100.0 * (err / norm).sqrt()
    } else {
        0.0
    }
}

/// Mean and max of per-sample errors.
fn mean_max(v: &[f64]) -> (f64, f64) {
    (v.iter().sum::<f64>() / v.len().max(1) as f64, v.iter().fold(0.0, |a, &b| a.max(b)))
}

/// The checks on the input `BrdfPca` relies on, and the specular samples' family.
fn check_space(space: &BrdfSpace) -> Result<BasisFamily, NodeError> {
    let bad = |msg: String| Err(NodeError::input("space", msg));
    let Some(d) = space.samples.first() else { return bad("holds no samples".into()) };
    if !d.is_diffuse() || d.is_cook_torrance() {
        return bad(format!(
            "sample 1 must be the diffuse sample (kd > 0, ks = 0), as BrdfSpaceSample makes it; it is (kd {}, ks {}, s {}, m {})",
            d.kd, d.ks, d.s, d.m
        ));
    }
    if space.samples.len() < 2 {
        return bad("holds no specular sample; give BrdfSpaceSample samples ≥ 2".into());
    }
    let ct = space.samples[1].is_cook_torrance();
    for (j, p) in space.samples.iter().enumerate().skip(1) {
        let finite = p.s.is_finite() && p.m.is_finite() && p.f0.is_finite();
        if !(p.kd == 0.0 && p.ks > 0.0 && p.ks.is_finite() && finite) {
            return bad(format!(
                "sample {} must be specular (kd = 0, ks > 0, finite parameters); it is (kd {}, ks {}, s {}, m {}, F0 {})",
                j + 1,
                p.kd,
                p.ks,
                p.s,
                p.m,
                p.f0
            ));
        }
        if p.is_cook_torrance() != ct {
            return bad(format!(
                "sample {} is not of sample 2's model: the specular samples must be all Blinn-Phong or all Cook-Torrance",
                j + 1
            ));
        }
        if !ct && j > 1 && p.s < space.samples[j - 1].s {
            return bad(format!(
                "the specular samples must come in non-decreasing s; sample {} has s {} after {}",
                j + 1,
                p.s,
                space.samples[j - 1].s
            ));
        }
    }
    if let Some(k) = space.values.iter().position(|v| !v.is_finite()) {
        return bad(format!("value {k} of the table is not finite"));
    }
    if !ct {
        return Ok(BasisFamily::BlinnPhong);
    }
    let range = |f: fn(&BrdfSample) -> f32| {
        let v = space.samples[1..].iter().map(|p| f(p) as f64);
        [v.clone().fold(f64::INFINITY, f64::min), v.fold(f64::NEG_INFINITY, f64::max)]
    };
    Ok(BasisFamily::CookTorrance { m: range(|p| p.m), f0: range(|p| p.f0) })
}

#[node(category = "relight", version = 2, metrics = ["bases", "specular_samples", "specular_rank", "l2_error_mean_pct", "l2_error_max_pct", "l2_error_total_pct", "solid_angle_l2_error_mean_pct", "solid_angle_l2_error_max_pct", "uniform_l2_error_mean_pct", "uniform_l2_error_max_pct", "energy_kept_pct"], outputs = [basis, metrics])]
impl BrdfPca {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        // The basis holds at most as many tables as the space has samples (its rank bounds
        // them), so at most the input's bytes; the normalised copy of the samples as much
        // again; the f64 components before conversion at most twice that; the Gram matrix
        // (N² f64) is small beside them.
        let b = inputs[0].map_or(0, |s| s.bytes);
        MemoryEstimate { outputs: vec![Some(PortSize::bytes(b)), Some(PortSize::bytes(1024))], working: b.saturating_mul(3) }
    }

    fn run(&self, space: &BrdfSpace, cx: &RunCtx) -> Result<(BrdfBasis, Metrics), NodeError> {
        let family = check_space(space)?;
        let (grid, cells) = (space.grid, space.grid.cells());
        let spec = &space.samples[1..];
        let solid = grid.weights();
        let weights = match self.weighting {
            Weighting::SolidAngle => solid.clone(),
            Weighting::Uniform => vec![1.0; cells],
        };
        let raw = &space.values[cells..];
        // Each sample's norm under the weighting (1 when not normalising, or for a zero sample).
        let norms: Vec<f64> = cx.par_map(spec.len(), |j| {
            let n = if self.normalise {
                crate::math::pca::weighted_dot(&raw[j * cells..(j + 1) * cells], &weights, &raw[j * cells..(j + 1) * cells]).sqrt()
            } else {
                1.0
            };
            if n > 0.0 && n.is_finite() {
                n
            } else {
                1.0
            }
        })?;
        let scaled: Vec<f32>;
        let rows: &[f32] = if self.normalise {
            scaled = raw.iter().enumerate().map(|(l, &v)| (v as f64 / norms[l / cells]) as f32).collect();
            &scaled
        } else {
            raw
        };
        let pca = uncentred_pca_with(rows, spec.len(), &weights, self.bases - 1, cx, (0.0, 0.85))?;
        let k = pca.components();

        // Tables: the diffuse sample per unit kd, then the components.
        let kd = space.samples[0].kd as f64;
        let mut tables: Vec<f32> = space.sample(0).iter().map(|&v| (v as f64 / kd) as f32).collect();
        tables.extend(pca.components.iter().map(|&v| v as f32));
        let coefficients: Vec<f64> = (0..spec.len())
            .flat_map(|j| {
                let scale = norms[j] / spec[j].ks as f64;
                pca.coefficients_of(j).iter().map(move |c| c * scale)
            })
            .collect();
        // A Blinn-Phong basis keeps c(s_j) as its table; a Cook-Torrance one keeps no table.
        let bp = family == BasisFamily::BlinnPhong;
        let basis = BrdfBasis {
            grid,
            family,
            tables,
            s_values: if bp { spec.iter().map(|p| p.s as f64).collect() } else { vec![] },
            coefficients: if bp { coefficients.clone() } else { vec![] },
            eigenvalues: pca.eigenvalues.clone(),
        };

        // Reconstruction errors from the tables as output, each sum in cell order.
        cx.phase(0.85, 1.0);
        let errors = cx.par_map(spec.len(), |j| {
            let c = &coefficients[j * k..(j + 1) * k];
            let ks = spec[j].ks as f64;
            let f = space.sample(j + 1);
            let mut e = SampleError::default();
            for l in 0..cells {
                let fit: f64 = ks * (0..k).map(|b| c[b] * basis.table(b + 1)[l] as f64).sum::<f64>();
                let (v, d) = (f[l] as f64, f[l] as f64 - fit);
                e.err_w += solid[l] * d * d;
                e.norm_w += solid[l] * v * v;
                e.err_u += d * d;
                e.norm_u += v * v;
            }
            e
        })?;
        let per_w: Vec<f64> = errors.iter().map(|e| pct(e.err_w, e.norm_w)).collect();
        let per_u: Vec<f64> = errors.iter().map(|e| pct(e.err_u, e.norm_u)).collect();
        let sum = |f: fn(&SampleError) -> f64| errors.iter().map(f).sum::<f64>();
        let ((mean_w, max_w), (mean_u, max_u)) = (mean_max(&per_w), mean_max(&per_u));
        let total_w = pct(sum(|e| e.err_w), sum(|e| e.norm_w));
        let total_u = pct(sum(|e| e.err_u), sum(|e| e.norm_u));
        let (mean, max, total) = match self.weighting {
            Weighting::SolidAngle => (mean_w, max_w, total_w),
            Weighting::Uniform => (mean_u, max_u, total_u),
        };
        let kept: f64 = pca.eigenvalues.iter().sum();
        let all: f64 = pca.spectrum.iter().filter(|l| **l > 0.0).sum();
        let m = Metrics(vec![
            ("bases".into(), basis.bases() as f64),
            ("specular_samples".into(), spec.len() as f64),
            ("specular_rank".into(), pca.rank as f64),
            ("l2_error_mean_pct".into(), mean),
            ("l2_error_max_pct".into(), max),
            ("l2_error_total_pct".into(), total),
            ("solid_angle_l2_error_mean_pct".into(), mean_w),
            ("solid_angle_l2_error_max_pct".into(), max_w),
            ("uniform_l2_error_mean_pct".into(), mean_u),
            ("uniform_l2_error_max_pct".into(), max_u),
            ("energy_kept_pct".into(), if all > 0.0 { 100.0 * kept / all } else { 100.0 }),
        ]);
        for (name, v) in &m.0 {
            cx.metric(name, *v);
        }
        if basis.bases() < self.bases {
            cx.note(format!(
                "the {} specular samples have numerical rank {} (eigenvalues under 1e-12 × the largest dropped): {} bases instead of the {} asked for",
                spec.len(),
                pca.rank,
                basis.bases(),
                self.bases
            ));
        }
        Ok((basis, m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::blinn_phong;
    use crate::brdf_space::brdf_space_sample::BrdfSpaceSample;
    use crate::brdf_space::test_support::{basis, ct_space, space, space_of};
    use crate::math::rng::uniform;
    use crate::testing::{cancels_midway, first, i, id, run_full, run_on};
    use crate::types::BrdfGrid;
    use glam::Vec3;
    use relume_core::{ParamValue, PortValue, Value};
    use std::f64::consts::PI;
    use std::path::Path;

    /// The directions of cell `cell`'s centre, turned about the normal by a random angle and
    /// with a random sign of the relative azimuth (the lookup there has weight 1 on the cell).
    fn centre_directions(g: &BrdfGrid, cell: usize, seed: u64) -> (Vec3, Vec3) {
        let [ti, to, phi] = g.centre(cell);
        let rot = 2.0 * PI * uniform(seed, cell as u64, 1) as f64;
        let sign = if uniform(seed, cell as u64, 2) < 0.5 { -1.0 } else { 1.0 };
        let dir = |t: f64, a: f64| Vec3::new((t.sin() * a.cos()) as f32, (t.sin() * a.sin()) as f32, t.cos() as f32);
        (dir(ti, rot + sign * phi), dir(to, rot))
    }

    /// Relative L2 difference in % of `f` (basis sum, reference) over every cell centre,
    /// solid-angle weighted: the norm `BrdfPca` reports its error in.
    fn at_centres(g: &BrdfGrid, seed: u64, f: impl Fn(Vec3, Vec3) -> (f64, f64)) -> f64 {
        let w = g.weights();
        let (mut e, mut n) = (0.0, 0.0);
        for (cell, wc) in w.iter().enumerate() {
            let (wi, wo) = centre_directions(g, cell, seed);
            let (got, want) = f(wi, wo);
            e += wc * (got - want) * (got - want);
            n += wc * want * want;
        }
        100.0 * (e / n).sqrt()
    }

    /// A random pair of directions, uniform in solid angle over both hemispheres.
    fn random_directions(seed: u64, n: u64) -> (Vec3, Vec3) {
        let dir = |k: u32| {
            let z = uniform(seed, n, k) as f64;
            let a = 2.0 * PI * uniform(seed, n, k + 1) as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            Vec3::new((r * a.cos()) as f32, (r * a.sin()) as f32, z.max(1e-4) as f32)
        };
        (dir(0), dir(2))
    }

    /// Relative RMS difference in % of `f` (value, reference) over `n` random direction pairs.
    fn at_random(n: u64, seed: u64, f: impl Fn(Vec3, Vec3) -> (f64, f64)) -> f64 {
        let (mut e, mut w) = (0.0, 0.0);
        for k in 0..n {
            let (wi, wo) = random_directions(seed, k);
            let (got, want) = f(wi, wo);
            e += (got - want) * (got - want);
            w += want * want;
        }
        100.0 * (e / w).sqrt()
    }

    /// The library's Blinn-Phong (kd = 0, ks = 1, s) at (ωi, ωo).
    fn analytic(s: f32, wi: Vec3, wo: Vec3) -> f64 {
        blinn_phong::eval(Vec3::ZERO, Vec3::ONE, s, wo, wi).x as f64
    }

    #[test]
    fn the_basis_sum_reproduces_analytic_blinn_phong_within_the_reported_error() {
        let sp = space(16, 16, 32, 40, 1.0, 40.0);
        let (b, m) = basis(&sp, 6);
        assert_eq!(b.bases(), 6);
        let (mean, max) = (m.get("l2_error_mean_pct").unwrap(), m.get("l2_error_max_pct").unwrap());
        assert!(mean > 0.0 && mean < max && max < 25.0, "mean {mean} max {max}");
        for s in [1.0f32, 10.0, 40.0] {
            let c = b.project(0.0, 1.0, s as f64).unwrap();
            // At cell centres the sum is the PCA fit of the table: its error is the PCA's.
            let centres = at_centres(&b.grid, 11, |wi, wo| (b.eval_sum(&c, wi, wo), analytic(s, wi, wo)));
            assert!(centres <= max * 1.001, "s {s}: {centres} % at centres, reported max {max} %");
            // Anywhere: the PCA error plus the table's own interpolation error, measured with
            // the exact table of this material.
            let exact = space(16, 16, 32, 2, s, s);
            let table = at_random(4000, 12, |wi, wo| (exact.grid.trilinear(wi, wo).unwrap().apply(exact.sample(1)), analytic(s, wi, wo)));
            let anywhere = at_random(4000, 12, |wi, wo| (b.eval_sum(&c, wi, wo), analytic(s, wi, wo)));
            assert!(anywhere <= table + 1.5 * max, "s {s}: {anywhere} % vs table {table} % + PCA {max} %");
        }
        // Between sampled exponents c(s) is interpolated linearly: still within the error.
        let c = b.project(0.0, 1.0, 12.5).unwrap();
        let mid = at_centres(&b.grid, 13, |wi, wo| (b.eval_sum(&c, wi, wo), analytic(12.5, wi, wo)));
        assert!(mid <= max, "s 12.5: {mid} % (max at the samples {max} %)");
    }

    #[test]
    fn bases_are_orthonormal_under_their_weighting_and_the_diffuse_one_is_one_over_pi() {
        let sp = space(8, 8, 16, 30, 1.0, 60.0);
        let (b, _) = basis(&sp, 5);
        let solid = run_on::<BrdfPca>(&[("bases", i(5)), ("weighting", id("SolidAngle"))], vec![Value::new(sp.clone())]).unwrap();
        let solid = solid[0].get::<BrdfBasis>().unwrap();
        for (b, w) in [(&b, vec![1.0; b.grid.cells()]), (solid, solid.grid.weights())] {
            for p in 1..5 {
                for q in 1..5 {
                    let d: f64 = (0..b.grid.cells()).map(|l| w[l] * b.table(p)[l] as f64 * b.table(q)[l] as f64).sum();
                    assert!((d - if p == q { 1.0 } else { 0.0 }).abs() < 1e-5, "⟨{p}, {q}⟩ = {d}");
                }
            }
        }
        assert!(b.table(0).iter().all(|&v| v == std::f32::consts::FRAC_1_PI));
        assert!(b.eigenvalues.windows(2).all(|e| e[0] >= e[1]));
        // Higher bases have negative lobes.
        assert!(b.table(2).iter().any(|v| *v < 0.0));
    }

    #[test]
    fn reruns_and_thread_counts_give_identical_bytes() {
        let sp = space(6, 6, 12, 25, 1.0, 200.0);
        let run = || basis(&sp, 6).0.encode();
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(run);
        let three = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap().install(run);
        assert_eq!(one, three);
        assert_eq!(run(), run());
    }

    #[test]
    fn exponents_up_to_ten_thousand_give_finite_bases_and_bounded_errors() {
        // docs/QUALITY.md §2: PCA over s ∈ [1, 10⁴] (ill-conditioned: narrow lobes on a coarse grid).
        let sp = space(10, 10, 20, 60, 1.0, 1e4);
        let (b, m) = basis(&sp, 8);
        assert_eq!(b.bases(), 8);
        assert!(b.tables.iter().all(|v| v.is_finite()) && b.coefficients.iter().all(|c| c.is_finite()));
        for name in ["l2_error_mean_pct", "l2_error_max_pct", "l2_error_total_pct", "uniform_l2_error_max_pct"] {
            let v = m.get(name).unwrap();
            // An orthogonal projection never has more than 100 % error (f32 tables: a hair more).
            assert!(v.is_finite() && (0.0..=100.01).contains(&v), "{name} {v}");
        }
        for s in [1.0, 5000.5, 1e4] {
            assert!(b.project(0.5, 0.5, s).unwrap().iter().all(|c| c.is_finite()));
        }
    }

    #[test]
    fn rank_deficient_sample_sets_give_fewer_bases_with_a_note() {
        // All specular samples equal: rank 1, so 2 bases whatever was asked.
        let sp = space(6, 6, 10, 12, 30.0, 30.0);
        let e = run_full::<BrdfPca>(&[("bases", i(6))], Path::new("."), vec![Value::new(sp.clone())]).unwrap();
        let b = e.outputs[0].get::<BrdfBasis>().unwrap();
        assert_eq!(b.bases(), 2);
        assert!(e.notes.iter().any(|n| n.contains("rank 1") && n.contains("2 bases instead of the 6")), "{:?}", e.notes);
        let m = e.outputs[1].get::<Metrics>().unwrap();
        assert!(m.get("l2_error_max_pct").unwrap() < 1e-4, "one direction rebuilds every sample");
        assert!(b.tables.iter().all(|v| v.is_finite()));
        // Duplicated samples in a larger set: the rank is that of the distinct ones.
        let dup = space_of(6, 6, 10, &[5.0, 5.0, 27.5, 27.5, 27.5, 50.0, 50.0]);
        let (b, _) = basis(&dup, 10);
        assert_eq!(b.bases(), 4, "3 distinct exponents");
        assert!(b.project(0.0, 1.0, 20.0).unwrap().iter().all(|c| c.is_finite()));
    }

    #[test]
    fn one_specular_sample_is_rebuilt_exactly() {
        let sp = space(8, 8, 16, 2, 20.0, 20.0);
        let (b, m) = basis(&sp, 6);
        assert_eq!(b.bases(), 2);
        assert!(m.get("l2_error_max_pct").unwrap() < 1e-4);
        let c = b.project(0.0, 1.0, 20.0).unwrap();
        for l in 0..b.grid.cells() {
            let fit = c[1] * b.table(1)[l] as f64;
            assert!((fit - sp.sample(1)[l] as f64).abs() <= 1e-5 * (sp.sample(1)[l] as f64).max(1e-3));
        }
    }

    #[test]
    fn a_space_without_the_diffuse_sample_first_is_refused() {
        let mut sp = space(4, 4, 4, 3, 1.0, 2.0);
        sp.samples.swap(0, 1);
        let e = run_full::<BrdfPca>(&[], Path::new("."), vec![Value::new(sp)]).unwrap_err();
        assert!(e.to_string().contains("sample 1 must be the diffuse sample"), "{e}");
        let mut sp = space(4, 4, 4, 3, 1.0, 2.0);
        sp.samples[2] = BrdfSample::blinn_phong(0.0, 1.0, 0.5);
        let e = run_full::<BrdfPca>(&[], Path::new("."), vec![Value::new(sp)]).unwrap_err();
        assert!(e.to_string().contains("non-decreasing s"), "{e}");
        let mut sp = space(4, 4, 4, 3, 1.0, 2.0);
        sp.values[40] = f32::NAN;
        assert!(run_full::<BrdfPca>(&[], Path::new("."), vec![Value::new(sp)]).unwrap_err().to_string().contains("not finite"));
    }

    #[test]
    fn a_cook_torrance_space_gives_a_basis_with_its_ranges_and_no_table() {
        let sp = ct_space(8, 21, 2, 0.1, 0.6);
        let (b, m) = basis(&sp, 8);
        assert_eq!(b.family, BasisFamily::CookTorrance { m: [0.1f32 as f64, 0.6f32 as f64], f0: [0.02f32 as f64, 1.0] });
        assert!(b.s_values.is_empty() && b.coefficients.is_empty(), "no c(s) table");
        assert_eq!((b.bases(), b.eigenvalues.len()), (8, 7));
        assert!(b.specular_coefficients(20.0).unwrap_err().contains("Cook-Torrance"));
        // The reported errors are those of the samples rebuilt from the tables: a sample's
        // least-squares fit under the solid angle is its PCA projection, as good or better.
        let (mean, max) = (m.get("l2_error_mean_pct").unwrap(), m.get("l2_error_max_pct").unwrap());
        assert!(mean > 0.0 && mean <= max && max < 30.0, "mean {mean} max {max}");
        let (_, err) = b.fit_specular(|a| sp.samples[7].eval(a));
        assert!(err.is_finite() && err < 0.3, "{err}");
        // A decoded basis keeps its family.
        assert_eq!(BrdfBasis::decode(&b.encode()).unwrap(), b);
    }

    #[test]
    fn a_space_mixing_blinn_phong_and_cook_torrance_samples_is_refused() {
        let mut sp = ct_space(4, 5, 2, 0.1, 0.6);
        sp.samples[3] = BrdfSample::blinn_phong(0.0, 1.0, 10.0);
        let e = run_full::<BrdfPca>(&[], Path::new("."), vec![Value::new(sp)]).unwrap_err();
        assert!(e.to_string().contains("all Blinn-Phong or all Cook-Torrance"), "{e}");
    }

    #[test]
    fn stops_when_cancelled() {
        cancels_midway::<BrdfPca>(&[], vec![Value::new(space(8, 8, 16, 200, 1.0, 200.0))]);
    }

    #[test]
    fn normalising_evens_out_the_error_over_exponents() {
        let sp = space(12, 12, 24, 40, 1.0, 200.0);
        let run = |weighting: &str, normalise: bool| {
            let p = [("bases", i(4)), ("weighting", id(weighting)), ("normalise", ParamValue::Bool(normalise))];
            run_on::<BrdfPca>(&p, vec![Value::new(sp.clone())]).unwrap()[1].get::<Metrics>().unwrap().clone()
        };
        let (raw, even) = (run("SolidAngle", false), run("SolidAngle", true));
        assert!(even.get("l2_error_max_pct").unwrap() < raw.get("l2_error_max_pct").unwrap(), "{raw:?} {even:?}");
        let uniform = run("Uniform", true);
        assert_eq!(uniform.get("l2_error_max_pct"), uniform.get("uniform_l2_error_max_pct"));
        assert_eq!(even.get("l2_error_max_pct"), even.get("solid_angle_l2_error_max_pct"));
        // Each PCA is best in its own norm (up to the f32 tables).
        assert!(uniform.get("uniform_l2_error_mean_pct").unwrap() <= even.get("uniform_l2_error_mean_pct").unwrap() * 1.01);
    }

    /// The thesis' setting: 30 × 30 × 60, N_s = 201, s ∈ [1, 200], N_b = 6 (release only:
    /// 11 M table values). The figures are printed for the record; the bounds are loose.
    #[test]
    #[cfg_attr(debug_assertions, ignore = "release only: the full-size BRDF space")]
    fn the_default_space_at_six_bases() {
        let t = std::time::Instant::now();
        let sp: BrdfSpace = first(&run_on::<BrdfSpaceSample>(&[], vec![]).unwrap());
        let t_space = t.elapsed();
        let e = run_full::<BrdfPca>(&[], Path::new("."), vec![Value::new(sp.clone())]).unwrap();
        let t_all = t.elapsed();
        let m = e.outputs[1].get::<Metrics>().unwrap();
        println!("BrdfSpaceSample {:.3} s, BrdfPca {:.3} s\n{}", t_space.as_secs_f64(), (t_all - t_space).as_secs_f64(), m.to_json());
        let b = e.outputs[0].get::<BrdfBasis>().unwrap();
        assert_eq!((b.bases(), b.grid.cells(), b.s_values.len()), (6, 54_000, 200));
        let (mean, max) = (m.get("l2_error_mean_pct").unwrap(), m.get("l2_error_max_pct").unwrap());
        assert!(mean < 2.0 && max < 12.0, "mean {mean} max {max}");
        assert_eq!(b.project(1.0, 0.0, 100.0).unwrap(), vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        // [S]'s weighting (every cell alike, samples normalised) is the default: near its
        // 0.7979 % / 6.747 %; by solid angle, its own norm's mean 1.18 %, max 8.85 %.
        assert!(mean < 1.0 && max < 7.5 && m.get("l2_error_total_pct").unwrap() < 0.85, "{}", m.to_json());
        let sa = run_on::<BrdfPca>(&[("weighting", id("SolidAngle"))], vec![Value::new(sp)]).unwrap()[1].get::<Metrics>().unwrap().clone();
        println!("SolidAngle:\n{}", sa.to_json());
        assert!(sa.get("l2_error_mean_pct").unwrap() < 1.5 && sa.get("l2_error_max_pct").unwrap() < 10.0);
    }
}
