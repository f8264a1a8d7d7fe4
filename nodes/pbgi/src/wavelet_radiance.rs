//! A surfel's outgoing radiance as wavelets (wavelet PBGI, [P] 4.4; docs/PIPELINES.md pipeline 4
//! step 8): the radiance it sends in every direction, on a world-aligned cube map of side n
//! (6 × 32² by default, 6 × 128² for `ring`), through the non-standard Haar transform per face
//! (`math::cube_haar`, which says why that variant) and the thesis' non-linear
//! approximation by threshold. Glossy surfels send a lobe, so their points carry what classic
//! PBGI's single diffuse radiance cannot: glossy inter-reflection and caustics.
//!
//! Directions below the surfel's tangent plane send nothing. The incident light comes as
//! samples (world direction toward the light, weight = radiance × cos θi / pdf / count), so
//! delta lights are one sample each and extended lights many; each texel's radiance is
//! Σ f(ωo, ωi) × weight with f the material's BRDF in the surfel's frame.

use super::texel_cache;
use crate::types::{CodedWavelets, PointTree, PointWavelets};
use glam::Vec3;
use relume_base::brdf;
use relume_base::math::cube_haar::{texel_terms, CubeHaar, SparseCubeHaar};
use relume_base::math::cubemap::CubeMap;
use relume_base::math::cubemap::{texel_directions, texel_of_side, texel_solid_angles};
use relume_base::math::frame::Frame;
use relume_base::math::tree_coding::{CodedTree, Threshold, TreeShape};
use relume_base::types::Material;

/// The surfel's outgoing radiance on a cube map of side `n`: texel k holds the radiance
/// toward its centre direction.
pub fn outgoing_cube(material: &Material, normal: Vec3, incident: &[(Vec3, Vec3)], n: usize) -> CubeMap {
    let material = &band_limited(material, n);
    let frame = Frame::from_normal(normal);
    let local: Vec<(Vec3, Vec3)> = incident.iter().map(|&(wi, w)| (frame.to_local(wi), w)).filter(|(wi, _)| wi.z > 0.0).collect();
    let mut map = CubeMap::constant(n, Vec3::ZERO);
    for (t, &d) in map.texels.iter_mut().zip(texel_directions(n).iter()) {
        let wo = frame.to_local(d);
        if wo.z <= 0.0 {
            continue;
        }
        *t = local.iter().map(|&(wi, w)| brdf::eval(material, wo, wi) * w).sum();
    }
    map
}

/// The material as a side-`n` map can hold it. A texel holds the radiance toward its centre,
/// so a lobe narrower than a texel is either missed or hit at its peak, and then the texel
/// sends many times the lobe's energy (measured: Blinn-Phong s = 10⁴ at 16² sent 1.20× the
/// irradiance it received, kd + ks = 1). Lobes are widened until the half-vector angle at
/// half maximum, θ½, is at least 1/n rad (the reflected lobe then spans at least two texels
/// of 2/n rad at half maximum): Blinn-Phong's cos^s θ½ = ½ gives s ≤ 2 ln 2 · n² (355 at 16²,
/// 1,420 at 32², 22,713 at 128²); Beckmann's tan θ½ ≈ m √(ln 2) gives roughness
/// m ≥ 1.2 / n. Wider lobes, and other materials, are returned as they are.
pub fn band_limited(m: &Material, n: usize) -> Material {
    let n = n as f32;
    match *m {
        Material::BlinnPhong { kd, ks, exponent } => {
            Material::BlinnPhong { kd, ks, exponent: exponent.min(2.0 * std::f32::consts::LN_2 * n * n) }
        }
        Material::CookTorrance { kd, ks, roughness, f0 } => Material::CookTorrance { kd, ks, roughness: roughness.max(1.2 / n), f0 },
        other => other,
    }
}

