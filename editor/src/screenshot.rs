//! The screenshot mode (`relume-editor GRAPH --screenshot OUT.png`): run the graph, wait until
//! the viewer shows the image, take an in-app screenshot (`ViewportCommand::Screenshot`),
//! write it, check that the viewer's part of it is not blank, and close with an exit code.

use crate::viewer::Viewer;
use std::path::PathBuf;
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Frames to draw with the image before the screenshot (layout settles, texture uploads).
const SETTLE_FRAMES: u32 = 5;

pub struct ScreenshotJob {
    pub path: PathBuf,
    deadline: Instant,
    frames_with_image: u32,
    requested: bool,
    done: bool,
    /// The message of a run that failed: nothing will show, so the next frame ends the job.
    failed: Option<String>,
    /// Process exit code: 0 when the screenshot shows a picture.
    pub exit: Arc<AtomicI32>,
}

/// Statistics of the viewer's region of a screenshot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    pub pixels: usize,
    pub distinct_colors: usize,
    pub luma_std: f64,
}

impl Region {
    /// A rendered picture: more than one colour and visible variation (a blank or flat panel
    /// has one colour and no spread; a two-colour checker is a picture).
    pub fn is_picture(&self) -> bool {
        self.pixels > 0 && self.distinct_colors >= 2 && self.luma_std >= 4.0
    }
}

/// The pixel bounds of `rect` (physical pixels) within `img`: x0, y0, x1, y1.
fn bounds(img: &egui::ColorImage, rect: egui::Rect) -> (usize, usize, usize, usize) {
    let x0 = rect.min.x.max(0.0) as usize;
    let y0 = rect.min.y.max(0.0) as usize;
    let x1 = (rect.max.x.max(0.0) as usize).min(img.size[0]);
    let y1 = (rect.max.y.max(0.0) as usize).min(img.size[1]);
    (x0, y0, x1.max(x0), y1.max(y0))
}

/// The part of `img` inside `rect` (physical pixels).
pub fn crop(img: &egui::ColorImage, rect: egui::Rect) -> egui::ColorImage {
    let (x0, y0, x1, y1) = bounds(img, rect);
    let pixels = (y0..y1).flat_map(|y| img.pixels[y * img.size[0] + x0..y * img.size[0] + x1].iter().copied()).collect();
    egui::ColorImage { size: [x1 - x0, y1 - y0], pixels }
}

/// Images side by side with `gap` pixels of `background` between them, top-aligned.
pub fn strip(images: &[egui::ColorImage], gap: usize, background: egui::Color32) -> egui::ColorImage {
    let w = images.iter().map(|i| i.size[0]).sum::<usize>() + gap * images.len().saturating_sub(1);
    let h = images.iter().map(|i| i.size[1]).max().unwrap_or(0);
    let mut out = egui::ColorImage::new([w, h], background);
    let mut x = 0;
    for img in images {
        for y in 0..img.size[1] {
            out.pixels[y * w + x..y * w + x + img.size[0]].copy_from_slice(&img.pixels[y * img.size[0]..(y + 1) * img.size[0]]);
        }
        x += img.size[0] + gap;
    }
    out
}

