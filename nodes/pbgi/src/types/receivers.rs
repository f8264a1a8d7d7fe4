//! `Receivers`: the camera's primary hits (PBGI gathers indirect light at each), and
//! `PointRadiance`: outgoing radiance per surface point.

use glam::Vec3;
use relume_base::types::Material;
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};

/// The camera's primary hits a gather lights: one per pixel whose primary ray hit a surface,
/// or several for a pixel whose footprint spans more than one surface (`GBuffer`), each with
/// its share of the pixel.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Receivers {
    pub width: usize,
    pub height: usize,
    /// Pixel index (y · width + x) of each receiver.
    #[serde(with = "pod_vec")]
    pub pixel: Vec<u32>,
    #[serde(with = "pod_vec")]
    pub position: Vec<Vec3>,
    /// Shading normal, facing the camera's side.
    #[serde(with = "pod_vec")]
    pub normal: Vec<Vec3>,
    /// Unit direction from the receiver toward the camera.
    #[serde(with = "pod_vec")]
    pub wo: Vec<Vec3>,
    #[serde(with = "pod_vec")]
    pub object: Vec<u32>,
    pub material: Vec<Material>,
    /// Each receiver's share of its pixel: 1 for a pixel's only receiver; the shares of one
    /// pixel add up to at most 1 (the rest of its footprint sees nothing a gather lights).
    #[serde(with = "pod_vec")]
    pub weight: Vec<f32>,
    /// Pixels with no receiver of their own whose gathered light is read off pixels around
    /// them on the same surface (`GBuffer`'s `stride`), filled after a gather in this order.
    #[serde(with = "pod_vec")]
    pub fill: Vec<Fill>,
}

/// A pixel whose gathered light is the weighted sum of up to four other pixels' (weight 0:
/// no pixel), each of those a single receiver's whole pixel or one filled before it.
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct Fill {
    pub pixel: u32,
    pub from: [u32; 4],
    pub weight: [f32; 4],
}

impl Receivers {
    /// Memory per receiver: pixel index, position, normal, outgoing direction, object,
    /// material, weight.
    pub const BYTES_PER_RECEIVER: usize = 4 + 36 + 4 + std::mem::size_of::<Material>() + 4;
    /// Memory per filled pixel.
    pub const BYTES_PER_FILL: usize = std::mem::size_of::<Fill>();

    pub fn len(&self) -> usize {
        self.pixel.len()
    }
    pub fn is_empty(&self) -> bool {
        self.pixel.is_empty()
    }

    /// A black image of the receivers' size.
    pub fn blank_image(&self) -> relume_base::types::Image {
        relume_base::types::Image { width: self.width, height: self.height, pixels: vec![[0.0; 3]; self.width * self.height] }
    }

    /// Adds receiver `i`'s value `l`, times its share of the pixel, to its pixel of `img`.
    pub fn add_to(&self, img: &mut relume_base::types::Image, i: usize, l: Vec3) {
        let px = &mut img.pixels[self.pixel[i] as usize];
        let w = self.weight[i];
        for (c, v) in px.iter_mut().zip(l.to_array()) {
            *c += w * v;
        }
    }

    /// Writes each filled pixel of `img`, in the list's order, after every receiver's light was
    /// added: from receivers' pixels or pixels filled before it, so the result is fixed by the
    /// list, never by the order the receivers were gathered in.
    pub fn fill_in(&self, img: &mut relume_base::types::Image) {
        for f in &self.fill {
            let mut sum = [0.0f32; 3];
            for (&p, &w) in f.from.iter().zip(&f.weight).filter(|(_, &w)| w > 0.0) {
                for (s, v) in sum.iter_mut().zip(img.pixels[p as usize]) {
                    *s += w * v;
                }
            }
            img.pixels[f.pixel as usize] = sum;
        }
    }
}

impl Receivers {
    /// Whether every per-receiver list has one entry per receiver and every pixel index lies in
    /// the image (what a decoded payload must satisfy).
    pub fn is_consistent(&self) -> bool {
        let n = self.len();
        let Some(pixels) = self.width.checked_mul(self.height) else { return false };
        let lengths = [self.position.len(), self.normal.len(), self.wo.len(), self.object.len(), self.material.len(), self.weight.len()]
            .iter()
            .all(|&l| l == n);
        let fill_ok = self.fill.iter().all(|f| {
            (f.pixel as usize) < pixels && f.from.iter().all(|&p| (p as usize) < pixels) && f.weight.iter().all(|w| (0.0..=1.0).contains(w))
        });
        lengths && fill_ok && self.pixel.iter().all(|&p| (p as usize) < pixels) && self.weight.iter().all(|w| (0.0..=1.0).contains(w))
    }
}

