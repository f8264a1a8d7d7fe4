//! Port types of the transfer-tensor pipeline: the environment as the renderer reads it
//! (`EnvLight`) and the vertices' visibility of it (`Visibility`); the BRDF tensor and its
//! factors in `brdf`, the light and transfer of the bounces in `incident` and `transfer`.

pub mod brdf;
mod incident;
mod transfer;

pub use incident::{BounceLight, DirectLight, LitCore, ShColumns, VertexIncident, NO_OWNER, NO_SLOT};
pub use transfer::{BounceTransfer, DirectTransfer, LobeVisibility, PackedTwoBounce, TwoBounce};

use glam::Vec3;
use relume_base::math::cubemap::CubeMap;
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// One environment prefiltered by a Gaussian lobe of angular standard deviation `sigma_deg`
/// (`CubeMap::gaussian_prefilter`), at side `n`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PrefilteredEnv {
    pub sigma_deg: f32,
    pub n: u32,
    #[serde(with = "pod_vec")]
    pub texels: Vec<Vec3>,
}

/// The environment on a cube map of side `n` (6 n² texels of radiance, `math::cubemap`'s
/// layout), its Haar coefficients C^L (`math::cube_haar`, dense, all kept: the transfer
/// keeps its own largest terms) and the environment prefiltered for each specular lobe of
/// non-zero width (the 0° lobe reads `map`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvLight {
    pub n: u32,
    #[serde(with = "pod_vec")]
    pub map: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub haar: Vec<Vec3>,
    pub lobes: Vec<PrefilteredEnv>,
}

impl EnvLight {
    /// The radiance map as a `CubeMap`.
    pub fn cube(&self) -> CubeMap {
        CubeMap { n: self.n as usize, texels: self.map.clone() }
    }

    fn is_consistent(&self) -> bool {
        let n = self.n as usize;
        let texels = 6 * n * n;
        n > 0
            && n.is_power_of_two()
            && self.map.len() == texels
            && self.haar.len() == texels
            && self.map.iter().chain(&self.haar).all(|v| v.is_finite())
            && self.lobes.iter().all(|l| {
                let m = l.n as usize;
                m > 0
                    && l.texels.len() == 6 * m * m
                    && l.sigma_deg.is_finite()
                    && l.sigma_deg > 0.0
                    && l.texels.iter().all(|v| v.is_finite())
            })
    }
}

impl PortValue for EnvLight {
    const NAME: &'static str = "EnvLight";
    const COLOR: [u8; 3] = [250, 210, 90];
    const DOC: &'static str =
        "an environment on a cube map, its Haar coefficients and its Gaussian-prefiltered copies for the specular lobes";
    fn byte_size(&self) -> usize {
        (self.map.len() + self.haar.len() + self.lobes.iter().map(|l| l.texels.len()).sum::<usize>()) * 12 + 64
    }
    relume_core::serde_codec!(check EnvLight::is_consistent);
}

/// Per vertex, the binary visibility of the environment over the 6 n² directions of a cube
/// map (`math::cubemap`'s texel order; bit k of vertex v is bit k % 32 of word
/// `v × words + k / 32`; set where the texel's centre direction is above the vertex's
/// tangent plane and its ray escapes), and per texel of the coarse map of side `coarse` the
/// visible, cosine-weighted solid angle Σ V(ω) (ω · n) Ω(ω) over the fine texels it covers
/// (what a hit point's direct light from each box lighting basis needs, [S] 5.3.3.6). The
/// normals are the vertices' shading normals the rays were cast around.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Visibility {
    pub n: u32,
    pub coarse: u32,
    #[serde(with = "pod_vec")]
    pub normals: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub bits: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub coarse_cos: Vec<f32>,
}

impl Visibility {
    /// 32-bit words per vertex.
    pub fn words(n: u32) -> usize {
        (6 * n as usize * n as usize).div_ceil(32)
    }
    pub fn vertices(&self) -> usize {
        self.normals.len()
    }
    /// The visibility words of vertex `v`.
    pub fn of(&self, v: usize) -> &[u32] {
        let w = Self::words(self.n);
        &self.bits[v * w..(v + 1) * w]
    }
    /// Whether texel `k` is visible from vertex `v`.
    pub fn visible(&self, v: usize, k: usize) -> bool {
        self.of(v)[k / 32] >> (k % 32) & 1 == 1
    }
    /// The coarse cosine-weighted visible solid angles of vertex `v`.
    pub fn coarse_of(&self, v: usize) -> &[f32] {
        let c = 6 * self.coarse as usize * self.coarse as usize;
        &self.coarse_cos[v * c..(v + 1) * c]
    }
    /// Bytes held for `vertices` at sides `n` and `coarse` (checked before allocating).
    pub fn bytes_for(vertices: u64, n: u32, coarse: u32) -> u64 {
        vertices * (Self::words(n) as u64 * 4 + 6 * coarse as u64 * coarse as u64 * 4 + 12)
    }

    fn is_consistent(&self) -> bool {
        let v = self.normals.len();
        self.n > 0
            && self.coarse > 0
            && self.n.is_multiple_of(self.coarse)
            && self.bits.len() == v * Self::words(self.n)
            && self.coarse_cos.len() == v * 6 * (self.coarse as usize).pow(2)
            && self.normals.iter().all(|n| n.is_finite())
            && self.coarse_cos.iter().all(|c| c.is_finite() && *c >= 0.0)
    }
}

