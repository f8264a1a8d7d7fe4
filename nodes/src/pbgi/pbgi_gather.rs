//! PbgiGather node.

use super::microbuffer::Microbuffer;
use super::traversal::{count_metrics, microbuffer_params, tree_extent, GatherBuffer, GatherCounts, NodeRadiance, Traversal};
use crate::math::frame::Frame;
use crate::math::morton::morton2;
use crate::pbgi::types::{PointTree, Receivers};
use crate::types::{Image, Metrics};
use glam::Vec3;
use relume_core::{inputs, node, outputs, NodeError, Params, RunCtx};

microbuffer_params! {
    /// Point-based gather of one bounce of indirect light ([P] 2.2, eq. 2.1). For each receiver
    /// the point tree is traversed from the root: a node whose solid angle A/d² is at most
    /// `threshold` × one microbuffer pixel's is rasterised into the receiver's microbuffer
    /// with depth (radiance toward the receiver from its SH power / SH projected area); larger
    /// nodes are opened; a leaf still too large (a near point) is ray-cast exactly as a disk;
    /// a receiver inside a node's bounding sphere always opens it. The microbuffer is the
    /// hemisphere in the Nusselt mapping (equal projected solid angle per pixel; a cube map is
    /// not implemented), then convolved with the receiver's BRDF and cosine. Outputs the
    /// indirect image and per-receiver counts (nodes visited, rasterised, near leaves).
    #[derive(Params)]
    pub struct PbgiGather {}
}

inputs!(pub PbgiGatherIn { tree: PointTree, receivers: Receivers });
outputs!(pub PbgiGatherOut { indirect: Image, stats: Metrics });

/// Receivers gathered with one microbuffer (a unit of parallel work and of progress).
const RECEIVERS_PER_TASK: usize = 16;

/// Indirect radiance toward the camera for every receiver (`extent` sets the traversal's ε).
pub fn gather(tree: &PointTree, r: &Receivers, p: &PbgiGather, extent: f32, cx: &RunCtx) -> Result<(Image, GatherCounts), NodeError> {
    gather_with(&Traversal::new(tree, p.threshold, 1e-5 * extent), r, Microbuffer::new(p.resolution), cx)
}

/// The gather over traversal `t` (whatever its nodes send) into copies of `blank` (uniform
/// or adaptive): one buffer per receiver, convolved with the receiver's BRDF. Receivers are
/// taken in Z order over the image (`z_order`), so a task's receivers are a small square and
/// see the tree's nodes from nearly the same place (what memos of node values reuse); each
/// receiver's result is its own, so the order changes no byte.
pub fn gather_with<R: NodeRadiance, B: GatherBuffer>(
    t: &Traversal<R>,
    r: &Receivers,
    blank: B,
    cx: &RunCtx,
) -> Result<(Image, GatherCounts), NodeError> {
    let order = z_order(r);
    let tasks = cx.par_map(r.len().div_ceil(RECEIVERS_PER_TASK), |task| {
        let (mut mb, mut stack) = (blank.clone(), Vec::new());
        let first = task * RECEIVERS_PER_TASK;
        order[first..(first + RECEIVERS_PER_TASK).min(r.len())]
            .iter()
            .map(|&i| {
                let i = i as usize;
                let mut counts = GatherCounts::default();
                if !mb.shades(&r.material[i]) {
                    return (Vec3::ZERO, counts);
                }
                let frame = Frame::from_normal(r.normal[i]);
                let wo = frame.to_local(r.wo[i]);
                mb.begin(&r.material[i], wo);
                mb.gather(t, &r.material[i], r.position[i], &frame, &mut stack, &mut counts);
                (mb.end(&r.material[i], wo), counts)
            })
            .collect::<Vec<_>>()
    })?;
    let mut img = Image { width: r.width, height: r.height, pixels: vec![[0.0; 3]; r.width * r.height] };
    let mut total = GatherCounts::default();
    for (&i, (l, c)) in order.iter().zip(tasks.into_iter().flatten()) {
        img.pixels[r.pixel[i as usize] as usize] = l.to_array();
        total = total + c;
    }
    Ok((img, total))
}

