//! `Receivers`: the camera's primary hits (PBGI gathers indirect light at each), and
//! `PointRadiance`: outgoing radiance per surface point.

use super::material::Material;
use glam::Vec3;
use relume_core::{Hash, Hasher, PortValue};

/// One receiver per pixel whose primary ray hit a surface.
#[derive(Clone, Debug, Default)]
pub struct Receivers {
    pub width: usize,
    pub height: usize,
    /// Pixel index (y · width + x) of each receiver.
    pub pixel: Vec<u32>,
    pub position: Vec<Vec3>,
    /// Shading normal, facing the camera's side.
    pub normal: Vec<Vec3>,
    /// Unit direction from the receiver toward the camera.
    pub wo: Vec<Vec3>,
    pub object: Vec<u32>,
    pub material: Vec<Material>,
}

impl Receivers {
    pub fn len(&self) -> usize {
        self.pixel.len()
    }
    pub fn is_empty(&self) -> bool {
        self.pixel.is_empty()
    }
}

impl PortValue for Receivers {
    const NAME: &'static str = "Receivers";
    const COLOR: [u8; 3] = [230, 140, 80];
    const DOC: &'static str = "camera primary hits: pixel, position, normal, view direction, material";
    fn fingerprint(&self) -> Hash {
        let mut h = Hasher::new();
        h.str(Self::NAME).u64(self.width as u64).u64(self.height as u64);
        for p in &self.pixel {
            h.u64(*p as u64);
        }
        let f: Vec<f32> = self.position.iter().chain(&self.normal).chain(&self.wo).flat_map(|v| v.to_array()).collect();
        h.f32s(&f);
        h.str(&format!("{:?}{:?}", self.object, self.material));
        h.finish()
    }
    fn byte_size(&self) -> usize {
        self.len() * (4 + 36 + 4 + std::mem::size_of::<Material>())
    }
}

/// Outgoing (diffuse) radiance of each point of a `SurfacePoints`, in the same order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointRadiance(pub Vec<Vec3>);

impl PortValue for PointRadiance {
    const NAME: &'static str = "PointRadiance";
    const COLOR: [u8; 3] = [250, 210, 90];
    const DOC: &'static str = "outgoing radiance per surface point";
    fn fingerprint(&self) -> Hash {
        let f: Vec<f32> = self.0.iter().flat_map(|v| v.to_array()).collect();
        Hasher::new().str(Self::NAME).f32s(&f).finish()
    }
    fn byte_size(&self) -> usize {
        self.0.len() * 12
    }
}
