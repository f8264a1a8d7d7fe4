//! The editable BRDF space both relighting pipelines share ([S] 4.1.2): a BRDF family sampled
//! on a grid of directions (`BrdfSpaceSample`), its PCA basis (`BrdfPca`), the scene's
//! dynamic materials (`SceneMaterials`) and their coefficients on the basis
//! (`MaterialProject`), and signed evaluation of the basis at any pair of directions
//! (`basis_brdf`).

pub mod basis_brdf;
pub mod brdf_pca;
pub mod brdf_space_sample;
pub mod material_project;
pub mod scene_materials;

/// Small BRDF spaces and bases made by the nodes themselves, for unit tests here and in the
/// pipelines that use them.
#[doc(hidden)]
pub mod test_support {
    use crate::testing::{f, first, i, run_on};
    use crate::types::{BrdfBasis, BrdfGrid, BrdfSample, BrdfSpace, Metrics};
    use relume_core::Value;

    /// A Cook-Torrance `BrdfSpaceSample` on an n × n × 2n grid: `samples` − 1 specular samples,
    /// roughnesses over [m_min, m_max] × `f0_count` F0 values over [0.02, 1].
    pub fn ct_space(n: i64, samples: i64, f0_count: i64, m_min: f64, m_max: f64) -> BrdfSpace {
        let p = [
            ("n_theta_i", i(n)),
            ("n_theta_o", i(n)),
            ("n_phi", i(2 * n)),
            ("samples", i(samples)),
            ("model", crate::testing::id("CookTorrance")),
            ("m_min", f(m_min)),
            ("m_max", f(m_max)),
            ("f0_count", i(f0_count)),
        ];
        first(&run_on::<super::brdf_space_sample::BrdfSpaceSample>(&p, vec![]).unwrap())
    }

    /// `BrdfSpaceSample` with the given grid, sample count and exponent range.
    pub fn space(n_theta_i: i64, n_theta_o: i64, n_phi: i64, samples: i64, s_min: f32, s_max: f32) -> BrdfSpace {
        let p = [
            ("n_theta_i", i(n_theta_i)),
            ("n_theta_o", i(n_theta_o)),
            ("n_phi", i(n_phi)),
            ("samples", i(samples)),
            ("s_min", f(s_min as f64)),
            ("s_max", f(s_max as f64)),
        ];
        first(&run_on::<super::brdf_space_sample::BrdfSpaceSample>(&p, vec![]).unwrap())
    }

    /// A space with the diffuse sample and specular samples of exactly the exponents `s`
    /// (repeats allowed: rank-deficient sets).
    pub fn space_of(n_theta_i: u32, n_theta_o: u32, n_phi: u32, s: &[f32]) -> BrdfSpace {
        let grid = BrdfGrid { n_theta_i, n_theta_o, n_phi };
        let samples: Vec<BrdfSample> =
            std::iter::once(BrdfSample::diffuse(1.0)).chain(s.iter().map(|&s| BrdfSample::blinn_phong(0.0, 1.0, s))).collect();
        let values = samples.iter().flat_map(|p| (0..grid.cells()).map(move |c| p.eval(grid.centre(c)) as f32)).collect();
        BrdfSpace { grid, samples, values }
    }

    /// `BrdfPca` of `space` with `bases` bases: the basis and its metrics.
    pub fn basis(space: &BrdfSpace, bases: i64) -> (BrdfBasis, Metrics) {
        let out = run_on::<super::brdf_pca::BrdfPca>(&[("bases", i(bases))], vec![Value::new(space.clone())]).unwrap();
        (out[0].get::<BrdfBasis>().unwrap().clone(), out[1].get::<Metrics>().unwrap().clone())
    }
}