/// Writes an egui image as PNG.
pub fn save_png(img: &egui::ColorImage, path: &std::path::Path) -> Result<(), String> {
    let rgba: Vec<u8> = img.pixels.iter().flat_map(|c| [c.r(), c.g(), c.b(), 255]).collect();
    image::save_buffer(path, &rgba, img.size[0] as u32, img.size[1] as u32, image::ExtendedColorType::Rgba8)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// The screenshot that arrived this frame, if any.
pub fn arrived(ctx: &egui::Context) -> Option<Arc<egui::ColorImage>> {
    ctx.input(|i| {
        i.raw.events.iter().find_map(|e| match e {
            egui::Event::Screenshot { image, .. } => Some(image.clone()),
            _ => None,
        })
    })
}

/// Measures the pixels of `img` inside `rect` (in physical pixels).
pub fn region_stats(img: &egui::ColorImage, rect: egui::Rect) -> Region {
    let (x0, y0, x1, y1) = bounds(img, rect);
    let mut colors = std::collections::HashSet::new();
    let (mut n, mut sum, mut sum2) = (0usize, 0.0f64, 0.0f64);
    for y in y0..y1 {
        for x in x0..x1 {
            let c = img.pixels[y * img.size[0] + x];
            colors.insert((c.r(), c.g(), c.b()));
            let l = 0.2126 * c.r() as f64 + 0.7152 * c.g() as f64 + 0.0722 * c.b() as f64;
            n += 1;
            sum += l;
            sum2 += l * l;
        }
    }
    let mean = if n > 0 { sum / n as f64 } else { 0.0 };
    let var = if n > 0 { (sum2 / n as f64 - mean * mean).max(0.0) } else { 0.0 };
    Region { pixels: n, distinct_colors: colors.len(), luma_std: var.sqrt() }
}

impl ScreenshotJob {
    pub fn new(path: PathBuf, timeout: Duration, exit: Arc<AtomicI32>) -> Self {
        exit.store(3, Ordering::SeqCst);
        ScreenshotJob { path, deadline: Instant::now() + timeout, frames_with_image: 0, requested: false, done: false, failed: None, exit }
    }

    /// The run failed with `msg` (the status bar shows it): the job ends at the next frame,
    /// with exit code 5 and the message, instead of waiting for an image until the timeout.
    pub fn run_failed(&mut self, msg: &str) {
        self.failed.get_or_insert_with(|| msg.to_string());
    }

    fn finish(&mut self, ctx: &egui::Context, code: i32, msg: &str) {
        eprintln!("relume-editor screenshot: {msg}");
        self.exit.store(code, Ordering::SeqCst);
        self.done = true;
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    /// Called once per frame after drawing.
    pub fn frame(&mut self, ctx: &egui::Context, viewer: &Viewer, busy: bool) {
        if self.done {
            return;
        }
        if let Some(m) = self.failed.take() {
            return self.finish(ctx, 5, &format!("the run failed: {m}"));
        }
        ctx.request_repaint();
        if Instant::now() > self.deadline {
            return self.finish(ctx, 3, "timed out before the viewer showed an image");
        }
        if let Some(img) = arrived(ctx) {
            let ppp = ctx.pixels_per_point();
            let rect = viewer.image_rect.map(|r| egui::Rect::from_min_max(r.min * ppp, r.max * ppp)).unwrap_or(egui::Rect::NOTHING);
            let stats = region_stats(&img, rect);
            let saved = save_png(&img, &self.path);
            let msg = format!(
                "{} ({}×{}); viewer region {} px, {} colours, luma std {:.1}",
                self.path.display(),
                img.size[0],
                img.size[1],
                stats.pixels,
                stats.distinct_colors,
                stats.luma_std
            );
            return match (saved, stats.is_picture()) {
                (Err(e), _) => self.finish(ctx, 4, &e),
                (Ok(()), true) => self.finish(ctx, 0, &format!("ok: {msg}")),
                (Ok(()), false) => self.finish(ctx, 2, &format!("the viewer looks blank: {msg}")),
            };
        }
        if !busy && viewer.has_image() && viewer.image_rect.is_some() {
            self.frames_with_image += 1;
            if self.frames_with_image >= SETTLE_FRAMES && !self.requested {
                self.requested = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_run_ends_the_job_at_the_next_frame_with_its_message() {
        let exit = Arc::new(AtomicI32::new(0));
        let mut job = ScreenshotJob::new(PathBuf::from("never.png"), Duration::from_secs(600), exit.clone());
        let (ctx, viewer) = (egui::Context::default(), Viewer::default());
        let _ = ctx.run(egui::RawInput::default(), |ctx| job.frame(ctx, &viewer, true));
        assert_eq!(exit.load(Ordering::SeqCst), 3, "still waiting while the run is busy");
        job.run_failed("node \"scene\" (LoadScene): cannot read scenes/missing.ron");
        let _ = ctx.run(egui::RawInput::default(), |ctx| job.frame(ctx, &viewer, false));
        assert_eq!(exit.load(Ordering::SeqCst), 5, "ended at once, long before the timeout");
        assert!(job.done);
    }

    #[test]
    fn flat_regions_are_blank_and_pictures_are_not() {
        let flat = egui::ColorImage::new([64, 64], egui::Color32::from_gray(30));
        let r = egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(64.0, 64.0));
        assert!(!region_stats(&flat, r).is_picture());
        let mut pic = flat.clone();
        for (i, p) in pic.pixels.iter_mut().enumerate() {
            *p = egui::Color32::from_rgb((i % 64 * 4) as u8, (i / 64 * 4) as u8, 90);
        }
        assert!(region_stats(&pic, r).is_picture());
        assert_eq!(region_stats(&pic, egui::Rect::NOTHING).pixels, 0);
        // A 16 × 16 checker of two colours is a picture, not a blank viewer.
        let mut checker = flat.clone();
        for (i, p) in checker.pixels.iter_mut().enumerate() {
            let (x, y) = (i % 64 / 4, i / 64 / 4);
            *p = if (x + y) % 2 == 0 { egui::Color32::from_rgb(230, 128, 51) } else { egui::Color32::from_gray(20) };
        }
        assert!(region_stats(&checker, r).is_picture());
    }

    #[test]
    fn crops_lie_side_by_side_in_a_strip() {
        let mut img = egui::ColorImage::new([8, 6], egui::Color32::BLACK);
        img.pixels[2 * 8 + 3] = egui::Color32::WHITE;
        let c = crop(&img, egui::Rect::from_min_max(egui::pos2(2.0, 1.0), egui::pos2(5.0, 4.0)));
        assert_eq!(c.size, [3, 3]);
        assert_eq!(c.pixels[3 + 1], egui::Color32::WHITE);
        assert_eq!(crop(&img, egui::Rect::from_min_max(egui::pos2(6.0, 5.0), egui::pos2(20.0, 20.0))).size, [2, 1]);
        let s = strip(&[c.clone(), c], 2, egui::Color32::RED);
        assert_eq!(s.size, [8, 3]);
        assert_eq!((s.pixels[3], s.pixels[4], s.pixels[5 + 8 + 1]), (egui::Color32::RED, egui::Color32::RED, egui::Color32::WHITE));
    }
}
