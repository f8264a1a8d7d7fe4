//! Uncentred PCA of a matrix that is never held: n rows (a few hundred to a few thousand, the
//! sub-regions of [S] 4.2) by very many columns (pixels × channels), given one column at a
//! time as a sparse vector — the spatially varying relighting's compression along r1 of a
//! group that would hold gigabytes.
//!
//! 1. `Gram::add` accumulates G = Σ_p x_p x_pᵀ from each sparse column (the lower triangle,
//!    f64, in the order the columns come). A parallel producer sums its tiles in a fixed
//!    order (`Gram::merge`): the tiling is part of the input, never the thread count, so the
//!    bytes are the same on any number of threads.
//! 2. `Gram::decompose` takes G = U Λ Uᵀ (faer, sequential, f64, as `math::pca`), keeps at
//!    most `k` components with λ above `RANK_TOLERANCE` × the largest, and fixes each
//!    eigenvector's sign: its entry of largest magnitude (the first on ties) is positive.
//! 3. A second pass over the columns projects each one: the k-vector B_k(p) = u_kᵀ x_p / σ_k
//!    (`StreamedPca::project`) — the column of the component images; row i of the matrix is
//!    rebuilt as Σ_k c_ik B_k with c_ik = σ_k u_ik (`coefficient`).

use super::pca::{symmetric_eigen, RANK_TOLERANCE};
use faer::Mat;
use relume_core::NodeError;

/// The Gram matrix of the columns seen so far (lower triangle, row-major, n (n + 1) / 2).
#[derive(Clone, Debug, PartialEq)]
pub struct Gram {
    n: usize,
    g: Vec<f64>,
}

/// Largest row count: G holds n (n + 1) / 2 f64 (64 MiB at 4096).
pub const MAX_GRAM_ROWS: usize = 4096;

impl Gram {
    pub fn new(n: usize) -> Result<Gram, NodeError> {
        if n > MAX_GRAM_ROWS {
            return Err(NodeError::failed(format!("a Gram matrix of {n} rows is over the {MAX_GRAM_ROWS} this PCA takes")));
        }
        Ok(Gram { n, g: vec![0.0; n * (n + 1) / 2] })
    }

    pub fn rows(&self) -> usize {
        self.n
    }

    /// Adds the column with entries `value[j]` at rows `index[j]` (strictly increasing).
    pub fn add(&mut self, index: &[u32], value: &[f64]) {
        debug_assert!(index.len() == value.len() && index.windows(2).all(|w| w[0] < w[1]));
        for (a, (&i, &vi)) in index.iter().zip(value).enumerate() {
            let row = i as usize * (i as usize + 1) / 2;
            for (&j, &vj) in index[..=a].iter().zip(&value[..=a]) {
                self.g[row + j as usize] += vi * vj;
            }
        }
    }

    /// The trace: the squared norm of every column seen (the energy the components share).
    pub fn trace(&self) -> f64 {
        (0..self.n).map(|i| self.g[i * (i + 1) / 2 + i]).sum()
    }

    /// Adds another Gram matrix of the same rows (a tile's, summed in tile order).
    pub fn merge(&mut self, other: &Gram) {
        assert_eq!(self.n, other.n, "Gram matrices of different sizes");
        self.g.iter_mut().zip(&other.g).for_each(|(a, b)| *a += b);
    }

