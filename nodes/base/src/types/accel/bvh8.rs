//! An eight-wide BVH with float boxes stored lane by lane, so that one SIMD compare tests a
//! ray against all eight children (one AVX register where the CPU has AVX2, two SSE or NEON
//! registers otherwise, with the same bits), and its triangles in packets of four laid out the
//! same way, so that one pass of Möller–Trumbore tests a ray against four (against eight, two
//! packets of a leaf in one AVX register, where the CPU has AVX2; the same hit either way).
//!
//! It is built by collapsing a binary BVH: each node takes its two children, then opens the
//! inner child of largest surface area until it has eight or only leaves are left. Closest-hit
//! rays visit children nearest first and drop any stacked child whose box starts beyond the
//! nearest hit found since; shadow rays stop at the first blocker.
//!
//! Children are stored after their parent (a decoded tree is checked for it), so a walk never
//! loops; the stack a walk needs is seven entries per level, counted when the tree is built or
//! checked.

#[cfg(target_arch = "x86_64")]
mod avx2;

use glam::{Vec3A, Vec4};
use obvhs::bvh2::Bvh2;
use std::mem::MaybeUninit;

/// A child reference with this bit set is a leaf: `LEAF | (count − 1) << COUNT_SHIFT | first`.
const LEAF: u32 = 1 << 31;
const COUNT_SHIFT: u32 = 27;
/// The most triangles one leaf holds (four packets).
pub const MAX_LEAF: u32 = 16;
/// The most packets a tree can index (and so the most triangles it surely holds).
pub const MAX_TRIS: usize = 1 << COUNT_SHIFT;
/// Stack entries kept on the thread's stack; deeper trees walk with a heap stack.
const INLINE_STACK: usize = 96;
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
        let (mask, t, u, v) = self.solve(o, d, tmin, tmax);
        lowest(mask, &t.to_array(), &u.to_array(), &v.to_array())
    }
}

/// (lane, t, b1, b2) of the lane of `mask` with the least t, the lower lane on a tie.
#[inline(always)]
fn lowest(mut mask: u32, t: &[f32], u: &[f32], v: &[f32]) -> Option<(usize, f32, f32, f32)> {
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

/// Children per node.
pub const WIDTH: usize = 8;

/// `WIDTH` children: their boxes as lo x, hi x, lo y, hi y, lo z, hi z, each over the lanes
/// (an empty lane's box is inverted, lo = +∞ and hi = −∞, and no ray enters it), and their
/// references (an inner node's index, or a leaf).
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(32))]
pub struct Node {
    pub bounds: [[f32; WIDTH]; 6],
    pub child: [u32; WIDTH],
}

