use super::terms::{Channels, First, Second, Term};
use crate::types::{kd_map_digest, Transfer};
use relume_base::render::film::with_ctx;
use relume_base::types::{Image, ObjectMaterials};
use relume_core::{node, NodeError, Params, RunCtx};

/// Pixel relighting's interactive step ([S] 4-12, 4-26, 4-27): per pixel,
/// L = Σ c(R′, ρ′) I(P0, ρ′) + Σ c(R′, ρ′) c(R1, ρ1) I(P1, ρ′, R1, ρ1), with the coefficients of
/// the pixel's object at x′ (1 for a fixed object's own BRDF) and of the object at x″ (1 for the
/// fixed ones), per colour channel; grey images are multiplied by the light colour. The
/// weights are folded per object class into three rows of the transfer's stride, so each pixel
/// is three dot products over its contiguous floats: one pass over the transfer, rows in
/// parallel, an 8-lane loop the compiler vectorises (the same bytes on any thread count). A
/// dynamic object's Kd map is already in its diffuse basis' images (the precompute multiplied
/// it in, [S] 4.1's textured airplane): materials whose Kd map is not that one (painted since)
/// are refused, as are Ks and exponent maps (`SvRelight` takes those).
#[derive(Params)]
pub struct Relight {}

/// The weights of every class (0: fixed; g + 1: dynamic object g): for each, three rows (R, G,
/// B) of `stride` floats such that a pixel's channel is the row · the pixel's floats.
pub fn class_weights(t: &Transfer, m: &ObjectMaterials) -> Result<Vec<f32>, String> {
    let nb = t.specular_bases as usize + 1;
    let names: Vec<&str> = m.0.iter().map(|o| o.name.as_str()).collect();
    if names != t.groups.iter().map(String::as_str).collect::<Vec<_>>() {
        return Err(format!("the materials are for the objects [{}], the transfer for [{}]", names.join(", "), t.groups.join(", ")));
    }
    if let Some(o) = m.0.iter().find(|o| o.maps.ks.is_some() || o.maps.exponent.is_some()) {
        return Err(format!(
            "\"{}\" has a Ks or exponent map: this transfer keeps one specular lobe per object; such maps need `SvTransferPrecompute` and `SvRelight`",
            o.name
        ));
    }
    for (o, baked) in m.0.iter().zip(&t.kd_maps) {
        if o.maps.kd.as_ref().map(kd_map_digest) != *baked {
            return Err(format!(
                "\"{}\"'s Kd map is not the one the precompute multiplied into its images (painted, replaced or dropped since): run the precompute on this map, or paint with `SvTransferPrecompute` and `SvRelight`",
                o.name
            ));
        }
    }
    if let Some(o) = m.0.iter().find(|o| o.coefficients.len() != nb) {
        return Err(format!(
            "\"{}\" has {} coefficients, the transfer {nb} bases (project the materials on the basis the transfer used)",
            o.name,
            o.coefficients.len()
        ));
    }
    let stride = t.stride as usize;
    let offsets = t.offsets();
    let mut w = vec![0.0f32; (t.groups.len() + 1) * 3 * stride];
    let coef = |g: u16, k: usize| m.0[g as usize].coefficients[k];
    for class in 0..=t.groups.len() {
        let rows = &mut w[class * 3 * stride..(class + 1) * 3 * stride];
        for (i, (term, ch)) in t.terms.iter().enumerate() {
            let (first, second) = match *term {
                Term::Direct(f) => (Some(f), None),
                Term::Bounce(f, s) => (Some(f), Some(s)),
                Term::Emitted => (None, None),
            };
            let cf = match (first, class) {
                (None, _) | (Some(First::Merged), 0) => [1.0; 3],
                (Some(First::Merged), g) => coef(g as u16 - 1, 0),
                (Some(First::Specular(_)), 0) => [0.0; 3],
                (Some(First::Specular(k)), g) => coef(g as u16 - 1, k as usize),
            };
            let cs = match second {
                None | Some(Second::Fixed) => [1.0; 3],
                Some(Second::Diffuse { object }) => coef(object, 0),
                Some(Second::Specular { object, basis }) => coef(object, basis as usize),
            };
            for c in 0..3 {
                let v = cf[c] * cs[c];
                match ch {
                    Channels::Grey => rows[c * stride + offsets[i]] = (v * t.colour[c] as f64) as f32,
                    Channels::Rgb => rows[c * stride + offsets[i] + c] = v as f32,
                }
            }
        }
    }
    Ok(w)
}

