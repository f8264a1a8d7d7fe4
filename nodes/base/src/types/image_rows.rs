//! `ImageRows`: a band of rows of one or more images with counters, the partial result of a
//! node sharded over image rows (`PathTrace`, `DirectLight`), and the gather that stacks
//! bands back into whole images.

use super::Image;
use relume_core::{NodeError, PortValue, ShardSpec};
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Rows `first_row ..` of `layers.len()` images of width `width` (each layer row-major,
/// `width × rows` pixels) and counters summed over the band (rays, dropped samples, …).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageRows {
    pub width: u64,
    pub first_row: u64,
    pub rows: u64,
    pub layers: Vec<Layer>,
    pub counters: Vec<u64>,
}

/// One image's pixels in a band.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Layer(#[serde(with = "relume_core::codec::pod_vec")] pub Vec<[f32; 3]>);

impl ImageRows {
    /// The band of rows `rows` holding the given images (each `width × rows.len()`).
    pub fn new(width: usize, rows: Range<usize>, layers: Vec<Image>, counters: Vec<u64>) -> ImageRows {
        debug_assert!(layers.iter().all(|l| l.width == width && l.height == rows.len()));
        ImageRows {
            width: width as u64,
            first_row: rows.start as u64,
            rows: rows.len() as u64,
            layers: layers.into_iter().map(|l| Layer(l.pixels)).collect(),
            counters,
        }
    }
}

/// Disk encoding: serde through postcard, pixels as little-endian f32 arrays.
impl PortValue for ImageRows {
    const NAME: &'static str = "ImageRows";
    const COLOR: [u8; 3] = [200, 150, 60];
    const DOC: &'static str = "a band of image rows with counters (a sharded renderer's partial result)";
    fn byte_size(&self) -> usize {
        self.layers.iter().map(|l| l.0.len() * 12).sum::<usize>() + self.counters.len() * 8 + 24
    }
    relume_core::serde_codec!();
}

/// The shard spec of an image `width × height` split over rows: chunks of about 4096 pixels
/// (whole rows), so that a 256² image has 16 chunks and a 1920 × 1080 one 540.
pub fn row_spec(width: usize, height: usize) -> ShardSpec {
    ShardSpec::new(height as u64, (4096 / width.max(1)).max(1) as u64)
}

/// Stacks bands (in row order) into `layers` whole images of `width × height` and sums the
/// counters in band order. Refuses bands that do not tile the image exactly.
pub fn gather_rows(width: usize, height: usize, layers: usize, parts: &[&ImageRows]) -> Result<(Vec<Image>, Vec<u64>), NodeError> {
    let mut images = (0..layers).map(|_| Image::try_new(width, height)).collect::<Result<Vec<_>, _>>()?;
    let mut counters: Vec<u64> = Vec::new();
    let mut next = 0u64;
    for p in parts {
        let ok = p.width == width as u64
            && p.first_row == next
            && p.layers.len() == layers
            && p.layers.iter().all(|l| l.0.len() as u64 == p.width * p.rows);
        if !ok {
            return Err(NodeError::failed(format!(
                "a band of rows {}..{} does not continue the image at row {next} ({width} wide, {layers} layers)",
                p.first_row,
                p.first_row + p.rows
            )));
        }
        let at = next as usize * width;
        for (img, l) in images.iter_mut().zip(&p.layers) {
            img.pixels[at..at + l.0.len()].copy_from_slice(&l.0);
        }
        if counters.len() < p.counters.len() {
            counters.resize(p.counters.len(), 0);
        }
        for (c, x) in counters.iter_mut().zip(&p.counters) {
            *c += x;
        }
        next += p.rows;
    }
    if next != height as u64 {
        return Err(NodeError::failed(format!("the bands cover {next} of {height} rows")));
    }
    Ok((images, counters))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn band(width: usize, rows: Range<usize>) -> ImageRows {
        let img = Image::from_fn(width, rows.len(), |x, y| [x as f32, (y + rows.start) as f32, 1.0]);
        ImageRows::new(width, rows.clone(), vec![img.clone(), img], vec![rows.len() as u64, 1])
    }

    #[test]
    fn bands_stack_into_the_image_and_counters_sum() {
        let parts = [band(3, 0..2), band(3, 2..3), band(3, 3..5)];
        let (imgs, counters) = gather_rows(3, 5, 2, &parts.iter().collect::<Vec<_>>()).unwrap();
        assert_eq!(imgs[0], Image::from_fn(3, 5, |x, y| [x as f32, y as f32, 1.0]));
        assert_eq!(imgs[1], imgs[0]);
        assert_eq!(counters, vec![5, 3]);
    }

    #[test]
    fn gaps_overlaps_and_short_covers_are_refused() {
        let gather = |parts: &[ImageRows]| gather_rows(3, 5, 2, &parts.iter().collect::<Vec<_>>());
        assert!(gather(&[band(3, 0..2), band(3, 3..5)]).is_err(), "gap");
        assert!(gather(&[band(3, 0..3), band(3, 2..5)]).is_err(), "overlap");
        assert!(gather(&[band(3, 0..2), band(3, 2..4)]).is_err(), "short");
        assert!(gather(&[band(4, 0..5)]).is_err(), "width");
    }

    #[test]
    fn round_trips_through_the_disk_encoding_and_refuses_truncation() {
        let b = band(4, 3..6);
        let bytes = b.encode();
        assert_eq!(ImageRows::decode(&bytes).unwrap(), b);
        assert!(ImageRows::decode(&bytes[..bytes.len() - 1]).is_none());
    }

    #[test]
    fn row_chunks_are_whole_rows_of_about_4096_pixels() {
        assert_eq!(row_spec(256, 256).chunks(), 16);
        assert_eq!(row_spec(8192, 3).chunk, 1);
        assert_eq!(row_spec(1920, 1080).chunks(), 540);
    }
}
