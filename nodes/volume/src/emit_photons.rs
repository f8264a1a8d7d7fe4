use super::optics::{across, box_interval, intensity_along, lamp_point, luminance, photon_lights, PhotonLight};
use crate::types::{Photons, Volume};
use glam::Vec3;
use relume_base::math::cubemap::rect_solid_angle;
use relume_base::math::rng::uniform;
use relume_base::types::{Accel, Light, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

params! {
    /// Photons from every light into a medium's box, shadow-map style ([S] 6.3.3): each light
    /// looks at the proxy through a `resolution`² image (a frustum around the proxy's bounding
    /// sphere for point and spot lights, a square across it for directional ones); every texel
    /// whose ray (jittered inside the texel, seeded) reaches the proxy unoccluded emits one photon
    /// at the entry point. Power: the light's intensity along the ray × the texel's exact solid
    /// angle (point, spot), or the irradiance × the texel's area (directional) — so an empty
    /// volume under a directional light holds fluence E. Emissive objects become lights of the
    /// same power at their centroids, each photon leaving from a seeded point of the disk the
    /// object shows along its direction, as a uniformly bright sphere sends it
    /// (`optics::photon_lights`, `optics::lamp_point`). The proxy is the box of the
    /// voxels that differ from empty space (n ≠ 1 or κ > 0), one voxel wider (`Active`: photons
    /// through the rest would go straight and deposit nothing), or the whole box. A light inside
    /// the proxy is an error. Rows in parallel, the same photons on any thread count.
    pub struct EmitPhotons {
        /// texels across the light's view of the proxy (photons ≤ resolution² per light)
        pub resolution: u32 = 1024, range = 1..=8192, unit = "texels", test = 64;
        /// where photons enter: the active part of the medium or its whole box
        pub proxy: Proxy = Active;
        /// seed of the jitter inside texels
        pub seed: u32 = 1, range = 0..=1000000;
    }
}

/// What the lights aim photons at.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum Proxy {
    /// the box of voxels that differ from empty space, one voxel wider
    Active,
    /// the medium's whole box
    Box,
}

/// The box of voxels of `m` with n ≠ 1 or κ > 0, one voxel wider (clamped to the box), if any.
pub fn active_box(m: &Volume) -> Option<(Vec3, Vec3)> {
    use rayon::prelude::*;
    let d = m.dims.map(|x| x as usize);
    let ch = m.channels as usize;
    // Rows in parallel; a min and a max come out the same in any order.
    let (lo, hi) = m
        .data
        .par_chunks(d[0] * ch)
        .enumerate()
        .map(|(r, row)| {
            let (y, z) = (r % d[1], r / d[1]);
            let active = |c: &[f32]| c[0] != 1.0 || (ch > 1 && c[1] > 0.0);
            match (row.chunks(ch).position(active), row.chunks(ch).rposition(active)) {
                (Some(x0), Some(x1)) => ([x0, y, z], [x1, y, z]),
                _ => ([usize::MAX; 3], [0; 3]),
            }
        })
        .reduce(|| ([usize::MAX; 3], [0; 3]), |a, b| ([0, 1, 2].map(|k| a.0[k].min(b.0[k])), [0, 1, 2].map(|k| a.1[k].max(b.1[k]))));
    if lo[0] == usize::MAX {
        return None;
    }
    let h = m.voxel();
    let a = Vec3::from(lo.map(|c| c.saturating_sub(1) as f32));
    let b = Vec3::from([0, 1, 2].map(|k| (hi[k] + 2).min(d[k]) as f32));
    Some((m.min + a * h, m.min + b * h))
}

