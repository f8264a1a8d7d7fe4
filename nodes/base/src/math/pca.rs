//! Uncentred, weighted principal component analysis of an N × M matrix (N samples, a few
//! hundred; M columns, tens of thousands) by the Gram route, in f64.
//!
//! X holds one sample per row; W = diag(w) weights the columns (a quadrature weight such as a
//! solid angle), so the inner product of two rows is ⟨a, b⟩_W = Σ_l a_l w_l b_l. Uncentred:
//! no mean is subtracted (the BRDF PCA of [S] 4-20 has no mean term).
//!
//! 1. G = X W Xᵀ (N × N). Each entry is one dot product summed in a fixed order (four
//!    interleaved partial sums, column l into sum l mod 4, added as (s0 + s1) + (s2 + s3),
//!    then the tail), parallel only over blocks of four rows, so G has the same bytes on any
//!    thread count.
//! 2. G = U Λ Uᵀ with faer's self-adjoint eigen-decomposition, sequential (`Par::Seq`), f64.
//!    Order: decreasing eigenvalue. Eigenvalues below [`RANK_TOLERANCE`] × the largest (or
//!    ≤ 0) are noise: [`Pca::rank`] counts the others, and at most that many components are
//!    returned (a rank-deficient set, with duplicated or zero rows, gives fewer components,
//!    never NaN).
//! 3. Components B_k = u_kᵀ X / σ_k (σ_k = √λ_k), rows of length M, orthonormal under W.
//!    Forming them through G loses accuracy for small σ_k (the Gram matrix squares the
//!    condition number), so they are re-orthonormalised under W (modified Gram-Schmidt, two
//!    passes, in order); a component that does not survive it (its remaining norm under 10⁻⁶)
//!    ends the list.
//! 4. Sign: the entry of largest |value| of each component (the first such index on ties) is
//!    positive.
//! 5. Coefficients c_ik = ⟨x_i, B_k⟩_W (= (U Σ)_ik in exact arithmetic; computed by projection
//!    so that x_i ≈ Σ_k c_ik B_k is the best approximation in the span of the returned
//!    components even where step 3 corrected them).
//!
//! Every loop runs in a fixed order or in parallel over independent outputs, so the result
//! has the same bytes on any thread count (tested). faer's f32 thin SVD is known to be wrong
//! on the tall, low-rank-plus-noise BRDF matrix: nothing here uses f32 arithmetic (f32 input
//! is widened to f64 as it is read).

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::{self, ComputeEigenvectors};
use faer::{Mat, Par};
use relume_core::{CancelToken, NodeError, RunCtx};

/// Eigenvalues below this fraction of the largest are treated as zero (numerical rank).
pub const RANK_TOLERANCE: f64 = 1e-12;

/// Rows per parallel item of the Gram product (each item reads every earlier row once).
const GRAM_BLOCK: usize = 4;

/// Columns per parallel item when the components are formed.
const COLUMN_CHUNK: usize = 2048;

/// A component whose W-norm falls under this after re-orthonormalisation is dropped.
const SURVIVAL_NORM: f64 = 1e-6;

/// The result of [`uncentred_pca`]: `components()` W-orthonormal rows of length `cols`, in
/// order of decreasing eigenvalue, and the coefficients that rebuild each input row from them.
#[derive(Clone, Debug, PartialEq)]
pub struct Pca {
    /// Number of input rows (samples), N.
    pub rows: usize,
    /// Length of a row, M.
    pub cols: usize,
    /// λ_k of the returned components (eigenvalues of G = X W Xᵀ; σ_k² of X W^½), decreasing.
    pub eigenvalues: Vec<f64>,
    /// Every eigenvalue of G, decreasing (the returned ones first), for reports.
    pub spectrum: Vec<f64>,
    /// The components, `components() × cols`, row-major: B_k = `components[k * cols..][..cols]`.
    pub components: Vec<f64>,
    /// The coefficients, `rows × components()`, row-major: x_i ≈ Σ_k c_ik B_k.
    pub coefficients: Vec<f64>,
    /// Numerical rank: eigenvalues ≥ `RANK_TOLERANCE` × the largest (0 for a zero matrix).
    pub rank: usize,
}

