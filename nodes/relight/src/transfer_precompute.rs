use super::paths::{Paths, Slots};
use super::shades::{check_scene, light_colour, scene_terms, BasisShade};
use super::terms::{Channels, TermSet};
use crate::types::{floats_and_stride, kd_map_digest, PathCounts, Transfer, TransferRows, MAX_TRANSFER_BYTES};
use relume_base::render::film::with_ctx;
use relume_base::types::accel::Accel;
use relume_base::types::{row_spec, BrdfBasis, Image, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, params, NodeError, RunCtx, ShardSpec};
use std::ops::Range;

params! {
    /// Pixel relighting's precompute ([S] 4.1.1, 4.1.3, table 4-1): per pixel, ONE set of paths
    /// fills every transfer image the scene needs — direct light at the first hit x′ with each basis
    /// BRDF (I(P0, ρ′)) and one bounce through uniform hemisphere rays to x″ with direct light there,
    /// with each basis at x″ and at x′ (I(P1, ρ′, R1, ρ1)); fixed-material objects use their own
    /// BRDF. A dynamic object's Kd map multiplies its diffuse basis at each hit, as [S] 4.1 renders
    /// its textured airplane (the edit's Kd stays the coefficient; Ks and exponent maps need the
    /// spatially varying extension). Which images exist, and which are grey, follows the scene
    /// (`relight::terms`; the report counts them and says what was left out). Basis BRDFs are
    /// signed: nothing is clamped, rouletted or importance-sampled by them. Camera samples are jittered over the pixel (the
    /// reference's box filter); a pixel takes the object most of its samples hit (the object-id
    /// image) and drops the reflected light of the others (counted: `dropped_samples`,
    /// `mixed_pixels`; the `dropped` image holds each pixel's share of dropped samples, 0 where
    /// one object covers it: the pixels a z-test against the reference can hold the model to).
    /// Light seen directly (emitters, the environment) has an image of its own
    /// (`images_emitted`) averaged over every camera sample, so a light's edge is antialiased as in
    /// the reference. Seeded: the same bytes on any thread count and
    /// any sharding (sharded over image rows for `relume shard` / `--processes`); `paths` gives
    /// the path counts to a same-seed render (`RelightReference`). The held bytes
    /// (images × pixels × 4) are checked against the limit before anything is allocated.
    pub struct TransferPrecompute {
        /// the path counts and the seed (shared with the other precompute)
        pub paths: PathCounts, flatten;
    }
}

inputs!(pub TransferPrecomputeIn { scene: Scene, accel: Accel, basis: BrdfBasis });
outputs!(pub TransferPrecomputeOut { transfer: Transfer, paths: PathCounts, dropped: Image });

/// The terms of the scene after the checks, with the bytes they will hold refused over the
/// limit: 16 GiB or the run's memory budget (`--memory-budget`), the lower.
fn terms_checked(scene: &Scene, basis: &BrdfBasis, budget: u64) -> Result<TermSet, NodeError> {
    check_scene(scene, basis.bases()).map_err(|m| NodeError::input("scene", m))?;
    let set = scene_terms(scene, basis.bases());
    let (_, stride) = floats_and_stride(&set.terms);
    let (w, h) = (scene.camera.width as u64, scene.camera.height as u64);
    let bytes = stride as u64 * 4 * w * h;
    let limit = MAX_TRANSFER_BYTES.min(budget);
    if bytes > limit {
        return Err(NodeError::OverLimit {
            param: None,
            msg: format!(
                "{} images ({} grey, {} RGB) at {w} × {h} would hold {}, over the {} limit: lower the resolution or the number of bases",
                set.terms.len(),
                set.count(Channels::Grey),
                set.count(Channels::Rgb),
                fmt_bytes(bytes),
                fmt_bytes(limit)
            ),
        });
    }
    Ok(set)
}

