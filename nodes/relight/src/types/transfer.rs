//! The stored transfer of pixel relighting ([S] 4.1.1, 4.1.3): `Transfer` (every image of one
//! scene's terms, pixel-major, with the per-pixel object class), its band `TransferRows` (the
//! partial result of the precompute sharded over rows).

use crate::terms::{Channels, Term};
use relume_base::types::Texture;
use relume_core::codec::pod_vec;
use relume_core::{params, PortValue};
use serde::{Deserialize, Serialize};

/// Largest transfer the precompute may hold (the thesis' two-object scene at 512² is 142 MiB;
/// 16 GiB is a 4096² image of the same scene).
pub const MAX_TRANSFER_BYTES: u64 = 16 << 30;

params! {
    /// How the stored images were sampled (the precompute's parameters), kept with them so that a
    /// same-seed reference traces exactly the same paths. Both precompute nodes take these as
    /// their own parameters (`#[param(flatten)]`).
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
    pub struct PathCounts {
        /// camera samples per pixel, jittered over the pixel
        pub spp: u32 = 16, range = 1..=65536, unit = "samples/pixel", test = 2;
        /// light samples at the first hit, per camera sample ([S]: 98 per pixel)
        pub light_samples: u32 = 4, range = 1..=4096;
        /// uniform hemisphere rays from the first hit, per camera sample ([S]: 4096 per pixel)
        pub bounce_rays: u32 = 16, range = 0..=65536, test = 2;
        /// light samples at the second hit, per hemisphere ray ([S]: 8)
        pub bounce_light_samples: u32 = 1, range = 1..=4096;
        /// random seed
        pub seed: u64 = 0, range = 0..=u32::MAX;
    }
}

/// Disk encoding: serde through postcard. A port of its own, so that a same-seed render reads
/// the paths of either precompute (`RelightReference` after `TransferPrecompute` or
/// `SvTransferPrecompute`).
impl PortValue for PathCounts {
    const NAME: &'static str = "PathCounts";
    const COLOR: [u8; 3] = [160, 210, 190];
    const DOC: &'static str = "how a relighting precompute sampled its paths (camera, light and hemisphere samples, seed)";
    fn byte_size(&self) -> usize {
        32
    }
    relume_core::serde_codec!();
}

/// Every stored image of a scene's terms at `width × height`, pixel-major: pixel p's floats are
/// `data[p * stride ..][.. floats]`, term by term in `terms` order (grey: one float, RGB:
/// three), zero-padded to `stride` (a multiple of 8, for the combine's vector loop).
/// `class[p]` is 0 where the pixel shows a fixed-material object, an emitter or nothing, and
/// g + 1 where it shows dynamic object g (`groups[g]`); grey images hold the light colour's
/// multiple (`colour`, largest component 1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Transfer {
    pub width: u32,
    pub height: u32,
    pub terms: Vec<(Term, Channels)>,
    /// Names of the dynamic objects (`Scene::dynamic_groups`).
    pub groups: Vec<String>,
    /// Specular bases S (N_b − 1).
    pub specular_bases: u32,
    pub colour: [f32; 3],
    pub counts: PathCounts,
    /// Per dynamic object, the digest of the Kd map multiplied into its diffuse basis' images
    /// (`kd_map_digest`), or `None` where it has none: the combine refuses materials whose map
    /// differs (painted after the precompute).
    pub kd_maps: Vec<Option<[u8; 32]>>,
    pub stride: u32,
    #[serde(with = "pod_vec")]
    pub class: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub data: Vec<f32>,
}

/// The digest a `Transfer` keeps of a Kd map: the hash of its encoding.
pub fn kd_map_digest(map: &Texture) -> [u8; 32] {
    relume_core::codec::fingerprint("Texture", map).0
}

/// Floats per pixel of `terms`, and that rounded up to a multiple of 8.
pub fn floats_and_stride(terms: &[(Term, Channels)]) -> (usize, usize) {
    let floats: usize = terms.iter().map(|t| t.1.count()).sum();
    (floats, floats.div_ceil(8) * 8)
}

