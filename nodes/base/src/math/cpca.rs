//! Clustered principal component analysis (CPCA; Sloan, Hall, Hart & Snyder 2003, "Clustered
//! principal components for precomputed radiance transfer"), in f64: n points of dimension d
//! are split into k clusters, and each point is approximated in its cluster c by the cluster's
//! mean plus its m leading principal directions, x_i ≈ x̂_i = μ_c + Σ_j c_ij b_cj, so as to
//! make the total squared error E = Σ_i ‖x_i − x̂_i‖² small. Pipeline 2 uses it to cluster mesh
//! vertices by feature vectors before a per-cluster Tucker compression, and to compress the
//! per-vertex two-bounce transfer vectors.
//!
//! 1. Start: the assignment of seeded k-means ([`super::kmeans`]: k-means++ seeding from
//!    `seed`, then at most [`INIT_ITERATIONS`] Lloyd iterations, squared Euclidean distance).
//!    k-means groups points by their distance to a centre only; the CPCA iterations then
//!    regroup them by the affine subspace that rebuilds them best.
//! 2. Fit: per cluster, μ_c = the mean of its members (summed in point order) and the m
//!    leading eigenvectors of the members' centred scatter matrix, through whichever of the
//!    two Gram forms is smaller: with more members than dimensions the d × d covariance
//!    Σ (x − μ)(x − μ)ᵀ (faer's product, sequential, over chunks of `FIT_CHUNK` members
//!    added in order; then [`leading_eigenvectors`]), otherwise the members' n_c × n_c Gram
//!    matrix through [`uncentred_pca`] of the centred members (which re-orthonormalises the
//!    directions it forms from it). Either way the directions are orthonormal rows, no more
//!    than the cluster's numerical rank (eigenvalues ≥ `RANK_TOLERANCE` × the largest: a
//!    cluster of coincident points has only its mean), and each has its entry of largest
//!    magnitude (the first on ties) positive, as in [`super::pca`].
//! 3. Assign: every point goes to the cluster whose affine subspace rebuilds it with the least
//!    squared error, e_ic = ‖x_i − μ_c‖² − Σ_j (b_cj · (x_i − μ_c))² (orthonormal b_cj; clamped
//!    at 0 against rounding). A point keeps its cluster on a tie, otherwise the lowest index
//!    wins.
//! 4. Empty clusters: each (in index order) takes the point with the largest e_i among the
//!    clusters that keep two or more members (the first such point on ties), which it then
//!    rebuilds exactly as its mean. So no cluster is ever empty (n ≥ k is required), and the
//!    move lowers E.
//! 5. Stop when an assignment step (with its refills) changes nothing: `converged`. Otherwise
//!    the cluster fits are redone and the loop goes on, at most `max_iterations` times; the
//!    limit reached, `converged` is false and the result is the fit of the last assignment.
//!    Each of steps 2 and 3 can only lower E (the fit is the best mean and m-subspace for the
//!    members; a point moves only to a smaller error), so `objective` — E after each
//!    assignment step — never increases, and the final `total_error` is at most its last
//!    entry. `max_iterations` = 0 returns the fit of the k-means assignment, not converged.
//! 6. Output: per point its cluster and m coefficients c_ij = b_cj · (x_i − μ_c) (zeros past
//!    its cluster's rank), and E computed from the residuals themselves (not from the
//!    difference of step 3, which loses digits when the error is small).
//!
//! Every loop runs in a fixed order or in parallel over independent outputs (points by blocks
//! of `BLOCK`, clusters), with faer's products sequential inside one item, and the sums over
//! points taken afterwards in point order: the result has the same bytes on any thread count
//! (tested). The working memory beyond the result is a few d² f64 per thread (the covariance
//! or Gram matrix being decomposed, never larger than d × d, and a block's `BLOCK` × d values)
//! plus 16 bytes a point; the result holds [`Cpca::bytes_for`] bytes, so a node can refuse a
//! request before anything is allocated. Points are unweighted, as in Sloan et al.

use super::kmeans::{members_of, refill_empty_clusters, Euclidean, KMeans, Metric};
use super::pca::{leading_eigenvectors, uncentred_pca};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use relume_core::{CancelToken, NodeError, RunCtx};

/// Lloyd iterations of the k-means that gives the starting assignment.
pub const INIT_ITERATIONS: usize = 8;

/// Points per parallel item of the assignment and projection steps.
const BLOCK: usize = 256;

