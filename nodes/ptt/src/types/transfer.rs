//! The port types of the transfer precompute: the per-vertex lobe visibility (T̃⁰'s side
//! product), and the one- and two-bounce transfer (T1, T2).

use super::CtaPlan;
use crate::bounce::SH;
use glam::Vec3;
use relume_base::math::cta::ClusterTensor;
use relume_base::math::cubemap::CubeAt;
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// Per vertex, the visible fraction of each specular lobe of non-zero width ([S] 5.3.1) over
/// mirror directions d: a cube map of side `side` per lobe of vis_σ(d) = Σ_t g_σ(∠(d, ω_t))
/// V(t) Ω_t / Σ_t g_σ Ω_t over the whole sphere (directions below the tangent plane count as
/// hidden, as in the BRDF lobe they stand in for), quantised to u8 (value / 255). Vertex v's
/// maps at `maps[v · 6 side² · lobes ..]`, texel after texel (face, row, column), each
/// texel's values of the lobes side by side: a lookup reads every lobe from the same two
/// rows (one or two cache lines). `sigmas` (radians) their widths, in the order of the
/// `SpecularLobes` input, a 0° lobe left out: it reads the visibility bit of the mirror
/// direction's texel (`Visibility::visible`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LobeVisibility {
    pub side: u32,
    pub sigmas: Vec<f64>,
    #[serde(with = "relume_core::codec::byte_vec")]
    pub maps: Vec<u8>,
}

impl LobeVisibility {
    fn texels(&self) -> usize {
        6 * (self.side as usize).pow(2)
    }

    /// The map of the lobe of width `sigma` (radians, as `SpecularLobes::sigmas` holds it);
    /// `None` for 0° or a width not mapped.
    pub fn map_for(&self, sigma: f64) -> Option<usize> {
        self.sigmas.iter().position(|&s| s == sigma && s > 0.0)
    }

    /// The visible fraction of lobe map `k` of vertex `v` around the world mirror direction
    /// `d` (bilinear between texel centres on its face, as `CubeMap::lookup`).
    pub fn lobe_visibility(&self, v: usize, k: usize, d: Vec3) -> f32 {
        let mut all = vec![0.0; self.sigmas.len()];
        self.lobe_visibilities_at(v, &CubeAt::of(d), &mut all);
        all[k]
    }

    /// Every lobe's `lobe_visibility` of vertex `v` at a direction already located, into
    /// `out` (one per lobe map).
    pub fn lobe_visibilities_at(&self, v: usize, at: &CubeAt, out: &mut [f32]) {
        let (map, [r0, r1], [i0, i1], fx, fy) = self.taps(v, at);
        let lobes = self.sigmas.len();
        let texel = |r: usize, i: usize| &map[(r + i) * lobes..][..lobes];
        let (a, b, c, d) = (texel(r0, i0), texel(r0, i1), texel(r1, i0), texel(r1, i1));
        for (k, o) in out[..lobes].iter_mut().enumerate() {
            let at = |t: &[u8]| t[k] as f32 / 255.0;
            *o = (at(a) * (1.0 - fx) + at(b) * fx) * (1.0 - fy) + (at(c) * (1.0 - fx) + at(d) * fx) * fy;
        }
    }

    /// Asks the processor to fetch the two texel rows `lobe_visibilities_at(v, at, …)` reads
    /// (the maps are read one vertex after another, far apart in memory: the fetch of the
    /// next vertices' rows overlaps the shading of this one's).
    pub fn prefetch(&self, v: usize, at: &CubeAt) {
        let (map, [r0, r1], [i0, _], _, _) = self.taps(v, at);
        let lobes = self.sigmas.len();
        relume_base::math::prefetch(&map[(r0 + i0) * lobes]);
        relume_base::math::prefetch(&map[(r1 + i0) * lobes]);
    }

    /// Whether it holds every lobe's map for `vertices` vertices.
    pub fn covers(&self, vertices: usize) -> bool {
        self.maps.len() == vertices * self.texels() * self.sigmas.len()
    }

    /// Vertex `v`'s maps and where the bilinear lookup at `at` reads them: the two rows'
    /// starts, the two columns (in texels), the weights toward the second of each.
    fn taps(&self, v: usize, at: &CubeAt) -> (&[u8], [usize; 2], [usize; 2], f32, f32) {
        let per = self.texels() * self.sigmas.len();
        let map = &self.maps[v * per..][..per];
        let (rows, cols, fx, fy) = at.taps(self.side as usize);
        (map, rows, cols, fx, fy)
    }

