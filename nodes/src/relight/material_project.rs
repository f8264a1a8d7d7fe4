//! MaterialProject node.

use crate::types::{BasisCoefficients, BrdfBasis};
use relume_core::{inputs, node, outputs, NodeError, Params, RunCtx};

/// Projects a Blinn-Phong material (Kd, Ks, s) on a BRDF basis ([S] 4-22): the coefficients
/// are (Kd, Ks c(s)), diffuse first, with c(s) interpolated linearly in s between the basis'
/// sampled exponents. An s outside the sampled range is a parameter error naming the range,
/// never clamped: a clamped exponent would silently render another material (widen
/// `BrdfSpaceSample`'s s_min / s_max instead). With Ks = 0 the exponent plays no part.
/// One object for now; Kd + Ks > 1 ([S] 4-16 asks ≤ 1) is allowed with a note.
#[derive(Params)]
pub struct MaterialProject {
    /// diffuse reflectance Kd
    #[param(default = 0.5, range = 0.0..=1.0)]
    pub kd: f32,
    /// specular reflectance Ks
    #[param(default = 0.5, range = 0.0..=1.0)]
    pub ks: f32,
    /// Blinn-Phong exponent s, within the basis' sampled range
    #[param(default = 20.0, range = 0.0..=1e5)]
    pub s: f32,
}

inputs!(pub MaterialProjectIn { basis: BrdfBasis });
outputs!(pub MaterialProjectOut { coefficients: BasisCoefficients });

