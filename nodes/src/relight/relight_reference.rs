//! RelightReference node.

use super::paths::{Paths, Slots};
use super::shades::{check_scene, MaterialBrdf, MaterialShade};
use crate::render::film::{per_pixel, with_ctx};
use crate::types::accel::Accel;
use crate::types::{gather_rows, row_spec, BrdfBasis, Image, ImageRows, ObjectMaterials, PathCounts, Scene, Transfer};
use relume_core::{inputs, node, outputs, NodeError, ParamEnum, Params, RunCtx, ShardSpec};
use std::ops::Range;

/// The same-seed render of pixel relighting: exactly the paths `TransferPrecompute` traced for
/// `transfer` (its sample counts and seed), weighted with one material per object instead of
/// every basis. With `Analytic` BRDFs its difference to `Relight` is the basis error alone, no
/// Monte Carlo noise — the figure [S] 4.1.5 reports (figures 4-3, 4-4). With `Tabulated` BRDFs
/// (each dynamic material as Σ c_k ρ̃_k on the basis) it equals `Relight` to float precision:
/// the test that the stored images and the combine are right. Sharded over image rows.
#[derive(Params)]
pub struct RelightReference {
    /// the dynamic objects' BRDFs: the analytic Blinn-Phong, or its projection on the basis
    #[param(default = Analytic)]
    pub brdf: ReferenceBrdf,
}

/// How `RelightReference` evaluates the dynamic materials.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum ReferenceBrdf {
    /// the analytic Blinn-Phong of (Kd, Ks, s)
    Analytic,
    /// Σ c_k ρ̃_k, the material as the basis represents it
    Tabulated,
}

inputs!(pub RelightReferenceIn { scene: Scene, accel: Accel, transfer: Transfer, basis: BrdfBasis, materials: ObjectMaterials });
outputs!(pub RelightReferenceOut { image: Image });

/// Rows `rows` of the same-seed render with path counts `counts`.
#[allow(clippy::too_many_arguments)]
pub fn reference_rows(
    scene: &Scene,
    accel: &Accel,
    counts: PathCounts,
    basis: &BrdfBasis,
    materials: &ObjectMaterials,
    brdf: ReferenceBrdf,
    rows: Range<usize>,
    cx: Option<&RunCtx>,
) -> Result<ImageRows, NodeError> {
    check_scene(scene, basis.bases()).map_err(|m| NodeError::input("scene", m))?;
    let groups = scene.dynamic_groups();
    if materials.0.len() != groups.len() || materials.0.iter().zip(&groups).any(|(m, g)| m.name != g.0) {
        return Err(NodeError::input("materials", "the materials are not those of the scene's dynamic objects"));
    }
    if brdf == ReferenceBrdf::Tabulated && materials.0.iter().any(|m| m.coefficients.len() != basis.bases()) {
        return Err(NodeError::input("materials", "tabulated BRDFs need the materials projected on this basis (MaterialProject)"));
    }
    let mb = match brdf {
        ReferenceBrdf::Analytic => MaterialBrdf::Analytic,
        ReferenceBrdf::Tabulated => MaterialBrdf::Tabulated(basis),
    };
    let shade = MaterialShade::new(scene, materials, mb);
    let slots = Slots::single();
    let paths = Paths::new(scene, accel, counts, &shade, &slots);
    let (w, y0) = (scene.camera.width, rows.start);
    let (img, rays) = with_ctx(cx, |cx| {
        per_pixel(cx, w, rows.len(), |x, y, c| {
            let mut acc = [[0.0f64; 3]];
            c.rays += paths.pixel(x, y0 + y, &mut acc).rays;
            acc[0].map(|v| v as f32)
        })
    })?;
    Ok(ImageRows::new(w, rows, vec![img], vec![rays]))
}