/// One pixel: the three dot products of its floats with its class's weight rows, in 8 lanes
/// (the portable path; `combine_row_avx2` does the same in AVX2 registers). Separate
/// multiplies and adds (no fused multiply-add), so every instruction set gives the same bytes.
#[inline(always)]
fn combine_pixel(px: &[f32], w: &[f32], stride: usize) -> [f32; 3] {
    let (wr, rest) = w.split_at(stride);
    let (wg, wb) = rest.split_at(stride);
    let (mut r, mut g, mut b) = ([0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
    let blocks = px.as_chunks::<8>().0.iter().zip(wr.as_chunks::<8>().0).zip(wg.as_chunks::<8>().0).zip(wb.as_chunks::<8>().0);
    for (((d, x), y), z) in blocks {
        for l in 0..8 {
            r[l] += d[l] * x[l];
            g[l] += d[l] * y[l];
            b[l] += d[l] * z[l];
        }
    }
    [r, g, b].map(reduce_lanes)
}

/// The sum of 8 lanes, in a fixed order.
#[inline(always)]
fn reduce_lanes(a: [f32; 8]) -> f32 {
    ((a[0] + a[4]) + (a[1] + a[5])) + ((a[2] + a[6]) + (a[3] + a[7]))
}

/// One row of the image: each pixel with its class's weights.
#[inline(always)]
fn combine_row(t: &Transfer, w: &[f32], y: usize, row: &mut [[f32; 3]]) {
    let (width, stride) = (t.width as usize, t.stride as usize);
    for (x, out) in row.iter_mut().enumerate() {
        let p = y * width + x;
        let class = t.class[p] as usize;
        *out = combine_pixel(&t.data[p * stride..(p + 1) * stride], &w[class * 3 * stride..(class + 1) * 3 * stride], stride);
    }
}

/// `combine_row` in AVX2 registers: the same multiplies and adds in the same lanes and order
/// as `combine_pixel` (8 lanes, no fused multiply-add), so the same bytes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn combine_row_avx2(t: &Transfer, w: &[f32], y: usize, row: &mut [[f32; 3]]) {
    use std::arch::x86_64::{_mm256_add_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_setzero_ps, _mm256_storeu_ps};
    let (width, stride) = (t.width as usize, t.stride as usize);
    for (x, out) in row.iter_mut().enumerate() {
        let p = y * width + x;
        let class = t.class[p] as usize;
        let px = &t.data[p * stride..(p + 1) * stride];
        let wc = &w[class * 3 * stride..(class + 1) * 3 * stride];
        let mut lanes = [[0.0f32; 8]; 3];
        // SAFETY: `px` holds `stride` floats and `wc` three rows of `stride`; `stride` is a
        // multiple of 8, so every 8-float load at j < stride is in bounds; AVX2 is enabled.
        unsafe {
            let (mut r, mut g, mut b) = (_mm256_setzero_ps(), _mm256_setzero_ps(), _mm256_setzero_ps());
            for j in (0..stride).step_by(8) {
                let d = _mm256_loadu_ps(px.as_ptr().add(j));
                r = _mm256_add_ps(r, _mm256_mul_ps(d, _mm256_loadu_ps(wc.as_ptr().add(j))));
                g = _mm256_add_ps(g, _mm256_mul_ps(d, _mm256_loadu_ps(wc.as_ptr().add(stride + j))));
                b = _mm256_add_ps(b, _mm256_mul_ps(d, _mm256_loadu_ps(wc.as_ptr().add(2 * stride + j))));
            }
            _mm256_storeu_ps(lanes[0].as_mut_ptr(), r);
            _mm256_storeu_ps(lanes[1].as_mut_ptr(), g);
            _mm256_storeu_ps(lanes[2].as_mut_ptr(), b);
        }
        *out = lanes.map(reduce_lanes);
    }
}

/// `combine_row` with the widest vectors this CPU has.
fn combine_row_best(t: &Transfer, w: &[f32], y: usize, row: &mut [[f32; 3]]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { combine_row_avx2(t, w, y, row) };
    }
    combine_row(t, w, y, row)
}

