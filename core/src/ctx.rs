//! What a running node sees besides its data: cancellation, progress, metrics and notes.

use crate::hash::Hash;
use crate::node::NodeError;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Shared cancellation flag: the caller sets it, nodes poll it through `RunCtx::check`.
#[derive(Clone, Default, Debug)]
pub struct CancelToken(Arc<AtomicBool>);

impl CancelToken {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn cancel(&self) {
        self.0.store(true, Ordering::SeqCst)
    }
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// Whether a node's result came from running it or from a cache.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NodeStatus {
    Ran,
    CachedMemory,
    CachedDisk,
}

impl NodeStatus {
    pub fn as_str(&self) -> &'static str {
        match self {
            NodeStatus::Ran => "ran",
            NodeStatus::CachedMemory | NodeStatus::CachedDisk => "cached",
        }
    }
}

/// Events a run sends to whoever watches it (the CLI's progress bars, the editor).
#[derive(Clone, Debug)]
pub enum Event<'a> {
    /// The plan is made: `nodes` nodes are needed.
    Planned {
        nodes: usize,
    },
    Started {
        id: &'a str,
        kind: &'a str,
    },
    /// Fraction in [0, 1] of a node's own work.
    Progress {
        id: &'a str,
        fraction: f32,
    },
    Finished {
        id: &'a str,
        kind: &'a str,
        status: NodeStatus,
        wall_ms: f64,
    },
    Failed {
        id: &'a str,
        kind: &'a str,
        message: &'a str,
    },
}

/// Receives run events; called from the coordinating thread and from node threads.
pub trait Observer: Send + Sync {
    fn event(&self, e: &Event<'_>);
}

/// What a run recorded besides its outputs: metrics, notes, file dependencies.
pub(crate) type Recorded = (Vec<(String, f64)>, Vec<String>, Vec<(PathBuf, Hash)>);

/// Handed to `Node::run`.
pub struct RunCtx<'a> {
    pub(crate) id: &'a str,
    pub(crate) cancel: &'a CancelToken,
    pub(crate) observer: Option<&'a dyn Observer>,
    pub(crate) metrics: Mutex<Vec<(String, f64)>>,
    pub(crate) notes: Mutex<Vec<String>>,
    pub(crate) deps: Mutex<Vec<(PathBuf, Hash)>>,
    last_permille: AtomicU64,
}

impl<'a> RunCtx<'a> {
    pub fn new(id: &'a str, cancel: &'a CancelToken, observer: Option<&'a dyn Observer>) -> Self {
        RunCtx {
            id,
            cancel,
            observer,
            metrics: Mutex::default(),
            notes: Mutex::default(),
            deps: Mutex::default(),
            last_permille: AtomicU64::new(u64::MAX),
        }
    }

    /// The node's id in the graph.
    pub fn node_id(&self) -> &str {
        self.id
    }

    /// Returns `Err(Cancelled)` once the run is cancelled; call it in long loops.
    pub fn check(&self) -> Result<(), NodeError> {
        if self.cancel.is_cancelled() {
            Err(NodeError::Cancelled)
        } else {
            Ok(())
        }
    }

    /// Reports `done` of `total` units of work (cheap: forwards at most 1000 steps).
    pub fn progress(&self, done: u64, total: u64) {
        let Some(obs) = self.observer else { return };
        let permille = (done.min(total) * 1000).checked_div(total).unwrap_or(1000);
        if self.last_permille.swap(permille, Ordering::Relaxed) != permille {
            obs.event(&Event::Progress { id: self.id, fraction: permille as f32 / 1000.0 });
        }
    }

    /// Adds a quality figure to the report (`metrics` of this node).
    pub fn metric(&self, name: &str, value: f64) {
        self.metrics.lock().unwrap().push((name.to_string(), value));
    }

    /// Adds a sentence to the report, e.g. what the node left out because the scene lacks it.
    pub fn note(&self, text: impl Into<String>) {
        self.notes.lock().unwrap().push(text.into());
    }

    /// Records a file the node read that is not one of its file parameters (a mesh named in a
    /// scene file): the cached result is reused only while the file keeps this content.
    /// `content_hash` is `Hash::of_bytes` of the file's bytes as the node read them.
    pub fn depends_on_file(&self, path: &Path, content_hash: Hash) {
        self.deps.lock().unwrap().push((path.to_path_buf(), content_hash));
    }

    pub(crate) fn take(self) -> Recorded {
        (self.metrics.into_inner().unwrap(), self.notes.into_inner().unwrap(), self.deps.into_inner().unwrap())
    }
}