#[node(category = "relight")]
impl MaterialProject {
    fn run(&self, i: MaterialProjectIn, cx: &RunCtx) -> Result<MaterialProjectOut, NodeError> {
        let c = i.basis.project(self.kd as f64, self.ks as f64, self.s as f64).map_err(|m| NodeError::param("s", m))?;
        if self.kd + self.ks > 1.0 {
            cx.note(format!(
                "Kd + Ks = {} > 1: the material reflects more light than it receives ([S] 4-16 asks Kd + Ks ≤ 1)",
                self.kd + self.ks
            ));
        }
        Ok(MaterialProjectOut { coefficients: BasisCoefficients(c) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::relight::test_support::{basis, space};
    use crate::testing::{f, first, run_full, run_on};
    use crate::types::BrdfSample;
    use relume_core::Value;
    use std::f64::consts::PI;
    use std::path::Path;

    fn project(b: &BrdfBasis, kd: f64, ks: f64, s: f64) -> Result<Vec<f64>, NodeError> {
        run_on::<MaterialProject>(&[("kd", f(kd)), ("ks", f(ks)), ("s", f(s))], vec![Value::new(b.clone())])
            .map(|o| first::<BasisCoefficients>(&o).0)
    }

    #[test]
    fn the_diffuse_material_projects_to_the_first_basis_alone() {
        let (b, _) = basis(&space(6, 6, 12, 20, 1.0, 200.0), 6);
        assert_eq!(project(&b, 1.0, 0.0, 20.0).unwrap(), vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        // Ks = 0: the exponent does not matter, even outside the sampled range.
        assert_eq!(project(&b, 0.25, 0.0, 5000.0).unwrap(), vec![0.25, 0.0, 0.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn sampled_exponents_give_their_table_row_and_others_interpolate() {
        let (b, _) = basis(&space(6, 6, 12, 5, 10.0, 40.0), 4);
        assert_eq!(b.s_values, vec![10.0, 20.0, 30.0, 40.0]);
        let row = |j: usize| b.coefficients[j * 3..(j + 1) * 3].to_vec();
        let c = project(&b, 0.0, 1.0, 20.0).unwrap();
        assert!(c[1..].iter().zip(row(1)).all(|(a, b)| (a - b).abs() < 1e-15), "{c:?} vs {:?}", row(1));
        let c = project(&b, 0.2, 0.5, 25.0).unwrap();
        for k in 0..3 {
            let want = 0.5 * (0.5 * row(1)[k] + 0.5 * row(2)[k]);
            assert!((c[k + 1] - want).abs() < 1e-12);
        }
        assert_eq!(c[0], 0.2f32 as f64);
    }

    #[test]
    fn an_exponent_outside_the_sampled_range_is_a_parameter_error_naming_it() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 200.0), 4);
        let e = project(&b, 0.0, 1.0, 250.0).unwrap_err();
        assert!(matches!(&e, NodeError::Param { name, .. } if name == "s"), "{e}");
        assert!(e.to_string().contains("[1, 200]"), "{e}");
        assert!(project(&b, 0.0, 1.0, 0.5).is_err());
    }

    #[test]
    fn the_extreme_exponents_one_and_ten_thousand_project_finitely() {
        // QUALITY.md §2: s = 1 and s = 10⁴ materials, at the ends of the sampled range.
        let (b, _) = basis(&space(10, 10, 20, 40, 1.0, 1e4), 6);
        for s in [1.0, 1e4] {
            let c = project(&b, 0.3, 0.7, s).unwrap();
            assert!(c.iter().all(|v| v.is_finite()) && c.len() == 6, "{c:?}");
        }
    }

    #[test]
    fn kd_plus_ks_one_keeps_the_rebuilt_albedo_at_most_one_and_near_the_analytic_one() {
        // QUALITY.md §2 (furnace): Kd + Ks = 1. The directional albedo ∫ f cos θi dωi of the
        // basis sum stays ≤ 1 and follows the analytic BRDF's (which conserves energy) within
        // the basis error (relative to Kd + Ks), at normal, oblique and grazing θo.
        let (b, m) = basis(&space(24, 24, 48, 60, 1.0, 60.0), 6);
        let max_err = m.get("l2_error_max_pct").unwrap() / 100.0;
        let g = b.grid;
        let band = |k: u32, n: u32| {
            let d = std::f64::consts::FRAC_PI_2 / n as f64;
            (k as f64 * d).cos() - ((k + 1) as f64 * d).cos()
        };
        for (kd, ks, s) in [(1.0, 0.0, 1.0), (0.5, 0.5, 10.0), (0.0, 1.0, 1.0), (0.0, 1.0, 60.0), (0.2, 0.8, 33.3)] {
            let c = project(&b, kd, ks, s).unwrap();
            let material = BrdfSample { kd: kd as f32, ks: ks as f32, s: s as f32 };
            for bo in [0u32, 12, 23] {
                // Over θi and φ of one θo row: 2 (folded φ) × Σ f cos θi × band(θi) × Δφ.
                let (mut fit, mut exact) = (0.0, 0.0);
                for a in 0..g.n_theta_i {
                    for ph in 0..g.n_phi {
                        let cell = g.index(a, bo, ph);
                        let measure = 2.0 * g.centre(cell)[0].cos() * band(a, g.n_theta_i) * PI / g.n_phi as f64;
                        fit += measure * (0..b.bases()).map(|k| c[k] * b.table(k)[cell] as f64).sum::<f64>();
                        exact += measure * material.eval(g.centre(cell));
                    }
                }
                assert!(fit.is_finite() && fit <= 1.0 + 1e-3, "({kd}, {ks}, {s}) θo row {bo}: albedo {fit}");
                // An integral of the residual, bounded by the basis error on the material's scale.
                assert!((fit - exact).abs() <= max_err * (kd + ks) + 1e-4, "({kd}, {ks}, {s}) θo row {bo}: {fit} vs {exact}");
            }
        }
    }

    #[test]
    fn kd_plus_ks_over_one_is_noted() {
        let (b, _) = basis(&space(4, 4, 8, 4, 1.0, 10.0), 3);
        let e = run_full::<MaterialProject>(&[("kd", f(0.8)), ("ks", f(0.8)), ("s", f(5.0))], Path::new("."), vec![Value::new(b)]).unwrap();
        assert!(e.notes.iter().any(|n| n.contains("> 1")), "{:?}", e.notes);
    }
}