/// The receivers' indices sorted by the Morton code of their pixel (`math::morton`; ties
/// keep the receivers' order).
pub fn z_order(r: &Receivers) -> Vec<u32> {
    let w = r.width.max(1);
    let key = |i: u32| {
        let p = r.pixel[i as usize] as usize;
        morton2(p % w, p / w)
    };
    let mut order: Vec<u32> = (0..r.len() as u32).collect();
    order.sort_by_key(|&i| key(i));
    order
}

#[node(category = "pbgi")]
impl PbgiGather {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let image = inputs[1].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        relume_core::MemoryEstimate { outputs: vec![image, Some(relume_core::PortSize::bytes(256))], working: 0 }
    }

    fn run(&self, i: PbgiGatherIn, cx: &RunCtx) -> Result<PbgiGatherOut, NodeError> {
        let (img, counts) = gather(i.tree, i.receivers, self, tree_extent(i.tree), cx)?;
        let m = count_metrics(counts, i.receivers.len());
        for (k, v) in &m.0 {
            cx.metric(k, *v);
        }
        Ok(PbgiGatherOut { indirect: img, stats: m })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pbgi::test_support::pbgi_setup;
    use crate::testing::{cancels_midway, first, i, run_on};
    use relume_core::Value;

    #[test]
    fn receivers_are_taken_in_z_order_over_their_pixels() {
        let (_, mut r) = pbgi_setup::tree_and_receivers();
        // Pretend the receivers cover a 4 × 4 image in reverse row order.
        let n = r.len().min(16);
        r.width = 4;
        r.pixel = (0..r.len() as u32).map(|i| if (i as usize) < n { 15 - i } else { 16 + i }).collect();
        let order = z_order(&r);
        let pixels: Vec<u32> = order[..n].iter().map(|&i| r.pixel[i as usize]).collect();
        let want: Vec<u32> = [0, 1, 4, 5, 2, 3, 6, 7, 8, 9, 12, 13, 10, 11, 14, 15].into_iter().filter(|&p| p + (n as u32) >= 16).collect();
        assert_eq!(pixels, want);
        let mut all = order.clone();
        all.sort_unstable();
        assert_eq!(all, (0..r.len() as u32).collect::<Vec<_>>(), "a permutation");
    }

    #[test]
    fn the_node_lights_the_receivers_and_reports_its_counts() {
        let (tree, r) = pbgi_setup::tree_and_receivers();
        let out = run_on::<PbgiGather>(&[("resolution", i(8))], vec![Value::new(tree), Value::new(r.clone())]).unwrap();
        let img: Image = first(&out);
        assert_eq!((img.width, img.height), (r.width, r.height));
        assert!(img.as_floats().iter().all(|x| x.is_finite() && *x >= 0.0));
        assert!(img.as_floats().iter().any(|x| *x > 0.0), "light bounces between the walls of the box");
        let stats = out[1].get::<Metrics>().unwrap();
        assert!(stats.get("nodes_rasterised_per_receiver").unwrap() > 0.0);
        assert!(stats.get("nodes_visited_per_receiver").unwrap() >= stats.get("nodes_rasterised_per_receiver").unwrap());
    }

    #[test]
    fn the_gather_gives_the_same_bytes_on_one_and_four_threads() {
        let (tree, r) = pbgi_setup::tree_and_receivers();
        let p = PbgiGather { resolution: 8, threshold: 1.0 };
        let cancel = relume_core::CancelToken::new();
        let cx = RunCtx::new("t", &cancel, None);
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let (img, c) = pool.install(|| gather(&tree, &r, &p, 4.0, &cx).unwrap());
            (img.pixels, c.visited, c.rasterised, c.near_leaves)
        };
        assert_eq!(run(1), run(4));
    }

    #[test]
    fn the_node_stops_when_cancelled() {
        let (tree, r) = pbgi_setup::tree_and_receivers();
        cancels_midway::<PbgiGather>(&[("resolution", i(8))], vec![Value::new(tree), Value::new(r)]);
    }
}