    /// The components (see the module doc): at most `k`.
    pub fn decompose(&self, k: usize) -> Result<StreamedPca, NodeError> {
        let n = self.n;
        if self.g.iter().any(|v| !v.is_finite()) {
            return Err(NodeError::failed("PCA: the Gram matrix is not finite"));
        }
        // Only rows some column reached take part (a zero diagonal means a zero row), and the
        // matrix is scaled to a unit largest diagonal: sparse blocks leave most rows empty,
        // and an eigensolver meets neither the exact zeros nor tiny magnitudes.
        let diag = |i: usize| self.g[i * (i + 1) / 2 + i];
        let active: Vec<usize> = (0..n).filter(|&i| diag(i) > 0.0).collect();
        let scale = active.iter().map(|&i| diag(i)).fold(0.0f64, f64::max);
        let at = |i: usize, j: usize| if j <= i { self.g[i * (i + 1) / 2 + j] } else { self.g[j * (j + 1) / 2 + i] };
        let m = active.len();
        let (mut sigma, mut vectors) = (Vec::new(), Vec::new());
        if m == 0 {
            return Ok(StreamedPca { n, sigma, u: vectors });
        }
        let reduced = Mat::<f64>::from_fn(m, m, |a, b| at(active[a], active[b]) / scale);
        let (lambda, u) = symmetric_eigen(&reduced)?;
        let top = lambda.last().copied().unwrap_or(0.0).max(0.0);
        for c in (0..m).rev() {
            if sigma.len() == k || lambda[c] <= RANK_TOLERANCE * top || lambda[c] <= 0.0 {
                break;
            }
            let mut v = vec![0.0f64; n];
            for (a, &i) in active.iter().enumerate() {
                v[i] = u[(a, c)];
            }
            let big = (0..n).fold(0, |b, i| if v[i].abs() > v[b].abs() { i } else { b });
            if v[big] < 0.0 {
                v.iter_mut().for_each(|x| *x = -*x);
            }
            sigma.push((lambda[c] * scale).sqrt());
            vectors.push(v);
        }
        Ok(StreamedPca { n, sigma, u: vectors })
    }
}

/// The kept components of a streamed PCA.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamedPca {
    n: usize,
    /// σ_k, decreasing.
    pub sigma: Vec<f64>,
    /// u_k, each of length n.
    u: Vec<Vec<f64>>,
}

impl StreamedPca {
    pub fn components(&self) -> usize {
        self.sigma.len()
    }

    /// The components' values for one column (`out.len()` = `components()`).
    pub fn project(&self, index: &[u32], value: &[f64], out: &mut [f64]) {
        for (k, o) in out.iter_mut().enumerate() {
            let s: f64 = index.iter().zip(value).map(|(&i, &v)| self.u[k][i as usize] * v).sum();
            *o = s / self.sigma[k];
        }
    }

