//! Tucker decomposition of a 3-way tensor ([S] 2.5, 2-16, 2-17; pipeline 2's BRDF tensor over
//! material parameter × outgoing × incoming direction): T ≈ G ×₁ U₁ ×₂ U₂ ×₃ U₃ with U_n
//! (dim_n × r_n) orthonormal columns and the core G (r₁ × r₂ × r₃), by higher-order orthogonal
//! iteration (HOOI) started from the truncated higher-order SVD (HOSVD), in f64.
//!
//! - HOSVD: U_n = the r_n leading left singular vectors of the mode-n unfolding T₍ₙ₎, as the
//!   leading eigenvectors of its Gram matrix T₍ₙ₎ T₍ₙ₎ᵀ (dim_n × dim_n, small here: the
//!   unfolding itself is dim_n × the product of the other two).
//! - HOOI: for each mode in turn, U_n from the Gram matrix of T projected on the other two
//!   modes' current factors; then G = T ×₁ U₁ᵀ ×₂ U₂ᵀ ×₃ U₃ᵀ. It stops when ‖G‖² gains less
//!   than `tolerance` × ‖T‖² over a sweep (‖T − T̂‖² = ‖T‖² − ‖G‖² for orthonormal factors),
//!   or after `max_iterations` sweeps, reporting then that it did not converge.
//! - Sign: each column of each U_n has its entry of largest magnitude (the first on ties)
//!   positive, G following; ranks above a mode's numerical rank are cut to it (a zero tensor
//!   has rank 0 everywhere: an empty core, no NaN).
//!
//! Loops run in a fixed order on one thread: the same bytes every time.

use super::pca::symmetric_eigen;
use faer::Mat;
use relume_core::NodeError;

/// A dense 3-way tensor, entry (i, j, k) at (i · d₁ + j) · d₂ + k.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor3 {
    pub dims: [usize; 3],
    pub data: Vec<f64>,
}

impl Tensor3 {
    pub fn zeros(dims: [usize; 3]) -> Tensor3 {
        Tensor3 { dims, data: vec![0.0; dims.iter().product()] }
    }

    pub fn at(&self, i: usize, j: usize, k: usize) -> f64 {
        self.data[(i * self.dims[1] + j) * self.dims[2] + k]
    }

    /// ‖T‖² (the sum of squares).
    pub fn norm2(&self) -> f64 {
        self.data.iter().map(|x| x * x).sum()
    }

    /// T ×ₙ Mᵀ for `m`, dims[n] rows of `r` entries (m[a][c]): mode `n` goes from dims[n]
    /// to r.
    fn project(&self, n: usize, m: &[Vec<f64>], r: usize) -> Tensor3 {
        let mut dims = self.dims;
        dims[n] = r;
        let mut out = Tensor3::zeros(dims);
        let [d0, d1, d2] = self.dims;
        for i in 0..d0 {
            for j in 0..d1 {
                for k in 0..d2 {
                    let x = self.data[(i * d1 + j) * d2 + k];
                    if x == 0.0 {
                        continue;
                    }
                    let (a, base) = match n {
                        0 => (i, (j * dims[2]) + k),
                        1 => (j, i * dims[1] * dims[2] + k),
                        _ => (k, (i * dims[1] + j) * dims[2]),
                    };
                    let stride = match n {
                        0 => dims[1] * dims[2],
                        1 => dims[2],
                        _ => 1,
                    };
                    for (c, w) in m[a].iter().enumerate() {
                        out.data[base + c * stride] += x * w;
                    }
                }
            }
        }
        out
    }

    /// The Gram matrix of the mode-`n` unfolding (dims[n] × dims[n]): its rows gathered in
    /// one pass over the entries (a fixed order), then their dot products.
    fn gram(&self, n: usize) -> Mat<f64> {
        let d = self.dims[n];
        let mut rows = vec![Vec::with_capacity(self.data.len() / d.max(1)); d];
        let [d0, d1, d2] = self.dims;
        for i in 0..d0 {
            for j in 0..d1 {
                for k in 0..d2 {
                    rows[[i, j, k][n]].push(self.data[(i * d1 + j) * d2 + k]);
                }
            }
        }
        Mat::from_fn(d, d, |a, b| rows[a].iter().zip(&rows[b]).map(|(x, y)| x * y).sum())
    }
}

