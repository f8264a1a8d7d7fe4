//! A four-wide BVH with float boxes stored lane by lane, so that one SIMD compare tests a ray
//! against all four children, and its triangles in packets of four laid out the same way, so
//! that one pass of Möller–Trumbore tests a ray against four.
//!
//! It is built by collapsing a binary BVH: each node takes its two children, then opens the
//! inner child of largest surface area until it has four or only leaves are left. Closest-hit
//! rays visit children nearest first and drop any stacked child whose box starts beyond the
//! nearest hit found since; shadow rays stop at the first blocker.
//!
//! Children are stored after their parent (a decoded tree is checked for it), so a walk never
//! loops; the stack a walk needs is three entries per level, counted when the tree is built or
//! checked.

use glam::{Vec3A, Vec4};
use obvhs::bvh2::Bvh2;

/// A child reference with this bit set is a leaf: `LEAF | (count − 1) << COUNT_SHIFT | first`.
const LEAF: u32 = 1 << 31;
const COUNT_SHIFT: u32 = 27;
/// The most triangles one leaf holds (four packets).
pub const MAX_LEAF: u32 = 16;
/// The most packets a tree can index (and so the most triangles it surely holds).
pub const MAX_TRIS: usize = 1 << COUNT_SHIFT;
/// Stack entries kept on the thread's stack; deeper trees walk with a heap stack.
const INLINE_STACK: usize = 48;
/// Box exits are widened by this factor, so that rounding in the slab test never drops a box a
/// ray touches (two ulps of the three-operation distance).
const FAR_WIDEN: f32 = 1.0 + 2.0 * f32::EPSILON;

/// A triangle prepared for Möller–Trumbore: corner and two edges.
#[derive(Clone, Copy, Debug)]
pub struct Tri {
    pub v0: Vec3A,
    pub e1: Vec3A,
    pub e2: Vec3A,
}

impl Tri {
    /// (t, b1, b2) of the hit within (tmin, tmax), if any (the scalar test the packets
    /// repeat lane by lane; tests compare against it).
    #[cfg(test)]
    pub fn intersect(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let p = d.cross(self.e2);
        let det = self.e1.dot(p);
        if det.abs() < 1e-30 {
            return None;
        }
        let inv = 1.0 / det;
        let s = o - self.v0;
        let u = s.dot(p) * inv;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let q = s.cross(self.e1);
        let v = d.dot(q) * inv;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = self.e2.dot(q) * inv;
        (t > tmin && t < tmax).then_some((t, u, v))
    }
}

/// Four triangles side by side: corner, first edge and second edge, each coordinate over the
/// four lanes. An empty lane is all zeros: its determinant is zero and no ray hits it.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(16))]
pub struct Tri4 {
    pub c: [[f32; 4]; 9],
}

impl Tri4 {
    fn set(&mut self, lane: usize, t: &Tri) {
        for (k, v) in [t.v0, t.e1, t.e2].iter().flat_map(|v| v.to_array()).enumerate() {
            self.c[k][lane] = v;
        }
    }

    /// The mask of lanes hit within (tmin, tmax).
    #[inline(always)]
    fn hits(&self, o: [Vec4; 3], d: [Vec4; 3], tmin: f32, tmax: f32) -> u32 {
        self.solve(o, d, tmin, tmax).0
    }