    /// Bytes held for `vertices` with `lobes` maps of side `side`.
    pub fn bytes_for(vertices: u64, lobes: u64, side: u64) -> u64 {
        vertices.saturating_mul(lobes).saturating_mul(6 * side * side).saturating_add(64)
    }

    pub(crate) fn is_consistent(&self) -> bool {
        self.side > 0 && self.sigmas.iter().all(|s| s.is_finite() && *s > 0.0) && {
            let per = self.sigmas.len() * self.texels();
            if per == 0 {
                self.maps.is_empty()
            } else {
                self.maps.len().is_multiple_of(per)
            }
        }
    }
}

impl PortValue for LobeVisibility {
    const NAME: &'static str = "LobeVisibility";
    const COLOR: [u8; 3] = [210, 210, 140];
    const DOC: &'static str = "per vertex and specular lobe width, the visible fraction of the lobe around each mirror direction";
    fn byte_size(&self) -> usize {
        self.maps.len() + self.sigmas.len() * 8 + 32
    }
    relume_core::serde_codec!(check LobeVisibility::is_consistent);
}

/// The compressed one-bounce transfer of every vertex: per cluster of `plan`, its tensor
/// approximation over (member, lighting basis, channel × 16 SH); `fixed`, `groups`, `bases`
/// and `textured` (per group) give the channel layout (`ptt::channels`), `coarse` the lighting
/// cube's side.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BounceTransfer {
    pub coarse: u32,
    pub fixed: u32,
    pub groups: Vec<String>,
    pub bases: u32,
    pub plan: CtaPlan,
    pub clusters: Vec<ClusterTensor>,
    #[serde(default)]
    pub textured: Vec<bool>,
}

impl BounceTransfer {
    /// Channels in all.
    pub fn channels(&self) -> usize {
        self.fixed as usize + crate::channels::group_channels(self.bases as usize, &self.textured).sum::<usize>()
    }
    pub(crate) fn is_consistent(&self) -> bool {
        let (l, s) = (6 * (self.coarse as usize).pow(2), self.channels() * SH);
        self.textured.len() == self.groups.len()
            && self.clusters.len() == self.plan.members.len()
            && self.clusters.iter().zip(&self.plan.members).all(|(t, m)| {
                let (rv, rl) = (t.rank_v as usize, t.rank_l as usize);
                t.vertices as usize == m.len()
                    && t.lights as usize == l
                    && t.columns as usize == s
                    && t.a.len() == m.len() * rv
                    && t.b.len() == rl * l
                    && t.core.len() == rv * rl * s
                    && t.a.iter().chain(&t.b).chain(&t.core).all(|x| x.is_finite())
            })
    }
}

impl PortValue for BounceTransfer {
    const NAME: &'static str = "BounceTransfer";
    const COLOR: [u8; 3] = [170, 140, 230];
    const DOC: &'static str = "the one-bounce transfer tensors of every vertex, compressed per cluster";
    fn byte_size(&self) -> usize {
        self.clusters.iter().map(|t| t.floats() * 4 + 64).sum::<usize>() + self.plan.byte_size()
    }
    relume_core::serde_codec!(check BounceTransfer::is_consistent);
}

/// Per vertex, T²(l, c₁, c₂) at `values[v · stride ..]`, laid out (l, c₁, c₂); `stride` =
/// 6 side² × channels².
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TwoBounce {
    pub side: u32,
    pub channels: u32,
    #[serde(with = "pod_vec")]
    pub values: Vec<f32>,
}

impl TwoBounce {
    pub fn stride(&self) -> usize {
        6 * (self.side as usize).pow(2) * (self.channels as usize).pow(2)
    }
    pub fn of(&self, v: usize) -> &[f32] {
        let s = self.stride();
        &self.values[v * s..(v + 1) * s]
    }
    pub(crate) fn is_consistent(&self) -> bool {
        self.side > 0 && self.values.len().is_multiple_of(self.stride().max(1)) && self.values.iter().all(|x| x.is_finite())
    }
}

impl PortValue for TwoBounce {
    const NAME: &'static str = "TwoBounce";
    const COLOR: [u8; 3] = [150, 120, 210];
    const DOC: &'static str = "the two-bounce transfer of every vertex (a scalar per lighting basis and reflector pair)";
    fn byte_size(&self) -> usize {
        self.values.len() * 4 + 16
    }
    relume_core::serde_codec!(check TwoBounce::is_consistent);
}