const EMPTY: Node = Node {
    bounds: [
        [f32::INFINITY; WIDTH],
        [f32::NEG_INFINITY; WIDTH],
        [f32::INFINITY; WIDTH],
        [f32::NEG_INFINITY; WIDTH],
        [f32::INFINITY; WIDTH],
        [f32::NEG_INFINITY; WIDTH],
    ],
    child: [LEAF; WIDTH],
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
pub struct Bvh8 {
    pub nodes: Vec<Node>,
    pub packets: Vec<Tri4>,
    stack: usize,
}

/// The binary children a wide node over binary node `n` takes (`[n]` for a leaf root).
fn open(b2: &Bvh2, n: usize) -> Vec<usize> {
    let node = &b2.nodes[n];
    if node.prim_count > 0 {
        return vec![n];
    }
    let mut kids = vec![node.first_index as usize, node.first_index as usize + 1];
    while kids.len() < WIDTH {
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

impl Bvh8 {
    /// The wide tree over a binary one whose primitive `i` is `tri(i)`, and which
    /// primitive each packet lane holds (`u32::MAX` for an empty lane). Refuses more
    /// triangles than leaf references can name, or leaves over `MAX_LEAF`.
    pub fn collapse(b2: &Bvh2, tri: impl Fn(usize) -> Tri) -> Result<(Bvh8, Vec<u32>), String> {
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
        let stack = Bvh8::checked_stack(&nodes, packets.len()).expect("a collapsed tree is well formed");
        Ok((Bvh8 { nodes, packets, stack }, lanes))
    }

    /// A decoded tree, when every inner child follows its parent and every leaf lies within
    /// the packets.
    pub fn from_parts(nodes: Vec<Node>, packets: Vec<Tri4>) -> Option<Bvh8> {
        let stack = Bvh8::checked_stack(&nodes, packets.len())?;
        Some(Bvh8 { nodes, packets, stack })
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
        Some((WIDTH - 1) * depth.first().copied().unwrap_or(0) + 1)
    }

    /// The closest hit along `o + t d` for t in (tmin, tmax): (t, packet lane, b1, b2), the
    /// lane counted over all packets (`lanes` names its primitive).
    pub fn intersect(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> Option<(f32, usize, f32, f32)> {
        if !self.walks(o, d) {
            return None;
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return self.with_stack(|stack| unsafe { self.walk_avx2::<true>(o, d, tmin, tmax, stack) });
        }
        self.intersect_portable(o, d, tmin, tmax)
    }

    /// `intersect` four lanes at a time, on any CPU.
    fn intersect_portable(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> Option<(f32, usize, f32, f32)> {
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
        if !self.walks(o, d) {
            return false;
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return self.with_stack(|stack| unsafe { self.walk_avx2::<false>(o, d, tmin, tmax, stack) }).is_some();
        }
        self.occluded_portable(o, d, tmin, tmax)
    }

    /// `occluded` four lanes at a time, on any CPU.
    fn occluded_portable(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> bool {
        let (o4, d4) = (splat(o), splat(d));
        let mut blocked = false;
        self.walk::<false>(o, d, tmin, tmax, |first, count, _| {
            blocked = self.packets[first..first + count].iter().any(|p| p.hits(o4, d4, tmin, tmax) != 0);
            blocked
        });
        blocked
    }

    /// Whether a ray has anything to walk: a tree with nodes, and a finite ray (a ray that is
    /// not finite meets nothing).
    fn walks(&self, o: Vec3A, d: Vec3A) -> bool {
        !self.nodes.is_empty() && o.is_finite() && d.is_finite()
    }

    /// Runs `f` with a walk's stack: on the thread's stack, or on the heap for trees deeper
    /// than that holds. Entries are read only below the top, where they were written, so the
    /// stack is left uninitialised.
    #[inline(always)]
    fn with_stack<R>(&self, f: impl FnOnce(&mut [MaybeUninit<(u32, f32)>]) -> R) -> R {
        if self.stack <= INLINE_STACK {
            f(&mut [MaybeUninit::uninit(); INLINE_STACK])
        } else {
            f(&mut vec![MaybeUninit::uninit(); self.stack])
        }
    }

    /// Visits the leaves a ray meets, nearest box first, skipping stacked children whose box
    /// starts beyond `tmax`; `leaf(first, count, &mut tmax)` may shorten the ray, and ends the
    /// walk by returning true. The ray is finite and the tree has nodes (`walks`).
    #[inline(always)]
    fn walk<const ORDERED: bool>(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32, mut leaf: impl FnMut(usize, usize, &mut f32) -> bool) {
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
                    let (near, mask) = ray.enter_halves(node, tmin, tmax);
                    if mask != 0 {
                        cur = descend::<ORDERED>(node, &near, mask, stack, &mut sp);
                        continue;
                    }
                }
                match pop(stack, &mut sp, tmax) {
                    Some(c) => cur = c,
                    None => return,
                }
            }
        })
    }
}

/// The child of `node` a walk goes to next among those of `mask` (entered at `near`): the
/// nearest with `ORDERED`, else the last met; the others are stacked, farthest deepest.
#[inline(always)]
fn descend<const ORDERED: bool>(
    node: &Node,
    near: &[f32; WIDTH],
    mut mask: u32,
    stack: &mut [MaybeUninit<(u32, f32)>],
    sp: &mut usize,
) -> u32 {
    let mut kids = [(0.0f32, 0u32); WIDTH];
    let mut k = 0;
    while mask != 0 {
        let lane = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        kids[k] = (near[lane], node.child[lane]);
        k += 1;
    }
    if ORDERED {
        farthest_first(&mut kids[..k]);
    }
    for &(t, c) in &kids[..k - 1] {
        stack[*sp].write((c, t));
        *sp += 1;
    }
    kids[k - 1].1
}

/// The next stacked child whose box starts before `tmax` (the others are dropped), or `None`
/// when the stack is spent.
#[inline(always)]
fn pop(stack: &[MaybeUninit<(u32, f32)>], sp: &mut usize, tmax: f32) -> Option<u32> {
    while *sp > 0 {
        *sp -= 1;
        // SAFETY: entry `sp` was written when the stack last grew past it.
        let (c, t) = unsafe { stack[*sp].assume_init() };
        if t < tmax {
            return Some(c);
        }
    }
    None
}

/// Sorts a node's children met, farthest entry first (insertion sort of at most `WIDTH`), so
/// that the nearest is walked next and the rest are stacked behind it.
#[inline(always)]
fn farthest_first(kids: &mut [(f32, u32)]) {
    for i in 1..kids.len() {
        let mut j = i;
        while j > 0 && kids[j - 1].0 < kids[j].0 {
            kids.swap(j - 1, j);
            j -= 1;
        }
    }
}

fn splat(v: Vec3A) -> [Vec4; 3] {
    v.to_array().map(Vec4::splat)
}

/// A ray prepared for slab tests against a node's boxes: origin and inverse direction, and
/// which stored bound each axis enters by.
struct Slabs {
    o: [f32; 3],
    inv: [f32; 3],
    near: [usize; 3],
}

impl Slabs {
    fn new(o: Vec3A, d: Vec3A) -> Slabs {
        let inv = d.recip().to_array();
        // The sign of the inverse picks the entry plane: 1/−0 is −∞, so a −0 component enters
        // by the high bound, as its inverse says.
        let near = [0, 1, 2].map(|a| 2 * a + (inv[a] < 0.0) as usize);
        Slabs { o: o.to_array(), inv, near }
    }

    /// Entry distances of the children and the mask of those the ray meets within
    /// (tmin, tmax), four lanes at a time. A NaN distance (an origin on a slab plane of a flat axis)
    /// is ignored, so that axis does not cull: `max` and `min` give their second operand when
    /// the first is NaN.
    #[inline(always)]
    fn enter_halves(&self, node: &Node, tmin: f32, tmax: f32) -> ([f32; WIDTH], u32) {
        let (mut out, mut hit) = ([0.0; WIDTH], 0);
        for h in (0..WIDTH).step_by(4) {
            let (mut near, mut far) = (Vec4::splat(tmin), Vec4::splat(tmax));
            for a in 0..3 {
                let bound = |k: usize| Vec4::from_slice(&node.bounds[k][h..h + 4]);
                let (o, inv) = (Vec4::splat(self.o[a]), Vec4::splat(self.inv[a]));
                near = ((bound(self.near[a]) - o) * inv).max(near);
                far = ((bound(self.near[a] ^ 1) - o) * inv).min(far);
            }
            hit |= near.cmple(far * FAR_WIDEN).bitmask() << h;
            near.write_to_slice(&mut out[h..h + 4]);
        }
        (out, hit)
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

    /// A tree over `n` random triangles in the cube [−1, 1]³, and the triangles.
    fn soup(n: u64) -> (Bvh8, Vec<Tri>) {
        let tris: Vec<Tri> = (0..n).map(|i| random_tri(3, i)).map(|t| Tri { e1: t.e1 * 0.2, e2: t.e2 * 0.2, ..t }).collect();
        let obv: Vec<obvhs::triangle::Triangle> =
            tris.iter().map(|t| obvhs::triangle::Triangle { v0: t.v0, v1: t.v0 + t.e1, v2: t.v0 + t.e2 }).collect();
        let b2 = obvhs::bvh2::builder::build_bvh2_from_tris(&obv, obvhs::BvhBuildParams::medium_build(), &mut Default::default());
        let (tree, lanes) = Bvh8::collapse(&b2, |i| tris[i]).unwrap();
        let by_lane = lanes.iter().map(|&p| if p == u32::MAX { tris[0] } else { tris[p as usize] });
        assert!(by_lane.count() == 4 * tree.packets.len() && tree.nodes.len() > 8, "a tree several levels deep");
        (tree, tris)
    }

    #[test]
    fn the_wide_tree_finds_the_closest_of_every_triangle() {
        let (tree, tris) = soup(3000);
        let mut hits = 0;
        for i in 0..3000u64 {
            let u = |k| uniform(11, i, k);
            let o = Vec3A::new(u(0), u(1), u(2)) * 4.0 - Vec3A::splat(2.0);
            let d = (Vec3A::new(u(3), u(4), u(5)) * 2.0 - Vec3A::ONE).normalize();
            let brute = tris.iter().filter_map(|t| t.intersect(o, d, 0.0, f32::INFINITY)).map(|h| h.0).fold(f32::INFINITY, f32::min);
            let found = tree.intersect_portable(o, d, 0.0, f32::INFINITY);
            assert_eq!(found.map_or(f32::INFINITY, |h| h.0), brute, "ray {i}");
            assert_eq!(tree.occluded_portable(o, d, 0.0, f32::INFINITY), brute.is_finite());
            assert_eq!(tree.occluded_portable(o, d, 0.0, brute), false, "nothing before the closest hit");
            // The dispatching entry points (AVX2 where the CPU has it) give the same bits.
            assert_eq!(tree.intersect(o, d, 0.0, f32::INFINITY), found);
            assert_eq!(tree.occluded(o, d, 0.0, brute * 1.5), brute.is_finite());
            hits += brute.is_finite() as usize;
        }
        assert!(hits > 400, "{hits} of 3000 rays hit");
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_slab_test_gives_the_bits_of_the_four_lane_one() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 on this CPU: the portable slab test alone is used");
            return;
        }
        let (tree, _) = soup(500);
        let mut culled = 0;
        for i in 0..4000u64 {
            let u = |k| uniform(12, i, k);
            let node = &tree.nodes[(u(0) * tree.nodes.len() as f32) as usize % tree.nodes.len()];
            // Every fourth ray runs along an axis from a point on a box's plane: 0 × ∞ is NaN.
            let (o, d) = if i % 4 == 0 {
                let lane = (u(1) * WIDTH as f32) as usize % WIDTH;
                let o = Vec3A::new(node.bounds[0][lane], u(2), u(3));
                (o, Vec3A::Y * if u(4) < 0.5 { 1.0 } else { -1.0 })
            } else {
                (Vec3A::new(u(1), u(2), u(3)) * 4.0 - Vec3A::splat(2.0), (Vec3A::new(u(4), u(5), u(6)) * 2.0 - Vec3A::ONE).normalize())
            };
            let ray = Slabs::new(o, d);
            let (a, b) = (ray.enter_halves(node, 0.0, 3.0), unsafe { ray.enter_avx2(node, 0.0, 3.0) });
            assert_eq!((a.0.map(f32::to_bits), a.1), (b.0.map(f32::to_bits), b.1), "ray {i}");
            culled += (a.1.count_ones() < WIDTH as u32) as usize;
        }
        assert!(culled > 1000, "{culled} rays missed some child");
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn two_packets_in_one_avx_register_hit_what_one_after_the_other_hits() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 on this CPU: packets are tested one at a time");
            return;
        }
        let (mut hits, mut second) = (0, 0);
        for i in 0..3000u64 {
            let mut tris: Vec<Tri> = (0..8).map(|k| random_tri(i + 5000, k)).collect();
            // Every fourth pair repeats a triangle of the first packet in the second: a tie.
            if i % 4 == 0 {
                tris[6] = tris[1];
            }
            let (mut a, mut b) = (Tri4 { c: [[0.0; 4]; 9] }, Tri4 { c: [[0.0; 4]; 9] });
            tris.iter().enumerate().for_each(|(lane, t)| if lane < 4 { a.set(lane, t) } else { b.set(lane - 4, t) });
            let o = Vec3A::new(uniform(8, i, 0), uniform(8, i, 1), 3.0);
            let d = (Vec3A::new(uniform(8, i, 2) - 0.5, uniform(8, i, 3) - 0.5, 0.0) - o).normalize();
            let tmax = if i % 3 == 0 { 3.2 } else { f32::INFINITY };
            let first = a.closest(splat(o), splat(d), 0.0, tmax);
            let then = b.closest(splat(o), splat(d), 0.0, first.map_or(tmax, |h| h.1)).map(|h| (h.0 + 4, h.1, h.2, h.3));
            let (o3, d3) = (o.to_array(), d.to_array());
            // SAFETY: the CPU has AVX2.
            let pair = unsafe { Tri4::solve_pair(&a, &b, o3, d3, 0.0, tmax) };
            let pair = lowest(pair.0, &pair.1, &pair.2, &pair.3);
            assert_eq!(pair, then.or(first), "pair {i}");
            let any = a.hits(splat(o), splat(d), 0.0, tmax) | b.hits(splat(o), splat(d), 0.0, tmax);
            assert_eq!(unsafe { Tri4::solve_pair(&a, &b, o3, d3, 0.0, tmax) }.0 != 0, any != 0);
            hits += pair.is_some() as usize;
            second += then.is_some() as usize;
        }
        assert!(hits > 1000 && second > 200, "{hits} hits, {second} in the second packet");
    }

    /// A chain of `depth` nodes, each holding the next and a leaf of one packet: a triangle at
    /// z = −level under the ray down the z axis.
    fn chain(depth: usize) -> Bvh8 {
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
        Bvh8::from_parts(nodes, packets).unwrap()
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
