//! TransferT0 node: the direct-light transfer T̃⁰ ([S] 5-7, 5.3.3.3) as sparse Haar terms per
//! vertex and column (`types::DirectTransfer`), and the per-vertex visible
//! fraction of each specular lobe over mirror directions ([`LobeVisibility`], [S] 5.3.1).

use super::types::brdf::{SpecularLobes, TuckerBrdf};
use super::types::Visibility;
use super::vertices::vertex_frame;
use crate::types::lobe_side as fraction_side;
use crate::types::{DirectTransfer, LobeVisibility};
use glam::Vec3;
use relume_base::math::cube_haar::{largest, CubeHaar};
use relume_base::math::cubemap::CubeMap;
use relume_base::math::frame::Frame;
use relume_core::codec::pod_vec;
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, params, MemoryEstimate, NodeError, PortSize, PortValue, RunCtx, ShardSpec};
use serde::{Deserialize, Serialize};
use std::ops::Range;

// ---- port types ----------------------------------------------------------------------------

/// A run of vertices' direct transfer and lobe maps: the partial result of `TransferT0`
/// sharded over vertices, with the squared coefficient energy of T̃ it kept and had.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransferT0Chunk {
    pub first: u64,
    pub count: u64,
    /// Terms kept per (vertex, column).
    #[serde(with = "pod_vec")]
    pub counts: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub index: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub value: Vec<f32>,
    pub maps: Vec<u8>,
    pub energy_kept: f64,
    pub energy: f64,
}

impl TransferT0Chunk {
    fn is_consistent(&self) -> bool {
        self.index.len() == self.value.len()
            && self.counts.iter().map(|&c| c as u64).sum::<u64>() == self.index.len() as u64
            && self.value.iter().all(|v| v.is_finite())
            && self.energy.is_finite()
            && self.energy_kept.is_finite()
    }
}

impl PortValue for TransferT0Chunk {
    const NAME: &'static str = "TransferT0Chunk";
    const COLOR: [u8; 3] = [230, 190, 60];
    const DOC: &'static str = "the direct transfer of a run of vertices (a shard's partial)";
    fn byte_size(&self) -> usize {
        (self.counts.len() + self.index.len() + self.value.len()) * 4 + self.maps.len() + 48
    }
    relume_core::serde_codec!(check TransferT0Chunk::is_consistent);
}

// ---- the computation -----------------------------------------------------------------------

/// How the kept terms are ranked: by |c| × the solid angle of the coefficient's support
/// (`true`, as `CubeHaar::keep_largest`) or by |c| alone (`false`); `TransferT0`'s doc has
/// the measurement that chose it.
pub const AREA_WEIGHTED: bool = true;

/// One lobe's blur from a fractional-visibility map of side `from` to the lobe map: per
/// output texel o, the weights `w[start[o]..start[o + 1]]` of source texels `src[..]`
/// (g_σ Ω normalised to sum 1).
struct LobeKernel {
    from: usize,
    start: Vec<u32>,
    src: Vec<u32>,
    w: Vec<f32>,
}

impl LobeKernel {
    fn new(sigma: f64, from: usize, side: usize) -> LobeKernel {
        let (src_map, out) = (CubeMap::constant(from, Vec3::ZERO), CubeMap::constant(side, Vec3::ZERO));
        let dirs: Vec<Vec3> = (0..src_map.texels.len()).map(|t| src_map.direction(t)).collect();
        let reach = (4.0 * sigma).min(std::f64::consts::PI);
        let mut k = LobeKernel { from, start: vec![0], src: vec![], w: vec![] };
        for o in 0..out.texels.len() {
            let d = out.direction(o);
            let mut row = vec![];
            for (t, e) in dirs.iter().enumerate() {
                let theta = (d.dot(*e).clamp(-1.0, 1.0) as f64).acos();
                if theta <= reach {
                    row.push((t as u32, (-(theta * theta) / (2.0 * sigma * sigma)).exp() * src_map.solid_angle(t) as f64));
                }
            }
            let total: f64 = row.iter().map(|r| r.1).sum();
            for (t, g) in row {
                k.src.push(t);
                k.w.push((g / total) as f32);
            }
            k.start.push(k.src.len() as u32);
        }
        k
    }

    /// The lobe map of `fraction` (the visible fractions at side `from`), quantised.
    fn apply(&self, fraction: &[f32], out: &mut Vec<u8>) {
        for o in self.start.windows(2) {
            let r = o[0] as usize..o[1] as usize;
            let v: f32 = self.src[r.clone()].iter().zip(&self.w[r]).map(|(&t, &w)| w * fraction[t as usize]).sum();
            out.push((v.clamp(0.0, 1.0) * 255.0).round() as u8);
        }
    }
}

/// One vertex's transfer: per column its kept (indices, values), its lobe maps (u8), and
/// the squared coefficient energy kept and in all.
pub struct VertexT0 {
    pub columns: Vec<(Vec<u32>, Vec<f32>)>,
    pub maps: Vec<u8>,
    pub energy_kept: f64,
    pub energy: f64,
}

/// What the per-vertex computation reads (see `TransferT0`'s doc).
pub struct DirectSetup<'a> {
    vis: &'a Visibility,
    brdf: &'a TuckerBrdf,
    terms: usize,
    dirs: Vec<Vec3>,
    omega: Vec<f32>,
    /// Per coefficient, its ranking weight besides |c| (its support's solid angle, or 1).
    support: Vec<f64>,
    lobes: Vec<LobeKernel>,
    /// Per fraction side the lobes read: per fine texel its coarse texel, and per coarse
    /// texel the fine solid angle it covers.
    fractions: Vec<(usize, Vec<u32>, Vec<f32>)>,
}