/// The two-bounce transfer compressed by clustered PCA ([S] 5.3.3.4 compresses T² by CPCA as
/// T¹; `CompressT2`): the vertices' rows of `TwoBounce` (length `dim()` = 6 side² × channels²,
/// laid out (l, c₁, c₂)) fall into clusters, and vertex v of cluster c = `cluster[v]` is rebuilt
/// as mean_c + Σ_j coefficients[v · m + j] · direction_{c, j}. Cluster c's mean at
/// `means[c · dim ..]`, its m directions at `directions[(c · m + j) · dim ..]` (zero past the
/// cluster's rank).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PackedTwoBounce {
    pub side: u32,
    pub channels: u32,
    pub m: u32,
    #[serde(with = "pod_vec")]
    pub means: Vec<f32>,
    #[serde(with = "pod_vec")]
    pub directions: Vec<f32>,
    #[serde(with = "pod_vec")]
    pub cluster: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub coefficients: Vec<f32>,
}

impl PackedTwoBounce {
    /// Length of a vertex's row: 6 side² × channels².
    pub fn dim(&self) -> usize {
        6 * (self.side as usize).pow(2) * (self.channels as usize).pow(2)
    }
    pub fn clusters(&self) -> usize {
        self.means.len() / self.dim().max(1)
    }
    pub fn vertices(&self) -> usize {
        self.cluster.len()
    }
    /// Cluster c's mean row.
    pub fn mean(&self, c: usize) -> &[f32] {
        let d = self.dim();
        &self.means[c * d..(c + 1) * d]
    }
    /// Cluster c's direction j.
    pub fn direction(&self, c: usize, j: usize) -> &[f32] {
        let d = self.dim();
        &self.directions[(c * self.m as usize + j) * d..][..d]
    }
    /// Vertex v's coefficients, one per direction.
    pub fn coefficients_of(&self, v: usize) -> &[f32] {
        let m = self.m as usize;
        &self.coefficients[v * m..(v + 1) * m]
    }
    /// Vertex v's row rebuilt (the `TwoBounce::of` it stands for).
    pub fn row(&self, v: usize) -> Vec<f32> {
        let c = self.cluster[v] as usize;
        let mut out = self.mean(c).to_vec();
        for (j, &w) in self.coefficients_of(v).iter().enumerate() {
            out.iter_mut().zip(self.direction(c, j)).for_each(|(o, x)| *o += w * x);
        }
        out
    }
    /// Bytes held for `vertices`, rows of `dim`, `clusters` and `m` directions (checked before
    /// allocating; saturating).
    pub fn bytes_for(vertices: u64, dim: u64, clusters: u64, m: u64) -> u64 {
        let floats = clusters.saturating_mul(m.saturating_add(1)).saturating_mul(dim).saturating_add(vertices.saturating_mul(m));
        floats.saturating_add(vertices).saturating_mul(4).saturating_add(32)
    }
    pub(crate) fn is_consistent(&self) -> bool {
        let (d, m, k) = (self.dim(), self.m as usize, self.clusters());
        self.side > 0
            && d > 0
            && self.means.len() == k * d
            && self.directions.len() == k * m * d
            && self.coefficients.len() == self.cluster.len() * m
            && self.cluster.iter().all(|&c| (c as usize) < k)
            && self.means.iter().chain(&self.directions).chain(&self.coefficients).all(|x| x.is_finite())
    }
}

impl PortValue for PackedTwoBounce {
    const NAME: &'static str = "PackedTwoBounce";
    const COLOR: [u8; 3] = [140, 110, 200];
    const DOC: &'static str =
        "the two-bounce transfer of every vertex compressed by clustered PCA (a cluster mean and directions, per vertex coefficients)";
    fn byte_size(&self) -> usize {
        (self.means.len() + self.directions.len() + self.cluster.len() + self.coefficients.len()) * 4 + 32
    }
    relume_core::serde_codec!(check PackedTwoBounce::is_consistent);
}

/// Per vertex, the direct-light transfer T̃⁰ ([S] 5-7) as the largest Haar terms of each column:
/// columns 0 … n_ωi − 1 are the columns k of the BRDF tensor's incoming factor U^ωi, column
/// n_ωi (`diffuse()`) the cosine alone (the diffuse term, shaded outside the tensor, [S]
/// 5.3.3.1). Column k of vertex v holds (index, value) pairs, indices ascending, at
/// `offsets[v · columns + k] .. offsets[v · columns + k + 1]` of `index` and `value` (at most
/// `terms`, fewer where fewer coefficients are non-zero). The values are Haar coefficients
/// (`math::cube_haar`, side `n`) of U^ωi(F⁻¹ω, k) (ω · n)⁺ V(ω) Ω(ω), the texel's solid angle
/// folded in, so that against the environment's plain coefficients C^L (`EnvLight::haar`)
/// Σ_c C^L_c T̃_c = Σ_texels L T̃ ≈ ∫ L U^ωi (ω · n)⁺ V dω (Parseval): `apply`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DirectTransfer {
    pub n: u32,
    pub columns: u32,
    pub terms: u32,
    #[serde(with = "pod_vec")]
    pub offsets: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub index: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub value: Vec<f32>,
}

