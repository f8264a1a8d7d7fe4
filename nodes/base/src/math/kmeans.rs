//! Seeded, deterministic k-means (Lloyd's iterations with k-means++ seeding) over any point
//! type, with the distance and the mean given by the caller through [`Metric`].
//!
//! Randomness comes only from `rng::uniform(seed, draw, 0)`, and every loop runs in index order,
//! so a result depends on nothing but the points, `k`, the iteration limit and the seed.
//!
//! One iteration is: assign every point to its closest centre (a point already assigned keeps
//! its cluster on a tie; on the first iteration ties go to the lowest centre index), refill each
//! empty cluster, then move every centre to the mean of its members. Empty clusters are refilled
//! by taking, from the clusters with two or more members, the point farthest from its centre and
//! making it a cluster of its own (its centre placed on it), so with n ≥ k points no cluster is
//! ever empty. When the metric's mean minimises the summed distance of the members (as the
//! arithmetic mean does for squared Euclidean distance), every step lowers or keeps the
//! objective Σ D(centre, point), so the objective never increases across iterations (up to
//! float rounding). The loop stops when an iteration changes no assignment (converged) or after
//! `max_iterations`.

use super::rng::uniform;
use glam::{DVec3, Vec3};

/// Distance and centre computation for k-means over points of type `P`.
pub trait Metric<P> {
    type Center: Clone;
    /// A centre standing exactly on `p`: `distance(&center_at(p), p)` should be 0.
    fn center_at(&self, p: &P) -> Self::Center;
    /// The dissimilarity of `p` from centre `c` (≥ 0, finite).
    fn distance(&self, c: &Self::Center, p: &P) -> f32;
    /// The centre of the (non-empty) `members` (indices into `points`): ideally the centre that
    /// minimises the members' summed distance. `previous` is the cluster's last centre, for
    /// degenerate cases (e.g. normals that sum to zero).
    fn mean(&self, points: &[P], members: &[u32], previous: &Self::Center) -> Self::Center;
}

/// Squared Euclidean distance on 3-D points; the centre is the arithmetic mean.
#[derive(Clone, Copy, Debug, Default)]
pub struct Euclidean;

impl Metric<Vec3> for Euclidean {
    type Center = Vec3;
    fn center_at(&self, p: &Vec3) -> Vec3 {
        *p
    }
    fn distance(&self, c: &Vec3, p: &Vec3) -> f32 {
        c.distance_squared(*p)
    }
    fn mean(&self, points: &[Vec3], members: &[u32], _previous: &Vec3) -> Vec3 {
        let sum: DVec3 = members.iter().map(|&i| points[i as usize].as_dvec3()).sum();
        (sum / members.len() as f64).as_vec3()
    }
}

