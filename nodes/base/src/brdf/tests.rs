//! Cross-model tests: reciprocity, energy conservation, sampling against densities, finiteness
//! at the extremes (docs/QUALITY.md §2 BRDF rows) and the smooth dielectric's delta lobes.

use super::*;
use crate::math::rng::uniform;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Debug builds use fewer samples (the module's tests must stay fast there).
fn n(debug: usize, release: usize) -> usize {
    if cfg!(debug_assertions) {
        debug
    } else {
        release
    }
}

/// Direction at polar angle θ (degrees) and azimuth φ (radians), computed in f64.
fn dir(theta_deg: f64, phi: f64) -> Vec3 {
    let t = theta_deg.to_radians();
    DVec3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos()).as_vec3()
}

fn lambert(a: f32) -> Material {
    Material::Lambert { albedo: Vec3::splat(a) }
}
fn bp(kd: f32, ks: f32, s: f32) -> Material {
    Material::BlinnPhong { kd: Vec3::splat(kd), ks: Vec3::splat(ks), exponent: s }
}
fn ct(kd: f32, ks: f32, m: f32, f0: f32) -> Material {
    Material::CookTorrance { kd: Vec3::splat(kd), ks: Vec3::splat(ks), roughness: m, f0 }
}

/// A named opaque material of the test spread.
struct Case {
    name: &'static str,
    m: Material,
}

fn opaque_cases() -> Vec<Case> {
    let c = |name, m| Case { name, m };
    vec![
        c("lambert white (furnace)", lambert(1.0)),
        c("lambert coloured", Material::Lambert { albedo: Vec3::new(0.8, 0.5, 0.2) }),
        c("blinn-phong s=1 kd+ks=1", bp(0.5, 0.5, 1.0)),
        c("blinn-phong s=1 specular only", bp(0.0, 1.0, 1.0)),
        c("blinn-phong s=20 kd+ks=1", bp(0.3, 0.7, 20.0)),
        c("blinn-phong s=200 specular only", bp(0.0, 1.0, 200.0)),
        c(
            "blinn-phong s=50 coloured kd+ks=1",
            Material::BlinnPhong { kd: Vec3::new(0.6, 0.2, 0.1), ks: Vec3::new(0.4, 0.8, 0.9), exponent: 50.0 },
        ),
        c("blinn-phong s=1e4 specular only", bp(0.0, 1.0, 1e4)),
        c("blinn-phong s=1e4 kd+ks=1", bp(0.4, 0.6, 1e4)),
        c("cook-torrance m=1 kd+ks=1", ct(0.5, 0.5, 1.0, 0.04)),
        c("cook-torrance m=1 white mirror facets", ct(0.0, 1.0, 1.0, 1.0)),
        c("cook-torrance m=0.3 kd+ks=1", ct(0.2, 0.8, 0.3, 1.0)),
        c("cook-torrance m=0.1 specular only", ct(0.0, 1.0, 0.1, 0.5)),
        c("cook-torrance m=0.001 white mirror facets", ct(0.0, 1.0, 0.001, 1.0)),
        c("cook-torrance m=0.001 kd+ks=1", ct(0.3, 0.7, 0.001, 0.04)),
    ]
}

/// Outgoing directions from normal incidence to θ = 89.9°.
fn wo_spread() -> Vec<Vec3> {
    [0.0, 30.0, 60.0, 80.0, 89.0, 89.9].iter().map(|&t| dir(t, 0.7)).collect()
}

/// A direction on the upper hemisphere; every fourth one is pushed toward the horizon.
fn random_upper(seed: u64, i: u64) -> Vec3 {
    let (a, b) = (uniform(seed, i, 0) as f64, uniform(seed, i, 1) as f64);
    let z = if i.is_multiple_of(4) { a.powi(4) } else { a }.max(1e-6);
    let r = (1.0 - z * z).sqrt();
    DVec3::new(r * (2.0 * PI * b).cos(), r * (2.0 * PI * b).sin(), z).as_vec3()
}

fn u2(seed: u64, i: u64) -> Vec2 {
    Vec2::new(uniform(seed, i, 0), uniform(seed, i, 1))
}