/// A Tucker decomposition and how it was reached.
#[derive(Clone, Debug)]
pub struct Tucker {
    /// Per mode, dims[n] rows of r_n entries (U_n).
    pub factors: [Vec<Vec<f64>>; 3],
    pub core: Tensor3,
    /// HOOI sweeps run.
    pub iterations: usize,
    /// Whether the gain fell below the tolerance within the limit.
    pub converged: bool,
    /// ‖T − T̂‖² / ‖T‖² (0 for a zero tensor).
    pub relative_error: f64,
}

impl Tucker {
    /// T̂ = G ×₁ U₁ ×₂ U₂ ×₃ U₃.
    pub fn reconstruct(&self) -> Tensor3 {
        let mut t = self.core.clone();
        for n in 0..3 {
            // ×ₙ U_n: project with U_nᵀ's rows, i.e. the columns of U_n as rows.
            let r = t.dims[n];
            let ut: Vec<Vec<f64>> = (0..r).map(|c| self.factors[n].iter().map(|row| row[c]).collect()).collect();
            t = t.project(n, &ut, self.factors[n].len());
        }
        t
    }
}

/// The `r` leading eigenvectors of `gram` as dims × r rows (fewer where the numerical rank
/// is lower), each column's largest-magnitude entry positive.
fn leading(gram: &Mat<f64>, r: usize) -> Result<Vec<Vec<f64>>, NodeError> {
    let d = gram.nrows();
    let (vals, vecs) = symmetric_eigen(gram)?;
    let top = vals.last().copied().unwrap_or(0.0);
    let rank = vals.iter().filter(|&&v| v > top * super::pca::RANK_TOLERANCE && v > 0.0).count();
    let r = r.min(rank);
    let mut out = vec![vec![0.0; r]; d];
    for c in 0..r {
        let col = d - 1 - c; // ascending eigenvalues: the largest last
        let mut best = 0;
        for a in 0..d {
            if vecs[(a, col)].abs() > vecs[(best, col)].abs() {
                best = a;
            }
        }
        let s = if vecs[(best, col)] < 0.0 { -1.0 } else { 1.0 };
        for (a, row) in out.iter_mut().enumerate() {
            row[c] = s * vecs[(a, col)];
        }
    }
    Ok(out)
}

