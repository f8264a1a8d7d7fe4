use super::bounce::{Bounce, SH};
use super::channels::Channels;
use super::types::{CtaPlan, Visibility};
use crate::types::BounceTransfer;
use relume_base::math::cta::{compress, ClusterTensor};
use relume_base::types::{Accel, BrdfBasis, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, params, NodeError, PortValue, RunCtx, ShardSpec};
use serde::{Deserialize, Serialize};
use std::ops::Range;

params! {
    /// The one-bounce transfer tensor T¹(l, c, s) of every vertex ([S] 5-8, 5-9, 5.3.3.4,
    /// 5.3.3.6), compressed cluster by cluster as it is traced: for each cluster of the
    /// `CtaPlan`, each member's raw transfer (`ptt::bounce`: rays through the centres of a
    /// 6 × `rays_side`² cube map above the vertex; at a hit, the box lighting bases' direct light
    /// interpolated from the hit triangle's vertex visibility, reflected by the fixed object's
    /// BRDF or each basis BRDF of a dynamic object, projected on 4-band SH in the vertex frame),
    /// then the cluster's tensor approximation (`math::cta`) at the plan's ranks. Only one
    /// cluster's raw tensor is held at a time; its bytes are checked against the budget before
    /// tracing. Sharded over clusters (`relume shard`, `--processes`): the same bytes on any
    /// sharding and thread count.
    ///
    /// Metrics: rays, the raw transfer's bytes (what holding it whole would take) and the
    /// compressed bytes, the approximation's relative error ‖T − T̂‖ / ‖T‖ over all clusters, the
    /// channels (fixed ones first) and the lighting bases.
    /// Memory: the channels and cluster sizes come with the inputs, so `run` checks its bytes
    /// itself before allocating.
    pub struct TransferT1 {
        /// texels along a face of the cube map whose centres the bounce rays go through
        pub rays_side: usize = 16, range = 2..=128, test = 2;
    }
}

inputs!(pub TransferT1In { scene: Scene, accel: Accel, visibility: Visibility, basis: BrdfBasis, plan: CtaPlan });
outputs!(pub TransferT1Out { transfer: BounceTransfer });

/// One cluster's compressed transfer with the rays it took (a shard's partial).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClusterPart {
    pub tensor: ClusterTensor,
    pub rays: u64,
}

impl PortValue for ClusterPart {
    const NAME: &'static str = "ClusterPart";
    const COLOR: [u8; 3] = [170, 140, 230];
    const DOC: &'static str = "one cluster's compressed bounce transfer (a shard's partial)";
    fn byte_size(&self) -> usize {
        self.tensor.floats() * 4 + 64
    }
    relume_core::serde_codec!();
}

impl TransferT1 {
    fn check(&self, i: &TransferT1In, budget: u64) -> Result<Channels, NodeError> {
        let ch = Channels::new(i.scene, i.basis.bases()).map_err(|m| NodeError::input("scene", m))?;
        let n = i.scene.positions.len();
        if i.visibility.vertices() != n || i.plan.vertices() != n {
            return Err(NodeError::input(
                "plan",
                format!(
                    "the scene has {n} vertices, the visibility {} and the plan {}: they must come from the same scene",
                    i.visibility.vertices(),
                    i.plan.vertices()
                ),
            ));
        }
        let floats = 6 * (i.visibility.coarse as u64).pow(2) * ch.count() as u64 * SH as u64;
        let bytes = i.plan.largest() as u64 * floats * 4 * 2;
        if bytes > budget {
            return Err(NodeError::over_limit(format!(
                "the largest cluster ({} vertices × {floats} floats) would hold {} raw while it is compressed, over the {} budget: ask CtaCompress for more clusters",
                i.plan.largest(),
                fmt_bytes(bytes),
                fmt_bytes(budget)
            )));
        }
        Ok(ch)
    }
}

#[node(category = "ptt", sharded, metrics = ["rays", "raw_bytes", "compressed_bytes", "relative_error", "channels", "lighting_bases"])]
impl TransferT1 {
    fn shard(&self, i: &TransferT1In) -> Result<ShardSpec, NodeError> {
        self.check(i, relume_core::limits::default_budget())?;
        Ok(ShardSpec::new(i.plan.members.len() as u64, 1))
    }