/// Members per product when a cluster's covariance matrix is accumulated.
const FIT_CHUNK: usize = 512;

/// What to run: `k` clusters of a mean and `m` directions each, at most `max_iterations`
/// CPCA iterations, random stream `seed` (for the k-means start).
#[derive(Clone, Copy, Debug)]
pub struct Cpca {
    pub k: usize,
    pub m: usize,
    pub max_iterations: usize,
    pub seed: u64,
}

/// The clustering and each point's coefficients (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct CpcaResult {
    /// Dimension of a point, d.
    pub dim: usize,
    /// Directions asked for per cluster, m: the stride of `bases` and `coefficients`.
    pub m: usize,
    /// Cluster means, k × d, row-major.
    pub means: Vec<f64>,
    /// Cluster directions, k × m × d: rows `ranks[c]..m` of cluster c are zero.
    pub bases: Vec<f64>,
    /// Directions each cluster has (≤ m, lower where its members span fewer).
    pub ranks: Vec<u32>,
    /// Cluster of each point.
    pub assignment: Vec<u32>,
    /// n × m, row-major: point i ≈ mean + Σ_j c_ij b_j of its cluster; zero past its rank.
    pub coefficients: Vec<f64>,
    /// E after each iteration's assignment step (index 0: after the first one).
    pub objective: Vec<f64>,
    /// Σ_i ‖x_i − x̂_i‖² of the returned fit, from the residuals.
    pub total_error: f64,
    /// CPCA iterations run (the last, when `converged`, is the one that changed nothing).
    pub iterations: usize,
    /// Whether an assignment step changed nothing before the limit.
    pub converged: bool,
}

impl CpcaResult {
    pub fn clusters(&self) -> usize {
        self.ranks.len()
    }

    pub fn points(&self) -> usize {
        self.assignment.len()
    }

    /// μ_c (length d).
    pub fn mean(&self, c: usize) -> &[f64] {
        &self.means[c * self.dim..(c + 1) * self.dim]
    }

    /// The directions of cluster c: `ranks[c]` orthonormal rows of length d, row-major.
    pub fn basis(&self, c: usize) -> &[f64] {
        let start = c * self.m * self.dim;
        &self.bases[start..start + self.ranks[c] as usize * self.dim]
    }

    /// The m coefficients of point i.
    pub fn coefficients_of(&self, i: usize) -> &[f64] {
        &self.coefficients[i * self.m..(i + 1) * self.m]
    }

    /// x̂_i = μ_c + Σ_j c_ij b_cj.
    pub fn reconstruct(&self, i: usize) -> Vec<f64> {
        let c = self.assignment[i] as usize;
        let mut out = self.mean(c).to_vec();
        for (b, &w) in self.basis(c).chunks_exact(self.dim).zip(self.coefficients_of(i)) {
            out.iter_mut().zip(b).for_each(|(o, v)| *o += w * v);
        }
        out
    }

    /// The member indices of each cluster, in point order.
    pub fn members(&self) -> Vec<Vec<u32>> {
        members_of(&self.assignment, self.clusters())
    }

    /// Bytes held by the arrays sized by n, d, k and m ([`Cpca::bytes_for`] of this result).
    pub fn held_bytes(&self) -> u64 {
        let f = |v: &[f64]| v.len() as u64 * 8;
        f(&self.means) + f(&self.bases) + f(&self.coefficients) + 4 * (self.ranks.len() + self.assignment.len()) as u64
    }
}

/// One fit of every cluster: k × d means, k × m × d directions (zero past each rank).
struct Fit {
    means: Vec<f64>,
    bases: Vec<f64>,
    ranks: Vec<u32>,
}

impl Cpca {
    /// Bytes a result for n points of dimension d, k clusters and m directions holds (its
    /// means, directions, ranks, assignment and coefficients; `objective` adds 8 per
    /// iteration); saturating, so an absurd request never overflows.
    pub fn bytes_for(n: usize, d: usize, k: usize, m: usize) -> u64 {
        let (n, d, k, m) = (n as u64, d as u64, k as u64, m as u64);
        let f64s = k.saturating_mul(d).saturating_add(k.saturating_mul(m).saturating_mul(d)).saturating_add(n.saturating_mul(m));
        f64s.saturating_mul(8).saturating_add(k.saturating_add(n).saturating_mul(4))
    }