/// The Tucker decomposition of `t` at `ranks` (see the module doc).
pub fn tucker(t: &Tensor3, ranks: [usize; 3], max_iterations: usize, tolerance: f64) -> Result<Tucker, NodeError> {
    if t.data.len() != t.dims.iter().product::<usize>() {
        return Err(NodeError::failed(format!(
            "a {:?} tensor needs {} entries, not {}",
            t.dims,
            t.dims.iter().product::<usize>(),
            t.data.len()
        )));
    }
    if !t.data.iter().all(|x| x.is_finite()) {
        return Err(NodeError::failed("the tensor holds a value that is not finite"));
    }
    let total = t.norm2();
    let mut factors: [Vec<Vec<f64>>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    for n in 0..3 {
        factors[n] = leading(&t.gram(n), ranks[n])?;
    }
    let rank = |f: &Vec<Vec<f64>>| f.first().map_or(0, |row| row.len());
    let core_of = |f: &[Vec<Vec<f64>>; 3]| t.project(0, &f[0], rank(&f[0])).project(1, &f[1], rank(&f[1])).project(2, &f[2], rank(&f[2]));
    let mut core = core_of(&factors);
    let (mut iterations, mut converged) = (0, total == 0.0);
    while !converged && iterations < max_iterations {
        let before = core.norm2();
        for n in 0..3 {
            let (a, b) = ((n + 1) % 3, (n + 2) % 3);
            let y = t.project(a, &factors[a], rank(&factors[a])).project(b, &factors[b], rank(&factors[b]));
            factors[n] = leading(&y.gram(n), ranks[n])?;
        }
        core = core_of(&factors);
        iterations += 1;
        converged = core.norm2() - before <= tolerance * total;
    }
    let relative_error = if total > 0.0 { ((total - core.norm2()) / total).max(0.0) } else { 0.0 };
    Ok(Tucker { factors, core, iterations, converged, relative_error })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;

    /// An orthonormal d × r basis from seeded values (Gram-Schmidt).
    fn basis(d: usize, r: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for c in 0..r {
            let mut v: Vec<f64> = (0..d).map(|a| uniform(seed, (c * d + a) as u64, 0) as f64 - 0.5).collect();
            for q in &cols {
                let p: f64 = v.iter().zip(q).map(|(x, y)| x * y).sum();
                v.iter_mut().zip(q).for_each(|(x, y)| *x -= p * y);
            }
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            cols.push(v.into_iter().map(|x| x / n).collect());
        }
        (0..d).map(|a| cols.iter().map(|c| c[a]).collect()).collect()
    }

    fn low_rank(dims: [usize; 3], ranks: [usize; 3]) -> Tensor3 {
        let mut core = Tensor3::zeros(ranks);
        for (i, x) in core.data.iter_mut().enumerate() {
            *x = uniform(7, i as u64, 0) as f64 * 2.0 - 1.0;
        }
        let f = [basis(dims[0], ranks[0], 1), basis(dims[1], ranks[1], 2), basis(dims[2], ranks[2], 3)];
        Tucker { factors: f, core, iterations: 0, converged: true, relative_error: 0.0 }.reconstruct()
    }

    #[test]
    fn an_exactly_low_rank_tensor_is_recovered() {
        let t = low_rank([9, 12, 10], [2, 3, 2]);
        let d = tucker(&t, [2, 3, 2], 20, 1e-12).unwrap();
        assert!(d.converged && d.iterations <= 3, "{} sweeps", d.iterations);
        assert!(d.relative_error < 1e-12, "{}", d.relative_error);
        let back = d.reconstruct();
        let worst = back.data.iter().zip(&t.data).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-10, "{worst}");
        // Orthonormal factors, signs fixed.
        for f in &d.factors {
            let r = f[0].len();
            for a in 0..r {
                for b in 0..r {
                    let dot: f64 = f.iter().map(|row| row[a] * row[b]).sum();
                    assert!((dot - if a == b { 1.0 } else { 0.0 }).abs() < 1e-10);
                }
                let big = f.iter().map(|row| row[a]).fold(0.0f64, |m, x| if x.abs() > m.abs() { x } else { m });
                assert!(big > 0.0);
            }
        }
        // Asking for more rank than there is gives the rank there is.
        let d = tucker(&t, [5, 5, 5], 20, 1e-12).unwrap();
        assert_eq!(d.core.dims, [2, 3, 2]);
    }

    #[test]
    fn a_zero_tensor_has_an_empty_core_and_no_nan() {
        let d = tucker(&Tensor3::zeros([4, 5, 6]), [2, 2, 2], 10, 1e-9).unwrap();
        assert!(d.converged && d.relative_error == 0.0);
        assert_eq!(d.core.dims, [0, 0, 0]);
        let back = d.reconstruct();
        assert_eq!(back.dims, [4, 5, 6]);
        assert!(back.data.len() == 120 && back.data.iter().all(|&x| x == 0.0));
    }

    #[test]
    fn the_iteration_limit_reports_non_convergence_and_truncation_costs_what_it_drops() {
        // Full rank: truncated to 2 × 2 × 2, HOOI improves on HOSVD over several sweeps.
        let mut t = Tensor3::zeros([8, 7, 6]);
        for (i, x) in t.data.iter_mut().enumerate() {
            *x = uniform(9, i as u64, 0) as f64;
        }
        let one = tucker(&t, [2, 2, 2], 1, 1e-15).unwrap();
        assert!(!one.converged && one.iterations == 1);
        let many = tucker(&t, [2, 2, 2], 200, 1e-12).unwrap();
        assert!(many.converged && many.iterations > 1, "{} sweeps", many.iterations);
        assert!(many.relative_error <= one.relative_error + 1e-15 && many.relative_error > 0.0);
        let direct = {
            let back = many.reconstruct();
            back.data.iter().zip(&t.data).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / t.norm2()
        };
        assert!((direct - many.relative_error).abs() < 1e-9, "‖T − T̂‖² = ‖T‖² − ‖G‖²: {direct} vs {}", many.relative_error);
        assert!(tucker(&Tensor3 { dims: [2, 2, 2], data: vec![f64::NAN; 8] }, [1, 1, 1], 5, 1e-9).is_err());
    }
}