/// `outgoing_cube` through the Haar transform, keeping the coefficients of magnitude at
/// least `threshold` ([P]: 0.002).
pub fn outgoing_wavelets(material: &Material, normal: Vec3, incident: &[(Vec3, Vec3)], n: usize, threshold: f32) -> SparseCubeHaar {
    CubeHaar::forward(&outgoing_cube(material, normal, incident, n)).keep_above(threshold)
}

/// What a surfel sends per unit of its area toward each direction: the outgoing radiance
/// times the cosine to its normal, J(ω) = L(ω) max(0, n·ω) (the texel's radiant intensity
/// per unit area). This is what the point tree averages: a node's area-weighted mean of J
/// times its area is the group's radiant intensity I(ω) = Σ A_j cos θ_j L_j(ω), so a
/// receiver that divides by the node's projected area toward it gets the radiance the group
/// shows, whatever mix of normals it holds. (Averaging L itself, as [P] 4.5 does, counts
/// the points facing away as dark and halves what a curved group sends.) J also falls to 0
/// at the horizon instead of stepping, which costs fewer wavelet terms.
pub fn outgoing_intensity(material: &Material, normal: Vec3, incident: &[(Vec3, Vec3)], n: usize) -> CubeMap {
    let mut map = outgoing_cube(material, normal, incident, n);
    let nn = normal.normalize_or(Vec3::Z);
    for (t, d) in map.texels.iter_mut().zip(texel_directions(n).iter()) {
        *t *= d.dot(nn).max(0.0);
    }
    let irradiance: Vec3 = incident.iter().filter(|(wi, _)| wi.dot(nn) > 0.0).map(|&(_, w)| w).sum();
    cap_exitance(&mut map, material, irradiance);
    map
}

/// What one side of a smooth dielectric interface sends per unit area (J, as
/// `outgoing_intensity`) of the direct light: `front` is the light arriving on the normal's
/// side, `back` the light arriving from behind, both as (direction toward the light,
/// irradiance) samples. The point sends toward its front only (its twin, facing the other
/// way, sends the rest: `TwinDielectrics`): front light reflected about the normal with the
/// Fresnel reflectance F, and back light refracted through to the front with 1 − F, none past
/// the critical angle. `ior` is n(behind) / n(front). Each lobe is a Dirac one: its flux per
/// unit area lands in the texel of its direction (J = flux / the texel's solid angle), the
/// narrowest lobe the map holds, so the map sends out exactly F and 1 − F of what arrives.
pub fn interface_intensity(ior: f32, normal: Vec3, front: &[(Vec3, Vec3)], back: &[(Vec3, Vec3)], n: usize) -> CubeMap {
    let mut map = CubeMap::constant(n, Vec3::ZERO);
    let frame = Frame::from_normal(normal.normalize_or(Vec3::Z));
    let omega = texel_solid_angles(n);
    let mut deposit = |dir: Vec3, flux: Vec3| {
        let k = texel_of_side(n, dir);
        map.texels[k] += flux / omega[k];
    };
    for &(wi, e) in front {
        let wl = frame.to_local(wi);
        if wl.z > 0.0 {
            // Reflection of light from wi: the lobe toward wo = mirror(wi) reads wi with F.
            let wo = Vec3::new(-wl.x, -wl.y, wl.z);
            deposit(frame.to_world(wo), e * brdf::dielectric::lobes(ior, wo)[0].1);
        }
    }
    for &(wi, e) in back {
        let wl = frame.to_local(wi);
        // Snell from behind (index ior) to the front (index 1): sin θt = ior sin θi.
        let (sx, sy) = (-wl.x * ior, -wl.y * ior);
        let s2 = sx * sx + sy * sy;
        if wl.z >= 0.0 || s2 >= 1.0 {
            continue;
        }
        let wo = Vec3::new(sx, sy, (1.0 - s2).sqrt());
        // The reflectance is the same either way through the interface.
        deposit(frame.to_world(wo), e * (1.0 - brdf::dielectric::lobes(ior, wo)[0].1));
    }
    map
}

