//! The photons that land on surfaces other than the caustic map's planar receiver, kept as
//! points and read back by density estimation: the irradiance at a point is the power of the
//! photons within `radius` on the same object and facing the same way, weighted by the 2-D
//! Epanechnikov kernel 2 / (π r²) (1 − d² / r²). Photons are sorted into cells of side
//! `radius` (by cell, then in the order they came), so a lookup reads the 27 cells around the
//! point and every sum runs in one fixed order.

use glam::{IVec3, Vec3};
use relume_core::codec::pod_vec;
use serde::{Deserialize, Serialize};

/// One landed photon, as a march's chunk records it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landing {
    pub position: Vec3,
    /// The surface's geometric normal on the side the photon came from (unit).
    pub normal: Vec3,
    pub power: Vec3,
    pub object: u32,
}

/// Landed photons on the scene's surfaces, in cells of side `radius` (see the module's doc).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SurfacePhotons {
    /// The density estimate's radius (scene units); 0 when empty.
    pub radius: f32,
    #[serde(with = "pod_vec")]
    pub position: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub normal: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub power: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub object: Vec<u32>,
    /// The occupied cells' coordinates, ascending (x, then y, then z), each with where its
    /// photons start; `cell_start` has one more entry, the end.
    #[serde(with = "pod_vec")]
    pub cells: Vec<IVec3>,
    #[serde(with = "pod_vec")]
    pub cell_start: Vec<u32>,
}

/// Bytes a store of `n` photons takes (each photon and, at most, a cell of its own).
pub fn bytes_for(n: u64) -> u64 {
    n.saturating_mul(40 + 16) + 64
}

/// The least cos between a photon's surface normal and a lookup's for the photon to count.
const SAME_SIDE: f32 = 0.5;

impl SurfacePhotons {
    /// The store of `landed` (in the order given, which ties keep) for lookups of `radius`.
    pub fn new(landed: &[Landing], radius: f32) -> SurfacePhotons {
        if landed.is_empty() || !(radius > 0.0 && radius.is_finite()) {
            return SurfacePhotons::default();
        }
        let cell = |p: Vec3| (p / radius).floor().as_ivec3();
        let mut order: Vec<usize> = (0..landed.len()).collect();
        order.sort_by_key(|&k| {
            let c = cell(landed[k].position);
            (c.x, c.y, c.z, k)
        });
        let mut s = SurfacePhotons { radius, ..Default::default() };
        for &k in &order {
            let l = landed[k];
            let c = cell(l.position);
            if s.cells.last() != Some(&c) {
                s.cells.push(c);
                s.cell_start.push(s.position.len() as u32);
            }
            s.position.push(l.position);
            s.normal.push(l.normal);
            s.power.push(l.power);
            s.object.push(l.object);
        }
        s.cell_start.push(s.position.len() as u32);
        s
    }

