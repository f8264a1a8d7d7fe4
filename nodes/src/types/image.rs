//! `Image`: a linear-RGB f32 raster, row-major, top row first.

use relume_core::{Hash, Hasher, NodeError, PortValue};

/// Largest image a node may allocate (2 GiB of pixels); bigger requests are refused before
/// allocating, with the estimate in the message.
pub const MAX_IMAGE_BYTES: usize = 2 << 30;

#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<[f32; 3]>,
}

impl Image {
    /// A black image; refuses sizes over `MAX_IMAGE_BYTES` without allocating.
    pub fn try_new(width: usize, height: usize) -> Result<Image, NodeError> {
        let bytes = width.checked_mul(height).and_then(|n| n.checked_mul(12));
        match bytes {
            Some(b) if b <= MAX_IMAGE_BYTES && width > 0 && height > 0 => {
                Ok(Image { width, height, pixels: vec![[0.0; 3]; width * height] })
            }
            Some(0) => Err(NodeError::failed(format!("an image of {width} × {height} pixels is empty"))),
            _ => Err(NodeError::failed(format!(
                "an image of {width} × {height} pixels needs {:.1} GiB, over the {} GiB limit",
                width as f64 * height as f64 * 12.0 / (1u64 << 30) as f64,
                MAX_IMAGE_BYTES >> 30
            ))),
        }
    }

    /// A small image from a closure (tests, patterns).
    pub fn from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> Image {
        let pixels = (0..width * height).map(|i| f(i % width, i / width)).collect();
        Image { width, height, pixels }
    }

    pub fn get(&self, x: usize, y: usize) -> [f32; 3] {
        self.pixels[y * self.width + x]
    }

    /// Errors unless `other` has the same size; names both ports.
    pub fn check_same_size(&self, other: &Image, a: &str, b: &str) -> Result<(), NodeError> {
        if self.width == other.width && self.height == other.height {
            Ok(())
        } else {
            Err(NodeError::input(b, format!("is {} × {} but `{a}` is {} × {}", other.width, other.height, self.width, self.height)))
        }
    }

    /// Number of pixels with a NaN or infinite channel.
    pub fn nonfinite_pixels(&self) -> usize {
        self.pixels.iter().filter(|p| p.iter().any(|c| !c.is_finite())).count()
    }

    pub fn as_floats(&self) -> &[f32] {
        self.pixels.as_flattened()
    }
}

impl PortValue for Image {
    const NAME: &'static str = "Image";
    const COLOR: [u8; 3] = [232, 176, 64];
    const DOC: &'static str = "linear RGB f32 image";

    fn fingerprint(&self) -> Hash {
        Hasher::new().str(Self::NAME).u64(self.width as u64).u64(self.height as u64).f32s(self.as_floats()).finish()
    }
    fn byte_size(&self) -> usize {
        self.pixels.len() * 12 + 16
    }
    fn encode(&self) -> Option<Vec<u8>> {
        let mut b = Vec::with_capacity(16 + self.pixels.len() * 12);
        b.extend_from_slice(&(self.width as u64).to_le_bytes());
        b.extend_from_slice(&(self.height as u64).to_le_bytes());
        for x in self.as_floats() {
            b.extend_from_slice(&x.to_le_bytes());
        }
        Some(b)
    }
    fn decode(b: &[u8]) -> Option<Self> {
        let w = u64::from_le_bytes(b.get(0..8)?.try_into().ok()?) as usize;
        let h = u64::from_le_bytes(b.get(8..16)?.try_into().ok()?) as usize;
        let body = b.get(16..)?;
        if body.len() != w.checked_mul(h)?.checked_mul(12)? {
            return None;
        }
        let floats: Vec<f32> = body.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
        let pixels = floats.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        Some(Image { width: w, height: h, pixels })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encodes_and_decodes_to_the_same_fingerprint() {
        let img = Image::from_fn(3, 2, |x, y| [x as f32, y as f32, -0.5]);
        let back = Image::decode(&img.encode().unwrap()).unwrap();
        assert_eq!(back, img);
        assert_eq!(back.fingerprint(), img.fingerprint());
        assert!(Image::decode(&img.encode().unwrap()[..20]).is_none(), "truncated payload is refused");
    }

    #[test]
    fn huge_images_are_refused_before_allocating_with_the_estimate() {
        let e = Image::try_new(100_000, 100_000).unwrap_err().to_string();
        assert!(e.contains("111.8 GiB"), "{e}");
        assert!(Image::try_new(usize::MAX, 2).is_err());
        assert!(Image::try_new(0, 5).is_err());
    }
}