/// The relit image of `t` with the materials `m` (see the node's doc).
pub fn relight(t: &Transfer, m: &ObjectMaterials, cx: Option<&RunCtx>) -> Result<Image, NodeError> {
    let w = class_weights(t, m).map_err(|e| NodeError::input("materials", e))?;
    let width = t.width as usize;
    let mut img = Image::try_new(width, t.height as usize)?;
    with_ctx(cx, |cx| cx.par_chunks_mut(&mut img.pixels, width, |y, row| combine_row_best(t, &w, y, row)))?;
    Ok(img)
}

#[node(category = "relight", outputs = [image])]
impl Relight {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // An RGB image of the transfer's size; the dimensions are not known before it exists.
        let _ = inputs;
        relume_core::MemoryEstimate { outputs: vec![None], working: 1 << 20 }
    }

    fn run(&self, transfer: &Transfer, materials: &ObjectMaterials, cx: &RunCtx) -> Result<Image, NodeError> {
        relight(transfer, materials, Some(cx))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::relight_reference::{reference_rows, ReferenceBrdf};
    use crate::test_support::{precompute, scene, tiny_transfer};
    use relume_base::brdf_space::test_support::{basis, space, space_of};
    use relume_base::testing::{first, run_on};
    use relume_base::types::{gather_rows, Accel, BrdfBasis};
    use relume_core::Value;

    /// (Relight, the same-seed render with `brdf`) for `scene(size)` on `b`.
    fn both(size: usize, b: &BrdfBasis, brdf: ReferenceBrdf, counts: [i64; 4]) -> (Image, Image, Transfer, ObjectMaterials) {
        let s = scene(size);
        let (accel, m, t, _) = precompute(&s, b, counts);
        let relit: Image = first(&run_on::<Relight>(&[], vec![Value::new(t.clone()), Value::new(m.clone())]).unwrap());
        let rows = reference_rows(&s, accel.get::<Accel>().unwrap(), t.counts, b, &m, brdf, 0..size, None).unwrap();
        let (mut r, _) = gather_rows(size, size, 2, &[&rows]).unwrap();
        (relit, r.swap_remove(0), t, m)
    }

    fn max_rel_diff(a: &Image, b: &Image) -> f64 {
        let peak = b.as_floats().iter().fold(0.0f32, |m, &v| m.max(v.abs())) as f64;
        a.as_floats().iter().zip(b.as_floats()).map(|(x, y)| (*x as f64 - *y as f64).abs()).fold(0.0, f64::max) / peak
    }

    #[test]
    fn relight_equals_the_same_seed_render_with_the_tabulated_brdf_to_float_precision() {
        // A space holding exactly the rendered exponents (20 and 60, one specular sample each):
        // the basis is exact up to the table; and a general space, where Relight still equals
        // the projected (tabulated) materials on the same paths.
        for b in [basis(&space_of(8, 8, 16, &[20.0, 60.0]), 3).0, basis(&space(8, 8, 16, 12, 1.0, 100.0), 4).0] {
            let (relit, reference, _, _) = both(12, &b, ReferenceBrdf::Tabulated, [3, 2, 3, 1]);
            let d = max_rel_diff(&relit, &reference);
            eprintln!("max |Relight − tabulated| / peak = {d:e}");
            assert!(d < 1e-5, "max |Relight − reference| / peak = {d}");
            assert!(reference.as_floats().iter().any(|v| *v > 0.0));
        }
    }

    /// Relative L2 distance of `a` from `r`.
    fn l2(a: &Image, r: &Image) -> f64 {
        let e: f64 = a.as_floats().iter().zip(r.as_floats()).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
        (e / r.as_floats().iter().map(|y| (*y as f64).powi(2)).sum::<f64>()).sqrt()
    }

    #[test]
    fn the_basis_sum_follows_the_analytic_brdf_within_the_table_error() {
        // Exact exponents in the space: what is left against the analytic BRDF is the table's
        // trilinear interpolation on 16 × 16 × 32 cells, a few percent at most.
        let (b, _) = basis(&space_of(16, 16, 32, &[20.0, 60.0]), 3);
        let (relit, analytic, _, _) = both(12, &b, ReferenceBrdf::Analytic, [3, 2, 3, 1]);
        let e = l2(&relit, &analytic);
        eprintln!("L2 against the analytic BRDF on the same paths: {e:e}");
        assert!(e > 0.0 && e < 0.05, "L2 {e}");
    }

    #[test]
    fn against_the_sampled_brdfs_only_the_truncation_of_the_basis_is_left() {
        // The rendered exponents (20 and 60) in the space and every component kept: nothing is
        // truncated, so Relight is the sampled tables to float precision, while the analytic
        // BRDF still differs by the grid's interpolation.
        let (b, _) = basis(&space_of(16, 16, 32, &[20.0, 60.0]), 3);
        let (relit, sampled, _, _) = both(12, &b, ReferenceBrdf::Sampled, [3, 2, 3, 1]);
        let (_, analytic, _, _) = both(12, &b, ReferenceBrdf::Analytic, [3, 2, 3, 1]);
        let (truncation, grid) = (max_rel_diff(&relit, &sampled), l2(&sampled, &analytic));
        eprintln!("exact basis: |Relight − sampled| / peak = {truncation:e}, grid L2 {grid:e}");
        assert!(truncation < 1e-5 && grid > 1e-3, "{truncation} {grid}");
        // Two components of twelve exponents: the truncation shows against the sampled BRDFs.
        let (b, _) = basis(&space(16, 16, 32, 12, 1.0, 100.0), 3);
        let (relit, sampled, _, _) = both(12, &b, ReferenceBrdf::Sampled, [3, 2, 3, 1]);
        assert!(l2(&relit, &sampled) > 1e-3, "{}", l2(&relit, &sampled));
    }

    #[test]
    fn an_edit_is_linear_in_the_objects_coefficients_and_reaches_others_through_the_bounce() {
        let (b, _) = basis(&space(8, 8, 16, 12, 1.0, 100.0), 4);
        let (relit, _, t, m) = both(10, &b, ReferenceBrdf::Tabulated, [2, 1, 32, 1]);
        // Sphere c is convex (it never lights itself): on its own pixels every term carries
        // exactly one of its coefficients, so doubling them doubles the pixel.
        let mut doubled = m.clone();
        doubled.0[1].coefficients.iter_mut().for_each(|c| *c = c.map(|v| 2.0 * v));
        let twice = relight(&t, &doubled, None).unwrap();
        let mut seen = 0;
        for p in (0..t.pixels()).filter(|&p| t.class[p] == 2) {
            for ch in 0..3 {
                let (a, b) = (twice.pixels[p][ch], 2.0 * relit.pixels[p][ch]);
                assert!((a - b).abs() <= 1e-5 * b.abs().max(1e-3), "pixel {p}: {a} vs {b}");
            }
            seen += 1;
        }
        assert!(seen > 0);
        // Zeroing sphere c changes its pixels and, through the bounce, the floor's under it.
        let mut dark = m.clone();
        dark.0[1].coefficients.iter_mut().for_each(|c| *c = [0.0; 3]);
        let without = relight(&t, &dark, None).unwrap();
        let changed = |class: u32| (0..t.pixels()).filter(|&p| t.class[p] == class && without.pixels[p] != relit.pixels[p]).count();
        assert!(changed(2) > 0 && changed(0) > 0, "sphere pixels {} floor pixels {}", changed(2), changed(0));
    }

    #[test]
    fn the_avx2_combine_gives_the_portable_combines_bytes() {
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 6);
        let (_, m, t, _) = precompute(&scene(9), &b, [2, 1, 4, 1]);
        let w = class_weights(&t, &m).unwrap();
        let width = t.width as usize;
        for y in 0..t.height as usize {
            let (mut a, mut best) = (vec![[0.0; 3]; width], vec![[0.0; 3]; width]);
            combine_row(&t, &w, y, &mut a);
            combine_row_best(&t, &w, y, &mut best);
            assert_eq!(a, best, "row {y}");
        }
    }

    #[test]
    fn materials_of_other_objects_or_another_basis_are_refused() {
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 3);
        let (_, m, t, _) = precompute(&scene(6), &b, [1, 1, 1, 1]);
        let mut other = m.clone();
        other.0[0].name = "teapot".into();
        let e = relight(&t, &other, None).unwrap_err();
        assert!(e.to_string().contains("teapot"), "{e}");
        let mut short = m.clone();
        short.0[1].coefficients.pop();
        assert!(relight(&t, &short, None).unwrap_err().to_string().contains("coefficients"));
    }

    #[test]
    fn a_kd_map_on_a_dynamic_object_multiplies_its_diffuse_images_and_a_painted_one_is_refused() {
        // Sphere c (dynamic, with UVs) gets a map of four strong colours: the relit image equals
        // the same paths with the textured tabulated materials to float precision, follows the
        // analytic textured BRDF (read through `MaterialMaps::apply`) within the table error,
        // and differs from the untextured image by far more than that.
        use relume_base::types::Texture;
        let (b, _) = basis(&space_of(16, 16, 32, &[20.0, 60.0]), 3);
        let mut s = crate::test_support::sv_scene(12);
        let colours = vec![glam::Vec3::new(1.0, 0.1, 0.1), glam::Vec3::new(0.1, 1.0, 0.1), glam::Vec3::new(0.1, 0.1, 1.0), glam::Vec3::ONE];
        s.objects[2].maps.kd = Texture::new(2, 2, colours);
        let (accel, m, t, _) = precompute(&s, &b, [3, 2, 3, 1]);
        assert_eq!((t.kd_maps[0], t.kd_maps[1].is_some()), (None, true), "the map of c, none on the glossy pair");
        let relit = relight(&t, &m, None).unwrap();
        let same = |brdf: ReferenceBrdf| {
            let rows = reference_rows(&s, accel.get::<Accel>().unwrap(), t.counts, &b, &m, brdf, 0..12, None).unwrap();
            gather_rows(12, 12, 2, &[&rows]).unwrap().0.swap_remove(0)
        };
        let d = max_rel_diff(&relit, &same(ReferenceBrdf::Tabulated));
        assert!(d < 1e-5, "max |Relight − tabulated| / peak = {d}");
        let analytic = same(ReferenceBrdf::Analytic);
        let plain = precompute(&crate::test_support::sv_scene(12), &b, [3, 2, 3, 1]);
        let untextured = relight(&plain.2, &plain.1, None).unwrap();
        let (e, off) = (l2(&relit, &analytic), l2(&untextured, &analytic));
        eprintln!("|Relight − tabulated| / peak {d:e}; L2 to the textured analytic BRDF {e:e}, untextured {off:e}");
        assert!(e < 0.05 && off > 4.0 * e, "L2 to the textured BRDF {e}, the untextured image's {off}");
        // A map painted after the precompute, or a Ks map, is refused with its reason.
        let mut painted = m.clone();
        painted.0[1].maps.kd.as_mut().unwrap().texels[0] = glam::Vec3::splat(0.5);
        assert!(relight(&t, &painted, None).unwrap_err().to_string().contains("Kd map is not the one"));
        let mut dropped = m.clone();
        dropped.0[1].maps.kd = None;
        assert!(relight(&t, &dropped, None).is_err(), "the images hold the map");
        let mut specular = m.clone();
        specular.0[1].maps.ks = specular.0[1].maps.kd.clone();
        assert!(relight(&t, &specular, None).unwrap_err().to_string().contains("Ks or exponent map"));
    }

    #[test]
    fn the_combine_is_the_per_pixel_formula() {
        // One group, S = 1, hand-made floats: L = Σ w·I with the coefficients and the colour.
        let t = tiny_transfer(vec![1.0, 2.0, 3.0, 10.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 10.0, 0.0, 0.0, 0.0, 0.0]);
        let m = ObjectMaterials(vec![relume_base::types::ObjectMaterial {
            name: "a".into(),
            kd: [0.5; 3],
            ks: [0.0; 3],
            s: 1.0,
            coefficients: vec![[0.5, 0.25, 0.0], [2.0, 2.0, 4.0]],
            maps: Default::default(),
            specular: Default::default(),
        }]);
        let img = relight(&t, &m, None).unwrap();
        // Class 0 (fixed): merged image × 1, no specular term.
        assert_eq!(img.pixels[0], [1.0, 2.0, 3.0]);
        // Class 1: merged × Kd + grey × c_1 × colour.
        assert_eq!(img.pixels[1], [0.5 + 20.0, 0.5 + 10.0, 0.0 + 10.0]);
    }
}
