use super::wavelet_radiance::code_tree;
use crate::types::{CodedWavelets, PointTree, PointWavelets};
use relume_base::math::tree_coding::Threshold;
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

/// How small stored coefficients are dropped.
#[derive(ParamEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rule {
    /// each coefficient below the threshold ([P] 4.5.2)
    Coefficient,
    /// each detail vector whose L2 norm is below the threshold (EGSR 2015); averages whole
    Vector,
}

params! {
    /// The points' wavelets coded along the point tree ([P] 4.5; `math::tree_coding`): every
    /// node's vector is the area-weighted average G of its children's (the thesis averages
    /// unweighted, which biases groups of unequal area; the module says why), nodes above level
    /// `split` keep G, nodes at `split` G and the detail H = (G_l − G_r) / 2, nodes below H
    /// only; stored vectors are thresholded by `rule`. One post-order pass holding at most
    /// depth + 2 uncompressed vectors. The report gives the coded bytes against every node
    /// keeping its average (the uncoded tree, measured by coding it so) and the vectors held.
    /// Memory: known only from the inputs' content; `run` checks the coded bound before coding.
    pub struct WaveletTree {
        /// split level ε: nodes above keep averages, below details ([P]: 20)
        pub split: u32 = 20, range = 0..=64, unit = "levels";
        /// drop stored coefficients (or detail vectors) below this ([P]: 0.002)
        pub threshold: f32 = 0.002, range = 0.0..=10.0;
        /// what the threshold drops
        pub rule: Rule = Coefficient;
        /// also code the uncoded tree for the report's bytes ratio (a second pass)
        pub report_uncoded: bool = true;
    }
}

impl WaveletTree {
    fn threshold(&self) -> Threshold {
        match self.rule {
            Rule::Coefficient => Threshold::Coefficient(self.threshold),
            Rule::Vector => Threshold::Vector(self.threshold),
        }
    }
}

