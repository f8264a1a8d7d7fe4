//! The BRDF side of pipeline 2 ([S] 5.2.2, 5.3.1, 5.3.3.1): `BrdfTensor` samples a BRDF
//! family's specular part into F(h, ωo, ωi) over the disk-projected hemisphere,
//! `SpecularSeparation` splits F into Gaussian lobes around the mirror direction plus a
//! low-frequency residual, and `TuckerDecompose` factors a tensor (F or the residual) into
//! the core and the h, ωo, ωi factors a renderer shades with. Their port types are in
//! `types::brdf`.

pub mod brdf_tensor;
pub mod specular_separation;
pub mod tucker_decompose;

/// Tensors, separations and decompositions made by the nodes themselves, for this folder's
/// unit tests.
#[cfg(test)]
pub(crate) mod test_support {
    use crate::types::brdf::{BrdfTensorTable, SpecularLobes, TuckerBrdf};
    use relume_base::testing::{first, run_on};
    use relume_base::types::Metrics;
    use relume_core::{ParamValue, Value};

    /// `BrdfTensor` with the given parameters.
    pub fn tensor(p: &[(&str, ParamValue)]) -> BrdfTensorTable {
        first(&run_on::<super::brdf_tensor::BrdfTensor>(p, vec![]).unwrap())
    }

    /// `SpecularSeparation` of `t`: residual, lobes, metrics.
    pub fn separate(t: &BrdfTensorTable, p: &[(&str, ParamValue)]) -> (BrdfTensorTable, SpecularLobes, Metrics) {
        let out = run_on::<super::specular_separation::SpecularSeparation>(p, vec![Value::new(t.clone())]).unwrap();
        (first(&out), first(&out[1..]), first(&out[2..]))
    }

    /// A small Blinn-Phong family (s 1 … 100, disk 16), separated into 0°, 7°, 14°, 21° lobes
    /// and its residual decomposed at ranks (3, 8, 8); built once per test binary.
    pub fn small_brdf() -> &'static (TuckerBrdf, SpecularLobes) {
        use relume_base::testing::{f, i};
        static B: std::sync::OnceLock<(TuckerBrdf, SpecularLobes)> = std::sync::OnceLock::new();
        B.get_or_init(|| {
            let t = tensor(&[("disk", i(16)), ("samples", i(12)), ("s_max", f(100.0))]);
            let (residual, lobes, _) = separate(&t, &[]);
            (decompose(&residual, &[]).0, lobes)
        })
    }

    /// The Cook-Torrance family the tests shade with (m 0.1, 0.3, 0.5 × F0 0.2, 0.5, 0.8, disk
    /// 16), separated like [`small_brdf`] and its residual decomposed at ranks (4, 8, 8), the
    /// thesis' n_h for Cook-Torrance; built once per test binary.
    pub fn small_ct_brdf() -> &'static (TuckerBrdf, SpecularLobes) {
        use relume_base::testing::{f, i, id};
        static B: std::sync::OnceLock<(TuckerBrdf, SpecularLobes)> = std::sync::OnceLock::new();
        B.get_or_init(|| {
            let t = tensor(&[
                ("model", id("CookTorrance")),
                ("disk", i(16)),
                ("m_count", i(3)),
                ("m_min", f(0.1)),
                ("m_max", f(0.5)),
                ("f0_count", i(3)),
                ("f0_min", f(0.2)),
                ("f0_max", f(0.8)),
            ]);
            let (residual, lobes, _) = separate(&t, &[]);
            (decompose(&residual, &[("n_h", i(4))]).0, lobes)
        })
    }

    /// `TuckerDecompose` of `t`: the decomposition and its metrics.
    pub fn decompose(t: &BrdfTensorTable, p: &[(&str, ParamValue)]) -> (TuckerBrdf, Metrics) {
        let out = run_on::<super::tucker_decompose::TuckerDecompose>(p, vec![Value::new(t.clone())]).unwrap();
        (first(&out), first(&out[1..]))
    }
}