    /// The mask of lanes hit within (tmin, tmax), with t, b1 and b2 of every lane.
    #[inline(always)]
    fn solve(&self, o: [Vec4; 3], d: [Vec4; 3], tmin: f32, tmax: f32) -> (u32, Vec4, Vec4, Vec4) {
        let c = self.c.map(Vec4::from);
        let cross = |a: [Vec4; 3], b: [Vec4; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
        let dot = |a: [Vec4; 3], b: [Vec4; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let (v0, e1, e2) = ([c[0], c[1], c[2]], [c[3], c[4], c[5]], [c[6], c[7], c[8]]);
        let p = cross(d, e2);
        let det = dot(e1, p);
        let inv = Vec4::ONE / det;
        let s = [o[0] - v0[0], o[1] - v0[1], o[2] - v0[2]];
        let u = dot(s, p) * inv;
        let q = cross(s, e1);
        let v = dot(d, q) * inv;
        let t = dot(e2, q) * inv;
        let ok = det.abs().cmpge(Vec4::splat(1e-30))
            & u.cmpge(Vec4::ZERO)
            & u.cmple(Vec4::ONE)
            & v.cmpge(Vec4::ZERO)
            & (u + v).cmple(Vec4::ONE)
            & t.cmpgt(Vec4::splat(tmin))
            & t.cmplt(Vec4::splat(tmax));
        (ok.bitmask(), t, u, v)
    }

    /// (lane, t, b1, b2) of the closest hit within (tmin, tmax), the lower lane on a tie.
    #[inline(always)]
    fn closest(&self, o: [Vec4; 3], d: [Vec4; 3], tmin: f32, tmax: f32) -> Option<(usize, f32, f32, f32)> {
        let (mut mask, t, u, v) = self.solve(o, d, tmin, tmax);
        let (t, u, v) = (t.to_array(), u.to_array(), v.to_array());
        let mut best: Option<(usize, f32, f32, f32)> = None;
        while mask != 0 {
            let lane = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if best.is_none_or(|b| t[lane] < b.1) {
                best = Some((lane, t[lane], u[lane], v[lane]));
            }
        }
        best
    }
}

/// Four children: their boxes as lo x, hi x, lo y, hi y, lo z, hi z, each over the four lanes
/// (an empty lane's box is inverted, lo = +∞ and hi = −∞, and no ray enters it), and their
/// references (an inner node's index, or a leaf).
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(16))]
pub struct Node {
    pub bounds: [[f32; 4]; 6],
    pub child: [u32; 4],
}

const EMPTY: Node = Node {
    bounds: [
        [f32::INFINITY; 4],
        [f32::NEG_INFINITY; 4],
        [f32::INFINITY; 4],
        [f32::NEG_INFINITY; 4],
        [f32::INFINITY; 4],
        [f32::NEG_INFINITY; 4],
    ],
    child: [LEAF; 4],
};

fn leaf(first: u32, count: u32) -> u32 {
    LEAF | (count - 1) << COUNT_SHIFT | first
}

/// (first, count) of a leaf reference.
#[inline(always)]
fn leaf_range(r: u32) -> (usize, usize) {
    ((r & ((1 << COUNT_SHIFT) - 1)) as usize, ((r & !LEAF) >> COUNT_SHIFT) as usize + 1)
}

/// The tree: nodes (the root first), triangle packets (leaves name runs of them) and the
/// stack depth a walk needs.
#[derive(Clone, Debug, Default)]
pub struct Bvh4 {
    pub nodes: Vec<Node>,
    pub packets: Vec<Tri4>,
    stack: usize,
}

/// The binary children a four-wide node over binary node `n` takes (`[n]` for a leaf root).
fn open(b2: &Bvh2, n: usize) -> Vec<usize> {
    let node = &b2.nodes[n];
    if node.prim_count > 0 {
        return vec![n];
    }
    let mut kids = vec![node.first_index as usize, node.first_index as usize + 1];
    while kids.len() < 4 {
        let widest = kids
            .iter()
            .enumerate()
            .filter(|(_, &k)| b2.nodes[k].prim_count == 0)
            .max_by(|a, b| b2.nodes[*a.1].aabb.half_area().total_cmp(&b2.nodes[*b.1].aabb.half_area()).then(b.0.cmp(&a.0)));
        let Some((i, &k)) = widest else { break };
        let first = b2.nodes[k].first_index as usize;
        kids.splice(i..=i, [first, first + 1]);
    }
    kids
}

