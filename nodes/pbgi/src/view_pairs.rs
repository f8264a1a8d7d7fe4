//! The view tree's pair test ([P] 5.3.2–5.3.3): the point tree traversed against itself as
//! pairs of a receiver node R (a group of points that gather) and a sender node S (a group
//! that sends). A pair is decided for every receiver below R at once:
//!
//! - **culled** when no receiver below R can see S: for a leaf R, S lies under its tangent
//!   plane (the slab test the per-receiver traversal uses); for an inner R, the view cone
//!   test: every direction from R's sphere to S's lies within β = asin((b_R + b_S)/d) of the
//!   centres' direction, every normal below R within θ_R of R's cone axis, so S is under
//!   every receiver's horizon when the axis makes more than 90° + θ_R + β with that
//!   direction; for a flat R (one normal), the leaf's slab test from R's lowest point;
//! - **too close** when S, seen from the nearest point R may hold (at d − b_R), is larger
//!   than `sender_omega` (the microbuffer threshold, as in the per-receiver traversal) or
//!   may hold a receiver: if it is too large from R's farthest point as well (d + b_R), every
//!   receiver below R would open it and S is split; otherwise only the nearer receivers
//!   would, and R is split. So a sender is split no sooner than a per-receiver traversal
//!   would split it. A receiver group wholly inside the sender splits the sender: docs/PIPELINES.md
//!   notes that [P]'s text and figure 5.2's caption disagree on this case; this follows the
//!   caption. A group only partly inside splits itself (its points outside may accept S);
//! - **receiver too large** when R's sphere, seen from S's (π b_R² / (d − b_S)²), exceeds
//!   `view_omega` ([P]: 0.005 sr): the directions from R's points to S then differ by more
//!   than a microbuffer pixel can tell, and R is split;
//! - **near**: a leaf too large for a leaf receiver, ray-cast as a disk (as the per-receiver
//!   traversal's near leaves);
//! - **accepted** otherwise: S goes into R's cut, rasterised once for every receiver below R
//!   (or once for a group whose normals agree: `view_walk`). An accepted S whose normals all
//!   face away from R sends nothing and is culled instead.

use super::traversal::height_above_plane;
use crate::types::{PointTree, TreeNode};
use glam::Vec3;
use std::f32::consts::PI;

/// The thresholds of the pair test.
#[derive(Clone, Copy, Debug)]
pub struct PairTest {
    /// Largest solid angle (sr) of a sender rasterised as one node.
    pub sender_omega: f32,
    /// Largest solid angle (sr) of a receiver group seen from its sender.
    pub view_omega: f32,
    /// Height above a leaf receiver's plane under which a sender is culled.
    pub eps: f32,
}

/// What a pair comes to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pair {
    Cull,
    Accept,
    Near,
    SplitSender,
    SplitReceiver,
}

/// Decides the pair (receiver `r`, sender `s`).
pub fn classify(tree: &PointTree, r: u32, s: u32, t: &PairTest) -> Pair {
    let (rn, sn) = (&tree.nodes[r as usize], &tree.nodes[s as usize]);
    let v = sn.center - rn.center;
    let d = v.length();
    if rn.is_leaf() {
        if r == s || height_above_plane(sn.cone_axis, sn.slab, sn.bound, v, rn.cone_axis) <= t.eps {
            return Pair::Cull;
        }
    } else if hidden_from(rn, sn, v, d) || under_flat_group(rn, sn, v, t.eps) {
        return Pair::Cull;
    }
    // A leaf receiver gathers at its point (its centre), a group anywhere within its bound.
    let br = if rn.is_leaf() { 0.0 } else { rn.bound };
    let too_large = |dist: f32| dist <= sn.bound || sn.area > t.sender_omega * dist * dist;
    if too_large(d - br) {
        // Split the sender when every receiver below R would open it (R wholly inside it
        // among them); when only the nearer ones would, split the receivers.
        let split_sender = !sn.is_leaf() && too_large(d + br);
        return match (split_sender, rn.is_leaf()) {
            (true, _) => Pair::SplitSender,
            (false, false) => Pair::SplitReceiver,
            (false, true) => Pair::Near,
        };
    }
    let back = d - sn.bound;
    if !rn.is_leaf() && PI * br * br > t.view_omega * back * back {
        return Pair::SplitReceiver;
    }
    if faces_away(sn, rn, v, d) {
        return Pair::Cull;
    }
    Pair::Accept
}

/// Whether every sender point lies under every receiver's horizon (view-cone culling).
fn hidden_from(rn: &TreeNode, sn: &TreeNode, v: Vec3, d: f32) -> bool {
    beyond_cone(rn.cone_axis, rn.cone_cos, v, d, rn.bound + sn.bound)
}

