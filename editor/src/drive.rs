//! The measured drag (`relume-editor GRAPH --drive NODE.PARAM=FROM:TO --record OUT.csv`): once
//! the viewer shows the graph's image, every frame sets the parameter the way a slider drag
//! does — from FROM to TO and back over `--drive-seconds` — while the recorder writes each
//! frame; then the same kind of edit runs through the engine alone, without the window, and
//! both rates are printed, so the editor's speed stands beside the pipeline's in one run.

use crate::app::EditorApp;
use relume_core::{Engine, Graph, ParamValue, RunOptions};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// How many edits the engine-alone comparison makes.
const ENGINE_EDITS: usize = 40;
/// When, as fractions of the drive, the strip's screenshots are taken (the way out).
const SHOTS: [f64; 4] = [0.02, 0.17, 0.33, 0.49];

pub struct DriveJob {
    node: String,
    param: String,
    from: f64,
    to: f64,
    seconds: f64,
    record: PathBuf,
    deadline: Instant,
    started: Option<Instant>,
    /// The drive ended (the summary is printed, the window asked to close).
    pub done: bool,
    /// Exit code: 0 when the drive ran to its end.
    pub exit: i32,
    /// Where the strip of screenshots goes, the viewer's part of those taken so far, and
    /// whether one was asked for and has not arrived.
    strip: Option<(PathBuf, Vec<egui::ColorImage>, bool)>,
}

impl DriveJob {
    /// From `node.param=from:to`.
    pub fn parse(spec: &str, seconds: f64, record: PathBuf, timeout: Duration) -> Result<DriveJob, String> {
        let bad = || format!("--drive wants NODE.PARAM=FROM:TO, not {spec:?}");
        let (target, range) = spec.split_once('=').ok_or_else(bad)?;
        let (node, param) = target.split_once('.').ok_or_else(bad)?;
        let (a, b) = range.split_once(':').ok_or_else(bad)?;
        let (from, to) = (a.trim().parse::<f64>().map_err(|_| bad())?, b.trim().parse::<f64>().map_err(|_| bad())?);
        if !(seconds > 0.0 && seconds.is_finite()) {
            return Err(format!("--drive-seconds must be a positive number, not {seconds}"));
        }
        Ok(DriveJob {
            node: node.into(),
            param: param.into(),
            from,
            to,
            seconds,
            record,
            deadline: Instant::now() + timeout,
            started: None,
            done: false,
            exit: 0,
            strip: None,
        })
    }

    /// Also takes screenshots during the drive and writes the viewer's part of them side by
    /// side to `path` (each screenshot costs a frame: measure without it).
    pub fn with_strip(mut self, path: PathBuf) -> Self {
        self.strip = Some((path, Vec::new(), false));
        self
    }