/// Scales a channel of J down where the map sends out more than the surfel can reflect:
/// its `irradiance` (the incident weights from above its plane, or a microbuffer's sum)
/// times the material's largest albedo (kd + ks; Lambert's albedo). The BRDFs here conserve energy, but a map samples
/// them at texel centres, and at grazing light the reflected lobe is squeezed against the
/// horizon into less than a texel (measured: Cook-Torrance m = 0.0375, light at 89.9°, 32²
/// map: 3.3× the irradiance). Maps within the bound are left as they are.
pub fn cap_exitance(map: &mut CubeMap, material: &Material, irradiance: Vec3) {
    let most = match *material {
        Material::Lambert { albedo } => albedo,
        Material::BlinnPhong { kd, ks, .. } | Material::CookTorrance { kd, ks, .. } => kd + ks,
        Material::Dielectric { .. } => Vec3::ONE,
    };
    let bound = (irradiance * most).as_dvec3();
    let mut sent = glam::DVec3::ZERO;
    for (t, &w) in map.texels.iter().zip(texel_solid_angles(map.n).iter()) {
        sent += t.as_dvec3() * w as f64;
    }
    let scale =
        Vec3::from_array(std::array::from_fn(|c| if sent[c] > bound[c] && sent[c] > 0.0 { (bound[c] / sent[c]) as f32 } else { 1.0 }));
    if scale != Vec3::ONE {
        for t in &mut map.texels {
            *t *= scale;
        }
    }
}

/// The point tree's per-point wavelets (`per_point`'s point i for the tree's point i)
/// coded hierarchically along the tree (`math::tree_coding`: nodes above level `split` keep
/// their area-weighted average, nodes below their detail), each vector the RGB coefficients
/// flattened (coefficient k's channel c at 3k + c). `split` = `u32::MAX` keeps every node's
/// average and no detail: the uncoded tree the coding is measured against.
pub fn code_tree(tree: &PointTree, per_point: &PointWavelets, split: u32, threshold: Threshold) -> CodedTree {
    let n = per_point.n as usize;
    let children: Vec<Option<[u32; 2]>> = tree.nodes.iter().map(|t| t.children).collect();
    let area: Vec<f32> = tree.nodes.iter().map(|t| t.area).collect();
    let shape = TreeShape { children: &children, area: &area, root: tree.root };
    CodedTree::build(shape, 6 * n * n * 3, split, threshold, |node, out| {
        let (index, value) = per_point.point(tree.nodes[node as usize].point as usize);
        for (&k, v) in index.iter().zip(value) {
            out[3 * k as usize..3 * k as usize + 3].copy_from_slice(&v.to_array());
        }
    })
}

/// The radiance tree nodes send, read from their coded wavelets: what a gather rasterises.
/// Node i's intensity toward ω is its area × the coded mean of J (`outgoing_intensity`) at
/// ω's texel; divided by its projected area toward ω (the tree's SH estimate, exact for
/// leaves) that is the radiance it shows. Negative values of the approximation are clamped
/// to 0, and a node whose projected area is below `MIN_AREA_FRACTION` of its area sends
/// nothing (as the diffuse tree's `radiance_toward`).
/// Texel values are memoised per thread (`texel_cache`), which changes no result.
pub struct WaveletSource<'a> {
    tree: &'a PointTree,
    coded: &'a CodedWavelets,
    owner: u64,
}

impl<'a> WaveletSource<'a> {
    pub fn new(tree: &'a PointTree, coded: &'a CodedWavelets) -> Self {
        WaveletSource { tree, coded, owner: super::texel_cache::new_owner() }
    }

    /// `new`, after checking that `coded` was coded along this tree (the error names the
    /// input port `coded`, as the nodes that read both take them).
    pub fn checked(tree: &'a PointTree, coded: &'a CodedWavelets) -> Result<Self, relume_core::NodeError> {
        if coded.tree.parent.len() != tree.nodes.len() {
            return Err(relume_core::NodeError::input(
                "coded",
                format!("wavelets coded for a tree of {} nodes, not this tree of {}", coded.tree.parent.len(), tree.nodes.len()),
            ));
        }
        Ok(Self::new(tree, coded))
    }

