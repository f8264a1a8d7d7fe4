//! ClusterReceivers node (FPBGI receiver clustering, docs/PIPELINES.md pipeline 4 step 6; [P] 3.3.2).

use crate::types::Receivers;
use glam::{DVec3, Vec3};
use relume_base::math::kmeans::{KMeans, Metric};
use relume_base::math::rng::mix64;
use relume_base::types::{Cluster, Clusters};
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// Groups the receivers into clusters of similar position and normal, for the factorized
    /// gather ([P] 3.3.2). The image is cut into `tile` × `tile` pixel tiles and each tile's
    /// receivers are clustered on their own by k-means (k-means++ seeding where [P] picks random
    /// receivers, at most `iterations` Lloyd iterations, a random stream per tile from `seed`)
    /// with D = ‖p_c − p_x‖² + α‖n_c − n_x‖², α = the diagonal of the bounding box of the tile's
    /// receiver positions, as the spec and [P] set it. α is a length and the position term a
    /// squared length, so D is not scale-invariant: normals weigh more in small scenes (see
    /// `PositionNormal`). A cluster's centre is the mean position and the normalised summed
    /// normal of its members. A tile with no more receivers than k gets one cluster per
    /// receiver; no cluster is ever empty. The active receiver of a cluster is its member
    /// closest (by D) to the final centre. Same inputs and seed give the same clusters on any
    /// thread count.
    pub struct ClusterReceivers {
        /// side of the square image tiles clustered independently
        pub tile: usize = 32, range = 1..=1024, unit = "px";
        /// clusters per tile (a tile with fewer receivers gets one per receiver)
        pub k: usize = 100, range = 1..=4096, unit = "clusters";
        /// most k-means (Lloyd) iterations per tile; a tile stops earlier once nothing moves
        pub iterations: usize = 10, range = 1..=1000;
        /// random seed of the k-means++ seeding
        pub seed: u64 = 0, range = 0..=u32::MAX;
    }
}

/// A receiver (or a cluster centre) as k-means sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Oriented {
    pub position: Vec3,
    pub normal: Vec3,
}

/// [P]'s position/normal metric D(c, x) = ‖p_c − p_x‖² + α‖n_c − n_x‖².
///
/// Units: the position term is a squared length, while α (a length: [P] and the spec set it to
/// the tile's bounding-box diagonal) times the unitless ‖n_c − n_x‖² is a length, so D is not
/// homogeneous: scaling a scene by s scales the position term by s² but the normal term by s,
/// and normals weigh relatively more in small scenes (diagonal < 1) than in large ones. We
/// follow the spec as written; α = diagonal² would make the clustering scale-invariant.
///
/// The centre update ([P]: mean position, normalised summed normal) minimises the members'
/// summed D for unit normals, so k-means' objective never increases. A normal sum of (nearly)
/// zero length keeps the previous centre normal (any unit normal is then as good).
#[derive(Clone, Copy, Debug)]
pub struct PositionNormal {
    pub alpha: f32,
}

impl Metric<Oriented> for PositionNormal {
    type Center = Oriented;
    fn center_at(&self, p: &Oriented) -> Oriented {
        *p
    }
    fn distance(&self, c: &Oriented, x: &Oriented) -> f32 {
        c.position.distance_squared(x.position) + self.alpha * c.normal.distance_squared(x.normal)
    }
    fn mean(&self, points: &[Oriented], members: &[u32], previous: &Oriented) -> Oriented {
        let (mut p, mut n) = (DVec3::ZERO, DVec3::ZERO);
        for &i in members {
            p += points[i as usize].position.as_dvec3();
            n += points[i as usize].normal.as_dvec3();
        }
        let len = n.length();
        let normal = if len > 1e-9 * members.len() as f64 { (n / len).as_vec3() } else { previous.normal };
        Oriented { position: (p / members.len() as f64).as_vec3(), normal }
    }
}

/// What the clustering did, for metrics and notes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClusterStats {
    /// Tiles holding at least one receiver.
    pub tiles: usize,
    /// Of those, tiles with fewer receivers than k (one cluster per receiver there).
    pub tiles_below_k: usize,
    /// Tiles whose k-means hit the iteration limit before converging.
    pub tiles_unconverged: usize,
    /// Most Lloyd iterations any tile ran.
    pub max_iterations_used: usize,
}

