//! MedianFilter node.

use crate::types::Image;
use rayon::prelude::*;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};

node_doc! {
    /// Per-channel median over a (2·radius + 1)² window with clamp-to-edge borders: removes
    /// isolated outliers (fireflies) while keeping edges. NaN sorts above every number
    /// (total order), so a lone NaN pixel is replaced by its neighbours' median.
    pub struct MedianFilter;
}

pub struct MedianFilterParams {
    pub radius: usize,
}

impl Params for MedianFilterParams {
    fn schema() -> Schema {
        Schema::new().int("radius", 1, 0, 16).unit("px").help("window half-size; 0 returns the input")
    }
    fn from_values(v: &ParamValues) -> Self {
        MedianFilterParams { radius: v.int("radius") as usize }
    }
}

/// Median-filters an image (shared with later pipeline stages).
pub fn median_filter(img: &Image, radius: usize) -> Image {
    if radius == 0 {
        return img.clone();
    }
    let (w, h, r) = (img.width as i64, img.height as i64, radius as i64);
    let mut out = vec![[0.0f32; 3]; img.pixels.len()];
    out.par_chunks_mut(img.width).enumerate().for_each(|(y, row)| {
        let mut win = Vec::with_capacity(((2 * r + 1) * (2 * r + 1)) as usize);
        for (x, px) in row.iter_mut().enumerate() {
            for (c, out_c) in px.iter_mut().enumerate() {
                win.clear();
                for dy in -r..=r {
                    let sy = (y as i64 + dy).clamp(0, h - 1);
                    for dx in -r..=r {
                        let sx = (x as i64 + dx).clamp(0, w - 1);
                        win.push(img.pixels[(sy * w + sx) as usize][c]);
                    }
                }
                let mid = win.len() / 2;
                win.select_nth_unstable_by(mid, f32::total_cmp);
                *out_c = win[mid];
            }
        }
    });
    Image { width: img.width, height: img.height, pixels: out }
}

impl Node for MedianFilter {
    const KIND: &'static str = "MedianFilter";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "image";
    const CACHING: Caching = Caching::Disk;
    type Params = MedianFilterParams;

    fn ports() -> Ports {
        Ports::new().input::<Image>("image").output::<Image>("image")
    }

    fn run(&self, p: &MedianFilterParams, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        cx.check()?;
        let out = median_filter(io.input::<Image>("image")?, p.radius);
        io.set("image", out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{first, i, run_on};
    use relume_core::Value;

    #[test]
    fn removes_an_isolated_outlier_and_keeps_a_step_edge() {
        let img = Image::from_fn(7, 7, |x, y| {
            [if (x, y) == (3, 3) {
                1e6
            } else if x < 3 {
                0.0
            } else {
                1.0
            }; 3]
        });
        let out: Image = first(&run_on(MedianFilter, &[("radius", i(1))], vec![Value::new(img)]).unwrap());
        assert_eq!(out.get(3, 3), [1.0; 3]);
        assert_eq!(out.get(1, 5), [0.0; 3]);
        assert_eq!(out.get(5, 5), [1.0; 3]);
    }

    #[test]
    fn a_nan_pixel_is_replaced_and_tiny_images_work() {
        let img = Image::from_fn(3, 3, |x, y| [if (x, y) == (1, 1) { f32::NAN } else { 0.5 }; 3]);
        assert_eq!(median_filter(&img, 1).get(1, 1), [0.5; 3]);
        let one = Image::from_fn(1, 1, |_, _| [4.0; 3]);
        assert_eq!(median_filter(&one, 16), one);
    }
}
