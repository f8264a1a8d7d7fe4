use super::traversal::NodeRadiance;
use super::wavelet_radiance::WaveletSource;
use crate::types::{CodedWavelets, PointTree, Receivers};
use glam::Vec3;
use relume_base::types::{Image, Metrics};
use relume_core::{node, params, MemoryEstimate, NodeError, PortSize, RunCtx};

params! {
    /// A fast preview of what the coded point tree sends toward the camera ([P] 5.4): the tree's
    /// nodes at level `level` (and leaves above it) are splatted over the G-buffer. A receiver
    /// pixel at x within `radius` × a node's bound of its centre adds w·L to a radiance buffer
    /// and w to a weight buffer, L being the node's radiance toward the camera (its coded J over
    /// its projected area, `WaveletSource`) and w = (1 − (d / R)²)² × max(0, n_x · a)², which
    /// falls to 0 at the kernel's edge and across creases (a: the node's cone axis); the image
    /// is the radiance over the weight. No microbuffer, one descent to level ε per pixel. The
    /// tree holds what the points send (direct light, plus the bounces a `ViewTree` added), so
    /// the preview shows that, smoothed over groups; light sources' own emission is not in it.
    /// Pixels no node reaches stay black and are counted in the report.
    pub struct PreviewSplat {
        /// tree level whose nodes are splatted (leaves above it too)
        pub level: u32 = 12, range = 0..=64, unit = "levels";
        /// kernel radius, in node bounds
        pub radius: f32 = 1.5, range = 1.0..=10.0;
    }
}

/// Receivers per unit of parallel work.
const RECEIVERS_PER_TASK: usize = 64;

impl PreviewSplat {
    /// The normalised radiance at receiver position `x` (normal `n`, toward the camera `wo`),
    /// or `None` where no node's kernel reaches.
    #[allow(clippy::too_many_arguments)]
    fn pixel(
        &self,
        tree: &PointTree,
        level: &[u32],
        source: &WaveletSource,
        x: Vec3,
        n: Vec3,
        wo: Vec3,
        stack: &mut Vec<u32>,
    ) -> Option<Vec3> {
        let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
        stack.clear();
        // The outside of all glass: inner twins send into it only (`PointTree::sides`).
        stack.push(tree.outer_root());
        while let Some(i) = stack.pop() {
            let node = &tree.nodes[i as usize];
            let d = x.distance(node.center);
            match node.children {
                // Every kernel below lies within `radius` × this node's nested sphere.
                Some(c) if level[i as usize] < self.level => {
                    if d <= self.radius * node.radius {
                        stack.extend(c);
                    }
                }
                _ => {
                    let r = self.radius * node.bound;
                    let facing = n.dot(node.cone_axis);
                    if d >= r || facing <= 0.0 {
                        continue;
                    }
                    let (a, l) = source.area_and_radiance(i, wo);
                    if a <= 0.0 {
                        continue;
                    }
                    let k = 1.0 - (d / r) * (d / r);
                    let w = k * k * facing * facing;
                    sum += l * w;
                    weight += w;
                }
            }
        }
        (weight > 0.0).then(|| sum / weight)
    }
}