/// Whether direction `v` (length `d`) makes more than 90° + θ + β with `axis`: θ = acos
/// `cone_cos`, β = asin(`reach` / d) the spread of directions between two spheres whose
/// radii sum to `reach` (never when they touch). With α the angle to the axis, α ≥ 90° +
/// θ + β is cos α ≤ −sin(θ + β) with θ + β ≤ 90°; no inverse trigonometry.
fn beyond_cone(axis: Vec3, cone_cos: f32, v: Vec3, d: f32, reach: f32) -> bool {
    if d <= reach || cone_cos <= 0.0 {
        return false;
    }
    let (sin_b, ct) = (reach / d, cone_cos.min(1.0));
    let (cos_b, st) = ((1.0 - sin_b * sin_b).max(0.0).sqrt(), (1.0 - ct * ct).max(0.0).sqrt());
    let cos_sum = ct * cos_b - st * sin_b;
    if cos_sum < 0.0 {
        return false;
    }
    let sin_sum = st * cos_b + ct * sin_b;
    axis.dot(v) <= -sin_sum * d
}

/// For a flat receiver group (every normal its cone axis, to rounding), whether the sender lies under
/// the plane of every receiver: the slab test of a leaf, from the group's lowest point.
fn under_flat_group(rn: &TreeNode, sn: &TreeNode, v: Vec3, eps: f32) -> bool {
    rn.cone_cos >= 1.0 - 1e-6 && height_above_plane(sn.cone_axis, sn.slab, sn.bound, v, rn.cone_axis) - rn.slab[0] <= eps
}

