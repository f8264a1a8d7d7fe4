use crate::types::brdf::{BrdfFamily, BrdfTensorTable, DiskGrid, MAX_BRDF_TENSOR_BYTES};
use relume_base::brdf::BrdfModel;
use relume_base::math::spread;
use relume_core::{memory::fmt_bytes, node, params, MemoryEstimate, NodeError, PortSize, RunCtx};

params! {
    /// Samples the specular (non-diffuse) part of a BRDF family, ks = 1, into the tensor
    /// F(h, ωo, ωi) of [S] 5.2.2 (N_h × N_ωo × N_ωi) for `TuckerDecompose` (directly, or after
    /// `SpecularSeparation`). The diffuse term is shaded outside the tensor, as in [S] 5.3.3.1.
    ///
    /// Directions ([S] 5.3.3.1, after Wang et al.): the upper hemisphere projected orthographically
    /// onto the unit disk; `disk` = n cuts [−1, 1]² into n × n cells and keeps those whose centre
    /// is inside the disk; a sample's direction is (x, y, √(1 − x² − y²)) and its solid angle the
    /// cell's area over cos θ, (2/n)²/cos θ (they sum to 2π within 4.9 % at n = 16, 0.35 % at 32:
    /// the midpoint rule's error at the rim, where 1/cos θ is singular). The default n = 16 gives
    /// 208 directions, 7.2° apart at the normal: the separated lobes' step ([S]: 0°, 7°, 14°,
    /// 21°) is resolved and the residual they leave varies on a larger scale, while 200 × 208²
    /// f32 values stay at 35 MB (n = 32: 812 directions, 527 MB, and a Tucker's Gram matrices
    /// 15× slower).
    ///
    /// Families (`model`): Blinn-Phong, the project's (s+2)/(8π) cos^s δ (not [S] 4-15's 2π), with
    /// `samples` exponents spread linearly over [s_min, s_max] (default 200 over 1 … 200: the
    /// integers, as [S] 5.3.2); Cook-Torrance ([S] 2-12 as `brdf/cook_torrance.rs` writes it:
    /// Beckmann D, Schlick F, V-cavity G, the microfacet 1/4) on an `m_count` × `f0_count` grid
    /// over roughness × F0, h = i_m · f0_count + i_F0. The thesis' Cook-Torrance space is 100 fits
    /// of measured materials (Ngan et al.) that relume does not have; the default 10 × 10 sweep
    /// (m 0.05 … 0.6, F0 0.02 … 1) stands in for it. Values come from the library's `eval`.
    /// A material's parameter maps to a fractional h: linear in s, bilinear on (m, F0).
    ///
    /// Tensors over 2 GiB (or the run's memory budget) are refused before allocating, with the
    /// estimate.
    pub struct BrdfTensor {
        /// the BRDF model whose specular part is sampled along h
        pub model: BrdfModel = BlinnPhong;
        /// disk resolution n: n × n cells over [−1, 1]², those inside the unit disk are directions
        pub disk: usize = 16, range = 1..=256, test = 6;
        /// Blinn-Phong: number of exponents (h samples)
        pub samples: usize = 200, range = 1..=4096, test = 12;
        /// Blinn-Phong: smallest exponent
        pub s_min: f32 = 1.0, range = 0.0..=1e5;
        /// Blinn-Phong: largest exponent
        pub s_max: f32 = 200.0, range = 0.0..=1e5;
        /// Cook-Torrance: number of roughness values
        pub m_count: usize = 10, range = 1..=256, test = 3;
        /// Cook-Torrance: smallest Beckmann roughness m (RMS slope)
        pub m_min: f32 = 0.05, range = 0.001..=1.0;
        /// Cook-Torrance: largest Beckmann roughness m
        pub m_max: f32 = 0.6, range = 0.001..=1.0;
        /// Cook-Torrance: number of F0 values
        pub f0_count: usize = 10, range = 1..=256, test = 2;
        /// Cook-Torrance: smallest Schlick F0 (reflectance at normal incidence)
        pub f0_min: f32 = 0.02, range = 0.0..=1.0;
        /// Cook-Torrance: largest Schlick F0
        pub f0_max: f32 = 1.0, range = 0.0..=1.0;
    }
}

