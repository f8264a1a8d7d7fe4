//! Wavelet PBGI's port types: `PointWavelets`, each surface point's outgoing radiance as
//! sparse cube-map Haar coefficients, and `CodedWavelets`, those coded along the point tree.

use glam::Vec3;
use relume_base::math::cube_haar::SparseCubeHaar;
use relume_base::math::tree_coding::CodedTree;
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// Largest cube-map side the wavelet types accept (6 × 1024² coefficients per point).
pub const MAX_WAVELET_SIDE: u32 = 1024;

/// Per surface point (the order of its `SurfacePoints`), the kept Haar coefficients of its
/// outgoing radiance on a cube map of side `n` (`math::cube_haar`'s layout), all points in
/// one array: point i's are `start[i] .. start[i + 1]`, indices ascending.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointWavelets {
    pub n: u32,
    #[serde(with = "pod_vec")]
    pub start: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub index: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub value: Vec<Vec3>,
}

impl PointWavelets {
    /// Bytes per kept coefficient (index and RGB value).
    pub const BYTES_PER_TERM: usize = 16;

    /// The points' approximations gathered into one value (all of side `n`).
    pub fn from_points(n: usize, points: &[SparseCubeHaar]) -> PointWavelets {
        let mut w = PointWavelets { n: n as u32, start: vec![0], ..Default::default() };
        for p in points {
            assert_eq!(p.n, n, "the points' wavelets are of different sides");
            w.index.extend_from_slice(&p.index);
            w.value.extend_from_slice(&p.value);
            w.start.push(w.index.len() as u32);
        }
        w
    }

    pub fn len(&self) -> usize {
        self.start.len().saturating_sub(1)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Point `i`'s kept coefficients: indices and values.
    pub fn point(&self, i: usize) -> (&[u32], &[Vec3]) {
        let r = self.start[i] as usize..self.start[i + 1] as usize;
        (&self.index[r.clone()], &self.value[r])
    }

    /// Point `i`'s approximation on its own.
    pub fn sparse(&self, i: usize) -> SparseCubeHaar {
        let (index, value) = self.point(i);
        SparseCubeHaar { n: self.n as usize, index: index.to_vec(), value: value.to_vec() }
    }

    fn is_consistent(&self) -> bool {
        let dim = 6 * (self.n as u64).pow(2);
        (1..=MAX_WAVELET_SIDE).contains(&self.n)
            && self.n.is_power_of_two()
            && self.start.first() == Some(&0)
            && self.start.last().is_some_and(|&e| e as usize == self.index.len())
            && self.value.len() == self.index.len()
            && self.start.windows(2).all(|w| w[0] <= w[1])
            && self.start.windows(2).all(|w| {
                let ix = &self.index[w[0] as usize..w[1] as usize];
                ix.windows(2).all(|p| p[0] < p[1]) && ix.last().is_none_or(|&i| (i as u64) < dim)
            })
    }
}

/// Disk encoding: serde through postcard, the arrays as little-endian byte strings; decoding
/// checks the ranges (ascending, inside the map, one range per point) before anything reads them.
impl PortValue for PointWavelets {
    const NAME: &'static str = "PointWavelets";
    const COLOR: [u8; 3] = [240, 190, 60];
    const DOC: &'static str = "per surface point, its outgoing radiance as sparse cube-map Haar coefficients";
    relume_core::serde_codec!(check PointWavelets::is_consistent);
    fn byte_size(&self) -> usize {
        self.index.len() * Self::BYTES_PER_TERM + self.start.len() * 4
    }
}

/// The points' wavelets coded hierarchically along their point tree (`math::tree_coding`,
/// node numbers the tree's), each stored vector the RGB coefficients flattened (coefficient
/// k's channel c at 3k + c) of a cube map of side `n`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CodedWavelets {
    pub n: u32,
    pub tree: CodedTree,
}

impl CodedWavelets {
    /// An upper bound on the coded tree's bytes, from the points' term counts: a node's
    /// vector has entries only where some point under it has, so each stored vector holds at
    /// most min(dim, the terms under it) entries of 8 B; at most two vectors per node.
    pub fn bound(tree: &super::PointTree, w: &PointWavelets) -> u64 {
        let dim = 18 * (w.n as u64).pow(2);
        let mut under = vec![0u64; tree.nodes.len()];
        // Children follow their parent in the depth-first layout: children first, backwards.
        for v in (0..tree.nodes.len()).rev() {
            under[v] = match tree.nodes[v].children {
                Some([l, r]) => under[l as usize] + under[r as usize],
                None => {
                    let (ix, _) = w.point(tree.nodes[v].point as usize);
                    3 * ix.len() as u64
                }
            };
        }
        under.iter().map(|&u| 2 * 8 * u.min(dim)).sum()
    }

    fn is_consistent(&self) -> bool {
        (1..=MAX_WAVELET_SIDE).contains(&self.n)
            && self.n.is_power_of_two()
            && self.tree.dim == 18 * (self.n as usize).pow(2)
            && self.tree.is_consistent()
    }
}

/// Disk encoding: serde through postcard; decoding checks the tree's links, levels and
/// sparse vectors (`CodedTree::is_consistent`) before anything walks them.
impl PortValue for CodedWavelets {
    const NAME: &'static str = "CodedWavelets";
    const COLOR: [u8; 3] = [220, 160, 40];
    const DOC: &'static str = "per-point radiance wavelets coded along the point tree (averages and details)";
    relume_core::serde_codec!(check CodedWavelets::is_consistent);
    fn byte_size(&self) -> usize {
        self.tree.bytes() + self.tree.parent.len() * 16
    }
}