/// Disk encoding: serde through postcard, the per-receiver numbers as little-endian byte
/// strings; decoding checks that every array has one entry per receiver and that every
/// pixel index lies inside the image.
impl PortValue for Receivers {
    const NAME: &'static str = "Receivers";
    const COLOR: [u8; 3] = [230, 140, 80];
    const DOC: &'static str = "camera primary hits: pixel, position, normal, view direction, material";
    relume_core::serde_codec!(check Receivers::is_consistent);
    fn byte_size(&self) -> usize {
        self.len() * Self::BYTES_PER_RECEIVER + self.fill.len() * Self::BYTES_PER_FILL
    }
    /// Bytes, and the image the receivers are pixels of.
    fn size(&self) -> relume_core::PortSize {
        relume_core::PortSize { bytes: self.byte_size() as u64, dims: Some([self.width, self.height]) }
    }
}

/// Outgoing (diffuse) radiance of each point of a `SurfacePoints`, in the same order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointRadiance(#[serde(with = "pod_vec")] pub Vec<Vec3>);

/// Disk encoding: serde through postcard, the radiance as one little-endian byte string.
impl PortValue for PointRadiance {
    const NAME: &'static str = "PointRadiance";
    const COLOR: [u8; 3] = [250, 210, 90];
    const DOC: &'static str = "outgoing radiance per surface point";
    relume_core::serde_codec!();
    fn byte_size(&self) -> usize {
        self.0.len() * 12
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn receivers() -> Receivers {
        let n = 3;
        Receivers {
            width: 4,
            height: 2,
            pixel: vec![0, 5, 7],
            position: (0..n).map(|i| Vec3::new(i as f32, 0.5, -2.0)).collect(),
            normal: vec![Vec3::Z; n],
            wo: vec![Vec3::new(0.0, 0.6, 0.8); n],
            object: vec![0, 1, 1],
            material: vec![Material::Lambert { albedo: Vec3::splat(0.5) }; n],
            weight: vec![1.0, 0.5, 0.25],
            fill: vec![Fill { pixel: 4, from: [0, 5, 0, 0], weight: [0.25, 0.75, 0.0, 0.0] }],
        }
    }

    #[test]
    fn receivers_encode_and_decode_to_the_same_fingerprint() {
        for r in [Receivers::default(), receivers()] {
            let b = r.encode();
            let back = Receivers::decode(&b).unwrap();
            assert_eq!(back.fingerprint(), r.fingerprint());
            assert_eq!((back.width, back.height, &back.pixel, &back.wo, &back.material), (r.width, r.height, &r.pixel, &r.wo, &r.material));
            assert!(Receivers::decode(&b[..b.len() - 1]).is_none(), "truncated");
        }
        let mut r = receivers();
        r.pixel[2] = 8;
        assert!(Receivers::decode(&r.encode()).is_none(), "a pixel outside the image");
        let mut r = receivers();
        r.wo.pop();
        assert!(Receivers::decode(&r.encode()).is_none(), "arrays of different lengths");
        let mut r = receivers();
        r.weight[1] = f32::NAN;
        assert!(Receivers::decode(&r.encode()).is_none(), "a share that is not a number");
        let mut r = receivers();
        r.fill[0].from[1] = 8;
        assert!(Receivers::decode(&r.encode()).is_none(), "a filled pixel reading outside the image");
        let mut r = receivers();
        r.fill[0].weight[0] = -1.0;
        assert!(Receivers::decode(&r.encode()).is_none(), "a negative fill weight");
        let mut r = receivers();
        r.width = 8;
        assert_ne!(r.fingerprint(), receivers().fingerprint());
    }

    #[test]
    fn a_filled_pixel_is_the_weighted_sum_of_the_pixels_it_reads() {
        let r = receivers();
        let mut img = r.blank_image();
        for (i, l) in [(0, 2.0), (1, 4.0), (2, 8.0)] {
            r.add_to(&mut img, i, Vec3::splat(l));
        }
        img.pixels[4] = [9.0; 3];
        r.fill_in(&mut img);
        assert_eq!(img.pixels[4], [0.25 * 2.0 + 0.75 * 2.0; 3], "pixel 0 holds 2, pixel 5 half of 4");
        assert_eq!(img.pixels[0], [2.0; 3], "the pixels read are left alone");
    }

    #[test]
    fn point_radiance_encodes_and_decodes_to_the_same_fingerprint() {
        let p = PointRadiance(vec![Vec3::new(0.1, 2.0, f32::INFINITY), Vec3::ZERO]);
        let b = p.encode();
        assert_eq!(b.len(), 1 + 24, "a length and the floats");
        let back = PointRadiance::decode(&b).unwrap();
        assert_eq!(back, p);
        assert_eq!(back.fingerprint(), p.fingerprint());
        assert!(PointRadiance::decode(&b[..b.len() - 1]).is_none(), "truncated");
        assert!(PointRadiance::decode(&b[..b.len() - 4]).is_none(), "truncated to whole floats");
        assert_ne!(PointRadiance(vec![Vec3::ZERO]).fingerprint(), PointRadiance(vec![]).fingerprint());
    }
}
