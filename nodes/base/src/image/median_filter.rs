use crate::types::Image;
use relume_core::{node, params, CancelToken, NodeError, RunCtx};

params! {
    /// Per-channel median over a (2·radius + 1)² window with clamp-to-edge borders: removes
    /// isolated outliers (fireflies) while keeping edges. NaN sorts above every number
    /// (total order), so a lone NaN pixel is replaced by its neighbours' median.
    pub struct MedianFilter {
        /// window half-size; 0 returns the input
        pub radius: usize = 1, range = 0..=16, unit = "px";
    }
}

/// Median-filters an image (shared with later pipeline stages), outside a node run: never
/// cancelled.
pub fn median_filter(img: &Image, radius: usize) -> Image {
    let cancel = CancelToken::new();
    median_filter_with(img, radius, &RunCtx::new("median_filter", &cancel, None)).expect("never cancelled")
}

/// Median-filters an image row by row in parallel, with `cx`'s progress and cancellation.
pub fn median_filter_with(img: &Image, radius: usize, cx: &RunCtx) -> Result<Image, NodeError> {
    if radius == 0 {
        return Ok(img.clone());
    }
    let (w, h, r) = (img.width as i64, img.height as i64, radius as i64);
    let mut out = vec![[0.0f32; 3]; img.pixels.len()];
    cx.par_chunks_mut(&mut out, img.width, |y, row| {
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
    })?;
    Ok(Image { width: img.width, height: img.height, pixels: out })
}

/// The median over a (2·radius + 1)² window of one `w × h` plane, taking only the window's
/// pixels of the centre's class (`class[p]`, e.g. the object-id image) and inside the image:
/// a filter that never mixes objects (the SV relighting's per-basis-image filter, [S] 4.2).
/// Even counts take the upper median, as `median_filter`; NaN sorts above every number.
pub fn median_plane_by_class(plane: &[f32], class: &[u32], w: usize, h: usize, radius: usize) -> Vec<f32> {
    assert!(plane.len() == w * h && class.len() == w * h, "plane, classes and size disagree");
    let r = radius as i64;
    let mut win = Vec::with_capacity(((2 * r + 1) * (2 * r + 1)) as usize);
    (0..w * h)
        .map(|p| {
            let (x, y, c) = ((p % w) as i64, (p / w) as i64, class[p]);
            win.clear();
            for sy in (y - r).max(0)..=(y + r).min(h as i64 - 1) {
                for sx in (x - r).max(0)..=(x + r).min(w as i64 - 1) {
                    let q = sy as usize * w + sx as usize;
                    if class[q] == c {
                        win.push(plane[q]);
                    }
                }
            }
            let mid = win.len() / 2;
            win.select_nth_unstable_by(mid, f32::total_cmp);
            win[mid]
        })
        .collect()
}

#[node(category = "image", outputs = [image])]
impl MedianFilter {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        relume_core::MemoryEstimate { outputs: vec![inputs[0]], working: 0 }
    }

    fn run(&self, image: &Image, cx: &RunCtx) -> Result<Image, NodeError> {
        median_filter_with(image, self.radius, cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{cancels_midway, first, i, run_on};
    use relume_core::Value;

    #[test]
    fn the_class_median_never_mixes_classes() {
        // Left half class 0 at 1.0, right half class 1 at 5.0, one outlier in each; a thin
        // class-1 line of 9.0 inside class 0 keeps its value (its window has only itself and
        // its line neighbours), where the plain median would erase it.
        let (w, h) = (8, 6);
        let class: Vec<u32> = (0..w * h).map(|p| if p % w >= 4 || p % w == 1 { 1 } else { 0 }).collect();
        let mut plane: Vec<f32> = (0..w * h)
            .map(|p| {
                if p % w >= 4 {
                    5.0
                } else if p % w == 1 {
                    9.0
                } else {
                    1.0
                }
            })
            .collect();
        plane[2 * w + 2] = 1e6;
        plane[3 * w + 6] = -1e6;
        let out = median_plane_by_class(&plane, &class, w, h, 1);
        for (p, v) in out.iter().enumerate() {
            let want = if p % w >= 4 {
                5.0
            } else if p % w == 1 {
                9.0
            } else {
                1.0
            };
            assert_eq!(*v, want, "pixel {p}");
        }
        assert_eq!(median_plane_by_class(&plane, &class, w, h, 0), plane, "radius 0 is the identity");
    }

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
        let out: Image = first(&run_on::<MedianFilter>(&[("radius", i(1))], vec![Value::new(img)]).unwrap());
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

    #[test]
    fn cancels_midway_through_a_large_image() {
        let img = Image::from_fn(512, 512, |x, y| [x as f32, y as f32, 1.0]);
        cancels_midway::<MedianFilter>(&[("radius", i(2))], vec![Value::new(img)]);
    }
}
