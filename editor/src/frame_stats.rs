//! The frame-time overlay and recorder: how many frames the editor draws and how many new
//! images the viewer shows per second, the time from an edit to its pixels, the last run's
//! per-node times; a record switch writes every frame of a session to CSV, so the editor's
//! speed can be set beside the benches'.

use relume_core::RunReport;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The window the rates are counted over.
const RATE_WINDOW: Duration = Duration::from_secs(1);
/// Per-node times the overlay lists (the slowest of the last run).
const OVERLAY_NODES: usize = 4;

/// A new image in the viewer: which revision of the graph it shows and how it got there.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageShown {
    pub revision: u64,
    /// From the edit that made `revision` to the frame that shows it.
    pub latency_ms: f64,
    /// The run's own time.
    pub run_ms: f64,
    /// Nodes that ran for it, with their times.
    pub nodes: Vec<(String, f64)>,
}

impl ImageShown {
    pub fn new(revision: u64, latency_ms: f64, report: &RunReport) -> Self {
        let mut nodes: Vec<(String, f64)> = report.nodes.iter().filter(|n| n.status == "ran").map(|n| (n.id.clone(), n.wall_ms)).collect();
        nodes.sort_by(|a, b| b.1.total_cmp(&a.1));
        ImageShown { revision, latency_ms, run_ms: report.total_ms, nodes }
    }
}

/// One recorded frame.
#[derive(Clone, Debug)]
struct Row {
    t_s: f64,
    frame_ms: f64,
    /// Of which the editor's own work on the frame (drawing aside).
    ui_ms: f64,
    revision: u64,
    image: Option<ImageShown>,
}

/// What a recording measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    pub seconds: f64,
    pub frames: usize,
    pub images: usize,
    /// Median and 95th percentile of the edit-to-pixels latency of the images shown.
    pub latency_median_ms: f64,
    pub latency_p95_ms: f64,
    /// Median of the runs' own times.
    pub run_median_ms: f64,
    /// Median of the editor's own work per frame.
    pub ui_median_ms: f64,
}

impl Summary {
    pub fn frames_per_s(&self) -> f64 {
        self.frames as f64 / self.seconds.max(1e-9)
    }
    pub fn images_per_s(&self) -> f64 {
        self.images as f64 / self.seconds.max(1e-9)
    }
    pub fn line(&self) -> String {
        format!(
            "{:.1} s: {} frames ({:.1}/s, editor's work median {:.1} ms), {} new images ({:.1}/s), edit to pixels median {:.1} ms (95 % {:.1} ms), run median {:.1} ms",
            self.seconds,
            self.frames,
            self.frames_per_s(),
            self.ui_median_ms,
            self.images,
            self.images_per_s(),
            self.latency_median_ms,
            self.latency_p95_ms,
            self.run_median_ms
        )
    }
}

fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Frame and image rates, the last image's latency and node times, and the recording.
pub struct FrameStats {
    frames: VecDeque<Instant>,
    images: VecDeque<Instant>,
    last_frame: Option<Instant>,
    pub last_image: Option<ImageShown>,
    /// Draw the overlay on the viewer.
    pub overlay: bool,
    recording: Option<(Instant, Vec<Row>)>,
    /// Where a recording is written when it stops.
    pub record_path: Option<PathBuf>,
    /// The image shown since the last frame was counted.
    fresh: Option<ImageShown>,
}

impl Default for FrameStats {
    fn default() -> Self {
        FrameStats {
            frames: VecDeque::new(),
            images: VecDeque::new(),
            last_frame: None,
            last_image: None,
            overlay: true,
            recording: None,
            record_path: None,
            fresh: None,
        }
    }
}

impl FrameStats {
    /// A new image went to the viewer.
    pub fn image(&mut self, shown: ImageShown) {
        self.images.push_back(Instant::now());
        self.last_image = Some(shown.clone());
        self.fresh = Some(shown);
    }

    /// A frame was drawn (called once per frame, after the viewer took its image in);
    /// `ui_ms`: the editor's own work on it.
    pub fn frame(&mut self, revision: u64, ui_ms: f64) {
        let now = Instant::now();
        let frame_ms = self.last_frame.map_or(0.0, |t| now.duration_since(t).as_secs_f64() * 1e3);
        self.last_frame = Some(now);
        self.frames.push_back(now);
        for q in [&mut self.frames, &mut self.images] {
            while q.front().is_some_and(|t| now.duration_since(*t) > RATE_WINDOW) {
                q.pop_front();
            }
        }
        let image = self.fresh.take();
        if let Some((t0, rows)) = &mut self.recording {
            rows.push(Row { t_s: now.duration_since(*t0).as_secs_f64(), frame_ms, ui_ms, revision, image });
        }
    }

    /// Frames drawn and new images shown over the last second.
    pub fn rates(&self) -> (usize, usize) {
        (self.frames.len(), self.images.len())
    }

    pub fn is_recording(&self) -> bool {
        self.recording.is_some()
    }

    pub fn start_recording(&mut self) {
        self.recording = Some((Instant::now(), Vec::new()));
    }