    /// c_ik: row i's weight on component k.
    pub fn coefficient(&self, i: usize, k: usize) -> f64 {
        debug_assert!(i < self.n);
        self.sigma[k] * self.u[k][i]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;

    /// An n × m matrix of rank r plus noise, by columns (dense, as sparse with every row).
    fn columns(n: usize, m: usize, r: usize, noise: f64, seed: u64) -> Vec<Vec<f64>> {
        let a: Vec<f64> = (0..n * r).map(|i| uniform(seed, i as u64, 0) as f64 - 0.5).collect();
        (0..m)
            .map(|p| {
                let b: Vec<f64> = (0..r).map(|k| uniform(seed, (p * r + k) as u64, 1) as f64 - 0.5).collect();
                (0..n)
                    .map(|i| (0..r).map(|k| a[i * r + k] * b[k]).sum::<f64>() + noise * (uniform(seed, (p * n + i) as u64, 2) as f64 - 0.5))
                    .collect()
            })
            .collect()
    }

    fn gram_of(cols: &[Vec<f64>], n: usize) -> Gram {
        let idx: Vec<u32> = (0..n as u32).collect();
        let mut g = Gram::new(n).unwrap();
        cols.iter().for_each(|c| g.add(&idx, c));
        g
    }

    #[test]
    fn an_exactly_low_rank_matrix_is_rebuilt_from_its_rank_many_components() {
        let (n, m, r) = (12, 300, 3);
        let cols = columns(n, m, r, 0.0, 4);
        let pca = gram_of(&cols, n).decompose(8).unwrap();
        assert_eq!(pca.components(), r, "σ = {:?}", pca.sigma);
        let idx: Vec<u32> = (0..n as u32).collect();
        let mut b = vec![0.0; r];
        for c in &cols {
            pca.project(&idx, c, &mut b);
            for (i, x) in c.iter().enumerate() {
                let rebuilt: f64 = (0..r).map(|k| pca.coefficient(i, k) * b[k]).sum();
                assert!((rebuilt - x).abs() < 1e-9, "{rebuilt} vs {x}");
            }
        }
    }

    #[test]
    fn it_agrees_with_the_batch_pca_on_every_rows_coefficients_up_to_sign() {
        let (n, m) = (10, 400);
        let cols = columns(n, m, 4, 0.05, 9);
        let streamed = gram_of(&cols, n).decompose(4).unwrap();
        // The batch route takes rows: transpose.
        let rows: Vec<f64> = (0..n).flat_map(|i| cols.iter().map(move |c| c[i])).collect();
        let batch = crate::math::pca::uncentred_pca(&rows, n, &vec![1.0; m], 4).unwrap();
        assert_eq!(batch.components(), 4);
        for i in 0..n {
            // Row i's coefficients agree up to each component's sign.
            for k in 0..4 {
                let (a, b) = (streamed.coefficient(i, k), batch.coefficients_of(i)[k]);
                assert!((a.abs() - b.abs()).abs() < 1e-8 * (1.0 + b.abs()), "row {i} component {k}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn sparse_columns_tiles_and_orders_give_the_dense_result() {
        let n = 6;
        // Columns touching a few rows each, as hemisphere rays reach a few sub-regions.
        let sparse: Vec<(Vec<u32>, Vec<f64>)> = (0..50u64)
            .map(|p| {
                let idx: Vec<u32> = (0..n as u32).filter(|&i| uniform(3, p * 8 + i as u64, 0) < 0.4).collect();
                let val = idx.iter().map(|&i| uniform(3, p * 8 + i as u64, 1) as f64).collect();
                (idx, val)
            })
            .collect();
        let mut one = Gram::new(n).unwrap();
        sparse.iter().for_each(|(i, v)| one.add(i, v));
        let dense: Vec<Vec<f64>> = sparse
            .iter()
            .map(|(idx, val)| {
                let mut c = vec![0.0; n];
                idx.iter().zip(val).for_each(|(&i, &v)| c[i as usize] = v);
                c
            })
            .collect();
        let d = gram_of(&dense, n);
        for (a, b) in one.g.iter().zip(&d.g) {
            assert!((a - b).abs() < 1e-12);
        }
        // Tiles merged in order: the same bytes every time.
        let tiled = || {
            let mut total = Gram::new(n).unwrap();
            for tile in sparse.chunks(7) {
                let mut t = Gram::new(n).unwrap();
                tile.iter().for_each(|(i, v)| t.add(i, v));
                total.merge(&t);
            }
            total
        };
        assert_eq!(tiled(), tiled());
        assert_eq!(tiled().decompose(3).unwrap(), tiled().decompose(3).unwrap());
    }

    #[test]
    fn zero_and_oversized_inputs_are_handled() {
        let g = Gram::new(5).unwrap();
        assert_eq!(g.decompose(3).unwrap().components(), 0, "a zero matrix has no component");
        assert!(Gram::new(MAX_GRAM_ROWS + 1).is_err());
        let mut bad = Gram::new(2).unwrap();
        bad.add(&[0], &[f64::NAN]);
        assert!(bad.decompose(1).is_err());
    }

    #[test]
    fn a_gram_matrix_with_mostly_empty_rows_and_tiny_values_decomposes() {
        // 1024 rows, columns touching 6 of them with values around 1e-12: what a small image's
        // sparse block gives.
        let n = 1024;
        let rows = [3u32, 40, 41, 300, 777, 1000];
        let mut g = Gram::new(n).unwrap();
        for p in 0..50u64 {
            let v: Vec<f64> = (0..rows.len()).map(|r| 1e-12 * (uniform(2, p * 8 + r as u64, 0) as f64 + 0.1)).collect();
            g.add(&rows, &v);
        }
        let pca = g.decompose(8).unwrap();
        assert_eq!(pca.components(), 6);
        let sum: f64 = pca.sigma.iter().map(|s| s * s).sum();
        assert!((sum - g.trace()).abs() < 1e-9 * g.trace(), "the components carry the whole trace");
        assert!(pca.u.iter().all(|u| (0..n as u32).filter(|i| !rows.contains(i)).all(|i| u[i as usize] == 0.0)));
        let empty = Gram::new(n).unwrap().decompose(4).unwrap();
        assert_eq!(empty.components(), 0);
    }
}