impl Bvh4 {
    /// The four-wide tree over a binary one whose primitive `i` is `tri(i)`, and which
    /// primitive each packet lane holds (`u32::MAX` for an empty lane). Refuses more
    /// triangles than leaf references can name, or leaves over `MAX_LEAF`.
    pub fn collapse(b2: &Bvh2, tri: impl Fn(usize) -> Tri) -> Result<(Bvh4, Vec<u32>), String> {
        if b2.primitive_indices.len() > MAX_TRIS {
            return Err(format!("{} leaf triangles, over the {MAX_TRIS} a tree indexes", b2.primitive_indices.len()));
        }
        if b2.nodes.is_empty() || b2.primitive_indices.is_empty() {
            return Ok(Default::default());
        }
        let (mut nodes, mut packets, mut lanes) = (vec![EMPTY], vec![], vec![]);
        let mut work = vec![(0usize, 0usize)];
        while let Some((n, slot)) = work.pop() {
            let mut node = EMPTY;
            for (lane, k) in open(b2, n).into_iter().enumerate() {
                let b = &b2.nodes[k];
                let (lo, hi) = (b.aabb.min.to_array(), b.aabb.max.to_array());
                for axis in 0..3 {
                    node.bounds[2 * axis][lane] = lo[axis];
                    node.bounds[2 * axis + 1][lane] = hi[axis];
                }
                node.child[lane] = if b.prim_count > 0 {
                    if b.prim_count > MAX_LEAF {
                        return Err(format!("a leaf of {} triangles, over {MAX_LEAF}", b.prim_count));
                    }
                    let first = packets.len() as u32;
                    let prims = &b2.primitive_indices[b.first_index as usize..(b.first_index + b.prim_count) as usize];
                    for group in prims.chunks(4) {
                        let mut packet = Tri4 { c: [[0.0; 4]; 9] };
                        for (lane, &p) in group.iter().enumerate() {
                            packet.set(lane, &tri(p as usize));
                        }
                        packets.push(packet);
                        lanes.extend(group.iter().copied().chain([u32::MAX; 4]).take(4));
                    }
                    leaf(first, packets.len() as u32 - first)
                } else {
                    nodes.push(EMPTY);
                    work.push((k, nodes.len() - 1));
                    (nodes.len() - 1) as u32
                };
            }
            nodes[slot] = node;
        }
        let stack = Bvh4::checked_stack(&nodes, packets.len()).expect("a collapsed tree is well formed");
        Ok((Bvh4 { nodes, packets, stack }, lanes))
    }

    /// A decoded tree, when every inner child follows its parent and every leaf lies within
    /// the packets.
    pub fn from_parts(nodes: Vec<Node>, packets: Vec<Tri4>) -> Option<Bvh4> {
        let stack = Bvh4::checked_stack(&nodes, packets.len())?;
        Some(Bvh4 { nodes, packets, stack })
    }

    /// The stack a walk needs, when the nodes are well formed.
    fn checked_stack(nodes: &[Node], tris: usize) -> Option<usize> {
        let mut depth = vec![1usize; nodes.len()];
        for n in (0..nodes.len()).rev() {
            for &c in &nodes[n].child {
                if c & LEAF != 0 {
                    let (first, count) = leaf_range(c);
                    if first + count > tris {
                        return None;
                    }
                } else {
                    let c = c as usize;
                    if c <= n || c >= nodes.len() {
                        return None;
                    }
                    depth[n] = depth[n].max(depth[c] + 1);
                }
            }
        }
        Some(3 * depth.first().copied().unwrap_or(0) + 1)
    }

    fn with_stack<R>(&self, walk: impl FnOnce(&mut [(u32, f32)]) -> R) -> R {
        if self.stack <= INLINE_STACK {
            walk(&mut [(0, 0.0); INLINE_STACK])
        } else {
            walk(&mut vec![(0, 0.0); self.stack])
        }
    }