impl Pca {
    /// Number of components returned: min(asked, rank), fewer only if re-orthonormalisation
    /// dropped a component.
    pub fn components(&self) -> usize {
        self.eigenvalues.len()
    }

    /// Component k (a row of length `cols`).
    pub fn component(&self, k: usize) -> &[f64] {
        &self.components[k * self.cols..(k + 1) * self.cols]
    }

    /// The coefficients of input row i, one per component.
    pub fn coefficients_of(&self, i: usize) -> &[f64] {
        let k = self.components();
        &self.coefficients[i * k..(i + 1) * k]
    }

    /// Σ_k c_ik B_k: input row i rebuilt from the components.
    pub fn reconstruct(&self, i: usize) -> Vec<f64> {
        let mut out = vec![0.0; self.cols];
        for (k, &c) in self.coefficients_of(i).iter().enumerate() {
            for (o, b) in out.iter_mut().zip(self.component(k)) {
                *o += c * b;
            }
        }
        out
    }
}

/// ⟨a, b⟩_W = Σ_l a_l w_l b_l in the fixed order of the module comment.
pub fn weighted_dot<A: Copy + Into<f64>, B: Copy + Into<f64>>(a: &[A], w: &[f64], b: &[B]) -> f64 {
    let n = a.len().min(b.len()).min(w.len());
    let mut s = [0.0f64; 4];
    let body = n - n % 4;
    for l in (0..body).step_by(4) {
        for q in 0..4 {
            s[q] += a[l + q].into() * (w[l + q] * b[l + q].into());
        }
    }
    let mut t = (s[0] + s[1]) + (s[2] + s[3]);
    for l in body..n {
        t += a[l].into() * (w[l] * b[l].into());
    }
    t
}

/// [`uncentred_pca_with`] without progress or cancellation (tests, small matrices).
pub fn uncentred_pca<T: Copy + Into<f64> + Send + Sync>(
    x: &[T],
    rows: usize,
    weights: &[f64],
    max_components: usize,
) -> Result<Pca, NodeError> {
    let cancel = CancelToken::new();
    uncentred_pca_with(x, rows, weights, max_components, &RunCtx::new("pca", &cancel, None), (0.0, 1.0))
}

