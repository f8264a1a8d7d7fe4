use super::brdf_wavelets::{to_cube, BrdfWavelets};
use super::microbuffer::Microbuffer;
use super::spherical_microbuffer::SphericalMicrobuffer;
use super::traversal::{tree_extent, GatherBuffer, GatherCounts, Traversal};
use super::view_walk::{ViewWalk, WalkCounts};
use super::wavelet_radiance::{band_limited, cap_exitance, code_tree, WaveletSource};
use crate::types::{CodedWavelets, PointTree, PointWavelets};
use glam::Vec3;
use relume_base::brdf;
use relume_base::math::cube_haar::{CubeHaar, SparseCubeHaar};
use relume_base::math::cubemap::{texel_directions, CubeMap};
use relume_base::math::frame::Frame;
use relume_base::math::tree_coding::Threshold;
use relume_base::types::{Material, Metrics, SurfacePoints};
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

/// How every point gathers.
#[derive(ParamEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Walk {
    /// the view tree: the point tree against itself, group buffers reused
    ViewTree,
    /// each point traverses the tree from the root on its own (to measure against)
    PerReceiver,
}

params! {
    /// More bounces of glossy light through the point tree (view-tree PBGI, [P] 5.3): every
    /// point gathers the light the tree's points send (`view_walk`: receiver and sender nodes
    /// paired from the root, view-cone culling, one buffer for a group whose normals agree),
    /// reflects it through its BRDF (`brdf_wavelets`: the wavelet radiance product on the
    /// microbuffer's grid, resampled into the world cube as J, [P] 5.3.1 scheme 2; Lambert
    /// points send albedo/π × irradiance) and adds it to what it sends of the direct light
    /// (`SurfelWavelets`); the points' maps are coded along the tree again (post-order,
    /// `WaveletTree`'s coding with `split` and `threshold`), and the next bounce gathers from
    /// that. `bounces` = 0 codes the direct light alone (the input of a one-bounce gather);
    /// each bounce adds one to the light a final `WaveletGather` shows. Points on smooth
    /// dielectrics (with their twins, `TwinDielectrics`) gather the whole sphere on their own
    /// (`spherical_microbuffer`) and send what their reflected and refracted lobes read.
    /// A reused group buffer stands for its points' own frames (within `reuse_angle`).
    /// Memory: known only from the inputs' content; `run` checks it before each bounce.
    pub struct ViewTree {
        /// bounces of light between the points (0: the direct light, coded)
        pub bounces: u32 = 1, range = 0..=8, unit = "bounces";
        /// microbuffer side (a power of two: the BRDF's Haar grid)
        pub resolution: usize = 16, range = 2..=64, unit = "px";
        /// largest solid angle of a rasterised node, in microbuffer pixels
        pub threshold: f32 = 1.0, range = 0.01..=100.0, unit = "pixels";
        /// largest solid angle of a receiver group seen from its sender ([P]: 0.005)
        pub view_threshold: f32 = 0.005, range = 0.0..=12.6, unit = "sr";
        /// widest normal cone of a group whose points share one buffer
        pub reuse_angle: f32 = 5.0, range = 0.0..=90.0, unit = "°";
        /// drop BRDF wavelet coefficients below this (the product's own approximation)
        pub brdf_threshold: f32 = 0.001, range = 0.0..=10.0;
        /// drop point and tree coefficients below this ([P]: 0.002)
        pub wavelet_threshold: f32 = 0.002, range = 0.0..=10.0;
        /// split level ε of the coding (`WaveletTree`'s)
        pub split: u32 = 20, range = 0..=64, unit = "levels";
        /// most coefficients kept per point
        pub max_terms: usize = 4096, range = 1..=98304, unit = "terms/point";
        /// the view tree, or each point on its own
        pub walk: Walk = ViewTree;
    }
}

/// What a point reflects with: Lambert's constant, the BRDF's wavelets, a smooth
/// dielectric's two lobes read from a spherical buffer, or nothing.
enum Reflector {
    None,
    Lambert(Vec3),
    Glossy(usize),
    Interface,
}

impl ViewTree {
    fn cap(&self, side: usize) -> usize {
        self.max_terms.min(6 * side * side)
    }