#[node(category = "pbgi", metrics = ["nodes", "coded_bytes", "coefficients_kept", "coefficients_before_threshold", "uncompressed_vectors_held", "uncoded_bytes", "coding_ratio"], outputs = [coded])]
impl WaveletTree {
    fn run(&self, tree: &PointTree, wavelets: &PointWavelets, cx: &RunCtx) -> Result<CodedWavelets, NodeError> {
        let w = wavelets;
        let points = tree.nodes.iter().filter(|t| t.is_leaf()).count();
        if points != w.len() || tree.nodes.iter().any(|t| t.is_leaf() && t.point as usize >= w.len()) {
            return Err(NodeError::input("wavelets", format!("{} points' wavelets for a tree of {points} points", w.len())));
        }
        let dim = 18 * (w.n as u64).pow(2);
        let held = (tree.depth() as u64 + 2) * dim * 4;
        let bound = CodedWavelets::bound(tree, w) + held;
        if bound > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "coding could hold up to {} ({} nodes of vectors of {dim} values), over the {} budget: raise the threshold or lower SurfelWavelets' max_terms or resolution",
                relume_core::memory::fmt_bytes(bound),
                tree.nodes.len(),
                relume_core::memory::fmt_bytes(cx.memory_budget())
            )));
        }
        cx.check()?;
        let coded = code_tree(tree, w, self.split, self.threshold());
        cx.progress(1, 2);
        cx.metric("nodes", tree.nodes.len() as f64);
        cx.metric("coded_bytes", coded.bytes() as f64);
        cx.metric("coefficients_kept", coded.kept as f64);
        cx.metric("coefficients_before_threshold", coded.total as f64);
        cx.metric("uncompressed_vectors_held", coded.peak_live as f64);
        if self.report_uncoded {
            cx.check()?;
            let uncoded = code_tree(tree, w, u32::MAX, self.threshold());
            cx.metric("uncoded_bytes", uncoded.bytes() as f64);
            cx.metric("coding_ratio", uncoded.bytes() as f64 / coded.bytes().max(1) as f64);
        }
        cx.progress(2, 2);
        Ok(CodedWavelets { n: w.n, tree: coded })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wavelet_radiance::outgoing_intensity;
    use glam::Vec3;
    use relume_base::testing::{f, first, i, id, run_full, run_on};
    use relume_base::types::{Material, SurfacePoints};
    use relume_core::{PortValue, Value};

    /// A glossy floor of `count` points lit from one side, its tree and wavelets at side 8.
    fn floor(count: usize) -> (PointTree, PointWavelets) {
        let pts = SurfacePoints {
            position: (0..count).map(|k| Vec3::new((k % 20) as f32 * 0.1, 0.0, (k / 20) as f32 * 0.1)).collect(),
            normal: vec![Vec3::Y; count],
            radius: vec![0.05; count],
            object: vec![0; count],
            material: vec![Material::BlinnPhong { kd: Vec3::splat(0.2), ks: Vec3::splat(0.5), exponent: 60.0 }; count],
        };
        let light = Vec3::new(0.5, 1.0, 0.2).normalize();
        let per: Vec<_> = (0..count)
            .map(|k| {
                let e = Vec3::splat(1.0 + 0.3 * pts.position[k].x);
                relume_base::math::cube_haar::CubeHaar::forward(&outgoing_intensity(&pts.material[k], Vec3::Y, &[(light, e)], 8))
                    .keep_above(0.0)
            })
            .collect();
        (PointTree::build(&pts, &vec![Vec3::ZERO; count]), PointWavelets::from_points(8, &per))
    }

    #[test]
    fn the_coded_tree_is_smaller_within_its_bound_and_rebuilds_each_point_at_threshold_zero() {
        let (tree, w) = floor(300);
        let inputs = vec![Value::new(tree.clone()), Value::new(w.clone())];
        let exact: CodedWavelets = first(&run_on::<WaveletTree>(&[("split", i(3)), ("threshold", f(0.0))], inputs.clone()).unwrap());
        for (v, node) in tree.nodes.iter().enumerate().filter(|(_, t)| t.is_leaf()) {
            let got = exact.tree.reconstruct(v as u32);
            let want = w.sparse(node.point as usize).dense().coeffs;
            for (k, c) in want.iter().enumerate() {
                assert!((Vec3::new(got[3 * k], got[3 * k + 1], got[3 * k + 2]) - *c).abs().max_element() <= 1e-4, "leaf {v} [{k}]");
            }
        }
        let entry = run_full::<WaveletTree>(&[("split", i(3))], std::path::Path::new("."), inputs).unwrap();
        let m = |k: &str| entry.metrics.iter().find(|(n, _)| n == k).map(|(_, v)| *v).unwrap();
        assert!(m("coding_ratio") > 2.0, "{:?}", entry.metrics);
        assert!(m("coded_bytes") <= CodedWavelets::bound(&tree, &w) as f64);
        assert!(m("uncompressed_vectors_held") <= tree.depth() as f64 + 2.0);
        // The vector rule keeps averages whole and drops small details whole.
        let by_vector: CodedWavelets = first(
            &run_on::<WaveletTree>(&[("split", i(3)), ("rule", id("Vector"))], vec![Value::new(tree.clone()), Value::new(w.clone())])
                .unwrap(),
        );
        let small = |c: &CodedWavelets| c.tree.detail.iter().flatten().any(|d| d.value.iter().any(|v| v.abs() < 0.002));
        assert!(by_vector.tree.detail.iter().flatten().any(|d| d.index.is_empty()) && small(&by_vector));
        let by_coefficient: CodedWavelets = first(&entry.outputs);
        assert!(!small(&by_coefficient));
        // A stored tree decodes to itself; half of it is no tree.
        let bytes = by_vector.encode();
        assert_eq!(CodedWavelets::decode(&bytes).unwrap().encode(), bytes);
        assert!(CodedWavelets::decode(&bytes[..bytes.len() / 2]).is_none());
    }

    #[test]
    fn wavelets_of_another_point_set_and_a_tree_over_the_budget_are_refused() {
        let (tree, w) = floor(50);
        let (_, other) = floor(40);
        let err = run_on::<WaveletTree>(&[], vec![Value::new(tree.clone()), Value::new(other)]).unwrap_err();
        assert!(err.to_string().contains("40 points' wavelets for a tree of 50 points"), "{err}");
        let cancel = relume_core::CancelToken::new();
        let cx = RunCtx::new("t", &cancel, None).with_memory_budget(1000);
        let node = WaveletTree { split: 20, threshold: 0.002, rule: Rule::Coefficient, report_uncoded: false };
        let err = node.run_ports(&tree, &w, &cx).err().unwrap();
        assert!(err.to_string().contains("over the 1000 B budget") || err.to_string().contains("budget"), "{err}");
    }
}