    /// Asks for the strip's next screenshot when its time has come; keeps one that arrived.
    fn shoot(&mut self, app: &EditorApp, ctx: &egui::Context, t: f64) {
        let Some((_, shots, pending)) = &mut self.strip else { return };
        if let Some(img) = crate::screenshot::arrived(ctx) {
            let ppp = ctx.pixels_per_point();
            if let Some(r) = app.viewer.image_rect {
                shots.push(crate::screenshot::crop(&img, egui::Rect::from_min_max(r.min * ppp, r.max * ppp)));
            }
            *pending = false;
        }
        if !*pending && SHOTS.get(shots.len()).is_some_and(|&f| t >= f * self.seconds) {
            *pending = true;
            ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot);
        }
    }

    /// The value `t` seconds into the drive: FROM to TO in the first half, back in the second.
    pub fn value_at(&self, t: f64) -> f64 {
        let x = (t / self.seconds).clamp(0.0, 1.0);
        let tri = if x < 0.5 { 2.0 * x } else { 2.0 - 2.0 * x };
        self.from + (self.to - self.from) * tri
    }

    /// Checks the target against the open graph's schema.
    pub fn check(&self, app: &EditorApp) -> Result<(), String> {
        let kind = app.doc.graph.node(&self.node).map(|n| n.kind.clone()).ok_or_else(|| format!("no node \"{}\" to drive", self.node))?;
        let spec = app.registry.node(&kind).and_then(|k| k.schema().get(&self.param));
        match spec.map(|s| &s.kind) {
            Some(relume_core::ParamKind::Float { .. }) => Ok(()),
            Some(_) => Err(format!("{}.{} is not a number parameter", self.node, self.param)),
            None => Err(format!("{kind} has no parameter {}", self.param)),
        }
    }

    /// One frame: wait for the first image, then edit, then finish.
    pub fn frame(&mut self, app: &mut EditorApp, ctx: &egui::Context) {
        if self.done {
            return;
        }
        ctx.request_repaint();
        let Some(t0) = self.started else {
            if app.report.is_some() && app.viewer.has_image() && !app.preview_shown {
                self.started = Some(Instant::now());
                app.stats.record_path = Some(self.record.clone());
                app.stats.start_recording();
            } else if Instant::now() > self.deadline {
                eprintln!("relume-editor: no image to drive before the timeout: {}", app.status);
                self.finish(app, ctx, 3);
            }
            return;
        };
        let t = t0.elapsed().as_secs_f64();
        self.shoot(app, ctx, t);
        if t < self.seconds {
            if let Err(e) = app.set_param(&self.node, &self.param, ParamValue::Float(self.value_at(t))) {
                eprintln!("relume-editor: {e}");
                self.finish(app, ctx, 4);
            }
            return;
        }
        app.toggle_recording();
        println!("window: {}", app.status);
        if let Some((path, shots, _)) = &self.strip {
            let strip = crate::screenshot::strip(shots, 6, egui::Color32::from_gray(27));
            match crate::screenshot::save_png(&strip, path) {
                Ok(()) => println!("strip: {} screenshots in {}", shots.len(), path.display()),
                Err(e) => eprintln!("relume-editor: {e}"),
            }
        }
        match self.engine_alone(app) {
            Ok(line) => println!("engine alone: {line}"),
            Err(e) => eprintln!("relume-editor: the engine-alone comparison failed: {e}"),
        }
        self.finish(app, ctx, 0);
    }

    /// Ends the drive and closes the window, leaving the graph file as it was.
    fn finish(&mut self, app: &mut EditorApp, ctx: &egui::Context, code: i32) {
        self.done = true;
        self.exit = code;
        app.discard_and_close(ctx);
    }

    /// The same edit through the engine alone: the viewed image re-run for values none of
    /// which was set before (offsets drawn from the clock, so not even an earlier drive's
    /// results are in the disk cache), keeping the results in memory only, one after another.
    /// Fails where an edit re-ran fewer nodes than the first: it would time a load, not the edit.
    fn engine_alone(&self, app: &EditorApp) -> Result<String, String> {
        let (mut g, view): (Graph, String) = app.view_request().ok_or("no viewed image")?;
        let (view_graph, outputs) = (&mut g, vec![view]);
        let engine: &Engine = app.runner.engine();
        let step = (self.to - self.from) / ENGINE_EDITS as f64;
        let offset = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.37, |d| d.subsec_nanos() as f64 * 1e-9);
        let (mut times, mut first_ran) = (Vec::with_capacity(ENGINE_EDITS), 0);
        for i in 0..ENGINE_EDITS {
            let v = self.from + step * (i as f64 + offset);
            view_graph.set_param(&self.node, &self.param, ParamValue::Float(v));
            let t = Instant::now();
            let opts = RunOptions { outputs: Some(outputs.clone()), memory_only: true, ..Default::default() };
            let run = engine.run(view_graph, &opts).map_err(|e| e.to_string())?;
            times.push(t.elapsed().as_secs_f64() * 1e3);
            if i == 0 {
                first_ran = run.report.ran;
            } else if run.report.ran < first_ran {
                return Err(format!("edit {i} re-ran {} nodes, the first {first_ran}: some came from a cache", run.report.ran));
            }
        }
        let total: f64 = times.iter().sum();
        times.sort_by(f64::total_cmp);
        Ok(format!(
            "{ENGINE_EDITS} edits of {}.{} in {:.1} ms: {:.1} edits/s, median {:.1} ms per edit",
            self.node,
            self.param,
            total,
            ENGINE_EDITS as f64 / (total / 1e3),
            times[ENGINE_EDITS / 2]
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_drive_goes_there_and_back_and_refuses_bad_specs() {
        let d = DriveJob::parse("project.s=10:90", 4.0, "f.csv".into(), Duration::from_secs(1)).unwrap();
        assert_eq!((d.value_at(0.0), d.value_at(1.0), d.value_at(2.0), d.value_at(3.0), d.value_at(9.0)), (10.0, 50.0, 90.0, 50.0, 10.0));
        for bad in ["project.s", "s=1:2", "project.s=1", "project.s=a:2"] {
            assert!(DriveJob::parse(bad, 4.0, "f.csv".into(), Duration::from_secs(1)).is_err(), "{bad}");
        }
        assert!(DriveJob::parse("a.b=1:2", 0.0, "f.csv".into(), Duration::from_secs(1)).is_err());
    }
}