    /// Node i's radiant intensity per unit area toward `dir` (the coded J, negative values
    /// of the approximation clamped to 0).
    pub fn intensity_per_area(&self, i: u32, dir: Vec3) -> Vec3 {
        let n = self.coded.n as usize;
        let k = texel_of_side(n, dir) as u32;
        let value = texel_cache::get_or(self.owner, i, k, || {
            let (mut terms, len) = texel_terms(n, k as usize);
            let terms = &mut terms[..len];
            terms.sort_unstable_by_key(|t| t.0);
            self.texel(i, k, terms)
        });
        value.max(Vec3::ZERO)
    }

    /// Node i's coded J at texel k (`terms` its Haar terms, ascending): a stored average's
    /// entries, or the parent's value (memoised: siblings and neighbours share it) plus the
    /// parent's detail toward i. The same sums however the memo is filled.
    fn texel(&self, i: u32, k: u32, terms: &[(u32, f32)]) -> Vec3 {
        let t = &self.coded.tree;
        let mut out = [0.0f32; 3];
        if let Some(g) = &t.average[i as usize] {
            g.add_groups(terms, 3, 1.0, &mut out);
            return Vec3::from_array(out);
        }
        let (p, left) = t.parent[i as usize];
        assert!(p != u32::MAX, "node {i} has no stored average above it");
        let above = texel_cache::get_or(self.owner, p, k, || self.texel(p, k, terms));
        if let Some(h) = &t.detail[p as usize] {
            h.add_groups(terms, 3, t.detail_weight(p, left), &mut out);
        }
        above + Vec3::from_array(out)
    }
}

