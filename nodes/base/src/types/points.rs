//! `SurfacePoints`: points on a scene's surfaces, each standing for a small disk of area.

use super::material::Material;
use glam::Vec3;
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct SurfacePoints {
    #[serde(with = "pod_vec")]
    pub position: Vec<Vec3>,
    /// Shading normal at the point.
    #[serde(with = "pod_vec")]
    pub normal: Vec<Vec3>,
    /// Radius of the disk the point stands for (area = π r²).
    #[serde(with = "pod_vec")]
    pub radius: Vec<f32>,
    /// Scene object index.
    #[serde(with = "pod_vec")]
    pub object: Vec<u32>,
    pub material: Vec<Material>,
}

impl SurfacePoints {
    pub fn len(&self) -> usize {
        self.position.len()
    }
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }
    /// Bytes per point, for refusing oversized requests before allocating.
    pub const BYTES_PER_POINT: usize = 12 + 12 + 4 + 4 + std::mem::size_of::<Material>();
}

impl SurfacePoints {
    /// Whether every per-point list has one entry per point (what a decoded payload must
    /// satisfy).
    pub fn is_consistent(&self) -> bool {
        let n = self.len();
        [self.normal.len(), self.radius.len(), self.object.len(), self.material.len()].iter().all(|&l| l == n)
    }
}

/// Disk encoding: serde through postcard, the per-point numbers as little-endian byte
/// strings; decoding checks that every array has one entry per point.
impl PortValue for SurfacePoints {
    const NAME: &'static str = "SurfacePoints";
    const COLOR: [u8; 3] = [220, 110, 150];
    const DOC: &'static str = "surface points with normal, disk radius, object and material";
    relume_core::serde_codec!(check SurfacePoints::is_consistent);
    fn byte_size(&self) -> usize {
        self.len() * Self::BYTES_PER_POINT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points() -> SurfacePoints {
        let n = 5;
        SurfacePoints {
            position: (0..n).map(|i| Vec3::new(i as f32, -0.5, 1e-3)).collect(),
            normal: vec![Vec3::Y; n],
            radius: vec![0.25; n],
            object: (0..n as u32).collect(),
            material: (0..n)
                .map(|i| {
                    if i % 2 == 0 {
                        Material::Lambert { albedo: Vec3::splat(0.5) }
                    } else {
                        Material::Dielectric { ior: 1.5, medium: None }
                    }
                })
                .collect(),
        }
    }

    #[test]
    fn encodes_and_decodes_to_the_same_fingerprint() {
        for p in [SurfacePoints::default(), points()] {
            let b = p.encode();
            let back = SurfacePoints::decode(&b).unwrap();
            assert_eq!(back.fingerprint(), p.fingerprint());
            assert_eq!(
                (back.position, back.normal, back.radius, back.object, back.material),
                (p.position, p.normal, p.radius, p.object, p.material)
            );
            assert!(SurfacePoints::decode(&b[..b.len() - 1]).is_none(), "truncated");
        }
        let b = points().encode();
        assert!(SurfacePoints::decode(&b[..b.len() / 2]).is_none(), "truncated");
        let mut p = points();
        p.radius.pop();
        assert!(SurfacePoints::decode(&p.encode()).is_none(), "arrays of different lengths");
        let mut q = points();
        q.object[0] = 9;
        assert_ne!(q.fingerprint(), points().fingerprint());
    }
}