/// ∫ g(ω) dω over the cap θ < θmax of the upper hemisphere by the midpoint rule in (x, φ),
/// dω = sin θ dθ dφ, θ = θmax (3x² − 2x³): the nodes crowd toward the pole and the rim, where
/// lobes of normal and grazing incidence sit.
fn integrate_cap<T: Default + std::ops::AddAssign + std::ops::Mul<f64, Output = T>>(
    theta_max: f64,
    nt: usize,
    np: usize,
    mut g: impl FnMut(DVec3) -> T,
) -> T {
    let (dx, dp) = (1.0 / nt as f64, 2.0 * PI / np as f64);
    let mut acc = T::default();
    for a in 0..nt {
        let x = (a as f64 + 0.5) * dx;
        let t = theta_max * x * x * (3.0 - 2.0 * x);
        let dtheta = theta_max * 6.0 * x * (1.0 - x) * dx;
        for b in 0..np {
            let p = (b as f64 + 0.5) * dp;
            acc += g(DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())) * (t.sin() * dtheta * dp);
        }
    }
    acc
}

/// ∫ g(ω) dω over the whole upper hemisphere.
fn integrate_hemisphere<T: Default + std::ops::AddAssign + std::ops::Mul<f64, Output = T>>(
    nt: usize,
    np: usize,
    mut g: impl FnMut(Vec3) -> T,
) -> T {
    integrate_cap(0.5 * PI, nt, np, |w| g(w.as_vec3()))
}

/// Splits a glossy material into its diffuse-only and specular-only parts (f is linear in
/// kd, ks), with the polar angle of the half vector beyond which the specular D is < e⁻⁴⁰ of
/// its peak. Lambert is all diffuse.
fn split_lobes(m: &Material) -> (Material, Option<(Material, f64)>) {
    match *m {
        Material::Lambert { .. } | Material::Dielectric { .. } => (*m, None),
        Material::BlinnPhong { kd, ks, exponent } => (
            Material::BlinnPhong { kd, ks: Vec3::ZERO, exponent },
            // cos^s θ ≈ exp(−s θ²/2).
            Some((Material::BlinnPhong { kd: Vec3::ZERO, ks, exponent }, (80.0 / exponent as f64).sqrt().min(0.5 * PI))),
        ),
        Material::CookTorrance { kd, ks, roughness, f0 } => (
            Material::CookTorrance { kd, ks: Vec3::ZERO, roughness, f0 },
            Some((Material::CookTorrance { kd: Vec3::ZERO, ks, roughness, f0 }, (7.0 * roughness as f64).atan())),
        ),
    }
}

/// Directional albedo ∫ f cos θi dωi by deterministic quadrature, independent of `sample` and
/// `pdf`: the diffuse part over ωi; the specular part over the half vector h, where its lobe is
/// smooth and as wide as the roughness (over ωi it degenerates into a sliver along the horizon
/// at grazing ωo), with ωi = 2(ωo·h)h − ωo and dωi = 4 (ωo·h) dωh.
fn albedo_quadrature(m: &Material, wo: Vec3) -> DVec3 {
    let (nt, np) = (n(128, 512), n(256, 1024));
    let (diffuse, specular) = split_lobes(m);
    let mut total = integrate_hemisphere(nt, np, |wi| eval(&diffuse, wo, wi).as_dvec3() * wi.z as f64);
    if let Some((spec, theta_max)) = specular {
        let o = wo.as_dvec3();
        total += integrate_cap(theta_max, nt, np, |h| {
            let woh = o.dot(h);
            let wi = (2.0 * woh * h - o).as_vec3();
            if woh <= 0.0 || wi.z <= 0.0 {
                return DVec3::ZERO;
            }
            eval(&spec, wo, wi).as_dvec3() * (wi.z as f64 * 4.0 * woh)
        });
    }
    total
}

/// Directional albedo by importance sampling: the mean of f cos θi / pdf (0 when no sample),
/// with stratified u. Returns (mean, standard error) per channel.
fn albedo_sampled(m: &Material, wo: Vec3, seed: u64) -> (DVec3, DVec3) {
    let side = n(96, 256);
    let (mut sum, mut sum2) = (DVec3::ZERO, DVec3::ZERO);
    for a in 0..side {
        for b in 0..side {
            let i = (a * side + b) as u64;
            let u = Vec2::new((a as f32 + uniform(seed, i, 0)) / side as f32, (b as f32 + uniform(seed, i, 1)) / side as f32);
            let u = u.min(Vec2::splat(1.0 - f32::EPSILON / 2.0));
            let w = match sample(m, wo, u, uniform(seed, i, 2)) {
                Some(s) => (s.f * s.wi.z.abs() / s.pdf).as_dvec3(),
                None => DVec3::ZERO,
            };
            sum += w;
            sum2 += w * w;
        }
    }
    let count = (side * side) as f64;
    let mean = sum / count;
    let var = (sum2 / count - mean * mean).max(DVec3::ZERO);
    (mean, (var / count).sqrt())
}