#[node(category = "pbgi", metrics = ["receivers", "receivers_missed", "nodes_splatted"], outputs = [image, stats])]
impl PreviewSplat {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        let image = inputs[2].and_then(|s| s.dims).map(|[w, h]| PortSize::image(w, h));
        let memo = super::texel_cache::BYTES_PER_THREAD as u64 * rayon::current_num_threads() as u64;
        MemoryEstimate { outputs: vec![image, Some(PortSize::bytes(256))], working: memo }
    }

    fn run(&self, tree: &PointTree, coded: &CodedWavelets, receivers: &Receivers, cx: &RunCtx) -> Result<(Image, Metrics), NodeError> {
        let r = receivers;
        let source = WaveletSource::checked(tree, coded)?;
        let level = &coded.tree.level;
        let tasks = cx.par_map(r.len().div_ceil(RECEIVERS_PER_TASK), |task| {
            let mut stack = Vec::new();
            let range = task * RECEIVERS_PER_TASK..((task + 1) * RECEIVERS_PER_TASK).min(r.len());
            range.map(|k| self.pixel(tree, level, &source, r.position[k], r.normal[k], r.wo[k], &mut stack)).collect::<Vec<_>>()
        })?;
        let mut img = r.blank_image();
        let mut missed = 0u64;
        for (k, l) in tasks.into_iter().flatten().enumerate() {
            match l {
                Some(l) => r.add_to(&mut img, k, l),
                None => missed += 1,
            }
        }
        r.fill_in(&mut img);
        let nodes =
            tree.nodes.iter().enumerate().filter(|(k, t)| level[*k] == self.level || (t.is_leaf() && level[*k] < self.level)).count();
        let m = Metrics(vec![
            ("receivers".into(), r.len() as f64),
            ("receivers_missed".into(), missed as f64),
            ("nodes_splatted".into(), nodes as f64),
        ]);
        for (k, v) in &m.0 {
            cx.metric(k, *v);
        }
        Ok((img, m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::wpbgi_setup::setup;
    use crate::types::PointWavelets;
    use crate::wavelet_radiance::{code_tree, outgoing_intensity};
    use relume_base::math::cube_haar::CubeHaar;
    use relume_base::math::tree_coding::Threshold;
    use relume_base::testing::{cancels_midway, f, first, i, run_on};
    use relume_base::types::{Material, SurfacePoints};
    use relume_core::Value;

    /// A 40 × 40 grid of disks on z = 0 facing up, each sending radiance `l` everywhere above
    /// (Lambert albedo π lit by unit irradiance along the normal: L = 1 · `l`), its tree, the
    /// coded maps, and receivers at every point and between them, looking down from above.
    fn plane(l: f32) -> (PointTree, CodedWavelets, Receivers) {
        let position: Vec<Vec3> = (0..1600).map(|k| Vec3::new((k % 40) as f32 * 0.05, (k / 40) as f32 * 0.05, 0.0)).collect();
        let (tree, coded) = disks(position, l);
        (tree, coded, receivers())
    }

    /// Disks of radius 0.028 at `position` facing up, each sending radiance `l` everywhere
    /// above: their tree and coded maps (split level 6, nothing dropped).
    fn disks(position: Vec<Vec3>, l: f32) -> (PointTree, CodedWavelets) {
        let count = position.len();
        let pts = SurfacePoints {
            position,
            normal: vec![Vec3::Z; count],
            radius: vec![0.028; count],
            object: vec![0; count],
            material: vec![Material::Lambert { albedo: Vec3::splat(std::f32::consts::PI * l) }; count],
        };
        let tree = PointTree::build(&pts, &vec![Vec3::splat(l); count]);
        let map = outgoing_intensity(&pts.material[0], Vec3::Z, &[(Vec3::Z, Vec3::ONE)], 8);
        let w = CubeHaar::forward(&map).keep_above(0.0);
        let maps = PointWavelets::from_points(8, &vec![w; count]);
        let coded = CodedWavelets { n: 8, tree: code_tree(&tree, &maps, 6, Threshold::Coefficient(0.0)) };
        (tree, coded)
    }

    /// Receivers at 30 × 30 places inside the 40 × 40 grid of `plane`, seen from straight above.
    fn receivers() -> Receivers {
        let position: Vec<Vec3> =
            (0..900).map(|k| Vec3::new(0.2 + (k % 30) as f32 * 0.05 + 0.013, 0.2 + (k / 30) as f32 * 0.05 + 0.021, 0.0)).collect();
        Receivers {
            width: 30,
            height: 30,
            pixel: (0..900).collect(),
            position,
            normal: vec![Vec3::Z; 900],
            wo: vec![Vec3::Z; 900],
            object: vec![0; 900],
            material: vec![Material::Lambert { albedo: Vec3::ONE }; 900],
            weight: vec![1.0; 900],
            fill: vec![],
        }
    }

    #[test]
    fn coincident_points_one_point_and_a_level_below_the_leaves_stay_finite_and_bounded() {
        // docs/QUALITY.md §2 "PBGI": a hundred disks at one place, a tree of one point, and a level
        // deeper than the tree (its leaves splat). Every pixel is a weighted mean of what the
        // nodes send (0.5), so none may exceed it; pixels no kernel reaches stay black.
        let centre = Vec3::new(0.95, 0.95, 0.0);
        for (what, position, level) in
            [("coincident", vec![centre; 100], 3), ("one point", vec![centre], 12), ("below the leaves", vec![centre; 100], 64)]
        {
            let (tree, coded) = disks(position, 0.5);
            let out =
                run_on::<PreviewSplat>(&[("level", i(level))], vec![Value::new(tree), Value::new(coded), Value::new(receivers())]).unwrap();
            let img: Image = first(&out);
            assert!(img.as_floats().iter().all(|x| x.is_finite() && (0.0..=0.5 * 1.02).contains(x)), "{what}");
            let lit = img.pixels.iter().filter(|p| p[0] > 0.0).count();
            let missed = out[1].get::<Metrics>().unwrap().get("receivers_missed").unwrap();
            // The disks' kernel (1.5 × 0.028) reaches the one receiver 0.013, 0.021 from them.
            assert!(lit >= 1 && lit as f64 + missed == 900.0, "{what}: {lit} lit, {missed} missed");
        }
    }

    #[test]
    fn a_plane_sending_one_radiance_previews_as_that_radiance_at_every_level() {
        for level in [0, 4, 8, 30] {
            let (tree, coded, r) = plane(0.5);
            let out = run_on::<PreviewSplat>(&[("level", i(level))], vec![Value::new(tree), Value::new(coded), Value::new(r)]).unwrap();
            let img: Image = first(&out);
            let worst = img.pixels.iter().map(|p| (p[0] - 0.5).abs()).fold(0.0f32, f32::max);
            // Within 2.0 % (measured at level 0): a group's projected area is its 3-band SH
            // estimate, exact for leaves only.
            assert!(worst < 0.0125, "level {level}: a pixel {worst} off 0.5");
            assert_eq!(out[1].get::<Metrics>().unwrap().get("receivers_missed"), Some(0.0));
        }
    }

    #[test]
    fn on_the_corner_coarser_levels_fill_the_gaps_between_points_and_keep_the_mean() {
        // The preview of the direct light's tree at level 64 (every leaf splats its own disk,
        // 1.5 × its radius) against level 6 (64 nodes). Random points leave gaps the leaves'
        // kernels miss (measured: 8 of 90 receivers); over the receivers both reach, the
        // means stay close (measured: 0.2064 against 0.2090, 1.2 % apart).
        let s = setup(Material::Lambert { albedo: Vec3::splat(0.6) });
        let run = |level: i64| -> (Image, Metrics) {
            let inputs = vec![Value::new(s.tree.clone()), Value::new(s.coded.clone()), Value::new(s.receivers.clone())];
            let out = run_on::<PreviewSplat>(&[("level", i(level))], inputs).unwrap();
            (first(&out), out[1].get::<Metrics>().unwrap().clone())
        };
        let (fine, mf) = run(64);
        let (coarse, mc) = run(6);
        assert!(fine.as_floats().iter().chain(coarse.as_floats().iter()).all(|x| x.is_finite() && *x >= 0.0));
        assert!(mc.get("nodes_splatted").unwrap() < mf.get("nodes_splatted").unwrap());
        assert!(mf.get("receivers_missed").unwrap() > 0.0 && mc.get("receivers_missed") == Some(0.0), "{mf:?} {mc:?}");
        let both: Vec<usize> = (0..fine.pixels.len()).filter(|&k| fine.pixels[k][0] > 0.0 && coarse.pixels[k][0] > 0.0).collect();
        let mean = |img: &Image| both.iter().map(|&k| img.pixels[k][0] as f64).sum::<f64>() / both.len() as f64;
        let (a, b) = (mean(&fine), mean(&coarse));
        assert!(a > 0.0 && ((b - a) / a).abs() < 0.05, "leaves {a}, level 6 {b}");
    }

    #[test]
    fn another_trees_wavelets_are_refused_and_a_run_can_be_cancelled() {
        let (tree, coded, r) = plane(0.5);
        let (other, _, _) = {
            let (t, c, rr) = plane(0.5);
            let mut t = t;
            t.nodes.truncate(5);
            (t, c, rr)
        };
        let e = run_on::<PreviewSplat>(&[], vec![Value::new(other), Value::new(coded.clone()), Value::new(r.clone())]).unwrap_err();
        assert!(e.to_string().contains("not this tree"), "{e}");
        cancels_midway::<PreviewSplat>(&[("radius", f(1.5))], vec![Value::new(tree), Value::new(coded), Value::new(r)]);
    }
}
