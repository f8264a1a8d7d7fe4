use super::sv_precompute::{sv_precompute, SvSettings};
use super::sv_shade::scene_sv_terms;
use crate::types::{PathCounts, SvTransfer};
use relume_base::types::accel::Accel;
use relume_base::types::{BrdfBasis, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// The precompute of spatially varying pixel relighting ([S] 4.2.1–4.2.2): the paths of
    /// `TransferPrecompute`, but each dynamic object is split into n × n sub-regions of its UV
    /// square and the one-bounce images gain the sub-region r1 of x″. Direct light keeps every
    /// basis (N_b direct, the basis' size); the bounce uses the first `indirect_bases` and drops
    /// specular-to-specular inter-reflection (4-36), which leaves 2·N_b,indirect − 1 groups of n²
    /// images per dynamic object. Streamed (see `relight::sv_precompute`): the direct images are
    /// kept whole; each group is compressed as the thesis orders it — uncentred PCA along the
    /// sub-regions (keep `pca_keep`), a median filter per basis image that never mixes objects,
    /// 2-D Haar per basis image padded to a power-of-two square (keep `haar_keep`) — from Gram
    /// matrices filled in a first pass and projections of the same seeded paths in a second, so
    /// the uncompressed blocks (21 GiB in the thesis' setting) are never held. What it would hold
    /// is checked against the memory budget before anything is allocated. Every dynamic object
    /// needs UVs; its texture maps may be anything (`SvRelight` reads them per edit). Seeded:
    /// the same bytes on any thread count; `paths` gives the path counts to a same-seed render
    /// (`RelightReference`, which reads the texture maps at every hit). Not sharded: the second pass needs every pixel's
    /// Gram sums first.
    pub struct SvTransferPrecompute {
        /// the path counts and the seed (shared with the other precompute)
        pub paths: PathCounts, flatten;
        /// sub-regions per side of each dynamic object's UV square ([S]: 32, 1024 in all)
        pub sub_regions: u32 = 32, range = 1..=64, test = 4;
        /// bases of the bounce (the first of the basis; [S]: 4 of 6)
        pub indirect_bases: u32 = 4, range = 1..=64;
        /// fraction of the PCA components along the sub-regions kept per group ([S]: 12.5 %)
        pub pca_keep: f64 = 0.125, range = 0.0001..=1.0;
        /// fraction of Haar coefficients kept per basis image ([S]: 13.3 %)
        pub haar_keep: f64 = 0.133, range = 0.0001..=1.0;
        /// radius of the median filter on each basis image (0: none; 1: 3 × 3)
        pub median_radius: u32 = 1, range = 0..=8, unit = "pixels";
    }
}

impl SvTransferPrecompute {
    pub fn settings(&self) -> SvSettings {
        SvSettings {
            sub_regions: self.sub_regions as usize,
            indirect_bases: self.indirect_bases as usize,
            pca_keep: self.pca_keep,
            haar_keep: self.haar_keep,
            median_radius: self.median_radius as usize,
        }
    }
}