impl DirectTransfer {
    pub fn vertices(&self) -> usize {
        (self.offsets.len().max(1) - 1) / self.columns.max(1) as usize
    }

    /// The column of the cosine alone (the last).
    pub fn diffuse(&self) -> usize {
        self.columns as usize - 1
    }

    /// Column `k` of vertex `v`: its kept coefficients' indices and values.
    pub fn column(&self, v: usize, k: usize) -> (&[u32], &[f32]) {
        let i = v * self.columns as usize + k;
        let r = self.offsets[i] as usize..self.offsets[i + 1] as usize;
        (&self.index[r.clone()], &self.value[r])
    }

    /// Per column of vertex `v`, Σ_c C^L_c T̃_c for the environment's Haar coefficients
    /// `env_haar` (6 n² of them, `EnvLight::haar` at this side) into `out` (`columns` long):
    /// U^I0(·, k) of [S] 5-7 and, in the last slot, the irradiance.
    pub fn apply_into(&self, v: usize, env_haar: &[Vec3], out: &mut [Vec3]) {
        assert_eq!(env_haar.len(), 6 * (self.n as usize).pow(2), "the environment's coefficients are at another side");
        let c = self.columns as usize;
        let offs = &self.offsets[v * c..=(v + 1) * c];
        for (o, w) in out.iter_mut().zip(offs.windows(2)) {
            let r = w[0] as usize..w[1] as usize;
            let (index, value) = (&self.index[r.clone()], &self.value[r]);
            // Four running sums, so that the adds do not wait on each other; a fixed order.
            let mut acc = [Vec3::ZERO; 4];
            let (i4, v4) = (index.chunks_exact(4), value.chunks_exact(4));
            let tail = i4.remainder().iter().zip(v4.remainder()).fold(Vec3::ZERO, |s, (&i, &t)| s + env_haar[i as usize] * t);
            for (i, t) in i4.zip(v4) {
                for q in 0..4 {
                    acc[q] += env_haar[i[q] as usize] * t[q];
                }
            }
            *o = (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail;
        }
    }

    /// `apply_into` into a new vector.
    pub fn apply(&self, v: usize, env_haar: &[Vec3]) -> Vec<Vec3> {
        let mut out = vec![Vec3::ZERO; self.columns as usize];
        self.apply_into(v, env_haar, &mut out);
        out
    }

    /// Bytes held for `vertices` with `columns` columns of at most `terms` terms (checked
    /// before allocating).
    pub fn bytes_for(vertices: u64, columns: u64, terms: u64) -> u64 {
        vertices.saturating_mul(columns).saturating_mul(terms.saturating_mul(8).saturating_add(4)).saturating_add(64)
    }

    fn is_consistent(&self) -> bool {
        let (c, texels) = (self.columns as usize, 6 * (self.n as u64).pow(2));
        c > 0
            && self.n > 0
            && self.n.is_power_of_two()
            && !self.offsets.is_empty()
            && (self.offsets.len() - 1).is_multiple_of(c)
            && self.offsets[0] == 0
            && self.offsets.windows(2).all(|w| w[0] <= w[1] && w[1] - w[0] <= self.terms)
            && *self.offsets.last().unwrap_or(&0) as usize == self.index.len()
            && self.index.len() == self.value.len()
            && self.index.iter().all(|&i| (i as u64) < texels)
            && self.value.iter().all(|v| v.is_finite())
    }
}

impl PortValue for DirectTransfer {
    const NAME: &'static str = "DirectTransfer";
    const COLOR: [u8; 3] = [230, 190, 60];
    const DOC: &'static str = "per vertex, the direct-light transfer's largest Haar terms per column of the BRDF's incoming factor";
    fn byte_size(&self) -> usize {
        (self.offsets.len() + self.index.len() + self.value.len()) * 4 + 32
    }
    relume_core::serde_codec!(check DirectTransfer::is_consistent);
}