#[test]
fn glossy_and_lambert_models_are_reciprocal_for_random_and_sampled_direction_pairs() {
    let pairs = n(1500, 20_000) as u64;
    for (k, c) in opaque_cases().iter().enumerate() {
        // The peak value (mirror configuration at normal incidence): sampled pairs must get
        // near it, so that narrow lobes are really compared and not just their zero tails.
        let peak = eval(&c.m, Vec3::Z, Vec3::Z).max_element();
        let mut highest = 0f32;
        for i in 0..pairs {
            let wo = random_upper(10 + k as u64, i);
            // Half the pairs are drawn from the material itself so that narrow lobes are hit.
            let wi = if i % 2 == 0 {
                random_upper(100 + k as u64, i)
            } else {
                match sample(&c.m, wo, u2(200 + k as u64, i), uniform(300, i, 0)) {
                    Some(s) => s.wi,
                    None => continue,
                }
            };
            let (a, b) = (eval(&c.m, wo, wi), eval(&c.m, wi, wo));
            assert!(a.is_finite() && b.is_finite(), "{}: {a} {b}", c.name);
            let tol = 1e-5 * a.max_element().max(b.max_element());
            assert!((a - b).abs().max_element() <= tol, "{}: f({wo}, {wi}) = {a} but f({wi}, {wo}) = {b}", c.name);
            highest = highest.max(a.max_element());
        }
        assert!(highest >= 0.1 * peak, "{}: the test never got near the peak {peak} (highest {highest})", c.name);
    }
}

#[test]
fn directional_albedo_never_exceeds_one_even_at_grazing_angles() {
    // Kd + Ks = 1, white facets (f0 = 1) and a white Lambertian are the furnace cases.
    let cases = opaque_cases();
    let failures: Vec<String> = cases
        .par_iter()
        .enumerate()
        .flat_map_iter(|(k, c)| {
            let mut out = vec![];
            for (j, wo) in wo_spread().into_iter().enumerate() {
                let deg = wo.z.acos().to_degrees();
                let (mean, se) = albedo_sampled(&c.m, wo, 1000 + (k * 10 + j) as u64);
                if mean.cmpgt(DVec3::splat(1.0 + 1e-3) + 4.0 * se).any() || !mean.is_finite() {
                    out.push(format!("{} θo={deg:.1}°: sampled albedo {mean} (se {se})", c.name));
                }
                let q = albedo_quadrature(&c.m, wo);
                if q.max_element() > 1.0 + 1e-3 || !q.is_finite() {
                    out.push(format!("{} θo={deg:.1}°: integrated albedo {q}", c.name));
                }
            }
            out
        })
        .collect();
    assert!(failures.is_empty(), "energy created:\n{}", failures.join("\n"));
}

#[test]
fn importance_sampled_albedo_agrees_with_quadrature() {
    // The sample weights f cos / pdf estimate the same integral only when `sample`, `pdf` and
    // `eval` agree; this catches a wrong Jacobian or lobe probability at every angle.
    let cases = opaque_cases();
    let failures: Vec<String> = cases
        .par_iter()
        .enumerate()
        .flat_map_iter(|(k, c)| {
            let mut out = vec![];
            for (j, wo) in wo_spread().into_iter().enumerate() {
                let (mean, se) = albedo_sampled(&c.m, wo, 2000 + (k * 10 + j) as u64);
                let q = albedo_quadrature(&c.m, wo);
                if (mean - q).abs().cmpgt(5.0 * se + DVec3::splat(1e-3)).any() {
                    out.push(format!("{} θo={:.1}°: sampled {mean} ± {se} vs quadrature {q}", c.name, wo.z.acos().to_degrees()));
                }
            }
            out
        })
        .collect();
    assert!(failures.is_empty(), "estimates disagree:\n{}", failures.join("\n"));
}

#[test]
fn near_mirror_lobes_reflect_almost_all_energy_at_normal_incidence() {
    // With the 8π normalisation the s → ∞ Blinn-Phong lobe becomes a perfect mirror of
    // reflectance ks (the thesis' 2π would give ~4); likewise Cook-Torrance with m → 0 and F = 1.
    for m in [bp(0.0, 1.0, 1e4), ct(0.0, 1.0, 0.001, 1.0)] {
        let (mean, se) = albedo_sampled(&m, Vec3::Z, 7);
        assert!(mean.x > 0.99 && mean.x < 1.0 + 1e-3 + 4.0 * se.x, "{m:?}: albedo {mean} ± {se}");
    }
    // And a white Lambertian reflects exactly its albedo for every ωo.
    for wo in wo_spread() {
        let (mean, _) = albedo_sampled(&lambert(1.0), wo, 8);
        assert!((mean - DVec3::ONE).abs().max_element() < 1e-5, "{mean}");
        let q = albedo_quadrature(&lambert(1.0), wo);
        assert!((q - DVec3::ONE).abs().max_element() < 1e-3, "{q}");
    }
}