impl<'a> DirectSetup<'a> {
    /// The tables for visibility `vis` (its side a power of two), BRDF `brdf`, `terms` kept per
    /// column, lobes of widths `sigmas` (radians; 0° ones skipped) on maps of side `lobe_side`.
    pub fn new(vis: &'a Visibility, brdf: &'a TuckerBrdf, terms: usize, sigmas: &[f64], lobe_side: usize, area_weighted: bool) -> Self {
        let n = vis.n as usize;
        let cube = CubeMap::constant(n, Vec3::ZERO);
        let texels = cube.texels.len();
        let dirs = (0..texels).map(|k| cube.direction(k)).collect();
        let omega: Vec<f32> = (0..texels).map(|k| cube.solid_angle(k)).collect();
        let shape = CubeHaar { n, coeffs: vec![] };
        let support = (0..texels).map(|k| if area_weighted { shape.support_solid_angle(k) } else { 1.0 }).collect();
        let lobes: Vec<LobeKernel> =
            sigmas.iter().filter(|s| **s > 0.0).map(|&s| LobeKernel::new(s, fraction_side(s.to_degrees(), n), lobe_side)).collect();
        let mut sides: Vec<usize> = lobes.iter().map(|l| l.from).collect();
        sides.sort_unstable();
        sides.dedup();
        let fractions = sides
            .into_iter()
            .map(|m| {
                let of: Vec<u32> = (0..texels).map(|k| cube.coarse_of(k, m) as u32).collect();
                let mut area = vec![0.0f32; 6 * m * m];
                of.iter().zip(&omega).for_each(|(&c, &w)| area[c as usize] += w);
                (m, of, area)
            })
            .collect();
        DirectSetup { vis, brdf, terms, dirs, omega, support, lobes, fractions }
    }

    /// n_ωi + 1.
    pub fn columns(&self) -> usize {
        self.brdf.ranks[2] as usize + 1
    }

    /// The lobe maps per vertex.
    pub fn lobe_maps(&self) -> usize {
        self.lobes.len()
    }

    /// The visible texels of vertex `v` above its tangent plane, ascending.
    fn visible(&self, v: usize) -> impl Iterator<Item = usize> + '_ {
        let n = self.vis.normals[v];
        let words = if n == Vec3::ZERO { &[][..] } else { self.vis.of(v) };
        words.iter().enumerate().flat_map(|(i, &w)| {
            let mut bits = w;
            std::iter::from_fn(move || {
                (bits != 0).then(|| {
                    let b = bits.trailing_zeros();
                    bits &= bits - 1;
                    i * 32 + b as usize
                })
            })
        })
    }

    /// The dense T̃⁰ of vertex `v` in frame `frame` (its normal the vertex's): the columns
    /// packed three to a cube map (column k in channel k % 3 of map k / 3), the diffuse column
    /// last.
    pub fn dense(&self, v: usize, frame: &Frame) -> Vec<CubeMap> {
        let (r, cols) = (self.brdf.ranks[2] as usize, self.columns());
        let mut maps = vec![CubeMap::constant(self.vis.n as usize, Vec3::ZERO); cols.div_ceil(3)];
        let (n, mut u, mut acc) = (self.vis.normals[v], vec![0.0f32; r], vec![0.0f64; r]);
        for t in self.visible(v) {
            let d = self.dirs[t];
            let c = d.dot(n);
            if c <= 0.0 {
                continue;
            }
            let w = c * self.omega[t];
            u_i_into(self.brdf, frame.to_local(d), &mut acc, &mut u);
            for (k, uk) in u.iter().enumerate() {
                maps[k / 3].texels[t][k % 3] = uk * w;
            }
            maps[r / 3].texels[t][r % 3] = w;
        }
        maps
    }

    /// Vertex `v`'s transfer in frame `frame`.
    pub fn vertex(&self, v: usize, frame: &Frame) -> VertexT0 {
        let cols = self.columns();
        let mut out = VertexT0 { columns: Vec::with_capacity(cols), maps: vec![], energy_kept: 0.0, energy: 0.0 };
        let mut weight = vec![0.0f64; self.dirs.len()];
        for (g, map) in self.dense(v, frame).iter().enumerate() {
            let h = CubeHaar::forward(map);
            for ch in 0..3.min(cols - 3 * g) {
                for ((w, c), s) in weight.iter_mut().zip(&h.coeffs).zip(&self.support) {
                    *w = c[ch].abs() as f64 * s;
                }
                let index = largest(&weight, self.terms);
                let value: Vec<f32> = index.iter().map(|&i| h.coeffs[i as usize][ch]).collect();
                out.energy += h.coeffs.iter().map(|c| (c[ch] as f64).powi(2)).sum::<f64>();
                out.energy_kept += value.iter().map(|&c| (c as f64).powi(2)).sum::<f64>();
                out.columns.push((index, value));
            }
        }
        let fractions: Vec<Vec<f32>> = self
            .fractions
            .iter()
            .map(|(m, of, area)| {
                let mut f = vec![0.0f32; 6 * m * m];
                self.visible(v).for_each(|t| f[of[t] as usize] += self.omega[t]);
                f.iter_mut().zip(area).for_each(|(f, a)| *f /= a);
                f
            })
            .collect();
        let mut planar = vec![];
        for l in &self.lobes {
            let i = self.fractions.iter().position(|f| f.0 == l.from).expect("a fraction map per lobe side");
            l.apply(&fractions[i], &mut planar);
        }
        // Texel by texel, the lobes' values side by side (`LobeVisibility`'s layout).
        let texels = planar.len() / self.lobes.len().max(1);
        out.maps = (0..texels).flat_map(|t| planar[t..].iter().step_by(texels).copied()).collect();
        out
    }
}

