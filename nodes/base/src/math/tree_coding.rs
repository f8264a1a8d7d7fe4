//! Hierarchical (wavelet-like) coding of per-node coefficient vectors in a binary point tree
//! ([P] 4.5, "Wavelet Point based Global Illumination" §4): every node's vector is the
//! average G of its children's, and the tree is coded as a 1-D Haar analysis along it. A
//! parent's detail is H = (G_left − G_right) / 2 (the thesis' definition). Nodes are
//! levelled from the root (level 0); with the split level ε, a node above ε (level < ε) keeps
//! its average G, a node at ε keeps G and H, a node below ε keeps H only (a leaf below ε keeps
//! nothing: it has no children to differ). A node below ε is rebuilt from its level-ε
//! ancestor down its path: each ancestor's detail enters with the sign of the child the path
//! takes (+ left, − right).
//!
//! **Area-weighted averages.** The thesis averages the two children unweighted, G = (G_l +
//! G_r) / 2. A node's radiance is the area-weighted mean of its points' (what a receiver
//! sees of the group), so with children of unequal area the unweighted mean over-weights the
//! smaller one and biases every inner node toward its sparse side. Here G = α G_l + β G_r with
//! α = A_l / (A_l + A_r), β = A_r / (A_l + A_r); H stays (G_l − G_r) / 2, so a child is
//! G_l = G + 2β H, G_r = G − 2α H (equal areas give the thesis' G ± H). The weights come from
//! the tree's areas, which the coding keeps (`share`).
//!
//! **Thresholds.** Each stored vector is approximated non-linearly after it has served its
//! parent (the parent is formed from the children's exact vectors, so errors do not compound
//! up the tree, as the thesis' algorithm 1 does): `Threshold::Coefficient` drops coefficients
//! of magnitude below t (the thesis), `Threshold::Vector` drops a whole detail vector whose
//! L2 norm is below t (the EGSR paper; averages are then kept whole).
//!
//! **Memory.** One post-order pass: a node's exact G lives until its parent is formed. The
//! uncompressed vectors held at once are those of the finished left siblings along the path
//! being descended plus the node being formed, so at most depth + 2, never one per point;
//! `CodedTree::peak_live` reports the count reached.

/// How small stored coefficients are dropped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Threshold {
    /// Drop each coefficient with |c| < t ([P] 4.5.2).
    Coefficient(f32),
    /// Drop a whole detail vector with ‖H‖₂ < t (EGSR 2015); averages are kept whole.
    Vector(f32),
}

/// A sparse vector: ascending indices and their values.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sparse {
    #[serde(with = "relume_core::codec::pod_vec")]
    pub index: Vec<u32>,
    #[serde(with = "relume_core::codec::pod_vec")]
    pub value: Vec<f32>,
}

impl Sparse {
    /// The entries of `dense` that pass `keep`, in index order.
    fn keep(dense: &[f32], keep: impl Fn(f32) -> bool) -> Sparse {
        let mut s = Sparse::default();
        for (i, &v) in dense.iter().enumerate() {
            if v != 0.0 && keep(v) {
                s.index.push(i as u32);
                s.value.push(v);
            }
        }
        s
    }

    /// Adds `w` times this vector to `out`.
    pub fn add_to(&self, w: f32, out: &mut [f32]) {
        for (&i, &v) in self.index.iter().zip(&self.value) {
            out[i as usize] += w * v;
        }
    }

    pub fn bytes(&self) -> usize {
        self.index.len() * 8
    }

    /// Entry `i` (0 where nothing is kept), by binary search.
    pub fn get(&self, i: u32) -> f32 {
        self.index.binary_search(&i).map_or(0.0, |k| self.value[k])
    }

    /// For each term (index i, weight t; ascending i), entries `stride · i … stride · i +
    /// stride − 1` added to `out` times `w · t`. The terms are found in one forward sweep:
    /// each search gallops on from where the last one stopped (a vector of RGB triples keeps
    /// a texel's channels adjacent, so a group is one search and a few reads).
    pub fn add_groups(&self, terms: &[(u32, f32)], stride: usize, w: f32, out: &mut [f32]) {
        let ix = &self.index;
        let mut lo = 0;
        for &(i, t) in terms {
            let first = stride as u32 * i;
            // Gallop: the first k ≥ lo with ix[k] ≥ first lies in (lo + step / 2, lo + step].
            let mut step = 1;
            while lo + step <= ix.len() && ix[lo + step - 1] < first {
                step *= 2;
            }
            let (a, b) = (lo + step / 2, (lo + step).min(ix.len()));
            let mut k = a + ix[a..b].partition_point(|&x| x < first);
            lo = k;
            while k < ix.len() && ix[k] < first + stride as u32 {
                out[(ix[k] - first) as usize] += w * t * self.value[k];
                k += 1;
            }
        }
    }
}

