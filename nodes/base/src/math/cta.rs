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
//!
//! The vertex factor A holds the leading left singular vectors of Y = X projected on B
//! (V × r_l·S). Where V > r_l·S it comes from the smaller Gram matrix Yᵀ Y (r_l·S square)
//! instead of Y Yᵀ (V × V): its eigenvectors W (same rank cut) give A = Y W Λ^-½, formed in
//! f64 per vertex, then re-orthonormalised (modified Gram–Schmidt, two passes, in column
//! order, as `pca` does) and signed by `pca`'s rule (each column's entry of largest magnitude,
//! the first on ties, positive). Measured (`time_a_large_cluster`, 2 cores, one sweep, ranks
//! (32, 16)) on a 3,000-vertex cluster at L = 96, S = 48: 12.9 s through the 3,000 × 3,000
//! eigenproblem (f64), 0.4 s through the 768 × 768 one, at the same error; the gain shrinks
//! as r_l·S nears V (none at r_l·S = 3,072 against V = 3,118). The lighting factor needs no
//! such switch: its Gram matrix is L × L (L ≤ 384) against the r_v·S (or V·S) columns of the
//! other side.

use super::pca::{largest_entry, leading_eigenvectors};
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
    #[serde(with = "relume_core::codec::pod_vec")]
    pub a: Vec<f32>,
    #[serde(with = "relume_core::codec::pod_vec")]
    pub b: Vec<f32>,
    #[serde(with = "relume_core::codec::pod_vec")]
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

/// Yᵀ Y for Y row-major (n × cols): per tile of `BLOCK` columns (in parallel), the lower
/// triangle's rows of that tile as f32 products over fixed blocks of `BLOCK` rows of Y, added
/// in f64 in block order; mirrored.
fn gram_cols(y: &[f32], n: usize, cols: usize) -> Mat<f64> {
    let ym = MatRef::from_row_major_slice(y, n, cols);
    let tiles: Vec<Mat<f64>> = (0..cols.div_ceil(BLOCK))
        .into_par_iter()
        .map(|t| {
            let (c0, c1) = (t * BLOCK, ((t + 1) * BLOCK).min(cols));
            let mut sum = Mat::<f64>::zeros(cols - c0, c1 - c0);
            let mut part = Mat::<f32>::zeros(cols - c0, c1 - c0);
            for k in 0..n.div_ceil(BLOCK) {
                let rows = ym.subrows(k * BLOCK, ((k + 1) * BLOCK).min(n) - k * BLOCK);
                let (left, right) = (rows.subcols(c0, cols - c0), rows.subcols(c0, c1 - c0));
                matmul(part.as_mut(), Accum::Replace, left.transpose(), right, 1.0f32, Par::Seq);
                for j in 0..c1 - c0 {
                    for i in j..cols - c0 {
                        sum[(i, j)] += part[(i, j)] as f64;
                    }
                }
            }
            sum
        })
        .collect();
    let mut g = Mat::<f64>::zeros(cols, cols);
    for (t, sum) in tiles.iter().enumerate() {
        let c0 = t * BLOCK;
        for j in 0..sum.ncols() {
            for i in j..sum.nrows() {
                g[(c0 + i, c0 + j)] = sum[(i, j)];
                g[(c0 + j, c0 + i)] = sum[(i, j)];
            }
        }
    }
    g
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

/// How many of the decreasing eigenvalues `values` are above the f32 rank floor.
fn f32_rank(values: &[f64]) -> usize {
    values.iter().take_while(|&&x| x >= F32_RANK_FLOOR * values[0]).count()
}

/// The leading `r` eigenvectors of `g` as rows (f32), cut to its numerical rank at f32
/// precision.
fn leading_rows(g: &Mat<f64>, r: usize) -> Result<(Vec<f32>, usize), NodeError> {
    let (values, vectors) = leading_eigenvectors(g, r)?;
    let kept = f32_rank(&values);
    let n = g.nrows();
    Ok((vectors[..kept * n].iter().map(|&x| x as f32).collect(), kept))
}

/// A factor column whose norm falls under this after re-orthonormalisation is dropped (with
/// those after it), as in `pca`.
const SURVIVAL_NORM: f64 = 1e-6;

/// Which Gram matrix of Y (V × cols) the vertex factor comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum VertexGram {
    /// The smaller one: Yᵀ Y where V > cols, else Y Yᵀ.
    Smaller,
    /// Y Yᵀ (V × V), A its leading eigenvectors.
    Vertices,
    /// Yᵀ Y (cols × cols), A = Y W Λ^-½ re-orthonormalised.
    Columns,
}

