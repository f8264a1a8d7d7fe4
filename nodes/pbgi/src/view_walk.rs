//! The view tree's walk ([P] 5.3.2–5.3.4): every point of the tree gathers its incoming
//! light, the tree traversed against itself rather than once per point.
//!
//! The walk descends the receiver tree from the root carrying the senders still to decide
//! (`view_pairs::classify`, starting from (root, root)). At a receiver node R each candidate
//! is culled, accepted into R's cut, split (its children decided against R in turn) or handed
//! down to R's children; so a sender accepted at R is decided once for every point below R,
//! where a per-receiver traversal decides it again for each. The cuts are not stored: each
//! receiver leaf rasterises the cuts of its ancestors and its own, and its near leaves, into
//! its microbuffer.
//!
//! Buffer reuse: where a group's normals agree (cone within `reuse_angle`), its cut and the
//! cuts above it are rasterised once, into one buffer at the group's centre in the frame of
//! its cone axis (the topmost such group's), and every group and leaf below starts from a
//! copy of it, adds what it accepted itself, and hands it down (a leaf adds its near leaves
//! last). A flat wall's leaves share their normal exactly;
//! the view threshold keeps a group small as seen from its senders, so their directions from
//! the group's centre and from its points fall in the same pixel. Leaves whose group normals
//! disagree rasterise everything themselves, in their own frame.
//!
//! The per-receiver traversal (`Walk::PerReceiver`), each point from the root on its own, is
//! kept to measure the view tree against (same microbuffer, same thresholds).
//!
//! Results are per point and a pure function of the inputs: the order of work between
//! threads changes no byte.

use super::microbuffer::Microbuffer;
use super::traversal::{disk_light, flat_of, GatherCounts, NodeRadiance, Traversal};
use super::view_pairs::{classify, Pair, PairTest};
use crate::types::PointTree;
use glam::Vec3;
use relume_base::math::frame::Frame;
use relume_core::{NodeError, RunCtx};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// The settings of a walk; `R` says what the nodes send.
pub struct ViewWalk<'a, R: NodeRadiance> {
    pub tree: &'a PointTree,
    pub source: &'a R,
    /// Microbuffer side.
    pub resolution: usize,
    /// Largest solid angle of a rasterised node, in microbuffer pixels.
    pub threshold: f32,
    /// Largest solid angle (sr) of a receiver group seen from a sender it accepts.
    pub view_omega: f32,
    /// Cosine of the widest normal cone whose group shares one buffer.
    pub reuse_cos: f32,
    /// Self-intersection guard and horizon slack.
    pub eps: f32,
}

/// What a walk did, summed over receivers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WalkCounts {
    /// Pairs decided (the per-receiver traversal: nodes visited).
    pub pairs: u64,
    /// Nodes rasterised into buffers.
    pub rasterised: u64,
    /// Near leaves ray-cast.
    pub near: u64,
    /// Buffers rasterised for groups.
    pub group_buffers: u64,
    /// Leaves that started from their group's buffer.
    pub reused: u64,
}

impl std::ops::AddAssign for WalkCounts {
    fn add_assign(&mut self, o: WalkCounts) {
        self.pairs += o.pairs;
        self.rasterised += o.rasterised;
        self.near += o.near;
        self.group_buffers += o.group_buffers;
        self.reused += o.reused;
    }
}

/// Receiver subtrees at most this deep are split between threads.
const PARALLEL_DEPTH: u32 = 10;

/// A group's shared buffer and its frame.
type Group = Arc<(Microbuffer, Frame)>;