    /// The distinct glossy materials' BRDF wavelets and each point's reflector.
    fn reflectors(&self, pts: &SurfacePoints, side: usize) -> (Vec<(Material, BrdfWavelets)>, Vec<Reflector>) {
        let mut glossy: Vec<Material> = vec![];
        let per_point = pts
            .material
            .iter()
            .map(|m| match *m {
                Material::Dielectric { .. } => Reflector::Interface,
                _ if brdf::is_delta(m) || brdf::albedo_hint(m) == Vec3::ZERO => Reflector::None,
                Material::Lambert { albedo } => Reflector::Lambert(albedo),
                _ => Reflector::Glossy(glossy.iter().position(|g| g == m).unwrap_or_else(|| {
                    glossy.push(*m);
                    glossy.len() - 1
                })),
            })
            .collect();
        // The grid resolves the lobes the map can hold (`band_limited`), no narrower.
        let n = self.resolution.min(side.max(2));
        let brdfs = glossy.iter().map(|m| (*m, BrdfWavelets::new(&band_limited(m, n), self.resolution, self.brdf_threshold))).collect();
        (brdfs, per_point)
    }

    /// What point `p` sends after reflecting the light in `mb` (in `frame`): J = L_o cos on
    /// a side-`side` map, through the Haar transform, plus what it sends of the direct light.
    #[allow(clippy::too_many_arguments)]
    fn reflect(
        &self,
        how: &Reflector,
        brdfs: &[(Material, BrdfWavelets)],
        normal: Vec3,
        mb: &Microbuffer,
        frame: &Frame,
        side: usize,
        direct: SparseCubeHaar,
    ) -> (SparseCubeHaar, bool) {
        let map = match *how {
            // Interfaces gather on their own (`interfaces`), everything else sends nothing.
            Reflector::None | Reflector::Interface => return (direct, false),
            Reflector::Lambert(albedo) => {
                let own = Frame::from_normal(normal);
                let lo = mb.convolve_in(&Material::Lambert { albedo }, normal, frame, &own);
                let mut map = CubeMap::constant(side, Vec3::ZERO);
                for (t, d) in map.texels.iter_mut().zip(texel_directions(side).iter()) {
                    *t = lo * d.dot(normal).max(0.0);
                }
                map
            }
            Reflector::Glossy(k) => {
                let (m, b) = &brdfs[k];
                let mut map = to_cube(&b.outgoing(mb.radiance()), b.n, frame, side);
                let irradiance = mb.radiance().iter().sum::<Vec3>() * mb.pixel_weight();
                cap_exitance(&mut map, m, irradiance);
                map
            }
        };
        let reflected = CubeHaar::forward(&map).keep_above(self.wavelet_threshold);
        direct.sum(&reflected).limit(self.cap(side))
    }

    /// What the points on smooth dielectrics (`glass`) send after this bounce: each gathers
    /// the whole sphere around it on its own (`spherical_microbuffer`, the per-receiver
    /// traversal: the view tree's pairs cull by the horizon) and sends toward every texel on
    /// its front the light its two lobes read there (reflected from its front, refracted from
    /// behind) times the cosine, plus what it sends of the direct light.
    #[allow(clippy::too_many_arguments)]
    fn interfaces(
        &self,
        glass: &[usize],
        t: &Traversal<WaveletSource>,
        pts: &SurfacePoints,
        direct: &PointWavelets,
        side: usize,
        cx: &RunCtx,
    ) -> Result<(Vec<(SparseCubeHaar, bool)>, WalkCounts), NodeError> {
        let results = cx.par_map_init(
            glass.len(),
            || (SphericalMicrobuffer::new(self.resolution), Vec::new()),
            |(mb, stack), k| {
                let p = glass[k];
                let (m, normal) = (&pts.material[p], pts.normal[p]);
                let frame = Frame::from_normal(normal);
                let mut c = GatherCounts::default();
                mb.begin(m, Vec3::Z);
                mb.gather(t, m, pts.position[p], &frame, stack, &mut c);
                let mut map = CubeMap::constant(side, Vec3::ZERO);
                for (tex, d) in map.texels.iter_mut().zip(texel_directions(side).iter()) {
                    let cos = d.dot(normal);
                    if cos > 0.0 {
                        *tex = mb.outgoing(m, frame.to_local(*d)) * cos;
                    }
                }
                let sent = CubeHaar::forward(&map).keep_above(self.wavelet_threshold);
                let counts = WalkCounts { pairs: c.visited, rasterised: c.rasterised, near: c.near_leaves, ..Default::default() };
                (direct.sparse(p).sum(&sent).limit(self.cap(side)), counts)
            },
        )?;
        let mut total = WalkCounts::default();
        let out = results
            .into_iter()
            .map(|(w, c)| {
                total += c;
                w
            })
            .collect();
        Ok((out, total))
    }
}

