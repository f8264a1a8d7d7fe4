use super::gather::gather_with;
use super::microbuffer::Microbuffer;
use super::traversal::{count_metrics, tree_extent, GatherCounts, MicrobufferParams, Traversal};
use crate::types::{PointTree, Receivers};
use relume_base::types::{Image, Metrics};
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// Point-based gather of one bounce of indirect light ([P] 2.2, eq. 2.1). For each receiver
    /// the point tree is traversed from the root: a node whose solid angle A/d² is at most
    /// `threshold` × one microbuffer pixel's is rasterised into the receiver's microbuffer
    /// with depth (radiance toward the receiver from its SH power / SH projected area); larger
    /// nodes are opened; a leaf still too large (a near point) is ray-cast exactly as a disk;
    /// a receiver inside a node's bounding sphere always opens it. The microbuffer is the
    /// hemisphere in the Nusselt mapping (equal projected solid angle per pixel; a cube map is
    /// not implemented), then convolved with the receiver's BRDF and cosine. Outputs the
    /// indirect image and per-receiver counts (nodes visited, rasterised, near leaves).
    pub struct PbgiGather {
        pub microbuffer: MicrobufferParams, flatten;
    }
}

/// Indirect radiance toward the camera for every receiver (`extent` sets the traversal's ε).
pub fn gather(tree: &PointTree, r: &Receivers, p: &PbgiGather, extent: f32, cx: &RunCtx) -> Result<(Image, GatherCounts), NodeError> {
    gather_with(
        &Traversal::new(tree, p.microbuffer.threshold, 1e-5 * extent),
        r,
        Microbuffer::new(p.microbuffer.resolution).with_rule(p.microbuffer.splat),
        cx,
    )
}

#[node(category = "pbgi", version = 6, metrics = ["receivers", "nodes_visited_per_receiver", "nodes_rasterised_per_receiver", "near_leaves_per_receiver"], outputs = [indirect, stats])]
impl PbgiGather {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let image = inputs[1].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        relume_core::MemoryEstimate { outputs: vec![image, Some(relume_core::PortSize::bytes(256))], working: 0 }
    }

    fn run(&self, tree: &PointTree, receivers: &Receivers, cx: &RunCtx) -> Result<(Image, Metrics), NodeError> {
        let (img, counts) = gather(tree, receivers, self, tree_extent(tree), cx)?;
        let m = count_metrics(counts, receivers.len());
        for (k, v) in &m.0 {
            cx.metric(k, *v);
        }
        Ok((img, m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gather::z_order;
    use crate::microbuffer::SplatRule;
    use crate::test_support::pbgi_setup;
    use relume_base::testing::{cancels_midway, first, i, run_on};
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
    fn a_filled_pixel_takes_the_gathered_light_of_the_pixels_it_reads() {
        let (tree, r) = pbgi_setup::tree_and_receivers();
        let (r, pixels) = pbgi_setup::with_a_fill(&r);
        let out = run_on::<PbgiGather>(&[("resolution", i(8))], vec![Value::new(tree), Value::new(r)]).unwrap();
        pbgi_setup::assert_filled(&first(&out), pixels);
    }

    #[test]
    fn the_gather_gives_the_same_bytes_on_one_and_four_threads() {
        let (tree, r) = pbgi_setup::tree_and_receivers();
        let p = PbgiGather { microbuffer: MicrobufferParams { resolution: 8, threshold: 1.0, splat: SplatRule::Bilinear } };
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