/// A binary tree as the coding reads it: per node its two children (`None` for a leaf) and
/// its area (a leaf's point area; an inner node's the sum of its children's).
#[derive(Clone, Copy)]
pub struct TreeShape<'a> {
    pub children: &'a [Option<[u32; 2]>],
    pub area: &'a [f32],
    pub root: u32,
}

/// The coded tree: per node its stored average (level ≤ ε) and detail (inner nodes at level
/// ≥ ε), with what rebuilding a node needs (parent, side, level, the children's area shares).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct CodedTree {
    pub dim: usize,
    /// The split level ε.
    pub split: u32,
    pub average: Vec<Option<Sparse>>,
    pub detail: Vec<Option<Sparse>>,
    /// Per node its parent (`u32::MAX` at the root) and whether it is its parent's left child.
    pub parent: Vec<(u32, bool)>,
    pub level: Vec<u32>,
    /// Per inner node, its left child's share α = A_l / (A_l + A_r) (½ when both are empty).
    pub share: Vec<f32>,
    /// The most uncompressed vectors held at once while coding.
    pub peak_live: usize,
    /// Coefficients kept and coefficients before the thresholds (over stored vectors).
    pub kept: usize,
    pub total: usize,
}

impl CodedTree {
    /// Codes the tree: `leaf(node, out)` writes a leaf's exact vector (`dim` long, zeroed).
    /// Nodes are visited in post-order, left child first; `leaf` is called once per leaf.
    pub fn build(shape: TreeShape, dim: usize, split: u32, threshold: Threshold, mut leaf: impl FnMut(u32, &mut [f32])) -> CodedTree {
        let n = shape.children.len();
        let mut c = CodedTree {
            dim,
            split,
            average: vec![None; n],
            detail: vec![None; n],
            parent: vec![(u32::MAX, false); n],
            level: vec![0; n],
            share: vec![0.5; n],
            peak_live: 0,
            kept: 0,
            total: 0,
        };
        // Levels and parents, top down.
        let mut stack = vec![shape.root];
        while let Some(p) = stack.pop() {
            if let Some([l, r]) = shape.children[p as usize] {
                for (k, ch) in [l, r].into_iter().enumerate() {
                    c.parent[ch as usize] = (p, k == 0);
                    c.level[ch as usize] = c.level[p as usize] + 1;
                    stack.push(ch);
                }
            }
        }
        // Post-order with an explicit stack: (node, children done); finished exact vectors
        // wait on `live` until their parent takes them.
        let mut live: Vec<Vec<f32>> = vec![];
        let mut todo = vec![(shape.root, false)];
        while let Some((node, expanded)) = todo.pop() {
            match (shape.children[node as usize], expanded) {
                (Some([l, r]), false) => {
                    todo.push((node, true));
                    todo.push((r, false));
                    todo.push((l, false));
                }
                (Some(_), true) => {
                    // The two children's exact vectors are the last two on `live`.
                    let gr = live.pop().expect("right child");
                    let gl = live.pop().expect("left child");
                    let [l, r] = shape.children[node as usize].expect("inner");
                    let (al, ar) = (shape.area[l as usize] as f64, shape.area[r as usize] as f64);
                    let alpha = if al + ar > 0.0 { (al / (al + ar)) as f32 } else { 0.5 };
                    c.share[node as usize] = alpha;
                    let beta = 1.0 - alpha;
                    let g: Vec<f32> = gl.iter().zip(&gr).map(|(a, b)| alpha * a + beta * b).collect();
                    let h: Vec<f32> = gl.iter().zip(&gr).map(|(a, b)| (a - b) * 0.5).collect();
                    c.peak_live = c.peak_live.max(live.len() + 3);
                    c.store(l, gl, threshold);
                    c.store(r, gr, threshold);
                    if c.level[node as usize] >= split {
                        c.detail[node as usize] = Some(c.approximate(&h, threshold, true));
                    }
                    live.push(g);
                }
                (None, _) => {
                    let mut v = vec![0.0f32; dim];
                    leaf(node, &mut v);
                    live.push(v);
                    c.peak_live = c.peak_live.max(live.len());
                }
            }
        }
        let root = live.pop().expect("the root's vector");
        c.store(shape.root, root, threshold);
        c
    }

    /// Keeps node `v`'s exact average when its level is at most ε.
    fn store(&mut self, v: u32, g: Vec<f32>, threshold: Threshold) {
        if self.level[v as usize] <= self.split {
            self.average[v as usize] = Some(self.approximate(&g, threshold, false));
        }
    }