    /// [`Cpca::run_with`] without progress or cancellation (tests, small inputs).
    pub fn run(&self, points: &[f32], dim: usize) -> Result<CpcaResult, NodeError> {
        let cancel = CancelToken::new();
        self.run_with(points, dim, &RunCtx::new("cpca", &cancel, None), (0.0, 1.0))
    }

    /// The CPCA of the module doc of `points` (row-major, `dim` values a point). Progress goes
    /// to `cx` over the fraction `span` of its node's work; stops with `Cancelled` soon after
    /// the run is cancelled. Errors: `dim` or `k` of 0, a length that is not a whole number of
    /// points, fewer points than clusters, a value that is not finite, an eigen-decomposition
    /// that does not converge.
    pub fn run_with(&self, points: &[f32], dim: usize, cx: &RunCtx, span: (f64, f64)) -> Result<CpcaResult, NodeError> {
        let (d, k, m) = (dim, self.k, self.m);
        if d == 0 {
            return Err(NodeError::failed("CPCA: points of dimension 0 cannot be clustered"));
        }
        if !points.len().is_multiple_of(d) {
            return Err(NodeError::failed(format!("CPCA: {} values are not a whole number of points of dimension {d}", points.len())));
        }
        let n = points.len() / d;
        if k == 0 {
            return Err(NodeError::failed("CPCA: k = 0 clusters asked for; at least one is needed"));
        }
        if n < k {
            return Err(NodeError::failed(format!("CPCA: {k} clusters need at least {k} points ({n} given)")));
        }
        if let Some(at) = points.iter().position(|v| !v.is_finite()) {
            return Err(NodeError::failed(format!("CPCA: point {} holds a value that is not finite ({})", at / d, points[at])));
        }
        let at = |f: f64| span.0 + (span.1 - span.0) * f;
        let rows: Vec<&[f32]> = points.chunks_exact(d).collect();

        cx.phase(at(0.0), at(0.1));
        cx.check()?;
        let start = KMeans { k, max_iterations: INIT_ITERATIONS, seed: self.seed }.run(&rows, &Euclidean);
        let mut assignment = start.assignment;
        let mut fit = fit_all(&rows, m, k, &assignment, cx)?;
        let (mut objective, mut iterations, mut converged) = (Vec::new(), 0, false);
        let limit = self.max_iterations;
        for it in 1..=limit {
            cx.phase(at(0.1 + 0.85 * (it - 1) as f64 / limit as f64), at(0.1 + 0.85 * it as f64 / limit as f64));
            iterations = it;
            let (next, mut errors) = assign(&rows, &fit, &assignment, cx)?;
            let changed = next != assignment;
            assignment = next;
            let refilled = !refill_empty_clusters(&mut assignment, &mut errors, k, 0.0).is_empty();
            objective.push(errors.iter().sum());
            if !(changed || refilled) {
                converged = true;
                break;
            }
            fit = fit_all(&rows, m, k, &assignment, cx)?;
        }

        cx.phase(at(0.95), at(1.0));
        let parts = cx.par_map(n.div_ceil(BLOCK), |b| project_block(&rows, &fit, m, &assignment, b))?;
        let mut coefficients = Vec::with_capacity(n * m);
        let mut total_error = 0.0;
        for (c, e) in parts {
            coefficients.extend(c);
            total_error += e.iter().sum::<f64>();
        }
        let Fit { means, bases, ranks } = fit;
        Ok(CpcaResult { dim: d, m, means, bases, ranks, assignment, coefficients, objective, total_error, iterations, converged })
    }
}

/// Step 2 for every cluster, in parallel over clusters.
fn fit_all(rows: &[&[f32]], m: usize, k: usize, assignment: &[u32], cx: &RunCtx) -> Result<Fit, NodeError> {
    let d = rows[0].len();
    let members = members_of(assignment, k);
    let fits = cx.par_try_map(k, |c| fit_cluster(rows, m, &members[c]))?;
    let mut fit = Fit { means: Vec::with_capacity(k * d), bases: vec![0.0; k * m * d], ranks: Vec::with_capacity(k) };
    for (c, (mean, basis)) in fits.into_iter().enumerate() {
        fit.means.extend(mean);
        fit.bases[c * m * d..][..basis.len()].copy_from_slice(&basis);
        fit.ranks.push((basis.len() / d) as u32);
    }
    Ok(fit)
}