#[node(category = "pbgi", version = 10, metrics = ["bounces", "pairs_per_point", "nodes_rasterised_per_point", "near_leaves_per_point", "group_buffers", "points_reusing_a_group_buffer", "coded_bytes", "terms_per_point", "walk_seconds"], outputs = [coded, stats])]
impl ViewTree {
    fn run(
        &self,
        tree: &PointTree,
        points: &SurfacePoints,
        wavelets: &PointWavelets,
        cx: &RunCtx,
    ) -> Result<(CodedWavelets, Metrics), NodeError> {
        let (pts, direct) = (points, wavelets);
        let leaves = tree.nodes.iter().filter(|t| t.is_leaf()).count();
        if leaves != pts.len() || tree.nodes.iter().any(|t| t.is_leaf() && t.point as usize >= pts.len()) {
            return Err(NodeError::input("points", format!("{} points for a tree of {leaves} points", pts.len())));
        }
        if direct.len() != pts.len() {
            return Err(NodeError::input("wavelets", format!("{} points' wavelets for {} points", direct.len(), pts.len())));
        }
        if !self.resolution.is_power_of_two() {
            return Err(NodeError::param(
                "resolution",
                format!("{} is not a power of two (the BRDF's Haar grid halves it)", self.resolution),
            ));
        }
        let side = direct.n as usize;
        // Each bounce holds the points' old and new maps, the coded tree and one BRDF grid.
        let maps = 2 * pts.len() as u64 * self.cap(side) as u64 * PointWavelets::BYTES_PER_TERM as u64;
        let need = maps + CodedWavelets::bound(tree, direct) + BrdfWavelets::working_bytes(self.resolution);
        if need > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "a bounce could hold up to {} ({} points of up to {} terms, the coded tree, the BRDF grid), over the {} budget: lower max_terms or the wavelets' resolution",
                fmt_bytes(need),
                pts.len(),
                self.cap(side),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let threshold = Threshold::Coefficient(self.wavelet_threshold);
        let mut coded = CodedWavelets { n: direct.n, tree: code_tree(tree, direct, self.split, threshold) };
        let (brdfs, how) = self.reflectors(pts, side);
        let glass: Vec<usize> = (0..pts.len()).filter(|&p| matches!(how[p], Reflector::Interface)).collect();
        let mut total = WalkCounts::default();
        let mut capped = 0usize;
        let mut walk_seconds = 0.0;
        let mut terms_per_point = direct.index.len() as f64 / pts.len().max(1) as f64;
        for _ in 0..self.bounces {
            cx.check()?;
            let source = WaveletSource::new(tree, &coded);
            let walk = ViewWalk {
                tree,
                source: &source,
                resolution: self.resolution,
                threshold: self.threshold,
                view_omega: self.view_threshold,
                reuse_cos: self.reuse_angle.to_radians().cos(),
                eps: 1e-5 * tree_extent(tree),
            };
            let done = |p: u32, mb: &Microbuffer, frame: &Frame| {
                let p = p as usize;
                self.reflect(&how[p], &brdfs, pts.normal[p], mb, frame, side, direct.sparse(p))
            };
            let start = std::time::Instant::now();
            // Points on glass gather on their own (`interfaces`): the walks leave them out.
            let serves = |p: u32| !matches!(how[p as usize], Reflector::Interface);
            let (out, counts) = match self.walk {
                Walk::ViewTree => walk.run_serving(cx, &serves, &done)?,
                Walk::PerReceiver => walk.run_per_receiver_serving(cx, &serves, &done)?,
            };
            walk_seconds += start.elapsed().as_secs_f64();
            let mut per_point = vec![SparseCubeHaar { n: side, index: vec![], value: vec![] }; pts.len()];
            for (p, (w, cut)) in out {
                capped += usize::from(cut);
                per_point[p as usize] = w;
            }
            if !glass.is_empty() {
                let t = Traversal::with_source(tree, &source, self.threshold, 1e-5 * tree_extent(tree));
                let (sent, counts) = self.interfaces(&glass, &t, pts, direct, side, cx)?;
                for (&p, (w, cut)) in glass.iter().zip(sent) {
                    capped += usize::from(cut);
                    per_point[p] = w;
                }
                total += counts;
            }
            let maps = PointWavelets::from_points(side, &per_point);
            drop(per_point);
            coded = CodedWavelets { n: direct.n, tree: code_tree(tree, &maps, self.split, threshold) };
            total += counts;
            terms_per_point = maps.index.len() as f64 / pts.len().max(1) as f64;
        }
        let per = |x: u64| x as f64 / (pts.len().max(1) as f64 * self.bounces.max(1) as f64);
        let m = Metrics(vec![
            ("bounces".into(), self.bounces as f64),
            ("pairs_per_point".into(), per(total.pairs)),
            ("nodes_rasterised_per_point".into(), per(total.rasterised)),
            ("near_leaves_per_point".into(), per(total.near)),
            ("group_buffers".into(), total.group_buffers as f64 / self.bounces.max(1) as f64),
            ("points_reusing_a_group_buffer".into(), total.reused as f64 / self.bounces.max(1) as f64),
            ("coded_bytes".into(), coded.tree.bytes() as f64),
            ("terms_per_point".into(), terms_per_point),
        ]);
        // Time is reported, never tested: the walks (gathering and reflecting), all bounces.
        cx.metric("walk_seconds", walk_seconds);
        for (k, v) in &m.0 {
            cx.metric(k, *v);
        }
        if capped > 0 {
            cx.note(format!("{capped} point maps had more than {} terms and kept the largest", self.cap(side)));
        }
        Ok((coded, m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gather::gather_with;
    use crate::test_support::wpbgi_setup::{exact_one_bounce, setup, Setup};
    use crate::traversal::Traversal;
    use crate::types::Receivers;
    use crate::wavelet_gather::WaveletGather;
    use relume_base::testing::{cancels_midway, first, i, id, run_on};
    use relume_base::types::Image;
    use relume_core::{CancelToken, ParamValue, Value};
    use std::sync::OnceLock;

    fn grey() -> Material {
        Material::Lambert { albedo: Vec3::splat(0.6) }
    }

    /// The corner with a grey wall (computed once).
    fn diffuse() -> &'static Setup {
        static S: OnceLock<Setup> = OnceLock::new();
        S.get_or_init(|| setup(grey()))
    }

    fn inputs(s: &Setup) -> Vec<Value> {
        vec![Value::new(s.tree.clone()), Value::new(s.points.clone()), Value::new(s.wavelets.clone())]
    }

    fn view(s: &Setup, params: &[(&str, ParamValue)]) -> (CodedWavelets, Metrics) {
        let out = run_on::<ViewTree>(params, inputs(s)).unwrap();
        (first(&out), out[1].get::<Metrics>().unwrap().clone())
    }

    /// The mean red of the image a wavelet gather makes of `coded`.
    fn gathered(s: &Setup, coded: CodedWavelets) -> f64 {
        let out =
            run_on::<WaveletGather>(&[], vec![Value::new(s.tree.clone()), Value::new(coded), Value::new(s.receivers.clone())]).unwrap();
        let img: Image = first(&out);
        assert!(img.as_floats().iter().all(|x| x.is_finite() && *x >= 0.0));
        img.pixels.iter().map(|p| p[0] as f64).sum::<f64>() / img.pixels.len() as f64
    }

    #[test]
    fn one_bounce_of_the_view_tree_gathers_what_pbgi_gather_does_on_a_diffuse_scene() {
        // Receivers at the points themselves: PbgiGather over the diffuse tree, and the view
        // tree over the wavelet tree, both reflecting through the points' Lambert BRDF.
        let s = diffuse();
        let n = s.points.len();
        let p = &s.points;
        let r = Receivers {
            width: n,
            height: 1,
            pixel: (0..n as u32).collect(),
            position: p.position.clone(),
            normal: p.normal.clone(),
            wo: p.normal.clone(),
            object: p.object.clone(),
            material: p.material.clone(),
            weight: vec![1.0; n],
            fill: vec![],
        };
        let cancel = CancelToken::new();
        let cx = RunCtx::new("t", &cancel, None);
        let eps = 1e-5 * tree_extent(&s.tree);
        let (pbgi, _) = gather_with(&Traversal::new(&s.tree, 1.0, eps), &r, Microbuffer::new(16), &cx).unwrap();
        let source = WaveletSource::new(&s.tree, &s.coded);
        let reuse_cos = 5f32.to_radians().cos();
        let walk = ViewWalk { tree: &s.tree, source: &source, resolution: 16, threshold: 1.0, view_omega: 0.005, reuse_cos, eps };
        let lambert = |k: u32, mb: &Microbuffer, frame: &Frame| {
            let k = k as usize;
            mb.convolve_in(&p.material[k], p.normal[k], frame, &Frame::from_normal(p.normal[k]))
        };
        let (out, counts) = walk.run(&cx, &lambert).unwrap();
        assert_eq!(out.len(), n);
        let mut view = vec![0.0f64; n];
        out.iter().for_each(|(k, l)| view[*k as usize] = l.x as f64);
        // Per surface (floor, wall) the mean, and over all points the RMS difference.
        for object in [0, 1] {
            let pick = |v: &dyn Fn(usize) -> f64| {
                let ks: Vec<usize> = (0..n).filter(|&k| p.object[k] == object).collect();
                ks.iter().map(|&k| v(k)).sum::<f64>() / ks.len() as f64
            };
            let a = pick(&|k| pbgi.pixels[k][0] as f64);
            let b = pick(&|k| view[k]);
            // Measured: floor 0.015755 against 0.015650, wall 0.022377 against 0.022075. Each
            // point rasterises its nodes in the order its own traversal would (descending
            // index); without group buffers the view tree gives the per-receiver walk's
            // bytes (`view_walk`'s tests), and the microbuffer's depth layers depend on
            // that order (the pairs' order instead cost 3.6 % on the floor, sorted near to
            // far 10 %).
            assert!(a > 0.0 && ((b - a) / a).abs() < 0.015, "object {object}: PbgiGather {a}, view tree {b}");
            // Against the path tracer's expectation (`exact_one_bounce`, on every fourth point
            // of the surface). Measured: the floor 0.33 % over it, the wall 3.7 % under. The
            // wall sees the floor edge-on, so one pixel holds floor splats at depths several
            // times apart; they join one depth layer because they lie on one plane
            // (`microbuffer::Flat`). Split by depth alone, the far ones hid behind the near
            // ones: 1.5 % and 5.6 % under. What is left shrinks with the buffer's resolution.
            let ks: Vec<usize> = (0..n).filter(|&k| p.object[k] == object).step_by(4).collect();
            let mean = |v: &dyn Fn(usize) -> f64| ks.iter().map(|&k| v(k)).sum::<f64>() / ks.len() as f64;
            let exact = mean(&|k| exact_one_bounce(p.position[k], p.normal[k], 200));
            let (view_mean, bound) = (mean(&|k| view[k]), if object == 0 { 0.01 } else { 0.05 });
            assert!(((view_mean - exact) / exact).abs() < bound, "object {object}: view tree {view_mean}, exact {exact}");
        }
        let rms = |v: &dyn Fn(usize) -> f64| ((0..n).map(|k| v(k).powi(2)).sum::<f64>() / n as f64).sqrt();
        let diff = rms(&|k| view[k] - pbgi.pixels[k][0] as f64) / rms(&|k| pbgi.pixels[k][0] as f64);
        assert!(diff < 0.1, "relative RMS difference {diff}");
        assert!(counts.reused > n as u64 / 2, "the flat floor and wall share group buffers: {counts:?}");
    }

    #[test]
    fn no_bounce_codes_the_direct_light_and_each_bounce_adds_less_than_the_one_before() {
        let s = diffuse();
        let (zero, _) = view(s, &[("bounces", i(0))]);
        assert_eq!(format!("{:?}", zero.tree), format!("{:?}", s.coded.tree), "WaveletTree's coding at the same split and threshold");
        let (one, m1) = view(s, &[("bounces", i(1))]);
        let (two, _) = view(s, &[("bounces", i(2))]);
        let (g0, g1, g2) = (gathered(s, zero), gathered(s, one), gathered(s, two));
        assert!(g1 > g0 && g2 > g1, "{g0} {g1} {g2}");
        // Albedo 0.6 and an open corner: each bounce brings less than 0.6 of the one before.
        assert!(g2 - g1 < 0.6 * (g1 - g0), "{g0} {g1} {g2}");
        assert!(m1.get("pairs_per_point").unwrap() > 0.0 && m1.get("nodes_rasterised_per_point").unwrap() > 0.0);
    }

    #[test]
    fn the_view_tree_agrees_with_each_point_gathering_alone_and_decides_fewer_pairs() {
        let s = diffuse();
        let (shared, ms) = view(s, &[]);
        let (alone, ma) = view(s, &[("walk", id("PerReceiver"))]);
        let (a, b) = (gathered(s, alone), gathered(s, shared));
        assert!(((b - a) / a).abs() < 0.02, "per receiver {a}, view tree {b}");
        let pairs = |m: &Metrics| m.get("pairs_per_point").unwrap();
        assert!(pairs(&ms) < pairs(&ma), "view tree {ms:?}, per receiver {ma:?}");
        assert_eq!(ma.get("group_buffers"), Some(0.0));
    }

    #[test]
    fn glossy_walls_send_their_lobes_and_extreme_ones_stay_bounded() {
        // docs/QUALITY.md §2 (BRDF): kd 0.1 + ks 0.5 at s = 60 and at s = 10⁴ (far narrower than
        // a 16² grid resolves); the second bounce of either brings no more than a white
        // Lambert wall's would.
        let white = setup(Material::Lambert { albedo: Vec3::ONE });
        let bound = {
            let (z, _) = view(&white, &[("bounces", i(0))]);
            let (o, _) = view(&white, &[("bounces", i(1))]);
            gathered(&white, o) - gathered(&white, z)
        };
        for s_exp in [60.0, 1e4] {
            let s = setup(Material::BlinnPhong { kd: Vec3::splat(0.1), ks: Vec3::splat(0.5), exponent: s_exp });
            let (z, _) = view(&s, &[("bounces", i(0))]);
            let (o, _) = view(&s, &[("bounces", i(1))]);
            let added = gathered(&s, o) - gathered(&s, z);
            assert!(added > 0.0 && added < bound, "s = {s_exp}: the bounce adds {added}, a white wall's {bound}");
        }
    }

    #[test]
    fn the_same_bytes_on_one_and_four_threads() {
        let s = diffuse();
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| format!("{:?}", view(s, &[("bounces", i(1))]).0.tree))
        };
        assert!(run(1) == run(4));
    }