struct TileResult {
    clusters: Vec<Cluster>,
    iterations: usize,
    converged: bool,
    below_k: bool,
}

fn check_receivers(rx: &Receivers) -> Result<(), NodeError> {
    let n = rx.len();
    if rx.position.len() != n || rx.normal.len() != n {
        return Err(NodeError::input(
            "receivers",
            format!("{n} pixels but {} positions and {} normals", rx.position.len(), rx.normal.len()),
        ));
    }
    let pixels = rx.width as u64 * rx.height as u64;
    for i in 0..n {
        if rx.pixel[i] as u64 >= pixels {
            return Err(NodeError::input(
                "receivers",
                format!("receiver {i} has pixel {} outside the {}×{} image", rx.pixel[i], rx.width, rx.height),
            ));
        }
        if !rx.position[i].is_finite() || !rx.normal[i].is_finite() {
            return Err(NodeError::input("receivers", format!("receiver {i} has a non-finite position or normal")));
        }
    }
    Ok(())
}

/// Clusters one tile's receivers (`members`: receiver indices, ascending).
fn cluster_tile(rx: &Receivers, tile: u32, members: &[u32], p: &ClusterReceivers) -> TileResult {
    let points: Vec<Oriented> =
        members.iter().map(|&i| Oriented { position: rx.position[i as usize], normal: rx.normal[i as usize] }).collect();
    let (lo, hi) = points.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), x| (lo.min(x.position), hi.max(x.position)));
    let metric = PositionNormal { alpha: (hi - lo).length() };
    // Each tile has its own random stream, so its result does not depend on the others.
    let seed = mix64(mix64(p.seed) ^ tile as u64);
    let result = KMeans { k: p.k, max_iterations: p.iterations, seed }.run(&points, &metric);
    let clusters = result
        .members()
        .into_iter()
        .zip(&result.centers)
        .map(|(local, centre)| {
            let mut active = local[0];
            let mut best = f32::INFINITY;
            let mut radius = 0f32;
            for &j in &local {
                let x = &points[j as usize];
                let d = metric.distance(centre, x);
                if d < best {
                    best = d;
                    active = j;
                }
                radius = radius.max(x.position.distance(centre.position));
            }
            Cluster {
                tile,
                active: members[active as usize],
                members: local.iter().map(|&j| members[j as usize]).collect(),
                center: centre.position,
                normal: centre.normal,
                radius,
            }
        })
        .collect();
    TileResult { clusters, iterations: result.iterations, converged: result.converged, below_k: members.len() < p.k }
}

/// Clusters the receivers tile by tile (tiles in parallel; the result does not depend on the
/// thread count), with progress and cancellation through `cx`.
pub fn cluster_receivers(rx: &Receivers, p: &ClusterReceivers, cx: &RunCtx) -> Result<(Clusters, ClusterStats), NodeError> {
    check_receivers(rx)?;
    let t = p.tile.max(1);
    let tiles_x = rx.width.div_ceil(t);
    let tiles_y = rx.height.div_ceil(t);
    let mut by_tile: Vec<Vec<u32>> = vec![Vec::new(); tiles_x * tiles_y];
    for (i, &px) in rx.pixel.iter().enumerate() {
        let (x, y) = (px as usize % rx.width, px as usize / rx.width);
        by_tile[(y / t) * tiles_x + x / t].push(i as u32);
    }
    let occupied: Vec<(u32, Vec<u32>)> =
        by_tile.into_iter().enumerate().filter(|(_, m)| !m.is_empty()).map(|(i, m)| (i as u32, m)).collect();
    let results: Vec<TileResult> = cx.par_map(occupied.len(), |k| cluster_tile(rx, occupied[k].0, &occupied[k].1, p))?;
    let mut stats = ClusterStats { tiles: results.len(), ..Default::default() };
    let mut out = Clusters { tile: t, clusters: Vec::new(), of_receiver: vec![u32::MAX; rx.len()] };
    for r in results {
        stats.tiles_below_k += r.below_k as usize;
        stats.tiles_unconverged += !r.converged as usize;
        stats.max_iterations_used = stats.max_iterations_used.max(r.iterations);
        for c in r.clusters {
            for &m in &c.members {
                out.of_receiver[m as usize] = out.clusters.len() as u32;
            }
            out.clusters.push(c);
        }
    }
    Ok((out, stats))
}