/// The rows `rows` of the transfer (every pixel's images, pixel-major, grey terms as the
/// multiple of the light colour), with the counters [rays, dropped samples, mixed pixels].
pub fn precompute_rows(
    scene: &Scene,
    accel: &Accel,
    basis: &BrdfBasis,
    counts: PathCounts,
    rows: Range<usize>,
    cx: Option<&RunCtx>,
) -> Result<TransferRows, NodeError> {
    let budget = cx.map_or_else(relume_core::limits::default_budget, |c| c.memory_budget());
    let set = terms_checked(scene, basis, budget)?;
    let (floats, stride) = floats_and_stride(&set.terms);
    let w = scene.camera.width;
    let colour = light_colour(scene).unwrap_or([1.0; 3]);
    let c = (0..3).max_by(|&a, &b| colour[a].total_cmp(&colour[b])).unwrap_or(0);
    let (shade, slots): (BasisShade, Slots) = BasisShade::new(scene, basis, &set);
    let paths = Paths::new(scene, accel, counts, &shade, &slots);
    let mut data = vec![0.0f32; rows.len() * w * stride];
    let mut class = vec![0u32; rows.len() * w];
    let mut dropped = vec![0u32; rows.len() * w];
    let y0 = rows.start;
    let row_stats = with_ctx(cx, |cx| {
        cx.par_map(rows.len(), |r| {
            let mut out = vec![0.0f32; w * stride];
            let mut classes = vec![0u32; w];
            let mut drops = vec![0u32; w];
            let mut acc = vec![[0.0f64; 3]; set.terms.len()];
            let mut counters = [0u64; 3];
            for x in 0..w {
                acc.iter_mut().for_each(|a| *a = [0.0; 3]);
                let st = paths.pixel(x, y0 + r, &mut acc, &mut |_| {});
                classes[x] = st.class;
                drops[x] = st.dropped;
                counters[0] += st.rays;
                counters[1] += st.dropped as u64;
                counters[2] += (st.dropped > 0) as u64;
                let px = &mut out[x * stride..x * stride + floats];
                let mut o = 0;
                for (t, a) in set.terms.iter().zip(&acc) {
                    match t.1 {
                        Channels::Grey => {
                            px[o] = a[c] as f32;
                            o += 1;
                        }
                        Channels::Rgb => {
                            px[o..o + 3].copy_from_slice(&[a[0] as f32, a[1] as f32, a[2] as f32]);
                            o += 3;
                        }
                    }
                }
            }
            (out, classes, drops, counters)
        })
    })?;
    let mut counters = vec![0u64; 3];
    for (r, (out, classes, drops, cs)) in row_stats.into_iter().enumerate() {
        data[r * w * stride..(r + 1) * w * stride].copy_from_slice(&out);
        class[r * w..(r + 1) * w].copy_from_slice(&classes);
        dropped[r * w..(r + 1) * w].copy_from_slice(&drops);
        counters.iter_mut().zip(cs).for_each(|(a, b)| *a += b);
    }
    Ok(TransferRows { first_row: rows.start as u64, rows: rows.len() as u64, class, data, dropped, counters })
}