    #[test]
    fn wrong_inputs_and_budgets_are_refused_and_a_run_can_be_cancelled() {
        let s = diffuse();
        let mut fewer = inputs(s);
        let mut pts = s.points.clone();
        pts.position.pop();
        fewer[1] = Value::new(pts);
        let e = run_on::<ViewTree>(&[], fewer).unwrap_err();
        assert!(e.to_string().contains("points for a tree of"), "{e}");
        let e = run_on::<ViewTree>(&[("resolution", i(12))], inputs(s)).unwrap_err();
        assert!(e.to_string().contains("power of two"), "{e}");
        let cancel = CancelToken::new();
        let cx = RunCtx::new("t", &cancel, None).with_memory_budget(1 << 20);
        let node = ViewTree {
            bounces: 1,
            resolution: 16,
            threshold: 1.0,
            view_threshold: 0.005,
            reuse_angle: 5.0,
            brdf_threshold: 1e-3,
            wavelet_threshold: 2e-3,
            split: 20,
            max_terms: 4096,
            walk: Walk::ViewTree,
        };
        let e = node.run_ports(&s.tree, &s.points, &s.wavelets, &cx).err().unwrap();
        assert!(e.is_over_limit() && e.to_string().contains("budget"), "{e}");
        cancels_midway::<ViewTree>(&[], inputs(s));
    }
}