/// The uncentred PCA of the module comment of `x` (`rows` × `weights.len()`, row-major),
/// keeping at most `max_components` components. Progress goes to `cx` over the fraction
/// `span` of its node's work; stops with `Cancelled` soon after the run is cancelled.
/// Errors: a shape mismatch, negative or non-finite weights, a matrix that is not finite
/// (or whose Gram product overflows), an eigen-decomposition that does not converge.
pub fn uncentred_pca_with<T: Copy + Into<f64> + Send + Sync>(
    x: &[T],
    rows: usize,
    weights: &[f64],
    max_components: usize,
    cx: &RunCtx,
    span: (f64, f64),
) -> Result<Pca, NodeError> {
    let cols = weights.len();
    if rows.checked_mul(cols) != Some(x.len()) {
        return Err(NodeError::failed(format!("PCA: {} values do not make {rows} rows of {cols} columns", x.len())));
    }
    if let Some(w) = weights.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
        return Err(NodeError::failed(format!("PCA: column weights must be finite and ≥ 0 (found {w})")));
    }
    let at = |f: f64| span.0 + (span.1 - span.0) * f;
    let row = |i: usize| &x[i * cols..(i + 1) * cols];

    // 1. The Gram matrix, lower triangle by blocks of rows, mirrored.
    cx.phase(at(0.0), at(0.8));
    let blocks = rows.div_ceil(GRAM_BLOCK);
    let parts = cx.par_map(blocks, |b| gram_block(x, rows, cols, weights, b))?;
    let mut g = Mat::<f64>::zeros(rows, rows);
    for (b, part) in parts.iter().enumerate() {
        let mut it = part.iter();
        for i in b * GRAM_BLOCK..((b + 1) * GRAM_BLOCK).min(rows) {
            for j in 0..=i {
                let v = *it.next().expect("one entry per pair");
                g[(i, j)] = v;
                g[(j, i)] = v;
            }
        }
    }
    if (0..rows).any(|i| (0..rows).any(|j| !g[(i, j)].is_finite())) {
        return Err(NodeError::failed("PCA: the matrix holds NaN or infinite values, or its Gram product overflows"));
    }

    // 2. Eigen-decomposition, sequential, eigenvalues ascending from faer.
    cx.phase(at(0.8), at(0.85));
    cx.check()?;
    let (lambda_up, u) = symmetric_eigen(&g)?;
    let order: Vec<usize> = (0..rows).rev().collect();
    let spectrum: Vec<f64> = order.iter().map(|&k| lambda_up[k]).collect();
    let largest = spectrum.first().copied().unwrap_or(0.0);
    let rank = if largest > 0.0 { spectrum.iter().take_while(|&&l| l > 0.0 && l >= RANK_TOLERANCE * largest).count() } else { 0 };
    let kept = rank.min(max_components);

    // 3. Components B_k = u_kᵀ X / σ_k, by column chunks (each entry a sum over rows in order).
    cx.phase(at(0.85), at(0.92));
    let chunks = cols.div_ceil(COLUMN_CHUNK);
    let sigma: Vec<f64> = spectrum[..kept].iter().map(|l| l.sqrt()).collect();
    let pieces = cx.par_map(chunks, |c| {
        let (c0, c1) = (c * COLUMN_CHUNK, ((c + 1) * COLUMN_CHUNK).min(cols));
        let len = c1 - c0;
        let mut out = vec![0.0f64; kept * len];
        for i in 0..rows {
            let xi = &row(i)[c0..c1];
            for k in 0..kept {
                let uik = u[(i, order[k])];
                for (o, &v) in out[k * len..(k + 1) * len].iter_mut().zip(xi) {
                    *o += uik * v.into();
                }
            }
        }
        for k in 0..kept {
            out[k * len..(k + 1) * len].iter_mut().for_each(|o| *o /= sigma[k]);
        }
        out
    })?;
    let mut comps = vec![0.0f64; kept * cols];
    for (c, piece) in pieces.iter().enumerate() {
        let (c0, c1) = (c * COLUMN_CHUNK, ((c + 1) * COLUMN_CHUNK).min(cols));
        let len = c1 - c0;
        for k in 0..kept {
            comps[k * cols + c0..k * cols + c1].copy_from_slice(&piece[k * len..(k + 1) * len]);
        }
    }
    let survived = reorthonormalise(&mut comps, cols, kept, weights, cx)?;
    comps.truncate(survived * cols);

    // 4. Sign convention.
    for k in 0..survived {
        let b = &mut comps[k * cols..(k + 1) * cols];
        if largest_entry(b).is_some_and(|l| b[l] < 0.0) {
            b.iter_mut().for_each(|v| *v = -*v);
        }
    }

    // 5. Coefficients by projection, parallel over rows.
    cx.phase(at(0.92), at(1.0));
    let coefficients: Vec<f64> = cx
        .par_map(rows, |i| (0..survived).map(|k| weighted_dot(row(i), weights, &comps[k * cols..(k + 1) * cols])).collect::<Vec<f64>>())?
        .concat();
    Ok(Pca { rows, cols, eigenvalues: spectrum[..survived].to_vec(), spectrum, components: comps, coefficients, rank })
}

