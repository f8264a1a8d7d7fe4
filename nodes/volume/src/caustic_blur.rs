//! The caustic map's blur, kept on each side of the shadow's edge. The render lights a
//! receiver point directly only where its straight line to the light crosses no voxel that may
//! bend rays; the rest of that light arrives as photons, in the map. A plain Gaussian on the
//! map spreads photons landing just inside a shadow onto floor the shadow rays already light
//! (a bright band along the shadow's rim). Here each texel first gets its darkness — the
//! fraction f of lamp points whose straight line from the texel's centre crosses bends, as
//! the render's shadow rays test it — and a texel's photons are shared among its neighbours in
//! proportion to the Gaussian times the neighbour's f, the part of its light the shadow rays
//! leave to the photons. A texel with no dark neighbour (light bent onto floor the shadow rays
//! light in full) spreads by the plain Gaussian. Each source's weights are normalised over its
//! neighbours inside the map, so the map's power is kept. Each output texel is one fixed-order
//! sum: the same bytes on any thread count.

use super::blur::kernel;
use super::optics::{lamp_segment, Clearance, PhotonLight};
use crate::types::CausticMap;
use glam::Vec3;
use rayon::prelude::*;
use relume_base::render::lights::delta_sample;
use relume_core::{NodeError, RunCtx};

/// Lamp points a texel's darkness is tested at for a light of some size (one for a point).
const LAMP_POINTS: usize = 8;

/// Bytes a blur of a map of `texels` texels needs beyond the map itself (the darkness, each
/// source's weight sum and the output).
pub fn working_bytes(texels: u64) -> u64 {
    texels * (4 + 4 + 12)
}

/// `raw` (RGB, `map.width × map.height` row-major, texels of `map`) blurred by a Gaussian of
/// `radius` texels (σ = radius) that does not cross the shadow's edge under `lights`.
pub fn blur_caustics(
    raw: &[Vec3],
    map: &CausticMap,
    lights: &[PhotonLight],
    clearance: &Clearance,
    radius: usize,
    cx: &RunCtx,
) -> Result<Vec<Vec3>, NodeError> {
    if radius == 0 {
        return Ok(raw.to_vec());
    }
    let (w, h) = (map.width as usize, map.height as usize);
    let k = kernel(radius, radius as f32);
    let r = radius as i64;
    // Texels some photon's share reaches: only their darkness is needed.
    let mut near = vec![false; w * h];
    for (s, _) in raw.iter().enumerate().filter(|(_, v)| **v != Vec3::ZERO) {
        let (x, y) = ((s % w) as i64, (s / w) as i64);
        for j in (y - r).max(0)..=(y + r).min(h as i64 - 1) {
            let row = j as usize * w;
            near[row + (x - r).max(0) as usize..=row + (x + r).min(w as i64 - 1) as usize].fill(true);
        }
    }
    let dark = darkness_map(map, lights, clearance, &near, cx)?;
    // Per source with photons: Σ over its neighbours inside the map of Gaussian × darkness,
    // or −Σ Gaussian where none is dark (then it spreads by the plain Gaussian).
    let mut total = vec![0.0f32; w * h];
    cx.par_chunks_mut(&mut total, w, |y, row| {
        for (x, t) in row.iter_mut().enumerate() {
            if raw[y * w + x] == Vec3::ZERO {
                continue;
            }
            let (mut dark_sum, mut plain) = (0.0f32, 0.0f32);
            for (j, &kj) in taps(y, h, r, &k) {
                for (i, &ki) in taps(x, w, r, &k) {
                    dark_sum += kj * ki * dark[j * w + i];
                    plain += kj * ki;
                }
            }
            *t = if dark_sum > 0.0 { dark_sum } else { -plain };
        }
    })?;
    let mut out = vec![Vec3::ZERO; w * h];
    cx.par_chunks_mut(&mut out, w, |y, row| {
        for (x, o) in row.iter_mut().enumerate() {
            if !near[y * w + x] {
                continue;
            }
            let f = dark[y * w + x];
            for (j, &kj) in taps(y, h, r, &k) {
                for (i, &ki) in taps(x, w, r, &k) {
                    let s = j * w + i;
                    if raw[s] != Vec3::ZERO {
                        let share = if total[s] > 0.0 { f / total[s] } else { -1.0 / total[s] };
                        *o += raw[s] * (kj * ki * share);
                    }
                }
            }
        }
    })?;
    Ok(out)
}

