use super::bounce::SH;
use super::types::brdf::TuckerBrdf;
use super::types::Visibility;
use super::vertices::vertex_frame;
use crate::types::{ShColumns, NO_OWNER, NO_SLOT};
use glam::{Mat3, Vec3};
use relume_base::math::cubemap::CubeMap;
use relume_base::math::sh::sh_basis_into;
use relume_base::math::sh_rotation::ShRotation;
use relume_base::types::Scene;
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, NodeError, RunCtx};

/// Per scene vertex, the object it belongs to (the first triangle that uses it), if any.
pub fn vertex_objects(scene: &Scene) -> Vec<Option<u32>> {
    let mut out = vec![None; scene.positions.len()];
    for (t, tri) in scene.triangles.iter().enumerate() {
        for &v in tri {
            out[v as usize].get_or_insert(scene.tri_object[t]);
        }
    }
    out
}

/// P_k(s) in the local frame (normal +z), columns × 16, by quadrature over the texels of a
/// cube map of side `side` above the tangent plane (f64 sums in texel order).
pub fn local_projection(brdf: &TuckerBrdf, side: usize) -> Vec<f64> {
    let cols = brdf.ranks[2] as usize;
    let cube = CubeMap::constant(side, Vec3::ZERO);
    let mut p = vec![0.0f64; cols * SH];
    let mut y = [0.0f32; SH];
    for k in 0..cube.texels.len() {
        let d = cube.direction(k);
        if d.z <= 0.0 {
            continue;
        }
        sh_basis_into(d, &mut y);
        let w = d.z as f64 * cube.solid_angle(k) as f64;
        for (c, u) in brdf.u_i(d).iter().enumerate() {
            for (s, ys) in y.iter().enumerate() {
                p[c * SH + s] += w * *u as f64 * *ys as f64;
            }
        }
    }
    p
}

params! {
    /// The projection of the BRDF tensor's incoming factor for the one- and two-bounce light
    /// ([S] 5-5: U^I = U^{I0} + U^{I1} + U^{I2}, the bounces' incident light arriving in 4-band
    /// SH in world axes): per vertex of a dynamic object, each column k of U^ωi times the
    /// cosine, in the vertex frame (`vertex_frame`), projected on SH in the local frame once by
    /// quadrature over a cube map of side `quadrature_side` (bilinear U^ωi over the disk), then
    /// turned into world axes per vertex (`math::sh_rotation`, exact per band). Dotted with the
    /// bounce's SH coefficients it gives ∫ I U^ωi (ω · n)⁺ dω exactly for the 4-band incident
    /// light. Fixed objects (diffuse, shaded by their irradiance alone) get no slot: what the
    /// scene does not need is left out. Runs once per geometry and BRDF tensor; material,
    /// lighting and view edits do not reach it.
    ///
    /// Metrics: slots (vertices shaded with the tensor), columns, bytes.
    pub struct IncidentProjection {
        /// texels along a face of the quadrature cube map (local frame)
        pub quadrature_side: usize = 32, range = 4..=256;
    }
}