#[test]
fn sample_returns_the_value_and_density_of_its_own_direction() {
    for (k, c) in opaque_cases().iter().enumerate() {
        let mut some = 0;
        for (j, wo) in wo_spread().into_iter().enumerate() {
            for i in 0..n(300, 3000) as u64 {
                let seed = (k * 10 + j) as u64;
                let Some(s) = sample(&c.m, wo, u2(seed, i), uniform(seed, i, 2)) else { continue };
                some += 1;
                assert!(!s.delta && s.wi.z > 0.0 && (s.wi.length() - 1.0).abs() < 1e-5, "{}: {s:?}", c.name);
                let p = pdf(&c.m, wo, s.wi);
                assert!((s.pdf - p).abs() <= 1e-6 * p, "{}: sample pdf {} vs pdf() {p}", c.name, s.pdf);
                let f = eval(&c.m, wo, s.wi);
                assert!((s.f - f).abs().max_element() <= 1e-6 * f.max_element(), "{}: {} vs {f}", c.name, s.f);
            }
        }
        assert!(some > 0, "{}: never sampled", c.name);
    }
}

#[test]
fn pdf_integrates_to_one_less_the_probability_of_no_sample() {
    // Lobe samples mirrored below the horizon are rejected (`None`), and `pdf` is 0 there, so
    // ∫ pdf dω over the sphere plus P(None) must be 1. Moderately glossy parameters only.
    let mats = [
        lambert(0.7),
        bp(0.5, 0.5, 1.0),
        bp(0.3, 0.7, 20.0),
        bp(0.0, 1.0, 100.0),
        ct(0.5, 0.5, 1.0, 0.04),
        ct(0.2, 0.8, 0.3, 0.9),
        ct(0.0, 1.0, 0.1, 1.0),
    ];
    let failures: Vec<String> = mats
        .par_iter()
        .enumerate()
        .flat_map_iter(|(k, m)| {
            let mut out = vec![];
            for (j, theta) in [0.0, 45.0, 80.0].into_iter().enumerate() {
                let wo = dir(theta, 0.3);
                let integral = integrate_hemisphere(n(256, 512), n(512, 1024), |wi| pdf(m, wo, wi) as f64);
                // Below the surface the density is zero.
                let below = integrate_hemisphere(16, 32, |wi| pdf(m, wo, -wi) as f64);
                let count = n(20_000, 200_000);
                let seed = 5000 + (k * 10 + j) as u64;
                let none = (0..count as u64).filter(|&i| sample(m, wo, u2(seed, i), uniform(seed, i, 2)).is_none()).count();
                let p_none = none as f64 / count as f64;
                let tol = 4.0 * (p_none * (1.0 - p_none) / count as f64).sqrt() + 3e-3;
                if (integral + p_none - 1.0).abs() > tol || below != 0.0 {
                    out.push(format!("{m:?} θo={theta}: ∫pdf = {integral}, P(None) = {p_none}, below = {below}"));
                }
            }
            out
        })
        .collect();
    assert!(failures.is_empty(), "densities do not normalise:\n{}", failures.join("\n"));
}

/// Pearson's χ² of the counts of `sampled`'s samples over (cos θ, φ) bins against
/// n ∫_bin pdf of `claimed`, with the `None` outcome as one more bin; bins expecting < 5 are
/// pooled. Returns the Wilson–Hilferty z-score of the statistic (≈ standard normal when the
/// histogram follows the density).
fn chi_square_z(sampled: &Material, claimed: &Material, wo: Vec3, count: usize, seed: u64) -> f64 {
    const NC: usize = 10;
    const NP: usize = 20;
    const SUB: usize = 32;
    let mut observed = vec![0f64; NC * NP + 1];
    for i in 0..count as u64 {
        match sample(sampled, wo, u2(seed, i), uniform(seed, i, 2)) {
            Some(s) => {
                let c = ((s.wi.z as f64 * NC as f64) as usize).min(NC - 1);
                let phi = (s.wi.y as f64).atan2(s.wi.x as f64).rem_euclid(2.0 * PI);
                let p = ((phi / (2.0 * PI) * NP as f64) as usize).min(NP - 1);
                observed[c * NP + p] += 1.0;
            }
            None => observed[NC * NP] += 1.0,
        }
    }
    let mut expected = vec![0f64; NC * NP + 1];
    let (dc, dp) = (1.0 / (NC * SUB) as f64, 2.0 * PI / (NP * SUB) as f64);
    for c in 0..NC * SUB {
        let z = (c as f64 + 0.5) * dc;
        let r = (1.0 - z * z).sqrt();
        for p in 0..NP * SUB {
            let phi = (p as f64 + 0.5) * dp;
            let wi = DVec3::new(r * phi.cos(), r * phi.sin(), z).as_vec3();
            expected[(c / SUB) * NP + p / SUB] += pdf(claimed, wo, wi) as f64 * dc * dp * count as f64;
        }
    }
    expected[NC * NP] = (count as f64 - expected[..NC * NP].iter().sum::<f64>()).max(0.0);
    let (mut chi2, mut bins, mut pooled_o, mut pooled_e) = (0.0, 0usize, 0.0, 0.0);
    for (o, e) in observed.iter().zip(&expected) {
        if *e < 5.0 {
            pooled_o += o;
            pooled_e += e;
        } else {
            chi2 += (o - e).powi(2) / e;
            bins += 1;
        }
    }
    if pooled_e >= 5.0 {
        chi2 += (pooled_o - pooled_e).powi(2) / pooled_e;
        bins += 1;
    } else {
        assert!(pooled_o < 5.0 + 5.0 * pooled_e.max(1.0), "{pooled_o} samples where the density expects {pooled_e}");
    }
    let dof = (bins - 1) as f64;
    let k = 2.0 / (9.0 * dof);
    ((chi2 / dof).cbrt() - (1.0 - k)) / k.sqrt()
}