/// Lower-triangle entries G_ij (j ≤ i) of the rows of block `b`, row by row.
fn gram_block<T: Copy + Into<f64>>(x: &[T], rows: usize, cols: usize, w: &[f64], b: usize) -> Vec<f64> {
    let (i0, i1) = (b * GRAM_BLOCK, ((b + 1) * GRAM_BLOCK).min(rows));
    // The block's rows, padded with its last row so the inner loop has a fixed width.
    let block: [&[T]; GRAM_BLOCK] = std::array::from_fn(|r| {
        let i = (i0 + r).min(i1 - 1);
        &x[i * cols..(i + 1) * cols]
    });
    let mut dots = vec![[0.0f64; GRAM_BLOCK]; i1];
    let body = cols - cols % 4;
    for (j, d) in dots.iter_mut().enumerate() {
        let xj = &x[j * cols..(j + 1) * cols];
        let mut s = [[0.0f64; 4]; GRAM_BLOCK];
        for l in (0..body).step_by(4) {
            let wj: [f64; 4] = std::array::from_fn(|q| w[l + q] * xj[l + q].into());
            for (sr, xr) in s.iter_mut().zip(&block) {
                for q in 0..4 {
                    sr[q] += xr[l + q].into() * wj[q];
                }
            }
        }
        for (r, xr) in block.iter().enumerate() {
            let mut t = (s[r][0] + s[r][1]) + (s[r][2] + s[r][3]);
            for l in body..cols {
                t += xr[l].into() * (w[l] * xj[l].into());
            }
            d[r] = t;
        }
    }
    let mut out = Vec::with_capacity((i0..i1).map(|i| i + 1).sum());
    for i in i0..i1 {
        out.extend(dots[..=i].iter().map(|d| d[i - i0]));
    }
    out
}

/// Eigenvalues (ascending) and eigenvectors (columns) of the symmetric matrix `g`,
/// sequentially, so the bytes never depend on a thread pool.
pub(crate) fn symmetric_eigen(g: &Mat<f64>) -> Result<(Vec<f64>, Mat<f64>), NodeError> {
    let n = g.nrows();
    let mut s = Diag::<f64>::zeros(n);
    let mut u = Mat::<f64>::zeros(n, n);
    if n == 0 {
        return Ok((Vec::new(), u));
    }
    let scratch = evd::self_adjoint_evd_scratch::<f64>(n, ComputeEigenvectors::Yes, Par::Seq, Default::default());
    let mut mem = MemBuffer::new(scratch);
    if let Some(i) = (0..n * n).find(|&k| !g[(k % n, k / n)].is_finite()) {
        return Err(NodeError::failed(format!("entry ({}, {}) of a {n} × {n} Gram matrix is not finite", i % n, i / n)));
    }
    match evd::self_adjoint_evd(g.as_ref(), s.as_mut(), Some(u.as_mut()), Par::Seq, MemStack::new(&mut mem), Default::default()) {
        Ok(()) => Ok((s.column_vector().iter().copied().collect(), u)),
        // Measured: faer 0.24's divide and conquer reports NoConvergence on some finite,
        // exactly symmetric 390 × 390 covariance matrices (envlit's clustering features);
        // cyclic Jacobi always converges on a symmetric matrix.
        Err(_) => Ok(jacobi_eigen(g)),
    }
}

/// Eigenvalues (ascending) and eigenvectors (columns) of the symmetric matrix `g` by cyclic
/// Jacobi rotations (sweeps until the off-diagonal mass is under 10⁻³⁰ of the total, at most
/// 100), in a fixed order.
fn jacobi_eigen(g: &Mat<f64>) -> (Vec<f64>, Mat<f64>) {
    let n = g.nrows();
    let mut a = g.clone();
    let mut v = Mat::<f64>::identity(n, n);
    let total: f64 = (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).map(|(i, j)| a[(i, j)] * a[(i, j)]).sum();
    for _ in 0..100 {
        let off: f64 = (0..n).flat_map(|i| (0..i).map(move |j| (i, j))).map(|(i, j)| a[(i, j)] * a[(i, j)]).sum();
        if off <= 1e-30 * total {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[(p, q)];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[(q, q)] - a[(p, p)]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let (c, s) = (1.0 / (t * t + 1.0).sqrt(), t / (t * t + 1.0).sqrt());
                for k in 0..n {
                    let (akp, akq) = (a[(k, p)], a[(k, q)]);
                    a[(k, p)] = c * akp - s * akq;
                    a[(k, q)] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[(p, k)], a[(q, k)]);
                    a[(p, k)] = c * apk - s * aqk;
                    a[(q, k)] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[(k, p)], v[(k, q)]);
                    v[(k, p)] = c * vkp - s * vkq;
                    v[(k, q)] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&x, &y| a[(x, x)].total_cmp(&a[(y, y)]).then(x.cmp(&y)));
    let values = order.iter().map(|&k| a[(k, k)]).collect();
    let vectors = Mat::from_fn(n, n, |i, j| v[(i, order[j])]);
    (values, vectors)
}