impl PortValue for Visibility {
    const NAME: &'static str = "Visibility";
    const COLOR: [u8; 3] = [200, 200, 120];
    const DOC: &'static str =
        "per vertex, which cube-map directions see the environment (bitsets), with coarse cosine-weighted visible solid angles";
    fn byte_size(&self) -> usize {
        self.bits.len() * 4 + self.coarse_cos.len() * 4 + self.normals.len() * 12 + 32
    }
    relume_core::serde_codec!(check Visibility::is_consistent);
}

/// A run of vertices' visibility: the partial result of `VertexVisibility` sharded over
/// vertices.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VisibilityChunk {
    pub first: u64,
    pub count: u64,
    #[serde(with = "pod_vec")]
    pub bits: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub coarse_cos: Vec<f32>,
}

impl VisibilityChunk {
    fn is_consistent(&self) -> bool {
        self.coarse_cos.iter().all(|x| x.is_finite() && *x >= 0.0)
    }
}

impl PortValue for VisibilityChunk {
    const NAME: &'static str = "VisibilityChunk";
    const COLOR: [u8; 3] = [200, 200, 120];
    const DOC: &'static str = "the visibility of a run of vertices (a shard's partial)";
    fn byte_size(&self) -> usize {
        self.bits.len() * 4 + self.coarse_cos.len() * 4 + 16
    }
    relume_core::serde_codec!(check VisibilityChunk::is_consistent);
}

/// One RGB value per scene vertex (the relit radiance toward the camera, [S] 5-5), in the
/// scene's vertex order; and, where some object's diffuse reflectance is a texture map
/// (`textured` non-empty, one per vertex too), the part of each vertex's radiance that the
/// map multiplies at each pixel (the light times the material's own reflectance over π),
/// `colors` then holding the rest. Shading per vertex and texturing per pixel, as a GPU
/// multiplies a texture into the interpolated lighting.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct VertexColors {
    #[serde(with = "pod_vec")]
    pub colors: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub textured: Vec<Vec3>,
}

impl VertexColors {
    /// Refuses `vertices` colours over the budget, before they are allocated.
    pub fn check_budget(vertices: usize, budget: u64) -> Result<(), relume_core::NodeError> {
        let bytes = vertices as u64 * 12 + 8;
        if bytes > budget {
            return Err(relume_core::NodeError::over_limit(format!(
                "the colours of {vertices} vertices would hold {}, over the {} budget",
                relume_core::memory::fmt_bytes(bytes),
                relume_core::memory::fmt_bytes(budget)
            )));
        }
        Ok(())
    }

    /// Colours alone, nothing textured per pixel.
    pub fn plain(colors: Vec<Vec3>) -> VertexColors {
        VertexColors { colors, textured: vec![] }
    }

    fn is_consistent(&self) -> bool {
        (self.textured.is_empty() || self.textured.len() == self.colors.len())
            && self.colors.iter().chain(&self.textured).all(|c| c.is_finite())
    }
}

impl PortValue for VertexColors {
    const NAME: &'static str = "VertexColors";
    const COLOR: [u8; 3] = [240, 150, 200];
    const DOC: &'static str = "one RGB value per scene vertex (and the part a texture map multiplies per pixel)";
    fn byte_size(&self) -> usize {
        (self.colors.len() + self.textured.len()) * 12 + 16
    }
    relume_core::serde_codec!(check VertexColors::is_consistent);
}

/// The clustered tensor approximation's plan ([S] 5.3.3.4): the vertex clusters (each
/// cluster's members ascending; every vertex in exactly one) and the ranks each cluster's
/// bounce transfer is cut to: `rank_v` eigenvectors over its vertices, `rank_l` over the
/// lighting bases, after `sweeps` HOOI rounds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CtaPlan {
    pub members: Vec<Vec<u32>>,
    pub rank_v: u32,
    pub rank_l: u32,
    pub sweeps: u32,
}

impl CtaPlan {
    /// Vertices in all.
    pub fn vertices(&self) -> usize {
        self.members.iter().map(|m| m.len()).sum()
    }
    /// The largest cluster's size.
    pub fn largest(&self) -> usize {
        self.members.iter().map(|m| m.len()).max().unwrap_or(0)
    }

    fn is_consistent(&self) -> bool {
        let n = self.vertices();
        let mut seen = vec![false; n];
        self.members.iter().flatten().all(|&v| (v as usize) < n && !std::mem::replace(&mut seen[v as usize], true))
    }
}

impl PortValue for CtaPlan {
    const NAME: &'static str = "CtaPlan";
    const COLOR: [u8; 3] = [170, 140, 230];
    const DOC: &'static str = "vertex clusters and the ranks of the clustered tensor approximation";
    fn byte_size(&self) -> usize {
        self.vertices() * 4 + self.members.len() * 8 + 16
    }
    relume_core::serde_codec!(check CtaPlan::is_consistent);
}

/// The side of a lobe's prefiltered map: the coarsest power of two (at most `side`) whose
/// texels, 90°/m wide at a face's centre, are at most half of σ.
pub fn lobe_side(sigma_deg: f64, side: usize) -> usize {
    let mut m = 1;
    while m < side && 90.0 / m as f64 > 0.5 * sigma_deg {
        m *= 2;
    }
    m.min(side)
}