impl BrdfTensor {
    /// N_h the parameters ask for.
    fn n_h(&self) -> usize {
        match self.model {
            BrdfModel::BlinnPhong => self.samples,
            BrdfModel::CookTorrance => self.m_count * self.f0_count,
        }
    }

    /// The family, or the parameter whose range is upside down.
    fn family(&self) -> Result<BrdfFamily, NodeError> {
        let order = |lo: f32, hi: f32, a: &str, b: &str, count: usize| {
            if lo > hi || (lo == hi && count > 1) {
                Err(NodeError::param(a, format!("{a} = {lo} must be below {b} = {hi} (or equal with a single sample)")))
            } else {
                Ok(())
            }
        };
        Ok(match self.model {
            BrdfModel::BlinnPhong => {
                order(self.s_min, self.s_max, "s_min", "s_max", self.samples)?;
                BrdfFamily::BlinnPhong { s: spread(self.samples, self.s_min, self.s_max) }
            }
            BrdfModel::CookTorrance => {
                order(self.m_min, self.m_max, "m_min", "m_max", self.m_count)?;
                order(self.f0_min, self.f0_max, "f0_min", "f0_max", self.f0_count)?;
                BrdfFamily::CookTorrance {
                    m: spread(self.m_count, self.m_min, self.m_max),
                    f0: spread(self.f0_count, self.f0_min, self.f0_max),
                }
            }
        })
    }

    fn bytes(&self) -> u64 {
        BrdfTensorTable::bytes_for(self.n_h() as u64, DiskGrid::count(self.disk as u32) as u64)
    }
}

#[node(category = "ptt", metrics = ["samples", "directions"], outputs = [tensor])]
impl BrdfTensor {
    fn memory(&self, _inputs: &[Option<PortSize>]) -> MemoryEstimate {
        // The table; the directions beside it are small.
        MemoryEstimate { outputs: vec![Some(PortSize::bytes(self.bytes()))], working: DiskGrid::count(self.disk as u32) as u64 * 32 }
    }