#[node(category = "relight", sharded)]
impl RelightReference {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let image = inputs[0].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        relume_core::MemoryEstimate { outputs: vec![image], working: image.map_or(0, |s| s.bytes) }
    }

    fn shard(&self, i: &RelightReferenceIn) -> Result<ShardSpec, NodeError> {
        let (w, h) = (i.scene.camera.width, i.scene.camera.height);
        if (w as u32, h as u32) != (i.transfer.width, i.transfer.height) {
            return Err(NodeError::input(
                "transfer",
                format!("the transfer is {} × {}, the scene's camera {w} × {h}", i.transfer.width, i.transfer.height),
            ));
        }
        Ok(row_spec(w, h))
    }

    fn run_items(&self, i: &RelightReferenceIn, rows: Range<u64>, cx: &RunCtx) -> Result<ImageRows, NodeError> {
        reference_rows(
            i.scene,
            i.accel,
            i.transfer.counts,
            i.basis,
            i.materials,
            self.brdf,
            rows.start as usize..rows.end as usize,
            Some(cx),
        )
    }

    fn gather(&self, i: &RelightReferenceIn, parts: &[&ImageRows], cx: &RunCtx) -> Result<RelightReferenceOut, NodeError> {
        let (mut imgs, c) = gather_rows(i.scene.camera.width, i.scene.camera.height, 1, parts)?;
        cx.metric("rays", c[0] as f64);
        Ok(RelightReferenceOut { image: imgs.pop().expect("one layer") })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::path_trace::{render, PathTrace};
    use crate::relight::test_support::{basis, precompute, scene, space};
    use crate::testing::{cancels_midway, first, id, run_on};
    use relume_core::Value;

    #[test]
    fn the_same_seed_render_is_the_same_for_any_split_and_checks_its_inputs() {
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 3);
        let s = scene(10);
        let (accel, m, t, _) = precompute(&s, &b, [2, 1, 2, 1]);
        let a = accel.get::<Accel>().unwrap();
        let whole = reference_rows(&s, a, t.counts, &b, &m, ReferenceBrdf::Analytic, 0..10, None).unwrap();
        let parts = [0..3, 3..10].map(|r| reference_rows(&s, a, t.counts, &b, &m, ReferenceBrdf::Analytic, r, None).unwrap());
        assert_eq!(gather_rows(10, 10, 1, &[&whole]).unwrap(), gather_rows(10, 10, 1, &[&parts[0], &parts[1]]).unwrap());
        // The node over the graph's inputs gives the same image.
        let inputs = vec![Value::new(s.clone()), accel.clone(), Value::new(t.clone()), Value::new(b.clone()), Value::new(m.clone())];
        let img: Image = first(&run_on::<RelightReference>(&[("brdf", id("Analytic"))], inputs).unwrap());
        assert_eq!(img, gather_rows(10, 10, 1, &[&whole]).unwrap().0[0]);
        // Materials of another scene are refused.
        let mut other = m.clone();
        other.0.pop();
        assert!(reference_rows(&s, a, t.counts, &b, &other, ReferenceBrdf::Analytic, 0..10, None).is_err());
        // Unprojected materials cannot be tabulated.
        let mut raw = m.clone();
        raw.0.iter_mut().for_each(|o| o.coefficients.clear());
        assert!(reference_rows(&s, a, t.counts, &b, &raw, ReferenceBrdf::Tabulated, 0..10, None).is_err());
    }

    #[test]
    fn it_estimates_what_the_path_tracer_does_at_max_depth_three() {
        // Direct + one bounce with the original BRDFs: the same expectation as PathTrace with
        // max_depth 3 (other sampling, other noise). Over the whole image the means agree
        // within a few percent at these sample counts (edge pixels aside, which the
        // relighting paths give one object each).
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 3);
        let s = scene(16);
        let (accel, m, t, _) = precompute(&s, &b, [16, 4, 16, 2]);
        let a = accel.get::<Accel>().unwrap();
        let rows = reference_rows(&s, a, t.counts, &b, &m, ReferenceBrdf::Analytic, 0..16, None).unwrap();
        let ours = gather_rows(16, 16, 1, &[&rows]).unwrap().0.pop().unwrap();
        let (pt, _, _, _) = render(&s, a, &PathTrace { spp: 1024, max_depth: 3, rr_depth: 5, seed: 4 }, None).unwrap();
        let mean = |img: &Image| img.as_floats().iter().map(|v| *v as f64).sum::<f64>() / img.as_floats().len() as f64;
        let (x, y) = (mean(&ours), mean(&pt));
        assert!((x - y).abs() < 0.03 * y, "relighting paths {x} vs path tracer {y}");
    }

    #[test]
    fn the_node_stops_midway_when_cancelled() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let s = scene(16);
        let (accel, m, t, _) = precompute(&s, &b, [1, 1, 1, 1]);
        let mut t = t;
        t.counts.bounce_rays = 16;
        t.counts.spp = 4;
        cancels_midway::<RelightReference>(&[], vec![Value::new(s), accel, Value::new(t), Value::new(b), Value::new(m)]);
    }
}
