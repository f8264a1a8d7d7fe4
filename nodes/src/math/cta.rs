//! Tensor approximation of one vertex cluster's bounce transfer ([S] 5.3.3.4, after Tsai &
//! Shih 2006's clustered tensor approximation, CTA): the cluster's transfer X, a V × L × S
//! tensor (vertices × lighting bases × columns, the columns being channel × SH coefficient),
//! is approximated as X ≈ G ×_v A ×_l B with A (V × r_v) and B (L × r_l) of orthonormal
//! columns and the core G (r_v × r_l × S); the column mode is kept whole, as the thesis keeps
//! the SH mode ("另外一个维度 S 则保持不变").
//!
//! Fitted by HOSVD (B from the Gram matrix Σ_v X_v X_vᵀ of the lighting mode, then A from the
//! Gram matrix of X projected on B) and `sweeps` rounds of HOOI (each factor again from the
//! Gram matrix of X projected on the other). The Gram matrices are formed by f32 matrix
//! products (faer, sequential) over fixed blocks of vertices summed in block order, so the
//! bytes do not depend on the thread count; their eigenvectors in f64 with `pca`'s sign
//! convention and numerical rank cut (`pca::leading_eigenvectors`). ‖X − X̂‖² = ‖X‖² − ‖G‖²
//! for orthonormal factors.

use super::pca::leading_eigenvectors;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use rayon::prelude::*;
use relume_core::NodeError;
use serde::{Deserialize, Serialize};

/// Vertices per block of the Gram sums (fixed: the sums' order never depends on threads).
const BLOCK: usize = 64;

/// One cluster's approximation (see the module doc). Row-major: `a` is V × r_v (vertex v's
/// row at v · r_v), `b` is r_l × L (basis row b at b · L), `core` is r_v × r_l × S.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClusterTensor {
    pub vertices: u32,
    pub lights: u32,
    pub columns: u32,
    pub rank_v: u32,
    pub rank_l: u32,
    #[serde(with = "crate::types::pod_vec")]
    pub a: Vec<f32>,
    #[serde(with = "crate::types::pod_vec")]
    pub b: Vec<f32>,
    #[serde(with = "crate::types::pod_vec")]
    pub core: Vec<f32>,
    /// ‖X‖² and ‖X − X̂‖².
    pub norm2: f64,
    pub error2: f64,
}

/// Σ_v M_v M_vᵀ over `count` row-major blocks M_v (rows × cols) laid end to end in `x`, in
/// fixed blocks of vertices summed in order.
fn gram_sum(x: &[f32], count: usize, rows: usize, cols: usize) -> Mat<f64> {
    let blocks: Vec<Mat<f32>> = (0..count.div_ceil(BLOCK))
        .into_par_iter()
        .map(|k| {
            let mut g = Mat::<f32>::zeros(rows, rows);
            for v in k * BLOCK..((k + 1) * BLOCK).min(count) {
                let m = MatRef::from_row_major_slice(&x[v * rows * cols..(v + 1) * rows * cols], rows, cols);
                matmul(g.as_mut(), Accum::Add, m, m.transpose(), 1.0f32, Par::Seq);
            }
            g
        })
        .collect();
    let mut g = Mat::<f64>::zeros(rows, rows);
    for b in &blocks {
        for j in 0..rows {
            for i in 0..rows {
                g[(i, j)] += b[(i, j)] as f64;
            }
        }
    }
    g
}

/// Y Yᵀ for Y row-major (n × cols), in row blocks computed in parallel (each entry one dot
/// product: no order to keep).
fn gram_rows(y: &[f32], n: usize, cols: usize) -> Mat<f64> {
    let ym = MatRef::from_row_major_slice(y, n, cols);
    let blocks: Vec<Mat<f32>> = (0..n.div_ceil(BLOCK))
        .into_par_iter()
        .map(|k| {
            let (r0, r1) = (k * BLOCK, ((k + 1) * BLOCK).min(n));
            let mut g = Mat::<f32>::zeros(r1 - r0, n);
            matmul(g.as_mut(), Accum::Replace, ym.subrows(r0, r1 - r0), ym.transpose(), 1.0f32, Par::Seq);
            g
        })
        .collect();
    Mat::from_fn(n, n, |i, j| blocks[i / BLOCK][(i % BLOCK, j)] as f64)
}

