use super::bounce::SH;
use super::types::BounceLight;
use super::types::BounceTransfer;
use super::types::DirectLight;
use super::types::{ShColumns, NO_SLOT};
use crate::types::VertexIncident;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::math::sh::{clamped_cosine_zonal, sh_basis_into, Y00};
use relume_base::types::ObjectMaterials;
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, NodeError, Params, PortValue, RunCtx};
use std::f32::consts::PI;

/// The light arriving at every vertex under the current environment and materials ([S] 5-5,
/// 5-6; the view-independent half of the relighting, and the only part of it a material edit
/// re-runs): per vertex, the direct light E⁰ and U^{I0} (`PttDirect`); with one bounce or
/// more (`PttBounceLight`'s `bounces`), the one-bounce light from each cluster's
/// lighting-contracted core with the reflector slots weighted by the dynamic objects' basis
/// coefficients (`MaterialProject`; the fixed objects' slot weighs 1), expanded per vertex
/// by the cluster's vertex factors (one matrix product): 4-band SH I¹ in world axes, giving
/// E¹ = Σ_s c_s Â_l Y_s(n) and U^{I1}_k = Σ_s c_s P_k(s) (`IncidentProjection`); with two,
/// the two-bounce light I² (taken as uniform over the hemisphere, [S] 5.3.3.5, so E² = π I²
/// and U^{I2}_k = I² ∫ U^ωi_k cos), each reflector pair weighted by both slots'
/// coefficients. A view change does not reach it.
///
/// Metrics: vertices, slots, bounces, the mean luminance of E⁰, E¹ and E² over the vertices
/// (how much each bounce adds), bytes.
#[derive(Params)]
pub struct PttIncident {}

inputs!(pub PttIncidentIn {
    direct: DirectLight,
    bounce: BounceTransfer,
    light: BounceLight,
    projection: ShColumns,
    materials: ObjectMaterials,
});
outputs!(pub PttIncidentOut { incident: VertexIncident });

fn lum(v: Vec3) -> f64 {
    v.dot(Vec3::new(0.2126, 0.7152, 0.0722)) as f64
}

/// The reflector slots' weights for the dynamic objects' materials: the fixed objects' slot
/// 1, then each dynamic group's basis coefficients (in the light's group order, matched by
/// name; a textured group's diffuse one split into its colours, `channels::group_weights`).
fn slot_weights(light: &BounceLight, materials: &ObjectMaterials) -> Result<Vec<Vec3>, NodeError> {
    let mut w = vec![Vec3::ONE];
    for (g, &textured) in light.groups.iter().zip(&light.textured) {
        let m = materials.0.iter().find(|m| &m.name == g).ok_or_else(|| {
            NodeError::input("materials", format!("no material for the dynamic object \"{g}\" the transfer was traced for"))
        })?;
        if m.coefficients.len() != light.bases as usize {
            return Err(NodeError::input(
                "materials",
                format!(
                    "\"{}\" has {} basis coefficients, the transfer {} bases (project the materials with MaterialProject on the transfer's basis)",
                    m.name,
                    m.coefficients.len(),
                    light.bases
                ),
            ));
        }
        let c: Vec<Vec3> = m.coefficients.iter().map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)).collect();
        w.extend(crate::channels::group_weights(&c, textured));
    }
    Ok(w)
}

/// Vertices per task of the per-vertex pass.
const CHUNK: usize = 1024;

