//! The spatially varying precompute ([S] 4.2.2), streamed so that no group's uncompressed
//! block of n² sub-region images is ever held (21 GiB in the thesis' setting):
//!
//! 1. Pass 1 traces every pixel's paths once (`paths`, `SvShade`): the direct images, the
//!    light seen directly and the bounce onto fixed objects are kept whole; each group's
//!    per-pixel vector over the sub-regions (sparse: a pixel's hemisphere rays reach few
//!    sub-regions), one column per colour channel, is added to that group's Gram matrix
//!    (`math::streamed_pca`), groups in parallel, pixels in row order.
//! 2. Each Gram matrix is decomposed: the uncentred PCA along r1 keeps `pca_keep` of the n²
//!    components (12.5 %: 128 of 1024), weights a[r][j] = σ_j u_j[r].
//! 3. Pass 2 traces the same seeded paths again and projects each pixel's vectors on the kept
//!    components: the basis images, for as many groups at once as the memory budget holds
//!    (more rounds re-trace).
//! 4. Each basis image (per channel) is median-filtered within its object (the object-id
//!    image: the filter never mixes objects but crosses sub-region borders), padded by edge
//!    repetition to a power-of-two square, Haar-transformed (orthonormal non-standard) and
//!    its `haar_keep` largest coefficients kept (13.3 %).
//!
//! Everything is seeded and reduced in a fixed order: the same bytes on any thread count.

use super::paths::Paths;
use super::shades::{check_scene_sv, has_emitters};
use super::sv_shade::{scene_sv_terms, SvLayout, SvShade};
use super::sv_terms::SvTerms;
use crate::types::{PathCounts, SparsePlane, SvBlock, SvTransfer};
use relume_base::image::median_filter::median_plane_by_class;
use relume_base::math::haar;
use relume_base::math::streamed_pca::{Gram, StreamedPca};
use relume_base::types::accel::Accel;
use relume_base::types::{BrdfBasis, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{NodeError, RunCtx};

/// How the SV precompute splits and compresses.
#[derive(Clone, Copy, Debug)]
pub struct SvSettings {
    pub sub_regions: usize,
    pub indirect_bases: usize,
    /// Fraction of the n² PCA components kept per group.
    pub pca_keep: f64,
    /// Fraction of the padded square's Haar coefficients kept per basis image and channel.
    pub haar_keep: f64,
    /// Radius of the median filter's window (0: none).
    pub median_radius: usize,
}

/// What the precompute measured.
#[derive(Clone, Debug, Default)]
pub struct SvStats {
    pub rays: u64,
    pub dropped: u64,
    pub mixed: u64,
    /// Passes over the pixels' paths (1 + the rounds of pass 2).
    pub passes: u32,
    pub components: usize,
    /// Energy of every group's sub-region images, and what the PCA and the Haar truncation
    /// left out of it.
    pub energy: f64,
    pub pca_lost: f64,
    pub haar_lost: f64,
    pub uncompressed_bytes: u64,
}

/// Bytes the precompute will hold, by part.
#[derive(Clone, Copy, Debug)]
pub struct SvMemory {
    /// Whole images, classes, UVs, the Gram matrices and the compressed output.
    pub fixed: u64,
    /// One group's basis images in pass 2 and the buffers compressing them.
    pub per_group: u64,
    pub components: usize,
}

/// Rows traced together between two reductions (bounds the sparse vectors held).
const BAND_ROWS: usize = 8;

pub fn components(settings: &SvSettings) -> usize {
    let n2 = settings.sub_regions * settings.sub_regions;
    ((settings.pca_keep * n2 as f64).ceil() as usize).clamp(1, n2)
}

/// The bytes an SV precompute of `sv` at `w × h` holds (see `SvMemory`).
pub fn memory(sv: &SvTerms, settings: &SvSettings, w: usize, h: usize, emitters: bool) -> SvMemory {
    let t = sv.traits;
    let px = (w * h) as u64;
    let n2 = (t.sub_regions * t.sub_regions) as u64;
    let k = components(settings) as u64;
    let side = haar::padded_side(w, h) as u64;
    let whole = (t.direct_bases + emitters as usize + if t.fixed_objects { t.indirect_bases } else { 0 }) as u64 * px * 12;
    let grams = sv.groups.len() as u64 * n2 * (n2 + 1) / 2 * 8;
    let kept = ((settings.haar_keep * (side * side) as f64).ceil() as u64).max(1);
    let output = sv.groups.len() as u64 * (k * 3 * kept * 8 + n2 * k * 4);
    let threads = rayon::current_num_threads() as u64;
    SvMemory { fixed: whole + px * 16 + grams + output, per_group: k * px * 12 + threads * side * side * 12, components: k as usize }
}

/// One row's paths: the whole images' floats (`wholes` RGB per pixel), classes, UVs, object
/// ids and, per pixel and group, the sub-regions reached with their RGB values.
struct Row {
    whole: Vec<f32>,
    class: Vec<u32>,
    uv: Vec<[f32; 2]>,
    object: Vec<u32>,
    /// `[x * groups + q]`: (sub-region, RGB) in ascending sub-region order.
    cols: Vec<Vec<(u32, [f64; 3])>>,
    counters: [u64; 3],
}

struct Tracer<'a> {
    paths: Paths<'a, SvShade<'a>>,
    layout: SvLayout,
    groups: usize,
    n2: usize,
    wholes: usize,
    width: usize,
}