/// Per vertex v, P · X_v (P: p × L row-major, X_v: L × S), as a V × (p · S) row-major matrix.
fn project_lights(x: &[f32], v: usize, l: usize, s: usize, p: &[f32], rp: usize) -> Vec<f32> {
    let pm = MatRef::from_row_major_slice(p, rp, l);
    let rows: Vec<Vec<f32>> = (0..v)
        .into_par_iter()
        .map(|k| {
            let xv = MatRef::from_row_major_slice(&x[k * l * s..(k + 1) * l * s], l, s);
            let mut out = Mat::<f32>::zeros(rp, s);
            matmul(out.as_mut(), Accum::Replace, pm, xv, 1.0f32, Par::Seq);
            (0..rp * s).map(|i| out[(i / s, i % s)]).collect()
        })
        .collect();
    rows.concat()
}

/// Aᵀ X as r_v matrices L × S (A: V × r_v row-major), summed over fixed vertex blocks in order.
fn project_vertices(x: &[f32], v: usize, l: usize, s: usize, a: &[f32], rv: usize) -> Vec<f32> {
    let parts: Vec<Vec<f32>> = (0..v.div_ceil(BLOCK))
        .into_par_iter()
        .map(|k| {
            let (v0, v1) = (k * BLOCK, ((k + 1) * BLOCK).min(v));
            let am = MatRef::from_row_major_slice(&a[v0 * rv..v1 * rv], v1 - v0, rv);
            let xm = MatRef::from_row_major_slice(&x[v0 * l * s..v1 * l * s], v1 - v0, l * s);
            let mut out = Mat::<f32>::zeros(rv, l * s);
            matmul(out.as_mut(), Accum::Replace, am.transpose(), xm, 1.0f32, Par::Seq);
            (0..rv * l * s).map(|i| out[(i / (l * s), i % (l * s))]).collect()
        })
        .collect();
    let mut z = vec![0.0f32; rv * l * s];
    for p in &parts {
        z.iter_mut().zip(p).for_each(|(a, b)| *a += b);
    }
    z
}

/// Eigenvalues under this fraction of the largest are rounding of the f32 Gram sums, not
/// signal: directions under it are cut (they hold at most 10⁻⁶ of the energy each).
const F32_RANK_FLOOR: f64 = 1e-6;

/// The leading `r` eigenvectors of `g` as rows (f32), cut to its numerical rank at f32
/// precision.
fn leading_rows(g: &Mat<f64>, r: usize) -> Result<(Vec<f32>, usize), NodeError> {
    let (values, vectors) = leading_eigenvectors(g, r)?;
    let kept = values.iter().take_while(|&&x| x >= F32_RANK_FLOOR * values[0]).count();
    let n = g.nrows();
    Ok((vectors[..kept * n].iter().map(|&x| x as f32).collect(), kept))
}

