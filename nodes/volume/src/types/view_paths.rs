//! `ViewPaths`: the camera's curved rays through a medium (pipeline 3, [S] 6.3.5), traced once
//! by `EikonalPaths` and shaded by `EikonalRender` as often as the light changes.

use glam::Vec3;
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// Where a camera sample's path ends: it leaves along the straight segment `o + t d`,
/// t ∈ [0, `tmax`] (∞: on to the environment when nothing is met; finite: a surface inside the
/// medium's box stopped it there), carrying the medium's transmittance `tr` (0: the path was
/// cut off by the step limit and brings nothing).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct PathEnd {
    pub o: Vec3,
    pub d: Vec3,
    pub tmax: f32,
    pub tr: f32,
}

/// An in-scattering sample on a path: the medium at `p` scatters toward the camera what
/// arrives there, along direction `u` of travel, with weight `w` = σ × the step's
/// length-weighted transmittance (the fluence it is multiplied by, and the phase function, are
/// the light's).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct Gather {
    pub p: Vec3,
    pub u: Vec3,
    pub w: f32,
}

/// Per camera sample (`samples`² per pixel, pixels row by row): the camera ray `origin + t
/// dir` and where it enters the medium's box (`entry`, ∞ if it never does), the path's
/// in-scattering samples `gathers[offsets[k] .. offsets[k + 1]]`, and its end. `obstacles` is
/// the box of the surfaces inside the medium's box the paths stopped at (`Accel::bounds_within`),
/// so that the shading can tell whether it sees the same ones.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ViewPaths {
    pub width: u32,
    pub height: u32,
    pub samples: u32,
    pub min: Vec3,
    pub max: Vec3,
    pub obstacles: Option<(Vec3, Vec3)>,
    #[serde(with = "pod_vec")]
    pub origin: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub dir: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub entry: Vec<f32>,
    #[serde(with = "pod_vec")]
    pub offsets: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub gathers: Vec<Gather>,
    #[serde(with = "pod_vec")]
    pub ends: Vec<PathEnd>,
}

impl ViewPaths {
    /// Camera samples.
    pub fn len(&self) -> usize {
        self.ends.len()
    }
    pub fn is_empty(&self) -> bool {
        self.ends.is_empty()
    }
    /// Bytes a camera sample holds besides its gathers, and a gather's.
    pub const SAMPLE_BYTES: u64 = 12 + 12 + 4 + 4 + std::mem::size_of::<PathEnd>() as u64;
    pub const GATHER_BYTES: u64 = std::mem::size_of::<Gather>() as u64;

    fn is_consistent(&self) -> bool {
        let n = self.width as u64 * self.height as u64 * (self.samples as u64).pow(2);
        n == self.ends.len() as u64
            && self.origin.len() == self.ends.len()
            && self.dir.len() == self.ends.len()
            && self.entry.len() == self.ends.len()
            && self.offsets.len() == self.ends.len() + 1
            && self.offsets.first() == Some(&0)
            && self.offsets.windows(2).all(|w| w[0] <= w[1])
            && self.offsets.last().is_some_and(|&l| l as usize == self.gathers.len())
    }
}

impl PortValue for ViewPaths {
    const NAME: &'static str = "ViewPaths";
    const COLOR: [u8; 3] = [150, 200, 240];
    const DOC: &'static str = "the camera's curved rays through a medium: per sample its entry, in-scattering samples and end";
    /// The image the paths are for: its pixels are the camera's.
    fn size(&self) -> relume_core::PortSize {
        relume_core::PortSize { bytes: self.byte_size() as u64, dims: Some([self.width as usize, self.height as usize]) }
    }
    fn byte_size(&self) -> usize {
        (self.ends.len() as u64 * Self::SAMPLE_BYTES + self.gathers.len() as u64 * Self::GATHER_BYTES) as usize + 96
    }
    relume_core::serde_codec!(check ViewPaths::is_consistent);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_bad_bytes_decode_to_none() {
        let end = PathEnd { o: Vec3::ONE, d: Vec3::X, tmax: f32::INFINITY, tr: 0.5 };
        let p = ViewPaths {
            width: 2,
            height: 1,
            samples: 1,
            min: Vec3::ZERO,
            max: Vec3::ONE,
            obstacles: Some((Vec3::ZERO, Vec3::splat(0.5))),
            origin: vec![Vec3::Z; 2],
            dir: vec![-Vec3::Z; 2],
            entry: vec![1.0, f32::INFINITY],
            offsets: vec![0, 1, 1],
            gathers: vec![Gather { p: Vec3::splat(0.5), u: -Vec3::Z, w: 0.25 }],
            ends: vec![end; 2],
        };
        assert_eq!(ViewPaths::decode(&p.encode()).unwrap(), p);
        let bytes = p.encode();
        for len in [0, 9, bytes.len() / 2, bytes.len() - 1] {
            assert!(ViewPaths::decode(&bytes[..len]).is_none(), "{len}");
        }
        let mut bad = p.clone();
        bad.offsets[1] = 2;
        assert!(ViewPaths::decode(&bad.encode()).is_none(), "offsets past the gathers");
        let mut bad = p;
        bad.width = 3;
        assert!(ViewPaths::decode(&bad.encode()).is_none(), "sizes that disagree");
    }
}