#[test]
fn sample_histograms_over_cos_theta_and_phi_match_the_pdf_chi_square() {
    let mats = [
        lambert(0.5),
        bp(0.5, 0.5, 1.0),
        bp(0.3, 0.7, 20.0),
        bp(0.0, 1.0, 60.0),
        ct(0.5, 0.5, 1.0, 0.04),
        ct(0.2, 0.8, 0.3, 0.5),
        ct(0.0, 1.0, 0.2, 1.0),
    ];
    let count = n(40_000, 100_000);
    let failures: Vec<String> = mats
        .par_iter()
        .enumerate()
        .flat_map_iter(|(k, m)| {
            let mut out = vec![];
            for (j, theta) in [0.0, 45.0, 80.0].into_iter().enumerate() {
                let z = chi_square_z(m, m, dir(theta, 1.1), count, 9000 + (k * 10 + j) as u64);
                // z > 4.3 has probability ≈ 10⁻⁵ under the null hypothesis.
                if z.is_nan() || z >= 4.3 {
                    out.push(format!("{m:?} θo={theta}: χ² z-score {z:.2}"));
                }
            }
            out
        })
        .collect();
    assert!(failures.is_empty(), "histograms differ from pdf:\n{}", failures.join("\n"));
}

#[test]
fn chi_square_test_detects_a_wrong_density() {
    // Guard for the test above: samples of s = 60 judged against the pdf of s = 45 (what a
    // wrong exponent in the sampler would produce) must be rejected by a wide margin.
    let z = chi_square_z(&bp(0.0, 1.0, 60.0), &bp(0.0, 1.0, 45.0), dir(30.0, 0.2), n(40_000, 400_000), 77);
    assert!(z > 10.0, "the χ² test cannot tell s = 60 from s = 45 (z = {z})");
}

/// The docs/QUALITY.md §2 extremes plus some beyond them (clamped parameters, z = 10⁻³⁰).
fn extreme_materials() -> Vec<Material> {
    let mut v: Vec<Material> = opaque_cases().into_iter().map(|c| c.m).collect();
    v.extend([
        bp(0.0, 1.0, 0.0),
        bp(1.0, 0.0, 1e4),
        bp(0.0, 1.0, 1e6),
        ct(0.0, 1.0, 0.0, 1.0),
        ct(0.0, 1.0, 1e-4, 0.0),
        ct(1.0, 0.0, 0.001, 1.0),
    ]);
    v
}

fn extreme_wo() -> Vec<Vec3> {
    let mut v = wo_spread();
    v.extend([dir(89.999, 2.0), Vec3::new(1.0, 0.0, 1e-6).normalize(), Vec3::new(0.0, 1.0, 1e-30), Vec3::new(-0.6, 0.8, 1e-20)]);
    v
}

