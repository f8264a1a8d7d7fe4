//! PttIncident node.

use super::bounce::SH;
use super::incident_projection::{ShColumns, NO_SLOT};
use super::ptt_direct::DirectLight;
use super::transfer_t1::BounceTransfer;
use super::transfer_t2::TwoBounce;
use super::types::EnvLight;
use crate::math::cubemap::CubeMap;
use crate::math::sh::{clamped_cosine_zonal, sh_basis_into, Y00};
use crate::types::{pod_vec, ObjectMaterials};
use glam::Vec3;
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, MemoryEstimate, NodeError, Params, PortSize, PortValue, RunCtx};
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;

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

    fn is_consistent(&self) -> bool {
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

/// The light arriving at every vertex under the current environment and materials ([S] 5-5,
/// 5-6; the view-independent half of the relighting): per vertex, the direct light E⁰ and
/// U^{I0} (`PttDirect`, which a material edit does not re-run); with `bounces` ≥ 1 the one-bounce light, the
/// environment box-averaged to `TransferT1`'s lighting bases (`CubeMap::box_downsample`)
/// contracted with each cluster's compressed transfer and the channels weighted by the
/// dynamic objects' basis coefficients (`MaterialProject`; fixed channels weigh 1): 4-band SH
/// I¹ in world axes, giving E¹ = Σ_s c_s Â_l Y_s(n) and U^{I1}_k = Σ_s c_s P_k(s)
/// (`IncidentProjection`); with `bounces` = 2 the two-bounce light I² (`TransferT2`: taken
/// as uniform over the hemisphere, [S] 5.3.3.5, so E² = π I² and U^{I2}_k = I² ∫ U^ωi_k cos),
/// each reflector pair weighted by both channels' coefficients. Re-runs on a lighting or
/// material change; a view change does not reach it.
///
/// Metrics: vertices, slots, bounces, the mean luminance of E⁰, E¹ and E² over the vertices
/// (how much each bounce adds), bytes.
#[derive(Params)]
pub struct PttIncident {
    /// reflections carried: 0 direct only, 1 one bounce, 2 two bounces ([S] 5-5)
    #[param(default = 2, range = 0..=2)]
    pub bounces: usize,
}

inputs!(pub PttIncidentIn {
    env: EnvLight,
    direct: DirectLight,
    bounce: BounceTransfer,
    two: TwoBounce,
    projection: ShColumns,
    materials: ObjectMaterials,
});
outputs!(pub PttIncidentOut { incident: VertexIncident });

fn lum(v: Vec3) -> f64 {
    v.dot(Vec3::new(0.2126, 0.7152, 0.0722)) as f64
}

/// The channel weights of the transfer for the dynamic objects' materials (in the transfer's
/// group order, matched by name).
fn channel_weights(t: &BounceTransfer, materials: &ObjectMaterials) -> Result<Vec<Vec3>, NodeError> {
    let mut w = match t.fixed {
        0 => vec![],
        1 => vec![Vec3::ONE],
        _ => vec![Vec3::X, Vec3::Y, Vec3::Z],
    };
    for g in &t.groups {
        let m = materials.0.iter().find(|m| &m.name == g).ok_or_else(|| {
            NodeError::input("materials", format!("no material for the dynamic object \"{g}\" the transfer was traced for"))
        })?;
        if m.coefficients.len() != t.bases as usize {
            return Err(NodeError::input(
                "materials",
                format!(
                    "\"{}\" has {} basis coefficients, the transfer {} bases (project the materials with MaterialProject on the transfer's basis)",
                    m.name,
                    m.coefficients.len(),
                    t.bases
                ),
            ));
        }
        w.extend(m.coefficients.iter().map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)));
    }
    Ok(w)
}

/// The environment at side `m` as box-basis weights per colour (`CubeMap::box_downsample`).
fn box_light(env: &EnvLight, m: usize) -> Result<Vec<Vec3>, NodeError> {
    if m == 0 || !(env.n as usize).is_multiple_of(m) {
        return Err(NodeError::input("env", format!("a cube map of side {} cannot be box-filtered to the transfer's side {m}", env.n)));
    }
    Ok(CubeMap { n: env.n as usize, texels: env.map.clone() }.box_downsample(m).texels)
}