#[node(category = "relight", version = 3, metrics = ["groups", "sub_regions", "images_uncompressed", "components", "uncompressed_bytes", "bytes", "compression_ratio", "pca_energy_lost_pct", "haar_energy_lost_pct", "passes", "rays", "dropped_samples", "mixed_pixels"], outputs = [transfer, paths])]
impl SvTransferPrecompute {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // What it holds depends on the scene's objects: the node checks its own estimate
        // (`sv_precompute::memory`) against the budget before allocating.
        let px = inputs[0].and_then(|s| s.pixels()).unwrap_or(0);
        relume_core::MemoryEstimate { outputs: vec![None, Some(relume_core::PortSize::bytes(32))], working: px * 16 }
    }

    fn run(&self, scene: &Scene, accel: &Accel, basis: &BrdfBasis, cx: &RunCtx) -> Result<(SvTransfer, PathCounts), NodeError> {
        let (transfer, st) = sv_precompute(scene, accel, basis, self.paths, &self.settings(), cx)?;
        let sv = scene_sv_terms(scene, self.sub_regions as usize, basis.bases(), self.indirect_bases as usize)
            .map_err(|m| NodeError::param("indirect_bases", m))?;
        let bytes = transfer.bytes();
        cx.metric("groups", sv.groups.len() as f64);
        cx.metric("sub_regions", (self.sub_regions * self.sub_regions) as f64);
        cx.metric("images_uncompressed", sv.images() as f64);
        cx.metric("components", st.components as f64);
        cx.metric("uncompressed_bytes", st.uncompressed_bytes as f64);
        cx.metric("bytes", bytes as f64);
        cx.metric("compression_ratio", st.uncompressed_bytes as f64 / bytes.max(1) as f64);
        let pct = |x: f64| if st.energy > 0.0 { 100.0 * x / st.energy } else { 0.0 };
        cx.metric("pca_energy_lost_pct", pct(st.pca_lost));
        cx.metric("haar_energy_lost_pct", pct(st.haar_lost));
        cx.metric("passes", st.passes as f64);
        cx.metric("rays", st.rays as f64);
        cx.metric("dropped_samples", st.dropped as f64);
        cx.metric("mixed_pixels", st.mixed as f64);
        cx.note(format!(
            "{} groups of {} sub-region images ({} uncompressed) held as {} ({} PCA components of {}, {} % of Haar coefficients)",
            sv.groups.len(),
            self.sub_regions * self.sub_regions,
            fmt_bytes(st.uncompressed_bytes),
            fmt_bytes(bytes),
            st.components,
            self.sub_regions * self.sub_regions,
            self.haar_keep * 100.0
        ));
        if !sv.traits.fixed_objects {
            cx.note("no fixed-material object: no images of the bounce onto fixed objects");
        }
        if !scene.has_lights() {
            cx.note("the scene has no light: every image is black");
        }
        Ok((transfer, self.paths))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::sv_scene;
    use relume_base::brdf_space::test_support::{basis, space};
    use relume_base::testing::{cancels_midway, f, i, run_full};
    use relume_core::Value;

    fn inputs(size: usize) -> Vec<Value> {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let s = sv_scene(size);
        let accel = Accel::build(&s, relume_base::types::accel::BuildQuality::Fast);
        vec![Value::new(s), Value::new(accel), Value::new(b)]
    }

    #[test]
    fn the_report_counts_groups_components_and_bytes_and_the_paths_go_out() {
        let p = [("spp", i(2)), ("bounce_rays", i(2)), ("sub_regions", i(4)), ("indirect_bases", i(2)), ("pca_keep", f(0.25))];
        let e = run_full::<SvTransferPrecompute>(&p, std::path::Path::new("."), inputs(8)).unwrap();
        let m = |k: &str| e.metrics.iter().find(|x| x.0 == k).unwrap_or_else(|| panic!("no {k}")).1;
        // Two dynamic objects × (2 · 2 − 1) groups of 16 sub-regions, 4 components each.
        assert_eq!((m("groups"), m("sub_regions"), m("components"), m("passes")), (6.0, 16.0, 4.0, 2.0));
        assert_eq!(m("images_uncompressed"), 6.0 * 16.0 + 3.0 + 2.0);
        assert_eq!(m("uncompressed_bytes"), m("images_uncompressed") * 64.0 * 12.0);
        let t = e.outputs[0].get::<SvTransfer>().unwrap();
        assert_eq!(m("bytes"), t.bytes() as f64);
        assert!(e.notes.iter().any(|n| n.contains("6 groups of 16 sub-region images")), "{:?}", e.notes);
        let paths = e.outputs[1].get::<PathCounts>().unwrap();
        assert_eq!((paths.spp, paths.bounce_rays, paths.seed), (2, 2, 0));
        assert_eq!(t.counts, *paths);
    }

    #[test]
    fn indirect_bases_beyond_the_basis_are_a_parameter_error() {
        let e = run_full::<SvTransferPrecompute>(&[("indirect_bases", i(5))], std::path::Path::new("."), inputs(4)).unwrap_err();
        assert!(e.to_string().contains("1 to 3"), "{e}");
    }

    #[test]
    fn the_node_stops_midway_when_cancelled() {
        let p = [("spp", i(4)), ("bounce_rays", i(8)), ("sub_regions", i(2)), ("indirect_bases", i(2))];
        cancels_midway::<SvTransferPrecompute>(&p, inputs(16));
    }
}