/// The mean and (at most m) orthonormal directions of the (non-empty) `members`.
fn fit_cluster(rows: &[&[f32]], m: usize, members: &[u32]) -> Result<(Vec<f64>, Vec<f64>), NodeError> {
    let d = rows[0].len();
    let mean = Euclidean.mean(rows, members, &Vec::new());
    let n = members.len();
    if m == 0 {
        return Ok((mean, Vec::new()));
    }
    let centred = |i: u32| rows[i as usize].iter().zip(&mean).map(|(&x, mu)| x as f64 - mu);
    if n <= d {
        // The n × n Gram matrix is the smaller one.
        let x: Vec<f64> = members.iter().flat_map(|&i| centred(i)).collect();
        let p = uncentred_pca(&x, n, &vec![1.0; d], m)?;
        return Ok((mean, p.components));
    }
    let mut cov = Mat::<f64>::zeros(d, d);
    let mut chunk = Mat::<f64>::zeros(FIT_CHUNK.min(n), d);
    for (q, part) in members.chunks(FIT_CHUNK).enumerate() {
        for (r, &i) in part.iter().enumerate() {
            for (l, v) in centred(i).enumerate() {
                chunk[(r, l)] = v;
            }
        }
        let x = chunk.as_ref().subrows(0, part.len());
        matmul(cov.as_mut(), if q == 0 { Accum::Replace } else { Accum::Add }, x.transpose(), x, 1.0, Par::Seq);
    }
    for a in 0..d {
        for b in 0..a {
            cov[(b, a)] = cov[(a, b)];
        }
    }
    Ok((mean, leading_eigenvectors(&cov, m)?.1))
}

/// Step 3: each point's cluster (kept on a tie) and its error there, in parallel over blocks.
fn assign(rows: &[&[f32]], fit: &Fit, current: &[u32], cx: &RunCtx) -> Result<(Vec<u32>, Vec<f64>), NodeError> {
    let (n, d, k) = (rows.len(), rows[0].len(), fit.ranks.len());
    let m = fit.bases.len() / (k * d);
    // Each cluster's directions as the columns of a d × rank matrix (faer's own allocation).
    let directions: Vec<Mat<f64>> = (0..k).map(|c| Mat::from_fn(d, fit.ranks[c] as usize, |l, j| fit.bases[(c * m + j) * d + l])).collect();
    let blocks = cx.par_map(n.div_ceil(BLOCK), |b| {
        let (i0, i1) = (b * BLOCK, ((b + 1) * BLOCK).min(n));
        let len = i1 - i0;
        let mut centred = Mat::<f64>::zeros(len, d);
        let mut coef = Mat::<f64>::zeros(len, m);
        let mut errors = vec![0.0f64; len * k];
        for c in 0..k {
            let mean = &fit.means[c * d..(c + 1) * d];
            for r in 0..len {
                let mut s = 0.0;
                for (l, (&x, mu)) in rows[i0 + r].iter().zip(mean).enumerate() {
                    let v = x as f64 - mu;
                    centred[(r, l)] = v;
                    s += v * v;
                }
                errors[r * k + c] = s;
            }
            let rank = fit.ranks[c] as usize;
            if rank > 0 {
                matmul(coef.as_mut().subcols_mut(0, rank), Accum::Replace, centred.as_ref(), directions[c].as_ref(), 1.0, Par::Seq);
                for r in 0..len {
                    let kept: f64 = (0..rank).map(|j| coef[(r, j)] * coef[(r, j)]).sum();
                    errors[r * k + c] = (errors[r * k + c] - kept).max(0.0);
                }
            }
        }
        (i0..i1)
            .map(|i| {
                let e = &errors[(i - i0) * k..(i - i0 + 1) * k];
                let mut best = current[i] as usize;
                for (c, &ec) in e.iter().enumerate() {
                    if ec < e[best] {
                        best = c;
                    }
                }
                (best as u32, e[best])
            })
            .collect::<Vec<_>>()
    })?;
    Ok(blocks.into_iter().flatten().unzip())
}