impl Transfer {
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }
    /// The float offset of each term within a pixel.
    pub fn offsets(&self) -> Vec<usize> {
        self.terms
            .iter()
            .scan(0, |o, t| {
                let at = *o;
                *o += t.1.count();
                Some(at)
            })
            .collect()
    }
    /// One term's image as RGB (grey images times `colour`), for display and tests.
    pub fn image(&self, term: usize) -> relume_base::types::Image {
        let (off, ch) = (self.offsets()[term], self.terms[term].1);
        relume_base::types::Image::from_fn(self.width as usize, self.height as usize, |x, y| {
            let d = &self.data[(y * self.width as usize + x) * self.stride as usize + off..];
            match ch {
                Channels::Grey => self.colour.map(|c| c * d[0]),
                Channels::Rgb => [d[0], d[1], d[2]],
            }
        })
    }
    fn is_consistent(&self) -> bool {
        let (floats, stride) = floats_and_stride(&self.terms);
        let n = self.pixels();
        self.stride as usize == stride
            && floats <= stride
            && self.class.len() == n
            && self.data.len() == n * stride
            && self.class.iter().all(|&c| c as usize <= self.groups.len())
            && self.kd_maps.len() == self.groups.len()
    }
}

/// Disk encoding: serde through postcard, class and data as little-endian byte strings;
/// decoding checks the sizes against the terms and the classes against the groups.
impl PortValue for Transfer {
    const NAME: &'static str = "Transfer";
    const COLOR: [u8; 3] = [120, 200, 170];
    const DOC: &'static str = "the stored transfer images of pixel relighting, with the per-pixel object class";
    fn byte_size(&self) -> usize {
        self.data.len() * 4 + self.class.len() * 4 + self.terms.len() * 8 + 64
    }
    relume_core::serde_codec!(check Transfer::is_consistent);
}

/// Rows `first_row ..` of a transfer (same layout as `Transfer`), with counters summed over the
/// band: [rays, camera samples dropped at object edges, pixels with mixed coverage].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransferRows {
    pub first_row: u64,
    pub rows: u64,
    #[serde(with = "pod_vec")]
    pub class: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub data: Vec<f32>,
    /// Per pixel, the camera samples dropped because they hit another class.
    #[serde(with = "pod_vec")]
    pub dropped: Vec<u32>,
    pub counters: Vec<u64>,
}

/// Disk encoding: serde through postcard.
impl PortValue for TransferRows {
    const NAME: &'static str = "TransferRows";
    const COLOR: [u8; 3] = [100, 170, 150];
    const DOC: &'static str = "a band of rows of a relighting transfer (the precompute's partial result)";
    fn byte_size(&self) -> usize {
        self.data.len() * 4 + (self.class.len() + self.dropped.len()) * 4 + 64
    }
    relume_core::serde_codec!();
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transfer() -> Transfer {
        crate::test_support::tiny_transfer((0..16).map(|i| i as f32).collect())
    }

    #[test]
    fn encodings_round_trip_and_refuse_inconsistent_payloads() {
        let t = transfer();
        assert_eq!(Transfer::decode(&t.encode()).unwrap(), t);
        let mut bad = t.clone();
        bad.class[1] = 2;
        assert!(Transfer::decode(&bad.encode()).is_none(), "a class past the groups");
        let mut bad = t.clone();
        bad.data.pop();
        assert!(Transfer::decode(&bad.encode()).is_none(), "short data");
        let bytes = t.encode();
        for len in [0, 3, bytes.len() / 2, bytes.len() - 1] {
            assert!(Transfer::decode(&bytes[..len]).is_none(), "{len}");
        }
    }

    #[test]
    fn term_images_read_their_floats_and_grey_ones_take_the_light_colour() {
        let t = transfer();
        assert_eq!(t.offsets(), vec![0, 3]);
        assert_eq!(t.image(0).pixels, vec![[0.0, 1.0, 2.0], [8.0, 9.0, 10.0]]);
        assert_eq!(t.image(1).pixels, vec![[3.0, 1.5, 0.75], [11.0, 5.5, 2.75]]);
        assert_eq!(floats_and_stride(&t.terms), (4, 8));
    }
}
