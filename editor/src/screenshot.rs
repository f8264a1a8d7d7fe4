//! The screenshot mode (`relume-editor GRAPH --screenshot OUT.png`): run the graph, wait until
//! the viewer shows the image, take an in-app screenshot (`ViewportCommand::Screenshot`),
//! write it, check that the viewer's part of it and the node graph's are not blank, and close
//! with an exit code.

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
    ready_frames: u32,
    requested: bool,
    done: bool,
    /// The message of a run that failed: nothing will show, so the next frame ends the job.
    failed: Option<String>,
    /// Process exit code: 0 when the screenshot shows a picture.
    pub exit: Arc<AtomicI32>,
    /// Save only the node graph, cropped to what is drawn on it.
    graph_only: bool,
}

/// Statistics of the viewer's region of a screenshot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    pub pixels: usize,
    pub distinct_colors: usize,
    pub luma_std: f64,
}

impl Region {
    fn describe(&self) -> String {
        format!("{} px, {} colours, luma std {:.1}", self.pixels, self.distinct_colors, self.luma_std)
    }

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

/// The part of `rect` (physical pixels) in which `img` differs from the region's most common
/// colour (its background), grown by `margin` pixels and kept inside `rect`.
pub fn drawn_part(img: &egui::ColorImage, rect: egui::Rect, margin: usize) -> egui::Rect {
    let (x0, y0, x1, y1) = bounds(img, rect);
    let mut counts = std::collections::HashMap::new();
    for y in y0..y1 {
        for x in x0..x1 {
            *counts.entry(img.pixels[y * img.size[0] + x]).or_insert(0usize) += 1;
        }
    }
    let Some((&background, _)) = counts.iter().max_by_key(|(c, n)| (**n, c.to_array())) else { return egui::Rect::NOTHING };
    let (mut lo, mut hi) = ((x1, y1), (x0, y0));
    for y in y0..y1 {
        for x in x0..x1 {
            if img.pixels[y * img.size[0] + x] != background {
                lo = (lo.0.min(x), lo.1.min(y));
                hi = (hi.0.max(x + 1), hi.1.max(y + 1));
            }
        }
    }
    if hi.0 <= lo.0 {
        return egui::Rect::NOTHING;
    }
    let min = egui::pos2(lo.0.saturating_sub(margin).max(x0) as f32, lo.1.saturating_sub(margin).max(y0) as f32);
    let max = egui::pos2((hi.0 + margin).min(x1) as f32, (hi.1 + margin).min(y1) as f32);
    egui::Rect::from_min_max(min, max)
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
        ScreenshotJob {
            path,
            deadline: Instant::now() + timeout,
            ready_frames: 0,
            requested: false,
            done: false,
            failed: None,
            exit,
            graph_only: false,
        }
    }

    /// Saves only the node graph's part of the screenshot, cropped to its nodes, without
    /// waiting for a run (none is needed to draw the graph).
    pub fn graph_only(self) -> Self {
        ScreenshotJob { graph_only: true, ..self }
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

    /// Whether the job has ended (the window is closing).
    pub fn is_done(&self) -> bool {
        self.done
    }

    /// Called once per frame after drawing. `canvas`: where the node graph was drawn (points),
    /// none when the layout hides it.
    pub fn frame(&mut self, ctx: &egui::Context, viewer: &Viewer, canvas: Option<egui::Rect>, busy: bool) {
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
            return self.save(ctx, &img, viewer, canvas);
        }
        // The graph alone needs no run: the canvas is drawn from the first frame.
        let ready = if self.graph_only { canvas.is_some() } else { !busy && viewer.has_image() && viewer.image_rect.is_some() };
        if ready {
            self.ready_frames += 1;
            if self.ready_frames >= SETTLE_FRAMES && !self.requested {
                self.requested = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot);
            }
        }
    }

    /// Writes the screenshot (or the node graph's part of it) and ends the job with the
    /// verdict on the parts it checks: the viewer's image and the node graph must not be blank.
    fn save(&mut self, ctx: &egui::Context, img: &egui::ColorImage, viewer: &Viewer, canvas: Option<egui::Rect>) {
        let ppp = ctx.pixels_per_point();
        let physical = |r: egui::Rect| egui::Rect::from_min_max(r.min * ppp, r.max * ppp);
        let graph = canvas.map(|r| region_stats(img, physical(r)));
        let (saved, size) = match canvas {
            Some(r) if self.graph_only => {
                let part = crop(img, drawn_part(img, physical(r), 12));
                (save_png(&part, &self.path), part.size)
            }
            _ if self.graph_only => (Err("--graph-only: the layout shows no node graph".to_string()), [0, 0]),
            _ => (save_png(img, &self.path), img.size),
        };
        let mut msg = format!("{} ({}×{})", self.path.display(), size[0], size[1]);
        let viewer_ok = if self.graph_only {
            true
        } else {
            let stats = region_stats(img, viewer.image_rect.map(physical).unwrap_or(egui::Rect::NOTHING));
            msg += &format!("; viewer region {}", stats.describe());
            stats.is_picture()
        };
        if let Some(g) = &graph {
            msg += &format!("; node graph {}", g.describe());
        }
        match (saved, viewer_ok, graph.map_or(true, |g| g.is_picture())) {
            (Err(e), _, _) => self.finish(ctx, 4, &e),
            (Ok(()), true, true) => self.finish(ctx, 0, &format!("ok: {msg}")),
            (Ok(()), false, _) => self.finish(ctx, 2, &format!("the viewer looks blank: {msg}")),
            (Ok(()), true, false) => self.finish(ctx, 2, &format!("the node graph looks blank: {msg}")),
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
        let _ = ctx.run(egui::RawInput::default(), |ctx| job.frame(ctx, &viewer, None, true));
        assert_eq!(exit.load(Ordering::SeqCst), 3, "still waiting while the run is busy");
        job.run_failed("node \"scene\" (LoadScene): cannot read scenes/missing.ron");
        let _ = ctx.run(egui::RawInput::default(), |ctx| job.frame(ctx, &viewer, None, false));
        assert_eq!(exit.load(Ordering::SeqCst), 5, "ended at once, long before the timeout");
        assert!(job.done);
    }

    #[test]
    fn the_drawn_part_is_the_box_around_what_differs_from_the_background() {
        let mut img = egui::ColorImage::new([100, 80], egui::Color32::from_gray(27));
        for y in 30..40 {
            for x in 20..50 {
                img.pixels[y * 100 + x] = egui::Color32::from_gray(63);
            }
        }
        // Outside the region looked at: ignored.
        img.pixels[5 * 100 + 95] = egui::Color32::WHITE;
        let region = egui::Rect::from_min_max(egui::pos2(0.0, 10.0), egui::pos2(90.0, 80.0));
        let r = drawn_part(&img, region, 4);
        assert_eq!(r, egui::Rect::from_min_max(egui::pos2(16.0, 26.0), egui::pos2(54.0, 44.0)));
        // The margin stays inside the region.
        let r = drawn_part(&img, region, 25);
        assert_eq!(r, egui::Rect::from_min_max(egui::pos2(0.0, 10.0), egui::pos2(75.0, 65.0)));
        // Nothing drawn: nothing to keep.
        let flat = egui::ColorImage::new([10, 10], egui::Color32::BLACK);
        assert_eq!(drawn_part(&flat, region, 4), egui::Rect::NOTHING);
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