/// The positions within `r` of `c` on an axis of `n` texels, with the kernel's weight of each
/// (the kernel is symmetric, so a source's weight to a target is the target's from it).
fn taps(c: usize, n: usize, r: i64, k: &[f32]) -> impl Iterator<Item = (usize, &f32)> {
    let c = c as i64;
    ((c - r).max(0)..=(c + r).min(n as i64 - 1)).map(move |q| (q as usize, &k[(q - c + r) as usize]))
}

/// The darkness of the texels marked `near` (0 elsewhere). Each first from the lines to the
/// lamps' centres alone; then from every lamp point for the texels along an edge of that
/// first answer and, growing out from them, for every neighbour of a texel found in a
/// penumbra (darkness strictly between 0 and 1), until the penumbra's band is covered. A
/// texel is the same function of its position whatever order this takes.
fn darkness_map(
    map: &CausticMap,
    lights: &[PhotonLight],
    clearance: &Clearance,
    near: &[bool],
    cx: &RunCtx,
) -> Result<Vec<f32>, NodeError> {
    let (w, h) = (map.width as usize, map.height as usize);
    let centre = |t: usize| map.origin + map.u * (((t % w) as f32 + 0.5) / w as f32) + map.v * (((t / w) as f32 + 0.5) / h as f32);
    let mut dark = vec![0.0f32; w * h];
    cx.par_chunks_mut(&mut dark, w, |y, row| {
        for (x, d) in row.iter_mut().enumerate() {
            if near[y * w + x] {
                *d = darkness(centre(y * w + x), lights, clearance, 1);
            }
        }
    })?;
    let neighbours = |t: usize| {
        let (x, y) = (t % w, t / w);
        [(x > 0).then(|| t - 1), (x + 1 < w).then(|| t + 1), (y > 0).then(|| t - w), (y + 1 < h).then(|| t + w)].into_iter().flatten()
    };
    let mut done = vec![false; w * h];
    let mut next: Vec<usize> = (0..w * h).filter(|&t| near[t] && neighbours(t).any(|q| near[q] && dark[q] != dark[t])).collect();
    next.iter().for_each(|&t| done[t] = true);
    while !next.is_empty() {
        cx.check()?;
        let found: Vec<f32> = next.par_iter().map(|&t| darkness(centre(t), lights, clearance, LAMP_POINTS)).collect();
        let mut grow = Vec::new();
        for (&t, &f) in next.iter().zip(&found) {
            dark[t] = f;
            if f > 0.0 && f < 1.0 {
                for q in neighbours(t) {
                    if near[q] && !done[q] {
                        done[q] = true;
                        grow.push(q);
                    }
                }
            }
        }
        grow.sort_unstable();
        next = grow;
    }
    Ok(dark)
}