/// The (at most) `r` leading eigenvectors of the symmetric matrix `g` (n × n) and their
/// eigenvalues, decreasing: `(eigenvalues, vectors)`, the vectors as rows of length n,
/// row-major. No more than the numerical rank are returned (eigenvalues > 0 and ≥
/// [`RANK_TOLERANCE`] × the largest: a zero matrix gives none), and each vector's entry of
/// largest magnitude (the first on ties) is positive. Sequential, as `symmetric_eigen`.
pub fn leading_eigenvectors(g: &Mat<f64>, r: usize) -> Result<(Vec<f64>, Vec<f64>), NodeError> {
    let n = g.nrows();
    let (ascending, u) = symmetric_eigen(g)?;
    let largest = ascending.last().copied().unwrap_or(0.0);
    let rank = if largest > 0.0 { ascending.iter().rev().take_while(|&&l| l > 0.0 && l >= RANK_TOLERANCE * largest).count() } else { 0 };
    let kept = r.min(rank);
    let mut vectors = Vec::with_capacity(kept * n);
    for k in 0..kept {
        let start = vectors.len();
        vectors.extend((0..n).map(|a| u[(a, n - 1 - k)]));
        let v = &mut vectors[start..];
        if largest_entry(v).is_some_and(|l| v[l] < 0.0) {
            v.iter_mut().for_each(|x| *x = -*x);
        }
    }
    Ok((ascending.iter().rev().take(kept).copied().collect(), vectors))
}

/// Modified Gram-Schmidt under W, two passes, over the first `k` rows of `b` (each of W-norm
/// ≈ 1 as formed); returns how many leading rows survive (a row left with W-norm under
/// `SURVIVAL_NORM` after the projections ends the list).
fn reorthonormalise(b: &mut [f64], cols: usize, k: usize, w: &[f64], cx: &RunCtx) -> Result<usize, NodeError> {
    for i in 0..k {
        cx.check()?;
        let (done, rest) = b.split_at_mut(i * cols);
        let bi = &mut rest[..cols];
        for _pass in 0..2 {
            for j in 0..i {
                let bj = &done[j * cols..(j + 1) * cols];
                let p = weighted_dot(bi, w, bj);
                for (v, q) in bi.iter_mut().zip(bj) {
                    *v -= p * q;
                }
            }
        }
        let norm = weighted_dot(bi, w, bi).sqrt();
        if !(norm > SURVIVAL_NORM && norm.is_finite()) {
            return Ok(i);
        }
        bi.iter_mut().for_each(|v| *v /= norm);
    }
    Ok(k)
}