/// Approximates the cluster tensor `x` (V × L × S row-major) with ranks (`rank_v`, `rank_l`)
/// (cut to the numerical ranks) and `sweeps` HOOI rounds after the HOSVD start.
pub fn compress(x: &[f32], [v, l, s]: [usize; 3], rank_v: usize, rank_l: usize, sweeps: usize) -> Result<ClusterTensor, NodeError> {
    if x.len() != v * l * s {
        return Err(NodeError::failed(format!("a cluster tensor of {} values is not {v} × {l} × {s}", x.len())));
    }
    if let Some(i) = x.iter().position(|t| !t.is_finite()) {
        return Err(NodeError::failed(format!("value {i} of the cluster's transfer is not finite")));
    }
    let norm2: f64 = x.iter().map(|&t| t as f64 * t as f64).sum();
    // HOSVD: lighting mode from the whole tensor, then the vertex mode from X projected on it.
    let (mut b, mut rl) = leading_rows(&gram_sum(x, v, l, s), rank_l)?;
    let mut y = project_lights(x, v, l, s, &b, rl);
    let (mut a_rows, mut rv) = leading_rows(&gram_rows(&y, v, rl * s), rank_v)?;
    let to_columns = |rows: &[f32], r: usize| -> Vec<f32> { (0..v * r).map(|i| rows[(i % r) * v + i / r]).collect() };
    let mut a = to_columns(&a_rows, rv);
    for _ in 0..sweeps {
        let z = project_vertices(x, v, l, s, &a, rv);
        (b, rl) = leading_rows(&gram_sum(&z, rv, l, s), rank_l)?;
        y = project_lights(x, v, l, s, &b, rl);
        (a_rows, rv) = leading_rows(&gram_rows(&y, v, rl * s), rank_v)?;
        a = to_columns(&a_rows, rv);
    }
    // Core: Aᵀ Y, r_v × (r_l · S).
    let core = project_vertices(&y, v, rl, s, &a, rv);
    let core_norm2: f64 = core.iter().map(|&t| t as f64 * t as f64).sum();
    Ok(ClusterTensor {
        vertices: v as u32,
        lights: l as u32,
        columns: s as u32,
        rank_v: rv as u32,
        rank_l: rl as u32,
        a,
        b,
        core,
        norm2,
        error2: (norm2 - core_norm2).max(0.0),
    })
}

impl ClusterTensor {
    /// Floats held.
    pub fn floats(&self) -> usize {
        self.a.len() + self.b.len() + self.core.len()
    }

    /// The floats a cluster of `v` vertices holds at these ranks (at most).
    pub fn floats_for(v: usize, l: usize, s: usize, rank_v: usize, rank_l: usize) -> usize {
        v * rank_v + rank_l * l + rank_v * rank_l * s
    }

    /// Vertex `k`'s rebuilt L × S slice (for tests and error reports).
    pub fn vertex(&self, k: usize) -> Vec<f32> {
        let (l, s, rv, rl) = (self.lights as usize, self.columns as usize, self.rank_v as usize, self.rank_l as usize);
        let mut out = vec![0.0f32; l * s];
        for a in 0..rv {
            let w = self.a[k * rv + a];
            for bi in 0..rl {
                let row = &self.b[bi * l..(bi + 1) * l];
                let g = &self.core[(a * rl + bi) * s..(a * rl + bi + 1) * s];
                for (li, &bl) in row.iter().enumerate() {
                    for (o, &c) in out[li * s..(li + 1) * s].iter_mut().zip(g) {
                        *o += w * bl * c;
                    }
                }
            }
        }
        out
    }