#[test]
fn sampled_weights_are_finite_and_non_negative_at_every_extreme() {
    let edges = [0.0, 0.5, 1.0 - f32::EPSILON / 2.0];
    for (k, m) in extreme_materials().iter().enumerate() {
        for wo in extreme_wo() {
            let mut us: Vec<(Vec2, f32)> = (0..n(400, 4000) as u64).map(|i| (u2(k as u64, i), uniform(k as u64, i, 2))).collect();
            for &a in &edges {
                for &b in &edges {
                    for &c in &edges {
                        us.push((Vec2::new(a, b), c));
                    }
                }
            }
            for (u, uc) in us {
                let Some(s) = sample(m, wo, u, uc) else { continue };
                let w = s.f * s.wi.z.abs() / s.pdf;
                assert!(s.wi.is_finite() && (s.wi.length() - 1.0).abs() < 1e-4, "{m:?} {wo}: wi {}", s.wi);
                assert!(s.pdf.is_finite() && s.pdf > 0.0, "{m:?} {wo}: pdf {}", s.pdf);
                assert!(s.f.is_finite() && s.f.min_element() >= 0.0, "{m:?} {wo}: f {}", s.f);
                assert!(w.is_finite() && w.min_element() >= 0.0, "{m:?} {wo}: weight {w}");
            }
        }
    }
}

#[test]
fn eval_and_pdf_are_finite_and_non_negative_for_any_pair_including_grazing_opposites() {
    let mut ws = extreme_wo();
    ws.extend(ws.clone().iter().map(|w| Vec3::new(-w.x, -w.y, w.z)));
    ws.extend((0..40).map(|i| random_upper(42, i)));
    for m in extreme_materials() {
        for &wo in &ws {
            for &wi in &ws {
                let (f, p) = (eval(&m, wo, wi), pdf(&m, wo, wi));
                assert!(f.is_finite() && f.min_element() >= 0.0, "{m:?} f({wo}, {wi}) = {f}");
                assert!(p.is_finite() && p >= 0.0, "{m:?} pdf({wo}, {wi}) = {p}");
            }
        }
    }
}

#[test]
fn opaque_models_are_black_from_behind_and_below_the_horizon() {
    let above = dir(40.0, 0.5);
    let belows = [dir(140.0, 0.5), -Vec3::Z, Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.6, 0.8, -1e-30)];
    for m in extreme_materials() {
        for &b in &belows {
            assert_eq!(eval(&m, above, b), Vec3::ZERO, "{m:?}");
            assert_eq!(eval(&m, b, above), Vec3::ZERO, "{m:?}");
            assert_eq!((pdf(&m, above, b), pdf(&m, b, above)), (0.0, 0.0), "{m:?}");
            for i in 0..50 {
                assert!(sample(&m, b, u2(3, i), uniform(3, i, 2)).is_none(), "{m:?} sampled from behind");
            }
        }
        assert!(!is_delta(&m));
    }
    // A black material reflects nothing and samples nothing.
    assert!(sample(&bp(0.0, 0.0, 10.0), Vec3::Z, Vec2::splat(0.5), 0.5).is_none());
    assert_eq!(pdf(&ct(0.0, 0.0, 0.3, 0.5), Vec3::Z, Vec3::Z), 0.0);
}

// ---- smooth dielectric -------------------------------------------------------------------------

fn glass(ior: f32) -> Material {
    Material::Dielectric { ior, medium: None }
}

/// (reflection sample, refraction sample) of ωo: uc = 0 picks reflection when F > 0, uc → 1
/// refraction when F < 1.
fn both_lobes(ior: f32, wo: Vec3) -> (Option<BsdfSample>, Option<BsdfSample>) {
    (sample(&glass(ior), wo, Vec2::ZERO, 0.0), sample(&glass(ior), wo, Vec2::ZERO, 1.0 - f32::EPSILON / 2.0))
}

#[test]
fn dielectric_reflects_squared_index_contrast_at_normal_incidence_from_either_side() {
    for ior in [1.1f32, 1.333, 1.5, 2.4, 0.7] {
        let expect = ((ior - 1.0) / (ior + 1.0)).powi(2);
        for wo in [Vec3::Z, -Vec3::Z] {
            let (r, t) = both_lobes(ior, wo);
            let (r, t) = (r.unwrap(), t.unwrap());
            assert!((r.pdf - expect).abs() < 1e-6, "ior {ior}: F = {} vs {expect}", r.pdf);
            assert_eq!(r.wi, wo);
            assert!((t.wi + wo).length() < 1e-6, "normal incidence refracts straight: {}", t.wi);
            // The sampled reflection frequency is F.
            let count = 20_000;
            let refl = (0..count).filter(|&i| sample(&glass(ior), wo, Vec2::ZERO, uniform(11, i, 0)).unwrap().wi.z * wo.z > 0.0).count();
            let freq = refl as f32 / count as f32;
            assert!((freq - expect).abs() < 4.0 * (expect * (1.0 - expect) / count as f32).sqrt() + 1e-3, "{freq} vs {expect}");
        }
    }
}

