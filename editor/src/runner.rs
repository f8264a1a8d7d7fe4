//! Background runs through the core executor: one run at a time, a newer request cancels the
//! older one or waits for it (started by the worker that ends it), per-node state and progress for the node widgets, the report and the outputs
//! when it ends.

use relume_base::types::{Image, ImageRows};
use relume_core::{CancelToken, Engine, Event, Graph, NodeStatus, Observer, PlanAction, RunOptions, RunReport, Value};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// What a node shows.
#[derive(Clone, Debug, PartialEq)]
pub enum NodeState {
    /// Its result for the current parameters and inputs is in the cache.
    Cached,
    /// It would run: a parameter, an input or a file changed, or it never ran.
    Stale,
    /// No output of the graph needs it.
    Unused,
    /// Running; the fraction of its own work done.
    Running(f32),
    /// Ran in the last run, taking this many milliseconds.
    Done(f64),
    Failed(String),
}

impl NodeState {
    pub fn label(&self) -> String {
        match self {
            NodeState::Cached => "cached".into(),
            NodeState::Stale => "stale".into(),
            NodeState::Unused => "not needed".into(),
            NodeState::Running(f) => format!("running {:.0} %", f * 100.0),
            NodeState::Done(ms) => format!("done in {}", crate::fmt_ms(*ms)),
            NodeState::Failed(m) => format!("failed: {m}"),
        }
    }
}

/// A running node's images as far as they got, composed from its partial results (the bands
/// of a renderer sharded over rows, pass by pass): one image per output port, rows not yet
/// reached black.
#[derive(Clone, Debug)]
pub struct PartialImages {
    pub node: String,
    pub layers: Vec<Image>,
    /// Bumped on every partial result taken in.
    pub updates: u64,
}

impl PartialImages {
    /// Takes in one partial result of `node`: a band of rows (`ImageRows`) of an image of
    /// `total` rows, or a whole image.
    fn take(slot: &mut Option<PartialImages>, node: &str, value: &Value, total: Option<u64>) {
        if let (Some(band), Some(total)) = (value.get::<ImageRows>(), total) {
            let (w, h) = (band.width as usize, total as usize);
            let fits = |p: &PartialImages| {
                p.node == node && p.layers.len() == band.layers.len() && p.layers.iter().all(|l| l.width == w && l.height == h)
            };
            if !slot.as_ref().is_some_and(fits) {
                let Ok(layers) = band.layers.iter().map(|_| Image::try_new(w, h)).collect::<Result<Vec<_>, _>>() else { return };
                *slot = Some(PartialImages { node: node.into(), layers, updates: 0 });
            }
            let p = slot.as_mut().expect("made above");
            let start = band.first_row as usize * w;
            for (img, layer) in p.layers.iter_mut().zip(&band.layers) {
                let end = (start + layer.0.len()).min(img.pixels.len());
                if start < end {
                    img.pixels[start..end].copy_from_slice(&layer.0[..end - start]);
                }
            }
            p.updates += 1;
        } else if let Some(img) = value.get::<Image>() {
            let updates = slot.as_ref().filter(|p| p.node == node).map_or(0, |p| p.updates) + 1;
            *slot = Some(PartialImages { node: node.into(), layers: vec![img.clone()], updates });
        }
    }
}

/// The end of a run.
pub struct Finished {
    /// The document revision the run was started for.
    pub revision: u64,
    pub started: Instant,
    pub outcome: Result<(RunReport, Vec<(String, Value)>), String>,
}

/// A run to start: the graph, the outputs asked for, the document revision it is for, and
/// whether what it computes stays off the disk cache.
struct Request {
    graph: Graph,
    outputs: Vec<String>,
    revision: u64,
    memory_only: bool,
}

#[derive(Default)]
struct Shared {
    /// Run generation these states belong to.
    generation: u64,
    live: HashMap<String, NodeState>,
    finished: Option<Finished>,
    running: bool,
    /// The partial images of the node of the run under way that sent the latest.
    partial: Option<PartialImages>,
    /// The run under way's cancel token.
    cancel: Option<CancelToken>,
    /// The run to start as soon as the one under way ends (a newer one replaces it).
    queued: Option<Request>,
    /// Runs started, and runs cancelled while under way, since the runner was made.
    started: u64,
    cancelled: u64,
    /// The revision and outputs of the latest runs started, oldest first.
    history: std::collections::VecDeque<(u64, Vec<String>)>,
}