impl PttIncident {
    fn check(&self, i: &PttIncidentIn) -> Result<usize, NodeError> {
        let n = i.projection.normals.len();
        let (d, p) = (i.direct, i.projection);
        if d.irradiance.len() != n || i.bounce.plan.vertices() != n || (i.two.stride() > 0 && i.two.values.len() / i.two.stride() != n) {
            return Err(NodeError::input(
                "direct",
                format!(
                    "the direct light holds {} vertices, the transfers {} (one bounce) and {} (two bounces), the projection {n}: they must come from the same scene",
                    d.irradiance.len(),
                    i.bounce.plan.vertices(),
                    i.two.values.len() / i.two.stride().max(1)
                ),
            ));
        }
        if d.columns != p.columns || d.tensor.len() != p.slots() * p.columns as usize {
            return Err(NodeError::input(
                "projection",
                format!(
                    "projects {} columns on {} slots but the direct light has {} columns and {} values: they must come from the same BRDF tensor",
                    p.columns,
                    p.slots(),
                    d.columns,
                    d.tensor.len()
                ),
            ));
        }
        if i.two.channels as usize != i.bounce.channels() {
            return Err(NodeError::input(
                "two",
                format!(
                    "has {} channels, the one-bounce transfer {}: they must come from the same scene and basis",
                    i.two.channels,
                    i.bounce.channels()
                ),
            ));
        }
        Ok(n)
    }
}

#[node(category = "ptt")]
impl PttIncident {
    fn memory(&self, _inputs: &[Option<PortSize>]) -> MemoryEstimate {
        MemoryEstimate { outputs: vec![None], working: 0 }
    }