/// Step 6 for the points of block `b`: their m coefficients each (row-major) and their
/// squared residuals.
fn project_block(rows: &[&[f32]], fit: &Fit, m: usize, assignment: &[u32], b: usize) -> (Vec<f64>, Vec<f64>) {
    let (n, d) = (rows.len(), rows[0].len());
    let (i0, i1) = (b * BLOCK, ((b + 1) * BLOCK).min(n));
    let mut coefficients = vec![0.0f64; (i1 - i0) * m];
    let mut errors = Vec::with_capacity(i1 - i0);
    for i in i0..i1 {
        let c = assignment[i] as usize;
        let mut residual: Vec<f64> = rows[i].iter().zip(&fit.means[c * d..(c + 1) * d]).map(|(&x, mu)| x as f64 - mu).collect();
        let basis = &fit.bases[c * m * d..][..fit.ranks[c] as usize * d];
        let out = &mut coefficients[(i - i0) * m..][..m];
        for (o, bj) in out.iter_mut().zip(basis.chunks_exact(d)) {
            *o = bj.iter().zip(&residual).map(|(a, b)| a * b).sum();
        }
        // Projections of the centred point first, then the residual: each coefficient is
        // that of x − μ itself.
        for (&w, bj) in out.iter().zip(basis.chunks_exact(d)) {
            residual.iter_mut().zip(bj).for_each(|(r, v)| *r -= w * v);
        }
        errors.push(residual.iter().map(|r| r * r).sum());
    }
    (coefficients, errors)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;
    use proptest::prelude::*;

    /// A uniform number in [-1, 1) from (seed, index).
    fn r(seed: u64, i: u64) -> f64 {
        uniform(seed, i, 0) as f64 * 2.0 - 1.0
    }

    /// `count` orthonormal vectors of length `d` (Gram-Schmidt, twice, of seeded rows).
    fn orthonormal(count: usize, d: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut out: Vec<Vec<f64>> = Vec::new();
        let mut draw = 0u64;
        while out.len() < count {
            let mut v: Vec<f64> = (0..d)
                .map(|_| {
                    draw += 1;
                    r(seed, draw)
                })
                .collect();
            for _ in 0..2 {
                for q in &out {
                    let p: f64 = v.iter().zip(q).map(|(a, b)| a * b).sum();
                    v.iter_mut().zip(q).for_each(|(a, b)| *a -= p * b);
                }
            }
            let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
            if norm > 1e-3 {
                out.push(v.iter().map(|a| a / norm).collect());
            }
        }
        out
    }

    /// `per` points on each of `k` affine subspaces of dimension `m` in `d` dimensions (the
    /// j-th through `offset` × e_j along random orthonormal directions, coefficients uniform
    /// in [-1, 1)), subspace by subspace; with the subspace of each point.
    fn subspaces(k: usize, m: usize, d: usize, per: usize, offset: f64, seed: u64) -> (Vec<f32>, Vec<usize>) {
        let (mut x, mut label) = (Vec::new(), Vec::new());
        for j in 0..k {
            let b = orthonormal(m, d, seed * 31 + j as u64);
            for p in 0..per {
                let t: Vec<f64> = (0..m).map(|q| r(seed ^ 0x5eed, ((j * per + p) * m + q) as u64)).collect();
                x.extend(
                    (0..d).map(|l| (if l == j { offset } else { 0.0 } + t.iter().zip(&b).map(|(tq, bq)| tq * bq[l]).sum::<f64>()) as f32),
                );
                label.push(j);
            }
        }
        (x, label)
    }

    fn random_points(n: usize, d: usize, seed: u64) -> Vec<f32> {
        (0..n * d).map(|i| r(seed, i as u64) as f32).collect()
    }

    /// Σ_i ‖x_i − reconstruct(i)‖², from the result's accessors.
    fn direct_error(res: &CpcaResult, x: &[f32]) -> f64 {
        (0..res.points()).map(|i| res.reconstruct(i).iter().zip(&x[i * res.dim..]).map(|(a, &b)| (a - b as f64).powi(2)).sum::<f64>()).sum()
    }

    /// Orthonormal, signed directions and a consistent error in any result.
    fn check_invariants(res: &CpcaResult, x: &[f32]) {
        let d = res.dim;
        for c in 0..res.clusters() {
            let b: Vec<&[f64]> = res.basis(c).chunks_exact(d).collect();
            for p in 0..b.len() {
                for q in 0..b.len() {
                    let dot: f64 = b[p].iter().zip(b[q]).map(|(u, v)| u * v).sum();
                    assert!((dot - if p == q { 1.0 } else { 0.0 }).abs() < 1e-10, "cluster {c}: b{p}·b{q} = {dot}");
                }
                let big = b[p].iter().fold(0.0f64, |m, &v| if v.abs() > m.abs() { v } else { m });
                assert!(big > 0.0, "cluster {c}: direction {p} has its largest entry negative");
            }
            assert!(res.bases[c * res.m * d..(c + 1) * res.m * d][b.len() * d..].iter().all(|&v| v == 0.0));
        }
        assert!(res.members().iter().all(|m| !m.is_empty()), "a cluster is empty");
        // The residuals rebuilt through `reconstruct` differ from those summed in the run by a
        // few ulps of x per value, δ: |Σ (r + δ)² − Σ r²| ≤ 2 ‖r‖ ‖δ‖ + ‖δ‖².
        let direct = direct_error(res, x);
        let delta = 8.0 * f64::EPSILON * x.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
        let tol = 2.0 * res.total_error.sqrt() * delta + delta * delta + 1e-12 * res.total_error;
        assert!((direct - res.total_error).abs() <= tol, "{direct} vs {} (tolerance {tol:e})", res.total_error);
        assert!(res.means.iter().chain(&res.bases).chain(&res.coefficients).all(|v| v.is_finite()));
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

        /// Subspaces 1000 apart, points spread over ±1 along theirs: k-means++ seeds one
        /// cluster per subspace (a second seed in a covered one has odds of about 10⁻⁵ per
        /// draw), and the fit must then rebuild every point up to the f32 rounding of the
        /// input. The fit of the right clusters is the best m-subspace of each, so its error is
        /// at most that of the true subspaces: Σ over the values of (2⁻²⁴ |x|)², the bound
        /// asserted (with 10⁻⁶ relative slack for the f64 arithmetic).
        #[test]
        fn points_on_k_affine_subspaces_are_clustered_and_rebuilt(
            k in 2usize..7, m in 1usize..5, extra in 2usize..30, per in 0usize..40, seed in 0u64..1_000_000
        ) {
            let d = k.max(2 * m) + extra;
            let per = m + 2 + per;
            let (x, label) = subspaces(k, m, d, per, 1000.0, seed);
            let res = Cpca { k, m, max_iterations: 30, seed }.run(&x, d).unwrap();
            prop_assert!(res.converged);
            let bound: f64 = x.iter().map(|&v| (v.abs() as f64 * 2f64.powi(-24)).powi(2)).sum();
            prop_assert!(res.total_error <= bound * (1.0 + 1e-6), "error {:e} over the rounding bound {bound:e}", res.total_error);
            // One cluster per subspace and one subspace per cluster.
            let mut subspace_of = vec![usize::MAX; k];
            for (i, &c) in res.assignment.iter().enumerate() {
                let slot = &mut subspace_of[c as usize];
                prop_assert!(*slot == usize::MAX || *slot == label[i], "cluster {c} mixes subspaces {} and {}", *slot, label[i]);
                *slot = label[i];
            }
            prop_assert!(subspace_of.iter().all(|&s| s != usize::MAX));
            prop_assert!(res.ranks.iter().all(|&r| r as usize == m), "ranks {:?}", res.ranks);
            check_invariants(&res, &x);
        }
    }

    #[test]
    fn one_cluster_is_the_centred_pca_of_all_points() {
        // n > d takes the covariance route, n ≤ d the Gram route; math::pca on the centred
        // points is the reference either way.
        for (n, d, m, seed) in [(300, 20, 5, 1), (500, 7, 3, 2), (40, 90, 6, 3), (25, 25, 20, 4)] {
            let x: Vec<f32> = random_points(n, d, seed).iter().enumerate().map(|(i, v)| v * (1.0 + (i % d) as f32) + 3.0).collect();
            let res = Cpca { k: 1, m, max_iterations: 10, seed }.run(&x, d).unwrap();
            assert!(res.converged && res.iterations == 1, "{} iterations", res.iterations);
            let mut mean = vec![0.0f64; d];
            for p in x.chunks_exact(d) {
                mean.iter_mut().zip(p).for_each(|(a, &v)| *a += v as f64 / n as f64);
            }
            let centred: Vec<f64> = x.iter().enumerate().map(|(i, &v)| v as f64 - mean[i % d]).collect();
            let pca = uncentred_pca(&centred, n, &vec![1.0; d], m).unwrap();
            let reference: f64 = (0..n)
                .map(|i| pca.reconstruct(i).iter().zip(&centred[i * d..(i + 1) * d]).map(|(a, b)| (a - b).powi(2)).sum::<f64>())
                .sum();
            let rel = (res.total_error - reference).abs() / reference;
            assert!(rel < 1e-9, "n {n}, d {d}: {} vs {reference} ({rel:e})", res.total_error);
            // The same directions, sign convention included (distinct eigenvalues here).
            assert_eq!(res.ranks[0] as usize, pca.components());
            let worst = res.basis(0).iter().zip(&pca.components).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(worst < 1e-8, "n {n}, d {d}: directions differ by {worst:e}");
            check_invariants(&res, &x);
        }
    }

    #[test]
    fn the_error_never_increases_with_iterations_or_with_one_more_direction_on_the_same_start() {
        for seed in 0..16 {
            // Noisy 2-D subspaces too close for k-means to separate: the iterations have work.
            let (mut x, _) = subspaces(6, 2, 10, 60, 0.3, seed);
            x.iter_mut().enumerate().for_each(|(i, v)| *v += 0.05 * r(seed + 99, i as u64) as f32);
            let scale: f64 = Cpca { k: 1, m: 0, max_iterations: 1, seed }.run(&x, 10).unwrap().total_error;
            let tol = 1e-12 * scale;
            let full = Cpca { k: 6, m: 2, max_iterations: 200, seed }.run(&x, 10).unwrap();
            assert!(full.converged && full.iterations >= 2, "seed {seed}: {} iterations", full.iterations);
            assert_eq!(full.objective.len(), full.iterations);
            for w in full.objective.windows(2) {
                assert!(w[1] <= w[0] + tol, "seed {seed}: {} then {}", w[0], w[1]);
            }
            assert!(full.total_error <= full.objective.last().unwrap() + tol);
            check_invariants(&full, &x);
            // A limit truncates the same run, and each further iteration lowers the result.
            let mut previous = f64::INFINITY;
            for limit in 0..=full.iterations {
                let res = Cpca { k: 6, m: 2, max_iterations: limit, seed }.run(&x, 10).unwrap();
                assert_eq!(&res.objective[..], &full.objective[..limit], "seed {seed}, limit {limit}");
                assert!(res.total_error <= previous + tol, "seed {seed}, limit {limit}: {} after {previous}", res.total_error);
                previous = res.total_error;
            }
            assert_eq!(previous, full.total_error);
            // One more direction on the same start: the fit of the k-means clusters, and the
            // first assignment step, can only do better (nested subspaces, the same means).
            for m in 0..4 {
                for limit in [0, 1] {
                    let a = Cpca { k: 6, m, max_iterations: limit, seed }.run(&x, 10).unwrap();
                    let b = Cpca { k: 6, m: m + 1, max_iterations: limit, seed }.run(&x, 10).unwrap();
                    let (ea, eb) = if limit == 0 { (a.total_error, b.total_error) } else { (a.objective[0], b.objective[0]) };
                    assert!(eb <= ea + tol, "seed {seed}, m {m}, limit {limit}: {eb} > {ea}");
                }
            }
        }
    }

    #[test]
    fn zero_data_is_rebuilt_exactly_and_bad_shapes_are_refused() {
        let zeros = vec![0.0f32; 20 * 5];
        for (k, m) in [(1, 2), (3, 2), (20, 4), (4, 0)] {
            let res = Cpca { k, m, max_iterations: 10, seed: 1 }.run(&zeros, 5).unwrap();
            assert!(res.converged && res.total_error == 0.0, "k {k}: {}", res.total_error);
            assert!(res.ranks.iter().all(|&r| r == 0) && res.means.iter().all(|&v| v == 0.0));
            assert!(res.coefficients.iter().all(|&v| v == 0.0) && res.coefficients.len() == 20 * m);
            assert!(res.members().iter().all(|m| !m.is_empty()));
        }
        let x = random_points(10, 3, 5);
        let err = |k, d: usize, x: &[f32]| Cpca { k, m: 1, max_iterations: 5, seed: 0 }.run(x, d).unwrap_err().to_string();
        assert!(err(11, 3, &x[..30]).contains("at least 11 points"));
        assert!(err(0, 3, &x[..30]).contains("at least one is needed"));
        assert!(err(1, 0, &[]).contains("dimension 0"));
        assert!(err(1, 3, &x[..29]).contains("29 values"));
        assert!(err(1, 3, &[]).contains("(0 given)"));
        for bad in [f32::NAN, f32::INFINITY] {
            let mut y = x.clone();
            y[14] = bad;
            assert!(err(2, 3, &y).contains("point 4"), "{}", err(2, 3, &y));
        }
        // As many clusters as points: each point its own cluster, rebuilt exactly.
        let res = Cpca { k: 10, m: 1, max_iterations: 5, seed: 0 }.run(&x, 3).unwrap();
        assert!(res.converged && res.total_error == 0.0);
        // More directions than dimensions: the rank is the dimension, the error 0 (to rounding).
        let res = Cpca { k: 1, m: 5, max_iterations: 5, seed: 0 }.run(&x, 3).unwrap();
        assert_eq!(res.ranks, vec![3]);
        assert!(res.total_error < 1e-28, "{}", res.total_error);
    }

    #[test]
    fn no_directions_is_k_means_with_the_squared_distance_to_the_mean() {
        let x = random_points(300, 4, 8);
        let res = Cpca { k: 5, m: 0, max_iterations: 100, seed: 2 }.run(&x, 4).unwrap();
        assert!(res.converged && res.coefficients.is_empty());
        let expected: f64 = (0..300)
            .map(|i| res.mean(res.assignment[i] as usize).iter().zip(&x[i * 4..]).map(|(a, &b)| (a - b as f64).powi(2)).sum::<f64>())
            .sum();
        assert!((expected - res.total_error).abs() < 1e-12 * expected);
        // Converged: each point is nearest its own cluster's mean.
        for i in 0..300 {
            let dist = |c: usize| res.mean(c).iter().zip(&x[i * 4..]).map(|(a, &b)| (a - b as f64).powi(2)).sum::<f64>();
            let own = dist(res.assignment[i] as usize);
            assert!((0..5).all(|c| dist(c) >= own - 1e-12), "point {i}");
        }
    }

    #[test]
    fn one_and_two_threads_give_the_same_bytes() {
        // d = 40 with ~190 points a cluster (covariance route), d = 300 with ~125 (Gram route);
        // both over several blocks of points.
        for (n, d, k, m) in [(1500, 40, 8, 4), (1000, 300, 8, 6)] {
            let x: Vec<f32> = {
                let (mut s, _) = subspaces(k, m, d, n / k, 0.3, 7);
                s.iter_mut().enumerate().for_each(|(i, v)| *v += 0.1 * r(3, i as u64) as f32);
                s
            };
            let on = |threads| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap()
                    .install(|| Cpca { k, m, max_iterations: 20, seed: 5 }.run(&x, d).unwrap())
            };
            let (one, two) = (on(1), on(2));
            assert!(one.iterations >= 2, "d {d}: {} iterations", one.iterations);
            let bits = |r: &CpcaResult| {
                r.means.iter().chain(&r.bases).chain(&r.coefficients).chain(&r.objective).map(|v| v.to_bits()).collect::<Vec<_>>()
            };
            assert_eq!(bits(&one), bits(&two), "d {d}");
            assert_eq!(one, two);
            assert_eq!(one.total_error.to_bits(), two.total_error.to_bits());
            check_invariants(&one, &x);
        }
    }

    #[test]
    fn an_iteration_limit_that_stops_the_run_is_reported() {
        let x = random_points(600, 6, 11);
        let full = Cpca { k: 8, m: 2, max_iterations: 500, seed: 3 }.run(&x, 6).unwrap();
        assert!(full.converged && full.iterations > 2, "needs several iterations: {}", full.iterations);
        let one = Cpca { k: 8, m: 2, max_iterations: 1, seed: 3 }.run(&x, 6).unwrap();
        assert!(!one.converged && one.iterations == 1 && one.objective == full.objective[..1]);
        let none = Cpca { k: 8, m: 2, max_iterations: 0, seed: 3 }.run(&x, 6).unwrap();
        assert!(!none.converged && none.iterations == 0 && none.objective.is_empty());
        check_invariants(&one, &x);
        check_invariants(&none, &x);
    }

    #[test]
    fn the_bytes_held_are_known_before_the_run() {
        for (n, d, k, m) in [(300, 20, 7, 3), (40, 90, 4, 6), (20, 5, 3, 0)] {
            let res = Cpca { k, m, max_iterations: 10, seed: 1 }.run(&random_points(n, d, 2), d).unwrap();
            assert_eq!(res.held_bytes(), Cpca::bytes_for(n, d, k, m));
        }
        assert_eq!(Cpca::bytes_for(45_000, 864, 64, 32), 8 * (64 * 864 + 64 * 32 * 864 + 45_000 * 32) + 4 * (64 + 45_000));
        assert_eq!(Cpca::bytes_for(usize::MAX, usize::MAX, 2, 2), u64::MAX);
    }
}