impl<R: NodeRadiance> ViewWalk<'_, R> {
    fn pair_test(&self) -> PairTest {
        let per_pixel = Microbuffer::new(self.resolution).mean_pixel_solid_angle();
        PairTest { sender_omega: self.threshold * per_pixel, view_omega: self.view_omega, eps: self.eps }
    }

    /// Every point's gathered light, through the view tree: `done(point, buffer, frame)` for
    /// each leaf (its microbuffer and the frame it is in), in the tree's leaf order.
    pub fn run<T: Send>(
        &self,
        cx: &RunCtx,
        done: &(impl Fn(u32, &Microbuffer, &Frame) -> T + Sync),
    ) -> Result<(Vec<(u32, T)>, WalkCounts), NodeError> {
        self.run_serving(cx, &|_| true, done)
    }

    /// `run` for the points `serves` accepts only (the others get no result): the receiver
    /// subtrees with no such point are not walked at all, and a leaf outside it rasterises
    /// nothing. `ViewTree` gathers the points on glass on their own, in spherical buffers.
    pub fn run_serving<T: Send>(
        &self,
        cx: &RunCtx,
        serves: &(impl Fn(u32) -> bool + Sync),
        done: &(impl Fn(u32, &Microbuffer, &Frame) -> T + Sync),
    ) -> Result<(Vec<(u32, T)>, WalkCounts), NodeError> {
        cx.check()?;
        let progress = Progress::new(self.tree, cx);
        let mut out = Vec::new();
        let mut counts = WalkCounts::default();
        if self.tree.nodes.is_empty() {
            return Ok((out, counts));
        }
        let (root, senders) = (self.tree.root, self.tree.outer_root());
        let test = self.pair_test();
        let served = served_nodes(self.tree, serves);
        let ctx = Descent { test: &test, served: &served, progress: &progress };
        self.descend(root, 0, vec![senders], vec![], None, &ctx, done, &mut out, &mut counts)?;
        Ok((out, counts))
    }

    #[allow(clippy::too_many_arguments)]
    fn descend<T: Send>(
        &self,
        r: u32,
        depth: u32,
        candidates: Vec<u32>,
        mut pending: Vec<u32>,
        group: Option<Group>,
        ctx: &Descent,
        done: &(impl Fn(u32, &Microbuffer, &Frame) -> T + Sync),
        out: &mut Vec<(u32, T)>,
        counts: &mut WalkCounts,
    ) -> Result<(), NodeError> {
        let (test, progress) = (ctx.test, ctx.progress);
        if !ctx.served[r as usize] {
            return progress.leaves(leaves_below(self.tree, r));
        }
        let tree = self.tree;
        let (mut work, mut down, mut near) = (candidates, Vec::new(), Vec::new());
        while let Some(s) = work.pop() {
            counts.pairs += 1;
            match classify(tree, r, s, test) {
                Pair::Cull => {}
                Pair::Accept => pending.push(s),
                Pair::Near => near.push(s),
                Pair::SplitSender => work.extend(tree.nodes[s as usize].children.expect("only inner senders split")),
                Pair::SplitReceiver => down.push(s),
            }
        }
        let rn = &tree.nodes[r as usize];
        let Some([a, b]) = rn.children else {
            let (mut mb, frame) = match &group {
                Some(g) => {
                    counts.reused += 1;
                    (g.0.clone(), g.1)
                }
                None => (Microbuffer::new(self.resolution), Frame::from_normal(rn.cone_axis)),
            };
            // Near leaves among the rest, all by descending index: the order a per-receiver
            // traversal (right child first) meets them in.
            let mut all: Vec<(u32, bool)> = pending.iter().map(|&s| (s, false)).chain(near.iter().map(|&s| (s, true))).collect();
            all.sort_unstable_by_key(|a| std::cmp::Reverse(a.0));
            for (s, is_near) in all {
                if is_near {
                    counts.near += 1;
                    self.near_leaf(s, rn.center, &frame, &mut mb);
                } else {
                    self.rasterise(&[s], rn.center, &frame, &mut mb, counts);
                }
            }
            mb.resolve();
            out.push((rn.point, done(rn.point, &mb, &frame)));
            progress.leaves(1)?;
            return Ok(());
        };
        // A group whose normals agree rasterises what it accepted (and what is pending from
        // above) once, on top of its parent group's buffer, in that buffer's frame.
        let group = if rn.cone_cos >= self.reuse_cos && !pending.is_empty() {
            counts.group_buffers += 1;
            let (mut mb, frame) = match &group {
                Some(g) => (g.0.clone(), g.1),
                None => (Microbuffer::new(self.resolution), Frame::from_normal(rn.cone_axis)),
            };
            pending.sort_unstable_by(|a, b| b.cmp(a));
            self.rasterise(&pending, rn.center, &frame, &mut mb, counts);
            pending.clear();
            Some(Arc::new((mb, frame)))
        } else {
            group
        };
        if depth < PARALLEL_DEPTH {
            progress.cx.check()?;
            let (left, right) = rayon::join(
                || {
                    let (mut o, mut c) = (Vec::new(), WalkCounts::default());
                    let r = self.descend(a, depth + 1, down.clone(), pending.clone(), group.clone(), ctx, done, &mut o, &mut c);
                    r.map(|_| (o, c))
                },
                || {
                    let (mut o, mut c) = (Vec::new(), WalkCounts::default());
                    let r = self.descend(b, depth + 1, down.clone(), pending.clone(), group.clone(), ctx, done, &mut o, &mut c);
                    r.map(|_| (o, c))
                },
            );
            for part in [left?, right?] {
                out.extend(part.0);
                *counts += part.1;
            }
            Ok(())
        } else {
            self.descend(a, depth + 1, down.clone(), pending.clone(), group.clone(), ctx, done, out, counts)?;
            self.descend(b, depth + 1, down, pending, group, ctx, done, out, counts)
        }
    }

    /// Ray-casts near leaf `s` seen from `p` into `mb` (in `frame`) as a disk.
    fn near_leaf(&self, s: u32, p: Vec3, frame: &Frame, mb: &mut Microbuffer) {
        let sn = &self.tree.nodes[s as usize];
        let v = sn.center - p;
        let (c, nrm) = (frame.to_local(v), frame.to_local(sn.cone_axis));
        disk_light(self.source, s, v, frame, |l| mb.disk_lit(c, nrm, sn.bound, l, self.eps));
    }

    /// Rasterises senders seen from `p` into `mb` (in `frame`), in the order given.
    fn rasterise(&self, senders: &[u32], p: Vec3, frame: &Frame, mb: &mut Microbuffer, counts: &mut WalkCounts) {
        for &s in senders {
            let v = self.tree.nodes[s as usize].center - p;
            let d = v.length();
            if d <= 0.0 {
                continue;
            }
            let (a, l) = self.source.area_and_radiance(s, -v / d);
            if a > 0.0 {
                counts.rasterised += 1;
                let n = &self.tree.nodes[s as usize];
                let flat = flat_of(n.cone_axis, n.slab, n.bound, n.is_leaf(), frame, v);
                mb.splat(frame.to_local(v / d), d, a / (d * d), l, flat);
            }
        }
    }

    /// The same, each point traversing the tree from the root on its own (the per-receiver
    /// gather of `PbgiGather`), in its own frame.
    pub fn run_per_receiver<T: Send>(
        &self,
        cx: &RunCtx,
        done: &(impl Fn(u32, &Microbuffer, &Frame) -> T + Sync),
    ) -> Result<(Vec<(u32, T)>, WalkCounts), NodeError> {
        self.run_per_receiver_serving(cx, &|_| true, done)
    }

    /// `run_per_receiver` for the points `serves` accepts only.
    pub fn run_per_receiver_serving<T: Send>(
        &self,
        cx: &RunCtx,
        serves: &(impl Fn(u32) -> bool + Sync),
        done: &(impl Fn(u32, &Microbuffer, &Frame) -> T + Sync),
    ) -> Result<(Vec<(u32, T)>, WalkCounts), NodeError> {
        let t = Traversal::with_source(self.tree, self.source, self.threshold, self.eps);
        let nodes = &self.tree.nodes;
        let leaves: Vec<u32> =
            (0..nodes.len() as u32).filter(|&i| nodes[i as usize].is_leaf() && serves(nodes[i as usize].point)).collect();
        let results = cx.par_map_init(
            leaves.len(),
            || (Microbuffer::new(self.resolution), Vec::new()),
            |(mb, stack), k| {
                let node = &self.tree.nodes[leaves[k] as usize];
                let frame = Frame::from_normal(node.cone_axis);
                let mut c = GatherCounts::default();
                mb.clear();
                t.run(&[self.tree.outer_root()], node.center, &frame, mb, stack, &mut c, |_, _| false);
                mb.resolve();
                let counts = WalkCounts { pairs: c.visited, rasterised: c.rasterised, near: c.near_leaves, ..Default::default() };
                ((node.point, done(node.point, mb, &frame)), counts)
            },
        )?;
        let mut total = WalkCounts::default();
        let out = results
            .into_iter()
            .map(|(r, c)| {
                total += c;
                r
            })
            .collect();
        Ok((out, total))
    }
}