    fn approximate(&mut self, v: &[f32], threshold: Threshold, is_detail: bool) -> Sparse {
        self.total += v.len();
        let s = match threshold {
            Threshold::Coefficient(t) => Sparse::keep(v, |x| x.abs() >= t),
            Threshold::Vector(t) if is_detail => {
                let norm = v.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
                if norm < t as f64 {
                    Sparse::default()
                } else {
                    Sparse::keep(v, |_| true)
                }
            }
            Threshold::Vector(_) => Sparse::keep(v, |_| true),
        };
        self.kept += s.index.len();
        s
    }

    /// Node `v`'s vector: its stored average, or its level-ε ancestor's plus the details of
    /// the ancestors below that on its path, each with the sign (and area weight) of the
    /// child the path takes.
    pub fn reconstruct(&self, v: u32) -> Vec<f32> {
        let mut path = vec![];
        let mut at = v;
        while self.average[at as usize].is_none() {
            path.push(at);
            at = self.parent[at as usize].0;
            assert!(at != u32::MAX, "node {v} has no stored average above it");
        }
        let mut out = vec![0.0f32; self.dim];
        self.average[at as usize].as_ref().expect("stored").add_to(1.0, &mut out);
        // Down from the ancestor: each step adds the parent's detail toward the child taken.
        for &child in path.iter().rev() {
            let (p, left) = self.parent[child as usize];
            if let Some(h) = &self.detail[p as usize] {
                h.add_to(self.detail_weight(p, left), &mut out);
            }
        }
        out
    }

    /// Σ weight × entries `stride · index … + stride − 1` of node `v`'s vector, over `terms`
    /// (index, weight; indices ascending), into `out` (`stride` long, zeroed first): a few entries of the
    /// vector `reconstruct` would build whole, read from the same stored vectors (a texel
    /// of a node's radiance from `cube_haar::texel_terms`, RGB with stride 3).
    pub fn dot(&self, v: u32, terms: &[(u32, f32)], stride: usize, out: &mut [f32]) {
        out.fill(0.0);
        let mut at = v;
        // Up from `v` to its stored average: each detail on the way enters with the sign and
        // weight of the child the path takes, as in `reconstruct`.
        loop {
            if let Some(g) = &self.average[at as usize] {
                g.add_groups(terms, stride, 1.0, out);
                break;
            }
            let (p, left) = self.parent[at as usize];
            assert!(p != u32::MAX, "node {v} has no stored average above it");
            let w = self.detail_weight(p, left);
            if let Some(h) = &self.detail[p as usize] {
                h.add_groups(terms, stride, w, out);
            }
            at = p;
        }
    }

    /// The weight of parent p's detail in its child's vector: G_child = G_p + w H_p, with
    /// w = 2 (1 − α) for the left child and −2 α for the right (α the left child's area share).
    pub fn detail_weight(&self, p: u32, left: bool) -> f32 {
        let alpha = self.share[p as usize];
        if left {
            2.0 * (1.0 - alpha)
        } else {
            -2.0 * alpha
        }
    }

    /// Whether the parts agree (what decoding a stored tree checks before anything reads
    /// it): one entry per node everywhere, parents one level up, every node below ε with a
    /// stored average above it, sparse indices ascending and under `dim`, shares in [0, 1].
    pub fn is_consistent(&self) -> bool {
        let n = self.average.len();
        let lengths = [self.detail.len(), self.parent.len(), self.level.len(), self.share.len()].iter().all(|&l| l == n);
        let sparse_ok = |s: &Sparse| {
            s.index.len() == s.value.len()
                && s.index.windows(2).all(|w| w[0] < w[1])
                && s.index.last().is_none_or(|&i| (i as usize) < self.dim)
        };
        lengths
            && self.average.iter().chain(&self.detail).flatten().all(sparse_ok)
            && self.share.iter().all(|a| (0.0..=1.0).contains(a))
            && (0..n).all(|v| match self.parent[v].0 {
                u32::MAX => self.level[v] == 0 && self.average[v].is_some(),
                p => (p as usize) < n && self.level[p as usize].checked_add(1) == Some(self.level[v]),
            })
            // Levels strictly fall toward the root, so the walk up ends; it must meet an average.
            && (0..n).all(|v| {
                let mut at = v;
                while self.average[at].is_none() {
                    match self.parent[at].0 {
                        u32::MAX => return false,
                        p => at = p as usize,
                    }
                }
                true
            })
    }