impl PttIncident {
    fn check(&self, i: &PttIncidentIn) -> Result<usize, NodeError> {
        let n = i.projection.normals.len();
        let (d, p, l) = (i.direct, i.projection, i.light);
        let pairs = l.pairs.len() / (l.slots() * l.slots());
        if d.irradiance.len() != n || i.bounce.plan.vertices() != n || (l.bounces == 2 && pairs != n) {
            return Err(NodeError::input(
                "direct",
                format!(
                    "the direct light holds {} vertices, the transfer {} and the two-bounce light {pairs}, the projection {n}: they must come from the same scene",
                    d.irradiance.len(),
                    i.bounce.plan.vertices(),
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
        let same_clusters = l.bounces == 0
            || (l.cores.len() == i.bounce.clusters.len()
                && l.cores.iter().zip(&i.bounce.clusters).all(|(c, t)| c.rank_v == t.rank_v)
                && l.slots() == 1 + i.bounce.channels() - i.bounce.fixed as usize);
        if !same_clusters || l.groups != i.bounce.groups || l.textured != i.bounce.textured {
            return Err(NodeError::input(
                "light",
                "was lit from another transfer: the bounced light and the transfer must come from the same TransferT1",
            ));
        }
        Ok(n)
    }

    /// Per cluster its vertices' one-bounce SH (16 RGB each, world axes; column k the
    /// cluster's k-th member): the core folded with the slot weights `w`, then A (vertices ×
    /// r_v) times it (r_v × 48) in one product, held transposed.
    fn one_bounce(i: &PttIncidentIn, w: &[Vec3], cx: &RunCtx) -> Result<Vec<Mat<f32>>, NodeError> {
        let slots = w.len();
        cx.par_map(i.bounce.clusters.len(), |c| {
            let (t, lit) = (&i.bounce.clusters[c], &i.light.cores[c]);
            let rv = t.rank_v as usize;
            let folded = Mat::<f32>::from_fn(rv, 3 * SH, |a, col| {
                let (q, k) = (col / 3, col % 3);
                (0..slots).map(|r| w[r][k] * lit.core[(a * slots + r) * SH + q][k]).sum()
            });
            // Transposed, (48 × vertices) = foldedᵀ Aᵀ, so that a vertex's 48 values are one column.
            let mut out = Mat::<f32>::zeros(3 * SH, t.vertices as usize);
            let a = MatRef::from_column_major_slice(&t.a, rv, t.vertices as usize);
            matmul(out.as_mut(), Accum::Replace, folded.transpose(), a, 1.0f32, Par::Seq);
            out
        })
    }
}

#[node(category = "ptt", version = 2, caching = Keyed, metrics = ["vertices", "slots", "bounces", "e0_mean", "e1_mean", "e2_mean", "bytes"])]
impl PttIncident {
    fn run(&self, i: PttIncidentIn, cx: &RunCtx) -> Result<PttIncidentOut, NodeError> {
        let n = self.check(&i)?;
        let (p, cols, bounces) = (i.projection, i.projection.columns as usize, i.light.bounces);
        let slots = p.slots();
        // Beside the output, per vertex: its one-bounce SH (16 RGB), its cluster row, and its
        // two-bounce light twice (per chunk, then joined).
        let bytes = VertexIncident::bytes_for(n as u64, slots as u64, cols as u64) + n as u64 * (SH as u64 * 12 + 8 + 2 * 12);
        if bytes > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "the incident light of {n} vertices would hold {}, over the {} budget",
                fmt_bytes(bytes),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let w = slot_weights(i.light, i.materials)?;
        let sh1 = if bounces >= 1 { Self::one_bounce(&i, &w, cx)? } else { vec![] };
        // Each vertex's cluster and row there.
        let mut row_of = vec![(0u32, 0u32); if bounces >= 1 { n } else { 0 }];
        for (c, members) in i.bounce.plan.members.iter().enumerate().filter(|_| bounces >= 1) {
            for (k, &v) in members.iter().enumerate() {
                row_of[v as usize] = (c as u32, k as u32);
            }
        }
        // Two bounces: the weights of each reflector pair.
        let ww: Vec<Vec3> = w.iter().flat_map(|a| w.iter().map(move |b| *a * *b)).collect();
        let zonal: [f32; SH] = std::array::from_fn(|q| clamped_cosine_zonal((q as f64).sqrt() as usize));
        // Vertex v's one-bounce SH (16 RGB) and two-bounce light.
        let sh_of = |v: usize| -> [Vec3; SH] {
            if bounces == 0 || p.normals[v] == Vec3::ZERO {
                return [Vec3::ZERO; SH];
            }
            let m = sh1[row_of[v].0 as usize].col(row_of[v].1 as usize).try_as_col_major().expect("a column of a column-major matrix");
            let x = m.as_slice();
            std::array::from_fn(|q| Vec3::new(x[3 * q], x[3 * q + 1], x[3 * q + 2]))
        };
        let two_of = |v: usize| -> Vec3 {
            if bounces < 2 {
                return Vec3::ZERO;
            }
            i.light.pairs_of(v).iter().zip(&ww).map(|(t, w)| *w * *t).sum()
        };
        cx.check()?;
        // The diffuse irradiance of every vertex, with the sums of each bounce's luminance,
        // and its two-bounce light (the tensor pass reads it again: kept rather than summed
        // twice from the pairs, the largest array an edit reads).
        let chunks: Vec<(Vec<Vec3>, Vec<Vec3>, [f64; 3])> = cx.par_map(n.div_ceil(CHUNK), |k| {
            let range = k * CHUNK..((k + 1) * CHUNK).min(n);
            let (mut irr, mut sums) = (Vec::with_capacity(range.len()), [0.0f64; 3]);
            let mut two = Vec::with_capacity(if bounces == 2 { range.len() } else { 0 });
            let mut y = [0.0f32; SH];
            for v in range {
                let e0 = i.direct.irradiance[v];
                let mut e1 = Vec3::ZERO;
                if bounces >= 1 && p.normals[v] != Vec3::ZERO {
                    sh_basis_into(p.normals[v], &mut y);
                    e1 = sh_of(v).iter().zip(y.iter().zip(&zonal)).map(|(c, (y, a))| *c * (y * a)).sum();
                }
                let i2 = two_of(v);
                if bounces == 2 {
                    two.push(i2);
                }
                let e2 = PI * i2;
                irr.push(e0 + e1 + e2);
                for (m, e) in sums.iter_mut().zip([e0, e1, e2]) {
                    *m += lum(e);
                }
            }
            (irr, two, sums)
        })?;
        let mut out = VertexIncident {
            columns: cols as u32,
            bounces,
            irradiance: Vec::with_capacity(n),
            // Zeroed by the allocator (fresh pages, not written here): the slot pass below
            // writes every value, on every thread, so the pages are first touched there.
            tensor: bytemuck::zeroed_vec(slots * cols),
            bounce: bytemuck::zeroed_vec(slots * SH),
        };
        let mut means = [0.0f64; 3];
        let mut two = Vec::with_capacity(if bounces == 2 { n } else { 0 });
        for (irr, t, sums) in chunks {
            out.irradiance.extend(irr);
            two.extend(t);
            means.iter_mut().zip(sums).for_each(|(m, s)| *m += s);
        }
        // The tensor-shaded vertices' columns and SH, written in place slot by slot.
        let mut vertex_of = vec![0u32; slots];
        for (v, &t) in p.slot.iter().enumerate().filter(|(_, &t)| t != NO_SLOT) {
            vertex_of[t as usize] = v as u32;
        }
        out.tensor.par_chunks_mut(cols * CHUNK).zip(out.bounce.par_chunks_mut(SH * CHUNK)).enumerate().for_each(|(k, (tensor, bounce))| {
            // Per chunk: the slot's projection transposed (SH rows of `cols`), and the sums
            // per colour, so that the product runs along the columns, eight at a time.
            let (mut pt, mut acc) = (vec![0.0f32; SH * cols], [vec![0.0f32; cols], vec![0.0f32; cols], vec![0.0f32; cols]]);
            for ((j, tc), bc) in (k * CHUNK..).zip(tensor.chunks_exact_mut(cols)).zip(bounce.chunks_exact_mut(SH)) {
                let v = vertex_of[j] as usize;
                let c = sh_of(v);
                let mut total = c;
                total[0] += two.get(v).copied().unwrap_or(Vec3::ZERO) / Y00;
                let (pv, cols0) = (p.of(j), &i.direct.tensor[j * cols..(j + 1) * cols]);
                for (kk, row) in pv.chunks_exact(SH).enumerate() {
                    for (q, &x) in row.iter().enumerate() {
                        pt[q * cols + kk] = x;
                    }
                }
                // Column kk: Σ_q total[q] · P[kk][q], summed in q order from zero.
                acc.iter_mut().for_each(|a| a.fill(0.0));
                for (t, prow) in total.iter().zip(pt.chunks_exact(cols)) {
                    for (ch, a) in acc.iter_mut().enumerate() {
                        let tc = t[ch];
                        a.iter_mut().zip(prow).for_each(|(a, x)| *a += tc * *x);
                    }
                }
                for (kk, o) in tc.iter_mut().enumerate() {
                    *o = cols0[kk] + Vec3::new(acc[0][kk], acc[1][kk], acc[2][kk]);
                }
                bc.copy_from_slice(&c);
            }
        });
        cx.check()?;
        cx.metric("vertices", n as f64);
        cx.metric("slots", slots as f64);
        cx.metric("bounces", bounces as f64);
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
    use crate::test_support::{plane, Chain};
    use crate::types::EnvLight;
    use crate::vertex_visibility::tests::floor_and_tiled_roof;
    use relume_base::testing::run_on;
    use relume_base::types::{Environment, Material};
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
            .install(|| relume_base::testing::first(&run_on::<PttIncident>(&[], inputs.clone()).expect("runs")));
        assert_eq!(one, c.incident(&c.env, &m, 2));
        assert_eq!(VertexIncident::decode(&one.encode()), Some(one));
    }

    #[test]
    fn inputs_from_other_scenes_are_refused() {
        let c = Chain::new(plane(lambert(), false, Environment::Constant(Vec3::ONE)));
        let m = c.materials();
        let other = Chain::new(floor_and_tiled_roof(0.5));
        let mut inputs = c.incident_inputs(&c.env, &m);
        inputs[0] = Value::new(other.direct_light(&other.env));
        let e = run_on::<PttIncident>(&[], inputs).expect_err("other scene");
        assert!(e.to_string().contains("same scene"), "{e}");
        let mut inputs = c.incident_inputs(&c.env, &m);
        inputs[2] = Value::new(other.bounce_light(&other.env, 1));
        let e = run_on::<PttIncident>(&[], inputs).expect_err("other transfer");
        assert!(e.to_string().contains("same TransferT1"), "{e}");
    }
}
