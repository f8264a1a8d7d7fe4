use super::paths::{Paths, Slots};
use super::shades::{check_scene_textured, MaterialBrdf, MaterialShade};
use crate::types::PathCounts;
use relume_base::render::film::{per_pixel_layers, with_ctx};
use relume_base::types::accel::Accel;
use relume_base::types::{
    gather_rows, row_spec, BrdfBasis, BrdfSample, Image, ImageRows, ObjectMaterial, ObjectMaterials, Scene, Specular,
};
use relume_core::{inputs, node, outputs, params, NodeError, ParamEnum, RunCtx, ShardSpec};
use std::ops::Range;

params! {
    /// The same-seed render of pixel relighting: exactly the paths the precompute traced (`paths`:
    /// the sample counts and seed of `TransferPrecompute` or `SvTransferPrecompute`), weighted with
    /// one material per object instead of every basis. With `Analytic` BRDFs (texture maps read at
    /// every hit) its difference to `Relight` is the basis error alone, no Monte Carlo noise — the
    /// figure [S] 4.1.5 reports (figures 4-3, 4-4); to `SvRelight`, the basis, the sub-region and
    /// the compression errors together. With `Sampled` BRDFs (each dynamic material's own lobe
    /// tabulated on the basis' grid and interpolated as the bases are, uncompressed: [S]'s
    /// reference, "BRDF采用原始数据，而不是被压缩之后的", the raw BRDF data rather than the
    /// compressed) the difference is the truncation of the basis alone, and Analytic against
    /// Sampled is the grid's own error. With `Tabulated` BRDFs
    /// (each dynamic material as Σ c_k ρ̃_k on the basis) it equals `Relight` to float precision:
    /// the test that the stored images and the combine are right. Also the variance of its mean
    /// over the camera samples: `Relight`'s image has the same paths, so this is its variance too
    /// (to the basis error), what a z-test against the path tracer needs. Sharded over image rows.
    pub struct RelightReference {
        /// the dynamic objects' BRDFs: the analytic Blinn-Phong, its table on the basis' grid, or its projection on the basis
        pub brdf: ReferenceBrdf = Analytic;
    }
}

/// How `RelightReference` evaluates the dynamic materials.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum ReferenceBrdf {
    /// the analytic Blinn-Phong of (Kd, Ks, s)
    Analytic,
    /// Σ c_k ρ̃_k, the material as the basis represents it
    Tabulated,
    /// Kd (times its map)/π + Ks · the lobe tabulated on the basis' grid, uncompressed ([S]'s reference)
    Sampled,
}

inputs!(pub RelightReferenceIn { scene: Scene, accel: Accel, paths: PathCounts, basis: BrdfBasis, materials: ObjectMaterials });
outputs!(pub RelightReferenceOut { image: Image, variance: Image });

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
    check_scene_textured(scene, basis.bases()).map_err(|m| NodeError::input("scene", m))?;
    let groups = scene.dynamic_groups();
    if materials.0.len() != groups.len() || materials.0.iter().zip(&groups).any(|(m, g)| m.name != g.0) {
        return Err(NodeError::input("materials", "the materials are not those of the scene's dynamic objects"));
    }
    if brdf != ReferenceBrdf::Analytic && materials.0.iter().any(|m| m.maps.ks.is_some() || m.maps.exponent.is_some()) {
        return Err(NodeError::input(
            "materials",
            "Ks or exponent maps have no tabulated form here (one table per object, a Kd map times its diffuse term): use Analytic",
        ));
    }
    if brdf == ReferenceBrdf::Tabulated && materials.0.iter().any(|m| m.coefficients.len() != basis.bases()) {
        return Err(NodeError::input("materials", "tabulated BRDFs need the materials projected on this basis (MaterialProject)"));
    }
    let mb = match brdf {
        ReferenceBrdf::Analytic => MaterialBrdf::Analytic,
        ReferenceBrdf::Tabulated => MaterialBrdf::Tabulated(basis),
        ReferenceBrdf::Sampled => MaterialBrdf::Sampled(basis, materials.0.iter().map(|m| basis.grid.tabulate(&lobe(m))).collect()),
    };
    let shade = MaterialShade::new(scene, materials, mb);
    let slots = Slots::single();
    let paths = Paths::new(scene, accel, counts, &shade, &slots);
    let (w, y0) = (scene.camera.width, rows.start);
    let n = counts.spp as f64;
    let ([img, var], rays) = with_ctx(cx, |cx| {
        per_pixel_layers(cx, w, rows.len(), |x, y, c| {
            let mut acc = [[0.0f64; 3]];
            // Per camera sample, its share of the mean times spp (the mean of these is the pixel).
            let (mut last, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
            c.rays += paths
                .pixel(x, y0 + y, &mut acc, &mut |a| {
                    for (k, s2) in sum2.iter_mut().enumerate() {
                        let u = (a[0][k] - last[k]) * n;
                        *s2 += u * u;
                    }
                    last = a[0];
                })
                .rays;
            let mean = acc[0];
            // Variance of the mean: (Σu² − n·mean²) / (n (n − 1)), 0 for one sample.
            let var =
                std::array::from_fn(|k| if n > 1.0 { ((sum2[k] - n * mean[k] * mean[k]) / (n * (n - 1.0))).max(0.0) as f32 } else { 0.0 });
            [mean.map(|v| v as f32), var]
        })
    })?;
    Ok(ImageRows::new(w, rows, vec![img, var], vec![rays]))
}

