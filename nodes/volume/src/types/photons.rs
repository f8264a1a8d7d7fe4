//! Pipeline 3's photon types ([S] 6.3.3–6.3.4): `Photons`, the beams a light shoots at a
//! medium's box (entry point, direction, RGB power), and `CausticMap`, the irradiance
//! photons bring to a planar receiver and the photons landed on every other surface.

use super::surface_photons::{Landing, SurfacePhotons};
use glam::{Vec2, Vec3};
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// Photons at their entry into a medium's box: position on the box, unit direction of travel
/// and RGB power in watts, one entry per photon (in emission order).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Photons {
    #[serde(with = "pod_vec")]
    pub position: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub direction: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub power: Vec<Vec3>,
}

impl Photons {
    pub fn len(&self) -> usize {
        self.position.len()
    }
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }
    /// Bytes of `n` photons.
    pub fn bytes_for(n: u64) -> u64 {
        n.saturating_mul(36)
    }
    /// The summed power of every photon.
    pub fn total_power(&self) -> Vec3 {
        self.power.iter().fold(Vec3::ZERO, |a, p| a + *p)
    }
    fn is_consistent(&self) -> bool {
        let n = self.position.len();
        self.direction.len() == n && self.power.len() == n
    }
}

impl PortValue for Photons {
    const NAME: &'static str = "Photons";
    const COLOR: [u8; 3] = [250, 200, 90];
    const DOC: &'static str = "photons entering a medium's box: position, direction, RGB power (W)";
    fn byte_size(&self) -> usize {
        self.len() * 36 + 64
    }
    relume_core::serde_codec!(check Photons::is_consistent);
}

/// Irradiance (W/unit², RGB) on a rectangle of a planar receiver: texel (i, j) covers
/// `origin + u · [i, i+1]/width + v · [j, j+1]/height`; lookups are bilinear between texel
/// centres. `object` is the receiver's scene object (`u32::MAX`: none, an empty map). The
/// photons that landed on any other surface are in `surface`, read by density estimation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CausticMap {
    pub object: u32,
    pub origin: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub width: u32,
    pub height: u32,
    #[serde(with = "pod_vec")]
    pub texels: Vec<Vec3>,
    pub surface: SurfacePhotons,
}

impl CausticMap {
    /// A map of no receiver (one black texel) and no photons.
    pub fn none() -> CausticMap {
        CausticMap {
            object: u32::MAX,
            origin: Vec3::ZERO,
            u: Vec3::X,
            v: Vec3::Z,
            width: 1,
            height: 1,
            texels: vec![Vec3::ZERO],
            surface: SurfacePhotons::default(),
        }
    }

    /// The irradiance photons bring to point `p` of scene object `object`, whose geometric
    /// normal on the lit side is `n`: the map's on the receiver, the landed photons' elsewhere.
    pub fn irradiance(&self, object: u32, p: Vec3, n: Vec3) -> Vec3 {
        if object == self.object {
            self.lookup(object, p)
        } else {
            self.surface.irradiance(object, p, n)
        }
    }

    /// The (s, t) ∈ [0, 1]² coordinates of `p` on the rectangle (unclamped).
    pub fn coords(&self, p: Vec3) -> Vec2 {
        let d = p - self.origin;
        Vec2::new(d.dot(self.u) / self.u.length_squared(), d.dot(self.v) / self.v.length_squared())
    }

    /// The texel holding `p`, if it lies over the rectangle.
    pub fn texel(&self, p: Vec3) -> Option<usize> {
        let c = self.coords(p);
        if !(c.x >= 0.0 && c.x < 1.0 && c.y >= 0.0 && c.y < 1.0) {
            return None;
        }
        let (i, j) = ((c.x * self.width as f32) as usize, (c.y * self.height as f32) as usize);
        Some(j.min(self.height as usize - 1) * self.width as usize + i.min(self.width as usize - 1))
    }

    /// The area of one texel.
    pub fn texel_area(&self) -> f32 {
        self.u.cross(self.v).length() / (self.width * self.height) as f32
    }

