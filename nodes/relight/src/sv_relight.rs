use super::sv_shade::cell_rect;
use crate::types::SvTransfer;
use glam::{Vec2, Vec3};
use relume_base::math::haar;
use relume_base::render::film::with_ctx;
use relume_base::types::{BasisFamily, BrdfBasis, Image, Material, ObjectMaterial, ObjectMaterials};
use relume_core::{node, NodeError, Params, RunCtx};
use std::sync::atomic::{AtomicU64, Ordering};

/// Spatially varying pixel relighting's interactive step ([S] 4.2.3, 4-35): materials are
/// textures (Kd, Ks and s maps times the object's Kd, Ks, s; `PaintMaterial` edits them). Per
/// pixel, direct light Σ c_ρ′(x′) I(P0, ρ′) with the coefficients of the exact texel at x′
/// (its UV from the precompute), plus the bounce: each group's weights are summed with the
/// texture down-sampled to the sub-region grid (mean over each cell, then projected),
/// the basis images combined in the wavelet domain per x′ basis ρ′ (multithreaded over
/// coefficient ranges, a fixed order per coefficient), one inverse Haar transform per ρ′
/// and channel, then each ρ′ image times the pixel's texel coefficient (a per-pixel factor
/// does not commute with the transform). Exponents outside the basis' sampled range are
/// clamped to it (counted: `clamped_texels`). Same bytes on any thread count.
#[derive(Params)]
pub struct SvRelight {}

/// The coefficients of Blinn-Phong (kd, ks, s) on the first `out.len()` bases per channel,
/// s clamped to the basis' range; returns whether it was clamped.
pub fn project_clamped(basis: &BrdfBasis, kd: Vec3, ks: Vec3, s: f32, out: &mut [[f32; 3]]) -> bool {
    let (lo, hi) = basis.s_range().unwrap_or((s as f64, s as f64));
    let sc = (s as f64).clamp(lo, hi);
    let spec = if ks == Vec3::ZERO || out.len() < 2 { vec![] } else { basis.specular_coefficients(sc).unwrap_or_default() };
    for (k, o) in out.iter_mut().enumerate() {
        for c in 0..3 {
            o[c] = if k == 0 { kd[c] } else { spec.get(k - 1).map_or(0.0, |v| (ks[c] as f64 * v) as f32) };
        }
    }
    sc != s as f64 && ks != Vec3::ZERO
}

/// Object `m`'s (Kd, Ks, s) at `uv` (its maps bilinearly, as the path tracer reads them).
fn texel(m: &ObjectMaterial, uv: Vec2) -> (Vec3, Vec3, f32) {
    let bp = Material::BlinnPhong { kd: Vec3::from(m.kd), ks: Vec3::from(m.ks), exponent: m.s };
    match m.maps.apply(bp, uv) {
        Material::BlinnPhong { kd, ks, exponent } => (kd, ks, exponent),
        _ => unreachable!("a Blinn-Phong material stays Blinn-Phong"),
    }
}

/// Object `m`'s (Kd, Ks, s) down-sampled to sub-region `r` of an n × n grid.
fn cell_material(m: &ObjectMaterial, r: usize, n: usize) -> (Vec3, Vec3, f32) {
    let (u, v) = cell_rect(r, n);
    let mean = |t: &Option<relume_base::types::Texture>| t.as_ref().map_or(Vec3::ONE, |t| t.mean_over(u, v));
    let s = (m.s * mean(&m.maps.exponent).x).max(1.0);
    (Vec3::from(m.kd) * mean(&m.maps.kd), Vec3::from(m.ks) * mean(&m.maps.ks), s)
}

/// Parts each wavelet plane is split into for the parallel accumulation.
const PARTS: usize = 16;