/// Squared Euclidean distance on points of any dimension given as rows of a row-major f32
/// matrix (`data.chunks_exact(d)`), summed in f64 in index order; the centre is the arithmetic
/// mean in f64, its members summed in order.
impl<'a> Metric<&'a [f32]> for Euclidean {
    type Center = Vec<f64>;
    fn center_at(&self, p: &&'a [f32]) -> Vec<f64> {
        p.iter().map(|&v| v as f64).collect()
    }
    fn distance(&self, c: &Vec<f64>, p: &&'a [f32]) -> f32 {
        c.iter().zip(p.iter()).map(|(a, &b)| (a - b as f64) * (a - b as f64)).sum::<f64>() as f32
    }
    fn mean(&self, points: &[&'a [f32]], members: &[u32], _previous: &Vec<f64>) -> Vec<f64> {
        let mut sum = vec![0.0f64; points[members[0] as usize].len()];
        for &i in members {
            sum.iter_mut().zip(points[i as usize]).for_each(|(s, &v)| *s += v as f64);
        }
        sum.iter_mut().for_each(|s| *s /= members.len() as f64);
        sum
    }
}

/// What to run: `k` clusters, at most `max_iterations` Lloyd iterations, random stream `seed`.
#[derive(Clone, Copy, Debug)]
pub struct KMeans {
    pub k: usize,
    pub max_iterations: usize,
    pub seed: u64,
}

/// The clustering: `centers[c]` is the mean of the points with `assignment[i] == c`.
#[derive(Clone, Debug, PartialEq)]
pub struct KMeansResult<C> {
    pub centers: Vec<C>,
    /// Cluster index of each point.
    pub assignment: Vec<u32>,
    /// Lloyd iterations run (the last one, when `converged`, is the one that changed nothing).
    pub iterations: usize,
    /// True when an iteration changed no assignment before the limit; false when the limit
    /// stopped it. Also true when there was nothing to iterate (n ≤ k).
    pub converged: bool,
    /// Σ distance(centre, point) after each iteration (index 0 is after the first one).
    pub objective: Vec<f64>,
}

impl<C> KMeansResult<C> {
    /// The member indices of each cluster, in point order.
    pub fn members(&self) -> Vec<Vec<u32>> {
        members_of(&self.assignment, self.centers.len())
    }
}

/// The member indices of each of `k` clusters, in point order.
pub fn members_of(assignment: &[u32], k: usize) -> Vec<Vec<u32>> {
    let mut members = vec![Vec::new(); k];
    for (i, &a) in assignment.iter().enumerate() {
        members[a as usize].push(i as u32);
    }
    members
}

/// Gives each empty one of `k` clusters (in index order) a point of its own: the point of
/// largest `cost` (the first on ties) among the clusters with two or more members, whose cost
/// becomes `zero` (it now stands alone). Returns the moves as (cluster, point), in order. With
/// at least k points no cluster is left empty.
pub fn refill_empty_clusters<T: PartialOrd + Copy>(assignment: &mut [u32], cost: &mut [T], k: usize, zero: T) -> Vec<(usize, usize)> {
    let mut counts = vec![0usize; k];
    for &a in assignment.iter() {
        counts[a as usize] += 1;
    }
    let mut moves = Vec::new();
    for c in 0..k {
        if counts[c] > 0 {
            continue;
        }
        let mut far: Option<usize> = None;
        for i in 0..assignment.len() {
            if counts[assignment[i] as usize] >= 2 && far.is_none_or(|f| cost[i] > cost[f]) {
                far = Some(i);
            }
        }
        // n ≥ k points in fewer than k non-empty clusters: one of them has two members.
        let i = far.expect("at least k points leave a cluster with two members");
        counts[assignment[i] as usize] -= 1;
        counts[c] = 1;
        assignment[i] = c as u32;
        cost[i] = zero;
        moves.push((c, i));
    }
    moves
}

impl KMeans {
    /// Clusters `points`. With n ≤ k points every point is its own cluster, in point order
    /// (centre `center_at(p)`, no iteration); with no points the result is empty. Otherwise
    /// there are exactly k clusters, none empty. `k` = 0 is treated as 1 and `max_iterations` =
    /// 0 as 1 (the centres must be means of their members).
    pub fn run<P, M: Metric<P>>(&self, points: &[P], metric: &M) -> KMeansResult<M::Center> {
        let n = points.len();
        let k = self.k.max(1);
        if n <= k {
            return KMeansResult {
                centers: points.iter().map(|p| metric.center_at(p)).collect(),
                assignment: (0..n as u32).collect(),
                iterations: 0,
                converged: true,
                objective: Vec::new(),
            };
        }
        let mut centers = self.seed_plus_plus(points, metric, k);
        let mut assignment = vec![u32::MAX; n];
        let mut dist = vec![0f32; n];
        let mut objective = Vec::new();
        let mut converged = false;
        let mut iterations = 0;
        for it in 1..=self.max_iterations.max(1) {
            iterations = it;
            let mut changed = it == 1;
            // Assignment.
            for (i, p) in points.iter().enumerate() {
                let cur = assignment[i];
                let (mut best, mut best_d) =
                    if cur == u32::MAX { (0, f32::INFINITY) } else { (cur, metric.distance(&centers[cur as usize], p)) };
                for (c, center) in centers.iter().enumerate() {
                    let d = metric.distance(center, p);
                    // Strictly closer only: the current cluster wins ties, then the lowest index.
                    if d < best_d {
                        best = c as u32;
                        best_d = d;
                    }
                }
                if best != cur {
                    assignment[i] = best;
                    changed = true;
                }
                dist[i] = best_d;
            }
            // Refill empty clusters.
            for (c, i) in refill_empty_clusters(&mut assignment, &mut dist, k, 0.0) {
                centers[c] = metric.center_at(&points[i]);
                changed = true;
            }
            // Update.
            for (c, m) in members_of(&assignment, k).iter().enumerate() {
                centers[c] = metric.mean(points, m, &centers[c]);
            }
            objective.push(assignment.iter().zip(points).map(|(&a, p)| metric.distance(&centers[a as usize], p) as f64).sum());
            if !changed {
                converged = true;
                break;
            }
        }
        KMeansResult { centers, assignment, iterations, converged, objective }
    }