/// The vertex factor A (V × r row-major, f32) and r: the leading (at most `rank`, cut to the
/// numerical rank) left singular vectors of Y (V × cols row-major), by the Gram matrix
/// `route` picks (see the module doc).
fn vertex_factor(y: &[f32], v: usize, cols: usize, rank: usize, route: VertexGram) -> Result<(Vec<f32>, usize), NodeError> {
    let route = match route {
        VertexGram::Smaller if v > cols => VertexGram::Columns,
        VertexGram::Smaller => VertexGram::Vertices,
        picked => picked,
    };
    if route == VertexGram::Vertices {
        let (rows, r) = leading_rows(&gram_rows(y, v, cols), rank)?;
        return Ok(((0..v * r).map(|i| rows[(i % r) * v + i / r]).collect(), r));
    }
    let (values, w) = leading_eigenvectors(&gram_cols(y, v, cols), rank)?;
    let kept = f32_rank(&values);
    if kept == 0 {
        return Ok((Vec::new(), 0));
    }
    // W Λ^-½ as cols × kept row-major; then row i of A = y_i W Λ^-½, summed over j in order.
    let scaled: Vec<f64> = (0..cols * kept).map(|i| w[(i % kept) * cols + i / kept] / values[i % kept].sqrt()).collect();
    let mut a = vec![0.0f64; v * kept];
    a.par_chunks_mut(kept).zip(y.par_chunks(cols)).for_each(|(row, yi)| {
        for (&t, wj) in yi.iter().zip(scaled.chunks(kept)) {
            row.iter_mut().zip(wj).for_each(|(o, &c)| *o += t as f64 * c);
        }
    });
    // Columns of A, contiguous, for the Gram–Schmidt passes.
    let mut columns: Vec<f64> = (0..kept * v).map(|i| a[(i % v) * kept + i / v]).collect();
    let dot = |p: &[f64], q: &[f64]| -> f64 { p.iter().zip(q).map(|(x, y)| x * y).sum() };
    let mut r = kept;
    for k in 0..kept {
        let (done, rest) = columns.split_at_mut(k * v);
        let ak = &mut rest[..v];
        for _pass in 0..2 {
            for aj in done.chunks(v) {
                let p = dot(ak, aj);
                ak.iter_mut().zip(aj).for_each(|(x, q)| *x -= p * q);
            }
        }
        let norm = dot(ak, ak).sqrt();
        if !(norm > SURVIVAL_NORM && norm.is_finite()) {
            r = k;
            break;
        }
        ak.iter_mut().for_each(|x| *x /= norm);
        if largest_entry(ak).is_some_and(|l| ak[l] < 0.0) {
            ak.iter_mut().for_each(|x| *x = -*x);
        }
    }
    Ok(((0..v * r).map(|i| columns[(i % r) * v + i / r] as f32).collect(), r))
}

/// Approximates the cluster tensor `x` (V × L × S row-major) with ranks (`rank_v`, `rank_l`)
/// (cut to the numerical ranks) and `sweeps` HOOI rounds after the HOSVD start.
pub fn compress(x: &[f32], dims: [usize; 3], rank_v: usize, rank_l: usize, sweeps: usize) -> Result<ClusterTensor, NodeError> {
    compress_by(x, dims, rank_v, rank_l, sweeps, VertexGram::Smaller)
}

