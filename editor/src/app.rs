//! The editor application: the document, the node-graph view, background runs, the viewer.
//! `EditorApp::ui` draws one frame on any `egui::Context`, so tests drive it headlessly
//! through `Context::run` and the window (eframe) calls the same function.

use crate::document::Document;
use crate::edit;
use crate::file_dialog::{FileDialog, Purpose};
use crate::frame_stats::{FrameStats, ImageShown};
use crate::live::{Costs, When, PROBE_GRACE, REPROBE_FIRST, REPROBE_MAX};
use crate::palette::Palette;
use crate::panels::{Action, Panels};
use crate::runner::{NodeState, Runner};
use crate::screenshot::ScreenshotJob;
use crate::view::{GraphView, ViewEdit};
use crate::viewer::Viewer;
use relume_base::types::Image;
use relume_core::graph::PortRef;
use relume_core::ParamValue;
use relume_core::{Engine, Graph, Registry, RunReport, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

pub use crate::live::RUN_DEBOUNCE;
/// How often unsaved work is written to the recovery file.
const RECOVERY_EVERY: Duration = Duration::from_secs(5);
/// How long the window holds a frame back for the run an edit waits for
/// (`EditorApp::pace_frame`): at least 10 frames per second.
const PACED_FRAME: Duration = Duration::from_millis(100);
/// Graph output name used to view a port that is not one of the graph's outputs.
const VIEW_OUTPUT: &str = "__view";
/// Graph output that, where a graph has one (an image), is computed and shown before the
/// viewed image: a fast approximation such as `PreviewSplat`'s ([P] 5.4).
pub const PREVIEW_OUTPUT: &str = "preview";

pub struct EditorApp {
    pub registry: Registry,
    pub doc: Document,
    pub view: GraphView,
    pub runner: Runner,
    pub viewer: Viewer,
    pub(crate) palette: Palette,
    pub(crate) dialog: Option<FileDialog>,
    /// The last message for the status bar (refusals, errors, saves).
    pub status: String,
    /// What each node shows, for the current revision.
    pub states: HashMap<String, NodeState>,
    planned: Option<(u64, bool)>,
    /// States the last finished run reported, with the revision it ran.
    done_states: Option<(u64, HashMap<String, NodeState>)>,
    /// Re-run automatically after edits.
    pub auto_run: bool,
    /// The viewer-only layout (`Panels::viewer_only`).
    pub viewer_only: bool,
    /// When to start the next automatic run.
    pending_run: Option<Instant>,
    /// Whether that run starts at once (it fits the frame budget, or is tried: see
    /// [`crate::live`]).
    pending_live: bool,
    /// The nodes of the tried run the pending one is, if it is one.
    pending_probe: Option<Vec<String>>,
    /// The tried run under way: when it started and the nodes it runs.
    probe: Option<(Instant, Vec<String>)>,
    /// How long a tried run may go on before a newer edit cancels it.
    pub probe_grace: Duration,
    /// How often unsaved work is written to the recovery file (`RECOVERY_EVERY`).
    pub recovery_every: Duration,
    /// When the window's last frame began (`pace_frame`).
    frame_began: Instant,
    /// An edit came while the first run was under way: it runs once that run's image is in.
    after_first: bool,
    /// How long a drag may show nothing before its run is tried again (doubling after each
    /// trial cancelled, back to the first value after one that ends).
    pub reprobe_after: Duration,
    /// The run under way fits the frame budget: a newer edit waits for it instead of
    /// cancelling it.
    in_flight_live: bool,
    /// When the outputs after the viewed image start (once the edits pause).
    rest_at: Option<Instant>,
    /// When each recent revision was made, for the edit-to-pixels latency.
    edit_times: std::collections::VecDeque<(u64, Instant)>,
    /// What each node cost when it last ran.
    pub costs: Costs,
    /// Frame and image rates, latency, the recorder.
    pub stats: FrameStats,
    /// The viewer's tool: what a drag or click on the image does.
    pub tool: Option<crate::tool::Tool>,
    /// The drag or stroke under way.
    pub(crate) gesture: Option<crate::tool::Gesture>,
    /// The revision whose image the viewer shows.
    shown_revision: Option<u64>,
    /// The first edit the viewer does not show yet.
    edit_started: Option<Instant>,
    /// Time from the last edit to its image, in ms.
    pub edit_to_image_ms: Option<f64>,
    /// The revision whose other outputs run once its viewed image is in (a run computes the
    /// viewed image first, so an edit shows before the error figures that compare it).
    rest_after: Option<u64>,
    /// The revision whose viewed image runs once its preview is in (graphs with a `preview`
    /// output show it first, while the slower image is computed).
    view_after_preview: Option<u64>,
    /// The viewer shows the preview of the current run, not the viewed image yet.
    pub preview_shown: bool,
    /// The viewer shows the viewed image as far as the run under way got (a renderer's
    /// bands and passes so far).
    pub partial_shown: bool,
    /// The run and the partial update the viewer shows.
    partial_seen: (u64, u64),
    pub report: Option<RunReport>,
    /// What the viewer shows: a graph output name, or `node.port`.
    pub view_target: Option<String>,
    last_outputs: Vec<(String, Value)>,
    pub quit_prompt: bool,
    allow_close: bool,
    last_recovery: Instant,
    recovery_written: u64,
    pub(crate) recovery_offer: Option<std::path::PathBuf>,
    pub screenshot: Option<ScreenshotJob>,
    /// The window title last sent (sent again only when it changes).
    window_title: String,
}

impl EditorApp {
    pub fn new(registry: Registry, engine: Engine) -> Self {
        let runner = Runner::new(Arc::new(engine));
        EditorApp {
            view: GraphView::new(registry.clone()),
            registry,
            doc: Document::new(),
            runner,
            viewer: Viewer::default(),
            palette: Palette::default(),
            dialog: None,
            status: String::new(),
            states: HashMap::new(),
            planned: None,
            done_states: None,
            auto_run: true,
            viewer_only: false,
            pending_run: None,
            pending_live: false,
            pending_probe: None,
            probe: None,
            probe_grace: PROBE_GRACE,
            recovery_every: RECOVERY_EVERY,
            frame_began: Instant::now(),
            after_first: false,
            reprobe_after: REPROBE_FIRST,
            in_flight_live: false,
            rest_at: None,
            edit_times: std::collections::VecDeque::new(),
            costs: Costs::default(),
            stats: FrameStats::default(),
            tool: None,
            gesture: None,
            shown_revision: None,
            edit_started: None,
            edit_to_image_ms: None,
            rest_after: None,
            view_after_preview: None,
            preview_shown: false,
            partial_shown: false,
            partial_seen: (0, 0),
            report: None,
            view_target: None,
            last_outputs: Vec::new(),
            quit_prompt: false,
            allow_close: false,
            last_recovery: Instant::now(),
            recovery_written: 0,
            recovery_offer: None,
            screenshot: None,
            window_title: String::new(),
        }
    }

    /// Opens a graph file (replacing the document; the caller asks about unsaved changes).
    pub fn open(&mut self, path: &Path) -> Result<(), String> {
        let doc = Document::open(path, &self.registry)?;
        self.runner.cancel();
        self.recovery_offer = doc.pending_recovery();
        self.doc = doc;
        self.view.shown = None;
        self.view.fit_pending = true;
        self.view.state.selected_nodes.clear();
        self.gesture = None;
        self.tool = None;
        self.view_target = self.default_view_target();
        self.viewer.set_image(None);
        self.report = None;
        self.done_states = None;
        self.planned = None;
        self.costs.clear();
        self.after_first = false;
        self.status = format!("opened {}", path.display());
        Ok(())
    }

    fn port_type(&self, port: &PortRef) -> Option<&'static str> {
        let n = self.doc.graph.node(&port.node)?;
        self.registry.node(&n.kind)?.ports().find_output(&port.port).map(|p| p.ty.name)
    }

    /// Graph outputs that are images, by name.
    pub fn image_outputs(&self) -> Vec<String> {
        self.doc.graph.outputs.iter().filter(|o| self.port_type(&o.port) == Some("Image")).map(|o| o.name.clone()).collect()
    }

    fn default_view_target(&self) -> Option<String> {
        let outs = self.image_outputs();
        outs.iter().find(|o| *o == "image").or(outs.first()).cloned()
    }

    /// Applies an edit as one undo step. `in_view`: the node-graph widget already shows it.
    pub fn apply<R>(&mut self, tag: &str, in_view: bool, f: impl FnOnce(&mut Graph) -> R) -> R {
        let before = self.doc.revision;
        let r = self.doc.edit(tag, f);
        // The widget already shows an edit it made, or one that does not touch it (a
        // parameter), only when it showed the revision before: a widget not yet built from
        // the document (just opened) still needs its rebuild.
        if in_view && self.view.shown == Some(before) {
            self.view.shown = Some(self.doc.revision);
        }
        // Moving nodes changes the file but no result.
        if !tag.starts_with("move:") {
            self.after_change();
        }
        r
    }

    /// After any change of the graph: drop the old run's states and schedule a re-run, at
    /// once when what it reaches fits the frame budget, else after the edits pause; a run
    /// under way that the edit makes stale is cancelled unless both are cheap (then the newer
    /// edit waits for it: at most one run in flight, the newest value wins).
    fn after_change(&mut self) {
        let now = Instant::now();
        self.done_states = None;
        self.edit_times.push_back((self.doc.revision, now));
        if self.edit_times.len() > 256 {
            self.edit_times.pop_front();
        }
        if !self.auto_run {
            return;
        }
        if self.report.is_none() {
            // The first run has not shown its image yet: the edit runs once it has, without
            // cancelling it (it may be a long precompute the edit does not reach).
            self.after_first = self.runner.is_running();
            return;
        }
        let (mut when, mut nodes) = self.edit_plan();
        // A trial run still going past its grace is dear after all: its nodes cost at least
        // what it has run (the run is cancelled below), and the edit is priced again.
        if let Some((t0, probed)) = self.probe.take().filter(|(t0, _)| t0.elapsed() > self.probe_grace && self.runner.is_running()) {
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            for id in probed.iter().filter(|id| !self.costs.measured(id)).collect::<Vec<_>>() {
                self.costs.set(id, ms);
            }
            (when, nodes) = self.edit_plan();
            self.reprobe_after = (self.reprobe_after * 2).min(REPROBE_MAX);
        } else if when == When::AfterPause
            && !nodes.is_empty()
            && self.edit_started.is_some_and(|t| now.duration_since(t) > self.reprobe_after)
        {
            // A drag that has shown nothing for a while tries its run again: a cost measured
            // once (say a first run after opening, slowed by what it read) may not hold.
            when = When::Probe;
        }
        let live = when != When::AfterPause;
        self.pending_live = live;
        self.pending_probe = (when == When::Probe).then_some(nodes);
        self.pending_run = Some(if live { now } else { now + RUN_DEBOUNCE });
        self.rest_at = None;
        self.edit_started.get_or_insert(now);
        if self.runner.is_running() && !(live && self.in_flight_live) {
            self.runner.cancel();
            self.rest_after = None;
            self.view_after_preview = None;
        }
        // A cheap edit runs now, not at the next frame: a frame less between the edit and its
        // pixels. Behind a live run under way, it starts the moment that one ends.
        if live {
            self.start_run(true);
        }
    }

    /// When a re-run of the viewed image for the current graph starts: the nodes it would run
    /// priced at what they cost last time.
    pub fn when_edited(&self) -> When {
        self.edit_plan().0
    }

    /// `when_edited`, with the nodes the re-run would run.
    fn edit_plan(&self) -> (When, Vec<String>) {
        let Some(view) = self.view_output_name() else { return (When::AfterPause, Vec::new()) };
        let (g, _) = self.run_request();
        match self.runner.plan_states(&g, &[view]) {
            Ok(states) => {
                let nodes: Vec<String> = states.into_iter().filter(|(_, s)| *s == NodeState::Stale).map(|(id, _)| id).collect();
                (self.costs.when(nodes.iter().map(String::as_str)), nodes)
            }
            Err(_) => (When::AfterPause, Vec::new()),
        }
    }

    pub fn undo(&mut self) {
        if self.doc.undo() {
            self.after_change();
            self.status = "undone".into();
        }
    }

    pub fn redo(&mut self) {
        if self.doc.redo() {
            self.after_change();
            self.status = "redone".into();
        }
    }

    /// Sets a parameter after checking it against the schema (the panel's widgets call this).
    pub fn set_param(&mut self, id: &str, name: &str, value: relume_core::ParamValue) -> Result<(), String> {
        let kind = self.doc.graph.node(id).map(|n| n.kind.clone()).ok_or_else(|| format!("no node \"{id}\""))?;
        let spec = self.registry.node(&kind).and_then(|k| k.schema().get(name)).ok_or_else(|| format!("{kind} has no parameter {name}"))?;
        let v = spec.check(&value).map_err(|m| format!("{id}.{name}: {m}"))?;
        if self.doc.graph.node(id).and_then(|n| n.param(name)) == Some(&v) {
            return Ok(());
        }
        self.apply(&format!("param:{id}.{name}"), true, |g| g.set_param(id, name, v));
        Ok(())
    }

    /// Sets a parameter from `node.param=value` text, checked as `relume run --set` checks it.
    pub fn set_text(&mut self, assignment: &str) -> Result<(), String> {
        let (target, value) = assignment.split_once('=').ok_or("expected NODE.PARAM=VALUE")?;
        let mut g = self.doc.graph.clone();
        g.set_param_text(&self.registry, target.trim(), value.trim()).map_err(|e| e.to_string())?;
        let (id, name) = target.trim().split_once('.').expect("checked by set_param_text");
        let v = g.node(id).and_then(|n| n.param(name)).cloned().expect("just set");
        self.apply(&format!("param:{id}.{name}"), true, |g| g.set_param(id, name, v));
        self.doc.seal();
        Ok(())
    }

    /// Applies what the node-graph widget did.
    pub fn apply_view_edits(&mut self, edits: Vec<ViewEdit>) {
        // Deleting a node also reports its connections as disconnected: the removal is one
        // undo step, not one per edge.
        let removed: Vec<String> =
            edits.iter().filter_map(|e| if let ViewEdit::Removed(id) = e { Some(id.clone()) } else { None }).collect();
        let edge_of_removed =
            |g: &Graph, to: &PortRef| removed.contains(&to.node) || g.edges.iter().any(|e| &e.to == to && removed.contains(&e.from.node));
        for e in edits {
            if matches!(&e, ViewEdit::Disconnected { to } if edge_of_removed(&self.doc.graph, to)) {
                continue;
            }
            match e {
                ViewEdit::Added { kind, pos, node } => {
                    let id = self.apply("add", true, |g| edit::add_node(g, kind, pos));
                    self.view.name_node(node, &id);
                    self.doc.seal();
                    self.status = format!("added {id} ({kind})");
                }
                ViewEdit::Removed(id) => {
                    self.apply("remove", true, |g| edit::remove_node(g, &id));
                    self.doc.seal();
                    self.status = format!("removed {id}");
                }
                ViewEdit::Connected { from, to } => match edit::check_connect(&self.doc.graph, &self.registry, &from, &to) {
                    Ok(()) => {
                        let reg = self.registry.clone();
                        let _ = self.apply("connect", true, |g| edit::connect(g, &reg, from, to));
                        self.doc.seal();
                    }
                    Err(m) => {
                        self.status = m;
                        self.view.shown = None;
                    }
                },
                ViewEdit::Disconnected { to } => {
                    if self.doc.graph.edges.iter().any(|e| e.to == to) {
                        self.apply("disconnect", true, |g| edit::disconnect(g, &to));
                        self.doc.seal();
                    }
                }
                ViewEdit::Moved(list) => {
                    let tag = format!("move:{}", list.iter().map(|(id, _)| id.as_str()).collect::<Vec<_>>().join(","));
                    self.apply(&tag, true, |g| {
                        for (id, p) in &list {
                            edit::set_position(g, id, *p);
                        }
                    });
                }
                ViewEdit::Selected => {}
            }
        }
    }

    /// Adds a node from the palette near the middle of the view.
    pub fn add_from_palette(&mut self, kind: &'static str, at: [f64; 2]) {
        let id = self.apply("add", false, |g| edit::add_node(g, kind, at));
        self.doc.seal();
        self.view.rebuild(&self.doc.graph, self.doc.revision);
        self.view.select(&id);
        self.status = format!("added {id} ({kind})");
    }

    /// Deletes the selected nodes.
    pub fn delete_selected(&mut self) {
        let ids = self.view.selected_ids();
        if ids.is_empty() {
            return;
        }
        self.apply("remove", false, |g| ids.iter().for_each(|id| edit::remove_node(g, id)));
        self.doc.seal();
        self.status = format!("removed {}", ids.join(", "));
    }

    /// The outputs a run asks for and the graph it runs (with the viewed port as an output).
    fn run_request(&self) -> (Graph, Vec<String>) {
        let mut g = self.doc.graph.clone();
        let mut outputs: Vec<String> = g.outputs.iter().map(|o| o.name.clone()).collect();
        if let Some(t) = &self.view_target {
            if !outputs.contains(t) {
                if let Some(port) = PortRef::parse(t) {
                    edit::set_output(&mut g, &port, VIEW_OUTPUT, true);
                    outputs.push(VIEW_OUTPUT.into());
                }
            }
        }
        (g, outputs)
    }

    /// Image output `name` of the last run.
    pub fn last_output_image(&self, name: &str) -> Option<Image> {
        self.last_outputs.iter().find(|(n, _)| n == name).and_then(|(_, v)| v.get::<Image>()).cloned()
    }

    /// The port whose image the viewer shows.
    pub fn view_port(&self) -> Option<PortRef> {
        let t = self.view_target.as_ref()?;
        match self.doc.graph.outputs.iter().find(|o| &o.name == t) {
            Some(o) => Some(o.port.clone()),
            None => PortRef::parse(t),
        }
    }

    /// Shows the viewed image as far as the run under way got, when its node sent more.
    fn show_partial(&mut self) {
        let run = self.runner.started();
        let seen = if self.partial_seen.0 == run { self.partial_seen.1 } else { 0 };
        let Some(port) = self.view_port() else { return };
        let kind = self.doc.graph.node(&port.node).and_then(|n| self.registry.node(&n.kind));
        let Some(layer) = kind.and_then(|k| k.ports().outputs.iter().position(|o| o.name == port.port)) else { return };
        if let Some((updates, img)) = self.runner.partial_since(&port.node, layer, seen) {
            self.partial_seen = (run, updates);
            self.viewer.set_image(Some(Arc::new(img)));
            self.partial_shown = true;
        }
    }

    /// The graph a run of the viewed image takes and the output that delivers it.
    pub fn view_request(&self) -> Option<(Graph, String)> {
        let view = self.view_output_name()?;
        Some((self.run_request().0, view))
    }

    /// Starts a run of the graph in the background.
    pub fn run(&mut self) {
        self.start_run(false);
    }

    /// Starts a run; `live`: it fits the frame budget, so the viewed image runs alone (no
    /// preview first) and a newer edit waits for it.
    fn start_run(&mut self, live: bool) {
        let (g, outputs) = self.run_request();
        if outputs.is_empty() {
            self.status = "the graph has no outputs: tick \"graph output\" on a port of the selected node".into();
            return;
        }
        // A live run behind a live run under way waits for it, and starts the moment it ends.
        let behind = live && self.in_flight_live && self.runner.is_running();
        self.pending_run = None;
        self.rest_at = None;
        self.in_flight_live = live;
        self.probe = self.pending_probe.take().filter(|_| live).map(|nodes| (Instant::now(), nodes));
        self.edit_started.get_or_insert_with(Instant::now);
        // The preview first where the graph has one, then the viewed image, alone; the other
        // outputs when it is in (`take_in`).
        let view = self.view_output_name();
        self.view_after_preview = None;
        match view.filter(|v| outputs.len() > 1 && outputs.contains(v)) {
            Some(v) => {
                self.rest_after = Some(self.doc.revision);
                if !live && self.preview_output().is_some_and(|p| p != v && outputs.contains(&p)) {
                    self.view_after_preview = Some(self.doc.revision);
                    self.runner.start(g, vec![PREVIEW_OUTPUT.into()], self.doc.revision);
                } else if behind {
                    self.runner.start_next(g, vec![v], self.doc.revision, true);
                } else {
                    self.runner.start_with(g, vec![v], self.doc.revision, live);
                }
            }
            None => {
                self.rest_after = None;
                self.runner.start(g, outputs, self.doc.revision);
            }
        }
        self.status = "running...".into();
    }

    /// The graph's preview output, where it has an image output of that name.
    fn preview_output(&self) -> Option<String> {
        self.image_outputs().into_iter().find(|o| o == PREVIEW_OUTPUT)
    }

    /// Whether no run is under way, waiting (the viewed image's and the rest's) or ended but
    /// not taken in yet.
    pub fn is_idle(&self) -> bool {
        !self.runner.is_running()
            && !self.runner.has_finished()
            && self.pending_run.is_none()
            && self.rest_at.is_none()
            && self.rest_after.is_none()
            && self.view_after_preview.is_none()
    }

    /// The output name under which a run delivers the viewed image.
    fn view_output_name(&self) -> Option<String> {
        match &self.view_target {
            Some(t) if self.doc.graph.outputs.iter().any(|o| &o.name == t) => Some(t.clone()),
            Some(_) => Some(VIEW_OUTPUT.to_string()),
            None => None,
        }
    }

    pub fn cancel(&mut self) {
        self.runner.cancel();
        self.pending_run = None;
        self.rest_after = None;
        self.rest_at = None;
        self.view_after_preview = None;
        self.planned = None;
        self.status = "run cancelled".into();
    }

    /// Writes the last run's image outputs as one multi-layer EXR beside the graph file
    /// (`GRAPH.layers.exr`: a layer per image output, the graph, nodes and parameters in its
    /// header), as `relume run --exr-layers` does; the status bar says where.
    pub fn save_exr_layers(&mut self) -> Option<std::path::PathBuf> {
        if self.last_outputs.is_empty() {
            self.status = "nothing to save yet: run the graph (F5) first".into();
            return None;
        }
        let dir = self.doc.graph.base_dir.clone();
        let mut graph = self.doc.graph.clone();
        graph.file = graph.file.or_else(|| self.doc.path.clone());
        match relume_base::image::exr_layers::write_run_layers(&self.registry, &graph, &self.last_outputs, &dir, false) {
            Ok(path) => {
                self.status = format!("saved image layers to {}", path.display());
                Some(path)
            }
            Err(m) => {
                self.status = m;
                None
            }
        }
    }

    /// Takes in a finished run: report, states, the viewed image, edit-to-image time.
    fn collect_finished(&mut self) {
        if let Some(f) = self.runner.take_finished() {
            self.take_in(f);
        }
    }

    fn take_in(&mut self, f: crate::runner::Finished) {
        let live = self.runner.live_states();
        self.planned = None;
        // A live run queued behind this one may be under way already.
        self.in_flight_live &= self.runner.is_running();
        if self.probe.take().is_some() && f.outcome.is_ok() {
            self.reprobe_after = REPROBE_FIRST;
        }
        match f.outcome {
            Ok((report, outputs)) if f.revision == self.doc.revision && self.view_after_preview == Some(f.revision) => {
                // The preview is in: show it, then compute the viewed image.
                self.costs.learn(&report);
                self.view_after_preview = None;
                let preview = outputs.iter().find(|(n, _)| n == PREVIEW_OUTPUT).and_then(|(_, v)| v.get::<Image>()).cloned();
                if let Some(img) = preview {
                    self.viewer.set_image(Some(Arc::new(img)));
                    self.preview_shown = true;
                    self.stats.image(ImageShown::new(f.revision, self.latency_ms(f.revision, f.started), &report));
                }
                self.status = format!("preview in {}; the image is running...", crate::fmt_ms(report.total_ms));
                self.report = Some(report);
                if let Some(v) = self.view_output_name() {
                    let (g, _) = self.run_request();
                    self.runner.start(g, vec![v], self.doc.revision);
                }
            }
            Ok((report, outputs)) => {
                self.costs.learn(&report);
                self.status = format!("ran in {} ({} ran, {} cached)", crate::fmt_ms(report.total_ms), report.ran, report.cached);
                self.last_outputs = outputs;
                let new_revision = self.shown_revision != Some(f.revision) || self.preview_shown;
                if self.show_target() && new_revision {
                    self.shown_revision = Some(f.revision);
                    self.stats.image(ImageShown::new(f.revision, self.latency_ms(f.revision, f.started), &report));
                }
                self.report = Some(report);
                if std::mem::take(&mut self.after_first) && f.revision != self.doc.revision {
                    self.pending_run = Some(Instant::now());
                    self.pending_live = false;
                }
                if f.revision == self.doc.revision {
                    if let Some(t0) = self.edit_started.take() {
                        self.edit_to_image_ms = Some(t0.elapsed().as_secs_f64() * 1e3);
                    }
                    if self.rest_after == Some(f.revision) {
                        // The other outputs wait until the edits pause.
                        let quiet = self.edit_times.back().map(|(_, t)| *t + RUN_DEBOUNCE);
                        self.rest_at = Some(quiet.unwrap_or_else(Instant::now));
                    }
                }
            }
            Err(m) => {
                if let Some(job) = &mut self.screenshot {
                    job.run_failed(&m);
                }
                // An edit made while it ran may be what mends it.
                if std::mem::take(&mut self.after_first) {
                    self.pending_run = Some(Instant::now());
                    self.pending_live = false;
                }
                self.status = m;
                self.edit_started = None;
                self.rest_after = None;
                self.view_after_preview = None;
            }
        }
        self.done_states = Some((f.revision, live));
    }

    /// From the edit that made `revision` to now (from the run's start where no edit made it:
    /// the first run, an undo).
    fn latency_ms(&self, revision: u64, started: Instant) -> f64 {
        let t = self.edit_times.iter().rev().find(|(r, _)| *r == revision).map_or(started, |(_, t)| *t);
        t.elapsed().as_secs_f64() * 1e3
    }

    /// Starts the outputs after the viewed image, once the edits have paused.
    fn start_rest(&mut self) {
        self.rest_at = None;
        if self.rest_after.take() == Some(self.doc.revision) {
            let (g, outputs) = self.run_request();
            self.in_flight_live = false;
            self.runner.start(g, outputs, self.doc.revision);
            self.status = format!("{}; the other outputs are running...", self.status);
        }
    }

    /// Puts the viewed output of the last run in the viewer; whether there was one.
    pub fn show_target(&mut self) -> bool {
        let Some(name) = self.view_output_name() else { return false };
        let img = self.last_outputs.iter().find(|(n, _)| *n == name).and_then(|(_, v)| v.get::<Image>()).cloned();
        let found = img.is_some();
        if found {
            self.viewer.set_image(img.map(Arc::new));
            self.preview_shown = false;
            self.partial_shown = false;
        }
        found
    }

    /// Refreshes what the nodes show: the plan for the current revision under the states of
    /// the run under way or just finished.
    fn refresh_states(&mut self) {
        let running = self.runner.is_running();
        if self.planned != Some((self.doc.revision, running)) {
            let (g, outputs) = self.run_request();
            self.states = match self.runner.plan_states(&g, &outputs) {
                Ok(s) => s,
                Err(m) => {
                    if !running {
                        self.status = m;
                    }
                    HashMap::new()
                }
            };
            self.planned = Some((self.doc.revision, running));
        }
        let mut shown = self.states.clone();
        if running {
            shown.extend(self.runner.live_states());
        } else if let Some((rev, done)) = &self.done_states {
            if *rev == self.doc.revision {
                shown.extend(done.iter().map(|(k, v)| (k.clone(), v.clone())));
            }
        }
        self.view.user.states = shown;
    }

    /// Writes the recovery file when there is unsaved work that is not in it yet.
    fn keep_recovery(&mut self) {
        // Closing after the work was saved or discarded: nothing to keep.
        if self.allow_close || self.last_recovery.elapsed() < self.recovery_every || self.recovery_written == self.doc.revision {
            return;
        }
        self.last_recovery = Instant::now();
        if self.doc.is_dirty() {
            match self.doc.write_recovery() {
                Ok(_) => self.recovery_written = self.doc.revision,
                Err(e) => self.status = format!("cannot write the recovery file: {e}"),
            }
        }
    }

    /// Holds the window's next frame back while the live run an edit waits for is under way
    /// (a drag's, not a first run or the references after it), until it ends or `PACED_FRAME`
    /// after the frame before began, so a drag draws a frame per new image. Where OpenGL is software, drawing shares the cores with the run (llvmpipe takes
    /// about 16 ms of two cores a frame of this window), and a frame that shows the same image
    /// again only delays the next one. The window calls it before each frame; headless use
    /// (tests) does not.
    pub fn pace_frame(&mut self) {
        let until = self.frame_began + PACED_FRAME;
        while Instant::now() < until && self.in_flight_live && self.runner.is_running() {
            std::thread::sleep(Duration::from_millis(1));
        }
        self.frame_began = Instant::now();
    }

    /// One frame of the editor.
    pub fn ui(&mut self, ctx: &egui::Context) {
        let t0 = Instant::now();
        self.runner.set_repaint(ctx.clone());
        self.handle_close(ctx);
        self.shortcuts(ctx);
        self.collect_finished();
        self.schedule(ctx);
        self.show_partial();
        if self.view.shown != Some(self.doc.revision) {
            self.view.rebuild(&self.doc.graph, self.doc.revision);
        }
        self.refresh_states();
        self.keep_recovery();
        let image_outputs = self.image_outputs();
        let tools = self.tools();
        let panels = Panels {
            registry: &self.registry,
            doc: &self.doc,
            view: &mut self.view,
            viewer: &mut self.viewer,
            palette: &mut self.palette,
            dialog: &mut self.dialog,
            auto_run: &mut self.auto_run,
            viewer_only: &mut self.viewer_only,
            running: self.runner.is_running(),
            status: &self.status,
            edit_to_image_ms: self.edit_to_image_ms,
            view_target: self.view_target.clone(),
            image_outputs,
            preview_shown: self.preview_shown,
            partial_shown: self.partial_shown,
            report: self.report.as_ref(),
            stats: &mut self.stats,
            tools,
            tool: &mut self.tool,
            quit_prompt: self.quit_prompt,
            recovery_offer: self.recovery_offer.as_deref(),
        };
        for action in crate::panels::draw(panels, ctx) {
            self.act(action, ctx);
        }
        let input = std::mem::take(&mut self.viewer.input);
        self.manipulate(&input);
        if let Some(job) = &mut self.screenshot {
            job.frame(ctx, &self.viewer, self.view.canvas_rect, self.runner.is_running() || self.pending_run.is_some());
            // The --set edits are the command line's: the window closes without asking to save.
            if job.is_done() && !self.allow_close {
                self.discard_and_close(ctx);
            }
        }
        self.stats.frame(self.doc.revision, t0.elapsed().as_secs_f64() * 1e3);
        let title = format!("{} - relume editor", self.doc.title());
        if title != self.window_title {
            ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.window_title = title;
        }
    }

    /// Starts the re-run an edit asked for once it is due (a cheap one waits for the cheap run
    /// under way: its end asks for a frame), and the outputs after the viewed image once the
    /// edits pause.
    fn schedule(&mut self, ctx: &egui::Context) {
        let now = Instant::now();
        if let Some(t) = self.pending_run {
            if now < t {
                ctx.request_repaint_after(t - now);
            } else if !(self.in_flight_live && self.runner.is_running()) {
                self.start_run(self.pending_live);
            }
        }
        if let Some(t) = self.rest_at {
            if now < t {
                ctx.request_repaint_after(t - now);
            } else if self.pending_run.is_none() && !self.runner.is_running() {
                self.start_rest();
            }
        }
    }

    fn shortcuts(&mut self, ctx: &egui::Context) {
        use egui::{Key, KeyboardShortcut, Modifiers};
        let cmd = |k| KeyboardShortcut::new(Modifiers::COMMAND, k);
        let cmd_shift = |k| KeyboardShortcut::new(Modifiers::COMMAND | Modifiers::SHIFT, k);
        if ctx.input_mut(|i| i.consume_shortcut(&cmd_shift(Key::Z)) || i.consume_shortcut(&cmd(Key::Y))) {
            self.redo();
        }
        if ctx.input_mut(|i| i.consume_shortcut(&cmd(Key::Z))) {
            self.undo();
        }
        if ctx.input_mut(|i| i.consume_shortcut(&cmd_shift(Key::S))) {
            self.dialog = Some(self.save_as_dialog());
        } else if ctx.input_mut(|i| i.consume_shortcut(&cmd(Key::S))) {
            self.save();
        }
        if ctx.input_mut(|i| i.consume_shortcut(&cmd(Key::O))) {
            self.dialog = Some(self.open_dialog());
        }
        if ctx.input_mut(|i| i.consume_key(Modifiers::NONE, Key::F5)) {
            self.run();
        }
        if ctx.input_mut(|i| i.consume_key(Modifiers::NONE, Key::F11)) {
            self.viewer_only = !self.viewer_only;
        }
        let typing = ctx.wants_keyboard_input();
        if !typing && ctx.input_mut(|i| i.consume_key(Modifiers::NONE, Key::Delete)) {
            self.delete_selected();
        }
    }

    /// A file dialog to open a graph, starting in the current graph's folder.
    fn open_dialog(&self) -> FileDialog {
        let start = self.doc.path.as_ref().and_then(|p| p.parent()).map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
        FileDialog::new(Purpose::Open, &start, Some("ron"))
    }

    /// A file dialog to save the graph under a new name.
    fn save_as_dialog(&self) -> FileDialog {
        let start = self.doc.path.clone().unwrap_or_else(|| PathBuf::from("untitled.ron"));
        FileDialog::new(Purpose::SaveAs, &start, Some("ron"))
    }

    /// Carries out what the user asked for in the panels.
    fn act(&mut self, action: Action, ctx: &egui::Context) {
        match action {
            Action::AddNode { kind, at } => self.add_from_palette(kind, at),
            Action::ViewEdits(edits) => self.apply_view_edits(edits),
            Action::OpenDialog => self.dialog = Some(self.open_dialog()),
            Action::SaveAsDialog => self.dialog = Some(self.save_as_dialog()),
            Action::Save => self.save(),
            Action::SaveExrLayers => {
                self.save_exr_layers();
            }
            Action::Undo => self.undo(),
            Action::Redo => self.redo(),
            Action::DeleteSelected => self.delete_selected(),
            Action::Run => self.run(),
            Action::ToggleRecording => self.toggle_recording(),
            Action::Cancel => self.cancel(),
            Action::SetParam { node, name, value } => {
                if let Err(m) = self.set_param(&node, name, value) {
                    self.status = m;
                }
            }
            Action::ResetParam { node, name } => {
                self.apply(&format!("param:{node}.{name}"), true, |g| edit::reset_param(g, &node, name));
                self.doc.seal();
            }
            Action::BrowseParam { node, name, start } => self.dialog = Some(FileDialog::new(Purpose::Param { node, name }, &start, None)),
            Action::SetOutput { port, name, on } => {
                self.apply("outputs", true, |g| edit::set_output(g, &port, &name, on));
                self.doc.seal();
            }
            Action::ShowTarget(target) => {
                self.view_target = target;
                self.show_target();
            }
            Action::SaveAndClose => self.save_and_close(ctx),
            Action::DiscardAndClose => self.discard_and_close(ctx),
            Action::KeepEditing => self.quit_prompt = false,
            Action::RestoreRecovery => {
                let reg = self.registry.clone();
                self.status = match self.doc.restore_recovery(&reg) {
                    Ok(()) => "restored the unsaved changes (Ctrl+Z undoes)".into(),
                    Err(e) => e,
                };
                self.recovery_offer = None;
            }
            Action::DropRecovery => {
                self.doc.drop_recovery();
                self.recovery_offer = None;
            }
            Action::Chosen(purpose, path) => self.chosen(purpose, path),
        }
    }

    /// A file chosen in a file dialog, for the dialog's purpose.
    fn chosen(&mut self, purpose: Purpose, path: PathBuf) {
        match purpose {
            Purpose::Open => {
                if self.doc.is_dirty() {
                    self.status = "save or undo the unsaved changes before opening another graph".into();
                    return;
                }
                if let Err(e) = self.open(&path) {
                    self.status = e;
                }
            }
            Purpose::SaveAs => {
                let path = if path.extension().is_none() { path.with_extension("ron") } else { path };
                self.status = match self.doc.save_as(&path) {
                    Ok(()) => format!("saved {}", path.display()),
                    Err(e) => e,
                };
            }
            Purpose::Param { node, name } => {
                let base = self.doc.graph.base_dir.clone();
                let rel = path.strip_prefix(&base).map(Path::to_path_buf).unwrap_or(path);
                if let Err(m) = self.set_param(&node, &name, ParamValue::Text(rel.to_string_lossy().into_owned())) {
                    self.status = m;
                }
            }
        }
    }

    /// Starts recording frame times, or stops and writes them (`GRAPH.frames.csv` beside the
    /// graph unless a path was given); the status bar says what was measured.
    pub fn toggle_recording(&mut self) {
        if !self.stats.is_recording() {
            self.stats.start_recording();
            self.status = "recording frame times: press record again to stop and write them".into();
            return;
        }
        let stem =
            self.doc.path.as_ref().and_then(|p| p.file_stem()).map(|s| s.to_string_lossy().into_owned()).unwrap_or("untitled".into());
        let default = self.doc.graph.base_dir.join(format!("{stem}.frames.csv"));
        if let Some(r) = self.stats.stop_recording(&default) {
            self.status = match r {
                Ok((path, sum)) => format!("{} — written to {}", sum.line(), path.display()),
                Err(e) => e,
            };
        }
    }

    /// Saves, or asks for a file when the graph has none.
    pub fn save(&mut self) {
        if self.doc.path.is_none() {
            self.dialog = Some(self.save_as_dialog());
            return;
        }
        self.status = match self.doc.save() {
            Ok(()) => format!("saved {}", self.doc.path.as_ref().map(|p| p.display().to_string()).unwrap_or_default()),
            Err(e) => e,
        };
    }

    /// Unsaved changes are never dropped silently: closing asks first.
    fn handle_close(&mut self, ctx: &egui::Context) {
        if ctx.input(|i| i.viewport().close_requested()) && !self.allow_close && self.doc.is_dirty() {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.quit_prompt = true;
        }
    }

    /// The user chose to leave without saving.
    pub fn discard_and_close(&mut self, ctx: &egui::Context) {
        self.doc.drop_recovery();
        self.allow_close = true;
        self.quit_prompt = false;
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    /// Saves, then closes when the save worked.
    pub fn save_and_close(&mut self, ctx: &egui::Context) {
        self.save();
        if !self.doc.is_dirty() {
            self.allow_close = true;
            self.quit_prompt = false;
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
    }

    /// Waits for the run under way and takes it in, and for the outputs that run after the
    /// viewed image (tests, the screenshot mode).
    pub fn wait_for_run(&mut self) {
        while let Some(f) = self.runner.wait() {
            self.take_in(f);
            if self.rest_at.is_some() {
                self.start_rest();
            }
            if !self.runner.is_running() {
                break;
            }
        }
    }
}
