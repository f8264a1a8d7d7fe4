//! PbgiGather node.

use super::microbuffer::Microbuffer;
use super::point_tree::PointTree;
use crate::brdf;
use crate::math::frame::Frame;
use crate::types::{Image, Metrics, Receivers};
use glam::Vec3;
use rayon::prelude::*;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};

node_doc! {
    /// Point-based gather of one bounce of indirect light ([P] 2.2, eq. 2.1). For each receiver
    /// the point tree is traversed from the root: a node whose solid angle A/d² is at most
    /// `threshold` × one microbuffer pixel's is rasterised into the receiver's microbuffer
    /// with depth (radiance toward the receiver from its SH power / SH projected area); larger
    /// nodes are opened; a leaf still too large (a near point) is ray-cast exactly as a disk;
    /// a receiver inside a node's bounding sphere always opens it. The microbuffer is the
    /// hemisphere in the Nusselt mapping (equal projected solid angle per pixel; a cube map is
    /// not implemented), then convolved with the receiver's BRDF and cosine. Outputs the
    /// indirect image and per-receiver counts (nodes visited, rasterised, near leaves).
    pub struct PbgiGather;
}

pub struct PbgiGatherParams {
    pub resolution: usize,
    pub threshold: f32,
}

/// The microbuffer parameters both gathers share.
pub fn microbuffer_schema() -> Schema {
    Schema::new()
        .int("resolution", 16, 1, 256)
        .unit("px")
        .help("microbuffer side (N × N pixels over the hemisphere)")
        .float("threshold", 1.0, 0.01, 100.0)
        .unit("pixels")
        .help("largest solid angle of a rasterised node, in microbuffer pixels")
}

impl Params for PbgiGatherParams {
    fn schema() -> Schema {
        microbuffer_schema()
    }
    fn from_values(v: &ParamValues) -> Self {
        PbgiGatherParams { resolution: v.int("resolution") as usize, threshold: v.float("threshold") as f32 }
    }
}

/// Counts of one receiver's traversal.
#[derive(Clone, Copy, Debug, Default)]
pub struct GatherCounts {
    pub visited: u64,
    pub rasterised: u64,
    pub near_leaves: u64,
}

impl std::ops::Add for GatherCounts {
    type Output = GatherCounts;
    fn add(self, o: GatherCounts) -> GatherCounts {
        GatherCounts {
            visited: self.visited + o.visited,
            rasterised: self.rasterised + o.rasterised,
            near_leaves: self.near_leaves + o.near_leaves,
        }
    }
}

/// What a traversal reads of every node, packed into 48 bytes in the tree's depth-first order
/// (the whole tree's SH would not stay in cache; it is read only for nodes rasterised).
#[derive(Clone, Copy)]
struct HotNode {
    center: Vec3,
    /// `TreeNode::bound`; for a leaf the disk's radius.
    bound: f32,
    /// Cone axis (a leaf's normal).
    axis: Vec3,
    area: f32,
    slab: [f32; 2],
    /// Right child (the left one follows its parent); `u32::MAX` for leaves.
    right: u32,
}

/// Settings of one traversal.
pub struct Traversal<'a> {
    pub tree: &'a PointTree,
    /// Largest solid angle of a rasterised node, in microbuffer pixels.
    pub threshold: f32,
    /// Self-intersection guard for exactly ray-cast near leaves, and the height above a
    /// receiver's horizon under which a node is culled.
    pub eps: f32,
    hot: Vec<HotNode>,
}

impl<'a> Traversal<'a> {
    pub fn new(tree: &'a PointTree, threshold: f32, eps: f32) -> Self {
        let hot = tree
            .nodes
            .iter()
            .enumerate()
            .map(|(i, n)| {
                if let Some([l, _]) = n.children {
                    debug_assert_eq!(l as usize, i + 1, "depth-first layout");
                }
                HotNode {
                    center: n.center,
                    bound: n.bound,
                    axis: n.cone_axis,
                    area: n.area,
                    slab: n.slab,
                    right: n.children.map_or(u32::MAX, |[_, r]| r),
                }
            })
            .collect();
        Traversal { tree, threshold, eps, hot }
    }