impl Shared {
    /// Makes `r` the run under way (a new generation, nothing shown of it yet); its token.
    fn begin(&mut self, r: &Request) -> (u64, CancelToken) {
        self.started += 1;
        if self.history.len() == HISTORY {
            self.history.pop_front();
        }
        self.history.push_back((r.revision, r.outputs.clone()));
        let cancel = CancelToken::new();
        self.cancel = Some(cancel.clone());
        self.generation += 1;
        self.live.clear();
        self.partial = None;
        self.running = true;
        (self.generation, cancel)
    }
}

struct Watch {
    shared: Arc<Mutex<Shared>>,
    generation: u64,
    repaint: Option<egui::Context>,
    /// When the watch last asked for a frame, in µs since `born`.
    asked_us: std::sync::atomic::AtomicU64,
    born: Instant,
}

/// The least time between two frames a run's progress asks for: a node reports progress up to
/// a thousand times and partial results every pass, from its worker threads, and asking the
/// UI for a frame takes the UI's lock, which the frame being drawn holds.
const REPAINT_EVERY_US: u64 = 15_000;

impl Watch {
    /// Asks for a frame unless one was asked for less than `REPAINT_EVERY_US` ago.
    fn repaint_soon(&self) {
        let Some(ctx) = &self.repaint else { return };
        let now = self.born.elapsed().as_micros() as u64;
        let last = self.asked_us.load(std::sync::atomic::Ordering::Relaxed);
        if now >= last + REPAINT_EVERY_US
            && self.asked_us.compare_exchange(last, now, std::sync::atomic::Ordering::Relaxed, std::sync::atomic::Ordering::Relaxed).is_ok()
        {
            ctx.request_repaint_after(std::time::Duration::from_millis(1));
        }
    }
}

impl Observer for Watch {
    fn wants_partials(&self) -> bool {
        true
    }

    fn event(&self, e: &Event<'_>) {
        if let Event::Partial { id, value, chunk } = e {
            let mut s = self.shared.lock().unwrap();
            if s.generation == self.generation {
                PartialImages::take(&mut s.partial, id, value, chunk.as_ref().map(|c| c.1));
            }
            drop(s);
            self.repaint_soon();
            return;
        }
        let (id, state) = match e {
            Event::Planned { .. } | Event::Partial { .. } | Event::Output { .. } => return,
            Event::Started { id, .. } => (*id, NodeState::Running(0.0)),
            Event::Progress { id, fraction } => (*id, NodeState::Running(*fraction)),
            Event::Finished { id, status: NodeStatus::Ran, wall_ms, .. } => (*id, NodeState::Done(*wall_ms)),
            Event::Finished { id, .. } => (*id, NodeState::Cached),
            Event::Failed { id, message, .. } => (*id, NodeState::Failed(message.to_string())),
        };
        let mut s = self.shared.lock().unwrap();
        if s.generation == self.generation {
            s.live.insert(id.to_string(), state);
        }
        drop(s);
        self.repaint_soon();
    }
}

/// Runs graphs in a background thread and keeps what the UI shows about them.
pub struct Runner {
    engine: Arc<Engine>,
    shared: Arc<Mutex<Shared>>,
    repaint: Option<egui::Context>,
}

/// How many started runs `Runner::history` keeps.
const HISTORY: usize = 256;

impl Runner {
    pub fn new(engine: Arc<Engine>) -> Self {
        Runner { engine, shared: Arc::default(), repaint: None }
    }

    /// Asks for repaints on `ctx` as the run progresses.
    pub fn set_repaint(&mut self, ctx: egui::Context) {
        self.repaint = Some(ctx);
    }

    pub fn engine(&self) -> &Arc<Engine> {
        &self.engine
    }

    pub fn is_running(&self) -> bool {
        self.shared.lock().unwrap().running
    }

    /// Runs started so far.
    pub fn started(&self) -> u64 {
        self.shared.lock().unwrap().started
    }

    /// The revision and outputs of the latest runs started, oldest first.
    pub fn history(&self) -> Vec<(u64, Vec<String>)> {
        self.shared.lock().unwrap().history.iter().cloned().collect()
    }

    /// Runs cancelled while under way so far (a newer request, or the user).
    pub fn cancelled(&self) -> u64 {
        self.shared.lock().unwrap().cancelled
    }

    /// Whether a run ended and `take_finished` has not taken it yet.
    pub fn has_finished(&self) -> bool {
        self.shared.lock().unwrap().finished.is_some()
    }

    /// Starts a run of `outputs` of `graph` (cancelling the one under way).
    pub fn start(&mut self, graph: Graph, outputs: Vec<String>, revision: u64) {
        self.start_with(graph, outputs, revision, false);
    }