#[test]
fn dielectric_totally_reflects_beyond_the_critical_angle() {
    let ior = 1.5f32;
    let critical = (1.0 / ior as f64).asin().to_degrees(); // 41.8°
    for theta in [critical + 0.05, 50.0, 70.0, 89.9] {
        let wo = -dir(theta, 0.4); // inside the glass, heading out
        assert!(wo.z < 0.0);
        for i in 0..200 {
            let s = sample(&glass(ior), wo, Vec2::ZERO, uniform(12, i, 0)).unwrap();
            assert!(s.delta && s.pdf == 1.0, "θ {theta}: {s:?}");
            assert_eq!(s.wi, Vec3::new(-wo.x, -wo.y, wo.z));
            assert!(((s.f * s.wi.z.abs() / s.pdf) - Vec3::ONE).abs().max_element() < 1e-5);
        }
    }
    // Just inside the critical angle some light still leaves, bent to near grazing.
    let wo = -dir(critical - 0.5, 0.4);
    let (_, t) = both_lobes(ior, wo);
    let t = t.unwrap();
    assert!(t.wi.z > 0.0 && t.wi.z < 0.2 && t.pdf < 1.0, "{t:?}");
    // From outside there is no total internal reflection at any angle.
    for theta in [50.0, 80.0, 89.9] {
        assert!(both_lobes(ior, dir(theta, 0.4)).1.unwrap().wi.z < 0.0);
    }
}

#[test]
fn dielectric_of_index_one_passes_straight_through_with_weight_one() {
    for i in 0..500 {
        let mut wo = random_upper(13, i);
        if i % 2 == 1 {
            wo = -wo;
        }
        for uc in [0.0, uniform(14, i, 0), 1.0 - f32::EPSILON / 2.0] {
            let s = sample(&glass(1.0), wo, u2(15, i), uc).unwrap();
            assert_eq!(s.wi, -wo, "not straight through");
            assert!(s.delta && s.pdf == 1.0);
            let w = s.f * s.wi.z.abs() / s.pdf;
            assert!((w - Vec3::ONE).abs().max_element() < 1e-6, "weight {w}");
        }
    }
}

#[test]
fn dielectric_reflection_and_refraction_probabilities_sum_to_one() {
    for ior in [1.05f32, 1.5, 2.4, 1.0 / 1.5] {
        for k in 0..40 {
            let theta = 0.5 + 89.0 * k as f64 / 39.0;
            for wo in [dir(theta, 0.9), -dir(theta, 0.9)] {
                let (r, t) = both_lobes(ior, wo);
                let pr = r.map_or(0.0, |s| if s.wi.z * wo.z > 0.0 { s.pdf } else { 0.0 });
                let pt = t.map_or(0.0, |s| if s.wi.z * wo.z < 0.0 { s.pdf } else { 0.0 });
                if pt == 0.0 {
                    assert!((pr - 1.0).abs() < 1e-6, "TIR must reflect with probability 1, got {pr}");
                } else {
                    assert!((pr + pt - 1.0).abs() < 1e-6, "ior {ior} θ {theta}: {pr} + {pt}");
                }
                assert!((pr - dielectric::reflect_probability(ior, wo)).abs() < 1e-6);
            }
        }
    }
}

#[test]
fn dielectric_lobes_are_the_two_samples_with_their_probabilities_folded_in() {
    // What a gather reads the two lobes with (the spherical microbuffer): each lobe's weight
    // is its sample's probability times its throughput weight, in the sample's direction.
    for ior in [1.0f32, 1.05, 1.5, 2.4, 1.0 / 1.5] {
        for k in 0..40 {
            let theta = 0.5 + 89.0 * k as f64 / 39.0;
            for wo in [dir(theta, 0.9), -dir(theta, 0.9)] {
                let [(wr, kr), (wt, kt)] = dielectric::lobes(ior, wo);
                let (r, t) = both_lobes(ior, wo);
                let weight = |s: &BsdfSample| s.f.x * s.wi.z.abs();
                let r = r.filter(|s| s.wi.z * wo.z > 0.0);
                let t = t.filter(|s| s.wi.z * wo.z < 0.0);
                match r {
                    Some(s) => assert!((wr - s.wi).length() < 1e-6 && (kr - weight(&s)).abs() < 1e-6, "ior {ior} θ {theta}"),
                    None => assert_eq!(kr, 0.0),
                }
                match t {
                    Some(s) => assert!((wt - s.wi).length() < 1e-6 && (kt - weight(&s)).abs() < 1e-6, "ior {ior} θ {theta}"),
                    None => assert_eq!(kt, 0.0, "ior {ior} θ {theta}: total internal reflection"),
                }
                assert!(kr + kt * (if wo.z > 0.0 { ior * ior } else { 1.0 / (ior * ior) }) <= 1.0 + 1e-6);
            }
        }
    }
    // Index 1: straight through with weight 1, nothing reflected.
    let wo = dir(30.0, 0.4);
    assert_eq!(dielectric::lobes(1.0, wo)[1], (-wo, 1.0));
    assert_eq!(dielectric::lobes(1.0, wo)[0].1, 0.0);
}