/// What every step of a walk's descent reads: the pair test, which receiver subtrees hold a
/// point the walk serves, and the progress.
struct Descent<'a, 'c, 'r> {
    test: &'a PairTest,
    served: &'a [bool],
    progress: &'a Progress<'c, 'r>,
}

/// Per tree node, whether a point below it is one `serves` accepts (children follow their
/// parent in the tree's order, so one pass from the end sees them first).
fn served_nodes(tree: &PointTree, serves: &(impl Fn(u32) -> bool + Sync)) -> Vec<bool> {
    let mut served = vec![false; tree.nodes.len()];
    for i in (0..tree.nodes.len()).rev() {
        let n = &tree.nodes[i];
        served[i] = match n.children {
            None => serves(n.point),
            Some([a, b]) => served[a as usize] || served[b as usize],
        };
    }
    served
}

/// The leaves below tree node `r` (itself, for a leaf).
fn leaves_below(tree: &PointTree, r: u32) -> u64 {
    let (mut stack, mut n) = (vec![r], 0);
    while let Some(i) = stack.pop() {
        match tree.nodes[i as usize].children {
            None => n += 1,
            Some([a, b]) => stack.extend([a, b]),
        }
    }
    n
}

/// Leaves done, reported now and then; stops the walk when the run is cancelled.
struct Progress<'c, 'r> {
    cx: &'c RunCtx<'r>,
    done: AtomicU64,
    total: u64,
}