    /// Traverses from `roots` for a receiver at `p` with microbuffer frame `frame`, writing
    /// into `mb`. `leave(i, d)` may set node i (at distance d) aside instead of rasterising or
    /// opening it: the factorised gather leaves nodes near a cluster to its receivers.
    #[allow(clippy::too_many_arguments)]
    pub fn run(
        &self,
        roots: &[u32],
        p: Vec3,
        frame: &Frame,
        mb: &mut Microbuffer,
        stack: &mut Vec<u32>,
        counts: &mut GatherCounts,
        mut leave: impl FnMut(u32, f32) -> bool,
    ) {
        let limit = self.threshold * mb.mean_pixel_solid_angle();
        stack.clear();
        stack.extend_from_slice(roots);
        while let Some(i) = stack.pop() {
            counts.visited += 1;
            let v = self.hot[i as usize].center - p;
            let d = v.length();
            if leave(i, d) {
                continue;
            }
            self.visit(i, v, d, frame, mb, limit, stack, counts);
        }
    }

    /// One node of a traversal: skip it when it lies wholly under the receiver's horizon, open
    /// it, ray-cast it (near leaf) or rasterise it.
    #[allow(clippy::too_many_arguments)]
    fn visit(
        &self,
        i: u32,
        v: Vec3,
        d: f32,
        frame: &Frame,
        mb: &mut Microbuffer,
        limit: f32,
        stack: &mut Vec<u32>,
        counts: &mut GatherCounts,
    ) {
        let node = &self.hot[i as usize];
        if top_above_horizon(node, v, frame.n) <= self.eps {
            return;
        }
        let inside = d <= node.bound;
        let omega = node.area / (d * d).max(f32::MIN_POSITIVE);
        if inside || omega > limit {
            if node.right != u32::MAX {
                stack.push(i + 1);
                stack.push(node.right);
            } else {
                counts.near_leaves += 1;
                let c = frame.to_local(v);
                let toward = -v / d.max(f32::MIN_POSITIVE);
                mb.disk_exact(c, frame.to_local(node.axis), node.bound, self.tree.radiance_toward(i, toward), self.eps);
            }
            return;
        }
        let toward = -v / d;
        let (a, l) = self.tree.area_and_radiance(i, toward);
        if a <= 0.0 {
            return;
        }
        counts.rasterised += 1;
        mb.splat(frame.to_local(v / d), d, a / (d * d), l);
    }
}

/// An upper bound on the height of a node's disks above the plane through the receiver with
/// normal `n` (`v`: node centre − receiver): the least of the sphere's top and the slab's,
/// the slab bounding the disks along the cone axis and the sphere across it.
fn top_above_horizon(node: &HotNode, v: Vec3, n: Vec3) -> f32 {
    let vn = v.dot(n);
    let along = node.axis.dot(n);
    let across = (1.0 - along * along).max(0.0).sqrt();
    let slab = (along * node.slab[0]).max(along * node.slab[1]) + across * node.bound;
    vn + slab.min(node.bound)
}

/// Indirect radiance toward the camera for every receiver.
pub fn gather(tree: &PointTree, r: &Receivers, p: &PbgiGatherParams, extent: f32) -> (Image, GatherCounts) {
    let t = Traversal::new(tree, p.threshold, 1e-5 * extent);
    let results: Vec<(Vec3, GatherCounts)> = (0..r.len())
        .into_par_iter()
        .map_init(
            || (Microbuffer::new(p.resolution), Vec::new()),
            |(mb, stack), i| {
                let mut counts = GatherCounts::default();
                if brdf::is_delta(&r.material[i]) {
                    return (Vec3::ZERO, counts);
                }
                mb.clear();
                let frame = Frame::from_normal(r.normal[i]);
                t.run(&[tree.root], r.position[i], &frame, mb, stack, &mut counts, |_, _| false);
                (mb.convolve(&r.material[i], frame.to_local(r.wo[i])), counts)
            },
        )
        .collect();
    let mut img = Image { width: r.width, height: r.height, pixels: vec![[0.0; 3]; r.width * r.height] };
    let mut total = GatherCounts::default();
    for (i, (l, c)) in results.into_iter().enumerate() {
        img.pixels[r.pixel[i] as usize] = l.to_array();
        total = total + c;
    }
    (img, total)
}

/// Per-receiver means of the counts, for the report and the stats output.
pub fn count_metrics(c: GatherCounts, receivers: usize) -> Metrics {
    let n = receivers.max(1) as f64;
    Metrics(vec![
        ("receivers".into(), receivers as f64),
        ("nodes_visited_per_receiver".into(), c.visited as f64 / n),
        ("nodes_rasterised_per_receiver".into(), c.rasterised as f64 / n),
        ("near_leaves_per_receiver".into(), c.near_leaves as f64 / n),
    ])
}