#[node(category = "ptt", version = 2, metrics = ["slots", "columns", "bytes"], outputs = [projection])]
impl IncidentProjection {
    fn run(&self, scene: &Scene, visibility: &Visibility, brdf: &TuckerBrdf, cx: &RunCtx) -> Result<ShColumns, NodeError> {
        let vis = visibility;
        let n = scene.positions.len();
        if vis.vertices() != n {
            return Err(NodeError::input(
                "visibility",
                format!("holds {} vertices but the scene has {n}: they must come from the same scene", vis.vertices()),
            ));
        }
        let owner = vertex_objects(scene);
        let dynamic = |v: usize| owner[v].is_some_and(|o| scene.objects[o as usize].dynamic) && vis.normals[v] != Vec3::ZERO;
        let shaded: Vec<usize> = (0..n).filter(|&v| dynamic(v)).collect();
        let cols = brdf.ranks[2] as usize;
        let bytes = ShColumns::bytes_for(n as u64, shaded.len() as u64, cols as u64);
        if bytes > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "the projections of {} vertices × {cols} columns would hold {}, over the {} budget",
                shaded.len(),
                fmt_bytes(bytes),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let local = local_projection(brdf, self.quadrature_side);
        let local: Vec<Vec<f32>> = local.chunks(SH).map(|c| c.iter().map(|&x| x as f32).collect()).collect();
        cx.check()?;
        let per = cx.par_map(shaded.len(), |t| {
            let f = vertex_frame(vis.normals[shaded[t]]);
            let rot = ShRotation::new(4, Mat3::from_cols(f.s, f.t, f.n));
            local.iter().flat_map(|c| rot.apply(c)).collect::<Vec<f32>>()
        })?;
        let mut slot = vec![NO_SLOT; n];
        shaded.iter().enumerate().for_each(|(t, &v)| slot[v] = t as u32);
        let values: Vec<f32> = per.into_iter().flatten().collect();
        cx.metric("slots", shaded.len() as f64);
        cx.metric("columns", cols as f64);
        cx.metric("bytes", bytes as f64);
        let owner = owner.iter().map(|o| o.unwrap_or(NO_OWNER)).collect();
        Ok(ShColumns { columns: cols as u32, slot, owner, normals: vis.normals.clone(), values })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::brdf_factors::test_support::small_brdf;
    use crate::vertex_visibility::tests::{floor_and_roof, visibility};
    use relume_base::math::rng::uniform;
    use relume_base::math::sh::sh_eval;
    use relume_base::testing::{first, i, run_on};
    use relume_core::PortValue;
    use relume_core::Value;

    /// ∫ I U^ωi(F⁻¹ω, k) (ω·n)⁺ dω by a fine quadrature in world axes, I = Σ c_s Y_s.
    fn direct(brdf: &TuckerBrdf, n: Vec3, c: &[f32], k: usize) -> f64 {
        let f = vertex_frame(n);
        let cube = CubeMap::constant(96, Vec3::ZERO);
        (0..cube.texels.len())
            .map(|t| {
                let d = cube.direction(t);
                let l = f.to_local(d);
                if l.z <= 0.0 {
                    return 0.0;
                }
                sh_eval(c, d) as f64 * brdf.u_i(l)[k] as f64 * l.z as f64 * cube.solid_angle(t) as f64
            })
            .sum()
    }

    #[test]
    fn the_projection_integrates_band_limited_light_against_each_column() {
        let brdf = small_brdf().0.clone();
        let s = floor_and_roof(0.5);
        let vis = visibility(&s, 8, 2);
        let mut s2 = s.clone();
        s2.objects.iter_mut().for_each(|o| o.dynamic = true);
        let out = run_on::<IncidentProjection>(
            &[("quadrature_side", i(64))],
            vec![Value::new(s2.clone()), Value::new(vis.clone()), Value::new(brdf.clone())],
        )
        .expect("runs");
        let p: ShColumns = first(&out);
        assert_eq!(p.slots(), s2.positions.len());
        // Each vertex's owner: the object of its first triangle.
        for (v, &o) in p.owner.iter().enumerate() {
            let first_tri = s2.triangles.iter().position(|t| t.contains(&(v as u32))).expect("every vertex is used");
            assert_eq!(o, s2.tri_object[first_tri], "vertex {v}");
        }
        let c: Vec<f32> = (0..SH).map(|k| uniform(7, k as u64, 0) - 0.3).collect();
        for v in [0, 5, s2.positions.len() - 1] {
            let t = p.slot[v] as usize;
            for k in 0..brdf.ranks[2] as usize {
                let got: f64 = p.of(t)[k * SH..(k + 1) * SH].iter().zip(&c).map(|(a, b)| *a as f64 * *b as f64).sum();
                let want = direct(&brdf, vis.normals[v], &c, k);
                assert!((got - want).abs() < 0.02 * want.abs().max(0.05), "vertex {v} column {k}: {got} vs {want}");
            }
        }
        // Fixed objects get no slot.
        let out = run_on::<IncidentProjection>(&[], vec![Value::new(s.clone()), Value::new(vis), Value::new(brdf)]).expect("runs");
        let p: ShColumns = first(&out);
        assert!(p.slot.iter().all(|&t| t == NO_SLOT) && p.values.is_empty());
        assert_eq!(ShColumns::decode(&p.encode()), Some(p));
    }
}
