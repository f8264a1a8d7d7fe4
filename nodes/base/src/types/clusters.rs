//! `Clusters`: receiver clusters per image tile (FPBGI, [P] 3.3.2), made by ClusterReceivers
//! and read by FactorizedGather.

use glam::Vec3;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// One cluster of receivers, all in one tile.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Cluster {
    /// Tile index: (y / tile) · ceil(width / tile) + x / tile.
    pub tile: u32,
    /// The active receiver (a receiver index, one of `members`).
    pub active: u32,
    /// Receiver indices, ascending.
    pub members: Vec<u32>,
    /// Mean member position.
    pub center: Vec3,
    /// Normalised sum of the member normals.
    pub normal: Vec3,
    /// Largest distance of a member position from `center`.
    pub radius: f32,
}

/// Receiver clusters: tile by tile in tile-index order, within a tile in k-means order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Clusters {
    /// Tile size in pixels.
    pub tile: usize,
    pub clusters: Vec<Cluster>,
    /// Cluster index (into `clusters`) of each receiver.
    #[serde(with = "relume_core::codec::pod_vec")]
    pub of_receiver: Vec<u32>,
}

impl Clusters {
    /// Whether every index points where it may: each member and active receiver is a receiver
    /// (`< of_receiver.len()`) and each receiver's cluster exists. What a decoded payload must
    /// satisfy before the gather indexes with it.
    fn links_hold(&self) -> bool {
        let receivers = self.of_receiver.len();
        self.of_receiver.iter().all(|&c| (c as usize) < self.clusters.len())
            && self.clusters.iter().all(|c| (c.active as usize) < receivers && c.members.iter().all(|&m| (m as usize) < receivers))
    }
}

/// Disk encoding: serde through postcard (lists in order, so the bytes are deterministic);
/// decoding refuses payloads whose indices point outside the lists.
impl PortValue for Clusters {
    const NAME: &'static str = "Clusters";
    const COLOR: [u8; 3] = [200, 160, 70];
    const DOC: &'static str = "receiver clusters per image tile: members, active receiver, centre, normal, radius";
    fn byte_size(&self) -> usize {
        self.clusters.len() * std::mem::size_of::<Cluster>() + self.of_receiver.len() * 8
    }
    relume_core::serde_codec!(check Clusters::links_hold);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Clusters {
        let c = |tile, active, members: Vec<u32>, x: f32| Cluster {
            tile,
            active,
            members,
            center: Vec3::new(x, 2.0, -3.5),
            normal: Vec3::new(0.0, 0.6, 0.8),
            radius: 0.25 * x,
        };
        Clusters {
            tile: 32,
            clusters: vec![c(0, 1, vec![0, 1, 3], 1.0), c(2, 2, vec![2], f32::MIN_POSITIVE)],
            of_receiver: vec![0, 0, 1, 0],
        }
    }

    #[test]
    fn round_trips_through_the_disk_encoding() {
        let c = sample();
        let bytes = c.encode();
        let back = Clusters::decode(&bytes).unwrap();
        assert_eq!(back, c);
        assert_eq!(back.fingerprint(), c.fingerprint());
        assert_eq!(bytes, c.clone().encode(), "deterministic");
        assert!(Clusters::decode(&bytes[..bytes.len() - 1]).is_none(), "truncated payload is refused");
        assert!(Clusters::decode(&[]).is_none());
        let mut other = c.clone();
        other.clusters[1].radius = 0.5;
        assert_ne!(other.fingerprint(), c.fingerprint(), "the fingerprint follows every field");
    }

    #[test]
    fn a_payload_with_dangling_indices_is_refused() {
        let mut c = sample();
        c.of_receiver[3] = 2;
        assert!(Clusters::decode(&c.encode()).is_none());
        let mut c = sample();
        c.clusters[0].members.push(4);
        assert!(Clusters::decode(&c.encode()).is_none());
        assert_eq!(Clusters::decode(&Clusters::default().encode()), Some(Clusters::default()));
    }
}
