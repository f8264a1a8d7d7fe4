//! PttBounceLight node and its port type.

use super::bounce::SH;
use super::types::BounceTransfer;
use super::types::EnvLight;
use super::types::PackedTwoBounce;
use crate::types::{BounceLight, LitCore};
use glam::Vec3;
use relume_base::math::cubemap::CubeView;
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, NodeError, PortValue, RunCtx};

/// The environment at side `m` as box-basis weights per colour (`CubeMap::box_downsample`).
fn box_light(env: &EnvLight, m: usize) -> Result<Vec<Vec3>, NodeError> {
    if m == 0 || !(env.n as usize).is_multiple_of(m) {
        return Err(NodeError::input("env", format!("a cube map of side {} cannot be box-filtered to the transfer's side {m}", env.n)));
    }
    Ok(CubeView { n: env.n as usize, texels: &env.map }.box_downsample(m).texels)
}

/// The reflector slot of each transfer channel and the weight it enters that slot with: the
/// fixed channels into slot 0 with their colour (one grey channel: all colours; three: one
/// each), the dynamic ones into a slot of their own, weight one.
fn slot_of_channels(t: &BounceTransfer) -> Vec<(usize, Vec3)> {
    let fixed: Vec<(usize, Vec3)> = match t.fixed {
        0 => vec![],
        1 => vec![(0, Vec3::ONE)],
        _ => vec![(0, Vec3::X), (0, Vec3::Y), (0, Vec3::Z)],
    };
    fixed.into_iter().chain((0..t.channels() - t.fixed as usize).map(|j| (1 + j, Vec3::ONE))).collect()
}

/// Vertices per task of the two-bounce contraction.
const CHUNK: usize = 1024;

/// Per cluster of `two`, its mean and then each direction contracted with `light` (per colour,
/// Σ_l light_l T²(l, c₁, c₂)) and folded into slot pairs by `pair`: (1 + m) × slots² values.
fn lit_clusters(
    two: &PackedTwoBounce,
    light: &[Vec3],
    pair: &[(usize, Vec3)],
    slots: usize,
    cx: &RunCtx,
) -> Result<Vec<Vec<Vec3>>, NodeError> {
    let (m, cc) = (two.m as usize, (two.channels as usize).pow(2));
    cx.par_map(two.clusters(), |c| {
        let mut out = vec![Vec3::ZERO; (1 + m) * slots * slots];
        // Per colour, contiguous rows, so that it vectorises.
        let mut acc = [vec![0.0f32; cc], vec![0.0f32; cc], vec![0.0f32; cc]];
        for (j, dst) in out.chunks_mut(slots * slots).enumerate() {
            let row = if j == 0 { two.mean(c) } else { two.direction(c, j - 1) };
            acc.iter_mut().for_each(|a| a.fill(0.0));
            for (r, li) in row.chunks_exact(cc).zip(light) {
                for (a, lc) in acc.iter_mut().zip(li.to_array()) {
                    a.iter_mut().zip(r).for_each(|(a, x)| *a += lc * x);
                }
            }
            for (k, &(d, w)) in pair.iter().enumerate() {
                dst[d] += w * Vec3::new(acc[0][k], acc[1][k], acc[2][k]);
            }
        }
        out
    })
}

params! {
    /// The bounced light under the current environment ([S] 5-5, 5-6; the lighting half of the
    /// bounces, which a material edit does not re-run): the environment box-averaged to
    /// `TransferT1`'s lighting bases (`CubeMap::box_downsample`) contracted with each cluster's
    /// compressed transfer (its lighting factor, then its core), and, with `bounces` = 2, box-averaged to
    /// `TransferT2`'s bases and contracted with the two-bounce transfer as `CompressT2` packed it
    /// (each cluster's mean and directions once, then per vertex its coefficients). The fixed
    /// objects' channels are folded into one reflector slot on the way (their reflectance is
    /// known); the dynamic objects' channels stay apart for `PttIncident` to weigh by the
    /// materials' basis coefficients. With `bounces` 0 it holds nothing, with 1 no pairs: what
    /// is not asked for is not computed.
    ///
    /// Metrics: bounces, clusters, reflector slots, bytes.
    pub struct PttBounceLight {
        /// reflections carried: 0 direct only, 1 one bounce, 2 two bounces ([S] 5-5)
        pub bounces: usize = 2, range = 0..=2;
    }
}