    pub fn len(&self) -> usize {
        self.position.len()
    }

    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// The irradiance (W/unit², RGB) the photons bring to point `p` of object `object` whose
    /// geometric normal is `n` (unit, on the side being lit).
    pub fn irradiance(&self, object: u32, p: Vec3, n: Vec3) -> Vec3 {
        if self.is_empty() {
            return Vec3::ZERO;
        }
        let r2 = self.radius * self.radius;
        let centre = (p / self.radius).floor().as_ivec3();
        // Where `p` lies in its cell, in cell units: a neighbour whose nearest point is a
        // radius away or more holds no photon within it, and is skipped.
        let f = p / self.radius - centre.as_vec3();
        let gap = |d: i32, f: f32| match d {
            -1 => f,
            1 => 1.0 - f,
            _ => 0.0,
        };
        let mut sum = Vec3::ZERO;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let (gx, gy, gz) = (gap(dx, f.x), gap(dy, f.y), gap(dz, f.z));
                    if gx * gx + gy * gy + gz * gz >= 1.0 {
                        continue;
                    }
                    let c = centre + IVec3::new(dx, dy, dz);
                    let Ok(i) = self.cells.binary_search_by(|q| (q.x, q.y, q.z).cmp(&(c.x, c.y, c.z))) else { continue };
                    for k in self.cell_start[i] as usize..self.cell_start[i + 1] as usize {
                        let d2 = self.position[k].distance_squared(p);
                        if d2 < r2 && self.object[k] == object && self.normal[k].dot(n) > SAME_SIDE {
                            sum += self.power[k] * (1.0 - d2 / r2);
                        }
                    }
                }
            }
        }
        sum * (2.0 / (std::f32::consts::PI * r2))
    }

    /// The summed power of every photon (summed in f64).
    pub fn total_power(&self) -> Vec3 {
        self.power.iter().fold(glam::DVec3::ZERO, |a, p| a + p.as_dvec3()).as_vec3()
    }

    pub(crate) fn is_consistent(&self) -> bool {
        let n = self.position.len();
        let cells_ok = if n == 0 {
            self.cells.is_empty() && self.cell_start.is_empty()
        } else {
            self.cell_start.len() == self.cells.len() + 1
                && self.cell_start.first() == Some(&0)
                && self.cell_start.last() == Some(&(n as u32))
                && self.cell_start.windows(2).all(|w| w[0] < w[1])
                && self.cells.windows(2).all(|w| (w[0].x, w[0].y, w[0].z) < (w[1].x, w[1].y, w[1].z))
        };
        self.normal.len() == n
            && self.power.len() == n
            && self.object.len() == n
            && cells_ok
            && self.radius.is_finite()
            && self.radius >= 0.0
            && (n == 0 || self.radius > 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f32, z: f32, power: f32, object: u32) -> Landing {
        Landing { position: Vec3::new(x, 0.0, z), normal: Vec3::Y, power: Vec3::splat(power), object }
    }

    #[test]
    fn a_uniform_rain_of_photons_gives_its_irradiance_and_keeps_to_its_object_and_side() {
        // Photons of 1 mW on a 0.01 grid over a 2 × 2 plane: 10 W/unit² everywhere inside.
        let mut landed = Vec::new();
        for i in 0..200 {
            for j in 0..200 {
                landed.push(at(-1.0 + (i as f32 + 0.5) * 0.01, -1.0 + (j as f32 + 0.5) * 0.01, 1e-3, 2));
            }
        }
        let s = SurfacePhotons::new(&landed, 0.1);
        assert_eq!(s.len(), 40_000);
        for p in [Vec3::ZERO, Vec3::new(0.3, 0.0, -0.55), Vec3::new(-0.7, 0.0, 0.7)] {
            let e = s.irradiance(2, p, Vec3::Y).x;
            assert!((e - 10.0).abs() < 0.2, "{p}: {e}");
        }
        assert_eq!(s.irradiance(3, Vec3::ZERO, Vec3::Y), Vec3::ZERO, "another object");
        assert_eq!(s.irradiance(2, Vec3::ZERO, -Vec3::Y), Vec3::ZERO, "the other side");
        assert_eq!(s.irradiance(2, Vec3::new(5.0, 0.0, 0.0), Vec3::Y), Vec3::ZERO, "far away");
        assert!((s.total_power().x - 40.0).abs() < 1e-3);
    }

    #[test]
    fn the_same_photons_in_any_order_of_cells_give_the_same_bytes_and_bad_stores_are_refused() {
        let landed = vec![at(0.05, 0.0, 1.0, 0), at(-0.3, 0.2, 2.0, 0), at(0.06, 0.01, 3.0, 0)];
        let s = SurfacePhotons::new(&landed, 0.1);
        assert!(s.is_consistent());
        assert_eq!(s.cells.len(), 2);
        let e = s.irradiance(0, Vec3::new(0.05, 0.0, 0.0), Vec3::Y);
        let expected = (1.0 + 3.0 * (1.0 - (0.01f32 * 0.01 + 0.01 * 0.01) / 0.01)) * 2.0 / (std::f32::consts::PI * 0.01);
        assert!((e.x - expected).abs() < 1e-3 * expected, "{e} against {expected}");
        let mut bad = s.clone();
        bad.cell_start[1] = 9;
        assert!(!bad.is_consistent());
        assert!(SurfacePhotons::new(&[], 0.1).is_consistent());
        assert_eq!(SurfacePhotons::new(&landed, 0.0), SurfacePhotons::default());
    }
}