    /// The irradiance at `p` on scene object `object`: bilinear between texel centres (clamped
    /// at the edges), zero off the rectangle or on another object.
    pub fn lookup(&self, object: u32, p: Vec3) -> Vec3 {
        if object != self.object {
            return Vec3::ZERO;
        }
        let c = self.coords(p);
        if !(c.x >= 0.0 && c.x <= 1.0 && c.y >= 0.0 && c.y <= 1.0) {
            return Vec3::ZERO;
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let g = Vec2::new(c.x * w as f32 - 0.5, c.y * h as f32 - 0.5).clamp(Vec2::ZERO, Vec2::new(w as f32 - 1.0, h as f32 - 1.0));
        let (i0, j0) = (g.x as usize, g.y as usize);
        let (i1, j1) = ((i0 + 1).min(w - 1), (j0 + 1).min(h - 1));
        let f = g - Vec2::new(i0 as f32, j0 as f32);
        let at = |i: usize, j: usize| self.texels[j * w + i];
        let a = at(i0, j0).lerp(at(i1, j0), f.x);
        let b = at(i0, j1).lerp(at(i1, j1), f.x);
        a.lerp(b, f.y)
    }

    fn is_consistent(&self) -> bool {
        self.width > 0
            && self.height > 0
            && (self.width as u64 * self.height as u64) == self.texels.len() as u64
            && [self.origin, self.u, self.v].iter().all(|v| v.is_finite())
            && self.u.cross(self.v).length() > 0.0
            && self.surface.is_consistent()
    }
}

impl PortValue for CausticMap {
    const NAME: &'static str = "CausticMap";
    const COLOR: [u8; 3] = [240, 170, 60];
    const DOC: &'static str =
        "irradiance photons bring to a planar receiver, over a rectangle of it, and the photons landed on other surfaces";
    fn byte_size(&self) -> usize {
        self.texels.len() * 12 + 96 + super::surface_photons::bytes_for(self.surface.len() as u64) as usize
    }
    relume_core::serde_codec!(check CausticMap::is_consistent);
}

/// A chunk of photon marching's result (`MarchPhotons`' partial): fixed-point sums, so that
/// chunks and threads add up to the same bytes in any order — per scattering voxel (slot) the
/// length-weighted power (RGB) and the luminance-weighted direction (xyz), per caustic-map
/// texel the power landed (RGB), and counters — and the photons landed on other surfaces, in
/// the order of the photons.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhotonDeposits {
    pub volume: Vec<i64>,
    pub map: Vec<i64>,
    pub counters: Vec<u64>,
    #[serde(with = "pod_vec")]
    pub landed_position: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub landed_normal: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub landed_power: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub landed_object: Vec<u32>,
}

impl PhotonDeposits {
    /// The landed photons, in order.
    pub fn landings(&self) -> impl Iterator<Item = Landing> + '_ {
        (0..self.landed_position.len().min(self.landed_normal.len()).min(self.landed_power.len()).min(self.landed_object.len())).map(|k| {
            Landing {
                position: self.landed_position[k],
                normal: self.landed_normal[k],
                power: self.landed_power[k],
                object: self.landed_object[k],
            }
        })
    }
}

impl PortValue for PhotonDeposits {
    const NAME: &'static str = "PhotonDeposits";
    const COLOR: [u8; 3] = [230, 190, 110];
    const DOC: &'static str = "fixed-point sums of a chunk of marched photons (a sharded partial result)";
    fn byte_size(&self) -> usize {
        (self.volume.len() + self.map.len() + self.counters.len()) * 8 + self.landed_position.len() * 40 + 48
    }
    relume_core::serde_codec!();
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> CausticMap {
        let texels = (0..12).map(|k| Vec3::splat(k as f32)).collect();
        CausticMap {
            object: 3,
            origin: Vec3::new(-2.0, 0.0, -1.0),
            u: Vec3::new(4.0, 0.0, 0.0),
            v: Vec3::new(0.0, 0.0, 3.0),
            width: 4,
            height: 3,
            texels,
            surface: SurfacePhotons::default(),
        }
    }

    #[test]
    fn texels_and_lookups_follow_the_rectangle() {
        let m = map();
        assert_eq!(m.texel_area(), 1.0);
        assert_eq!(m.texel(Vec3::new(-1.5, 0.0, -0.5)), Some(0));
        assert_eq!(m.texel(Vec3::new(1.5, 0.0, 1.5)), Some(11));
        assert_eq!(m.texel(Vec3::new(2.5, 0.0, 1.5)), None);
        // At a texel centre the lookup is the texel; between two, their mean.
        assert_eq!(m.lookup(3, Vec3::new(-0.5, 0.0, 0.5)), Vec3::splat(5.0));
        assert_eq!(m.lookup(3, Vec3::new(0.0, 0.0, 0.5)), Vec3::splat(5.5));
        assert_eq!(m.lookup(2, Vec3::new(0.0, 0.0, 0.5)), Vec3::ZERO, "another object");
        assert_eq!(m.lookup(3, Vec3::new(9.0, 0.0, 0.5)), Vec3::ZERO, "off the rectangle");
    }

    #[test]
    fn round_trips_and_bad_bytes_decode_to_none() {
        let m = map();
        assert_eq!(CausticMap::decode(&m.encode()).unwrap(), m);
        let mut bad = m.clone();
        bad.width = 5;
        assert!(CausticMap::decode(&bad.encode()).is_none());
        let b = m.encode();
        assert!(CausticMap::decode(&b[..b.len() - 1]).is_none());
        let p = Photons { position: vec![Vec3::ONE], direction: vec![Vec3::X], power: vec![Vec3::splat(2.0)] };
        assert_eq!(Photons::decode(&p.encode()).unwrap(), p);
        let mut bad = p;
        bad.power.push(Vec3::ONE);
        assert!(Photons::decode(&bad.encode()).is_none());
    }
}