    fn run(&self, cx: &RunCtx) -> Result<BrdfTensorTable, NodeError> {
        let family = self.family()?;
        let bytes = self.bytes();
        let limit = MAX_BRDF_TENSOR_BYTES.min(cx.memory_budget());
        if bytes > limit {
            return Err(NodeError::over_limit(format!(
                "a BRDF tensor of {} samples over {} directions (disk {}) needs {}, over the {} limit; lower disk or the sample counts",
                self.n_h(),
                DiskGrid::count(self.disk as u32),
                self.disk,
                fmt_bytes(bytes),
                fmt_bytes(limit)
            )));
        }
        let disk = DiskGrid::new(self.disk as u32);
        let n = disk.len();
        let dirs: Vec<glam::Vec3> = (0..n).map(|k| disk.direction(k).as_vec3()).collect();
        let mut values = vec![0.0f32; family.len() * n * n];
        cx.par_chunks_mut(&mut values, n * n, |h, table| {
            for (o, row) in table.chunks_mut(n).enumerate() {
                for (v, wi) in row.iter_mut().zip(&dirs) {
                    *v = family.eval(h, dirs[o], *wi) as f32;
                }
            }
        })?;
        cx.metric("samples", family.len() as f64);
        cx.metric("directions", n as f64);
        Ok(BrdfTensorTable { family, disk, values })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf_factors::test_support::tensor;
    use crate::types::brdf::MaterialParam;
    use glam::Vec3;
    use relume_base::brdf::blinn_phong;
    use relume_base::testing::{cancels_midway, f, i, id, run_on};
    use relume_core::Params;
    use relume_core::PortValue;

    #[test]
    fn the_blinn_phong_tensor_is_the_library_eval_at_the_disk_samples() {
        let t = tensor(&[("disk", i(12)), ("samples", i(5)), ("s_max", f(41.0))]);
        assert_eq!(t.dims(), [5, t.disk.len(), t.disk.len()]);
        assert_eq!(t.family, BrdfFamily::BlinnPhong { s: vec![1.0, 11.0, 21.0, 31.0, 41.0] });
        let n = t.disk.len();
        for (h, s) in [1.0f32, 11.0, 21.0, 31.0, 41.0].into_iter().enumerate() {
            for (o, wi) in [(0, 3), (17, n - 1), (n / 2, n / 2), (n / 2, t.disk.mirror(n / 2))] {
                let (dwo, dwi) = (t.disk.direction(o).as_vec3(), t.disk.direction(wi).as_vec3());
                let lib = blinn_phong::eval(Vec3::ZERO, Vec3::ONE, s, dwo, dwi).x;
                assert_eq!(t.at(h, o, wi), lib, "s {s} o {o} i {wi}");
            }
        }
        // The default Blinn-Phong family is the integers 1 … 200 ([S] 5.3.2).
        let v = relume_core::ParamValues::resolve(&BrdfTensor::schema(), &[], std::path::Path::new(".")).unwrap();
        let p = BrdfTensor::from_values(&v).unwrap();
        assert_eq!(p.family().unwrap(), BrdfFamily::BlinnPhong { s: (1..=200).map(f64::from).collect() });
    }

    #[test]
    fn sampled_values_are_reciprocal() {
        // The disk grid is its own ωo ↔ ωi transpose: every entry has its partner.
        for model in ["BlinnPhong", "CookTorrance"] {
            let t = tensor(&[("model", id(model)), ("disk", i(10)), ("samples", i(4)), ("m_count", i(2)), ("f0_count", i(2))]);
            let [nh, n, _] = t.dims();
            for h in 0..nh {
                for o in 0..n {
                    for k in 0..n {
                        assert_eq!(t.at(h, o, k), t.at(h, k, o), "{model} h {h} ({o}, {k})");
                    }
                }
            }
            assert!(t.values.iter().all(|v| v.is_finite() && *v >= 0.0));
        }
    }

    #[test]
    fn the_cook_torrance_grid_orders_roughness_then_f0() {
        let t = tensor(&[("model", id("CookTorrance")), ("disk", i(8)), ("m_count", i(3)), ("f0_count", i(2)), ("f0_min", f(0.5))]);
        assert_eq!(t.family.len(), 6);
        let MaterialParam::CookTorrance { m, f0 } = t.family.param(3) else { panic!() };
        assert!((m - 0.325).abs() < 1e-7 && f0 == 1.0, "{m} {f0}");
        let (o, k) = (5, t.disk.mirror(5));
        let (wo, wi) = (t.disk.direction(o).as_vec3(), t.disk.direction(k).as_vec3());
        let lib = relume_base::brdf::cook_torrance::eval(Vec3::ZERO, Vec3::ONE, m as f32, 1.0, wo, wi).x;
        assert_eq!(t.at(3, o, k), lib);
        // At the mirror direction, rougher is lower and F0 higher is brighter.
        assert!(t.at(0, o, k) > t.at(2, o, k) && t.at(1, o, k) > t.at(0, o, k));
    }

    #[test]
    fn reversed_ranges_and_oversized_tensors_are_refused_before_allocating() {
        let e = run_on::<BrdfTensor>(&[("s_min", f(10.0)), ("s_max", f(5.0))], vec![]).unwrap_err();
        assert!(e.to_string().contains("s_min"), "{e}");
        let e = run_on::<BrdfTensor>(&[("model", id("CookTorrance")), ("f0_min", f(0.6)), ("f0_max", f(0.5))], vec![]).unwrap_err();
        assert!(e.to_string().contains("f0_min"), "{e}");
        let e = run_on::<BrdfTensor>(&[("disk", i(64)), ("samples", i(200))], vec![]).unwrap_err();
        assert!(e.is_over_limit() && e.to_string().contains("GiB") && e.to_string().contains("3228 directions"), "{e}");
        // One sample at s_min = s_max is a valid family.
        let t = tensor(&[("disk", i(4)), ("samples", i(1)), ("s_min", f(7.0)), ("s_max", f(7.0))]);
        assert_eq!(t.family, BrdfFamily::BlinnPhong { s: vec![7.0] });
        assert_eq!(BrdfTensorTable::decode(&t.encode()).unwrap(), t);
        let mut bad = t.clone();
        bad.values.pop();
        assert!(BrdfTensorTable::decode(&bad.encode()).is_none());
    }

    #[test]
    fn stops_when_cancelled() {
        cancels_midway::<BrdfTensor>(&[("disk", i(8)), ("samples", i(64))], vec![]);
    }
}