impl Node for PbgiGather {
    const KIND: &'static str = "PbgiGather";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "pbgi";
    const CACHING: Caching = Caching::Memory;
    type Params = PbgiGatherParams;

    fn ports() -> Ports {
        Ports::new().input::<PointTree>("tree").input::<Receivers>("receivers").output::<Image>("indirect").output::<Metrics>("stats")
    }

    fn run(&self, p: &PbgiGatherParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        let (tree, r) = (io.input::<PointTree>("tree")?, io.input::<Receivers>("receivers")?);
        cx.check()?;
        let extent = tree.nodes.get(tree.root as usize).map_or(1.0, |n| 2.0 * n.radius);
        let (img, counts) = gather(tree, r, p, extent);
        let m = count_metrics(counts, r.len());
        for (k, v) in &m.0 {
            cx.metric(k, *v);
        }
        io.set("indirect", img)?;
        io.set("stats", m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{first, i, pbgi_setup, run_on};
    use relume_core::Value;

    #[test]
    fn a_receiver_culls_the_flat_group_it_lies_in_and_what_lies_below_its_horizon() {
        // 400 disks on the plane z = 1 (normal +z) and 400 more on z = 0 facing up.
        use crate::types::{Material, SurfacePoints};
        let grid = |z: f32| (0..400).map(move |k| Vec3::new((k % 20) as f32 * 0.1 - 1.0, (k / 20) as f32 * 0.1 - 1.0, z));
        let position: Vec<Vec3> = grid(1.0).chain(grid(0.0)).collect();
        let n = position.len();
        let pts = SurfacePoints {
            position,
            normal: vec![Vec3::Z; n],
            radius: vec![0.05; n],
            object: vec![0; n],
            material: vec![Material::Lambert { albedo: Vec3::ONE }; n],
        };
        let tree = PointTree::build(&pts, &vec![Vec3::ONE; n]);
        let t = Traversal::new(&tree, 1.0, 1e-5 * 4.0);
        let (mut mb, mut stack) = (Microbuffer::new(8), Vec::new());
        let run = |p: Vec3, nrm: Vec3, mb: &mut Microbuffer, stack: &mut Vec<u32>| {
            let mut counts = GatherCounts::default();
            mb.clear();
            t.run(&[tree.root], p, &Frame::from_normal(nrm), mb, stack, &mut counts, |_, _| false);
            counts
        };
        // In the upper plane, facing up: both planes lie at or under its horizon.
        let c = run(Vec3::new(0.03, 0.02, 1.0), Vec3::Z, &mut mb, &mut stack);
        assert_eq!((c.rasterised, c.near_leaves), (0, 0), "{c:?}");
        assert!(c.visited <= 3, "the subtrees of both planes are culled at once: {c:?}");
        assert!(mb.radiance.iter().all(|l| *l == Vec3::ZERO));
        // Facing down from the same spot, the lower plane is seen; the upper one is still culled.
        let c = run(Vec3::new(0.03, 0.02, 1.0), -Vec3::Z, &mut mb, &mut stack);
        assert!(c.rasterised + c.near_leaves > 0 && c.visited < 2 * 400, "{c:?}");
        assert!(mb.radiance.iter().any(|l| *l != Vec3::ZERO));
    }

    #[test]
    fn the_node_lights_the_receivers_and_reports_its_counts() {
        let (tree, r) = pbgi_setup::tree_and_receivers();
        let out = run_on(PbgiGather, &[("resolution", i(8))], vec![Value::new(tree), Value::new(r.clone())]).unwrap();
        let img: Image = first(&out);
        assert_eq!((img.width, img.height), (r.width, r.height));
        assert!(img.as_floats().iter().all(|x| x.is_finite() && *x >= 0.0));
        assert!(img.as_floats().iter().any(|x| *x > 0.0), "light bounces between the spheres and the floor");
        let stats = out[1].get::<Metrics>().unwrap();
        assert!(stats.get("nodes_rasterised_per_receiver").unwrap() > 0.0);
        assert!(stats.get("nodes_visited_per_receiver").unwrap() >= stats.get("nodes_rasterised_per_receiver").unwrap());
    }
}