    /// The closest hit along `o + t d` for t in (tmin, tmax): (t, packet lane, b1, b2), the
    /// lane counted over all packets (`lanes` names its primitive).
    pub fn intersect(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> Option<(f32, usize, f32, f32)> {
        let (o4, d4) = (splat(o), splat(d));
        let mut best = None;
        self.walk::<true>(o, d, tmin, tmax, |first, count, tmax| {
            for (i, packet) in self.packets[first..first + count].iter().enumerate() {
                if let Some((lane, t, u, v)) = packet.closest(o4, d4, tmin, *tmax) {
                    *tmax = t;
                    best = Some((t, 4 * (first + i) + lane, u, v));
                }
            }
            false
        });
        best
    }

    /// Whether anything blocks `o + t d` for t in (tmin, tmax); stops at the first blocker.
    pub fn occluded(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> bool {
        let (o4, d4) = (splat(o), splat(d));
        let mut blocked = false;
        self.walk::<false>(o, d, tmin, tmax, |first, count, _| {
            blocked = self.packets[first..first + count].iter().any(|p| p.hits(o4, d4, tmin, tmax) != 0);
            blocked
        });
        blocked
    }

    /// Visits the leaves a ray meets, nearest box first, skipping stacked children whose box
    /// starts beyond `tmax`; `leaf(first, count, &mut tmax)` may shorten the ray, and ends the
    /// walk by returning true. A ray that is not finite meets nothing.
    #[inline(always)]
    fn walk<const ORDERED: bool>(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32, mut leaf: impl FnMut(usize, usize, &mut f32) -> bool) {
        if self.nodes.is_empty() || !(o.is_finite() && d.is_finite()) {
            return;
        }
        let ray = Slabs::new(o, d);
        self.with_stack(|stack| {
            let (mut sp, mut cur, mut tmax) = (0, 0u32, tmax);
            loop {
                if cur & LEAF != 0 {
                    let (first, count) = leaf_range(cur);
                    if leaf(first, count, &mut tmax) {
                        return;
                    }
                } else {
                    let node = &self.nodes[cur as usize];
                    let (near, mut mask) = ray.enter(node, tmin, tmax);
                    if mask != 0 {
                        let mut kids = [(0.0f32, 0u32); 4];
                        let mut k = 0;
                        while mask != 0 {
                            let lane = mask.trailing_zeros() as usize;
                            mask &= mask - 1;
                            kids[k] = (near[lane], node.child[lane]);
                            k += 1;
                        }
                        // Farthest first: insertion sort of at most four.
                        for i in (1..k).filter(|_| ORDERED) {
                            let mut j = i;
                            while j > 0 && kids[j - 1].0 < kids[j].0 {
                                kids.swap(j - 1, j);
                                j -= 1;
                            }
                        }
                        for &(t, c) in &kids[..k - 1] {
                            stack[sp] = (c, t);
                            sp += 1;
                        }
                        cur = kids[k - 1].1;
                        continue;
                    }
                }
                loop {
                    if sp == 0 {
                        return;
                    }
                    sp -= 1;
                    let (c, t) = stack[sp];
                    if t < tmax {
                        cur = c;
                        break;
                    }
                }
            }
        })
    }
}

fn splat(v: Vec3A) -> [Vec4; 3] {
    v.to_array().map(Vec4::splat)
}

/// A ray prepared for slab tests against four boxes: origin and inverse direction splatted,
/// and which stored bound each axis enters by.
struct Slabs {
    o: [Vec4; 3],
    inv: [Vec4; 3],
    near: [usize; 3],
}

impl Slabs {
    fn new(o: Vec3A, d: Vec3A) -> Slabs {
        let inv = d.recip().to_array();
        let o = o.to_array();
        // The sign of the inverse picks the entry plane: 1/−0 is −∞, so a −0 component enters
        // by the high bound, as its inverse says.
        let near = [0, 1, 2].map(|a| 2 * a + (inv[a] < 0.0) as usize);
        Slabs { o: o.map(Vec4::splat), inv: inv.map(Vec4::splat), near }
    }

    /// Entry distances of the four children and the mask of those the ray meets within
    /// (tmin, tmax). A NaN distance (an origin on a slab plane of a flat axis) is ignored, so
    /// that axis does not cull.
    #[inline(always)]
    fn enter(&self, node: &Node, tmin: f32, tmax: f32) -> ([f32; 4], u32) {
        let mut near = Vec4::splat(tmin);
        let mut far = Vec4::splat(tmax);
        for a in 0..3 {
            let t0 = (Vec4::from(node.bounds[self.near[a]]) - self.o[a]) * self.inv[a];
            let t1 = (Vec4::from(node.bounds[self.near[a] ^ 1]) - self.o[a]) * self.inv[a];
            near = t0.max(near);
            far = t1.min(far);
        }
        let hit = near.cmple(far * FAR_WIDEN).bitmask();
        (near.to_array(), hit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;

    fn random_tri(seed: u64, i: u64) -> Tri {
        let p = |k: u32| Vec3A::new(uniform(seed, i, k), uniform(seed, i, k + 1), uniform(seed, i, k + 2)) * 2.0 - Vec3A::ONE;
        let (a, b, c) = (p(0), p(3), p(6));
        Tri { v0: a, e1: b - a, e2: c - a }
    }

    #[test]
    fn a_packet_hits_what_the_scalar_test_hits_lane_by_lane() {
        let (mut hits, mut ties) = (0, 0);
        for i in 0..2000u64 {
            let tris: Vec<Tri> = (0..4).map(|k| random_tri(i, k)).collect();
            // Every eighth packet repeats a triangle, so that two lanes tie.
            let tris: Vec<Tri> = if i % 8 == 0 { vec![tris[0], tris[1], tris[0], tris[3]] } else { tris };
            let mut packet = Tri4 { c: [[0.0; 4]; 9] };
            tris.iter().enumerate().for_each(|(lane, t)| packet.set(lane, t));
            let o = Vec3A::new(uniform(7, i, 0), uniform(7, i, 1), 3.0);
            let d = (Vec3A::new(uniform(7, i, 2) - 0.5, uniform(7, i, 3) - 0.5, 0.0) - o).normalize();
            let scalar = tris
                .iter()
                .enumerate()
                .filter_map(|(lane, t)| t.intersect(o, d, 0.0, f32::INFINITY).map(|(t, u, v)| (lane, t, u, v)))
                .fold(None, |b: Option<(usize, f32, f32, f32)>, h| if b.is_none_or(|b| h.1 < b.1) { Some(h) } else { b });
            assert_eq!(packet.closest(splat(o), splat(d), 0.0, f32::INFINITY), scalar, "packet {i}");
            assert_eq!(packet.hits(splat(o), splat(d), 0.0, f32::INFINITY) != 0, scalar.is_some());
            hits += scalar.is_some() as usize;
            ties += (i % 8 == 0 && scalar.is_some_and(|s| s.0 == 0)) as usize;
        }
        assert!(hits > 400 && ties > 20, "{hits} hits, {ties} ties to the lower lane");
    }

    /// A chain of `depth` nodes, each holding the next and a leaf of one packet: a triangle at
    /// z = −level under the ray down the z axis.
    fn chain(depth: usize) -> Bvh4 {
        let mut nodes = vec![];
        let mut packets = vec![];
        for level in 0..depth {
            let z = -(level as f32) - 1.0;
            let mut packet = Tri4 { c: [[0.0; 4]; 9] };
            packet.set(0, &Tri { v0: Vec3A::new(-1.0, -1.0, z), e1: Vec3A::new(3.0, 0.0, 0.0), e2: Vec3A::new(0.0, 3.0, 0.0) });
            packets.push(packet);
            let mut node = EMPTY;
            for lane in 0..2 {
                let (lo, hi) = ([-1.0, -1.0, -(depth as f32) - 1.0], [2.0, 2.0, z]);
                for axis in 0..3 {
                    node.bounds[2 * axis][lane] = lo[axis];
                    node.bounds[2 * axis + 1][lane] = hi[axis];
                }
            }
            node.child[0] = if level + 1 < depth { (level + 1) as u32 } else { leaf(level as u32, 1) };
            node.child[1] = leaf(level as u32, 1);
            nodes.push(node);
        }
        Bvh4::from_parts(nodes, packets).unwrap()
    }

    #[test]
    fn a_tree_deeper_than_the_inline_stack_walks_with_a_heap_stack() {
        let deep = chain(40);
        assert!(deep.stack > INLINE_STACK);
        let (o, d) = (Vec3A::new(0.2, 0.3, 0.0), Vec3A::NEG_Z);
        let hit = deep.intersect(o, d, 0.0, f32::INFINITY).unwrap();
        assert_eq!((hit.0, hit.1), (1.0, 0), "the nearest of forty stacked triangles");
        assert_eq!(deep.intersect(o, d, 1.5, f32::INFINITY).map(|h| (h.0, h.1)), Some((2.0, 4)));
        assert!(deep.occluded(o, d, 39.5, 41.0) && !deep.occluded(o, d, 40.5, 100.0));
        assert!(chain(3).stack <= INLINE_STACK);
        assert_eq!(chain(3).intersect(o, d, 0.0, f32::INFINITY).map(|h| h.1), Some(0));
    }

    #[test]
    fn a_ray_that_is_not_finite_meets_nothing() {
        let tree = chain(3);
        for (o, d) in [
            (Vec3A::new(0.2, 0.3, f32::NAN), Vec3A::NEG_Z),
            (Vec3A::new(0.2, 0.3, 0.0), Vec3A::new(0.0, f32::NAN, -1.0)),
            (Vec3A::new(f32::INFINITY, 0.3, 0.0), Vec3A::NEG_Z),
        ] {
            assert_eq!(tree.intersect(o, d, 0.0, f32::INFINITY), None);
            assert!(!tree.occluded(o, d, 0.0, f32::INFINITY));
        }
    }
}
