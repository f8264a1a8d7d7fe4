use super::types::{PackedTwoBounce, TwoBounce};
use relume_base::math::cpca::Cpca;
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, MemoryEstimate, NodeError, PortSize, PortValue, RunCtx};

params! {
    /// Compresses the two-bounce transfer by clustered PCA ([S] 5.3.3.4: T² is CPCA-compressed
    /// like T¹; Sloan et al. 2003, `math::cpca`): every vertex's row of T² (a scalar per coarse
    /// lighting basis and reflector pair) is clustered, and each cluster keeps its mean and
    /// `eigenvectors` principal directions; a vertex keeps its cluster and one coefficient per
    /// direction. `PttBounceLight` contracts the means and directions with the sky once per
    /// cluster, so a sky edit reads a few megabytes where the raw rows are hundreds. Seeded and
    /// deterministic: the same bytes on any thread count.
    ///
    /// Metrics: `raw_bytes` (T² as traced), `bytes` (compressed), `relative_error` (√ of the
    /// squared error over the rows' squared norm, all vertices together), clusters, CPCA
    /// iterations.
    pub struct CompressT2 {
        /// vertex clusters ([S]: 13–62 per scene)
        pub clusters: usize = 32, range = 1..=4096, test = 2;
        /// principal directions kept per cluster ([S]: 16 or 32)
        pub eigenvectors: usize = 16, range = 0..=512, test = 4;
        /// CPCA iterations after the k-means start (0: the k-means clusters)
        pub iterations: usize = 2, range = 0..=100, test = 1;
        /// random seed of the k-means start
        pub seed: u64 = 1, range = 0..=u32::MAX;
    }
}

impl CompressT2 {
    /// Bytes of the result and the CPCA's own working arrays for `n` rows of `dim`.
    fn bytes(&self, n: usize, dim: usize) -> u64 {
        let k = self.clusters.min(n.max(1));
        let work = Cpca::bytes_for(n, dim, k, self.eigenvectors).saturating_add((dim as u64).pow(2).saturating_mul(8 * 2));
        work.saturating_add(PackedTwoBounce::bytes_for(n as u64, dim as u64, k as u64, self.eigenvectors as u64))
    }
}

#[node(category = "ptt", metrics = ["raw_bytes", "bytes", "relative_error", "clusters", "iterations"], outputs = [transfer])]
impl CompressT2 {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        let raw = inputs[0].map_or(0, |s| s.bytes);
        MemoryEstimate { outputs: vec![Some(PortSize::bytes(raw / 16))], working: raw / 2 }
    }

    fn run(&self, transfer: &TwoBounce, cx: &RunCtx) -> Result<PackedTwoBounce, NodeError> {
        self.pack(transfer, cx)
    }
}