/// Index of the entry of largest magnitude (the first on ties); `None` for an empty slice.
pub(crate) fn largest_entry(b: &[f64]) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (l, v) in b.iter().enumerate() {
        if best.is_none_or(|(_, m)| v.abs() > m) {
            best = Some((l, v.abs()));
        }
    }
    best.map(|(l, _)| l)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_agrees_with_faer_on_a_symmetric_matrix() {
        let n = 40;
        let x: Vec<f64> = (0..n * 60).map(|k| crate::math::rng::uniform(4, k as u64, 0) as f64 - 0.5).collect();
        let g = Mat::<f64>::from_fn(n, n, |a, b| (0..60).map(|i| x[a * 60 + i] * x[b * 60 + i]).sum());
        let (fv, _) = symmetric_eigen(&g).expect("faer");
        let (jv, ju) = jacobi_eigen(&g);
        for (a, b) in fv.iter().zip(&jv) {
            assert!((a - b).abs() < 1e-10 * fv[n - 1], "{a} vs {b}");
        }
        // G u = λ u for each column, and the columns are orthonormal.
        for k in 0..n {
            for i in 0..n {
                let gu: f64 = (0..n).map(|j| g[(i, j)] * ju[(j, k)]).sum();
                assert!((gu - jv[k] * ju[(i, k)]).abs() < 1e-9 * fv[n - 1]);
            }
            let norm: f64 = (0..n).map(|i| ju[(i, k)] * ju[(i, k)]).sum();
            assert!((norm - 1.0).abs() < 1e-10);
        }
    }
    use crate::math::rng::uniform;
    use proptest::prelude::*;

    /// A uniform number in [-1, 1) from (seed, index).
    fn r(seed: u64, i: u64) -> f64 {
        uniform(seed, i, 0) as f64 * 2.0 - 1.0
    }

    /// Rows of `k` × `n` orthonormal under the weights `w` (Gram-Schmidt of random rows).
    fn orthonormal_rows(k: usize, n: usize, w: &[f64], seed: u64) -> Vec<Vec<f64>> {
        let mut out: Vec<Vec<f64>> = Vec::new();
        let mut draw = 0u64;
        while out.len() < k {
            let mut v: Vec<f64> = (0..n)
                .map(|_| {
                    draw += 1;
                    r(seed, draw)
                })
                .collect();
            for _ in 0..2 {
                for q in &out {
                    let p = weighted_dot(&v, w, q);
                    v.iter_mut().zip(q).for_each(|(a, b)| *a -= p * b);
                }
            }
            let norm = weighted_dot(&v, w, &v).sqrt();
            if norm > 1e-3 {
                out.push(v.iter().map(|a| a / norm).collect());
            }
        }
        out
    }

    /// An `n` × `m` matrix of rank exactly `rank` with W-singular values in [0.5, 2]:
    /// X = A diag(s) B with orthonormal columns of A and W-orthonormal rows of B.
    fn rank_r(n: usize, m: usize, rank: usize, w: &[f64], seed: u64) -> Vec<f64> {
        let a = orthonormal_rows(rank, n, &vec![1.0; n], seed ^ 0xa);
        let b = orthonormal_rows(rank, m, w, seed ^ 0xb);
        let s: Vec<f64> = (0..rank).map(|k| 0.5 + 1.5 * uniform(seed, 1000 + k as u64, 1) as f64).collect();
        let mut x = vec![0.0; n * m];
        for i in 0..n {
            for l in 0..m {
                x[i * m + l] = (0..rank).map(|k| a[k][i] * s[k] * b[k][l]).sum();
            }
        }
        x
    }

    fn weights(m: usize, seed: u64) -> Vec<f64> {
        (0..m).map(|l| 0.1 + 1.9 * uniform(seed, l as u64, 2) as f64).collect()
    }

    fn frobenius(v: &[f64]) -> f64 {
        v.iter().map(|x| x * x).sum::<f64>().sqrt()
    }

    /// max |B W Bᵀ − I|.
    fn orthonormality_error(p: &Pca, w: &[f64]) -> f64 {
        let mut worst: f64 = 0.0;
        for a in 0..p.components() {
            for b in 0..p.components() {
                let d = weighted_dot(p.component(a), w, p.component(b)) - if a == b { 1.0 } else { 0.0 };
                worst = worst.max(d.abs());
            }
        }
        worst
    }

    fn check_sign_convention(p: &Pca) {
        for k in 0..p.components() {
            let b = p.component(k);
            let l = largest_entry(b).unwrap();
            assert!(b[l] > 0.0, "component {k}: its largest entry {} is not positive", b[l]);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

        #[test]
        fn a_rank_r_matrix_is_rebuilt_by_r_or_more_components(
            n in 2usize..14, m in 2usize..60, r_frac in 0.0f64..1.0, extra in 0usize..3, seed in 0u64..1_000_000
        ) {
            let rank = 1 + ((n.min(m) - 1) as f64 * r_frac) as usize;
            let w = weights(m, seed);
            let x = rank_r(n, m, rank, &w, seed);
            let p = uncentred_pca(&x, n, &w, rank + extra).unwrap();
            prop_assert_eq!(p.rank, rank, "spectrum {:?}", p.spectrum);
            prop_assert_eq!(p.components(), rank);
            let mut worst: f64 = 0.0;
            for i in 0..n {
                let back = p.reconstruct(i);
                let d: Vec<f64> = back.iter().zip(&x[i * m..(i + 1) * m]).map(|(a, b)| a - b).collect();
                worst = worst.max(frobenius(&d));
            }
            prop_assert!(worst <= 1e-10 * frobenius(&x).max(1.0), "reconstruction error {worst:e}");
            prop_assert!(orthonormality_error(&p, &w) < 1e-10, "B W Bᵀ − I = {:e}", orthonormality_error(&p, &w));
            check_sign_convention(&p);
            // The coefficients are U Σ: their columns are orthogonal with squared norms λ_k.
            for a in 0..p.components() {
                for b in 0..p.components() {
                    let d: f64 = (0..n).map(|i| p.coefficients_of(i)[a] * p.coefficients_of(i)[b]).sum();
                    let expect = if a == b { p.eigenvalues[a] } else { 0.0 };
                    prop_assert!((d - expect).abs() <= 1e-9 * p.eigenvalues[0], "cᵀc[{a}][{b}] = {d} vs {expect}");
                }
            }
        }

        #[test]
        fn fewer_components_than_the_rank_are_the_leading_ones(n in 3usize..10, m in 3usize..40, seed in 0u64..1_000_000) {
            let w = weights(m, seed);
            let rank = n.min(m);
            let x = rank_r(n, m, rank, &w, seed);
            let all = uncentred_pca(&x, n, &w, rank).unwrap();
            let two = uncentred_pca(&x, n, &w, 2).unwrap();
            prop_assert_eq!(two.components(), 2);
            prop_assert!(all.eigenvalues.windows(2).all(|p| p[0] >= p[1]), "decreasing");
            // The leading components agree (same G, same eigenvectors, same convention).
            for l in 0..2 * m {
                prop_assert!((all.components[l] - two.components[l]).abs() < 1e-9);
            }
        }

        #[test]
        fn rank_deficient_sets_give_finite_output_and_the_right_rank(
            n in 2usize..8, m in 2usize..40, dup in 1usize..4, zeros in 0usize..3, seed in 0u64..1_000_000
        ) {
            let w = weights(m, seed);
            let rank = 1 + (seed as usize % n.min(m));
            let base = rank_r(n, m, rank, &w, seed);
            // Every row repeated `dup` times, then `zeros` zero rows, interleaved.
            let mut x = Vec::new();
            for i in 0..n {
                for _ in 0..dup {
                    x.extend_from_slice(&base[i * m..(i + 1) * m]);
                }
                if i < zeros {
                    x.extend(std::iter::repeat_n(0.0, m));
                }
            }
            let rows = x.len() / m;
            let p = uncentred_pca(&x, rows, &w, rows).unwrap();
            prop_assert_eq!(p.rank, rank, "spectrum {:?}", p.spectrum);
            prop_assert_eq!(p.components(), rank);
            prop_assert!(p.components.iter().chain(&p.coefficients).chain(&p.eigenvalues).all(|v| v.is_finite()));
            prop_assert!(orthonormality_error(&p, &w) < 1e-10);
            for i in 0..rows {
                let back = p.reconstruct(i);
                let err = back.iter().zip(&x[i * m..(i + 1) * m]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                prop_assert!(err < 1e-10, "row {i}: {err:e}");
            }
            check_sign_convention(&p);
        }
    }

    #[test]
    fn reruns_and_thread_counts_give_identical_bytes() {
        let (n, m) = (37, 5003);
        let w = weights(m, 4);
        // Low rank plus noise, in f32 as the BRDF tables are.
        let x: Vec<f32> = rank_r(n, m, 6, &w, 4).iter().enumerate().map(|(i, v)| (v + 1e-4 * r(9, i as u64)) as f32).collect();
        let on = |threads| {
            rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| uncentred_pca(&x, n, &w, 8).unwrap())
        };
        let one = on(1);
        for threads in [1, 2, 3, 8] {
            let p = on(threads);
            assert_eq!(p, one, "{threads} threads");
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&p.components), bits(&one.components));
            assert_eq!(bits(&p.coefficients), bits(&one.coefficients));
        }
        check_sign_convention(&one);
        assert_eq!(one.components(), 8);
    }

    #[test]
    fn a_zero_matrix_and_an_empty_one_have_rank_zero() {
        let p = uncentred_pca(&[0.0f64; 12], 3, &[1.0; 4], 2).unwrap();
        assert_eq!((p.rank, p.components(), p.coefficients.len()), (0, 0, 0));
        let e = uncentred_pca::<f64>(&[], 0, &[1.0; 4], 2).unwrap();
        assert_eq!((e.rank, e.components()), (0, 0));
    }

    #[test]
    fn bad_shapes_weights_and_values_are_errors() {
        assert!(uncentred_pca(&[1.0f64; 5], 2, &[1.0; 3], 1).unwrap_err().to_string().contains("5 values"));
        assert!(uncentred_pca(&[1.0f64; 6], 2, &[1.0, -1.0, 1.0], 1).unwrap_err().to_string().contains("≥ 0"));
        assert!(uncentred_pca(&[1.0, f64::NAN, 0.0, 0.0], 2, &[1.0; 2], 1).unwrap_err().to_string().contains("NaN"));
        assert!(uncentred_pca(&[1e300f64, 1e300, 0.0, 0.0], 2, &[1.0; 2], 1).unwrap_err().to_string().contains("overflows"));
    }

    #[test]
    fn zero_weight_columns_do_not_count() {
        // Two rows that differ only in a column of weight 0 are one direction under W.
        let x = [1.0f64, 2.0, 5.0, 1.0, 2.0, -7.0];
        let p = uncentred_pca(&x, 2, &[1.0, 1.0, 0.0], 2).unwrap();
        assert_eq!(p.rank, 1);
    }

    #[test]
    fn leading_eigenvectors_are_cut_to_the_rank_and_signed() {
        let g = Mat::from_fn(2, 2, |i, j| if i == j { 2.0 } else { 1.0 });
        let (l, v) = leading_eigenvectors(&g, 5).unwrap();
        assert_eq!(l.len(), 2);
        assert!((l[0] - 3.0).abs() < 1e-14 && (l[1] - 1.0).abs() < 1e-14);
        let h = 0.5f64.sqrt();
        // (1, 1)/√2, then (1, −1)/√2: on a tie of magnitudes the first entry is the positive one.
        for (a, b) in v.iter().zip([h, h, h, -h]) {
            assert!((a - b).abs() < 1e-14, "{v:?}");
        }
        assert_eq!(leading_eigenvectors(&Mat::zeros(3, 3), 2).unwrap(), (vec![], vec![]));
    }

    #[test]
    fn a_column_of_ones_has_one_component_with_the_known_eigenvalue() {
        // X = [1 1 1; 2 2 2], W = I: G = [[3, 6], [6, 12]], λ = 15, B = (1, 1, 1)/√3.
        let p = uncentred_pca(&[1.0f64, 1.0, 1.0, 2.0, 2.0, 2.0], 2, &[1.0; 3], 2).unwrap();
        assert_eq!(p.components(), 1);
        assert!((p.eigenvalues[0] - 15.0).abs() < 1e-12);
        assert!(p.component(0).iter().all(|b| (b - 1.0 / 3f64.sqrt()).abs() < 1e-14));
        assert!((p.coefficients_of(1)[0] - 2.0 * 3f64.sqrt()).abs() < 1e-12);
    }
}