    /// Ends the recording: what it measured, and the CSV written to `record_path` (or to
    /// `default_path` when none is set). `None` when nothing was recording.
    pub fn stop_recording(&mut self, default_path: &Path) -> Option<Result<(PathBuf, Summary), String>> {
        let (_, rows) = self.recording.take()?;
        let path = self.record_path.clone().unwrap_or_else(|| default_path.to_path_buf());
        let summary = summarize(&rows);
        Some(
            relume_core::graph::write_atomic(&path, csv(&rows).as_bytes())
                .map(|_| (path.clone(), summary))
                .map_err(|e| format!("cannot write the frame times to {}: {e}", path.display())),
        )
    }

    /// The overlay's lines.
    pub fn overlay_lines(&self) -> Vec<String> {
        let (frames, images) = self.rates();
        let mut lines = vec![format!("{images} images/s · {frames} frames/s")];
        if let Some(i) = &self.last_image {
            lines.push(format!("edit to pixels {} · run {}", crate::fmt_ms(i.latency_ms), crate::fmt_ms(i.run_ms)));
            let nodes: Vec<String> = i.nodes.iter().take(OVERLAY_NODES).map(|(id, ms)| format!("{id} {ms:.1} ms")).collect();
            if !nodes.is_empty() {
                lines.push(nodes.join(" · "));
            }
        }
        if self.is_recording() {
            lines.push("● recording".into());
        }
        lines
    }

    /// Draws the overlay in the top-left corner of `rect`.
    pub fn draw_overlay(&self, ui: &egui::Ui, rect: egui::Rect) {
        if !self.overlay {
            return;
        }
        let text = self.overlay_lines().join("\n");
        let font = egui::FontId::monospace(11.0);
        let galley = ui.painter().layout_no_wrap(text, font, egui::Color32::WHITE);
        let at = rect.min + egui::vec2(4.0, 4.0);
        let bg = egui::Rect::from_min_size(at, galley.size()).expand(3.0);
        ui.painter().rect_filled(bg, 3.0, egui::Color32::from_black_alpha(160));
        ui.painter().galley(at, galley, egui::Color32::WHITE);
    }
}

fn summarize(rows: &[Row]) -> Summary {
    let images: Vec<&ImageShown> = rows.iter().filter_map(|r| r.image.as_ref()).collect();
    Summary {
        seconds: rows.last().map_or(0.0, |r| r.t_s),
        frames: rows.len(),
        images: images.len(),
        latency_median_ms: quantile(images.iter().map(|i| i.latency_ms).collect(), 0.5),
        latency_p95_ms: quantile(images.iter().map(|i| i.latency_ms).collect(), 0.95),
        run_median_ms: quantile(images.iter().map(|i| i.run_ms).collect(), 0.5),
        ui_median_ms: quantile(rows.iter().map(|r| r.ui_ms).collect(), 0.5),
    }
}

/// The recording as CSV: a row per frame; the image columns are empty where no new image came.
fn csv(rows: &[Row]) -> String {
    let mut s = String::from("time_s,frame_ms,ui_ms,revision,new_image,image_revision,latency_ms,run_ms,nodes_ran\n");
    for r in rows {
        s += &format!("{:.6},{:.3},{:.3},{},", r.t_s, r.frame_ms, r.ui_ms, r.revision);
        match &r.image {
            Some(i) => {
                let nodes: Vec<String> = i.nodes.iter().map(|(id, ms)| format!("{id}:{ms:.3}")).collect();
                s += &format!("1,{},{:.3},{:.3},{}\n", i.revision, i.latency_ms, i.run_ms, nodes.join(";"));
            }
            None => s += "0,,,,\n",
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shown(rev: u64, latency: f64) -> ImageShown {
        ImageShown { revision: rev, latency_ms: latency, run_ms: latency / 2.0, nodes: vec![("relight".into(), latency / 2.0)] }
    }

    #[test]
    fn a_recording_counts_frames_and_images_and_writes_a_row_per_frame() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = FrameStats::default();
        s.frame(0, 1.0);
        assert!(s.stop_recording(&dir.path().join("x.csv")).is_none(), "nothing was recording");
        s.start_recording();
        for (rev, lat) in [(1, 10.0), (2, 30.0), (3, 20.0)] {
            s.image(shown(rev, lat));
            s.frame(rev, 1.0);
            s.frame(rev, 1.0);
        }
        assert_eq!(s.rates(), (7, 3));
        let (path, sum) = s.stop_recording(&dir.path().join("frames.csv")).unwrap().unwrap();
        assert_eq!((sum.frames, sum.images, sum.latency_median_ms, sum.latency_p95_ms), (6, 3, 20.0, 30.0));
        let text = std::fs::read_to_string(path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 7);
        assert!(lines[1].ends_with(",1.000,1,1,1,10.000,5.000,relight:5.000"), "{}", lines[1]);
        assert!(lines[2].ends_with(",1.000,1,0,,,,"), "{}", lines[2]);
        assert!(!s.is_recording());
        assert!(s.overlay_lines()[1].starts_with("edit to pixels 20 ms"), "{:?}", s.overlay_lines());
    }

    #[test]
    fn quantiles_of_nothing_are_not_numbers() {
        assert!(quantile(vec![], 0.5).is_nan());
        assert_eq!(quantile(vec![3.0, 1.0, 2.0], 0.5), 2.0);
    }
}