/// [`compress`] with the vertex factor's Gram matrix picked by `route`.
fn compress_by(
    x: &[f32],
    [v, l, s]: [usize; 3],
    rank_v: usize,
    rank_l: usize,
    sweeps: usize,
    route: VertexGram,
) -> Result<ClusterTensor, NodeError> {
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
    let (mut a, mut rv) = vertex_factor(&y, v, rl * s, rank_v, route)?;
    for _ in 0..sweeps {
        let z = project_vertices(x, v, l, s, &a, rv);
        (b, rl) = leading_rows(&gram_sum(&z, rv, l, s), rank_l)?;
        y = project_lights(x, v, l, s, &b, rl);
        (a, rv) = vertex_factor(&y, v, rl * s, rank_v, route)?;
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

    /// max |AᵀA − I| of a factor (V × r row-major).
    fn orthonormality_error(a: &[f32], v: usize, r: usize) -> f64 {
        let mut worst: f64 = 0.0;
        for p in 0..r {
            for q in 0..r {
                let d: f64 = (0..v).map(|i| a[i * r + p] as f64 * a[i * r + q] as f64).sum();
                worst = worst.max((d - if p == q { 1.0 } else { 0.0 }).abs());
            }
        }
        worst
    }

    /// ‖X − X̂‖² from the rebuilt slices.
    fn direct_error2(t: &ClusterTensor, x: &[f32]) -> f64 {
        let ls = (t.lights * t.columns) as usize;
        (0..t.vertices as usize)
            .map(|k| t.vertex(k).iter().zip(&x[k * ls..(k + 1) * ls]).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>())
            .sum()
    }

    #[test]
    fn the_columns_gram_route_matches_the_vertex_gram_route_on_a_tall_cluster() {
        // r_l · S = 16 columns of Y against 300 vertices.
        let (v, l, s) = (300, 24, 4);
        let mut x = low_rank(v, l, s, 8, 6, 21);
        x.iter_mut().enumerate().for_each(|(k, y)| *y += 0.05 * (uniform(22, k as u64, 0) - 0.5));
        for sweeps in [0, 2] {
            let big = compress_by(&x, [v, l, s], 6, 4, sweeps, VertexGram::Vertices).expect("V × V");
            let small = compress_by(&x, [v, l, s], 6, 4, sweeps, VertexGram::Columns).expect("16 × 16");
            assert_eq!(small, compress(&x, [v, l, s], 6, 4, sweeps).expect("default"), "V > r_l · S takes the columns' Gram");
            assert_eq!((small.rank_v, small.rank_l), (big.rank_v, big.rank_l));
            let rv = small.rank_v as usize;
            assert_eq!(rv, 6);
            assert!(orthonormality_error(&small.a, v, rv) < 1e-5, "AᵀA − I: {:e}", orthonormality_error(&small.a, v, rv));
            // The same error, by the identity and rebuilt, and the same factor column by column
            // (the same sign convention).
            assert!((small.error2 / big.error2 - 1.0).abs() < 1e-5, "{} vs {}", small.error2, big.error2);
            let (ds, db) = (direct_error2(&small, &x), direct_error2(&big, &x));
            assert!((ds / db - 1.0).abs() < 1e-5 && (ds / small.error2 - 1.0).abs() < 1e-3, "{ds} vs {db} vs {}", small.error2);
            let worst_a = small.a.iter().zip(&big.a).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
            assert!(worst_a < 1e-5, "A differs by {worst_a}");
            for p in 0..rv {
                let col: Vec<f64> = (0..v).map(|i| small.a[i * rv + p] as f64).collect();
                assert!(col[largest_entry(&col).expect("entries")] > 0.0, "column {p}'s largest entry is positive");
            }
            let peak = x.iter().fold(0.0f32, |m, y| m.max(y.abs()));
            for k in [0, 151, 299] {
                let worst = small.vertex(k).iter().zip(big.vertex(k)).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
                assert!(worst < 1e-4 * peak, "vertex {k}: {worst} of {peak}");
            }
        }
    }

    #[test]
    fn the_columns_gram_route_has_the_same_bytes_on_one_two_and_three_threads() {
        // 330 vertices (not a whole number of blocks) against r_l · S = 5 · 20 = 100 columns
        // (two column tiles, the second partial).
        let (v, l, s) = (330, 30, 20);
        let mut x = low_rank(v, l, s, 7, 6, 31);
        x.iter_mut().enumerate().for_each(|(k, y)| *y += 0.5 * (uniform(32, k as u64, 0) - 0.5));
        let on = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool")
                .install(|| compress_by(&x, [v, l, s], 12, 5, 1, VertexGram::Columns).expect("runs"))
        };
        let one = on(1);
        assert_eq!(one.rank_v, 12);
        assert!(orthonormality_error(&one.a, v, 12) < 1e-5);
        for threads in [2, 3] {
            let t = on(threads);
            let bits = |a: &[f32]| a.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!((bits(&t.a), bits(&t.b), bits(&t.core)), (bits(&one.a), bits(&one.b), bits(&one.core)), "{threads} threads");
            assert_eq!(t, one);
        }
        // The Gram matrix itself against a direct f64 sum.
        let y: Vec<f32> = (0..v * 100).map(|k| uniform(33, k as u64, 0) - 0.5).collect();
        let g = gram_cols(&y, v, 100);
        for (i, j) in [(0, 0), (99, 0), (64, 63), (70, 99), (99, 99)] {
            let direct: f64 = (0..v).map(|k| y[k * 100 + i] as f64 * y[k * 100 + j] as f64).sum();
            assert!((g[(i, j)] - direct).abs() < 1e-4 && g[(i, j)] == g[(j, i)], "({i}, {j}): {} vs {direct}", g[(i, j)]);
        }
    }

    /// A V × L × S tensor with a decaying spectrum in both modes plus noise, built in
    /// O(V · L · S · r) (for timing at full size).
    fn decaying(v: usize, l: usize, s: usize, r: usize, seed: u64) -> Vec<f32> {
        let u = |k: u64| uniform(seed, k, 0) * 2.0 - 1.0;
        // H_p = Σ_q b_q g_pq / ((1 + p)(1 + q)): rank r over the lighting bases too.
        let b: Vec<f32> = (0..l * r).map(|k| u(1_000_000 + k as u64)).collect();
        let g: Vec<f32> = (0..r * r * s).map(|k| u(2_000_000 + k as u64) / ((1 + k / (r * s)) * (1 + k / s % r)) as f32).collect();
        let mut h = vec![0.0f32; r * l * s];
        for p in 0..r {
            for j in 0..l {
                for q in 0..r {
                    let (bq, g) = (b[j * r + q], &g[(p * r + q) * s..(p * r + q + 1) * s]);
                    h[(p * l + j) * s..(p * l + j + 1) * s].iter_mut().zip(g).for_each(|(o, t)| *o += bq * t);
                }
            }
        }
        let mut x: Vec<f32> = (0..v * l * s).map(|k| 0.01 * u(10_000_000 + k as u64)).collect();
        for i in 0..v {
            for p in 0..r {
                let w = u((i * r + p) as u64);
                let (row, hp) = (&mut x[i * l * s..(i + 1) * l * s], &h[p * l * s..(p + 1) * l * s]);
                row.iter_mut().zip(hp).for_each(|(o, t)| *o += w * t);
            }
        }
        x
    }

    /// Timing at the size of a large cluster, by both routes (release: `cargo test --release
    /// -q -p relume-base --lib cta::tests::time_a_large_cluster -- --ignored --nocapture`).
    #[test]
    #[ignore]
    fn time_a_large_cluster() {
        let (v, l, s) = (3000, 96, 48);
        let x = decaying(v, l, s, 48, 11);
        let mut errors = Vec::new();
        for route in [VertexGram::Vertices, VertexGram::Columns] {
            let t0 = std::time::Instant::now();
            let t = compress_by(&x, [v, l, s], 32, 16, 1, route).expect("compresses");
            println!(
                "{route:?}: V {v} L {l} S {s} ranks (32, 16) one sweep: {:.2} s, ranks ({}, {}), relative error {:.6}",
                t0.elapsed().as_secs_f64(),
                t.rank_v,
                t.rank_l,
                (t.error2 / t.norm2).sqrt()
            );
            assert!(orthonormality_error(&t.a, v, t.rank_v as usize) < 1e-5);
            errors.push(t.error2);
        }
        assert!((errors[1] / errors[0] - 1.0).abs() < 1e-5, "{errors:?}");
    }
}