impl<'c, 'r> Progress<'c, 'r> {
    fn new(tree: &PointTree, cx: &'c RunCtx<'r>) -> Self {
        Progress { cx, done: AtomicU64::new(0), total: tree.nodes.len().div_ceil(2) as u64 }
    }

    fn leaves(&self, n: u64) -> Result<(), NodeError> {
        if n == 0 {
            return Ok(());
        }
        let k = self.done.fetch_add(n, Ordering::Relaxed) + n;
        if k / 1024 != (k - n) / 1024 {
            self.cx.check()?;
            self.cx.progress(k, self.total);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view_pairs::tests::facing_planes;
    use relume_base::types::Material;
    use relume_core::CancelToken;

    fn walk(tree: &PointTree) -> ViewWalk<'_, PointTree> {
        ViewWalk { tree, source: tree, resolution: 8, threshold: 1.0, view_omega: 0.005, reuse_cos: 1.0, eps: 1e-5 }
    }

    /// Irradiance-weighted Lambert radiance (albedo 1) of every point, by point.
    fn per_point(out: Vec<(u32, Vec3)>) -> Vec<Vec3> {
        let mut v = vec![Vec3::ZERO; out.len()];
        for (p, l) in out {
            v[p as usize] = l;
        }
        v
    }

    fn lambert(_: u32, mb: &Microbuffer, frame: &Frame) -> Vec3 {
        let m = Material::Lambert { albedo: Vec3::ONE };
        mb.convolve_in(&m, frame.n, frame, frame)
    }

    /// Both walks over `tree`: per point the view tree's and the per-receiver result, and
    /// their counts.
    fn both(tree: &PointTree, reuse_cos: f32) -> (Vec<Vec3>, Vec<Vec3>, WalkCounts, WalkCounts) {
        let w = ViewWalk { reuse_cos, ..walk(tree) };
        let cancel = CancelToken::new();
        let cx = RunCtx::new("t", &cancel, None);
        let (shared, c_view) = w.run(&cx, &lambert).unwrap();
        let (alone, c_alone) = w.run_per_receiver(&cx, &lambert).unwrap();
        (per_point(shared), per_point(alone), c_view, c_alone)
    }

    fn mean(v: &[Vec3]) -> f64 {
        v.iter().map(|l| l.x as f64).sum::<f64>() / v.len() as f64
    }

    #[test]
    fn without_group_buffers_each_point_gets_the_bytes_of_its_own_traversal() {
        // Two facing planes 0.5 apart, every point sending radiance 1: each point rasterises
        // the nodes its own traversal would, in its order (descending index), so the same
        // bytes. Every sender is near, so groups accept nothing and share no buffer.
        let tree = facing_planes(0.5);
        let (shared, alone, c_view, c_alone) = both(&tree, 2.0);
        assert!(mean(&alone) > 0.1);
        assert_eq!(shared, alone);
        assert_eq!((c_view.rasterised, c_view.near), (c_alone.rasterised, c_alone.near));
        let (shared_reuse, _, c_reuse, _) = both(&tree, 1.0);
        assert_eq!((c_reuse.group_buffers, &shared_reuse), (0, &shared));
    }

    #[test]
    fn far_planes_share_their_senders_and_buffers_between_points() {
        // Ten units apart: groups of points accept the far plane's nodes together, and with
        // reuse each plane's leaves start from shared buffers.
        let tree = facing_planes(10.0);
        let (shared, alone, c_view, c_alone) = both(&tree, 1.0);
        let (a, b) = (mean(&alone), mean(&shared));
        assert!(a > 0.0 && ((b - a) / a).abs() < 0.01, "per receiver {a}, view tree {b}");
        assert_eq!(c_view.reused, 800, "{c_view:?}");
        // Measured: 58 nodes rasterised against 800, 67,239 pairs against 68,722 visits.
        assert!(c_view.pairs <= c_alone.pairs, "view tree {c_view:?}, per receiver {c_alone:?}");
        assert!(10 * c_view.rasterised < c_alone.rasterised, "view tree {c_view:?}, per receiver {c_alone:?}");
        // Without reuse every leaf rasterises its ancestors' cuts itself: the same pairs.
        let (_, _, c_own, _) = both(&tree, 2.0);
        assert_eq!((c_own.pairs, c_own.reused, c_own.group_buffers), (c_view.pairs, 0, 0));
        assert!(c_own.rasterised > c_view.rasterised);
    }

    #[test]
    fn a_walk_serving_some_points_gives_them_their_bytes_and_skips_the_rest() {
        // Half the points (those of index below half the count): each gets
        // what the full walk gives it, the other plane's get nothing and cost fewer pairs.
        let tree = facing_planes(0.5);
        let w = ViewWalk { reuse_cos: 2.0, ..walk(&tree) };
        let cancel = CancelToken::new();
        let cx = RunCtx::new("t", &cancel, None);
        let half = tree.nodes.iter().filter(|n| n.is_leaf()).count() as u32 / 2;
        let serves = |p: u32| p < half;
        let (all, c_all) = w.run(&cx, &lambert).unwrap();
        for (some, c_some) in [w.run_serving(&cx, &serves, &lambert).unwrap(), w.run_per_receiver_serving(&cx, &serves, &lambert).unwrap()]
        {
            let want: Vec<(u32, Vec3)> = all.iter().copied().filter(|(p, _)| serves(*p)).collect();
            let mut got = some;
            got.sort_by_key(|x| x.0);
            let mut want = want;
            want.sort_by_key(|x| x.0);
            assert_eq!(got.len(), half as usize);
            assert_eq!(got, want);
            assert!(c_some.rasterised + c_some.near < c_all.rasterised + c_all.near, "{c_some:?} against {c_all:?}");
        }
        let (none, c_none) = w.run_serving(&cx, &|_| false, &lambert).unwrap();
        assert_eq!((none.len(), c_none.pairs), (0, 0));
    }

    #[test]
    fn the_walk_gives_the_same_bytes_on_one_and_four_threads() {
        let tree = facing_planes(0.3);
        let w = ViewWalk { reuse_cos: 2.0, ..walk(&tree) };
        let cancel = CancelToken::new();
        let cx = RunCtx::new("t", &cancel, None);
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let (out, c) = w.run(&cx, &lambert).unwrap();
                (out.iter().map(|(p, l)| (*p, l.to_array().map(f32::to_bits))).collect::<Vec<_>>(), c)
            })
        };
        let one = run(1);
        assert_eq!(one.1.reused, 0, "reuse off");
        assert_eq!(one, run(4));
    }

    #[test]
    fn a_cancelled_walk_stops() {
        let tree = facing_planes(0.5);
        let cancel = CancelToken::new();
        cancel.cancel();
        let cx = RunCtx::new("t", &cancel, None);
        assert!(matches!(walk(&tree).run(&cx, &lambert), Err(NodeError::Cancelled)));
    }
}
