//! The `ScreenHits` port type: what a camera sees of a mesh, as weights on its vertices.

use glam::Vec3;
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// Per pixel of a camera's image, the weights of the scene vertices its samples see (each
/// sample's triangle corners weighted by its barycentrics over the samples per pixel) and
/// where its missing samples look: the fraction of its samples that hit nothing and the
/// direction through their mean position, so that pixel = fraction · L_env(direction) +
/// Σ weight · colour. The environment itself is not read here, so a sky edit leaves the
/// hits as they are.
/// `seen` lists, ascending, every vertex with a weight: the only ones whose colour can
/// reach the image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScreenHits {
    pub width: u32,
    pub height: u32,
    /// The scene's vertex count (colours must come one per vertex).
    pub vertices: u32,
    /// Pixel p's entries are `offsets[p]..offsets[p + 1]`.
    #[serde(with = "pod_vec")]
    pub offsets: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub vertex: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub weight: Vec<f32>,
    /// Per pixel, the fraction of its samples that hit nothing (0 ..= 1).
    #[serde(with = "pod_vec")]
    pub miss: Vec<f32>,
    /// Per pixel, the direction through its missing samples' mean position (zero if none).
    #[serde(with = "pod_vec")]
    pub miss_dir: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub seen: Vec<u32>,
}

impl ScreenHits {
    /// Bytes of hits with `entries` vertex weights over `pixels` pixels and `seen` vertices.
    pub fn bytes(pixels: u64, entries: u64, seen: u64) -> u64 {
        pixels * 20 + entries * 8 + seen * 4 + 32
    }

    fn is_consistent(&self) -> bool {
        let pixels = self.width as usize * self.height as usize;
        let n = self.vertex.len();
        self.offsets.len() == pixels + 1
            && self.offsets.first() == Some(&0)
            && self.offsets.last() == Some(&(n as u32))
            && self.offsets.windows(2).all(|w| w[0] <= w[1])
            && self.weight.len() == n
            && self.miss.len() == pixels
            && self.miss_dir.len() == pixels
            && self.vertex.iter().all(|&v| v < self.vertices)
            && self.weight.iter().all(|w| w.is_finite())
            && self.miss.iter().all(|m| (0.0..=1.0).contains(m))
            && self.miss_dir.iter().all(|d| d.is_finite())
            && self.seen.windows(2).all(|w| w[0] < w[1])
            && self.seen.last().is_none_or(|&v| v < self.vertices)
    }
}

impl PortValue for ScreenHits {
    const NAME: &'static str = "ScreenHits";
    const COLOR: [u8; 3] = [250, 200, 120];
    const DOC: &'static str = "per pixel, the weights of the vertices a camera sees and where its missing samples look";
    fn byte_size(&self) -> usize {
        Self::bytes(self.miss.len() as u64, self.vertex.len() as u64, self.seen.len() as u64) as usize
    }
    relume_core::serde_codec!(check ScreenHits::is_consistent);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decoding_refuses_inconsistent_hits() {
        let h = ScreenHits {
            width: 2,
            height: 1,
            vertices: 3,
            offsets: vec![0, 2, 3],
            vertex: vec![0, 2, 1],
            weight: vec![0.5, 0.5, 1.0],
            miss: vec![0.0, 0.5],
            miss_dir: vec![Vec3::ZERO, Vec3::Z],
            seen: vec![0, 1, 2],
        };
        assert_eq!(ScreenHits::decode(&h.encode()), Some(h.clone()));
        let broken: [fn(&mut ScreenHits); 6] = [
            |h| h.offsets[2] = 4,
            |h| h.vertex[0] = 3,
            |h| h.seen = vec![1, 0],
            |h| h.miss.truncate(1),
            |h| h.miss[1] = 1.5,
            |h| h.miss_dir[0].x = f32::NAN,
        ];
        for f in broken {
            let mut b = h.clone();
            f(&mut b);
            assert!(ScreenHits::decode(&b.encode()).is_none());
        }
    }
}