/// The photons of light `l` (number `k` among the lights) into the box `lo … hi`.
fn emit_one(l: &PhotonLight, k: u32, lo: Vec3, hi: Vec3, accel: &Accel, p: &EmitPhotons, cx: &RunCtx) -> Result<Photons, NodeError> {
    let res = p.resolution as usize;
    let c = (lo + hi) / 2.0;
    let r = (hi - lo).length() / 2.0;
    let seed = ((p.seed as u64) << 16) ^ k as u64;
    let eps = 1e-5 * (1.0 + r + c.abs().max_element());
    let rows = match l.light {
        Light::Directional { direction, irradiance } => {
            let w = direction.normalize();
            let (e1, e2) = across(w);
            let side = 2.0 * r / res as f32;
            let power = irradiance * side * side;
            cx.par_map(res, |j| {
                let mut out = Vec::new();
                for i in 0..res {
                    let id = (j * res + i) as u64;
                    let (x, y) = ((i as f32 + uniform(seed, id, 0)) * side - r, (j as f32 + uniform(seed, id, 1)) * side - r);
                    let o = c - w * (2.0 * r) + e1 * x + e2 * y;
                    if let Some((t0, _)) = box_interval(o, w, lo, hi) {
                        let entry = o + w * t0;
                        if !accel.occluded(entry, -w, eps, f32::INFINITY) {
                            out.push((entry, w, power));
                        }
                    }
                }
                out
            })?
        }
        Light::Point { position, .. } | Light::Spot { position, .. } => {
            let to = c - position;
            let dist = to.length();
            if dist <= r * 1.0001 {
                return Err(NodeError::failed(format!(
                    "the light at {position} is inside the medium's proxy (centre {c}, radius {r}): photons are shot from outside it; move the light out"
                )));
            }
            let w = to / dist;
            let (e1, e2) = across(w);
            let tan = (r / (dist * dist - r * r).sqrt()) as f64;
            let side = 2.0 * tan / res as f64;
            let start = l.radius * 1.001;
            cx.par_map(res, |j| {
                let mut out = Vec::new();
                for i in 0..res {
                    let id = (j * res + i) as u64;
                    let (x0, y0) = (i as f64 * side - tan, j as f64 * side - tan);
                    let (x, y) = (x0 + side * uniform(seed, id, 0) as f64, y0 + side * uniform(seed, id, 1) as f64);
                    let d = (w + e1 * x as f32 + e2 * y as f32).normalize();
                    // A lamp of some size sends this direction's light from all of its disk.
                    let o = lamp_point(position, l.radius, d, (uniform(seed, id, 2), uniform(seed, id, 3)));
                    let Some((t0, _)) = box_interval(o, d, lo, hi) else { continue };
                    if t0 <= start || accel.occluded(o, d, start, t0) {
                        continue;
                    }
                    let power = intensity_along(&l.light, d) * rect_solid_angle(x0, x0 + side, y0, y0 + side) as f32;
                    if power.max_element() > 0.0 {
                        out.push((o + d * t0, d, power));
                    }
                }
                out
            })?
        }
    };
    let mut ph = Photons::default();
    for (x, d, power) in rows.into_iter().flatten() {
        ph.position.push(x);
        ph.direction.push(d);
        ph.power.push(power);
    }
    Ok(ph)
}

/// The photons of every light of `scene` into `medium` (see the node's doc).
pub fn emit(scene: &Scene, accel: &Accel, medium: &Volume, p: &EmitPhotons, cx: &RunCtx) -> Result<Photons, NodeError> {
    let lights = photon_lights(scene);
    let most = Photons::bytes_for((p.resolution as u64).pow(2).saturating_mul(lights.len() as u64));
    if most > cx.memory_budget() {
        return Err(NodeError::OverLimit {
            param: Some("resolution".into()),
            msg: format!(
                "{} lights at {}² texels may emit {} of photons, over the {} budget: lower the resolution",
                lights.len(),
                p.resolution,
                fmt_bytes(most),
                fmt_bytes(cx.memory_budget())
            ),
        });
    }
    let (lo, hi) = match p.proxy {
        Proxy::Box => (medium.min, medium.max),
        Proxy::Active => match active_box(medium) {
            Some(b) => b,
            None => {
                cx.note("the medium is empty space everywhere (n = 1, κ = 0): no photons needed");
                return Ok(Photons::default());
            }
        },
    };
    let mut all = Photons::default();
    for (k, l) in lights.iter().enumerate() {
        cx.phase(k as f64 / lights.len() as f64, (k + 1) as f64 / lights.len() as f64);
        let ph = emit_one(l, k as u32, lo, hi, accel, p, cx)?;
        all.position.extend(ph.position);
        all.direction.extend(ph.direction);
        all.power.extend(ph.power);
    }
    Ok(all)
}