#[test]
fn dielectric_refraction_obeys_snell_and_scales_radiance_by_inverse_eta_squared() {
    for ior in [1.333f32, 1.5, 2.4] {
        for theta in [10.0, 35.0, 60.0, 85.0] {
            for (wo, eta) in [(dir(theta, 2.0), ior), (-dir(theta.min(0.9 * (1.0 / ior as f64).asin().to_degrees()), 2.0), 1.0 / ior)] {
                let (r, t) = both_lobes(ior, wo);
                let (r, t) = (r.unwrap(), t.unwrap());
                // Reflection: mirror, weight 1.
                assert_eq!(r.wi, Vec3::new(-wo.x, -wo.y, wo.z));
                assert!(((r.f * r.wi.z.abs() / r.pdf) - Vec3::ONE).abs().max_element() < 1e-5);
                // Refraction: other side, opposite azimuth, sin θt = sin θo / η, unit length.
                assert!(t.wi.z * wo.z < 0.0 && (t.wi.length() - 1.0).abs() < 1e-5);
                let (sin_o, sin_t) = (wo.truncate().length(), t.wi.truncate().length());
                assert!((sin_t - sin_o / eta).abs() < 1e-5, "Snell: {sin_t} vs {}", sin_o / eta);
                assert!(t.wi.truncate().dot(wo.truncate()) <= 0.0);
                let w = t.f * t.wi.z.abs() / t.pdf;
                assert!((w - Vec3::splat(1.0 / (eta * eta))).abs().max_element() < 1e-5, "η {eta}: weight {w}");
            }
        }
    }
}

#[test]
fn dielectric_is_delta_with_zero_eval_and_pdf_and_rough_hints_are_sane() {
    let g = glass(1.5);
    assert!(is_delta(&g));
    assert_eq!(eval(&g, Vec3::Z, Vec3::Z), Vec3::ZERO);
    assert_eq!(pdf(&g, Vec3::Z, -Vec3::Z), 0.0);
    assert!(sample(&glass(0.0), Vec3::Z, Vec2::ZERO, 0.5).is_none());
    assert!(sample(&glass(f32::NAN), Vec3::Z, Vec2::ZERO, 0.5).is_none());
    assert!(sample(&g, Vec3::X, Vec2::ZERO, 0.5).is_none(), "ωo in the surface plane carries nothing");
    assert_eq!(albedo_hint(&g), Vec3::ONE);
    assert_eq!(albedo_hint(&lambert(0.3)), Vec3::splat(0.3));
    assert_eq!(albedo_hint(&bp(0.3, 0.5, 10.0)), Vec3::splat(0.8));
    let h = albedo_hint(&ct(0.2, 0.8, 0.3, 0.04));
    assert!(h.x > 0.2 && h.x < 0.3, "{h}");
}

#[test]
fn lobe_choice_follows_the_luminance_of_kd_against_ks() {
    // Far from a near-mirror lobe only the diffuse part of the mixture density remains, so
    // pdf = P_d cos θi / π with P_d = Y(kd) / (Y(kd) + Y(ks)).
    let kd = Vec3::new(0.6, 0.1, 0.1);
    let ks = Vec3::new(0.05, 0.2, 0.05);
    let y = |c: Vec3| 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
    let pd = y(kd) / (y(kd) + y(ks));
    let (wo, wi) = (dir(30.0, 0.0), dir(50.0, 2.5));
    for m in [Material::BlinnPhong { kd, ks, exponent: 1e4 }, Material::CookTorrance { kd, ks, roughness: 0.001, f0: 0.5 }] {
        let p = pdf(&m, wo, wi);
        let expect = pd * wi.z / std::f32::consts::PI;
        assert!((p - expect).abs() < 1e-5 * expect, "{m:?}: {p} vs {expect}");
        // And the fraction of samples drawn from the diffuse lobe is P_d: those have
        // pdf ≈ P_d cos θi / π < 1, while the near-mirror lobe's samples have pdf ≫ 1 (the
        // two groups overlap with probability < 1 %).
        let count = 20_000;
        let diffuse = (0..count).filter_map(|i| sample(&m, wo, u2(21, i), uniform(21, i, 2))).filter(|s| s.pdf < 2.0).count();
        let frac = diffuse as f32 / count as f32;
        assert!((frac - pd).abs() < 0.015, "{m:?}: {frac} vs {pd}");
    }
}
