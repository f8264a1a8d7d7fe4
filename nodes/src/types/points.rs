//! `SurfacePoints`: points on a scene's surfaces, each standing for a small disk of area.

use super::material::Material;
use glam::Vec3;
use relume_core::{Hash, Hasher, PortValue};

#[derive(Clone, Debug, Default)]
pub struct SurfacePoints {
    pub position: Vec<Vec3>,
    /// Shading normal at the point.
    pub normal: Vec<Vec3>,
    /// Radius of the disk the point stands for (area = π r²).
    pub radius: Vec<f32>,
    /// Scene object index.
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

impl PortValue for SurfacePoints {
    const NAME: &'static str = "SurfacePoints";
    const COLOR: [u8; 3] = [220, 110, 150];
    const DOC: &'static str = "surface points with normal, disk radius, object and material";
    fn fingerprint(&self) -> Hash {
        let mut h = Hasher::new();
        h.str(Self::NAME);
        let f: Vec<f32> = self.position.iter().chain(&self.normal).flat_map(|v| v.to_array()).chain(self.radius.iter().copied()).collect();
        h.f32s(&f);
        for o in &self.object {
            h.u64(*o as u64);
        }
        h.str(&format!("{:?}", self.material));
        h.finish()
    }
    fn byte_size(&self) -> usize {
        self.len() * Self::BYTES_PER_POINT
    }
}