#[node(category = "volume", version = 2, metrics = ["photons", "lights", "power_w"], outputs = [photons])]
impl EmitPhotons {
    fn memory(&self, _inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let most = Photons::bytes_for((self.resolution as u64).pow(2));
        relume_core::MemoryEstimate { outputs: vec![Some(relume_core::PortSize::bytes(most))], working: most }
    }

    fn run(&self, scene: &Scene, accel: &Accel, medium: &Volume, cx: &RunCtx) -> Result<Photons, NodeError> {
        let photons = emit(scene, accel, medium, self, cx)?;
        cx.metric("photons", photons.len() as f64);
        cx.metric("lights", photon_lights(scene).len() as f64);
        cx.metric("power_w", luminance(photons.total_power()) as f64);
        Ok(photons)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::types::accel::BuildQuality;
    use relume_core::CancelToken;

    pub(crate) fn empty_scene(lights: Vec<Light>) -> Scene {
        let mut s = relume_base::testing::test_scene::spheres();
        s.objects.clear();
        s.triangles.clear();
        s.tri_object.clear();
        s.lights = lights;
        s
    }

    fn medium(n: f32) -> Volume {
        let mut m = Volume::try_new([8; 3], 3, Vec3::splat(-1.0), Vec3::ONE, 0.0, u64::MAX).unwrap();
        for c in m.data.chunks_mut(3) {
            c[0] = n;
        }
        m
    }

    fn run(scene: &Scene, m: &Volume, p: &EmitPhotons) -> Photons {
        let cancel = CancelToken::new();
        let cx = RunCtx::new("t", &cancel, None);
        let accel = Accel::build(scene, BuildQuality::Fast);
        emit(scene, &accel, m, p, &cx).unwrap()
    }

    #[test]
    fn a_directional_light_gives_its_irradiance_times_the_cross_section() {
        let e = Vec3::new(2.0, 1.0, 0.5);
        let s = empty_scene(vec![Light::Directional { direction: -Vec3::Y, irradiance: e }]);
        let p = EmitPhotons { resolution: 128, proxy: Proxy::Box, seed: 1 };
        let ph = run(&s, &medium(1.5), &p);
        // The box's cross-section facing the light is 2 × 2.
        let total = ph.total_power();
        assert!((total / (e * 4.0) - 1.0).abs().max_element() < 0.02, "{total}");
        assert!(ph.position.iter().all(|x| (x.y - 1.0).abs() < 1e-4), "entering through the top face");
        assert!(ph.direction.iter().all(|d| *d == -Vec3::Y));
        // The same photons again (seeded), others with another seed.
        assert_eq!(run(&s, &medium(1.5), &p), ph);
        assert_ne!(run(&s, &medium(1.5), &EmitPhotons { seed: 2, ..p }).position, ph.position);
    }

    #[test]
    fn a_point_light_gives_its_intensity_times_the_solid_angle_of_the_box() {
        let i = Vec3::splat(3.0);
        let s = empty_scene(vec![Light::Point { position: Vec3::new(0.0, 5.0, 0.0), intensity: i }]);
        let p = EmitPhotons { resolution: 200, proxy: Proxy::Box, seed: 1 };
        let ph = run(&s, &medium(1.2), &p);
        // The top face (2 × 2 at distance 4) and the sides seen past it: the box's solid angle
        // from (0, 5, 0) is that of the top face's rectangle plus the sides' slivers; compare
        // with the exact solid angle of the top face alone as a lower bound and the bounding
        // sphere's as an upper bound.
        let top = 4.0 * rect_solid_angle(0.0, 0.25, 0.0, 0.25) as f32;
        let total = ph.total_power().x / 3.0;
        let r = 3f32.sqrt();
        let cap = 2.0 * std::f32::consts::PI * (1.0 - (1.0 - (r / 5.0).powi(2)).sqrt());
        assert!(total > top * 0.99 && total < cap, "{top} < {total} < {cap}");
        // Only the top face is seen from above at this distance? No: sides too, at grazing
        // angles; the photons enter at the box's surface either way.
        assert!(ph.position.iter().all(|x| x.abs().max_element() > 0.9999));
    }

    #[test]
    fn a_lamp_of_some_size_sends_each_direction_from_all_of_its_disk() {
        // An emissive sphere of radius 0.3 five units above the box: every photon's line
        // passes within 0.3 of its centre, spread over the disk by area (mean squared distance
        // r²/2), and the power stays that of a point lamp of the same intensity.
        use relume_base::scene::builder::SceneBuilder;
        let (c, r) = (Vec3::new(0.0, 5.0, 0.0), 0.3);
        let black = relume_base::types::Material::Lambert { albedo: Vec3::ZERO };
        let lamp =
            SceneBuilder::new(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO, 40.0, 4, 4).sphere("lamp", c, r, black, Vec3::ONE, false).build();
        let p = EmitPhotons { resolution: 200, proxy: Proxy::Box, seed: 1 };
        let ph = run(&lamp, &medium(1.2), &p);
        let dist2: Vec<f32> = ph.position.iter().zip(&ph.direction).map(|(x, d)| (c - *x).cross(*d).length_squared()).collect();
        assert!(dist2.iter().all(|&q| q <= r * r * 1.0001), "every line passes through the disk");
        let mean = dist2.iter().sum::<f32>() / dist2.len() as f32;
        assert!((mean / (r * r / 2.0) - 1.0).abs() < 0.05, "mean squared distance {mean}, area-uniform {}", r * r / 2.0);
        let point = photon_lights(&lamp).pop().unwrap().light;
        let as_point = run(&empty_scene(vec![point]), &medium(1.2), &p).total_power();
        let ratio = ph.total_power() / as_point;
        assert!((ratio - Vec3::ONE).abs().max_element() < 0.05, "{ratio}");
    }

    #[test]
    fn an_empty_medium_needs_no_photons_and_the_active_box_hugs_what_is_not_empty() {
        let s = empty_scene(vec![Light::Directional { direction: -Vec3::Y, irradiance: Vec3::ONE }]);
        let p = EmitPhotons { resolution: 16, proxy: Proxy::Active, seed: 1 };
        assert!(run(&s, &medium(1.0), &p).is_empty());
        let mut m = medium(1.0);
        let i = m.index(3, 4, 5);
        m.data[i] = 1.3;
        let (lo, hi) = active_box(&m).unwrap();
        assert_eq!((lo, hi), (Vec3::new(-0.5, -0.25, 0.0), Vec3::new(0.25, 0.5, 0.75)), "voxels 2…4, 3…5, 4…6");
        // An absorbing voxel of index 1 elsewhere (another row and slice, at the grid's edge):
        // the box spans both, clamped to the grid.
        let i = m.index(6, 1, 2);
        m.data[i + 1] = 0.5;
        let (lo, hi) = active_box(&m).unwrap();
        assert_eq!((lo, hi), (Vec3::new(-0.5, -1.0, -0.75), Vec3::new(1.0, 0.5, 0.75)), "voxels 2…7, 0…5, 1…6");
        let e = {
            let s = empty_scene(vec![Light::Point { position: Vec3::ZERO, intensity: Vec3::ONE }]);
            let cancel = CancelToken::new();
            let cx = RunCtx::new("t", &cancel, None);
            emit(&s, &Accel::build(&s, BuildQuality::Fast), &medium(1.5), &p, &cx).unwrap_err().to_string()
        };
        assert!(e.contains("inside the medium's proxy"), "{e}");
    }
}