    /// k-means++: the first centre uniformly at random, each next one with probability
    /// proportional to its distance from the closest centre so far (uniformly among the points
    /// not yet taken when every point sits on a centre).
    fn seed_plus_plus<P, M: Metric<P>>(&self, points: &[P], metric: &M, k: usize) -> Vec<M::Center> {
        let n = points.len();
        let pick = |draw: usize, m: usize| ((uniform(self.seed, draw as u64, 0) as f64 * m as f64) as usize).min(m - 1);
        let mut taken = vec![false; n];
        let first = pick(0, n);
        taken[first] = true;
        let mut centers = vec![metric.center_at(&points[first])];
        let mut nearest: Vec<f32> = points.iter().map(|p| metric.distance(&centers[0], p)).collect();
        nearest[first] = 0.0;
        for draw in 1..k {
            let total: f64 = (0..n).filter(|&i| !taken[i]).map(|i| nearest[i] as f64).sum();
            let chosen = if total > 0.0 {
                let r = uniform(self.seed, draw as u64, 0) as f64 * total;
                let mut acc = 0.0;
                let mut last = None;
                let mut hit = None;
                for i in (0..n).filter(|&i| !taken[i] && nearest[i] > 0.0) {
                    acc += nearest[i] as f64;
                    last = Some(i);
                    if acc > r {
                        hit = Some(i);
                        break;
                    }
                }
                hit.or(last).expect("a positive total has a positive weight")
            } else {
                let free = pick(draw, n - draw);
                (0..n).filter(|&i| !taken[i]).nth(free).expect("k < n leaves a free point")
            };
            taken[chosen] = true;
            let c = metric.center_at(&points[chosen]);
            for (i, p) in points.iter().enumerate() {
                nearest[i] = nearest[i].min(metric.distance(&c, p));
            }
            nearest[chosen] = 0.0;
            centers.push(c);
        }
        centers
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `per` points in each of the blobs centred at `centres`, uniform in a cube of half-side `r`.
    fn blobs(centres: &[Vec3], per: usize, r: f32, seed: u64) -> Vec<Vec3> {
        let mut pts = Vec::new();
        for (b, c) in centres.iter().enumerate() {
            for j in 0..per {
                let i = (b * per + j) as u64;
                let u = Vec3::new(uniform(seed, i, 0), uniform(seed, i, 1), uniform(seed, i, 2));
                pts.push(*c + (u * 2.0 - 1.0) * r);
            }
        }
        pts
    }

    fn random_points(n: usize, seed: u64) -> Vec<Vec3> {
        (0..n as u64).map(|i| Vec3::new(uniform(seed, i, 0), uniform(seed, i, 1), uniform(seed, i, 2)) * 10.0).collect()
    }

    #[test]
    fn well_separated_blobs_are_recovered_exactly() {
        let centres = [Vec3::ZERO, Vec3::new(10.0, 0.0, 0.0), Vec3::new(0.0, 10.0, 0.0), Vec3::new(0.0, 0.0, 10.0), Vec3::splat(10.0)];
        // Blobs 10 apart and 0.1 wide: k-means++ then seeds one centre per blob (a second seed in a
        // covered blob has odds of about 10⁻⁴ per draw) and Lloyd converges to the blobs. With wide
        // blobs (half-side 1) some seeds do put two centres in one blob, a local minimum k-means
        // cannot leave.
        let pts = blobs(&centres, 40, 0.1, 3);
        for seed in 0..20 {
            let r = KMeans { k: 5, max_iterations: 50, seed }.run(&pts, &Euclidean);
            assert!(r.converged, "seed {seed}");
            // Each blob maps to one cluster and each cluster to one blob.
            let mut blob_of_cluster = [usize::MAX; 5];
            for (i, &a) in r.assignment.iter().enumerate() {
                let b = i / 40;
                let slot = &mut blob_of_cluster[a as usize];
                assert!(*slot == usize::MAX || *slot == b, "seed {seed}: cluster {a} mixes blobs {} and {b}", *slot);
                *slot = b;
            }
            assert!(blob_of_cluster.iter().all(|&b| b != usize::MAX), "seed {seed}: a cluster is empty");
            for (c, &b) in blob_of_cluster.iter().enumerate() {
                assert!(r.centers[c].distance(centres[b]) < 0.05, "seed {seed}: centre {c} at {}", r.centers[c]);
            }
        }
    }

    #[test]
    fn the_objective_never_increases_across_iterations() {
        for seed in 0..30 {
            let pts = random_points(300, 100 + seed);
            let r = KMeans { k: 12, max_iterations: 100, seed }.run(&pts, &Euclidean);
            assert!(r.objective.len() == r.iterations && r.iterations >= 2);
            for w in r.objective.windows(2) {
                assert!(w[1] <= w[0] * (1.0 + 1e-6), "seed {seed}: {} then {}", w[0], w[1]);
            }
            // The reported objective is that of the returned centres and assignment.
            let j: f64 = r.assignment.iter().zip(&pts).map(|(&a, p)| Euclidean.distance(&r.centers[a as usize], p) as f64).sum();
            assert!((j - r.objective.last().unwrap()).abs() <= 1e-9 * j.max(1.0));
        }
    }

    #[test]
    fn the_iteration_limit_is_honoured_and_reported() {
        let pts = random_points(2000, 9);
        let full = KMeans { k: 40, max_iterations: 1000, seed: 1 }.run(&pts, &Euclidean);
        assert!(full.converged && full.iterations > 3, "needs several iterations to show the limit: {}", full.iterations);
        for limit in [1, 2, 3] {
            let r = KMeans { k: 40, max_iterations: limit, seed: 1 }.run(&pts, &Euclidean);
            assert_eq!(r.iterations, limit);
            assert_eq!(r.objective.len(), limit);
            assert!(!r.converged, "stopped by the limit at {limit}");
            assert_eq!(&r.objective[..], &full.objective[..limit], "a limit truncates the same run");
        }
        // Centres are the means of the returned members even when the limit stopped the run.
        let r = KMeans { k: 40, max_iterations: 2, seed: 1 }.run(&pts, &Euclidean);
        for (c, m) in r.members().iter().enumerate() {
            assert!(!m.is_empty());
            assert!(r.centers[c].distance(Euclidean.mean(&pts, m, &Vec3::ZERO)) < 1e-5);
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_clustering_and_another_seed_may_not() {
        let pts = random_points(500, 4);
        let a = KMeans { k: 17, max_iterations: 30, seed: 8 }.run(&pts, &Euclidean);
        let b = KMeans { k: 17, max_iterations: 30, seed: 8 }.run(&pts, &Euclidean);
        assert_eq!(a, b);
        let bits = |r: &KMeansResult<Vec3>| r.centers.iter().flat_map(|c| c.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b));
        let c = KMeans { k: 17, max_iterations: 30, seed: 9 }.run(&pts, &Euclidean);
        assert_ne!(a.assignment, c.assignment, "the seed should matter on uniform random points");
    }

    #[test]
    fn coincident_points_still_fill_every_cluster() {
        let pts = vec![Vec3::new(1.0, 2.0, 3.0); 50];
        for k in [1, 2, 7, 49] {
            let r = KMeans { k, max_iterations: 10, seed: 2 }.run(&pts, &Euclidean);
            assert_eq!(r.centers.len(), k);
            assert!(r.members().iter().all(|m| !m.is_empty()), "k = {k}");
            assert!(r.converged && r.objective.iter().all(|&j| j == 0.0));
            assert!(r.centers.iter().all(|&c| c == pts[0]));
        }
    }

    #[test]
    fn fewer_points_than_k_makes_one_cluster_per_point() {
        let pts = random_points(5, 1);
        let r = KMeans { k: 8, max_iterations: 10, seed: 0 }.run(&pts, &Euclidean);
        assert_eq!(r.assignment, vec![0, 1, 2, 3, 4]);
        assert_eq!(r.centers, pts);
        assert!(r.converged && r.iterations == 0);
        let empty = KMeans { k: 8, max_iterations: 10, seed: 0 }.run(&[] as &[Vec3], &Euclidean);
        assert!(empty.centers.is_empty() && empty.assignment.is_empty());
    }

    #[test]
    fn rows_of_any_dimension_cluster_as_the_same_points_in_vec3() {
        let pts = random_points(400, 12);
        let flat: Vec<f32> = pts.iter().flat_map(|p| p.to_array()).collect();
        let rows: Vec<&[f32]> = flat.chunks_exact(3).collect();
        let a = KMeans { k: 9, max_iterations: 50, seed: 3 }.run(&pts, &Euclidean);
        let b = KMeans { k: 9, max_iterations: 50, seed: 3 }.run(&rows, &Euclidean);
        assert_eq!(a.assignment, b.assignment);
        for (ca, cb) in a.centers.iter().zip(&b.centers) {
            assert!(ca.as_dvec3().distance(DVec3::from_slice(cb)) < 1e-5);
        }
    }

    #[test]
    fn k_of_one_puts_everything_in_one_cluster_at_the_mean() {
        let pts = random_points(100, 6);
        let r = KMeans { k: 1, max_iterations: 10, seed: 0 }.run(&pts, &Euclidean);
        assert!(r.assignment.iter().all(|&a| a == 0));
        let mean = pts.iter().copied().sum::<Vec3>() / 100.0;
        assert!(r.centers[0].distance(mean) < 1e-5);
        assert!(r.converged && r.iterations == 2, "one move, then one iteration that changes nothing: {}", r.iterations);
    }

    #[test]
    fn kmeans_plus_plus_seeds_spread_over_separated_blobs() {
        // With 5 blobs 10 apart and radius 0.1, seeding picks one point per blob almost surely.
        let centres: Vec<Vec3> = (0..5).map(|b| Vec3::new(10.0 * b as f32, 0.0, 0.0)).collect();
        let pts = blobs(&centres, 30, 0.1, 5);
        let mut spread = 0;
        for seed in 0..50 {
            let seeds = KMeans { k: 5, max_iterations: 1, seed }.seed_plus_plus(&pts, &Euclidean, 5);
            let mut hit = [false; 5];
            for s in seeds {
                hit[((s.x / 10.0).round() as usize).min(4)] = true;
            }
            spread += hit.iter().all(|&h| h) as usize;
        }
        assert!(spread >= 49, "{spread} of 50 seedings covered every blob");
    }
}