impl CompressT2 {
    /// The node's work: the budget check, the CPCA, the metrics.
    fn pack(&self, transfer: &TwoBounce, cx: &RunCtx) -> Result<PackedTwoBounce, NodeError> {
        let dim = transfer.stride();
        let n = transfer.values.len() / dim.max(1);
        let bytes = self.bytes(n, dim);
        if bytes > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "compressing the two-bounce transfer of {n} vertices would hold {}, over the {} budget",
                fmt_bytes(bytes),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let m = self.eigenvectors;
        let mut out = PackedTwoBounce {
            side: transfer.side,
            channels: transfer.channels,
            m: m as u32,
            means: vec![],
            directions: vec![],
            cluster: vec![],
            coefficients: vec![],
        };
        let k = self.clusters.min(n);
        if k < self.clusters {
            cx.note(format!("{} clusters asked for, {n} vertices: {k} clusters", self.clusters));
        }
        let (mut error, mut iterations) = (0.0, 0);
        if n > 0 {
            let cpca = Cpca { k, m, max_iterations: self.iterations, seed: self.seed };
            let r = cpca.run_with(&transfer.values, dim, cx, (0.0, 1.0))?;
            let norm: f64 = transfer.values.iter().map(|x| (*x as f64).powi(2)).sum();
            error = if norm > 0.0 { (r.total_error / norm).sqrt() } else { 0.0 };
            iterations = r.iterations;
            let f = |v: &[f64]| v.iter().map(|x| *x as f32).collect::<Vec<f32>>();
            (out.means, out.directions, out.coefficients) = (f(&r.means), f(&r.bases), f(&r.coefficients));
            out.cluster = r.assignment;
        }
        cx.metric("raw_bytes", transfer.byte_size() as f64);
        cx.metric("bytes", out.byte_size() as f64);
        cx.metric("relative_error", error);
        cx.metric("clusters", k as f64);
        cx.metric("iterations", iterations as f64);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::Chain;
    use crate::vertex_visibility::tests::floor_and_tiled_roof;
    use relume_base::testing::{first, i, run_on};
    use relume_core::Value;

    fn packed(t: &TwoBounce, clusters: i64, eigenvectors: i64) -> Result<PackedTwoBounce, NodeError> {
        run_on::<CompressT2>(&[("clusters", i(clusters)), ("eigenvectors", i(eigenvectors))], vec![Value::new(t.clone())])
            .map(|o| first(&o))
    }

    fn raw() -> TwoBounce {
        Chain::new(floor_and_tiled_roof(0.5)).get("two_raw").get::<TwoBounce>().expect("T2").clone()
    }

    #[test]
    fn enough_directions_rebuild_every_row_and_fewer_keep_the_best_subspace() {
        let t = raw();
        let n = t.values.len() / t.stride();
        let peak = t.values.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        assert!(peak > 0.0, "the roofed floor has two-bounce light");
        // As many directions as the rows' dimension: every row exactly (to f32 rounding).
        let exact = packed(&t, 2, t.stride() as i64).expect("runs");
        assert_eq!((exact.vertices(), exact.clusters()), (n, 2));
        for v in 0..n {
            let (got, want) = (exact.row(v), t.of(v));
            assert!(got.iter().zip(want).all(|(a, b)| (a - b).abs() <= 1e-5 * peak), "vertex {v}");
        }
        assert_eq!(PackedTwoBounce::decode(&exact.encode()).as_ref(), Some(&exact));
        // Fewer: the squared error falls as directions are added, and the bytes shrink.
        let err = |p: &PackedTwoBounce| {
            (0..n).map(|v| p.row(v).iter().zip(t.of(v)).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>()).sum::<f64>()
        };
        let (one, two) = (packed(&t, 2, 1).expect("runs"), packed(&t, 2, 2).expect("runs"));
        assert!(err(&two) <= err(&one) * (1.0 + 1e-6) && err(&one) > 0.0, "{} then {}", err(&one), err(&two));
        assert!(one.byte_size() < t.byte_size() && one.byte_size() < two.byte_size());
    }

    #[test]
    fn the_bytes_do_not_depend_on_threads_and_a_dark_scene_packs_to_zeros() {
        let t = raw();
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool").install(|| packed(&t, 2, 2).expect("runs"));
        assert_eq!(one, packed(&t, 2, 2).expect("runs"));
        // QUALITY "lighting": nothing bounced (a zero transfer) packs to zeros, never NaN.
        let zero = TwoBounce { values: vec![0.0; t.values.len()], ..t.clone() };
        let z = packed(&zero, 2, 2).expect("runs");
        assert!(z.means.iter().chain(&z.directions).chain(&z.coefficients).all(|x| *x == 0.0));
    }

    #[test]
    fn a_transfer_over_the_budget_is_refused_before_it_is_clustered() {
        let t = raw();
        let node = CompressT2 { clusters: 2, eigenvectors: 2, iterations: 1, seed: 1 };
        let n = t.values.len() / t.stride();
        let need = node.bytes(n, t.stride());
        assert!(need > PackedTwoBounce::bytes_for(n as u64, t.stride() as u64, 2, 2), "the working arrays count too");
        let cancel = relume_core::CancelToken::new();
        let cx = RunCtx::new("t2c", &cancel, None).with_memory_budget(need - 1);
        let e = node.pack(&t, &cx).expect_err("over the budget");
        assert!(matches!(e, NodeError::OverLimit { .. }) && e.to_string().contains("budget"), "{e}");
        assert!(node.pack(&t, &RunCtx::new("t2c", &cancel, None).with_memory_budget(need)).is_ok());
        let huge = CompressT2 { clusters: 4096, eigenvectors: 512, iterations: 1, seed: 1 };
        assert_eq!(huge.bytes(usize::MAX / 8, 1 << 20), u64::MAX, "saturates, never overflows");
    }
}