/// A material's specular lobe at ks = 1, as `BrdfSpaceSample` tabulates its samples.
fn lobe(m: &ObjectMaterial) -> BrdfSample {
    match m.specular {
        Specular::BlinnPhong => BrdfSample::blinn_phong(0.0, 1.0, m.s),
        Specular::CookTorrance { m, f0 } => BrdfSample::cook_torrance(1.0, m, f0),
    }
}

#[node(category = "relight", version = 6, sharded, metrics = ["rays"])]
impl RelightReference {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let image = inputs[0].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        // `Sampled` keeps one grid table per dynamic object: about the basis' bytes for as many
        // objects as bases.
        let tables = if self.brdf == ReferenceBrdf::Sampled { inputs[3].map_or(0, |s| s.bytes) } else { 0 };
        relume_core::MemoryEstimate { outputs: vec![image, image], working: image.map_or(0, |s| 2 * s.bytes) + tables }
    }

    fn shard(&self, i: &RelightReferenceIn) -> Result<ShardSpec, NodeError> {
        Ok(row_spec(i.scene.camera.width, i.scene.camera.height))
    }

    fn run_items(&self, i: &RelightReferenceIn, rows: Range<u64>, cx: &RunCtx) -> Result<ImageRows, NodeError> {
        reference_rows(i.scene, i.accel, *i.paths, i.basis, i.materials, self.brdf, rows.start as usize..rows.end as usize, Some(cx))
    }

    fn gather(&self, i: &RelightReferenceIn, parts: &[&ImageRows], cx: &RunCtx) -> Result<RelightReferenceOut, NodeError> {
        let (mut imgs, c) = gather_rows(i.scene.camera.width, i.scene.camera.height, 2, parts)?;
        cx.metric("rays", c[0] as f64);
        let variance = imgs.pop().expect("two layers");
        Ok(RelightReferenceOut { image: imgs.pop().expect("two layers"), variance })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{precompute, scene};
    use relume_base::brdf_space::test_support::{basis, space};
    use relume_base::reference::path_trace::{render, PathTrace};
    use relume_base::testing::{cancels_midway, first, id, run_on};
    use relume_core::Value;

    #[test]
    fn the_same_seed_render_is_the_same_for_any_split_and_checks_its_inputs() {
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 3);
        let s = scene(10);
        let (accel, m, t, _) = precompute(&s, &b, [2, 1, 2, 1]);
        let a = accel.get::<Accel>().unwrap();
        let whole = reference_rows(&s, a, t.counts, &b, &m, ReferenceBrdf::Analytic, 0..10, None).unwrap();
        let parts = [0..3, 3..10].map(|r| reference_rows(&s, a, t.counts, &b, &m, ReferenceBrdf::Analytic, r, None).unwrap());
        assert_eq!(gather_rows(10, 10, 2, &[&whole]).unwrap(), gather_rows(10, 10, 2, &[&parts[0], &parts[1]]).unwrap());
        // The node over the graph's inputs gives the same image.
        let inputs = vec![Value::new(s.clone()), accel.clone(), Value::new(t.counts), Value::new(b.clone()), Value::new(m.clone())];
        let img: Image = first(&run_on::<RelightReference>(&[("brdf", id("Analytic"))], inputs).unwrap());
        assert_eq!(img, gather_rows(10, 10, 2, &[&whole]).unwrap().0[0]);
        // Materials of another scene are refused.
        let mut other = m.clone();
        other.0.pop();
        assert!(reference_rows(&s, a, t.counts, &b, &other, ReferenceBrdf::Analytic, 0..10, None).is_err());
        // Unprojected materials cannot be tabulated.
        let mut raw = m.clone();
        raw.0.iter_mut().for_each(|o| o.coefficients.clear());
        assert!(reference_rows(&s, a, t.counts, &b, &raw, ReferenceBrdf::Tabulated, 0..10, None).is_err());
        // Sampled tables need no projection; a Kd map multiplies their diffuse term, a Ks map
        // has no table.
        assert!(reference_rows(&s, a, t.counts, &b, &raw, ReferenceBrdf::Sampled, 0..10, None).is_ok());
        let mut textured = m.clone();
        textured.0[0].maps.kd = relume_base::types::Texture::new(1, 1, vec![glam::Vec3::splat(0.5)]);
        assert!(reference_rows(&s, a, t.counts, &b, &textured, ReferenceBrdf::Sampled, 0..10, None).is_ok());
        textured.0[0].maps.ks = textured.0[0].maps.kd.clone();
        let err = reference_rows(&s, a, t.counts, &b, &textured, ReferenceBrdf::Sampled, 0..10, None).unwrap_err();
        assert!(err.to_string().contains("Ks or exponent maps"), "{err}");
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
        let [ours, ours_var]: [Image; 2] = gather_rows(16, 16, 2, &[&rows]).unwrap().0.try_into().unwrap();
        let (pt, pt_var, _, _) =
            render(&s, a, &PathTrace { spp: 1024, max_depth: 3, min_depth: 1, rr_depth: 5, seed: 4, fresnel_reflection: true }, None)
                .unwrap();
        let mean = |img: &Image| img.as_floats().iter().map(|v| *v as f64).sum::<f64>() / img.as_floats().len() as f64;
        let (x, y) = (mean(&ours), mean(&pt));
        assert!((x - y).abs() < 0.03 * y, "relighting paths {x} vs path tracer {y}");
        // Per pixel, with both variances: pixels away from the edges between objects of
        // different classes pass the z-test (up to the heavy tails of 16-sample variances);
        // edge pixels carry one object's light for the whole pixel, a bias the test shows.
        let z = relume_base::image::z_test::z_test(&ours, &ours_var, &pt, &pt_var, 3.29).unwrap();
        let class_edge = |p: usize| {
            let (x, y) = ((p % 16) as i64, (p / 16) as i64);
            [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|(dx, dy)| {
                let (u, v) = (x + dx, y + dy);
                (0..16).contains(&u) && (0..16).contains(&v) && t.class[(v * 16 + u) as usize] != t.class[p]
            })
        };
        let interior: Vec<usize> = (0..256).filter(|&p| !class_edge(p)).collect();
        let fails = interior.iter().filter(|&&p| z.z_map.pixels[p].iter().any(|v| *v > 3.29)).count();
        assert!(interior.len() > 120 && fails * 20 <= interior.len(), "{fails} of {} interior pixels fail", interior.len());
    }

    #[test]
    fn the_variance_of_the_mean_falls_as_one_over_the_camera_samples() {
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 3);
        let s = scene(12);
        let (accel, m, t, _) = precompute(&s, &b, [1, 1, 1, 1]);
        let a = accel.get::<Accel>().unwrap();
        let var_at = |spp: u32| {
            let counts = PathCounts { spp, ..t.counts };
            let rows = reference_rows(&s, a, counts, &b, &m, ReferenceBrdf::Analytic, 0..12, None).unwrap();
            let v = gather_rows(12, 12, 2, &[&rows]).unwrap().0.swap_remove(1);
            v.as_floats().iter().map(|v| *v as f64).sum::<f64>()
        };
        assert_eq!(var_at(1), 0.0, "one sample has no variance estimate");
        let (v8, v32) = (var_at(8), var_at(32));
        assert!(v8 > 0.0 && (3.0..5.3).contains(&(v8 / v32)), "variance at 8 and 32 samples: {v8} {v32}");
    }

    #[test]
    fn the_node_stops_midway_when_cancelled() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let s = scene(16);
        let (accel, m, t, _) = precompute(&s, &b, [1, 1, 1, 1]);
        let mut t = t;
        t.counts.bounce_rays = 16;
        t.counts.spp = 4;
        cancels_midway::<RelightReference>(&[], vec![Value::new(s), accel, Value::new(t.counts), Value::new(b), Value::new(m)]);
    }
}