    /// Bytes of the stored vectors (index and value per kept coefficient).
    pub fn bytes(&self) -> usize {
        self.average.iter().chain(&self.detail).flatten().map(Sparse::bytes).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A tree over leaves 0 … n − 1 split at the middle (unbalanced when n is not a power of
    /// two), with the leaves under each node.
    struct TestTree {
        children: Vec<Option<[u32; 2]>>,
        area: Vec<f32>,
        under: Vec<Vec<usize>>,
        root: u32,
    }

    impl TestTree {
        fn new(leaves: usize, leaf_area: impl Fn(usize) -> f32) -> TestTree {
            let mut t = TestTree { children: vec![], area: vec![], under: vec![], root: 0 };
            t.root = t.make(0..leaves, &leaf_area);
            t
        }

        fn make(&mut self, range: std::ops::Range<usize>, la: &dyn Fn(usize) -> f32) -> u32 {
            let (child, area, under) = if range.len() == 1 {
                (None, la(range.start), vec![range.start])
            } else {
                let mid = range.start + range.len() / 2;
                let l = self.make(range.start..mid, la);
                let r = self.make(mid..range.end, la);
                let (l, r) = (l as usize, r as usize);
                (Some([l as u32, r as u32]), self.area[l] + self.area[r], [self.under[l].clone(), self.under[r].clone()].concat())
            };
            self.children.push(child);
            self.area.push(area);
            self.under.push(under);
            (self.children.len() - 1) as u32
        }

        fn shape(&self) -> TreeShape<'_> {
            TreeShape { children: &self.children, area: &self.area, root: self.root }
        }

        /// Coded with leaf p's vector entry d = `value(p, d)`.
        fn code(&self, dim: usize, split: u32, threshold: Threshold, value: impl Fn(usize, usize) -> f32) -> CodedTree {
            CodedTree::build(self.shape(), dim, split, threshold, |v, out| {
                let p = self.under[v as usize][0];
                (0..dim).for_each(|d| out[d] = value(p, d));
            })
        }
    }

    /// The area-weighted mean of the leaves `under` a node, in f64.
    fn direct(under: &[usize], area: &dyn Fn(usize) -> f32, value: &dyn Fn(usize, usize) -> f32, dim: usize) -> Vec<f64> {
        let total: f64 = under.iter().map(|&p| area(p) as f64).sum();
        (0..dim).map(|d| under.iter().map(|&p| area(p) as f64 * value(p, d) as f64).sum::<f64>() / total).collect()
    }

    #[test]
    fn at_threshold_zero_every_node_is_its_leaves_average_exactly_on_dyadic_values() {
        // Equal areas and values in eighths: every sum and half is exact in f32, so the
        // rebuilt vectors equal the direct averages bit for bit, at every split level.
        let dim = 5;
        let value = |p: usize, d: usize| ((p * 7 + d * 3) % 16) as f32 / 8.0;
        let t = TestTree::new(16, |_| 1.0);
        for split in [0, 1, 2, 4] {
            let c = t.code(dim, split, Threshold::Coefficient(0.0), value);
            for (v, under) in t.under.iter().enumerate() {
                let want: Vec<f32> = direct(under, &|_| 1.0, &value, dim).iter().map(|&x| x as f32).collect();
                assert_eq!(c.reconstruct(v as u32), want, "split {split}, node {v}");
            }
        }
    }

    #[test]
    fn each_detail_enters_with_the_sign_of_the_child_on_the_path() {
        // Two leaves a and b of equal area under the root: H = (a − b)/2, left = G + H,
        // right = G − H; split 0 stores only the root's G and H.
        let t = TestTree::new(2, |_| 1.0);
        let vals = [[3.0f32, -1.0], [1.0, 5.0]];
        let c = t.code(2, 0, Threshold::Coefficient(0.0), |p, d| vals[p][d]);
        let h = c.detail[t.root as usize].as_ref().expect("the root's detail");
        assert_eq!(h.value, vec![1.0, -3.0]);
        assert!(c.average.iter().enumerate().all(|(v, a)| a.is_some() == (v == t.root as usize)));
        let [l, r] = t.children[t.root as usize].unwrap();
        assert_eq!((c.reconstruct(l), c.reconstruct(r)), (vals[0].to_vec(), vals[1].to_vec()));
    }

    #[test]
    fn unequal_areas_weight_the_average_and_a_bright_coefficient_survives_the_threshold() {
        // Leaf areas 1 … 9: the thesis' unweighted mean would be off by the areas' spread.
        let la = |p: usize| 1.0 + (p % 9) as f32;
        let t = TestTree::new(23, la);
        let dim = 64;
        let value = |p: usize, d: usize| if d == 10 && p == 5 { 50.0 } else { 0.0002 * ((p + d) % 7) as f32 };
        let exact = t.code(dim, 2, Threshold::Coefficient(0.0), value);
        for (v, under) in t.under.iter().enumerate() {
            let want = direct(under, &la, &value, dim);
            let got = exact.reconstruct(v as u32);
            for d in 0..dim {
                assert!((got[d] as f64 - want[d]).abs() <= 1e-5 * (1.0 + want[d].abs()), "node {v} [{d}]: {} vs {}", got[d], want[d]);
            }
        }
        // With the thesis' 0.002 the small coefficients go, the bright one stays on its path.
        let coded = t.code(dim, 2, Threshold::Coefficient(0.002), value);
        assert!(coded.kept < coded.total / 4, "{} of {}", coded.kept, coded.total);
        let leaf5 = (0..t.children.len()).find(|&v| t.children[v].is_none() && t.under[v][0] == 5).unwrap();
        let got = coded.reconstruct(leaf5 as u32);
        assert!((got[10] - 50.0).abs() < 0.01, "{}", got[10]);
        assert!(coded.bytes() < exact.bytes());
    }

    #[test]
    fn whole_detail_vectors_below_the_norm_are_dropped_and_constant_leaves_need_no_detail() {
        let t = TestTree::new(32, |p| 1.0 + p as f32);
        let flat = t.code(8, 0, Threshold::Vector(0.002), |_, _| 0.25);
        // Equal children: every detail is (about) zero and dropped; every node rebuilds to 0.25.
        assert!(flat.detail.iter().flatten().all(|h| h.index.is_empty()));
        assert_eq!(flat.kept, 8, "the root's average alone");
        for v in 0..t.children.len() {
            assert!(flat.reconstruct(v as u32).iter().all(|&x| (x - 0.25).abs() < 1e-6));
        }
    }

    #[test]
    fn the_uncompressed_vectors_held_stay_within_the_depth() {
        let t = TestTree::new(1000, |_| 1.0);
        let c = t.code(4, 3, Threshold::Coefficient(0.0), |_, _| 0.0);
        let depth = *c.level.iter().max().unwrap() as usize;
        assert!(c.peak_live <= depth + 2 && c.peak_live >= 3, "{} held, depth {depth}", c.peak_live);
    }

    #[test]
    fn a_few_entries_read_through_dot_are_those_of_the_rebuilt_vector() {
        // 60-long vectors as 20 triples, thresholded so that some stored entries are gone.
        let t = TestTree::new(37, |p| 1.0 + (p % 3) as f32);
        let c = t.code(60, 2, Threshold::Coefficient(0.3), |p, d| ((p * 7 + d * 5) % 11) as f32 / 5.0 - 1.0);
        let mut out = [0.0f32; 3];
        let all: Vec<(u32, f32)> = (0..20).map(|i| (i, 0.1 * i as f32 - 1.0)).collect();
        for v in 0..t.children.len() as u32 {
            let full = c.reconstruct(v);
            for terms in [vec![(0, 1.0)], vec![(19, 1.0)], vec![(1, 0.5), (7, -2.0), (8, 1.0), (19, 3.0)], all.clone()] {
                c.dot(v, &terms, 3, &mut out);
                for ch in 0..3 {
                    let want: f32 = terms.iter().map(|&(i, w)| w * full[3 * i as usize + ch]).sum();
                    assert!((out[ch] - want).abs() <= 1e-5 * (1.0 + want.abs()), "node {v} {terms:?} [{ch}]: {} vs {want}", out[ch]);
                }
            }
        }
    }

    proptest! {
        #[test]
        fn any_tree_and_areas_rebuild_to_the_weighted_average(leaves in 1usize..40, seed in 0u64..1000, split in 0u32..6) {
            let la = move |p: usize| 0.5 + ((p as u64 * 2654435761 + seed) % 97) as f32 / 10.0;
            let value = move |p: usize, d: usize| (((p as u64 * 31 + d as u64 * 17 + seed) % 101) as f32 - 50.0) / 7.0;
            let t = TestTree::new(leaves, la);
            let c = t.code(3, split, Threshold::Coefficient(0.0), value);
            for (v, under) in t.under.iter().enumerate() {
                let want = direct(under, &la, &value, 3);
                let got = c.reconstruct(v as u32);
                for d in 0..3 {
                    prop_assert!((got[d] as f64 - want[d]).abs() <= 1e-4 * (1.0 + want[d].abs()), "node {} [{}]: {} vs {}", v, d, got[d], want[d]);
                }
            }
        }
    }
}