#[node(category = "pbgi", metrics = ["clusters", "tiles", "mean_cluster_size", "max_iterations_used"], outputs = [clusters])]
impl ClusterReceivers {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The clusters (at most one a receiver, and k a tile), each receiver's cluster and its
        // place among a cluster's members; while it runs, the tiles' lists of receivers and one
        // tile's k-means points a thread.
        let Some(s) = inputs[0] else { return relume_core::MemoryEstimate::unknown(1) };
        let n = s.bytes / Receivers::BYTES_PER_RECEIVER as u64;
        let tiles = s.dims.map_or(n, |[w, h]| (w.div_ceil(self.tile) * h.div_ceil(self.tile)) as u64);
        let clusters = n.min(tiles * self.k as u64);
        let bytes = clusters * std::mem::size_of::<Cluster>() as u64 + n * 12;
        let working = n * 4 + tiles * std::mem::size_of::<Vec<u32>>() as u64 + (self.tile * self.tile) as u64 * 64;
        relume_core::MemoryEstimate { outputs: vec![Some(relume_core::PortSize::bytes(bytes))], working }
    }

    fn run(&self, receivers: &Receivers, cx: &RunCtx) -> Result<Clusters, NodeError> {
        let rx = receivers;
        let (clusters, stats) = cluster_receivers(rx, self, cx)?;
        let n = clusters.clusters.len();
        cx.metric("clusters", n as f64);
        cx.metric("tiles", stats.tiles as f64);
        cx.metric("mean_cluster_size", if n == 0 { 0.0 } else { rx.len() as f64 / n as f64 });
        cx.metric("max_iterations_used", stats.max_iterations_used as f64);
        if rx.is_empty() {
            cx.note("no receivers: there is nothing to cluster");
        }
        if stats.tiles_below_k > 0 {
            cx.note(format!(
                "{} of {} tiles had fewer receivers than k = {}: one cluster per receiver there",
                stats.tiles_below_k, stats.tiles, self.k
            ));
        }
        if stats.tiles_unconverged > 0 {
            cx.note(format!(
                "k-means stopped at the {}-iteration limit before converging in {} of {} tiles",
                self.iterations, stats.tiles_unconverged, stats.tiles
            ));
        }
        Ok(clusters)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use relume_base::math::rng::uniform;
    use relume_base::testing::{cancels_midway, first, i, run_full};
    use relume_base::types::Material;
    use relume_core::{CancelToken, PortValue, Value};
    use std::path::Path;

    /// `cluster_receivers` outside a run (never cancelled).
    fn cluster(rx: &Receivers, p: &ClusterReceivers) -> Result<(Clusters, ClusterStats), NodeError> {
        let cancel = CancelToken::new();
        cluster_receivers(rx, p, &RunCtx::new("t", &cancel, None))
    }

    /// Receivers at the given pixels of a `width` × `height` image, with the given positions and
    /// normals (view direction = normal).
    fn receivers(width: usize, height: usize, pixel: Vec<u32>, position: Vec<Vec3>, normal: Vec<Vec3>) -> Receivers {
        let n = pixel.len();
        Receivers {
            width,
            height,
            pixel,
            position,
            wo: normal.clone(),
            normal,
            object: vec![0; n],
            material: vec![Material::Lambert { albedo: Vec3::splat(0.5) }; n],
            weight: vec![1.0; n],
            fill: vec![],
        }
    }

    /// A receiver at each pixel kept with probability `density`; `mode` 0: random positions and
    /// normals, 1: positions and normals snapped to a coarse grid (many duplicates), 2: all
    /// receivers identical.
    fn random_receivers(width: usize, height: usize, density: f32, mode: u8, seed: u64) -> Receivers {
        let (mut pixel, mut position, mut normal) = (Vec::new(), Vec::new(), Vec::new());
        for px in 0..(width * height) as u64 {
            if uniform(seed, px, 0) >= density {
                continue;
            }
            let u = |d: u32| uniform(seed, px, d);
            let mut p = Vec3::new(u(1), u(2), u(3)) * 4.0 - 2.0;
            let mut n = (Vec3::new(u(4), u(5), u(6)) * 2.0 - 1.0).try_normalize().unwrap_or(Vec3::Z);
            if mode == 1 {
                p = p.round();
                n = n.round().try_normalize().unwrap_or(Vec3::Y);
            } else if mode == 2 {
                p = Vec3::new(0.5, -1.0, 2.0);
                n = Vec3::Y;
            }
            pixel.push(px as u32);
            position.push(p);
            normal.push(n);
        }
        receivers(width, height, pixel, position, normal)
    }

    #[test]
    fn the_memory_estimate_bounds_the_clusters_from_the_receivers_size_alone() {
        use relume_core::{Node, PortSize};
        for (w, h, density, tile, k) in [(64, 48, 0.9, 16, 20), (40, 40, 0.3, 8, 100), (33, 17, 1.0, 32, 1)] {
            let rx = random_receivers(w, h, density, 0, 7);
            let p = params(tile, k, 10, 1);
            let e = p.memory(&[Some(PortSize { bytes: rx.byte_size() as u64, dims: Some([w, h]) })]);
            let (c, _) = cluster(&rx, &p).unwrap();
            let members: usize = c.clusters.iter().map(|cl| cl.members.len() * 4).sum();
            let held = (c.byte_size() + members) as u64;
            let out = e.outputs[0].expect("known from the receivers' size").bytes;
            assert!(out >= held && out <= 4 * held.max(1), "{w}×{h}: estimate {out}, held {held}");
            assert!(e.working > 0);
        }
        assert_eq!(params(32, 100, 10, 0).memory(&[None]).outputs, vec![None], "unknown without the receivers' size");
    }

    fn params(tile: usize, k: usize, iterations: usize, seed: u64) -> ClusterReceivers {
        ClusterReceivers { tile, k, iterations, seed }
    }

    fn tile_of(rx: &Receivers, r: u32, tile: usize) -> u32 {
        let px = rx.pixel[r as usize] as usize;
        ((px / rx.width / tile) * rx.width.div_ceil(tile) + (px % rx.width) / tile) as u32
    }

    /// Every structural promise of `Clusters`, asserted.
    fn check_invariants(rx: &Receivers, c: &Clusters, p: &ClusterReceivers) {
        assert_eq!(c.tile, p.tile);
        assert_eq!(c.of_receiver.len(), rx.len());
        let mut seen = vec![0u32; rx.len()];
        let mut per_tile: std::collections::BTreeMap<u32, (usize, usize)> = Default::default();
        for (ci, cl) in c.clusters.iter().enumerate() {
            assert!(!cl.members.is_empty(), "cluster {ci} is empty");
            assert!(cl.members.windows(2).all(|w| w[0] < w[1]), "members ascending");
            assert!(cl.members.contains(&cl.active), "cluster {ci}: active receiver {} is not a member", cl.active);
            for &m in &cl.members {
                seen[m as usize] += 1;
                assert_eq!(c.of_receiver[m as usize], ci as u32, "of_receiver disagrees with members for receiver {m}");
                assert_eq!(tile_of(rx, m, p.tile), cl.tile, "receiver {m} lies outside its cluster's tile");
                assert!(rx.position[m as usize].distance(cl.center) <= cl.radius * (1.0 + 1e-5) + 1e-5);
            }
            assert!((cl.normal.length() - 1.0).abs() < 1e-4, "centre normal {}", cl.normal);
            per_tile.entry(cl.tile).or_default().0 += 1;
        }
        assert!(seen.iter().all(|&s| s == 1), "every receiver in exactly one cluster");
        assert!(c.clusters.windows(2).all(|w| w[0].tile <= w[1].tile), "clusters in tile order");
        for r in 0..rx.len() as u32 {
            per_tile.entry(tile_of(rx, r, p.tile)).or_default().1 += 1;
        }
        for (t, (clusters, receivers)) in per_tile {
            if receivers < p.k {
                assert_eq!(clusters, receivers, "tile {t}: {receivers} receivers < k = {}: one cluster per receiver", p.k);
            } else {
                assert_eq!(clusters, p.k, "tile {t}: {receivers} receivers ≥ k = {}: exactly k clusters", p.k);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

        #[test]
        fn clusters_partition_the_receivers_within_tiles_with_no_empty_cluster(
            width in 1usize..=100, height in 1usize..=100, density in 0.0f32..=1.0, mode in 0u8..3,
            tile in 1usize..=48, k in 1usize..=64, iterations in 1usize..=12, seed in 0u64..1000, data in 0u64..1000,
        ) {
            let rx = random_receivers(width, height, density, mode, data);
            let p = params(tile, k, iterations, seed);
            let (c, stats) = cluster(&rx, &p).unwrap();
            check_invariants(&rx, &c, &p);
            prop_assert!(stats.max_iterations_used <= iterations);
        }
    }

    #[test]
    fn the_active_receiver_is_the_member_closest_to_the_centre_by_d() {
        let rx = random_receivers(64, 64, 0.8, 0, 11);
        let p = params(16, 20, 10, 3);
        let (c, _) = cluster(&rx, &p).unwrap();
        check_invariants(&rx, &c, &p);
        for cl in &c.clusters {
            let tile_members: Vec<u32> = (0..rx.len() as u32).filter(|&r| tile_of(&rx, r, 16) == cl.tile).collect();
            let (lo, hi) = tile_members.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &r| {
                (lo.min(rx.position[r as usize]), hi.max(rx.position[r as usize]))
            });
            let alpha = (hi - lo).length();
            let d =
                |r: u32| cl.center.distance_squared(rx.position[r as usize]) + alpha * cl.normal.distance_squared(rx.normal[r as usize]);
            let best = cl.members.iter().map(|&m| d(m)).fold(f32::INFINITY, f32::min);
            assert_eq!(d(cl.active), best);
        }
    }

    #[test]
    fn clusters_separate_two_walls_by_their_normals() {
        // Two perpendicular walls meeting in a corner, seen through one 8 × 8 tile: left half on
        // the wall x = 0 (normal +x), right half on the floor y = 0 (normal +y), positions close
        // together near the corner. k = 2 must split them by normal.
        let (mut pixel, mut position, mut normal) = (Vec::new(), Vec::new(), Vec::new());
        for y in 0..8u32 {
            for x in 0..8u32 {
                pixel.push(y * 8 + x);
                let (s, t) = (x as f32 * 0.01, y as f32 * 0.01);
                if x < 4 {
                    position.push(Vec3::new(0.0, 0.04 - s, t));
                    normal.push(Vec3::X);
                } else {
                    position.push(Vec3::new(s - 0.04, 0.0, t));
                    normal.push(Vec3::Y);
                }
            }
        }
        let rx = receivers(8, 8, pixel, position, normal);
        for seed in 0..10 {
            let (c, _) = cluster(&rx, &params(8, 2, 20, seed)).unwrap();
            assert_eq!(c.clusters.len(), 2);
            for cl in &c.clusters {
                let wall = cl.members[0] % 8 < 4;
                assert!(cl.members.iter().all(|&m| (m % 8 < 4) == wall), "seed {seed}: a cluster mixes the walls");
                assert!(cl.normal.dot(if wall { Vec3::X } else { Vec3::Y }) > 0.999);
            }
        }
    }

    #[test]
    fn coincident_receivers_in_a_tile_still_give_k_clusters() {
        let rx = random_receivers(20, 20, 1.0, 2, 0);
        let p = params(20, 7, 10, 1);
        let (c, stats) = cluster(&rx, &p).unwrap();
        check_invariants(&rx, &c, &p);
        assert_eq!(c.clusters.len(), 7);
        assert!(c.clusters.iter().all(|cl| cl.radius == 0.0 && cl.center == rx.position[0] && cl.normal == Vec3::Y));
        assert_eq!(stats.tiles_unconverged, 0);
    }

    #[test]
    fn a_tile_with_one_receiver_gets_one_cluster_around_it() {
        let rx = receivers(4, 4, vec![5], vec![Vec3::new(1.0, 2.0, 3.0)], vec![Vec3::Z]);
        let (c, stats) = cluster(&rx, &params(32, 100, 10, 0)).unwrap();
        assert_eq!(
            c.clusters,
            vec![Cluster { tile: 0, active: 0, members: vec![0], center: Vec3::new(1.0, 2.0, 3.0), normal: Vec3::Z, radius: 0.0 }]
        );
        assert_eq!(c.of_receiver, vec![0]);
        assert_eq!(stats, ClusterStats { tiles: 1, tiles_below_k: 1, tiles_unconverged: 0, max_iterations_used: 0 });
    }

    #[test]
    fn k_of_one_makes_one_cluster_per_occupied_tile() {
        let rx = random_receivers(50, 30, 0.7, 0, 5);
        let p = params(16, 1, 10, 0);
        let (c, stats) = cluster(&rx, &p).unwrap();
        check_invariants(&rx, &c, &p);
        assert_eq!(c.clusters.len(), 4 * 2);
        assert_eq!(stats.tiles, 8);
        for cl in &c.clusters {
            let mean = cl.members.iter().map(|&m| rx.position[m as usize]).sum::<Vec3>() / cl.members.len() as f32;
            assert!(cl.center.distance(mean) < 1e-5);
            let far = cl.members.iter().map(|&m| rx.position[m as usize].distance(cl.center)).fold(0.0, f32::max);
            assert_eq!(cl.radius, far);
        }
    }

    #[test]
    fn empty_receivers_give_no_clusters() {
        let rx = receivers(10, 10, vec![], vec![], vec![]);
        let (c, stats) = cluster(&rx, &params(4, 5, 10, 0)).unwrap();
        assert!(c.clusters.is_empty() && c.of_receiver.is_empty());
        assert_eq!(stats.tiles, 0);
    }

    #[test]
    fn cluster_results_are_the_same_bytes_on_one_and_four_threads() {
        let rx = random_receivers(96, 80, 0.9, 0, 2);
        let p = params(16, 30, 10, 7);
        let run = |threads| rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| cluster(&rx, &p).unwrap().0);
        let (a, b) = (run(1), run(4));
        assert_eq!(a.fingerprint(), b.fingerprint());
        assert_eq!(a, b);
        let other = cluster(&rx, &params(16, 30, 10, 8)).unwrap().0;
        assert_ne!(a.fingerprint(), other.fingerprint(), "the seed reaches the result");
    }

    #[test]
    fn malformed_receivers_are_refused_with_the_reason() {
        let bad_pixel = receivers(4, 4, vec![16], vec![Vec3::ZERO], vec![Vec3::Z]);
        let e = cluster(&bad_pixel, &params(4, 2, 10, 0)).unwrap_err();
        assert!(e.to_string().contains("outside"), "{e}");
        let nan = receivers(4, 4, vec![1], vec![Vec3::NAN], vec![Vec3::Z]);
        let e = cluster(&nan, &params(4, 2, 10, 0)).unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");
    }

    #[test]
    fn the_cluster_node_reports_metrics_and_notes_small_tiles() {
        // 40 × 40 image, tile 32: one full tile of 1024 receivers and three partial ones (256,
        // 256 and 64 receivers); k = 100 leaves the 64-receiver corner tile below k.
        let rx = random_receivers(40, 40, 1.0, 0, 9);
        let e = run_full::<ClusterReceivers>(&[("k", i(100)), ("iterations", i(5))], Path::new("."), vec![Value::new(rx.clone())]).unwrap();
        let c: Clusters = first(&e.outputs);
        check_invariants(&rx, &c, &params(32, 100, 5, 0));
        let m = |name: &str| e.metrics.iter().find(|(n, _)| n == name).map(|(_, v)| *v).unwrap();
        assert_eq!(m("clusters"), 364.0);
        assert_eq!(m("tiles"), 4.0);
        assert!((m("mean_cluster_size") - 1600.0 / 364.0).abs() < 1e-12);
        assert!((1.0..=5.0).contains(&m("max_iterations_used")));
        assert!(e.notes.iter().any(|n| n.contains("1 of 4 tiles had fewer receivers than k = 100")), "{:?}", e.notes);
    }

    #[test]
    fn the_cluster_node_stops_when_cancelled() {
        // 128 × 128 receivers in 16 × 16 tiles: 64 tiles to cancel between.
        let rx = random_receivers(128, 128, 1.0, 0, 4);
        cancels_midway::<ClusterReceivers>(&[("tile", i(16)), ("k", i(8))], vec![Value::new(rx)]);
    }
}
