//! `SplatRows`: the partial result of a renderer sharded over image rows whose samples also
//! land outside their rows (light tracing): the band of its own rows, and sums over the whole
//! image of what its samples splatted, with their squares for the variance.

use super::{Image, ImageRows, Layer};
use relume_core::{NodeError, PortValue, ShardSpec};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SplatRows {
    /// The band's own pixels (mean and variance of what its samples brought to them).
    pub band: ImageRows,
    /// Per pixel of the whole image, the sum of the band's splats and of their squares (each
    /// sample's splats to one pixel summed before squaring).
    pub sum: Layer,
    pub sum2: Layer,
}

impl PortValue for SplatRows {
    const NAME: &'static str = "SplatRows";
    const COLOR: [u8; 3] = [210, 130, 70];
    const DOC: &'static str =
        "a band of image rows and the splats its samples left on the whole image (a sharded light tracer's partial result)";
    fn byte_size(&self) -> usize {
        self.band.byte_size() + (self.sum.0.len() + self.sum2.0.len()) * 12
    }
    relume_core::serde_codec!();
}

/// Bands for a splatting renderer: whole rows, at least about 4096 pixels and at most 16
/// bands, since every band carries two whole-image layers.
pub fn splat_spec(width: usize, height: usize) -> ShardSpec {
    let rows = (4096 / width.max(1)).max(height.div_ceil(16)).max(1);
    ShardSpec::new(height as u64, rows as u64)
}

/// Adds up the splats of `parts` (in order) over `n` samples in all, each the sum of `per`
/// samples' splats per pixel (a pixel's mean is sum / `per`): the mean image and the variance
/// of that mean. Refuses parts of another image size.
pub fn gather_splats(width: usize, height: usize, parts: &[&SplatRows], n: f64, per: f64) -> Result<(Image, Image), NodeError> {
    let pixels = width * height;
    let (mut mean, mut var) = (Image::try_new(width, height)?, Image::try_new(width, height)?);
    if parts.iter().any(|p| p.sum.0.len() != pixels || p.sum2.0.len() != pixels) {
        return Err(NodeError::failed(format!("a band's splats do not cover the {width} × {height} image")));
    }
    for i in 0..pixels {
        for c in 0..3 {
            let (s, s2) = parts.iter().fold((0.0f64, 0.0f64), |(a, b), p| (a + p.sum.0[i][c] as f64, b + p.sum2.0[i][c] as f64));
            mean.pixels[i][c] = (s / per) as f32;
            var.pixels[i][c] = ((s2 - s * s / n).max(0.0) / (per * per)) as f32;
        }
    }
    Ok((mean, var))
}