/// The relit image of `t` with `m` (see the node's doc), and the texels whose exponent was
/// clamped.
pub fn sv_relight(t: &SvTransfer, basis: &BrdfBasis, m: &ObjectMaterials, cx: Option<&RunCtx>) -> Result<(Image, u64), NodeError> {
    let names: Vec<&str> = m.0.iter().map(|o| o.name.as_str()).collect();
    if names != t.groups.iter().map(String::as_str).collect::<Vec<_>>() {
        return Err(NodeError::input(
            "materials",
            format!("the materials are for the objects [{}], the transfer for [{}]", names.join(", "), t.groups.join(", ")),
        ));
    }
    if basis.family != BasisFamily::BlinnPhong {
        return Err(NodeError::input(
            "basis",
            "the basis was made from Cook-Torrance samples; SvRelight projects Blinn-Phong texels through a Blinn-Phong basis' table c(s)",
        ));
    }
    if basis.bases() != t.direct_bases as usize {
        return Err(NodeError::input(
            "basis",
            format!("the basis has {} BRDFs, the transfer was computed on {}", basis.bases(), t.direct_bases),
        ));
    }
    let (w, h) = (t.width as usize, t.height as usize);
    let (nbd, nbi, n) = (t.direct_bases as usize, t.indirect_bases as usize, t.sub_regions as usize);
    let n2 = n * n;
    let clamped = AtomicU64::new(0);
    let mut img = Image::try_new(w, h)?;
    with_ctx(cx, |cx| -> Result<(), NodeError> {
        // The sub-regions' coefficients: cells[g][r * nbi + k].
        let cells: Vec<Vec<[f32; 3]>> =
            m.0.iter()
                .map(|o| {
                    let mut out = vec![[0.0f32; 3]; n2 * nbi];
                    for r in 0..n2 {
                        let (kd, ks, s) = cell_material(o, r, n);
                        clamped.fetch_add(project_clamped(basis, kd, ks, s, &mut out[r * nbi..(r + 1) * nbi]) as u64, Ordering::Relaxed);
                    }
                    out
                })
                .collect();
        // Each block's weight per (component, channel).
        let weights: Vec<Vec<[f32; 3]>> = t
            .blocks
            .iter()
            .map(|b| {
                let k = b.components as usize;
                let c = &cells[b.object as usize];
                (0..k)
                    .map(|j| {
                        let mut s = [0.0f64; 3];
                        for r in 0..n2 {
                            let a = b.weights[r * k + j] as f64;
                            for ch in 0..3 {
                                s[ch] += a * c[r * nbi + b.second as usize][ch] as f64;
                            }
                        }
                        s.map(|v| v as f32)
                    })
                    .collect()
            })
            .collect();
        // The wavelet images per (ρ′, channel), accumulated per coefficient range.
        let side = t.side as usize;
        let sq = side * side;
        let parts = PARTS.min(sq);
        let part = sq / parts;
        let mut wav = vec![0.0f32; nbi * 3 * sq];
        cx.par_chunks_mut(&mut wav, part, |i, out| {
            let (plane, p) = (i / parts, i % parts);
            let (f, ch) = (plane / 3, plane % 3);
            let lo = (p * part) as u32;
            for (b, wb) in t.blocks.iter().zip(&weights).filter(|(b, _)| b.first as usize == f) {
                for (j, wj) in wb.iter().enumerate() {
                    let pl = &b.images[j * 3 + ch];
                    let a = pl.index.partition_point(|&x| x < lo);
                    let e = pl.index.partition_point(|&x| x < lo + part as u32);
                    for (x, v) in pl.index[a..e].iter().zip(&pl.value[a..e]) {
                        out[(*x - lo) as usize] += wj[ch] * v;
                    }
                }
            }
        })?;
        cx.par_chunks_mut(&mut wav, sq, |_, d| haar::inverse(d, side))?;
        // Per pixel: the texel's coefficients times the direct and bounce images.
        let px = w * h;
        cx.par_chunks_mut(&mut img.pixels, w, |y, row| {
            let mut c = vec![[0.0f32; 3]; nbd];
            for (x, out) in row.iter_mut().enumerate() {
                let p = y * w + x;
                let class = t.class[p] as usize;
                c.iter_mut().for_each(|v| *v = [0.0; 3]);
                if class == 0 {
                    c[0] = [1.0; 3];
                } else {
                    let (kd, ks, s) = texel(&m.0[class - 1], Vec2::from(t.uv[p]));
                    clamped.fetch_add(project_clamped(basis, kd, ks, s, &mut c) as u64, Ordering::Relaxed);
                }
                let mut l = [0.0f32; 3];
                for ch in 0..3 {
                    let mut v = if t.emitted.is_empty() { 0.0 } else { t.emitted[p * 3 + ch] };
                    for (k, ck) in c.iter().enumerate() {
                        v += ck[ch] * t.direct[(k * px + p) * 3 + ch];
                    }
                    for f in 0..nbi {
                        let fixed = if t.fixed.is_empty() { 0.0 } else { t.fixed[(f * px + p) * 3 + ch] };
                        v += c[f][ch] * (fixed + wav[(f * 3 + ch) * sq + y * side + x]);
                    }
                    l[ch] = v;
                }
                *out = l;
            }
        })
    })?;
    Ok((img, clamped.into_inner()))
}

