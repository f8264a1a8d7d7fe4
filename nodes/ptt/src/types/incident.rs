//! The port types of the incident-light stages: the projected SH columns of the seen
//! vertices, and the per-vertex incident light (direct, bounced, and their sum).

use crate::bounce::SH;
use glam::Vec3;
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// One cluster's one-bounce core under the current environment: per vertex factor a, per
/// reflector slot r and SH coefficient q, RGB at `core[(a · slots + r) · 16 + q]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LitCore {
    pub rank_v: u32,
    #[serde(with = "pod_vec")]
    pub core: Vec<Vec3>,
}

/// No slot: the vertex is not shaded with the BRDF tensor.
pub const NO_SLOT: u32 = u32::MAX;

/// No owner: no triangle uses the vertex.
pub const NO_OWNER: u32 = u32::MAX;

/// Per vertex of a dynamic object (a "slot"), the projections P_k(s) = ∫ Y_s(ω) U^ωi(F⁻¹ω, k)
/// (ω · n)⁺ dω of each column k of the BRDF tensor's incoming factor, times the cosine, in
/// the vertex frame F, on 4-band real SH in world axes: against incident light given in
/// world SH (the one-bounce transfer's), U^I_k = Σ_s c_s P_k(s). `slot[v]` is the vertex's
/// slot or `NO_SLOT` (vertices of fixed objects, shaded diffuse only); slot t's values at
/// `values[t · columns · 16 ..]`, laid out (column, s). `normals` are every vertex's, and
/// `owner[v]` the scene object of v's first triangle (`NO_OWNER` for a vertex no triangle
/// uses), kept here so that the per-edit nodes need not walk the triangles again.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShColumns {
    pub columns: u32,
    pub slot: Vec<u32>,
    pub owner: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub normals: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub values: Vec<f32>,
}

impl ShColumns {
    /// Slots (vertices shaded with the tensor).
    pub fn slots(&self) -> usize {
        self.values.len() / (self.columns as usize * SH).max(1)
    }

    /// Slot `t`'s projections, `columns` × 16.
    pub fn of(&self, t: usize) -> &[f32] {
        let w = self.columns as usize * SH;
        &self.values[t * w..(t + 1) * w]
    }

    /// Vertex `v`'s scene object, if a triangle uses it.
    pub fn owner_of(&self, v: usize) -> Option<u32> {
        Some(self.owner[v]).filter(|&o| o != NO_OWNER)
    }

    /// Bytes held for `vertices` with `slots` of them shaded by `columns` columns.
    pub fn bytes_for(vertices: u64, slots: u64, columns: u64) -> u64 {
        vertices.saturating_mul(20).saturating_add(slots.saturating_mul(columns).saturating_mul(SH as u64 * 4)).saturating_add(32)
    }

    pub(crate) fn is_consistent(&self) -> bool {
        let w = self.columns as usize * SH;
        let slots = self.values.len().checked_div(w).unwrap_or(0);
        self.slot.len() == self.normals.len()
            && self.owner.len() == self.normals.len()
            && (w == 0 || self.values.len().is_multiple_of(w))
            && self.slot.iter().all(|&t| t == NO_SLOT || (t as usize) < slots)
            && self.values.iter().all(|x| x.is_finite())
            && self.normals.iter().all(|n| n.is_finite())
    }
}

impl PortValue for ShColumns {
    const NAME: &'static str = "ShColumns";
    const COLOR: [u8; 3] = [200, 170, 90];
    const DOC: &'static str = "per shaded vertex, the world-SH projection of the BRDF's incoming factor times the cosine";
    fn byte_size(&self) -> usize {
        self.values.len() * 4 + (self.slot.len() + self.owner.len()) * 4 + self.normals.len() * 12 + 16
    }
    relume_core::serde_codec!(check ShColumns::is_consistent);
}

/// The light arriving at every vertex, view-independent ([S] 5-5, 5-6): `irradiance[v]` the
/// diffuse part's E = E⁰ + E¹ + E² (∫ incident radiance × (ω · n)⁺, RGB); for the vertices
/// shaded with the BRDF tensor (slots of `ShColumns`, same numbering), `tensor` the incident
/// light against each column of its incoming factor, U^I_k = U^{I0}_k + U^{I1}_k + U^{I2}_k
/// (slot t's n_ωi values at `tensor[t · columns ..]`), and `bounce` the one-bounce light's
/// 4-band SH in world axes (slot t's 16 at `bounce[t · 16 ..]`) that the specular lobes
/// filter (two-bounce light gets no lobe, [S] 5.3.3.5).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VertexIncident {
    pub columns: u32,
    pub bounces: u32,
    #[serde(with = "pod_vec")]
    pub irradiance: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub tensor: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub bounce: Vec<Vec3>,
}

impl VertexIncident {
    /// Bytes held for `vertices` with `slots` shaded by `columns` columns.
    pub fn bytes_for(vertices: u64, slots: u64, columns: u64) -> u64 {
        vertices.saturating_mul(12).saturating_add(slots.saturating_mul(columns + SH as u64).saturating_mul(12)).saturating_add(32)
    }

