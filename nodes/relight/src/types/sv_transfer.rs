//! `SvTransfer`: the compressed transfer of the spatially varying extension of pixel
//! relighting ([S] 4.2): the direct images and the bounce onto fixed objects kept whole (RGB),
//! and each (ρ′, R1, ρ1) group's block of n² sub-region images as PCA weights along the
//! sub-regions times basis images kept as their largest Haar coefficients.

use super::transfer::PathCounts;
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// A Haar coefficient image keeping some terms: indices (ascending) into the `side × side`
/// padded square and their values.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SparsePlane {
    #[serde(with = "pod_vec")]
    pub index: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub value: Vec<f32>,
}

/// One compressed group: block[r](p, c) ≈ Σ_j weights[r · components + j] · basis image (j, c)
/// at p, the basis images median-filtered and Haar-compressed (`images[j · 3 + c]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SvBlock {
    /// x′ basis ρ′ (0: the diffuse basis, or a fixed object's own BRDF).
    pub first: u16,
    /// The dynamic object R1 at x″.
    pub object: u16,
    /// x″ basis ρ1.
    pub second: u16,
    pub components: u32,
    #[serde(with = "pod_vec")]
    pub weights: Vec<f32>,
    pub images: Vec<SparsePlane>,
}

/// Every stored image of an SV precompute at `width × height` (planes RGB-interleaved,
/// pixel-major: `[p * 3 + c]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SvTransfer {
    pub width: u32,
    pub height: u32,
    /// Names of the dynamic objects (`Scene::dynamic_groups`).
    pub groups: Vec<String>,
    /// Sub-regions per side of each object's UV square (n).
    pub sub_regions: u32,
    pub direct_bases: u32,
    pub indirect_bases: u32,
    pub counts: PathCounts,
    /// Per pixel: 0 for fixed objects, emitters and nothing; g + 1 for dynamic object g.
    #[serde(with = "pod_vec")]
    pub class: Vec<u32>,
    /// Per pixel: the UV of x′ (the texel its material is read at).
    #[serde(with = "pod_vec")]
    pub uv: Vec<[f32; 2]>,
    /// `direct_bases` RGB images, basis-major.
    #[serde(with = "pod_vec")]
    pub direct: Vec<f32>,
    /// The light seen directly (RGB), empty without emitters.
    #[serde(with = "pod_vec")]
    pub emitted: Vec<f32>,
    /// The bounce onto fixed objects per x′ basis (`indirect_bases` RGB images), empty
    /// without fixed objects.
    #[serde(with = "pod_vec")]
    pub fixed: Vec<f32>,
    /// Side of the padded Haar square (a power of two ≥ width, height).
    pub side: u32,
    pub blocks: Vec<SvBlock>,
}

impl SvTransfer {
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Bytes held (what the compression brought the blocks down to, plus the whole images).
    pub fn bytes(&self) -> u64 {
        let planes: usize = self.blocks.iter().flat_map(|b| &b.images).map(|p| p.index.len() * 8).sum();
        let weights: usize = self.blocks.iter().map(|b| b.weights.len() * 4).sum();
        ((self.direct.len() + self.emitted.len() + self.fixed.len() + self.class.len() + 2 * self.uv.len()) * 4 + planes + weights) as u64
    }

    fn is_consistent(&self) -> bool {
        let n = self.pixels();
        let (nbd, nbi) = (self.direct_bases as usize, self.indirect_bases as usize);
        let n2 = (self.sub_regions as usize).pow(2);
        let side = self.side as usize;
        let side_ok = side.is_power_of_two() && side >= self.width as usize && side >= self.height as usize && side <= 1 << 15;
        side_ok
            && self.sub_regions > 0
            && nbi >= 1
            && nbi <= nbd
            && self.class.len() == n
            && self.uv.len() == n
            && self.direct.len() == nbd * n * 3
            && (self.emitted.is_empty() || self.emitted.len() == n * 3)
            && (self.fixed.is_empty() || self.fixed.len() == nbi * n * 3)
            && self.class.iter().all(|&c| c as usize <= self.groups.len())
            && self.blocks.iter().all(|b| {
                let k = b.components as usize;
                (b.first as usize) < nbi
                    && (b.second as usize) < nbi
                    && (b.object as usize) < self.groups.len()
                    && b.weights.len() == n2 * k
                    && b.images.len() == 3 * k
                    && b.images.iter().all(|p| {
                        p.index.len() == p.value.len()
                            && p.index.windows(2).all(|w| w[0] < w[1])
                            && p.index.last().is_none_or(|&i| (i as usize) < side * side)
                    })
            })
    }
}

/// Disk encoding: serde through postcard, the arrays as little-endian byte strings; decoding
/// checks every size against the counts and every Haar index against the padded square.
impl PortValue for SvTransfer {
    const NAME: &'static str = "SvTransfer";
    const COLOR: [u8; 3] = [90, 200, 140];
    const DOC: &'static str =
        "the compressed transfer of spatially varying pixel relighting (whole direct images, PCA × Haar bounce blocks)";
    fn byte_size(&self) -> usize {
        self.bytes() as usize + self.blocks.len() * 64 + 128
    }
    relume_core::serde_codec!(check SvTransfer::is_consistent);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> SvTransfer {
        SvTransfer {
            width: 3,
            height: 2,
            groups: vec!["a".into()],
            sub_regions: 2,
            direct_bases: 2,
            indirect_bases: 1,
            counts: PathCounts { spp: 1, light_samples: 1, bounce_rays: 1, bounce_light_samples: 1, seed: 0 },
            class: vec![0, 1, 1, 0, 1, 0],
            uv: vec![[0.5, 0.5]; 6],
            direct: vec![0.25; 2 * 18],
            emitted: vec![],
            fixed: vec![0.5; 18],
            side: 4,
            blocks: vec![SvBlock {
                first: 0,
                object: 0,
                second: 0,
                components: 1,
                weights: vec![1.0, 0.5, 0.0, 2.0],
                images: vec![SparsePlane { index: vec![0, 5], value: vec![1.0, -1.0] }; 3],
            }],
        }
    }

    #[test]
    fn it_round_trips_and_bad_bytes_or_sizes_decode_to_none() {
        let t = tiny();
        assert_eq!(SvTransfer::decode(&t.encode()).unwrap(), t);
        let bytes = t.encode();
        for len in [0, 5, bytes.len() / 2, bytes.len() - 1] {
            assert!(SvTransfer::decode(&bytes[..len]).is_none(), "{len}");
        }
        let mut bad = t.clone();
        bad.blocks[0].images[1].index = vec![5, 0];
        assert!(SvTransfer::decode(&bad.encode()).is_none(), "unsorted indices");
        let mut bad = t.clone();
        bad.blocks[0].images[0].index = vec![0, 16];
        assert!(SvTransfer::decode(&bad.encode()).is_none(), "an index outside the 4 × 4 square");
        let mut bad = t.clone();
        bad.side = 2;
        assert!(SvTransfer::decode(&bad.encode()).is_none(), "a square smaller than the image");
        let mut bad = t;
        bad.blocks[0].weights.pop();
        assert!(SvTransfer::decode(&bad.encode()).is_none(), "weights of another grid");
    }
}