impl Tracer<'_> {
    fn row(&self, y: usize) -> Row {
        let (w, l) = (self.width, &self.layout);
        let mut acc = vec![[0.0f64; 3]; l.accumulators];
        let mut row = Row {
            whole: vec![0.0; w * self.wholes * 3],
            class: vec![0; w],
            uv: vec![[0.0; 2]; w],
            object: vec![0; w],
            cols: Vec::with_capacity(w * self.groups),
            counters: [0; 3],
        };
        // Whole images in accumulator order: direct, emitted, fixed bounce.
        let whole_at: Vec<usize> = (0..l.direct).chain(l.emitted).chain(l.fixed.map_or(0..0, |f| f..l.groups)).collect();
        for x in 0..w {
            acc.iter_mut().for_each(|a| *a = [0.0; 3]);
            let st = self.paths.pixel(x, y, &mut acc, &mut |_| {});
            (row.class[x], row.uv[x], row.object[x]) = (st.class, st.uv, st.object);
            row.counters[0] += st.rays;
            row.counters[1] += st.dropped as u64;
            row.counters[2] += (st.dropped > 0) as u64;
            for (i, &a) in whole_at.iter().enumerate() {
                let o = (x * self.wholes + i) * 3;
                row.whole[o..o + 3].copy_from_slice(&acc[a].map(|v| v as f32));
            }
            for q in 0..self.groups {
                let base = l.groups + q * self.n2;
                let col = acc[base..base + self.n2].iter().enumerate().filter(|(_, a)| **a != [0.0; 3]).map(|(r, a)| (r as u32, *a));
                row.cols.push(col.collect());
            }
        }
        row
    }
}

/// One column (channel `c` of a pixel's sparse vector) as indices and values.
fn channel(col: &[(u32, [f64; 3])], c: usize, index: &mut Vec<u32>, value: &mut Vec<f64>) {
    index.clear();
    value.clear();
    for (r, v) in col {
        if v[c] != 0.0 {
            index.push(*r);
            value.push(v[c]);
        }
    }
}