    /// The lighting-contracted core for box-basis weights `light` (L values): per vertex
    /// factor a, the S columns Σ_b G(a, b, ·) Σ_l B(b, l) light_l; a vertex's transfer under
    /// that lighting is then Σ_a A(v, a) × row a.
    pub fn light_core(&self, light: &[f32]) -> Vec<f32> {
        let (l, s, rv, rl) = (self.lights as usize, self.columns as usize, self.rank_v as usize, self.rank_l as usize);
        let w: Vec<f32> = (0..rl).map(|bi| self.b[bi * l..(bi + 1) * l].iter().zip(light).map(|(x, y)| x * y).sum()).collect();
        let mut out = vec![0.0f32; rv * s];
        for a in 0..rv {
            for (bi, wb) in w.iter().enumerate() {
                let g = &self.core[(a * rl + bi) * s..(a * rl + bi + 1) * s];
                out[a * s..(a + 1) * s].iter_mut().zip(g).for_each(|(o, c)| *o += wb * c);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::uniform;

    /// A V × L × S tensor of exact ranks (rv, rl) in the first two modes.
    fn low_rank(v: usize, l: usize, s: usize, rv: usize, rl: usize, seed: u64) -> Vec<f32> {
        let r = |k: u64| uniform(seed, k, 0) * 2.0 - 1.0;
        let a: Vec<f32> = (0..v * rv).map(|k| r(k as u64)).collect();
        let b: Vec<f32> = (0..l * rl).map(|k| r(100_000 + k as u64)).collect();
        let g: Vec<f32> = (0..rv * rl * s).map(|k| r(200_000 + k as u64)).collect();
        let mut x = vec![0.0f32; v * l * s];
        for i in 0..v {
            for j in 0..l {
                for c in 0..s {
                    let mut t = 0.0;
                    for p in 0..rv {
                        for q in 0..rl {
                            t += a[i * rv + p] * b[j * rl + q] * g[(p * rl + q) * s + c];
                        }
                    }
                    x[(i * l + j) * s + c] = t;
                }
            }
        }
        x
    }

    #[test]
    fn an_exactly_low_rank_cluster_is_recovered() {
        let (v, l, s) = (150, 24, 10);
        let x = low_rank(v, l, s, 4, 5, 3);
        let t = compress(&x, [v, l, s], 8, 8, 1).expect("compresses");
        assert_eq!((t.rank_v, t.rank_l), (4, 5), "ranks cut to the numerical ranks");
        let worst = (0..v)
            .map(|k| t.vertex(k).iter().zip(&x[k * l * s..(k + 1) * l * s]).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max))
            .fold(0.0f32, f32::max);
        let peak = x.iter().fold(0.0f32, |m, y| m.max(y.abs()));
        assert!(worst < 1e-4 * peak, "worst {worst} of {peak}");
        assert!(t.error2 < 1e-8 * t.norm2);
    }

    #[test]
    fn lower_ranks_lose_what_the_error_identity_says_and_sweeps_do_not_hurt() {
        let (v, l, s) = (120, 20, 6);
        let mut x = low_rank(v, l, s, 6, 6, 5);
        x.iter_mut().enumerate().for_each(|(k, y)| *y += 0.05 * (uniform(9, k as u64, 0) - 0.5));
        let t0 = compress(&x, [v, l, s], 3, 4, 0).expect("hosvd");
        let t2 = compress(&x, [v, l, s], 3, 4, 2).expect("hooi");
        // The identity: the rebuilt tensor's error equals ‖X‖² − ‖G‖².
        let direct: f64 = (0..v)
            .map(|k| t2.vertex(k).iter().zip(&x[k * l * s..(k + 1) * l * s]).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>())
            .sum();
        assert!((direct / t2.error2 - 1.0).abs() < 1e-3, "{direct} vs {}", t2.error2);
        assert!(t2.error2 <= t0.error2 * (1.0 + 1e-4), "HOOI {} after HOSVD {}", t2.error2, t0.error2);
        assert!(t2.error2 > 0.0 && t2.error2 < t2.norm2);
        // Lighting contraction agrees with the rebuilt slices.
        let light: Vec<f32> = (0..l).map(|j| 1.0 + j as f32 * 0.1).collect();
        let lc = t2.light_core(&light);
        let k = 17;
        let rebuilt = t2.vertex(k);
        for c in 0..s {
            let via_core: f32 = (0..t2.rank_v as usize).map(|a| t2.a[k * t2.rank_v as usize + a] * lc[a * s + c]).sum();
            let via_slice: f32 = (0..l).map(|j| light[j] * rebuilt[j * s + c]).sum();
            assert!((via_core - via_slice).abs() < 1e-4 * via_slice.abs().max(1.0), "{via_core} vs {via_slice}");
        }
    }

    #[test]
    fn a_zero_cluster_has_rank_zero_and_the_same_bytes_on_one_thread() {
        let t = compress(&vec![0.0; 5 * 4 * 3], [5, 4, 3], 2, 2, 1).expect("zero");
        assert_eq!((t.rank_v, t.rank_l, t.error2), (0, 0, 0.0));
        assert!(t.vertex(2).iter().all(|v| *v == 0.0));
        let x = low_rank(200, 16, 8, 5, 5, 7);
        let many = compress(&x, [200, 16, 8], 4, 4, 1).expect("runs");
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| compress(&x, [200, 16, 8], 4, 4, 1).expect("runs"));
        assert_eq!(many, one);
        assert!(compress(&[f32::NAN; 6], [1, 2, 3], 1, 1, 0).is_err());
    }
}
