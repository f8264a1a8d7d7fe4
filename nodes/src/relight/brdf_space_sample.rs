//! BrdfSpaceSample node.

use crate::types::{cos_half, BrdfGrid, BrdfSample, BrdfSpace, MAX_BRDF_SPACE_BYTES};
use relume_core::{memory::fmt_bytes, node, outputs, MemoryEstimate, NodeError, Params, PortSize, RunCtx};

/// Tabulates Blinn-Phong BRDFs on a (θi, θo, φ) grid, the BRDF space of pipeline 1 ([S] 4.1.2,
/// 4-17, 4-18). Sample 1 is diffuse (kd = 1, ks = 0); the other samples − 1 are specular
/// (kd = 0, ks = 1) with exponents spaced linearly over [s_min, s_max] ([S]: "s 在选定的范围内
/// 均匀采样", uniformly over the chosen range; one specular sample takes s_min). The BRDF is the
/// project's normalised Blinn-Phong, (s+2)/(8π) cos^s δ (`brdf/blinn_phong.rs`), not the
/// thesis' printed (s+2)/(2π). Values are taken at cell centres, φ the relative azimuth folded
/// into [0, π] with the mirror direction at φ = π (see `BrdfSpace`). Sizes over 2 GiB of table
/// are refused before allocating.
#[derive(Params)]
pub struct BrdfSpaceSample {
    /// cells over the incident polar angle θi ∈ [0, π/2]
    #[param(default = 30, range = 1..=1024)]
    pub n_theta_i: usize,
    /// cells over the outgoing polar angle θo ∈ [0, π/2]
    #[param(default = 30, range = 1..=1024)]
    pub n_theta_o: usize,
    /// cells over the relative azimuth φ ∈ [0, π] (mirror direction at π)
    #[param(default = 60, range = 1..=2048)]
    pub n_phi: usize,
    /// BRDF samples N_s: one diffuse, N_s − 1 specular
    #[param(default = 201, range = 2..=2048)]
    pub samples: usize,
    /// smallest Blinn-Phong exponent of the specular samples
    #[param(default = 1.0, range = 0.0..=1e5)]
    pub s_min: f32,
    /// largest Blinn-Phong exponent of the specular samples
    #[param(default = 200.0, range = 0.0..=1e5)]
    pub s_max: f32,
}

outputs!(pub BrdfSpaceSampleOut { space: BrdfSpace });

impl BrdfSpaceSample {
    fn grid(&self) -> BrdfGrid {
        BrdfGrid { n_theta_i: self.n_theta_i as u32, n_theta_o: self.n_theta_o as u32, n_phi: self.n_phi as u32 }
    }

    /// The sample list: the diffuse sample, then the specular ones in increasing s.
    pub fn sample_list(&self) -> Vec<BrdfSample> {
        let n = self.samples - 1;
        let (lo, hi) = (self.s_min as f64, self.s_max as f64);
        let s = |j: usize| if n > 1 { lo + (hi - lo) * j as f64 / (n - 1) as f64 } else { lo };
        std::iter::once(BrdfSample { kd: 1.0, ks: 0.0, s: 0.0 })
            .chain((0..n).map(|j| BrdfSample { kd: 0.0, ks: 1.0, s: s(j) as f32 }))
            .collect()
    }
}

#[node(category = "relight")]
impl BrdfSpaceSample {
    fn memory(&self, _inputs: &[Option<PortSize>]) -> MemoryEstimate {
        // The table, and one f64 cos δ per cell besides it.
        let g = self.grid();
        MemoryEstimate {
            outputs: vec![Some(PortSize::bytes(BrdfSpace::bytes_for(&g, self.samples as u64)))],
            working: g.cells_u64().saturating_mul(8),
        }
    }

    fn run(&self, _: (), cx: &RunCtx) -> Result<BrdfSpaceSampleOut, NodeError> {
        if self.s_min > self.s_max {
            return Err(NodeError::param("s_min", format!("s_min = {} is above s_max = {}; make s_min ≤ s_max", self.s_min, self.s_max)));
        }
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
        let samples = self.sample_list();
        let mut values = vec![0.0f32; samples.len() * cells];
        cx.par_chunks_mut(&mut values, cells, |i, table| {
            for (v, &ch) in table.iter_mut().zip(&cos_h) {
                *v = samples[i].eval_cos_h(ch) as f32;
            }
        })?;
        Ok(BrdfSpaceSampleOut { space: BrdfSpace { grid, samples, values } })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::blinn_phong;
    use crate::relight::test_support::space;
    use crate::testing::{cancels_midway, f, i, run_on};
    use glam::Vec3;
    use relume_core::PortValue;

    #[test]
    fn values_are_the_library_blinn_phong_at_cell_centres() {
        let sp = space(6, 5, 8, 11, 1.0, 50.0);
        assert_eq!(sp.samples.len(), 11);
        assert_eq!(sp.samples[0], BrdfSample { kd: 1.0, ks: 0.0, s: 0.0 });
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
        // QUALITY.md §2: s = 1 and s = 10⁴ (near mirror); s = 0 (constant lobe).
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
    fn stops_when_cancelled() {
        cancels_midway::<BrdfSpaceSample>(&[("n_theta_i", i(8)), ("n_theta_o", i(8)), ("n_phi", i(8)), ("samples", i(400))], vec![]);
    }
}