    /// `start`; `memory_only`: what the run computes stays off the disk cache (a live re-run
    /// during a drag).
    pub fn start_with(&mut self, graph: Graph, outputs: Vec<String>, revision: u64, memory_only: bool) {
        self.cancel();
        let r = Request { graph, outputs, revision, memory_only };
        let begun = self.shared.lock().unwrap().begin(&r);
        self.spawn(r, begun);
    }

    /// Runs `outputs` of `graph` as soon as the run under way ends, without cancelling it (at
    /// once when none is): the worker that ends it starts this one, so no frame of the UI
    /// passes between them. A newer request made before then replaces this one.
    pub fn start_next(&mut self, graph: Graph, outputs: Vec<String>, revision: u64, memory_only: bool) {
        let r = Request { graph, outputs, revision, memory_only };
        let mut s = self.shared.lock().unwrap();
        if s.running {
            s.queued = Some(r);
            return;
        }
        let begun = s.begin(&r);
        drop(s);
        self.spawn(r, begun);
    }

    /// Runs `first` on a thread of its own, then whatever was asked for next while it ran.
    fn spawn(&self, first: Request, begun: (u64, CancelToken)) {
        let (engine, shared, repaint) = (self.engine.clone(), self.shared.clone(), self.repaint.clone());
        std::thread::spawn(move || {
            let (mut r, (mut generation, mut cancel)) = (first, begun);
            loop {
                let started = Instant::now();
                let watch = Watch {
                    shared: shared.clone(),
                    generation,
                    repaint: repaint.clone(),
                    asked_us: Default::default(),
                    born: Instant::now(),
                };
                let opts = RunOptions {
                    outputs: Some(r.outputs),
                    cancel,
                    observer: Some(&watch),
                    memory_only: r.memory_only,
                    ..Default::default()
                };
                let outcome = engine.run(&r.graph, &opts).map(|x| (x.report, x.outputs)).map_err(|e| e.to_string());
                let mut s = shared.lock().unwrap();
                let next = if s.generation == generation {
                    s.running = false;
                    s.finished = Some(Finished { revision: r.revision, started, outcome });
                    s.queued.take().map(|q| {
                        let begun = s.begin(&q);
                        (q, begun)
                    })
                } else {
                    None
                };
                drop(s);
                if let Some(ctx) = &repaint {
                    ctx.request_repaint();
                }
                match next {
                    Some((q, begun)) => (r, (generation, cancel)) = (q, begun),
                    None => return,
                }
            }
        });
    }

    /// Cancels the run under way; its result is dropped.
    pub fn cancel(&mut self) {
        let mut s = self.shared.lock().unwrap();
        if let Some(c) = s.cancel.take() {
            c.cancel();
        }
        s.queued = None;
        s.generation += 1;
        s.cancelled += s.running as u64;
        s.running = false;
    }

    /// The end of the last run, once.
    pub fn take_finished(&self) -> Option<Finished> {
        self.shared.lock().unwrap().finished.take()
    }

    /// The images of the run under way as far as they got, when they changed since `seen`
    /// updates (of the same node).
    /// Its image `layer` (output port index) alone, with the update count.
    pub fn partial_since(&self, node: &str, layer: usize, seen: u64) -> Option<(u64, Image)> {
        let s = self.shared.lock().unwrap();
        let p = s.partial.as_ref().filter(|p| p.node == node && p.updates > seen && s.running)?;
        Some((p.updates, p.layers.get(layer)?.clone()))
    }

    /// The partial images the latest run sent, whether or not it is still under way.
    pub fn last_partial(&self) -> Option<PartialImages> {
        self.shared.lock().unwrap().partial.clone()
    }

    /// States the current run reported so far.
    pub fn live_states(&self) -> HashMap<String, NodeState> {
        self.shared.lock().unwrap().live.clone()
    }

    /// Blocks until the run under way ends (tests and the screenshot mode).
    pub fn wait(&self) -> Option<Finished> {
        loop {
            {
                let mut s = self.shared.lock().unwrap();
                if !s.running {
                    return s.finished.take();
                }
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    }

    /// What each node would do if the graph ran now, without running anything.
    pub fn plan_states(&self, graph: &Graph, outputs: &[String]) -> Result<HashMap<String, NodeState>, String> {
        let lines = self.engine.explain(graph, Some(outputs)).map_err(|e| e.to_string())?;
        Ok(lines
            .into_iter()
            .map(|l| {
                let s = match l.action {
                    PlanAction::Cached => NodeState::Cached,
                    PlanAction::Run => NodeState::Stale,
                    PlanAction::Skip => NodeState::Unused,
                };
                (l.id, s)
            })
            .collect())
    }
}

impl Drop for Runner {
    fn drop(&mut self) {
        self.cancel();
    }
}
