//! MaterialProject node.

use crate::types::{BrdfBasis, ObjectMaterials};
use relume_core::{inputs, node, outputs, NodeError, Params, RunCtx};

/// Projects the dynamic objects' Blinn-Phong materials on a BRDF basis ([S] 4-22), per colour
/// channel: basis 0 (diffuse) gets Kd, specular basis k gets Ks · c_k(s), with c(s)
/// interpolated linearly in s between the basis' sampled exponents. This is the edit node of
/// pixel relighting: `object` names the dynamic object whose (Kd, Ks, s) the parameters set
/// (empty: none, every object keeps the material its input gives); chain one node per edited
/// object. An s outside the sampled range is a parameter error naming the range, never
/// clamped: a clamped exponent would silently render another material (widen
/// `BrdfSpaceSample`'s s_min / s_max instead). With Ks = 0 the exponent plays no part.
/// Kd + Ks > 1 ([S] 4-16 asks ≤ 1) is allowed with a note.
#[derive(Params)]
pub struct MaterialProject {
    /// the dynamic object to edit (a name from `SceneMaterials`; empty: edit none)
    #[param(default = "")]
    pub object: String,
    /// diffuse reflectance Kd of the edited object
    #[param(rgb, default = (0.5, 0.5, 0.5), range = 0.0..=1.0)]
    pub kd: [f32; 3],
    /// specular reflectance Ks of the edited object
    #[param(rgb, default = (0.5, 0.5, 0.5), range = 0.0..=1.0)]
    pub ks: [f32; 3],
    /// Blinn-Phong exponent s of the edited object, within the basis' sampled range
    #[param(default = 20.0, range = 0.0..=1e5)]
    pub s: f32,
}

inputs!(pub MaterialProjectIn { basis: BrdfBasis, materials: ObjectMaterials });
outputs!(pub MaterialProjectOut { materials: ObjectMaterials });

#[node(category = "relight")]
impl MaterialProject {
    fn run(&self, i: MaterialProjectIn, cx: &RunCtx) -> Result<MaterialProjectOut, NodeError> {
        let mut out = i.materials.clone();
        if !self.object.is_empty() {
            let names: Vec<&str> = i.materials.0.iter().map(|m| m.name.as_str()).collect();
            let m = out.0.iter_mut().find(|m| m.name == self.object).ok_or_else(|| {
                NodeError::param("object", format!("no dynamic object \"{}\" (dynamic objects: {})", self.object, names.join(", ")))
            })?;
            (m.kd, m.ks, m.s) = (self.kd, self.ks, self.s);
        }
        for m in &mut out.0 {
            let mut coefficients = vec![[0.0; 3]; i.basis.bases()];
            for ch in 0..3 {
                let c = i.basis.project(m.kd[ch] as f64, m.ks[ch] as f64, m.s as f64).map_err(|msg| {
                    if m.name == self.object {
                        NodeError::param("s", msg)
                    } else {
                        NodeError::input("materials", format!("dynamic object \"{}\": {msg}", m.name))
                    }
                })?;
                c.iter().zip(&mut coefficients).for_each(|(v, o)| o[ch] = *v);
            }
            m.coefficients = coefficients;
            let over = (0..3).map(|ch| m.kd[ch] + m.ks[ch]).fold(0.0f32, f32::max);
            if over > 1.0 {
                cx.note(format!(
                    "\"{}\": Kd + Ks = {over} > 1: the material reflects more light than it receives ([S] 4-16 asks Kd + Ks ≤ 1)",
                    m.name
                ));
            }
        }
        Ok(MaterialProjectOut { materials: out })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::relight::test_support::{basis, space};
    use crate::testing::{f, first, rgb, run_full, run_on, t};
    use crate::types::{BrdfSample, ObjectMaterial};
    use relume_core::Value;
    use std::f64::consts::PI;
    use std::path::Path;

    fn one(kd: [f32; 3], ks: [f32; 3], s: f32) -> ObjectMaterials {
        ObjectMaterials(vec![ObjectMaterial { name: "obj".into(), kd, ks, s, coefficients: vec![], maps: Default::default() }])
    }

    /// Edits the one object to (kd, ks, s) grey and returns its red coefficients.
    fn project(b: &BrdfBasis, kd: f64, ks: f64, s: f64) -> Result<Vec<f64>, NodeError> {
        let p = [("object", t("obj")), ("kd", rgb([kd; 3])), ("ks", rgb([ks; 3])), ("s", f(s))];
        run_on::<MaterialProject>(&p, vec![Value::new(b.clone()), Value::new(one([0.5; 3], [0.5; 3], 20.0))])
            .map(|o| first::<ObjectMaterials>(&o).0[0].coefficients.iter().map(|c| c[0]).collect())
    }

    #[test]
    fn channels_project_separately_and_unedited_objects_keep_their_material() {
        let (b, _) = basis(&space(6, 6, 12, 20, 1.0, 200.0), 4);
        let mut two = one([0.2, 0.2, 0.0], [0.2, 0.2, 0.0], 180.0);
        two.0.push(ObjectMaterial {
            name: "plane".into(),
            kd: [0.2; 3],
            ks: [0.2; 3],
            s: 5.0,
            coefficients: vec![],
            maps: Default::default(),
        });
        let out = run_on::<MaterialProject>(&[], vec![Value::new(b.clone()), Value::new(two.clone())]).unwrap();
        let m = first::<ObjectMaterials>(&out);
        let yellow = &m.0[0];
        assert_eq!((yellow.kd, yellow.s), ([0.2, 0.2, 0.0], 180.0));
        let c = b.project(0.2f32 as f64, 0.2f32 as f64, 180.0).unwrap();
        for (k, ck) in c.iter().enumerate() {
            assert_eq!(yellow.coefficients[k], [*ck, *ck, 0.0], "basis {k}: the blue channel has no reflectance");
        }
        assert_eq!(m.0[1].coefficients[0], [0.2f32 as f64; 3]);
        // Editing the plane leaves the ring's coefficients as they were.
        let p = [("object", t("plane")), ("kd", rgb([0.5, 0.1, 0.1])), ("ks", rgb([0.0; 3])), ("s", f(5.0))];
        let edited = first::<ObjectMaterials>(&run_on::<MaterialProject>(&p, vec![Value::new(b), Value::new(two)]).unwrap());
        assert_eq!(edited.0[0], m.0[0]);
        assert_eq!(edited.0[1].coefficients[0], [0.5, 0.1f32 as f64, 0.1f32 as f64]);
        assert!(edited.0[1].coefficients[1..].iter().all(|c| *c == [0.0; 3]));
    }

    #[test]
    fn an_unknown_object_is_a_parameter_error_listing_the_dynamic_objects() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 200.0), 3);
        let e = run_on::<MaterialProject>(&[("object", t("teapot"))], vec![Value::new(b), Value::new(one([0.5; 3], [0.5; 3], 20.0))])
            .unwrap_err();
        assert!(matches!(&e, NodeError::Param { name, .. } if name == "object"), "{e}");
        assert!(e.to_string().contains("obj"), "{e}");
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
        let p = [("object", t("obj")), ("kd", rgb([0.8; 3])), ("ks", rgb([0.8; 3])), ("s", f(5.0))];
        let e = run_full::<MaterialProject>(&p, Path::new("."), vec![Value::new(b), Value::new(one([0.5; 3], [0.5; 3], 20.0))]).unwrap();
        assert!(e.notes.iter().any(|n| n.contains("> 1")), "{:?}", e.notes);
    }
}