/// Runs the SV precompute (see the module doc); refuses before allocating what would not fit
/// in `cx`'s memory budget.
pub fn sv_precompute(
    scene: &Scene,
    accel: &Accel,
    basis: &BrdfBasis,
    counts: PathCounts,
    settings: &SvSettings,
    cx: &RunCtx,
) -> Result<(SvTransfer, SvStats), NodeError> {
    check_scene_sv(scene, basis.bases()).map_err(|m| NodeError::input("scene", m))?;
    let sv = scene_sv_terms(scene, settings.sub_regions, basis.bases(), settings.indirect_bases)
        .map_err(|m| NodeError::param("indirect_bases", m))?;
    let (w, h) = (scene.camera.width, scene.camera.height);
    let emitters = has_emitters(scene);
    let mem = memory(&sv, settings, w, h, emitters);
    let budget = cx.memory_budget();
    let rounds_fit = budget.saturating_sub(mem.fixed) / mem.per_group.max(1);
    if rounds_fit == 0 {
        return Err(NodeError::OverLimit {
            param: None,
            msg: format!(
                "{} groups of {} sub-region images at {w} × {h} ({} uncompressed) would hold {} plus {} per group being compressed, over the {} budget: lower the resolution, the sub-regions or pca_keep",
                sv.groups.len(),
                settings.sub_regions * settings.sub_regions,
                fmt_bytes(sv.uncompressed_bytes(w, h)),
                fmt_bytes(mem.fixed),
                fmt_bytes(mem.per_group),
                fmt_bytes(budget)
            ),
        });
    }
    let per_round = (rounds_fit as usize).min(sv.groups.len()).max(1);
    let shade = SvShade::new(scene, basis, &sv);
    let (layout, slots) = SvLayout::new(&sv, emitters);
    let t = sv.traits;
    let n2 = t.sub_regions * t.sub_regions;
    let wholes = t.direct_bases + emitters as usize + if t.fixed_objects { t.indirect_bases } else { 0 };
    let tracer = Tracer { paths: Paths::new(scene, accel, counts, &shade, &slots), layout, groups: sv.groups.len(), n2, wholes, width: w };
    let bands: Vec<std::ops::Range<usize>> = (0..h).step_by(BAND_ROWS).map(|a| a..(a + BAND_ROWS).min(h)).collect();
    let rounds = sv.groups.len().div_ceil(per_round).max(1);
    let total_passes = 1 + rounds;
    let mut stats = SvStats {
        passes: total_passes as u32,
        components: mem.components,
        uncompressed_bytes: sv.uncompressed_bytes(w, h),
        ..Default::default()
    };

    // Pass 1: whole images, classes, Gram matrices.
    let mut whole = vec![0.0f32; w * h * wholes * 3];
    let (mut class, mut uv, mut object) = (vec![0u32; w * h], vec![[0.0f32; 2]; w * h], vec![0u32; w * h]);
    let mut grams: Vec<Gram> = (0..sv.groups.len()).map(|_| Gram::new(n2)).collect::<Result<_, _>>()?;
    for (b, band) in bands.iter().enumerate() {
        let pass = |b: usize| b as f64 / bands.len() as f64 / total_passes as f64;
        cx.phase(pass(b), pass(b + 1));
        let rows = cx.par_map(band.len(), |i| tracer.row(band.start + i))?;
        for (i, row) in rows.iter().enumerate() {
            let y = band.start + i;
            whole[y * w * wholes * 3..(y + 1) * w * wholes * 3].copy_from_slice(&row.whole);
            class[y * w..(y + 1) * w].copy_from_slice(&row.class);
            uv[y * w..(y + 1) * w].copy_from_slice(&row.uv);
            object[y * w..(y + 1) * w].copy_from_slice(&row.object);
            stats.rays += row.counters[0];
            stats.dropped += row.counters[1];
            stats.mixed += row.counters[2];
        }
        cx.par_chunks_mut(&mut grams, 1, |q, g| {
            let (mut index, mut value) = (Vec::new(), Vec::new());
            for row in &rows {
                for x in 0..w {
                    for c in 0..3 {
                        channel(&row.cols[x * sv.groups.len() + q], c, &mut index, &mut value);
                        g[0].add(&index, &value);
                    }
                }
            }
        })?;
    }

    // The PCA of each group along its sub-regions.
    let pcas: Vec<StreamedPca> = cx.par_try_map(grams.len(), |q| grams[q].decompose(mem.components))?;
    stats.energy = grams.iter().map(Gram::trace).sum();
    stats.pca_lost = (stats.energy - pcas.iter().flat_map(|p| &p.sigma).map(|s| s * s).sum::<f64>()).max(0.0);
    drop(grams);

    // Pass 2 in rounds of groups: basis images, then their compression.
    let side = haar::padded_side(w, h);
    let keep = ((settings.haar_keep * (side * side) as f64).ceil() as usize).max(1);
    let mut blocks = Vec::with_capacity(sv.groups.len());
    for round in 0..rounds {
        let qs = round * per_round..((round + 1) * per_round).min(sv.groups.len());
        let span = |f: f64| (1.0 + round as f64 + f) / total_passes as f64;
        // images[local q][j][p * 3 + c]
        let mut images: Vec<Vec<Vec<f32>>> = qs.clone().map(|q| vec![vec![0.0f32; w * h * 3]; pcas[q].components()]).collect();
        for (b, band) in bands.iter().enumerate() {
            cx.phase(span(0.6 * b as f64 / bands.len() as f64), span(0.6 * (b + 1) as f64 / bands.len() as f64));
            let rows = cx.par_map(band.len(), |i| {
                let row = tracer.row(band.start + i);
                let (mut index, mut value) = (Vec::new(), Vec::new());
                qs.clone()
                    .map(|q| {
                        let k = pcas[q].components();
                        let mut out = vec![0.0f64; w * 3 * k];
                        let mut b = vec![0.0f64; k];
                        for x in 0..w {
                            for c in 0..3 {
                                channel(&row.cols[x * sv.groups.len() + q], c, &mut index, &mut value);
                                pcas[q].project(&index, &value, &mut b);
                                for (j, v) in b.iter().enumerate() {
                                    out[(j * w + x) * 3 + c] = *v;
                                }
                            }
                        }
                        out
                    })
                    .collect::<Vec<_>>()
            })?;
            for (i, row) in rows.iter().enumerate() {
                let y = band.start + i;
                for (lq, out) in row.iter().enumerate() {
                    for (j, img) in images[lq].iter_mut().enumerate() {
                        let src = &out[j * w * 3..(j + 1) * w * 3];
                        img[y * w * 3..(y + 1) * w * 3].iter_mut().zip(src).for_each(|(d, s)| *d = *s as f32);
                    }
                }
            }
        }
        cx.phase(span(0.6), span(1.0));
        for (lq, q) in qs.clone().enumerate() {
            let k = pcas[q].components();
            let planes = cx.par_map(k * 3, |i| {
                let (j, c) = (i / 3, i % 3);
                let plane: Vec<f32> = images[lq][j].iter().skip(c).step_by(3).copied().collect();
                let filtered =
                    if settings.median_radius > 0 { median_plane_by_class(&plane, &object, w, h, settings.median_radius) } else { plane };
                let (mut sq, n) = haar::pad(&filtered, w, h);
                haar::forward(&mut sq, n);
                let total: f64 = sq.iter().map(|v| (*v as f64).powi(2)).sum();
                let s = haar::keep_largest(&sq, n, keep);
                let kept: f64 = s.value.iter().map(|v| (*v as f64).powi(2)).sum();
                (SparsePlane { index: s.index, value: s.value }, total - kept)
            })?;
            images[lq] = Vec::new();
            // The lost energy in image units: basis images carry unit norm; weights scale them.
            let sigma2: Vec<f64> = pcas[q].sigma.iter().map(|s| s * s).collect();
            stats.haar_lost += planes.iter().enumerate().map(|(i, p)| p.1 * sigma2[i / 3]).sum::<f64>();
            let g = sv.groups[q];
            let weights = (0..n2).flat_map(|r| (0..k).map(move |j| (r, j))).map(|(r, j)| pcas[q].coefficient(r, j) as f32).collect();
            blocks.push(SvBlock {
                first: match g.first {
                    super::terms::First::Merged => 0,
                    super::terms::First::Specular(k) => k,
                },
                object: g.object,
                second: g.second,
                components: k as u32,
                weights,
                images: planes.into_iter().map(|p| p.0).collect(),
            });
        }
    }

    // The whole images, basis-major.
    let plane_of =
        |i: usize| -> Vec<f32> { (0..w * h).flat_map(|p| whole[(p * wholes + i) * 3..(p * wholes + i) * 3 + 3].iter().copied()).collect() };
    let direct: Vec<f32> = (0..t.direct_bases).flat_map(plane_of).collect();
    let emitted = if emitters { plane_of(t.direct_bases) } else { vec![] };
    let fixed: Vec<f32> = if t.fixed_objects {
        (0..t.indirect_bases).flat_map(|f| plane_of(t.direct_bases + emitters as usize + f)).collect()
    } else {
        vec![]
    };
    let transfer = SvTransfer {
        width: w as u32,
        height: h as u32,
        groups: scene.dynamic_groups().into_iter().map(|g| g.0).collect(),
        sub_regions: t.sub_regions as u32,
        direct_bases: t.direct_bases as u32,
        indirect_bases: t.indirect_bases as u32,
        counts,
        class,
        uv,
        direct,
        emitted,
        fixed,
        side: side as u32,
        blocks,
    };
    Ok((transfer, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::sv_scene;
    use relume_base::brdf_space::test_support::{basis, space};
    use relume_core::CancelToken;

    pub(crate) fn settings(n: usize, pca_keep: f64, haar_keep: f64, median_radius: usize) -> SvSettings {
        SvSettings { sub_regions: n, indirect_bases: 2, pca_keep, haar_keep, median_radius }
    }

    fn run(scene: &Scene, b: &BrdfBasis, s: &SvSettings, budget: Option<u64>) -> Result<(SvTransfer, SvStats), NodeError> {
        let accel = Accel::build(scene, relume_base::types::accel::BuildQuality::Fast);
        let c = PathCounts { spp: 2, light_samples: 1, bounce_rays: 4, bounce_light_samples: 1, seed: 3 };
        let cancel = CancelToken::new();
        let cx = RunCtx::new("sv", &cancel, None);
        let cx = match budget {
            Some(b) => cx.with_memory_budget(b),
            None => cx,
        };
        sv_precompute(scene, &accel, b, c, s, &cx)
    }

    #[test]
    fn the_compressed_transfer_is_the_same_on_any_thread_count_and_in_any_number_of_rounds() {
        let (b, _) = basis(&space(6, 6, 12, 12, 1.0, 100.0), 3);
        let scene = sv_scene(10);
        let s = settings(3, 0.5, 0.05, 0);
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| run(&scene, &b, &s, None).unwrap());
        let tight = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap().install(|| {
            let sv = scene_sv_terms(&scene, 3, 3, 2).unwrap();
            let m = memory(&sv, &s, 10, 10, true);
            run(&scene, &b, &s, Some(m.fixed + m.per_group)).unwrap()
        });
        assert_eq!(one.1.passes, 2, "one round of pass 2");
        assert_eq!(tight.1.passes, 1 + 6, "two dynamic objects × 3 groups, one group a round");
        assert_eq!(one.0, tight.0);
        let t = &one.0;
        assert_eq!(t.blocks.len(), 6);
        assert_eq!(t.side, 16);
        assert_eq!((t.direct.len(), t.fixed.len(), t.emitted.len()), (3 * 300, 2 * 300, 300));
        // At most 5 of 9 components (few paths: the blocks are of lower rank), at most 5 % of
        // 256 coefficients (13) per basis image and channel.
        let shape: Vec<(u32, usize)> =
            t.blocks.iter().map(|b| (b.components, b.images.iter().map(|p| p.index.len()).max().unwrap_or(0))).collect();
        assert!(shape.iter().all(|&(k, n)| (1..=5).contains(&k) && (1..=13).contains(&n)), "{shape:?}");
        // Energy is lost to the truncations, never more than there is.
        let st = &one.1;
        assert!(st.energy > 0.0 && st.pca_lost >= 0.0 && st.haar_lost > 0.0 && st.pca_lost + st.haar_lost < st.energy, "{st:?}");
        // Pixels on the spheres carry their UVs.
        assert!(t.class.iter().zip(&t.uv).any(|(&c, uv)| c > 0 && uv[0] > 0.0 && uv[1] > 0.0));
    }

    #[test]
    fn a_precompute_over_the_budget_is_refused_before_tracing_with_the_estimate() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let e = run(&sv_scene(8), &b, &settings(4, 0.25, 0.2, 1), Some(4 << 10)).unwrap_err();
        assert!(matches!(e, NodeError::OverLimit { .. }), "{e}");
        let msg = e.to_string();
        assert!(msg.contains("6 groups of 16 sub-region images") && msg.contains("uncompressed") && msg.contains("4.0 KiB"), "{msg}");
        // The thesis' setting: 21 GiB uncompressed, but a group at a time holds far less.
        let sv = scene_sv_terms(&sv_scene(8), 32, 6, 4).unwrap();
        let m = memory(
            &sv,
            &SvSettings { sub_regions: 32, indirect_bases: 4, pca_keep: 0.125, haar_keep: 0.133, median_radius: 1 },
            512,
            512,
            true,
        );
        assert_eq!(m.components, 128);
        assert!(m.per_group < 1 << 30 && m.fixed < 2 << 30, "{m:?}");
    }

    #[test]
    fn a_dynamic_object_without_uvs_is_an_input_error_naming_it() {
        let (b, _) = basis(&space(4, 4, 8, 6, 1.0, 100.0), 3);
        let mut s = sv_scene(6);
        s.uvs.clear();
        let e = run(&s, &b, &settings(2, 1.0, 1.0, 0), None).unwrap_err().to_string();
        assert!(e.contains("\"glossy\" has no UVs"), "{e}");
    }
}