/// Whether every sender normal faces away from every receiver point.
fn faces_away(sn: &TreeNode, rn: &TreeNode, v: Vec3, d: f32) -> bool {
    beyond_cone(sn.cone_axis, sn.cone_cos, -v, d, rn.bound + sn.bound)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use relume_base::types::{Material, SurfacePoints};

    /// Two facing 20 × 20 grids of disks: z = 0 facing up, z = `gap` facing down.
    pub(crate) fn facing_planes(gap: f32) -> PointTree {
        let grid = |z: f32| (0..400).map(move |k| Vec3::new((k % 20) as f32 * 0.1 - 1.0, (k / 20) as f32 * 0.1 - 1.0, z));
        let position: Vec<Vec3> = grid(0.0).chain(grid(gap)).collect();
        let normal = (0..800).map(|k| if k < 400 { Vec3::Z } else { -Vec3::Z }).collect();
        let pts = SurfacePoints {
            position,
            normal,
            radius: vec![0.05; 800],
            object: vec![0; 800],
            material: vec![Material::Lambert { albedo: Vec3::ONE }; 800],
        };
        PointTree::build(&pts, &vec![Vec3::ONE; 800])
    }

    /// The pair test of an 8 × 8 microbuffer, ε from the tree's extent (as the gathers).
    fn test(tree: &PointTree) -> PairTest {
        PairTest { sender_omega: 8.0 / 64.0, view_omega: 0.005, eps: 1e-5 * crate::traversal::tree_extent(tree) }
    }

    /// Every pair reached from (root, root), with what it came to.
    fn all_pairs(tree: &PointTree) -> Vec<(u32, u32, Pair)> {
        let (mut stack, mut out) = (vec![(tree.root, tree.root)], vec![]);
        while let Some((r, s)) = stack.pop() {
            let p = classify(tree, r, s, &test(tree));
            out.push((r, s, p));
            let kids = |i: u32| tree.nodes[i as usize].children.unwrap();
            match p {
                Pair::SplitSender => stack.extend(kids(s).map(|c| (r, c))),
                Pair::SplitReceiver => stack.extend(kids(r).map(|c| (c, s))),
                _ => {}
            }
        }
        out
    }

    #[test]
    fn every_receiver_sees_every_sender_leaf_at_most_once_and_the_facing_plane_whole() {
        for gap in [0.5, 10.0] {
            covers_the_facing_plane_once(&facing_planes(gap));
        }
    }

    fn covers_the_facing_plane_once(tree: &PointTree) {
        let pairs = all_pairs(tree);
        // The leaves under a node, and the ancestors of every node.
        let n = tree.nodes.len();
        let mut parent = vec![u32::MAX; n];
        for (i, t) in tree.nodes.iter().enumerate() {
            if let Some(c) = t.children {
                c.iter().for_each(|&c| parent[c as usize] = i as u32);
            }
        }
        let leaves_under = |i: u32| -> Vec<u32> {
            let mut st = vec![i];
            let mut out = vec![];
            while let Some(k) = st.pop() {
                match tree.nodes[k as usize].children {
                    Some(c) => st.extend(c),
                    None => out.push(tree.nodes[k as usize].point),
                }
            }
            out
        };
        // For each receiver leaf: how often each sender point is reached through accepted or
        // near pairs of the leaf or an ancestor.
        for leaf in (0..n as u32).filter(|&i| tree.nodes[i as usize].is_leaf()).step_by(37) {
            let mut path = vec![leaf];
            while parent[*path.last().unwrap() as usize] != u32::MAX {
                path.push(parent[*path.last().unwrap() as usize]);
            }
            let mut seen = vec![0u32; 800];
            for &(r, s, p) in &pairs {
                if path.contains(&r) && matches!(p, Pair::Accept | Pair::Near) {
                    leaves_under(s).into_iter().for_each(|q| seen[q as usize] += 1);
                }
            }
            assert!(seen.iter().all(|&c| c <= 1), "a sender reached twice by receiver leaf {leaf}");
            let point = tree.nodes[leaf as usize].point as usize;
            let (own, other) = if point < 400 { (0..400, 400..800) } else { (400..800, 0..400) };
            // A node of the receiver's own plane alone is never sent (a node of both planes,
            // seen edge-on in part, may be).
            for &(r, s, p) in &pairs {
                if path.contains(&r) && matches!(p, Pair::Accept | Pair::Near) {
                    let under = leaves_under(s);
                    assert!(!under.iter().all(|q| own.contains(&(*q as usize))), "receiver leaf {leaf} is sent its own plane's node {s}");
                }
            }
            assert!(seen[other].iter().all(|&c| c == 1), "receiver leaf {leaf} misses part of the facing plane");
        }
    }

    #[test]
    fn the_cone_test_without_inverse_trigonometry_agrees_with_the_angles() {
        use relume_base::math::rng::uniform;
        for k in 0..20_000u64 {
            let u = |c| uniform(11, k, c);
            let axis = Vec3::new(u(0) - 0.5, u(1) - 0.5, u(2) - 0.5).normalize();
            let v = Vec3::new(u(3) - 0.5, u(4) - 0.5, u(5) - 0.5) * 4.0;
            let (cone_cos, reach, d) = (u(6) * 2.0 - 1.0, u(7), v.length());
            let want = d > reach && {
                let off = axis.dot(v / d).clamp(-1.0, 1.0).acos() - cone_cos.acos() - (reach / d).asin();
                off >= std::f32::consts::FRAC_PI_2
            };
            let got = beyond_cone(axis, cone_cos, v, d, reach);
            if got != want {
                // Only within rounding of the boundary.
                let off = axis.dot(v / d).acos() - cone_cos.acos() - (reach / d).asin() - std::f32::consts::FRAC_PI_2;
                assert!(off.abs() < 1e-4, "case {k}: {got} vs {want} ({off})");
            }
        }
    }

    #[test]
    fn groups_share_pairs_a_per_receiver_traversal_would_repeat() {
        let tree = facing_planes(10.0);
        let pairs = all_pairs(&tree);
        let inner_accepts = pairs.iter().filter(|(r, _, p)| *p == Pair::Accept && !tree.nodes[*r as usize].is_leaf()).count();
        assert!(inner_accepts > 0, "some senders are accepted for whole receiver groups");
    }

    #[test]
    fn a_group_behind_the_receivers_is_culled_whole_and_a_far_one_accepted_whole() {
        let children = |tree: &PointTree| {
            let [a, b] = tree.nodes[tree.root as usize].children.unwrap();
            if tree.nodes[a as usize].center.z < tree.nodes[b as usize].center.z {
                (a, b)
            } else {
                (b, a)
            }
        };
        // Ten units apart (the root splits the planes apart): the plane is larger than a
        // pixel, and with loose thresholds the whole upper plane is accepted by the whole
        // lower one.
        let far = facing_planes(10.0);
        let (lower, upper) = children(&far);
        assert!(far.nodes[lower as usize].cone_cos > 0.999 && far.nodes[upper as usize].cone_cos > 0.999, "one plane each");
        assert_eq!(classify(&far, lower, upper, &test(&far)), Pair::SplitReceiver, "the receiving plane is the larger");
        let loose = PairTest { sender_omega: 100.0, view_omega: 100.0, eps: 1e-5 };
        assert_eq!(classify(&far, lower, upper, &loose), Pair::Accept);
        // Every normal flipped: the lower plane faces away from the upper, whole (view cone)
        // and for each of its leaves (slab), and the upper plane faces away from the lower.
        let flip = |tree: &PointTree| {
            let mut tr = tree.clone();
            for n in &mut tr.nodes {
                n.cone_axis = -n.cone_axis;
                n.slab = [-n.slab[1], -n.slab[0]];
            }
            tr
        };
        assert_eq!(classify(&flip(&far), lower, upper, &loose), Pair::Cull);
        let flipped = flip(&far);
        let leaf = (lower..).find(|&i| flipped.nodes[i as usize].is_leaf()).unwrap();
        assert_eq!(classify(&flipped, leaf, upper, &test(&flipped)), Pair::Cull);
    }
}
