//! PttDirect node and its port type.

use super::types::EnvLight;
use super::types::{ShColumns, NO_SLOT};
use crate::types::{DirectLight, DirectTransfer};
use glam::Vec3;
use relume_core::memory::fmt_bytes;
use relume_core::{node, NodeError, Params, PortValue, RunCtx};

/// The direct light at every vertex under the current environment ([S] 5-7; the part of the
/// incident light that the dynamic objects' materials do not reach): per vertex, the
/// environment's Haar coefficients (`EnvLighting`) against `TransferT0`'s kept terms, its
/// diffuse column giving E⁰ and, for the vertices shaded with the tensor, its tensor columns
/// U^{I0}. Its own node so that a material edit, which changes only the bounces
/// (`PttIncident`), does not recompute it; a lighting edit does.
///
/// Metrics: vertices, slots, the mean luminance of E⁰ over the vertices, bytes.
#[derive(Params)]
pub struct PttDirect {}

#[node(category = "ptt", caching = Keyed, metrics = ["vertices", "slots", "e0_mean", "bytes"], outputs = [light])]
impl PttDirect {
    fn run(&self, env: &EnvLight, direct: &DirectTransfer, projection: &ShColumns, cx: &RunCtx) -> Result<DirectLight, NodeError> {
        let (d, p) = (direct, projection);
        let n = p.normals.len();
        if d.vertices() != n {
            return Err(NodeError::input(
                "direct",
                format!("the direct transfer holds {} vertices and the projection {n}: they must come from the same scene", d.vertices()),
            ));
        }
        if d.columns != p.columns + 1 {
            return Err(NodeError::input(
                "projection",
                format!(
                    "projects {} columns but the direct transfer has {} tensor columns: they must come from the same BRDF tensor",
                    p.columns,
                    d.columns - 1
                ),
            ));
        }
        if d.n != env.n {
            return Err(NodeError::input("env", format!("the environment's side is {} but the direct transfer's {}", env.n, d.n)));
        }
        let (cols, slots) = (p.columns as usize, p.slots());
        let bytes = DirectLight::bytes_for(n as u64, slots as u64, cols as u64);
        if bytes > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "the direct light of {n} vertices would hold {}, over the {} budget",
                fmt_bytes(bytes),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let mut out = DirectLight { columns: cols as u32, irradiance: vec![Vec3::ZERO; n], tensor: vec![Vec3::ZERO; slots * cols] };
        // In chunks of vertices: each writes its own irradiance and its slots' columns.
        const CHUNK: usize = 1024;
        let per = cx.par_map(n.div_ceil(CHUNK), |c| {
            let mut col = vec![Vec3::ZERO; cols + 1];
            let mut rows = Vec::with_capacity(CHUNK);
            for v in c * CHUNK..((c + 1) * CHUNK).min(n) {
                d.apply_into(v, &env.haar, &mut col);
                rows.push(col.clone());
            }
            rows
        })?;
        let mut sum = 0.0f64;
        for (v, col) in per.into_iter().flatten().enumerate() {
            out.irradiance[v] = col[cols];
            sum += col[cols].dot(Vec3::new(0.2126, 0.7152, 0.0722)) as f64;
            if p.slot[v] != NO_SLOT {
                let t = p.slot[v] as usize;
                out.tensor[t * cols..(t + 1) * cols].copy_from_slice(&col[..cols]);
            }
        }
        cx.metric("vertices", n as f64);
        cx.metric("slots", slots as f64);
        cx.metric("e0_mean", sum / n.max(1) as f64);
        cx.metric("bytes", out.byte_size() as f64);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{plane, Chain};
    use relume_base::testing::{first, run_on};
    use relume_base::types::{Environment, Material};
    use relume_core::Value;
    use std::f32::consts::PI;

    fn direct(c: &Chain, env: &EnvLight) -> Result<DirectLight, NodeError> {
        run_on::<PttDirect>(&[], vec![Value::new(env.clone()), c.get("direct"), c.get("projection")]).map(|v| first(&v))
    }

    #[test]
    fn an_open_plane_under_a_constant_sky_gets_pi_and_the_bytes_do_not_depend_on_threads() {
        let c = Chain::new(plane(Material::Lambert { albedo: Vec3::splat(0.6) }, false, Environment::Constant(Vec3::ONE)));
        let d = direct(&c, &c.env).unwrap();
        assert_eq!((d.irradiance.len(), d.tensor.len()), (81, 0), "fixed objects get no tensor slot");
        assert!(d.irradiance.iter().all(|e| (*e - Vec3::splat(PI)).abs().max_element() < 0.01 * PI), "{:?}", d.irradiance[0]);
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| direct(&c, &c.env).unwrap());
        assert_eq!(one.encode(), d.encode());
        assert_eq!(DirectLight::decode(&d.encode()), Some(d));
    }

    #[test]
    fn a_glossy_plane_gets_its_columns_and_other_sides_or_scenes_are_refused() {
        let c = Chain::new(plane(crate::test_support::GLOSSY, true, Environment::Constant(Vec3::ONE)));
        let d = direct(&c, &c.env).unwrap();
        assert_eq!(d.tensor.len(), 81 * d.columns as usize, "every vertex of the dynamic plane has a slot");
        assert!(d.tensor.iter().any(|v| v.x > 0.0));
        let small = EnvLight { n: 8, map: vec![Vec3::ONE; 384], haar: vec![Vec3::ZERO; 384], ..c.env.clone() };
        assert!(direct(&c, &small).unwrap_err().to_string().contains("side"));
        let other = Chain::new(crate::vertex_visibility::tests::floor_and_tiled_roof(0.5));
        let e = run_on::<PttDirect>(&[], vec![Value::new(c.env.clone()), other.get("direct"), c.get("projection")]).unwrap_err();
        assert!(e.to_string().contains("same scene"), "{e}");
    }
}
