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

/// Settings of one traversal.
pub struct Traversal<'a> {
    pub tree: &'a PointTree,
    /// Largest solid angle of a rasterised node, in microbuffer pixels.
    pub threshold: f32,
    /// Self-intersection guard for exactly ray-cast near leaves.
    pub eps: f32,
}

impl Traversal<'_> {
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
        let tree = self.tree;
        let limit = self.threshold * mb.mean_pixel_solid_angle();
        stack.clear();
        stack.extend_from_slice(roots);
        while let Some(i) = stack.pop() {
            let node = &tree.nodes[i as usize];
            counts.visited += 1;
            let v = node.center - p;
            let d = v.length();
            if leave(i, d) {
                continue;
            }
            visit(tree, i, v, d, frame, mb, limit, self.eps, stack, counts);
        }
    }
}

/// One node of a traversal: skip it below the horizon, open it, ray-cast it (near leaf) or
/// rasterise it.
#[allow(clippy::too_many_arguments)]
fn visit(
    tree: &PointTree,
    i: u32,
    v: Vec3,
    d: f32,
    frame: &Frame,
    mb: &mut Microbuffer,
    limit: f32,
    eps: f32,
    stack: &mut Vec<u32>,
    counts: &mut GatherCounts,
) {
    let node = &tree.nodes[i as usize];
    // Wholly below the receiver's horizon: cannot be seen.
    if v.dot(frame.n) + node.radius <= 0.0 {
        return;
    }
    let inside = d <= node.radius;
    let omega = node.area / (d * d).max(f32::MIN_POSITIVE);
    if inside || omega > limit {
        match node.children {
            Some([a, b]) => {
                stack.push(a);
                stack.push(b);
            }
            None => {
                counts.near_leaves += 1;
                let c = frame.to_local(v);
                let toward = -v / d.max(f32::MIN_POSITIVE);
                mb.disk_exact(c, frame.to_local(node.cone_axis), node.radius, tree.radiance_toward(i, toward), eps);
            }
        }
        return;
    }
    let toward = -v / d;
    let a = tree.projected_area(i, toward);
    if a <= 0.0 {
        return;
    }
    counts.rasterised += 1;
    mb.splat(frame.to_local(v / d), d, a / (d * d), tree.radiance_toward(i, toward));
}

/// Indirect radiance toward the camera for every receiver.
pub fn gather(tree: &PointTree, r: &Receivers, p: &PbgiGatherParams, extent: f32) -> (Image, GatherCounts) {
    let t = Traversal { tree, threshold: p.threshold, eps: 1e-5 * extent };
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