/// U^ωi's row at local `w` into `out`, as `TuckerBrdf::u_i` computes it (bilinear over the
/// disk in f64, rounded to f32; zeros below the horizon) without allocating; `acc` is scratch.
fn u_i_into(brdf: &TuckerBrdf, w: Vec3, acc: &mut [f64], out: &mut [f32]) {
    let r = out.len();
    acc.fill(0.0);
    if let Some(b) = brdf.disk.bilinear(w) {
        for (&i, &wt) in b.idx.iter().zip(&b.w) {
            if wt != 0.0 {
                let row = &brdf.factor_i[i as usize * r..(i as usize + 1) * r];
                acc.iter_mut().zip(row).for_each(|(a, &f)| *a += wt * f as f64);
            }
        }
    }
    out.iter_mut().zip(acc.iter()).for_each(|(o, a)| *o = *a as f32);
}

// ---- the node ------------------------------------------------------------------------------

params! {
    /// The direct-light transfer T̃⁰ per vertex ([S] 5-7, 5.3.3.3): for each column k of the BRDF
    /// tensor's incoming factor U^ωi, plus one column of the cosine alone for the diffuse term
    /// ([S] 5.3.3.1), the cube map (the visibility's side; [S]: 6 × 64 × 64) of
    /// U^ωi(F⁻¹ω, k) (ω · n)⁺ V(ω) Ω(ω) in the vertex frame F (`vertex_frame`), Haar-transformed
    /// (`math::cube_haar`) with the `terms` largest coefficients kept ([S]: n_L = 96). The texel
    /// solid angle Ω is folded in, so the environment's plain coefficients C^L give the integral
    /// as a dot product (`DirectTransfer::apply`, what the relighting runs per lighting change).
    ///
    /// Ranking: by |c| × the solid angle of the coefficient's support (`CubeHaar::keep_largest`,
    /// [S] "area-weighted Haar"), although Ω is already inside T̃: measured on the floor-and-roof
    /// test scene (81 floor vertices, side 64, 96 terms) under graphs/assets/envlit/sky.exr, the
    /// relative error against the dense sum, mean over vertices, is for the diffuse column 3.19 %
    /// area-weighted against 3.27 % by |c| alone, for the tensor columns 10.0 % against 11.3 %,
    /// and for the shaded f_r (Blinn-Phong s = 30, one view) 6.3 % against 9.0 %
    /// (`ranking_by_area_weighted_magnitude_is_closer_under_the_sky`): the sky's energy sits in
    /// coarse coefficients, so coarse terms of the transfer meet more of it.
    ///
    /// Second output: per vertex, for each specular lobe of non-zero width (`SpecularLobes`
    /// input; [S] 7°, 14°, 21°), the visible fraction of the lobe around each mirror direction d
    /// on a cube map of side `lobe_side`, vis_σ(d) = Σ g_σ(∠(d, ω)) V(ω) Ω / Σ g_σ Ω with g an
    /// un-normalised Gaussian cut at 4σ like `CubeMap::gaussian_prefilter`, over the whole
    /// sphere (below the tangent plane is hidden), quantised to u8 (error ≤ 1/510). It is summed
    /// from the bitsets box-filtered to fractional visibility at the side `EnvLighting` gives
    /// the lobe's prefiltered environment (texels at most σ/2 wide: 32 for 7°, 16 for 14° and
    /// 21° at side 64), so the blur resolves σ and costs a few hundred multiply-adds per texel.
    ///
    /// Sharded over vertices; the same bytes on any thread count and any sharding. The held
    /// bytes are checked against the budget before anything is allocated.
    ///
    /// Metrics: vertices, columns, the mean terms kept per column, the share of T̃'s squared
    /// coefficient energy the kept terms hold, lobe maps per vertex, bytes.
    pub struct TransferT0 {
        /// Haar terms kept per column ([S]: n_L = 96)
        pub terms: usize = 96, range = 1..=4096, test = 16;
        /// texels along a face of each lobe's visible-fraction map
        pub lobe_side: usize = 8, range = 1..=64, test = 2;
    }
}

inputs!(pub TransferT0In { visibility: Visibility, brdf: TuckerBrdf, lobes: SpecularLobes });
outputs!(pub TransferT0Out { transfer: DirectTransfer, lobe_visibility: LobeVisibility });

/// Vertices per chunk of the sharded run.
const CHUNK: u64 = 256;

impl TransferT0 {
    fn lobe_count(lobes: &SpecularLobes) -> usize {
        lobes.sigmas.iter().filter(|s| **s > 0.0).count()
    }

    fn bytes(&self, i: &TransferT0In) -> u64 {
        let v = i.visibility.vertices() as u64;
        DirectTransfer::bytes_for(v, i.brdf.ranks[2] as u64 + 1, self.terms as u64).saturating_add(LobeVisibility::bytes_for(
            v,
            Self::lobe_count(i.lobes) as u64,
            self.lobe_side as u64,
        ))
    }

    fn check(&self, i: &TransferT0In, budget: u64) -> Result<(), NodeError> {
        let n = i.visibility.n;
        if !n.is_power_of_two() {
            return Err(NodeError::input("visibility", format!("the Haar transform needs a power-of-two side, not {n}")));
        }
        let bytes = self.bytes(i);
        if bytes > budget {
            return Err(NodeError::over_limit_param(
                "terms",
                format!(
                    "the direct transfer of {} vertices × {} columns × {} terms would hold {}, over the {} budget",
                    i.visibility.vertices(),
                    i.brdf.ranks[2] + 1,
                    self.terms,
                    fmt_bytes(bytes),
                    fmt_bytes(budget)
                ),
            ));
        }
        let pairs = i.visibility.vertices() as u64 * (i.brdf.ranks[2] as u64 + 1) * self.terms as u64;
        if pairs > u32::MAX as u64 {
            return Err(NodeError::over_limit_param("terms", format!("{pairs} terms are more than 32-bit offsets address")));
        }
        Ok(())
    }