/// The most of any light's lamp points (`points` of them for a light of some size, its centre
/// alone for a point) whose straight line from `p` crosses voxels where rays bend: 1 deep in
/// a shadow the photons light, 0 where the shadow rays light `p`.
fn darkness(p: Vec3, lights: &[PhotonLight], clearance: &Clearance, points: usize) -> f32 {
    let mut most = 0.0f32;
    for l in lights {
        let Some((wi, dist, _)) = delta_sample(&l.light, p) else { continue };
        let n = if l.radius > 0.0 && dist.is_finite() { points } else { 1 };
        let mut crossed = 0;
        for j in 0..n {
            let (dir, len) = if n == 1 {
                (wi, if dist.is_finite() { (dist - l.radius * 1.001) * (1.0 - 1e-4) } else { f32::INFINITY })
            } else {
                // Stratified over the disk's area, the same points for every texel.
                let u = ((j as f32 + 0.5) / n as f32, (j as f32 * 0.618_034 + 0.5).fract());
                lamp_segment(p, p + wi * dist, l.radius, -wi, u)
            };
            if len > 0.0 && clearance.crosses_bends(p, dir, len) {
                crossed += 1;
            }
        }
        most = most.max(crossed as f32 / n as f32);
    }
    most
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::{photon_lights, planar_frame};
    use crate::test_support::*;

    /// The glass scene's floor as a map of `texels` across, its lights and the clearance of
    /// its sphere voxelised at 32³.
    fn setup(texels: u32) -> (CausticMap, Vec<PhotonLight>, std::sync::Arc<Clearance>) {
        let s = glass();
        let floor = s.objects.iter().position(|o| o.name == "floor").unwrap();
        let (origin, u, v) = planar_frame(&s, floor).unwrap();
        let map = CausticMap {
            object: floor as u32,
            origin,
            u,
            v,
            width: texels,
            height: texels,
            texels: Vec::new(),
            surface: Default::default(),
        };
        let oct = octree_of(&voxelize(&s, "glass", 32));
        (map, photon_lights(&s), Clearance::shared(&oct))
    }

    fn every(n: usize) -> Vec<bool> {
        vec![true; n]
    }

    #[test]
    fn the_darkness_is_that_of_every_lamp_point_everywhere_though_only_the_penumbra_tests_them_all() {
        let (map, lights, c) = setup(48);
        let n = (map.width * map.height) as usize;
        let dark = with_cx(|cx| darkness_map(&map, &lights, &c, &every(n), cx)).unwrap();
        let full: Vec<f32> = (0..n)
            .map(|t| {
                let p = map.origin + map.u * (((t % 48) as f32 + 0.5) / 48.0) + map.v * (((t / 48) as f32 + 0.5) / 48.0);
                darkness(p, &lights, &c, LAMP_POINTS)
            })
            .collect();
        assert_eq!(dark, full);
        let (lit, shade, pen) = (
            dark.iter().filter(|&&f| f == 0.0).count(),
            dark.iter().filter(|&&f| f == 1.0).count(),
            dark.iter().filter(|&&f| f > 0.0 && f < 1.0).count(),
        );
        assert!(lit > n / 2 && shade > 20 && pen > 10, "lit {lit}, shadow {shade}, penumbra {pen}");
    }

    #[test]
    fn photons_in_the_shadow_stay_off_the_lit_floor_and_the_power_is_kept() {
        let (map, lights, c) = setup(48);
        let n = (map.width * map.height) as usize;
        let dark = with_cx(|cx| darkness_map(&map, &lights, &c, &every(n), cx)).unwrap();
        // A deposit on every texel of the shadow and its penumbra.
        let raw: Vec<Vec3> =
            dark.iter().enumerate().map(|(t, &f)| if f > 0.0 { Vec3::splat(1.0 + (t % 7) as f32) } else { Vec3::ZERO }).collect();
        for radius in [1, 2] {
            let out = with_cx(|cx| blur_caustics(&raw, &map, &lights, &c, radius, cx)).unwrap();
            for t in 0..n {
                if dark[t] == 0.0 {
                    assert_eq!(out[t], Vec3::ZERO, "lit texel {t} got light across the shadow's edge");
                }
            }
            let (a, b) = (raw.iter().map(|v| v.x as f64).sum::<f64>(), out.iter().map(|v| v.x as f64).sum::<f64>());
            assert!((a - b).abs() < 1e-5 * a, "power {a} → {b}");
        }
    }

    #[test]
    fn where_nothing_bends_it_is_the_normalised_gaussian() {
        let (map, lights, _) = setup(16);
        let flat = octree_of(&source("Constant", 8, Vec3::new(0.0, 0.6, 0.0), 1.2, &[]));
        let c = Clearance::shared(&flat);
        let mut raw = vec![Vec3::ZERO; 256];
        raw[5 * 16 + 7] = Vec3::ONE;
        raw[0] = Vec3::splat(2.0);
        let out = with_cx(|cx| blur_caustics(&raw, &map, &lights, &c, 1, cx)).unwrap();
        let k = kernel(1, 1.0);
        for (j, kj) in k.iter().enumerate() {
            for (i, ki) in k.iter().enumerate() {
                let got = out[(4 + j) * 16 + 6 + i].x;
                assert!((got - kj * ki).abs() < 1e-6, "({i}, {j}): {got} against {}", kj * ki);
            }
        }
        // In a corner the share meant for outside the map stays inside it.
        let corner = out[0].x + out[1].x + out[16].x + out[17].x;
        assert!((corner - 2.0).abs() < 1e-5, "{corner}");
    }

    #[test]
    fn a_zero_radius_leaves_the_map_as_it_is() {
        let (map, lights, c) = setup(8);
        let raw: Vec<Vec3> = (0..64).map(|t| Vec3::splat(t as f32)).collect();
        assert_eq!(with_cx(|cx| blur_caustics(&raw, &map, &lights, &c, 0, cx)).unwrap(), raw);
    }
}