#[node(category = "ptt", caching = Keyed, metrics = ["bounces", "clusters", "slots", "bytes"], outputs = [light])]
impl PttBounceLight {
    fn run(&self, env: &EnvLight, bounce: &BounceTransfer, two: &PackedTwoBounce, cx: &RunCtx) -> Result<BounceLight, NodeError> {
        let t = bounce;
        let n = t.plan.vertices();
        let ch = t.channels();
        if two.channels as usize != ch {
            return Err(NodeError::input(
                "two",
                format!("has {} channels, the one-bounce transfer {ch}: they must come from the same scene and basis", two.channels),
            ));
        }
        if self.bounces == 2 && two.vertices() != n {
            return Err(NodeError::input(
                "two",
                format!("holds {} vertices, the one-bounce transfer {n}: they must come from the same scene", two.vertices()),
            ));
        }
        let slot = slot_of_channels(t);
        let slots = 1 + ch - t.fixed as usize;
        let rows: u64 = t.clusters.iter().map(|c| c.rank_v as u64).sum();
        let bytes = BounceLight::bytes_for(n as u64, rows, slots as u64, self.bounces as u32);
        if bytes > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "the bounced light of {n} vertices would hold {}, over the {} budget",
                fmt_bytes(bytes),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let mut out = BounceLight {
            bounces: self.bounces as u32,
            groups: t.groups.clone(),
            bases: t.bases,
            textured: t.textured.clone(),
            cores: vec![],
            pairs: vec![],
        };
        if self.bounces >= 1 {
            let light = box_light(env, t.coarse as usize)?;
            out.cores = cx.par_map(t.clusters.len(), |c| {
                let k = &t.clusters[c];
                let (l, s, rv, rl) = (k.lights as usize, k.columns as usize, k.rank_v as usize, k.rank_l as usize);
                // The lighting factor against the light: one RGB weight per lighting rank.
                let w: Vec<Vec3> = (0..rl).map(|b| k.b[b * l..(b + 1) * l].iter().zip(&light).map(|(x, y)| *y * *x).sum()).collect();
                let mut core = vec![Vec3::ZERO; rv * slots * SH];
                let mut lit = vec![Vec3::ZERO; s];
                for a in 0..rv {
                    lit.fill(Vec3::ZERO);
                    for (b, wb) in w.iter().enumerate() {
                        let g = &k.core[(a * rl + b) * s..(a * rl + b + 1) * s];
                        lit.iter_mut().zip(g).for_each(|(o, x)| *o += *wb * *x);
                    }
                    for (c, &(r, wc)) in slot.iter().enumerate() {
                        let dst = &mut core[(a * slots + r) * SH..(a * slots + r + 1) * SH];
                        dst.iter_mut().zip(&lit[c * SH..(c + 1) * SH]).for_each(|(o, x)| *o += wc * *x);
                    }
                }
                LitCore { rank_v: rv as u32, core }
            })?;
        }
        if self.bounces == 2 {
            let light = box_light(env, two.side as usize)?;
            // Each channel pair's slot pair and colour weight.
            let pair: Vec<(usize, Vec3)> =
                slot.iter().flat_map(|&(r1, w1)| slot.iter().map(move |&(r2, w2)| (r1 * slots + r2, w1 * w2))).collect();
            let lit = lit_clusters(two, &light, &pair, slots, cx)?;
            let ss = slots * slots;
            out.pairs = vec![Vec3::ZERO; n * ss];
            cx.par_chunks_mut(&mut out.pairs, CHUNK * ss, |k, pairs| {
                for (v, dst) in (k * CHUNK..).zip(pairs.chunks_mut(ss)) {
                    let l = &lit[two.cluster[v] as usize];
                    dst.copy_from_slice(&l[..ss]);
                    for (j, &w) in two.coefficients_of(v).iter().enumerate() {
                        dst.iter_mut().zip(&l[(1 + j) * ss..(2 + j) * ss]).for_each(|(o, x)| *o += w * *x);
                    }
                }
            })?;
        }
        cx.metric("bounces", self.bounces as f64);
        cx.metric("clusters", out.cores.len() as f64);
        cx.metric("slots", slots as f64);
        cx.metric("bytes", out.byte_size() as f64);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{plane, Chain};
    use crate::vertex_visibility::tests::floor_and_tiled_roof;
    use relume_base::testing::{first, i, run_on};
    use relume_base::types::{Environment, Material};
    use relume_core::Value;

    fn light(c: &Chain, bounces: i64) -> BounceLight {
        first(&run_on::<PttBounceLight>(&[("bounces", i(bounces))], c.bounce_light_inputs(&c.env)).expect("runs"))
    }

    #[test]
    fn holds_only_what_the_bounce_count_asks_for() {
        let c = Chain::new(floor_and_tiled_roof(0.5));
        let (l0, l1, l2) = (light(&c, 0), light(&c, 1), light(&c, 2));
        assert!(l0.cores.is_empty() && l0.pairs.is_empty());
        assert!(!l1.cores.is_empty() && l1.pairs.is_empty());
        assert_eq!(l1.cores, l2.cores);
        assert_eq!(l2.pairs.len(), c.scene.positions.len() * l2.slots() * l2.slots());
        assert!(l2.pairs.iter().any(|p| p.x > 0.0), "the roofed floor gets two-bounce light");
        assert_eq!(BounceLight::decode(&l2.encode()), Some(l2.clone()));
        // Linear in the environment: twice the sky, twice the light.
        let bright = EnvLight { map: c.env.map.iter().map(|t| *t * 2.0).collect(), ..c.env.clone() };
        let lb: BounceLight = first(&run_on::<PttBounceLight>(&[], c.bounce_light_inputs(&bright)).expect("runs"));
        for (a, b) in lb.pairs.iter().zip(&l2.pairs) {
            assert!((*a - *b * 2.0).abs().max_element() <= 1e-5 * b.abs().max_element().max(1e-3), "{a} {b}");
        }
    }

    #[test]
    fn a_zero_sky_gives_no_light_and_a_sun_ten_thousand_times_the_sky_stays_finite_and_linear() {
        // docs/QUALITY.md "lighting": a zero environment, and one texel 10⁴ times the rest.
        let c = Chain::new(floor_and_tiled_roof(0.5));
        let zero = EnvLight { map: vec![Vec3::ZERO; c.env.map.len()], ..c.env.clone() };
        let l: BounceLight = first(&run_on::<PttBounceLight>(&[], c.bounce_light_inputs(&zero)).expect("runs"));
        assert!(l.cores.iter().all(|k| k.core.iter().all(|v| *v == Vec3::ZERO)) && l.pairs.iter().all(|v| *v == Vec3::ZERO));
        let sun_only = |scale: f32| {
            let mut map = vec![Vec3::ZERO; c.env.map.len()];
            map[c.env.map.len() / 3 + 7] = Vec3::splat(1.0e4 * scale);
            EnvLight { map, ..c.env.clone() }
        };
        let sky = EnvLight { map: c.env.map.iter().zip(&sun_only(1.0).map).map(|(a, b)| *a + *b).collect(), ..c.env.clone() };
        let (with_sun, sun): (BounceLight, BounceLight) = (
            first(&run_on::<PttBounceLight>(&[], c.bounce_light_inputs(&sky)).expect("runs")),
            first(&run_on::<PttBounceLight>(&[], c.bounce_light_inputs(&sun_only(1.0))).expect("runs")),
        );
        let base = light(&c, 2);
        assert!(sun.pairs.iter().any(|v| v.max_element() > 0.0), "the sun reaches the two-bounce light");
        assert!(with_sun.pairs.iter().chain(with_sun.cores.iter().flat_map(|k| &k.core)).all(|v| v.is_finite()));
        // The sky plus the sun is the light of each, within f32 rounding at the sun's scale.
        for ((w, s), b) in with_sun.pairs.iter().zip(&sun.pairs).zip(&base.pairs) {
            let tol = 1e-5 * (s.abs().max_element() + b.abs().max_element()).max(1e-6);
            assert!((*w - (*s + *b)).abs().max_element() <= tol, "{w} vs {s} + {b}");
        }
    }

    #[test]
    fn the_bytes_do_not_depend_on_threads() {
        let c = Chain::new(floor_and_tiled_roof(0.5));
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool").install(|| light(&c, 2));
        assert_eq!(one, light(&c, 2));
    }

    #[test]
    fn a_grey_fixed_scene_has_one_slot_and_other_sides_or_scenes_are_refused() {
        let c = Chain::new(plane(Material::Lambert { albedo: Vec3::splat(0.6) }, false, Environment::Constant(Vec3::ONE)));
        let l = light(&c, 2);
        assert_eq!((l.slots(), l.groups.len()), (1, 0));
        let mut inputs = c.bounce_light_inputs(&c.env);
        inputs[0] = Value::new(EnvLight { n: 3, map: vec![Vec3::ONE; 54], haar: vec![Vec3::ZERO; 54], ..c.env.clone() });
        let e = run_on::<PttBounceLight>(&[], inputs).expect_err("other side");
        assert!(e.to_string().contains("side"), "{e}");
        let other = Chain::new(floor_and_tiled_roof(0.5));
        let mut inputs = c.bounce_light_inputs(&c.env);
        inputs[2] = other.get("two");
        let e = run_on::<PttBounceLight>(&[], inputs).expect_err("other scene");
        assert!(e.to_string().contains("same scene"), "{e}");
    }
}