    pub(crate) fn is_consistent(&self) -> bool {
        let c = self.columns as usize;
        let slots = self.bounce.len() / SH;
        self.bounce.len().is_multiple_of(SH)
            && self.tensor.len() == slots * c
            && self.bounces <= 2
            && self.irradiance.iter().chain(&self.tensor).chain(&self.bounce).all(|v| v.is_finite())
    }
}

impl PortValue for VertexIncident {
    const NAME: &'static str = "VertexIncident";
    const COLOR: [u8; 3] = [250, 200, 120];
    const DOC: &'static str =
        "per vertex, the incident light: diffuse irradiance, the BRDF tensor's incoming columns and the one-bounce SH";
    fn byte_size(&self) -> usize {
        (self.irradiance.len() + self.tensor.len() + self.bounce.len()) * 12 + 16
    }
    relume_core::serde_codec!(check VertexIncident::is_consistent);
}

/// The environment's direct light at every vertex ([S] 5-7): `irradiance[v]` E⁰ (RGB) and,
/// for the vertices shaded with the BRDF tensor (slots of `ShColumns`), `tensor` the direct
/// light against each column of the tensor's incoming factor, U^{I0} (slot t's `columns`
/// values at `tensor[t · columns ..]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DirectLight {
    pub columns: u32,
    #[serde(with = "pod_vec")]
    pub irradiance: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub tensor: Vec<Vec3>,
}

impl DirectLight {
    /// Bytes held for `vertices` with `slots` shaded by `columns` columns.
    pub fn bytes_for(vertices: u64, slots: u64, columns: u64) -> u64 {
        vertices.saturating_add(slots.saturating_mul(columns)).saturating_mul(12).saturating_add(16)
    }

    pub(crate) fn is_consistent(&self) -> bool {
        self.columns > 0
            && self.tensor.len().is_multiple_of(self.columns as usize)
            && self.irradiance.iter().chain(&self.tensor).all(|v| v.is_finite())
    }
}

impl PortValue for DirectLight {
    const NAME: &'static str = "DirectLight";
    const COLOR: [u8; 3] = [250, 220, 100];
    const DOC: &'static str = "per vertex, the environment's direct light: irradiance and the BRDF tensor's incoming columns";
    fn byte_size(&self) -> usize {
        Self::bytes_for(self.irradiance.len() as u64, (self.tensor.len() / self.columns.max(1) as usize) as u64, self.columns as u64)
            as usize
    }
    relume_core::serde_codec!(check DirectLight::is_consistent);
}

/// The bounced light of every vertex under the current environment, with the reflectors'
/// materials still open ([S] 5-5, 5-6): what `PttIncident` weighs by the materials. Reflector
/// slots: slot 0 the fixed objects together (their own reflectance folded in), slot 1 + j the
/// j-th dynamic channel (group by group, `bases` each, two more for a group a diffuse map
/// colours: `textured`), weighted by its basis coefficient.
/// `cores`: per cluster of `TransferT1`, the lighting-contracted core (`LitCore`); `pairs`:
/// per vertex, the two-bounce light per reflector pair (r₁, r₂), RGB at
/// `pairs[(v · slots + r₁) · slots + r₂]`, to be weighted by both slots' coefficients.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BounceLight {
    pub bounces: u32,
    pub groups: Vec<String>,
    pub bases: u32,
    #[serde(default)]
    pub textured: Vec<bool>,
    pub cores: Vec<LitCore>,
    #[serde(with = "pod_vec")]
    pub pairs: Vec<Vec3>,
}

impl BounceLight {
    /// Reflector slots: the fixed objects, then every dynamic channel.
    pub fn slots(&self) -> usize {
        1 + crate::channels::group_channels(self.bases as usize, &self.textured).sum::<usize>()
    }

    /// Vertex `v`'s pairs (slots² RGB values).
    pub fn pairs_of(&self, v: usize) -> &[Vec3] {
        let s2 = self.slots() * self.slots();
        &self.pairs[v * s2..(v + 1) * s2]
    }

    /// Bytes for `vertices` with one-bounce cores of `core_rows` vertex factors in all, at
    /// `slots` reflector slots and `bounces`.
    pub fn bytes_for(vertices: u64, core_rows: u64, slots: u64, bounces: u32) -> u64 {
        let cores = if bounces >= 1 { core_rows.saturating_mul(slots).saturating_mul(SH as u64) } else { 0 };
        let pairs = if bounces == 2 { vertices.saturating_mul(slots * slots) } else { 0 };
        cores.saturating_add(pairs).saturating_mul(12).saturating_add(64)
    }

    pub(crate) fn is_consistent(&self) -> bool {
        let s = self.slots();
        self.textured.len() == self.groups.len()
            && self.bounces <= 2
            && self.pairs.len().is_multiple_of(s * s)
            && self.cores.iter().all(|c| c.core.len() == c.rank_v as usize * s * SH && c.core.iter().all(|v| v.is_finite()))
            && self.pairs.iter().all(|v| v.is_finite())
    }
}

impl PortValue for BounceLight {
    const NAME: &'static str = "BounceLight";
    const COLOR: [u8; 3] = [240, 170, 110];
    const DOC: &'static str = "the bounced light under the current environment, per reflector slot, before the materials weigh it";
    fn byte_size(&self) -> usize {
        (self.cores.iter().map(|c| c.core.len()).sum::<usize>() + self.pairs.len()) * 12 + 64
    }
    relume_core::serde_codec!(check BounceLight::is_consistent);
}
