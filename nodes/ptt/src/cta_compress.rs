use super::types::{CtaPlan, Visibility};
use relume_base::math::cpca::Cpca;
use relume_base::types::Scene;
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, MemoryEstimate, NodeError, PortSize, RunCtx};

params! {
    /// Plans the clustered tensor approximation (CTA) of the bounce transfer ([S] 5.3.3.4, after
    /// Tsai & Shih 2006; defaults [S]: 32 eigenvectors, lighting 64): clusters the vertices by
    /// clustered PCA (`math::cpca`, seeded, deterministic) and fixes the ranks that `TransferT1`
    /// cuts each cluster's tensor (vertex × lighting × channel·SH) to as soon as the cluster's raw
    /// transfer is traced — so the raw transfer, several GB on `envlit`, is never held whole.
    ///
    /// Deviation, stated: [S] clusters on the transfer itself; holding it whole to cluster it is
    /// what the memory rule forbids, so the vertices are clustered on what shapes their bounce and
    /// is already known: their coarse cosine-weighted sky visibility (6 × 8 × 8 values), normal and
    /// position, each group scaled to unit total variance so that none dominates by its length.
    /// The clusters, the eigenvectors and the lighting rank are what `relume sweep` varies for the
    /// error-against-compression report ([S] figure 5-9).
    pub struct CtaCompress {
        /// vertex clusters ([S]: 13–62 per scene)
        pub clusters: usize = 32, range = 1..=4096, test = 64;
        /// eigenvectors kept over a cluster's vertices ([S]: 16 or 32)
        pub eigenvectors: usize = 32, range = 1..=1024, test = 8;
        /// rank kept over the lighting bases ([S]: 64)
        pub lighting: usize = 64, range = 1..=6144, test = 8;
        /// HOOI rounds after the HOSVD start (at test size none: on envlit's 49,261 vertices
        /// that halves `TransferT1`'s time and moves its relative error from 0.2358 to 0.2362)
        pub sweeps: usize = 1, range = 0..=20, test = 0;
        /// principal directions per cluster in the clustering
        pub cpca_components: usize = 4, range = 0..=64;
        /// iterations of the clustering
        pub cpca_iterations: usize = 10, range = 0..=200, test = 2;
        /// random seed of the clustering's start
        pub seed: u64 = 1, range = 0..=u32::MAX;
    }
}

/// The clustering features of every vertex (see the node doc), row-major.
pub fn features(scene: &Scene, vis: &Visibility) -> (Vec<f32>, usize) {
    let cells = 6 * (vis.coarse as usize).pow(2);
    let dim = cells + 6;
    let n = vis.vertices();
    let extent = scene.extent();
    let mut f = vec![0.0f32; n * dim];
    for v in 0..n {
        let row = &mut f[v * dim..(v + 1) * dim];
        row[..cells].copy_from_slice(vis.coarse_of(v));
        let (p, nv) = (scene.positions[v] / extent, vis.normals[v]);
        row[cells..].copy_from_slice(&[nv.x, nv.y, nv.z, p.x, p.y, p.z]);
    }
    // Each group (visibility, normal, position) to unit total variance.
    for group in [0..cells, cells..cells + 3, cells + 3..dim] {
        let mut var = 0.0f64;
        for c in group.clone() {
            let mean = (0..n).map(|v| f[v * dim + c] as f64).sum::<f64>() / n.max(1) as f64;
            var += (0..n).map(|v| (f[v * dim + c] as f64 - mean).powi(2)).sum::<f64>() / n.max(1) as f64;
        }
        let scale = if var > 0.0 { (1.0 / var.sqrt()) as f32 } else { 1.0 };
        for v in 0..n {
            f[v * dim + group.start..v * dim + group.end].iter_mut().for_each(|x| *x *= scale);
        }
    }
    (f, dim)
}

#[node(category = "ptt", metrics = ["clusters", "largest_cluster", "smallest_cluster"], outputs = [plan])]
impl CtaCompress {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        let b = inputs[1].map_or(0, |s| s.bytes);
        MemoryEstimate { outputs: vec![Some(PortSize::bytes(b / 64))], working: b / 2 }
    }

    fn run(&self, scene: &Scene, visibility: &Visibility, cx: &RunCtx) -> Result<CtaPlan, NodeError> {
        let vis = visibility;
        let n = vis.vertices();
        if n != scene.positions.len() {
            return Err(NodeError::input("visibility", format!("holds {n} vertices; the scene has {}", scene.positions.len())));
        }
        let dim = 6 * (vis.coarse as usize).pow(2) + 6;
        let bytes = (n * dim * 4) as u64 + Cpca::bytes_for(n, dim, self.clusters, self.cpca_components);
        if bytes > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "clustering {n} vertices would hold {}, over the {} budget",
                fmt_bytes(bytes),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let k = self.clusters.min(n.max(1));
        let members = if n == 0 {
            vec![]
        } else {
            let (f, dim) = features(scene, vis);
            let cpca = Cpca { k, m: self.cpca_components, max_iterations: self.cpca_iterations, seed: self.seed };
            let r = cpca.run_with(&f, dim, cx, (0.0, 1.0))?;
            if !r.converged {
                cx.note(format!("the clustering did not settle in {} iterations (its last assignment is used)", self.cpca_iterations));
            }
            r.members().into_iter().filter(|m| !m.is_empty()).collect()
        };
        if k < self.clusters {
            cx.note(format!("{} clusters asked for, {n} vertices: {k} clusters", self.clusters));
        }
        let plan = CtaPlan { members, rank_v: self.eigenvectors as u32, rank_l: self.lighting as u32, sweeps: self.sweeps as u32 };
        let sizes: Vec<usize> = plan.members.iter().map(|m| m.len()).collect();
        cx.metric("clusters", sizes.len() as f64);
        cx.metric("largest_cluster", plan.largest() as f64);
        cx.metric("smallest_cluster", sizes.iter().copied().min().unwrap_or(0) as f64);
        Ok(plan)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vertex_visibility::tests::{floor_and_roof, visibility};
    use relume_base::testing::{first, i, run_on};
    use relume_core::Value;

    #[test]
    fn every_vertex_lands_in_one_cluster_the_same_on_one_thread() {
        let s = floor_and_roof(0.5);
        let vis = visibility(&s, 16, 4);
        let plan: CtaPlan = first(
            &run_on::<CtaCompress>(&[("clusters", i(2)), ("cpca_components", i(1))], vec![Value::new(s.clone()), Value::new(vis.clone())])
                .expect("runs"),
        );
        assert_eq!(plan.vertices(), s.positions.len());
        assert_eq!(plan.members.len(), 2);
        let mut all: Vec<u32> = plan.members.iter().flatten().copied().collect();
        all.sort();
        assert_eq!(all, (0..s.positions.len() as u32).collect::<Vec<_>>());
        use relume_core::PortValue;
        assert_eq!(CtaPlan::decode(&plan.encode()).as_ref(), Some(&plan));
        // Same plan on one thread.
        let one: CtaPlan = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool").install(|| {
            first(
                &run_on::<CtaCompress>(
                    &[("clusters", i(2)), ("cpca_components", i(1))],
                    vec![Value::new(s.clone()), Value::new(vis.clone())],
                )
                .expect("runs"),
            )
        });
        assert_eq!(one, plan);
        // More clusters than vertices: one a vertex, with a note.
        let many: CtaPlan =
            first(&run_on::<CtaCompress>(&[("clusters", i(500))], vec![Value::new(s.clone()), Value::new(vis)]).expect("runs"));
        assert_eq!(many.members.len(), s.positions.len());
    }
}