    fn setup<'a>(&self, i: &TransferT0In<'a>) -> DirectSetup<'a> {
        DirectSetup::new(i.visibility, i.brdf, self.terms, &i.lobes.sigmas, self.lobe_side, AREA_WEIGHTED)
    }
}

/// The transfer of the vertices `range` as a chunk.
pub fn chunk_of(setup: &DirectSetup, range: Range<usize>, cx: &RunCtx) -> Result<TransferT0Chunk, NodeError> {
    let per_vertex = cx.par_map(range.len(), |r| {
        let v = range.start + r;
        setup.vertex(v, &vertex_frame(setup.vis.normals[v]))
    })?;
    let mut c = TransferT0Chunk {
        first: range.start as u64,
        count: range.len() as u64,
        counts: vec![],
        index: vec![],
        value: vec![],
        maps: vec![],
        energy_kept: 0.0,
        energy: 0.0,
    };
    for t in per_vertex {
        for (i, v) in t.columns {
            c.counts.push(i.len() as u32);
            c.index.extend(i);
            c.value.extend(v);
        }
        c.maps.extend(t.maps);
        c.energy_kept += t.energy_kept;
        c.energy += t.energy;
    }
    Ok(c)
}

#[node(category = "ptt", version = 2, sharded, metrics = ["vertices", "columns", "terms_mean", "energy_kept", "lobe_maps", "bytes"])]
impl TransferT0 {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        // The vertices and columns are known only from the inputs: the node checks itself.
        let _ = inputs;
        MemoryEstimate { outputs: vec![None, None], working: 4 * CubeMap::bytes_for(64) }
    }

    fn shard(&self, i: &TransferT0In) -> Result<ShardSpec, NodeError> {
        self.check(i, relume_core::limits::default_budget())?;
        Ok(ShardSpec::new(i.visibility.vertices() as u64, CHUNK))
    }

    fn run_items(&self, i: &TransferT0In, items: Range<u64>, cx: &RunCtx) -> Result<TransferT0Chunk, NodeError> {
        self.check(i, cx.memory_budget())?;
        chunk_of(&self.setup(i), items.start as usize..items.end as usize, cx)
    }

    fn gather(&self, i: &TransferT0In, parts: &[&TransferT0Chunk], cx: &RunCtx) -> Result<TransferT0Out, NodeError> {
        self.check(i, cx.memory_budget())?;
        let (v, cols) = (i.visibility.vertices(), i.brdf.ranks[2] as usize + 1);
        let lobes = Self::lobe_count(i.lobes);
        let per_maps = lobes * 6 * self.lobe_side * self.lobe_side;
        let mut t = DirectTransfer {
            n: i.visibility.n,
            columns: cols as u32,
            terms: self.terms as u32,
            offsets: Vec::with_capacity(v * cols + 1),
            index: vec![],
            value: vec![],
        };
        t.offsets.push(0);
        let mut maps = Vec::with_capacity(v * per_maps);
        let (mut kept, mut energy) = (0.0, 0.0);
        for p in parts {
            if p.first as usize * cols + 1 != t.offsets.len()
                || p.counts.len() != p.count as usize * cols
                || p.maps.len() != p.count as usize * per_maps
            {
                return Err(NodeError::failed(format!(
                    "a chunk of vertices {}..{} does not continue the transfer",
                    p.first,
                    p.first + p.count
                )));
            }
            for &c in &p.counts {
                t.offsets.push(t.offsets.last().copied().unwrap_or(0) + c);
            }
            t.index.extend_from_slice(&p.index);
            t.value.extend_from_slice(&p.value);
            maps.extend_from_slice(&p.maps);
            kept += p.energy_kept;
            energy += p.energy;
        }
        if t.offsets.len() != v * cols + 1 {
            return Err(NodeError::failed(format!("the chunks cover {} of {v} vertices", (t.offsets.len() - 1) / cols)));
        }
        let used = i.visibility.normals.iter().filter(|n| **n != Vec3::ZERO).count();
        cx.metric("vertices", v as f64);
        cx.metric("columns", cols as f64);
        cx.metric("terms_mean", if used > 0 { t.index.len() as f64 / (used * cols) as f64 } else { 0.0 });
        cx.metric("energy_kept", if energy > 0.0 { kept / energy } else { 1.0 });
        cx.metric("lobe_maps", lobes as f64);
        cx.metric("bytes", self.bytes(i) as f64);
        let sigmas = i.lobes.sigmas.iter().copied().filter(|s| *s > 0.0).collect();
        Ok(TransferT0Out { transfer: t, lobe_visibility: LobeVisibility { side: self.lobe_side as u32, sigmas, maps } })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::brdf::MaterialParam;
    use crate::vertex_visibility::tests::{floor_and_roof, visibility};
    use relume_base::testing::{first, run_on};
    use relume_core::Value;
    use std::f64::consts::PI;

    fn brdf() -> &'static (TuckerBrdf, SpecularLobes) {
        crate::brdf_factors::test_support::small_brdf()
    }

    /// graphs/assets/envlit/sky.exr on a cube map of side `n`.
    fn sky(n: usize) -> CubeMap {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../graphs/assets/envlit/sky.exr");
        let img = relume_base::image::io::read_image(&path).expect("sky.exr");
        let env = relume_base::types::EnvMap::new(img.width, img.height, img.pixels.iter().map(|p| Vec3::from(*p)).collect()).expect("map");
        CubeMap::from_fn(n, 2, |d| env.eval(d))
    }

    /// Visibility at side `n` of vertices with the given normals that see every texel above
    /// their tangent plane passing `open`.
    fn vis_where(n: u32, normals: &[Vec3], open: impl Fn(Vec3) -> bool) -> Visibility {
        let cube = CubeMap::constant(n as usize, Vec3::ZERO);
        let words = Visibility::words(n);
        let mut bits = vec![0u32; normals.len() * words];
        for (v, nv) in normals.iter().enumerate() {
            for k in 0..cube.texels.len() {
                let d = cube.direction(k);
                if d.dot(*nv) > 0.0 && open(d) {
                    bits[v * words + k / 32] |= 1 << (k % 32);
                }
            }
        }
        Visibility { n, coarse: 1, normals: normals.to_vec(), bits, coarse_cos: vec![0.0; normals.len() * 6] }
    }

    /// Σ_texels L T̃ of every column of a dense transfer (f64).
    fn dense_apply(maps: &[CubeMap], env: &CubeMap, cols: usize) -> Vec<[f64; 3]> {
        (0..cols)
            .map(|k| {
                let mut s = [0.0f64; 3];
                for (t, l) in env.texels.iter().enumerate() {
                    let x = maps[k / 3].texels[t][k % 3] as f64;
                    (0..3).for_each(|c| s[c] += l[c] as f64 * x);
                }
                s
            })
            .collect()
    }

    /// The columns of a vertex's transfer in sparse form (as `DirectTransfer` holds them).
    fn sparse(t: &VertexT0, n: u32) -> DirectTransfer {
        let mut d = DirectTransfer { n, columns: t.columns.len() as u32, terms: 0, offsets: vec![0], index: vec![], value: vec![] };
        for (i, v) in &t.columns {
            d.index.extend(i);
            d.value.extend(v);
            d.offsets.push(d.index.len() as u32);
            d.terms = d.terms.max(i.len() as u32);
        }
        d
    }

    fn frame_turned(n: Vec3, angle: f32) -> Frame {
        let f = vertex_frame(n);
        let (s, c) = angle.sin_cos();
        Frame { s: f.s * c + f.t * s, t: f.t * c - f.s * s, n }
    }

    /// The shaded f_r part toward world `wo` of material `p`: Σ_k (u_o · D(u_h))_k U^I0_k.
    fn shade(b: &TuckerBrdf, frame: &Frame, wo: Vec3, p: MaterialParam, u_i0: &[Vec3]) -> Vec3 {
        let m = b.core_for(&b.u_h(p).expect("in range"));
        let u_o = b.u_o(frame.to_local(wo));
        let ni = b.ranks[2] as usize;
        (0..ni).map(|k| u_i0[k] * u_o.iter().enumerate().map(|(j, &u)| u * m[j * ni + k]).sum::<f32>()).sum()
    }

    #[test]
    fn ranking_by_area_weighted_magnitude_is_closer_under_the_sky() {
        let s = floor_and_roof(0.5);
        let vis = visibility(&s, 64, 8);
        let (b, _) = brdf();
        let env = sky(64);
        let haar = CubeHaar::forward(&env).coeffs;
        let cols = b.ranks[2] as usize + 1;
        let p = MaterialParam::BlinnPhong { s: 30.0 };
        let wo = Vec3::new(0.5, 0.7, 0.3).normalize();
        // [ranking][diffuse column, tensor columns, shaded f_r toward wo]
        let mut err = [[0.0f64; 3]; 2];
        for (r, area) in [false, true].into_iter().enumerate() {
            let setup = DirectSetup::new(&vis, b, 96, &[], 8, area);
            for v in 0..81 {
                let frame = vertex_frame(vis.normals[v]);
                let exact = dense_apply(&setup.dense(v, &frame), &env, cols);
                let got = sparse(&setup.vertex(v, &frame), 64).apply(0, &haar);
                let d = |k: usize| (0..3).map(|c| (got[k][c] as f64 - exact[k][c]).powi(2)).sum::<f64>();
                let e = |k: usize| exact[k].iter().map(|x| x * x).sum::<f64>();
                err[r][0] += (d(cols - 1) / e(cols - 1)).sqrt() / 81.0;
                err[r][1] += ((0..cols - 1).map(d).sum::<f64>() / (0..cols - 1).map(e).sum::<f64>()).sqrt() / 81.0;
                let exact: Vec<Vec3> = exact.iter().map(|x| Vec3::new(x[0] as f32, x[1] as f32, x[2] as f32)).collect();
                let (a, x) = (shade(b, &frame, wo, p, &got), shade(b, &frame, wo, p, &exact));
                err[r][2] += ((a - x).length() / x.length()) as f64 / 81.0;
            }
        }
        println!("relative error of the integral, |c|: {:?}, |c| × support: {:?}", err[0], err[1]);
        assert!((0..3).all(|k| err[1][k] < err[0][k]), "{err:?}");
    }

    /// The sparse transfer of vertex `v` of `vis` in frame `frame`, 96 terms, no lobes.
    fn transfer(vis: &Visibility, v: usize, frame: &Frame) -> DirectTransfer {
        sparse(&DirectSetup::new(vis, &brdf().0, 96, &[], 8, AREA_WEIGHTED).vertex(v, frame), vis.n)
    }

    fn haar_of(env: &CubeMap) -> Vec<Vec3> {
        CubeHaar::forward(env).coeffs
    }

    /// A sky of 1 with a sun of 10⁴ in the texel holding `sun`.
    fn sunny(n: usize, sun: Vec3) -> CubeMap {
        let mut m = CubeMap::constant(n, Vec3::ONE);
        let t = m.texel_of(sun);
        m.texels[t] = Vec3::splat(1e4);
        m
    }

    #[test]
    fn an_open_vertex_under_a_constant_sky_receives_pi_l_and_under_a_zero_one_nothing() {
        let normals = [Vec3::Y, Vec3::new(0.3, 0.8, -0.5).normalize()];
        let vis = vis_where(16, &normals, |_| true);
        let l = Vec3::new(0.5, 1.0, 2.0);
        let (constant, zero) = (haar_of(&CubeMap::constant(16, l)), haar_of(&CubeMap::constant(16, Vec3::ZERO)));
        for (v, n) in normals.iter().enumerate() {
            let t = transfer(&vis, v, &vertex_frame(*n));
            let e = t.apply(0, &constant)[t.diffuse()] / (l * std::f32::consts::PI);
            // Only the texel-centre quadrature of the cosine stands between them (the constant
            // is one coefficient, and the transfer's total is always kept). Measured at side
            // 16: 1.3 × 10⁻³ on the axis, 5 × 10⁻⁵ tilted.
            assert!((e - Vec3::ONE).abs().max_element() < 3e-3, "vertex {v}: {e}");
            assert!(t.apply(0, &zero).iter().all(|c| *c == Vec3::ZERO));
        }
    }

    #[test]
    fn the_sun_survives_the_cut_and_a_wall_hides_half_the_sky() {
        let n = Vec3::Y;
        let sun = Vec3::new(0.3, 0.8, -0.5).normalize();
        let env = sunny(32, sun);
        let (b, haar) = (&brdf().0, haar_of(&env));
        let cols = b.ranks[2] as usize + 1;
        let open = vis_where(32, &[n], |_| true);
        let setup = DirectSetup::new(&open, b, 96, &[], 8, AREA_WEIGHTED);
        let dense = dense_apply(&setup.dense(0, &vertex_frame(n)), &env, cols)[cols - 1][0];
        let got = transfer(&open, 0, &vertex_frame(n)).apply(0, &haar)[cols - 1].x as f64;
        // The sun holds 84 % of the irradiance; measured 3.9 × 10⁻³ off the dense sum.
        assert!(dense > 5.0 * PI && (got / dense - 1.0).abs() < 1e-2, "{got} against {dense}");
        // A wall on the +x side: the sky's half (measured 3.2 × 10⁻⁴ off π/2), and the sun
        // behind it is gone though its bright coefficients meet the dropped terms (measured
        // 8 × 10⁻⁷ off the bare sky's).
        let walled = vis_where(32, &[n], |d| d.x < 0.0);
        let e = transfer(&walled, 0, &vertex_frame(n)).apply(0, &haar)[cols - 1].x as f64;
        let sky = transfer(&walled, 0, &vertex_frame(n)).apply(0, &haar_of(&CubeMap::constant(32, Vec3::ONE)))[cols - 1].x as f64;
        assert!((sky / (PI / 2.0) - 1.0).abs() < 2e-3, "{sky}");
        assert!((e / sky - 1.0).abs() < 1e-4, "{e} against the bare sky's {sky}");
    }

    /// Worst |shaded f_r − direct quadrature| / the material's largest |direct|, over
    /// Blinn-Phong s = 5, 30, 90 and five views, of an open vertex under `env` (side 32):
    /// [dense transfer, every term kept, 400 terms, 96 terms, 96 terms in frames turned by
    /// 0.5 and 1 rad about the normal against the unturned (views over 60° from the horizon),
    /// the same for the dense transfer].
    fn shading_errors(env: &CubeMap) -> [f32; 6] {
        let (b, _) = brdf();
        let n = Vec3::new(0.2, 0.9, 0.1).normalize();
        let vis = vis_where(32, &[n], |_| true);
        let cube = CubeMap::constant(32, Vec3::ZERO);
        let haar = haar_of(env);
        let frame = vertex_frame(n);
        let setup = |terms| DirectSetup::new(&vis, b, terms, &[], 8, AREA_WEIGHTED);
        let dense = |frame: &Frame| -> Vec<Vec3> {
            dense_apply(&setup(0).dense(0, frame), env, 9).iter().map(|x| Vec3::new(x[0] as f32, x[1] as f32, x[2] as f32)).collect()
        };
        let cut = |terms, frame: &Frame| sparse(&setup(terms).vertex(0, frame), 32).apply(0, &haar);
        let (t96, t400, all) = (cut(96, &frame), cut(400, &frame), cut(6 * 32 * 32, &frame));
        let turned: Vec<(Frame, Vec<Vec3>, Vec<Vec3>)> =
            [0.5f32, 1.0].iter().map(|&a| (frame_turned(n, a), cut(96, &frame_turned(n, a)), dense(&frame_turned(n, a)))).collect();
        let (d0, views) =
            (dense(&frame), [n, Vec3::new(0.5, 0.7, 0.3), Vec3::new(-0.3, 0.9, 0.4), Vec3::new(0.1, 0.8, -0.6), Vec3::new(-0.8, 0.3, 0.1)]);
        let mut worst = [0.0f32; 6];
        for s in [5.0, 30.0, 90.0] {
            let p = MaterialParam::BlinnPhong { s };
            let mut rows = vec![];
            for wo in views.map(|w| w.normalize()) {
                // ∫ L f_r cos dω over the texels with the decomposition's own `eval`.
                let mut direct = Vec3::ZERO;
                for (t, l) in env.texels.iter().enumerate() {
                    let d = cube.direction(t);
                    if d.dot(n) > 0.0 {
                        direct += *l * b.eval(p, frame.to_local(wo), frame.to_local(d)).unwrap() * d.dot(n) * cube.solid_angle(t);
                    }
                }
                let sh = |u: &[Vec3]| shade(b, &frame, wo, p, u);
                let high = wo.dot(n) > 0.5;
                let turn = |k: usize, base: &[Vec3]| {
                    let e = turned.iter().map(|t| (shade(b, &t.0, wo, p, if k == 1 { &t.1 } else { &t.2 }) - sh(base)).length());
                    if high {
                        e.fold(0.0, f32::max)
                    } else {
                        0.0
                    }
                };
                let e = [sh(&d0) - direct, sh(&all) - direct, sh(&t400) - direct, sh(&t96) - direct].map(|e| e.length());
                rows.push((direct.length(), [e[0], e[1], e[2], e[3], turn(1, &t96), turn(2, &d0)]));
            }
            let scale = rows.iter().map(|r| r.0).fold(0.0, f32::max);
            for (_, e) in rows {
                worst.iter_mut().zip(e).for_each(|(w, e)| *w = w.max(e / scale));
            }
        }
        worst
    }

    #[test]
    fn the_tensor_columns_shade_as_a_direct_quadrature_and_turning_the_frame_changes_little() {
        // The dense transfer is the quadrature (Parseval, the same U^ωi), and so is every
        // term kept: measured 1.2 × 10⁻⁶ and 1.7 × 10⁻⁶ of the scale under the sky. The cut
        // converges: under the sky, whose sun (~2000) meets the cut transfer's coarse
        // approximation, measured 0.074 at 400 terms and 0.28 at 96; under a smooth sky
        // 0.0013 and 0.0062. Turning the frame by 0.5 and 1 rad about the normal (views more
        // than 60° above the horizon) moves the shading by 0.038 under the smooth sky, the
        // same with every term (the disk's bilinear U^ωi, U^ωo are not rotation-invariant),
        // and under the sky by 0.085 dense, 0.26 at 96 terms (other terms survive the cut).
        let sun = shading_errors(&sky(32));
        let smooth = shading_errors(&CubeMap::from_fn(32, 2, |d| Vec3::new(1.0 + 0.5 * d.x, 1.0 + d.y * d.y, 1.2 - 0.4 * d.z)));
        println!("dense, all, 400, 96, turned 96, turned dense: sky {sun:?}, smooth {smooth:?}");
        assert!(sun[0] < 1e-5 && sun[1] < 1e-5 && sun[2] < 0.1 && sun[3] < 0.35, "{sun:?}");
        assert!(smooth[2] < 0.005 && smooth[3] < 0.02, "{smooth:?}");
        assert!(smooth[4] < 0.06 && smooth[5] < 0.06 && sun[4] < 0.35 && sun[5] < 0.12, "{smooth:?} {sun:?}");
    }

    /// Φ(1): the share of a (flat) Gaussian lobe whose centre is σ above the horizon that lies
    /// above it (half for one on the horizon).
    const PHI_1: f32 = 0.8413;

    #[test]
    fn lobes_are_visible_above_the_horizon_and_half_at_a_wall() {
        let (b, lobes) = brdf();
        let vis = vis_where(32, &[Vec3::Y, Vec3::Y], |_| true);
        let setup = DirectSetup::new(&vis, b, 96, &lobes.sigmas, 8, AREA_WEIGHTED);
        assert_eq!(setup.lobe_maps(), 3);
        let t = setup.vertex(0, &vertex_frame(Vec3::Y));
        let lv = LobeVisibility { side: 8, sigmas: lobes.sigmas[1..].to_vec(), maps: [t.maps.clone(), t.maps].concat() };
        assert_eq!(lv.map_for(0.0), None);
        let mut worst = 0.0f32;
        for (k, &sigma) in lv.sigmas.iter().enumerate() {
            assert_eq!(lv.map_for(sigma), Some(k));
            let at = |e: f64, phi: f64| {
                lv.lobe_visibility(1, k, Vec3::new((e.cos() * phi.cos()) as f32, e.sin() as f32, (e.cos() * phi.sin()) as f32))
            };
            for phi in [0.0, 0.7, 2.0, 4.0] {
                for e in [3.0 * sigma, 60f64.to_radians(), PI / 2.0] {
                    worst = worst.max(1.0 - at(e, phi));
                }
                let (horizon, one_sigma) = (at(0.0, phi), at(sigma, phi));
                // Measured: 0.5 at the horizon (the plane runs between texels), 0.81 … 0.84 a σ
                // above it.
                assert!((horizon - 0.5).abs() < 0.01 && (one_sigma - PHI_1).abs() < 0.05, "σ {sigma}: {horizon} {one_sigma}");
            }
        }
        // 3σ and more above the horizon: measured at most 0.0054 short of 1.
        assert!(worst < 0.01, "{worst}");
    }

    /// A floor ending 0.1 short of a tall wall at x = 0 (the floor's vertices 0 … 3, the
    /// wall's 4 … 7).
    fn floor_and_wall() -> relume_base::types::Scene {
        let grey = relume_base::types::Material::Lambert { albedo: Vec3::splat(0.5) };
        relume_base::scene::builder::SceneBuilder::new(Vec3::new(-2.0, 1.0, 0.0), Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(0.9, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), grey, Vec3::ZERO)
            .quad("wall", Vec3::new(0.0, 0.0, -100.0), Vec3::new(0.0, 100.0, 0.0), Vec3::new(0.0, 0.0, 200.0), grey, Vec3::ZERO)
            .environment(relume_base::types::Environment::Constant(Vec3::ONE))
            .build()
    }

    fn run_t0(vis: &Visibility, params: &[(&str, relume_core::ParamValue)]) -> (DirectTransfer, LobeVisibility) {
        let (b, l) = brdf();
        let out = run_on::<TransferT0>(params, vec![Value::new(vis.clone()), Value::new(b.clone()), Value::new(l.clone())]).expect("runs");
        (first(&out), first(&out[1..]))
    }

    #[test]
    fn through_the_nodes_a_wall_halves_the_irradiance_and_the_lobes_at_its_edge() {
        let s = floor_and_wall();
        let vis = visibility(&s, 16, 4);
        let (t, lv) = run_t0(&vis, &[]);
        assert_eq!((t.vertices(), t.columns, lv.sigmas.len()), (8, 9, 3));
        let haar = haar_of(&CubeMap::constant(16, Vec3::ONE));
        let open = transfer(&vis_where(16, &[Vec3::Y], |_| true), 0, &vertex_frame(Vec3::Y)).apply(0, &haar)[8].x;
        for v in 0..4 {
            // The floor's vertices, 0.1 and 1 from the tall wall: half the sky.
            let e = t.apply(v, &haar)[t.diffuse()].x;
            assert!((e / open - 0.5).abs() < 2e-3, "vertex {v}: {e} of {open}");
            for k in 0..3 {
                let up = lv.lobe_visibility(v, k, Vec3::Y);
                let away = lv.lobe_visibility(v, k, Vec3::new(-0.5, 1.0, 0.0).normalize());
                // Measured: 0.5 straight up along the wall; 26.6° away from it 1, 0.96, 0.88
                // for 7°, 14°, 21° (Φ(26.6°/σ): 1.0, 0.97, 0.90).
                assert!((up - 0.5).abs() < 0.01 && away > up + 0.3, "vertex {v}, lobe {k}: {up} {away}");
            }
        }
    }

    #[test]
    fn the_same_bytes_on_one_and_two_threads_and_any_chunking() {
        let s = floor_and_roof(0.5);
        let vis = visibility(&s, 16, 4);
        let pool = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().expect("pool");
        let one = pool(1).install(|| run_t0(&vis, &[]));
        let two = pool(2).install(|| run_t0(&vis, &[]));
        assert_eq!(one, two);
        assert_eq!(DirectTransfer::decode(&one.0.encode()).as_ref(), Some(&one.0));
        assert_eq!(LobeVisibility::decode(&one.1.encode()).as_ref(), Some(&one.1));
        assert!(DirectTransfer::decode(&one.0.encode()[..100]).is_none());
        // Chunks of any cut concatenate to the whole.
        let (b, l) = brdf();
        let setup = DirectSetup::new(&vis, b, 96, &l.sigmas, 8, AREA_WEIGHTED);
        let cancel = relume_core::CancelToken::new();
        let cx = RunCtx::new("t0", &cancel, None);
        let whole = chunk_of(&setup, 0..85, &cx).unwrap();
        let (a, c) = (chunk_of(&setup, 0..30, &cx).unwrap(), chunk_of(&setup, 30..85, &cx).unwrap());
        assert_eq!([a.index, c.index].concat(), whole.index);
        assert_eq!([a.value, c.value].concat(), whole.value);
        assert_eq!([a.maps, c.maps].concat(), whole.maps);
        assert_eq!(TransferT0Chunk::decode(&whole.encode()).as_ref(), Some(&whole));
        // Fewer terms per column where fewer coefficients are non-zero: a roof's vertex facing
        // down sees the few texels below the small floor.
        assert!((0..9).all(|k| one.0.column(0, k).0.len() <= 96));
    }

    /// The lobes' values of a texel lie side by side: a lookup at a texel's centre reads
    /// each lobe's own byte there; the maps travel as one byte string and a cut one is refused.
    #[test]
    fn lobe_maps_interleave_their_lobes_texel_by_texel_and_survive_the_codec() {
        let (side, lobes, vertices) = (2usize, 2usize, 2usize);
        let per = 6 * side * side * lobes;
        let maps: Vec<u8> = (0..vertices * per).map(|b| (b * 7 % 251) as u8).collect();
        let lv = LobeVisibility { side: side as u32, sigmas: vec![0.1, 0.2], maps };
        // The centre of face 0's first texel (+x face: u = −z/x, v = −y/x, both −½).
        let d = Vec3::new(1.0, 0.5, 0.5);
        for v in 0..vertices {
            for k in 0..lobes {
                let want = lv.maps[v * per + k] as f32 / 255.0;
                assert!((lv.lobe_visibility(v, k, d) - want).abs() < 1e-6, "vertex {v}, lobe {k}");
            }
        }
        let bytes = lv.encode();
        assert_eq!(LobeVisibility::decode(&bytes).as_ref(), Some(&lv));
        assert!(LobeVisibility::decode(&bytes[..bytes.len() - 5]).is_none());
    }

    #[test]
    fn bad_sides_and_over_budget_requests_are_refused_and_a_run_cancels() {
        let odd = vis_where(12, &[Vec3::Y], |_| true);
        let (b, l) = brdf();
        let e = run_on::<TransferT0>(&[], vec![Value::new(odd), Value::new(b.clone()), Value::new(l.clone())]).expect_err("refused");
        assert!(e.to_string().contains("power-of-two"), "{e}");
        let vis = vis_where(16, &vec![Vec3::Y; 1000], |_| true);
        let node = TransferT0 { terms: 96, lobe_side: 8 };
        let i = TransferT0In { visibility: &vis, brdf: b, lobes: l };
        let e = node.check(&i, 1 << 20).expect_err("over budget");
        assert!(e.to_string().contains("1000 vertices × 9 columns × 96 terms") && e.to_string().contains("budget"), "{e}");
        let s = floor_and_roof(0.5);
        let vis = visibility(&s, 16, 4);
        let late =
            relume_base::testing::cancels_midway::<TransferT0>(&[], vec![Value::new(vis), Value::new(b.clone()), Value::new(l.clone())]);
        assert!(late < 5, "{late} progress reports after cancelling");
    }
}