#[node(category = "relight", version = 2, metrics = ["clamped_texels"], outputs = [image])]
impl SvRelight {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The image and the wavelet planes (4 x′ bases × 3 channels of the padded square);
        // the sizes are known only from the transfer itself.
        let _ = inputs;
        relume_core::MemoryEstimate { outputs: vec![None], working: 16 << 20 }
    }

    fn run(&self, transfer: &SvTransfer, basis: &BrdfBasis, materials: &ObjectMaterials, cx: &RunCtx) -> Result<Image, NodeError> {
        let (image, clamped) = sv_relight(transfer, basis, materials, Some(cx))?;
        cx.metric("clamped_texels", clamped as f64);
        if clamped > 0 {
            cx.note(format!(
                "{clamped} texels or sub-regions have an exponent outside the basis' sampled range: clamped to it (widen BrdfSpaceSample's s_min / s_max)"
            ));
        }
        Ok(image)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::relight_pixels::relight;
    use crate::relight_reference::{reference_rows, ReferenceBrdf};
    use crate::sv_precompute::{sv_precompute, SvSettings};
    use crate::test_support::{precompute, sv_scene};
    use crate::types::PathCounts;
    use relume_base::brdf_space::scene_materials::scene_materials;
    use relume_base::brdf_space::test_support::{basis, space};
    use relume_base::types::{gather_rows, Accel, Scene, Texture};
    use relume_core::CancelToken;

    const COUNTS: PathCounts = PathCounts { spp: 2, light_samples: 1, bounce_rays: 4, bounce_light_samples: 1, seed: 3 };

    fn lossless(n: usize, indirect: usize) -> SvSettings {
        SvSettings { sub_regions: n, indirect_bases: indirect, pca_keep: 1.0, haar_keep: 1.0, median_radius: 0 }
    }

    fn sv(scene: &Scene, b: &BrdfBasis, s: &SvSettings) -> SvTransfer {
        let accel = Accel::build(scene, relume_base::types::accel::BuildQuality::Fast);
        let cancel = CancelToken::new();
        sv_precompute(scene, &accel, b, COUNTS, s, &RunCtx::new("sv", &cancel, None)).unwrap().0
    }

    /// The scene's materials with Ks = 0, projected on `b`.
    fn diffuse(scene: &Scene, b: &BrdfBasis) -> ObjectMaterials {
        let mut m = scene_materials(scene).unwrap();
        for o in &mut m.0 {
            o.ks = [0.0; 3];
            let c: Vec<Vec<f64>> = (0..3).map(|ch| b.project(o.kd[ch] as f64, 0.0, o.s as f64).unwrap()).collect();
            o.coefficients = (0..b.bases()).map(|k| [c[0][k], c[1][k], c[2][k]]).collect();
        }
        m
    }

    fn max_rel_diff(a: &Image, b: &Image) -> f64 {
        let peak = b.as_floats().iter().fold(0.0f32, |m, &v| m.max(v.abs())) as f64;
        a.as_floats().iter().zip(b.as_floats()).map(|(x, y)| (*x as f64 - *y as f64).abs()).fold(0.0, f64::max) / peak
    }

    #[test]
    fn without_compression_and_textures_it_equals_the_plain_relight_on_diffuse_materials() {
        // Ks = 0: 4-36 drops nothing, every sub-region has the object's Kd, and the sum over
        // sub-regions is the plain transfer's bounce image — on the same seeded paths.
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 3);
        let scene = sv_scene(12);
        let t = sv(&scene, &b, &lossless(3, 3));
        let m = diffuse(&scene, &b);
        let (img, clamped) = sv_relight(&t, &b, &m, None).unwrap();
        let (_, _, plain, _) = precompute(&scene, &b, [2, 1, 4, 1]);
        let want = relight(&plain, &m, None).unwrap();
        assert_eq!(clamped, 0);
        assert!(want.as_floats().iter().any(|v| *v > 0.0));
        assert!(max_rel_diff(&img, &want) < 1e-4, "{}", max_rel_diff(&img, &want));
        assert_eq!(t.class, plain.class, "the same pixels' objects");
    }

    #[test]
    fn a_texture_constant_per_sub_region_matches_the_same_seed_render_away_from_cell_edges() {
        // A 48 × 40 texture (not a power of two) of 2 × 2 blocks on sphere c, 2 × 2 sub-regions,
        // on a 12 × 10 image (padded to 16²): the down-sampled texture is exact, and x′ reads
        // the exact texel, so only pixels across a block edge (their samples see both) differ.
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 3);
        let mut scene = sv_scene(12);
        scene.camera.height = 10;
        let t = sv(&scene, &b, &lossless(2, 3));
        assert_eq!((t.side, t.width, t.height), (16, 12, 10));
        let mut m = diffuse(&scene, &b);
        let block =
            |x: usize, y: usize| if (x / 24 + y / 20).is_multiple_of(2) { Vec3::new(1.0, 0.2, 0.2) } else { Vec3::new(0.1, 0.1, 1.0) };
        m.0[1].maps.kd = Texture::new(48, 40, (0..48 * 40).map(|i| block(i % 48, i / 48)).collect());
        let (img, _) = sv_relight(&t, &b, &m, None).unwrap();
        let accel = Accel::build(&scene, relume_base::types::accel::BuildQuality::Fast);
        let rows = reference_rows(&scene, &accel, COUNTS, &b, &m, ReferenceBrdf::Analytic, 0..10, None).unwrap();
        let (mut r, _) = gather_rows(12, 10, 2, &[&rows]).unwrap();
        let want = r.swap_remove(0);
        let peak = want.as_floats().iter().fold(0.0f32, |a, &v| a.max(v)) as f64;
        let close = img.pixels.iter().zip(&want.pixels).filter(|(a, w)| (0..3).all(|c| ((a[c] - w[c]) as f64).abs() < 1e-4 * peak)).count();
        assert!(close as f64 >= 0.85 * img.pixels.len() as f64, "{close} of {} pixels agree", img.pixels.len());
        // The texture shows: sphere c's pixels are not all one colour.
        let c_pixels: Vec<[f32; 3]> = (0..120).filter(|&p| t.class[p] == 2).map(|p| img.pixels[p]).collect();
        assert!(c_pixels.iter().any(|p| p[0] > p[2]) && c_pixels.iter().any(|p| p[2] > p[0]), "{c_pixels:?}");
    }

    #[test]
    fn mismatched_materials_or_basis_are_input_errors() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let scene = sv_scene(6);
        let t = sv(&scene, &b, &lossless(2, 2));
        let mut m = diffuse(&scene, &b);
        m.0.swap(0, 1);
        assert!(sv_relight(&t, &b, &m, None).unwrap_err().to_string().contains("[c, glossy]"));
        let (b4, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 4);
        let e = sv_relight(&t, &b4, &diffuse(&scene, &b), None).unwrap_err().to_string();
        assert!(e.contains("4 BRDFs") && e.contains("computed on 3"), "{e}");
        // A Cook-Torrance space's basis has no c(s) table for the texels' exponents.
        let (ct, _) = basis(&relume_base::brdf_space::test_support::ct_space(4, 5, 2, 0.1, 0.6), 3);
        let e = sv_relight(&t, &ct, &diffuse(&scene, &b), None).unwrap_err().to_string();
        assert!(e.contains("Cook-Torrance"), "{e}");
    }

    #[test]
    fn exponents_outside_the_basis_range_are_clamped_and_counted() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let mut out = [[0.0f32; 3]; 3];
        assert!(project_clamped(&b, Vec3::splat(0.5), Vec3::splat(0.2), 500.0, &mut out));
        let mut at_max = [[0.0f32; 3]; 3];
        assert!(!project_clamped(&b, Vec3::splat(0.5), Vec3::splat(0.2), 100.0, &mut at_max));
        assert_eq!(out, at_max);
        assert!(!project_clamped(&b, Vec3::splat(0.5), Vec3::ZERO, 500.0, &mut out), "without Ks the exponent plays no part");
        assert_eq!(out[1], [0.0; 3]);
    }

    #[test]
    fn the_node_counts_clamped_exponents_and_says_so() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let scene = sv_scene(6);
        let t = sv(&scene, &b, &lossless(2, 2));
        let mut m = scene_materials(&scene).unwrap();
        m.0[1].maps.exponent = Texture::new(3, 5, vec![Vec3::splat(50.0); 15]);
        let inputs = vec![relume_core::Value::new(t), relume_core::Value::new(b), relume_core::Value::new(m)];
        let e = relume_base::testing::run_full::<SvRelight>(&[], std::path::Path::new("."), inputs).unwrap();
        let clamped = e.metrics.iter().find(|x| x.0 == "clamped_texels").unwrap().1;
        // Sphere c's s = 60 × 50 is beyond 100: its 4 sub-regions and its pixels are clamped.
        assert!(clamped >= 4.0, "{clamped}");
        assert!(e.notes.iter().any(|n| n.contains("clamped to it")), "{:?}", e.notes);
        assert!(e.outputs[0].get::<Image>().unwrap().as_floats().iter().all(|v| v.is_finite()));
    }
}
