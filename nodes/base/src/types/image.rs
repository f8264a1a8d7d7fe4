//! `Image`: a linear-RGB f32 raster, row-major, top row first.

use relume_core::{Hash, Hasher, NodeError, PortValue};
use std::borrow::Cow;

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
            _ => Err(NodeError::over_limit(format!(
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

/// The pixels' bytes as f32 little-endian: a view of the pixels on little-endian machines,
/// a converted copy elsewhere.
fn le_bytes(floats: &[f32]) -> Cow<'_, [u8]> {
    if cfg!(target_endian = "little") {
        Cow::Borrowed(bytemuck::cast_slice(floats))
    } else {
        Cow::Owned(floats.iter().flat_map(|x| x.to_le_bytes()).collect())
    }
}

/// Disk encoding: width and height as u64 little-endian, then the pixels as f32
/// little-endian, row-major.
impl PortValue for Image {
    const NAME: &'static str = "Image";
    const COLOR: [u8; 3] = [232, 176, 64];
    const DOC: &'static str = "linear RGB f32 image";
    fn size(&self) -> relume_core::PortSize {
        relume_core::PortSize::image(self.width, self.height)
    }

    /// The default fingerprint (the hash of the name and the encoding), streamed from the
    /// pixels without building the encoded copy.
    fn fingerprint(&self) -> Hash {
        Hasher::new()
            .str(Self::NAME)
            .u64(16 + self.pixels.len() as u64 * 12)
            .raw(&(self.width as u64).to_le_bytes())
            .raw(&(self.height as u64).to_le_bytes())
            .raw(&le_bytes(self.as_floats()))
            .finish()
    }
    fn byte_size(&self) -> usize {
        self.pixels.len() * 12 + 16
    }
    fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(16 + self.pixels.len() * 12);
        b.extend_from_slice(&(self.width as u64).to_le_bytes());
        b.extend_from_slice(&(self.height as u64).to_le_bytes());
        b.extend_from_slice(&le_bytes(self.as_floats()));
        b
    }
    fn decode(b: &[u8]) -> Option<Self> {
        let w = usize::try_from(u64::from_le_bytes(b.get(0..8)?.try_into().ok()?)).ok()?;
        let h = usize::try_from(u64::from_le_bytes(b.get(8..16)?.try_into().ok()?)).ok()?;
        let body = b.get(16..)?;
        let n = w.checked_mul(h)?;
        if body.len() != n.checked_mul(12)? {
            return None;
        }
        // Copied byte-wise: `body` need not be aligned for f32.
        let mut pixels = vec![[0.0f32; 3]; n];
        bytemuck::cast_slice_mut::<[f32; 3], u8>(&mut pixels).copy_from_slice(body);
        if cfg!(target_endian = "big") {
            for x in pixels.as_flattened_mut() {
                *x = f32::from_bits(u32::from_le(x.to_bits()));
            }
        }
        Some(Image { width: w, height: h, pixels })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encodes_and_decodes_to_the_same_fingerprint() {
        let img = Image::from_fn(3, 2, |x, y| [x as f32, y as f32, -0.5]);
        let back = Image::decode(&img.encode()).unwrap();
        assert_eq!(back, img);
        assert_eq!(back.fingerprint(), img.fingerprint());
        assert!(Image::decode(&img.encode()[..20]).is_none(), "truncated payload is refused");
    }

    #[test]
    fn the_encoding_is_the_documented_layout_and_the_fingerprint_its_hash() {
        let img = Image::from_fn(2, 1, |x, _| [x as f32, 0.5, -2.0]);
        let b = img.encode();
        assert_eq!(&b[..16], &[2, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(&b[16..20], &0f32.to_le_bytes());
        assert_eq!(&b[36..40], &(-2f32).to_le_bytes());
        assert_eq!(b.len(), 16 + 2 * 12);
        // The streamed fingerprint is the trait's default: the hash of the name and the encoding.
        assert_eq!(img.fingerprint(), Hasher::new().str(Image::NAME).bytes(&b).finish());
        let other = Image::from_fn(1, 2, |_, y| [y as f32, 0.5, -2.0]);
        assert_ne!(img.fingerprint(), other.fingerprint(), "the size is part of the content");
    }

    #[test]
    fn bad_payloads_are_refused_without_panicking() {
        let img = Image::from_fn(3, 2, |x, y| [x as f32, y as f32, -0.5]);
        let b = img.encode();
        for len in 0..b.len() {
            assert!(Image::decode(&b[..len]).is_none(), "{len} bytes");
        }
        let mut long = b.clone();
        long.push(0);
        assert!(Image::decode(&long).is_none(), "trailing bytes are refused");
        // Sizes whose product overflows, or far larger than the payload, allocate nothing.
        let mut huge = Vec::new();
        huge.extend_from_slice(&u64::MAX.to_le_bytes());
        huge.extend_from_slice(&3u64.to_le_bytes());
        assert!(Image::decode(&huge).is_none());
        let mut big = Vec::new();
        big.extend_from_slice(&(1u64 << 20).to_le_bytes());
        big.extend_from_slice(&(1u64 << 20).to_le_bytes());
        big.extend_from_slice(&[0; 24]);
        assert!(Image::decode(&big).is_none());
        // Decoding from an unaligned slice works.
        let mut shifted = vec![0u8];
        shifted.extend_from_slice(&b);
        assert_eq!(Image::decode(&shifted[1..]).unwrap(), img);
    }

    #[test]
    fn huge_images_are_refused_before_allocating_with_the_estimate() {
        let e = Image::try_new(100_000, 100_000).unwrap_err().to_string();
        assert!(e.contains("111.8 GiB"), "{e}");
        assert!(Image::try_new(usize::MAX, 2).is_err());
        assert!(Image::try_new(0, 5).is_err());
    }
}