impl super::traversal::NodeRadiance for WaveletSource<'_> {
    fn area_and_radiance(&self, i: u32, dir: Vec3) -> (f32, Vec3) {
        let a = self.tree.projected_area(i, dir);
        let node = &self.tree.nodes[i as usize];
        if a <= crate::types::MIN_AREA_FRACTION * node.area || a <= 0.0 {
            return (0.0, Vec3::ZERO);
        }
        (a, self.intensity_per_area(i, dir) * (node.area / a))
    }
    fn directional_leaves(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::PI;

    /// ∫ over the sphere of the radiance the kept coefficients give back.
    fn integral(w: &SparseCubeHaar) -> Vec3 {
        w.dense().inverse().integral()
    }

    #[test]
    fn a_lambert_surfel_sends_albedo_over_pi_times_irradiance_over_its_hemisphere_only() {
        let n = Vec3::new(0.2, 0.9, -0.3).normalize();
        let albedo = Vec3::new(0.6, 0.4, 0.2);
        // A light 30° off the normal: irradiance E = L cos 30°.
        let wi = (n * 30f32.to_radians().cos() + n.cross(Vec3::X).normalize() * 30f32.to_radians().sin()).normalize();
        let e = 2.0 * wi.dot(n);
        let map = outgoing_cube(&Material::Lambert { albedo }, n, &[(wi, Vec3::splat(e))], 16);
        for k in 0..map.texels.len() {
            let want = if map.direction(k).dot(n) > 0.0 { albedo / PI * e } else { Vec3::ZERO };
            assert!((map.texels[k] - want).abs().max_element() < 1e-6, "texel {k}: {} vs {want}", map.texels[k]);
        }
        // A light from behind the surfel sends nothing.
        let dark = outgoing_cube(&Material::Lambert { albedo }, n, &[(-wi, Vec3::ONE)], 8);
        assert!(dark.texels.iter().all(|t| *t == Vec3::ZERO));
    }

    #[test]
    fn a_blinn_phong_180_lobe_keeps_its_analytic_integral_from_few_wavelet_terms() {
        // Light along the normal with irradiance E: L(ωo) = E (kd/π + ks (s+2)/(8π) cos^s(θo/2)),
        // whose integral over the hemisphere is E (2 kd + ks (1 − 2^−(s+2)/2)).
        let (kd, ks, s) = (Vec3::splat(0.1), Vec3::new(0.8, 0.6, 0.4), 180.0);
        let e = 3.0;
        let want = (kd * 2.0 + ks * (1.0 - 2f32.powf(-(s + 2.0) / 2.0))) * e;
        let m = Material::BlinnPhong { kd, ks, exponent: s };
        for normal in [Vec3::Y, Vec3::new(0.3, 0.5, 0.8).normalize()] {
            // Measured (normal along y, then oblique): 0.068 % and 0.0069 % off with 448 and
            // 963 of 6,144 terms at 32²; 0.0046 % and 0.00044 % with 4,872 and 8,924 of
            // 98,304 at 128². The diffuse part's edge at the horizon costs most of the terms.
            for (side, tol) in [(32, 2e-3), (128, 2e-4)] {
                let w = outgoing_wavelets(&m, normal, &[(normal, Vec3::splat(e))], side, 0.002);
                let got = integral(&w);
                let err = ((got - want) / want).abs().max_element();
                assert!(err < tol, "side {side}, normal {normal}: {got} vs {want} ({err}), {} terms", w.index.len());
                assert!(w.index.len() * 4 < 6 * side * side, "side {side}: {} terms", w.index.len());
            }
        }
    }

    #[test]
    fn extreme_lobes_and_grazing_light_create_no_energy_and_no_nan() {
        // docs/QUALITY.md §2 "BRDF": Blinn-Phong s = 1 and 10⁴, Cook-Torrance roughness 0.001 and
        // 1, light along the normal and at 89.9°, kd + ks = 1. The surfel's exitance ∫ J dω
        // may not exceed its irradiance (1 here), whatever the lobe's width against a texel.
        let (kd, ks) = (Vec3::splat(0.3), Vec3::splat(0.7));
        let materials = [
            Material::BlinnPhong { kd, ks, exponent: 1.0 },
            Material::BlinnPhong { kd, ks, exponent: 1.0e4 },
            Material::CookTorrance { kd, ks, roughness: 0.001, f0: 1.0 },
            Material::CookTorrance { kd, ks, roughness: 1.0, f0: 1.0 },
        ];
        for m in &materials {
            for k in 0..12 {
                let normal = Vec3::new((k as f32 * 1.7).sin(), 1.0 + k as f32 * 0.1, (k as f32 * 0.9).cos()).normalize();
                let side = normal.any_orthonormal_vector();
                for theta in [0.0f32, 45.0, 89.9] {
                    let t = theta.to_radians();
                    let wi = normal * t.cos() + side * t.sin();
                    for n in [16, 32] {
                        let map = outgoing_intensity(m, normal, &[(wi, Vec3::ONE)], n);
                        assert!(map.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0), "{m:?}");
                        let exitance = map.integral().max_element();
                        assert!(exitance <= 1.0001, "{m:?}, normal {normal}, light at {theta}°, side {n}: exitance {exitance}");
                    }
                }
            }
        }
        // The band limit alone keeps the narrow lobe's energy (the cap does not act): this
        // case sent 1.20 before the lobe was widened to the map.
        let normal = Vec3::new(1.7f32.sin(), 1.1, 0.9f32.cos()).normalize();
        let narrow = Material::BlinnPhong { kd, ks, exponent: 1.0e4 };
        assert_eq!(band_limited(&narrow, 16), Material::BlinnPhong { kd, ks, exponent: 2.0 * std::f32::consts::LN_2 * 256.0 });
        let mut map = outgoing_cube(&narrow, normal, &[(normal, Vec3::ONE)], 16);
        for (t, d) in map.texels.iter_mut().zip(texel_directions(16).iter()) {
            *t *= d.dot(normal).max(0.0);
        }
        let sent = map.integral().max_element();
        assert!(sent > 0.9 && sent <= 1.0, "{sent}");
    }

    #[test]
    fn coding_a_glossy_floor_along_its_point_tree_rebuilds_each_point_and_stores_less() {
        use relume_base::geometry::sample_surface::{sample_surface, Method, SampleSurface};
        let glossy = Material::BlinnPhong { kd: Vec3::splat(0.2), ks: Vec3::splat(0.5), exponent: 60.0 };
        let scene = relume_base::scene::builder::SceneBuilder::new(Vec3::new(0.0, 2.0, 2.0), Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), glossy, Vec3::ZERO)
            .build();
        let pts = sample_surface(&scene, &SampleSurface { method: Method::AreaCdf, count: 300, seed: 1, emitters: true }).unwrap();
        // A light from one side, falling off across the floor: neighbours differ a little.
        let light = Vec3::new(0.5, 1.0, 0.2).normalize();
        let per_point: Vec<SparseCubeHaar> = (0..pts.len())
            .map(|i| {
                let e = Vec3::splat(1.0 + 0.3 * pts.position[i].x);
                outgoing_wavelets(&pts.material[i], pts.normal[i], &[(light, e)], 8, 0.0)
            })
            .collect();
        let tree = PointTree::build(&pts, &vec![Vec3::ZERO; pts.len()]);
        let wavelets = PointWavelets::from_points(8, &per_point);
        let exact = code_tree(&tree, &wavelets, 3, Threshold::Coefficient(0.0));
        for (v, node) in tree.nodes.iter().enumerate().filter(|(_, t)| t.is_leaf()) {
            let got = exact.reconstruct(v as u32);
            let want = per_point[node.point as usize].dense().coeffs;
            for (k, c) in want.iter().enumerate() {
                let g = Vec3::new(got[3 * k], got[3 * k + 1], got[3 * k + 2]);
                assert!((g - *c).abs().max_element() <= 1e-4 * (1.0 + c.abs().max_element()), "leaf {v} [{k}]: {g} vs {c}");
            }
        }
        // At the thesis' threshold the details of similar neighbours are mostly dropped:
        // the coded tree is smaller than every node keeping its average. Measured: 181,560 B
        // against 1,333,440 B (7.3×).
        let coded = code_tree(&tree, &wavelets, 3, Threshold::Coefficient(0.002));
        let uncoded = code_tree(&tree, &wavelets, u32::MAX, Threshold::Coefficient(0.002));
        assert!(uncoded.detail.iter().all(Option::is_none));
        assert!(coded.bytes() * 4 < uncoded.bytes(), "coded {} B, uncoded {} B", coded.bytes(), uncoded.bytes());

        // The gather's texel values (memoised, parent first) agree with `dot` along the
        // whole path, and do not depend on the order the memo was filled in.
        let cw = CodedWavelets { n: 8, tree: coded };
        let dirs: Vec<Vec3> = (0..40).map(|k| Vec3::new((k as f32 * 0.7).sin(), 1.0, (k as f32 * 1.3).cos()).normalize()).collect();
        let nodes: Vec<u32> = (0..tree.nodes.len() as u32).collect();
        let leaves_first = WaveletSource::new(&tree, &cw);
        let roots_first = WaveletSource::new(&tree, &cw);
        for &d in &dirs {
            let a: Vec<Vec3> = nodes.iter().rev().map(|&v| leaves_first.intensity_per_area(v, d)).collect();
            let b: Vec<Vec3> = nodes.iter().map(|&v| roots_first.intensity_per_area(v, d)).collect();
            for (&v, (x, y)) in nodes.iter().zip(a.iter().rev().zip(&b)) {
                assert_eq!(x, y, "node {v} toward {d}");
                let (mut terms, len) = texel_terms(8, texel_of_side(8, d));
                terms[..len].sort_unstable_by_key(|t| t.0);
                let mut want = [0.0f32; 3];
                cw.tree.dot(v, &terms[..len], 3, &mut want);
                let want = Vec3::from_array(want).max(Vec3::ZERO);
                assert!((*y - want).abs().max_element() <= 1e-5 * (1.0 + want.max_element()), "node {v}: {y} vs {want}");
            }
        }
    }
}