/// Stacks bands into the whole transfer (bands in any order; they must cover the image once),
/// with the image of the share of each pixel's camera samples dropped (grey) and the counters
/// [rays, dropped samples, mixed pixels].
pub fn gather_transfer(
    scene: &Scene,
    basis: &BrdfBasis,
    counts: PathCounts,
    parts: &[&TransferRows],
    budget: u64,
) -> Result<(Transfer, Image, [u64; 3]), NodeError> {
    let set = terms_checked(scene, basis, budget)?;
    let (_, stride) = floats_and_stride(&set.terms);
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut data = vec![0.0f32; w * h * stride];
    let mut class = vec![0u32; w * h];
    let mut dropped = Image::try_new(w, h)?;
    let mut covered = 0u64;
    let mut counters = [0u64; 3];
    for p in parts {
        let (a, n) = (p.first_row as usize, p.rows as usize);
        if a + n > h || p.data.len() != n * w * stride || p.class.len() != n * w || p.dropped.len() != n * w || p.counters.len() != 3 {
            return Err(NodeError::Failed(format!("a band of rows {a}..{} does not fit the {w} × {h} transfer", a + n)));
        }
        data[a * w * stride..(a + n) * w * stride].copy_from_slice(&p.data);
        class[a * w..(a + n) * w].copy_from_slice(&p.class);
        for (px, &k) in dropped.pixels[a * w..(a + n) * w].iter_mut().zip(&p.dropped) {
            *px = [k as f32 / counts.spp.max(1) as f32; 3];
        }
        covered += n as u64;
        counters.iter_mut().zip(&p.counters).for_each(|(x, y)| *x += y);
    }
    if covered != h as u64 {
        return Err(NodeError::Failed(format!("the bands cover {covered} of {h} rows")));
    }
    let transfer = Transfer {
        width: w as u32,
        height: h as u32,
        terms: set.terms.clone(),
        groups: scene.dynamic_groups().into_iter().map(|g| g.0).collect(),
        specular_bases: basis.bases() as u32 - 1,
        colour: light_colour(scene).unwrap_or([1.0; 3]),
        counts,
        kd_maps: scene
            .dynamic_groups()
            .iter()
            .map(|(_, members)| scene.objects[members[0] as usize].maps.kd.as_ref().map(kd_map_digest))
            .collect(),
        stride: stride as u32,
        class,
        data,
    };
    Ok((transfer, dropped, counters))
}