    fn run(&self, i: PttIncidentIn, cx: &RunCtx) -> Result<PttIncidentOut, NodeError> {
        let n = self.check(&i)?;
        let (p, cols) = (i.projection, i.projection.columns as usize);
        let slots = p.slots();
        let bytes = VertexIncident::bytes_for(n as u64, slots as u64, cols as u64);
        if bytes > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "the incident light of {n} vertices would hold {}, over the {} budget",
                fmt_bytes(bytes),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let w = channel_weights(i.bounce, i.materials)?;
        // One bounce: per vertex its world SH (16 RGB), from each cluster's lighting-contracted core.
        let mut sh1 = vec![[Vec3::ZERO; SH]; if self.bounces >= 1 { n } else { 0 }];
        if self.bounces >= 1 {
            let light = box_light(i.env, i.bounce.coarse as usize)?;
            let per = cx.par_map(i.bounce.clusters.len(), |c| {
                let t = &i.bounce.clusters[c];
                let cores: Vec<Vec<f32>> = (0..3).map(|k| t.light_core(&light.iter().map(|l| l[k]).collect::<Vec<f32>>())).collect();
                let (rv, s) = (t.rank_v as usize, t.columns as usize);
                // Channels folded in: per vertex factor a, 16 RGB values.
                let folded: Vec<[Vec3; SH]> = (0..rv)
                    .map(|a| {
                        let mut out = [Vec3::ZERO; SH];
                        for (ch, wc) in w.iter().enumerate() {
                            for (q, o) in out.iter_mut().enumerate() {
                                let at = a * s + ch * SH + q;
                                *o += *wc * Vec3::new(cores[0][at], cores[1][at], cores[2][at]);
                            }
                        }
                        out
                    })
                    .collect();
                (0..t.vertices as usize)
                    .map(|k| {
                        let mut out = [Vec3::ZERO; SH];
                        for (a, f) in folded.iter().enumerate() {
                            let x = t.a[k * rv + a];
                            out.iter_mut().zip(f).for_each(|(o, f)| *o += *f * x);
                        }
                        out
                    })
                    .collect::<Vec<_>>()
            })?;
            for (members, rows) in i.bounce.plan.members.iter().zip(per) {
                for (&v, row) in members.iter().zip(rows) {
                    sh1[v as usize] = row;
                }
            }
        }
        // Two bounces: the weights of (l, c1, c2), RGB.
        let w2: Vec<Vec3> = if self.bounces == 2 {
            let light = box_light(i.env, i.two.side as usize)?;
            let mut out = Vec::with_capacity(light.len() * w.len() * w.len());
            for l in &light {
                for a in &w {
                    out.extend(w.iter().map(|b| *l * *a * *b));
                }
            }
            out
        } else {
            vec![]
        };
        let zonal: [f32; SH] = std::array::from_fn(|q| clamped_cosine_zonal((q as f64).sqrt() as usize));
        cx.check()?;
        let per = cx.par_map(n, |v| {
            let e0 = i.direct.irradiance[v];
            let nv = p.normals[v];
            let (mut c, mut e1, mut i2) = ([Vec3::ZERO; SH], Vec3::ZERO, Vec3::ZERO);
            if self.bounces >= 1 && nv != Vec3::ZERO {
                c = sh1[v];
                let mut y = [0.0f32; SH];
                sh_basis_into(nv, &mut y);
                e1 = c.iter().zip(y.iter().zip(&zonal)).map(|(c, (y, a))| *c * (y * a)).sum();
            }
            if self.bounces == 2 {
                i2 = i.two.of(v).iter().zip(&w2).map(|(t, w)| *w * *t).sum();
            }
            let (tensor, bounce) = match p.slot[v] {
                NO_SLOT => (vec![], vec![]),
                t => {
                    let pv = p.of(t as usize);
                    let cols0 = &i.direct.tensor[t as usize * cols..(t as usize + 1) * cols];
                    let mut total = c;
                    total[0] += i2 / Y00;
                    let tensor = (0..cols)
                        .map(|k| cols0[k] + total.iter().zip(&pv[k * SH..(k + 1) * SH]).map(|(c, x)| *c * *x).sum::<Vec3>())
                        .collect();
                    (tensor, c.to_vec())
                }
            };
            (e0, e1, PI * i2, tensor, bounce)
        })?;
        let mut out = VertexIncident {
            columns: cols as u32,
            bounces: self.bounces as u32,
            irradiance: Vec::with_capacity(n),
            tensor: Vec::with_capacity(slots * cols),
            bounce: Vec::with_capacity(slots * SH),
        };
        let mut means = [0.0f64; 3];
        for (e0, e1, e2, t, b) in per {
            out.irradiance.push(e0 + e1 + e2);
            out.tensor.extend(t);
            out.bounce.extend(b);
            for (m, e) in means.iter_mut().zip([e0, e1, e2]) {
                *m += lum(e);
            }
        }
        cx.metric("vertices", n as f64);
        cx.metric("slots", slots as f64);
        cx.metric("bounces", self.bounces as f64);
        for (name, m) in ["e0_mean", "e1_mean", "e2_mean"].iter().zip(means) {
            cx.metric(name, m / n.max(1) as f64);
        }
        cx.metric("bytes", out.byte_size() as f64);
        Ok(PttIncidentOut { incident: out })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ptt::test_support::{plane, Chain};
    use crate::ptt::vertex_visibility::tests::floor_and_tiled_roof;
    use crate::testing::{i, run_on};
    use crate::types::{Environment, Material};
    use relume_core::Value;

    fn lambert() -> Material {
        Material::Lambert { albedo: Vec3::splat(0.6) }
    }

    #[test]
    fn an_open_plane_under_a_constant_sky_gets_pi_and_under_a_zero_sky_nothing() {
        let c = Chain::new(plane(lambert(), false, Environment::Constant(Vec3::ONE)));
        let m = c.materials();
        for b in 0..=2 {
            let inc = c.incident(&c.env, &m, b);
            assert_eq!((inc.irradiance.len(), inc.tensor.len(), inc.bounce.len()), (81, 0, 0), "fixed objects get no tensor slot");
            for e in &inc.irradiance {
                assert!((*e - Vec3::splat(PI)).abs().max_element() < 0.01 * PI, "bounces {b}: {e}");
            }
        }
        let zero = EnvLight {
            map: vec![Vec3::ZERO; c.env.map.len()],
            haar: vec![Vec3::ZERO; c.env.haar.len()],
            lobes: c
                .env
                .lobes
                .iter()
                .map(|l| super::super::types::PrefilteredEnv { texels: vec![Vec3::ZERO; l.texels.len()], ..l.clone() })
                .collect(),
            ..c.env.clone()
        };
        assert!(c.incident(&zero, &m, 2).irradiance.iter().all(|e| *e == Vec3::ZERO));
    }

    #[test]
    fn roofed_floor_vertices_gain_light_with_each_bounce_and_the_bytes_do_not_depend_on_threads() {
        let c = Chain::new(floor_and_tiled_roof(0.5));
        let m = c.materials();
        let e: Vec<Vec3> = (0..=2).map(|b| c.incident(&c.env, &m, b).irradiance[4 * 9 + 6]).collect();
        assert!(e[0].x > 0.1 && e[1].x > e[0].x * 1.01 && e[2].x > e[1].x * 1.001, "{e:?}");
        assert!(e.iter().all(|v| v.x == v.y && v.y == v.z), "grey scene, grey light: {e:?}");
        let inputs = c.incident_inputs(&c.env, &m);
        let one: VertexIncident = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| crate::testing::first(&run_on::<PttIncident>(&[], inputs.clone()).expect("runs")));
        assert_eq!(one, c.incident(&c.env, &m, 2));
        assert_eq!(VertexIncident::decode(&one.encode()), Some(one));
    }

    #[test]
    fn inputs_from_other_scenes_or_sides_are_refused() {
        let c = Chain::new(plane(lambert(), false, Environment::Constant(Vec3::ONE)));
        let m = c.materials();
        let mut inputs = c.incident_inputs(&c.env, &m);
        let odd = EnvLight { n: 3, map: vec![Vec3::ONE; 54], haar: vec![Vec3::ZERO; 54], ..c.env.clone() };
        inputs[0] = Value::new(odd);
        let e = run_on::<PttIncident>(&[("bounces", i(2))], inputs).expect_err("other side");
        assert!(e.to_string().contains("side"), "{e}");
        let other = Chain::new(floor_and_tiled_roof(0.5));
        let mut inputs = c.incident_inputs(&c.env, &m);
        inputs[1] = Value::new(other.direct_light(&other.env));
        let e = run_on::<PttIncident>(&[], inputs).expect_err("other scene");
        assert!(e.to_string().contains("same scene"), "{e}");
    }
}
