//! A run from Python: the engine on a thread of its own while the calling thread, the GIL
//! released, waits for it, hands progress to a callback and watches for Ctrl-C (which cancels
//! the run: the engine stops at its next check and writes nothing half-done to the cache).

use crate::errors::{graph_errors, RunError};
use crate::values::output_to_py;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use relume_core::{CancelToken, Engine, Event, Graph, Observer, RunOptions};
use std::sync::Mutex;
use std::time::Duration;

/// How often the waiting thread takes the GIL back to report progress and check for Ctrl-C.
const POLL: Duration = Duration::from_millis(50);

/// A finished run: `outputs` (name → numpy array, dict of metrics, or None for other port
/// types), `images` and `metrics` (the outputs of those kinds), `report` (the dict `relume run
/// --report` writes as JSON). `result[name]` is `result.outputs[name]`.
#[pyclass(module = "relume")]
pub struct RunResult {
    #[pyo3(get)]
    outputs: Py<PyDict>,
    #[pyo3(get)]
    images: Py<PyDict>,
    #[pyo3(get)]
    metrics: Py<PyDict>,
    #[pyo3(get)]
    report: Py<PyAny>,
}

#[pymethods]
impl RunResult {
    fn __getitem__(&self, py: Python<'_>, name: &str) -> PyResult<Py<PyAny>> {
        match self.outputs.bind(py).get_item(name)? {
            Some(v) => Ok(v.unbind()),
            None => Err(pyo3::exceptions::PyKeyError::new_err(name.to_string())),
        }
    }

    /// The nodes that ran (not taken from a cache), in the order they finished.
    #[getter]
    fn ran(&self, py: Python<'_>) -> PyResult<Vec<String>> {
        let nodes = self.report.bind(py).get_item("nodes")?;
        let mut ran = Vec::new();
        for n in nodes.try_iter()? {
            let n = n?;
            if n.get_item("status")?.extract::<String>()? == "ran" {
                ran.push(n.get_item("id")?.extract()?);
            }
        }
        Ok(ran)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let names: Vec<String> = self.outputs.bind(py).keys().iter().map(|k| k.to_string()).collect();
        format!("<relume.RunResult outputs {names:?}>")
    }
}

/// Progress events kept for the waiting thread: the latest fraction of each node that moved.
#[derive(Default)]
struct Progress {
    moved: Mutex<Vec<(String, f32)>>,
}

impl Observer for Progress {
    fn event(&self, e: &Event<'_>) {
        let (id, f) = match e {
            Event::Started { id, .. } => (*id, 0.0),
            Event::Progress { id, fraction } => (*id, *fraction),
            Event::Finished { id, .. } => (*id, 1.0),
            _ => return,
        };
        let mut m = self.moved.lock().unwrap();
        match m.iter_mut().find(|(n, _)| n == id) {
            Some(slot) => slot.1 = f,
            None => m.push((id.to_string(), f)),
        }
    }
}

pub fn run(
    py: Python<'_>,
    graph: &Graph,
    engine: &Engine,
    outputs: Option<Vec<String>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<RunResult> {
    let cancel = CancelToken::new();
    let watch = Progress::default();
    let opts = RunOptions { outputs, cancel: cancel.clone(), observer: Some(&watch), ..Default::default() };
    let outcome = std::thread::scope(|s| -> PyResult<_> {
        // The run says when it ends, so the wait ends then rather than at the next poll.
        let (ended, end) = std::sync::mpsc::channel::<()>();
        let end = Mutex::new(end);
        let opts = &opts;
        let handle = s.spawn(move || {
            let result = engine.run(graph, opts);
            let _ = ended.send(());
            result
        });
        // Any error here (Ctrl-C seen by `check_signals` or raised inside the callback, an
        // exception from the callback) cancels the run before it propagates: the scope would
        // otherwise wait for the whole run to end.
        let waited = (|| loop {
            let done = py.detach(|| end.lock().unwrap().recv_timeout(POLL).is_ok());
            if let Some(cb) = &progress {
                let moved = std::mem::take(&mut *watch.moved.lock().unwrap());
                for (id, f) in moved {
                    cb.call1(py, (id, f))?;
                }
            }
            if done {
                return Ok(());
            }
            py.check_signals()?;
        })();
        if let Err(e) = waited {
            cancel.cancel();
            let _ = py.detach(|| handle.join());
            return Err(e);
        }
        Ok(handle.join().expect("the run's thread does not panic"))
    })?;
    let result = outcome.map_err(|e| match e {
        relume_core::RunError::Graph(g) => graph_errors(py, &g),
        other => RunError::new_err(other.to_string()),
    })?;
    let (all, images, metrics) = (PyDict::new(py), PyDict::new(py), PyDict::new(py));
    for (name, v) in &result.outputs {
        let x = output_to_py(py, v)?;
        match v.type_name() {
            "Image" => images.set_item(name, &x)?,
            "Metrics" => metrics.set_item(name, &x)?,
            _ => {}
        }
        all.set_item(name, x)?;
    }
    let report = py.import("json")?.call_method1("loads", (result.report.to_json(),))?.unbind();
    Ok(RunResult { outputs: all.unbind(), images: images.unbind(), metrics: metrics.unbind(), report })
}