    fn run_items(&self, i: &TransferT1In, items: Range<u64>, cx: &RunCtx) -> Result<ClusterPart, NodeError> {
        let ch = self.check(i, cx.memory_budget())?;
        let members = &i.plan.members[items.start as usize];
        let b = Bounce::new(i.scene, i.accel, i.visibility, i.basis, &ch, self.rays_side);
        let floats = b.floats();
        cx.phase(0.0, 0.8);
        let rows = cx.par_map(members.len(), |k| {
            let mut t = vec![0.0f32; floats];
            let rays = b.vertex(members[k] as usize, &mut t);
            (t, rays)
        })?;
        let rays = rows.iter().map(|r| r.1).sum();
        let mut x = Vec::with_capacity(members.len() * floats);
        for (t, _) in rows {
            x.extend(t);
        }
        cx.check()?;
        let tensor = compress(
            &x,
            [members.len(), b.lights(), ch.count() * SH],
            i.plan.rank_v as usize,
            i.plan.rank_l as usize,
            i.plan.sweeps as usize,
        )?;
        Ok(ClusterPart { tensor, rays })
    }

    fn gather(&self, i: &TransferT1In, parts: &[&ClusterPart], cx: &RunCtx) -> Result<TransferT1Out, NodeError> {
        let ch = self.check(i, cx.memory_budget())?;
        let clusters: Vec<ClusterTensor> = parts.iter().map(|p| p.tensor.clone()).collect();
        let (norm2, error2): (f64, f64) = clusters.iter().fold((0.0, 0.0), |a, t| (a.0 + t.norm2, a.1 + t.error2));
        let floats = 6 * (i.visibility.coarse as u64).pow(2) * ch.count() as u64 * SH as u64;
        let t = BounceTransfer {
            coarse: i.visibility.coarse,
            fixed: ch.fixed as u32,
            groups: ch.groups.clone(),
            bases: ch.bases as u32,
            plan: i.plan.clone(),
            clusters,
            textured: ch.textured.clone(),
        };
        if !t.is_consistent() {
            return Err(NodeError::failed("the clusters' tensors do not fit the plan"));
        }
        cx.metric("rays", parts.iter().map(|p| p.rays).sum::<u64>() as f64);
        cx.metric("raw_bytes", (i.plan.vertices() as u64 * floats * 4) as f64);
        cx.metric("compressed_bytes", t.byte_size() as f64);
        cx.metric("relative_error", if norm2 > 0.0 { (error2 / norm2).sqrt() } else { 0.0 });
        cx.metric("channels", ch.count() as f64);
        cx.metric("lighting_bases", (6 * i.visibility.coarse.pow(2)) as f64);
        Ok(TransferT1Out { transfer: t })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cta_compress::CtaCompress;
    use crate::vertex_visibility::tests::{floor_and_roof, visibility};
    use relume_base::testing::{first, i, run_full, run_on};
    use relume_base::types::accel::BuildQuality;
    use relume_core::Value;

    #[test]
    fn full_ranks_keep_the_raw_transfer_and_low_ranks_report_their_error() {
        let s = floor_and_roof(0.5);
        let accel = Value::new(Accel::build(&s, BuildQuality::Fast));
        let vis = visibility(&s, 16, 2);
        let basis =
            relume_base::brdf_space::test_support::basis(&relume_base::brdf_space::test_support::space(6, 6, 12, 12, 1.0, 100.0), 3).0;
        let run = |eig: i64, light: i64| {
            let plan: CtaPlan = first(
                &run_on::<CtaCompress>(
                    &[("clusters", i(3)), ("eigenvectors", i(eig)), ("lighting", i(light))],
                    vec![Value::new(s.clone()), Value::new(vis.clone())],
                )
                .expect("plan"),
            );
            let inputs = vec![Value::new(s.clone()), accel.clone(), Value::new(vis.clone()), Value::new(basis.clone()), Value::new(plan)];
            run_full::<TransferT1>(&[("rays_side", i(8))], std::path::Path::new("."), inputs).expect("runs")
        };
        let metric = |e: &relume_core::cache::CacheEntry, n: &str| e.metrics.iter().find(|m| m.0 == n).expect("metric").1;
        let full = run(100, 24);
        assert!(metric(&full, "relative_error") < 1e-3, "{}", metric(&full, "relative_error"));
        assert_eq!(metric(&full, "channels"), 1.0);
        let low = run(2, 3);
        let e = metric(&low, "relative_error");
        assert!(e > 1e-3 && e < 1.0, "{e}");
        assert!(metric(&low, "compressed_bytes") < metric(&full, "compressed_bytes"));
        // Roofed floor vertices get light from the roof: the transfer is not all zero.
        let t = full.outputs[0].get::<BounceTransfer>().expect("transfer");
        assert!(t.clusters.iter().any(|c| c.norm2 > 0.0));
        assert_eq!(BounceTransfer::decode(&t.encode()).as_ref(), Some(t));
    }
}