#[node(category = "relight", version = 6, sharded, metrics = ["images", "images_grey", "images_rgb", "images_emitted", "dynamic_objects", "bytes", "rays", "hemisphere_rays_per_pixel", "dropped_samples", "mixed_pixels"])]
impl TransferPrecompute {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The images' count depends on the scene's objects and lights: the node checks the
        // bytes itself before allocating; here, the per-pixel classes and row buffers.
        let px = inputs[0].and_then(|s| s.pixels()).unwrap_or(0);
        let dropped = inputs[0].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        relume_core::MemoryEstimate { outputs: vec![None, Some(relume_core::PortSize::bytes(32)), dropped], working: px * 12 }
    }

    fn shard(&self, i: &TransferPrecomputeIn) -> Result<ShardSpec, NodeError> {
        terms_checked(i.scene, i.basis, relume_core::limits::default_budget())?;
        Ok(row_spec(i.scene.camera.width, i.scene.camera.height))
    }

    fn run_items(&self, i: &TransferPrecomputeIn, rows: Range<u64>, cx: &RunCtx) -> Result<TransferRows, NodeError> {
        precompute_rows(i.scene, i.accel, i.basis, self.paths, rows.start as usize..rows.end as usize, Some(cx))
    }

    fn gather(&self, i: &TransferPrecomputeIn, parts: &[&TransferRows], cx: &RunCtx) -> Result<TransferPrecomputeOut, NodeError> {
        let (transfer, dropped_share, [rays, dropped, mixed]) = gather_transfer(i.scene, i.basis, self.paths, parts, cx.memory_budget())?;
        let set = scene_terms(i.scene, i.basis.bases());
        cx.metric("images", set.terms.len() as f64);
        cx.metric("images_grey", set.count(Channels::Grey) as f64);
        cx.metric("images_rgb", set.count(Channels::Rgb) as f64);
        cx.metric("images_emitted", set.emitted() as u8 as f64);
        cx.metric("dynamic_objects", transfer.groups.len() as f64);
        cx.metric("bytes", (transfer.data.len() * 4) as f64);
        cx.metric("rays", rays as f64);
        cx.metric("hemisphere_rays_per_pixel", (self.paths.spp as u64 * self.paths.bounce_rays as u64) as f64);
        cx.metric("dropped_samples", dropped as f64);
        cx.metric("mixed_pixels", mixed as f64);
        for l in &set.left_out {
            cx.note(l.clone());
        }
        if !i.scene.has_lights() {
            cx.note("the scene has no light: every image is black");
        }
        Ok(TransferPrecomputeOut { transfer, paths: self.paths, dropped: dropped_share })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terms::{Second, Term};
    use crate::test_support::{precompute, scene};
    use relume_base::brdf_space::test_support::{basis, space};
    use relume_base::testing::{cancels_midway, i};
    use relume_base::types::{Material, ObjectMaterials};
    use relume_core::Value;

    fn metric(e: &relume_core::cache::CacheEntry, name: &str) -> f64 {
        e.metrics.iter().find(|m| m.0 == name).unwrap_or_else(|| panic!("no metric {name}")).1
    }

    #[test]
    fn the_scene_gets_the_images_its_objects_and_lights_need_and_the_report_counts_them() {
        // Two dynamic objects ("glossy" = spheres a + b, and c), fixed floor and lamp, one light
        // colour; N_b = 4 (S = 3): grey S + D S² = 21, RGB 2 + D + S + 2DS = 19.
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 4);
        let (_, _, t, e) = precompute(&scene(8), &b, [2, 1, 2, 1]);
        assert_eq!((metric(&e, "images_grey"), metric(&e, "images_rgb")), (21.0, 19.0));
        assert_eq!(t.groups, vec!["glossy".to_string(), "c".to_string()]);
        assert_eq!(t.stride as usize % 8, 0);
        assert_eq!(t.data.len(), 64 * t.stride as usize);
        assert_eq!(metric(&e, "bytes"), (t.data.len() * 4) as f64);
        assert!(e.notes.is_empty(), "nothing left out: {:?}", e.notes);
        // Every class appears: the spheres, sphere c and the fixed floor.
        for c in 0..3 {
            assert!(t.class.contains(&c), "class {c} in {:?}", t.class);
        }
        assert!(t.data.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn the_dropped_image_holds_each_pixels_share_of_samples_on_other_objects() {
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 4);
        let spp = 8;
        let (_, _, t, e) = precompute(&scene(16), &b, [spp, 1, 1, 1]);
        let dropped = e.outputs[2].get::<Image>().unwrap();
        assert_eq!((dropped.width, dropped.height), (t.width as usize, t.height as usize));
        let shares: Vec<f32> = dropped.pixels.iter().map(|p| p[0]).collect();
        // Every share is a whole number of samples over spp, under a half (the pixel's class
        // holds the most samples), and the counts add up to the report's.
        assert!(shares.iter().all(|&s| (s * spp as f32 - (s * spp as f32).round()).abs() < 1e-5 && s < 0.5 + 1e-6), "{shares:?}");
        let mixed = shares.iter().filter(|&&s| s > 0.0).count();
        assert_eq!(mixed as f64, metric(&e, "mixed_pixels"));
        let samples: f32 = shares.iter().map(|s| s * spp as f32).sum();
        assert_eq!(samples.round() as f64, metric(&e, "dropped_samples"));
        assert!(mixed > 0 && mixed < shares.len() / 2, "{mixed} of {} pixels mixed", shares.len());
        // A mixed pixel lies on an edge between classes: a neighbour took another class.
        let w = t.width as usize;
        for p in (0..shares.len()).filter(|&p| shares[p] > 0.0) {
            let (x, y) = ((p % w) as i64, (p / w) as i64);
            let other = (-1..=1i64).flat_map(|dy| (-1..=1i64).map(move |dx| (x + dx, y + dy))).any(|(a, b)| {
                (0..w as i64).contains(&a) && (0..t.height as i64).contains(&b) && t.class[b as usize * w + a as usize] != t.class[p]
            });
            let border = x == 0 || y == 0 || x == w as i64 - 1 || y == t.height as i64 - 1;
            assert!(other || border, "pixel ({x}, {y}) is mixed inside one class");
        }
    }

    #[test]
    fn without_fixed_objects_no_fixed_terms_are_stored_and_the_report_says_so() {
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 4);
        let mut s = scene(8);
        for o in &mut s.objects {
            if o.emission == glam::Vec3::ZERO {
                o.dynamic = true;
            }
        }
        // The lamp stays fixed (an emitter cannot be dynamic): drop it, the point light remains.
        let lamp = s.objects.iter().position(|o| o.name == "lamp").unwrap();
        let tris = s.objects[lamp].triangles.clone();
        s.triangles.truncate(tris.start as usize);
        s.tri_object.truncate(tris.start as usize);
        s.objects.truncate(lamp);
        let (_, _, t, e) = precompute(&s, &b, [1, 1, 1, 1]);
        assert!(t.terms.iter().all(|t| !matches!(t.0, Term::Bounce(_, Second::Fixed))));
        assert!(e.notes.iter().any(|n| n.contains("no fixed-material object")), "{:?}", e.notes);
        assert!(!t.class.contains(&0) || t.class.iter().all(|&c| c <= 3));
    }

    #[test]
    fn a_light_seen_directly_is_averaged_over_every_camera_sample_so_its_edge_is_antialiased() {
        // Look up at the lamp (emission 4, facing down): its edge pixels mix lamp and background
        // samples of other classes, and the emitted image counts every sample, not the kept ones.
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let mut s = scene(24);
        s.camera.target = glam::Vec3::new(0.0, 1.5, 0.0);
        let spp = 8;
        let (_, m, t, e) = precompute(&s, &b, [spp, 1, 1, 1]);
        assert!(!e.notes.iter().any(|n| n.contains("no emitter")), "{:?}", e.notes);
        let emitted = t.image(t.terms.iter().position(|x| x.0 == Term::Emitted).expect("an emitted image"));
        let k: Vec<f32> = emitted.pixels.iter().map(|p| p[0] / 4.0 * spp as f32).collect();
        // Every value is (samples on the lamp) × 4 / spp, in [0, spp].
        assert!(k.iter().all(|k| (k - k.round()).abs() < 1e-4 && (0.0..=spp as f32).contains(k)), "{k:?}");
        let full = k.iter().filter(|k| k.round() == spp as f32).count();
        let partial = k.iter().filter(|k| k.round() > 0.0 && k.round() < spp as f32).count();
        assert!(full > 4 && partial > 4, "lamp pixels {full}, edge pixels {partial}");
        // The relit image carries the fraction: on an edge pixel that is not the lamp's class
        // the light still shows.
        let relit = super::super::relight_pixels::relight(&t, &m, None).unwrap();
        let lamp_class_not_kept = (0..t.pixels()).filter(|&p| k[p].round() > 0.0 && k[p].round() < spp as f32 / 2.0);
        for p in lamp_class_not_kept {
            assert!(relit.pixels[p][0] >= k[p] * 4.0 / spp as f32 * 0.999, "pixel {p}: {:?}", relit.pixels[p]);
        }
    }

    #[test]
    fn bands_gather_to_the_same_bytes_as_one_run() {
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 3);
        let s = scene(12);
        let accel = relume_base::types::Accel::build(&s, relume_base::types::accel::BuildQuality::Fast);
        let c = PathCounts { spp: 2, light_samples: 1, bounce_rays: 2, bounce_light_samples: 1, seed: 9 };
        let whole = precompute_rows(&s, &accel, &b, c, 0..12, None).unwrap();
        let parts = [0..5, 5..6, 6..12].map(|r| precompute_rows(&s, &accel, &b, c, r, None).unwrap());
        let (t1, d1, c1) = gather_transfer(&s, &b, c, &[&whole], u64::MAX).unwrap();
        let (t2, d2, c2) = gather_transfer(&s, &b, c, &[&parts[2], &parts[0], &parts[1]], u64::MAX).unwrap();
        assert_eq!((t1, d1, c1), (t2, d2, c2));
        assert!(gather_transfer(&s, &b, c, &[&parts[0]], u64::MAX).is_err(), "missing rows are an error");
    }

    #[test]
    fn a_transfer_over_the_limit_is_refused_before_allocating() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 6);
        let mut s = scene(8);
        s.camera.width = 40_000;
        s.camera.height = 40_000;
        let e = terms_checked(&s, &b, u64::MAX).unwrap_err();
        assert!(matches!(e, NodeError::OverLimit { .. }), "{e}");
        assert!(e.to_string().contains("GiB"), "{e}");
        // The run's --memory-budget lowers the limit: an 8² transfer (144 floats a pixel: 36 KiB)
        // fits in 1 MiB, not in 16 KiB, and a run refuses it before tracing anything.
        let small = scene(8);
        assert!(terms_checked(&small, &b, 1 << 20).is_ok());
        let e = terms_checked(&small, &b, 16 << 10).unwrap_err();
        assert!(matches!(e, NodeError::OverLimit { .. }) && e.to_string().contains("16.0 KiB"), "{e}");
        let accel = relume_base::types::Accel::build(&small, relume_base::types::accel::BuildQuality::Fast);
        let cancel = relume_core::CancelToken::new();
        let cx = RunCtx::new("t", &cancel, None).with_memory_budget(16 << 10);
        let c = PathCounts { spp: 1, light_samples: 1, bounce_rays: 1, bounce_light_samples: 1, seed: 1 };
        assert!(matches!(precompute_rows(&small, &accel, &b, c, 0..8, Some(&cx)), Err(NodeError::OverLimit { .. })));
    }

    #[test]
    fn dielectrics_and_dynamic_emitters_are_clear_errors() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let mut s = scene(8);
        s.objects[3].material = Material::Dielectric { ior: 1.5, medium: None };
        assert!(terms_checked(&s, &b, u64::MAX).unwrap_err().to_string().contains("\"floor\" is a dielectric"));
        let mut s = scene(8);
        let lamp = s.objects.iter().position(|o| o.name == "lamp").unwrap();
        s.objects[lamp].dynamic = true;
        assert!(terms_checked(&s, &b, u64::MAX).unwrap_err().to_string().contains("\"lamp\" is dynamic and emits"));
        // A dynamic object's Kd map is taken (multiplied into its diffuse images); a Ks or
        // exponent map needs the spatially varying extension's nodes; a textured fixed object
        // is rendered with its texture.
        let mut s = scene(8);
        s.uvs = vec![glam::Vec2::ZERO; s.positions.len()];
        let grey = relume_base::types::Texture::new(1, 1, vec![glam::Vec3::splat(0.5)]).unwrap();
        s.objects[2].maps.kd = Some(grey.clone());
        assert!(terms_checked(&s, &b, u64::MAX).is_ok());
        s.objects[2].maps.exponent = Some(grey.clone());
        let e = terms_checked(&s, &b, u64::MAX).unwrap_err().to_string();
        assert!(e.contains("\"c\" is dynamic and has a Ks or exponent map") && e.contains("SvTransferPrecompute"), "{e}");
        *s.objects[2].maps = Default::default();
        s.objects[3].maps.kd = Some(grey);
        assert!(terms_checked(&s, &b, u64::MAX).is_ok());
    }

    #[test]
    fn no_light_gives_black_images_and_a_note() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let mut s = scene(6);
        s.lights.clear();
        s.objects.iter_mut().for_each(|o| o.emission = glam::Vec3::ZERO);
        let (_, _, t, e) = precompute(&s, &b, [1, 1, 1, 1]);
        assert!(t.data.iter().all(|v| *v == 0.0));
        assert!(e.notes.iter().any(|n| n.contains("no light")), "{:?}", e.notes);
    }

    #[test]
    fn the_node_stops_midway_when_cancelled() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let s = scene(16);
        let accel = relume_base::types::Accel::build(&s, relume_base::types::accel::BuildQuality::Fast);
        let p = [("spp", i(4)), ("bounce_rays", i(8))];
        cancels_midway::<TransferPrecompute>(&p, vec![Value::new(s), Value::new(accel), Value::new(b)]);
        let _ = ObjectMaterials::default();
    }
}
