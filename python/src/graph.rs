//! `relume.Graph`: a graph file loaded and validated as `relume run` loads it, its parameters
//! set with `--set`'s checks and messages, run through an engine it keeps (so that after an
//! edit the next run re-runs only what the edit reaches, in memory), sharing the command
//! line's disk cache.

use crate::errors::{graph_error, graph_errors};
use crate::feed::ArrayInput;
use crate::values::{param_to_py, py_to_param};
use pyo3::exceptions::{PyOSError, PyRuntimeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use relume_core::Engine;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A node graph and the engine that runs it. `Graph(path)` (or `Graph.load(path)`) reads a
/// `.ron` graph file, `Graph()` starts an empty one to build with `add`, `connect` and
/// `output`; `cache=` names the disk-cache folder (default: `$RELUME_CACHE`, else
/// `.relume-cache` in the current folder, as `relume run`), `no_disk_cache=True` keeps every
/// result in memory.
#[pyclass(module = "relume", subclass)]
pub struct Graph {
    pub graph: relume_core::Graph,
    pub engine: Arc<Engine>,
    /// The arrays fed with `feed`, registered as this graph's `ArrayInput` kind.
    feeds: Arc<ArrayInput>,
}

impl Graph {
    /// Takes in the Python node kinds defined (or redefined) since the last call.
    fn sync(&mut self) -> PyResult<()> {
        if crate::pynode::stale(self.engine.registry()) {
            let engine = Arc::get_mut(&mut self.engine)
                .ok_or_else(|| PyRuntimeError::new_err("a node kind cannot be defined while the graph runs"))?;
            crate::pynode::sync(engine.registry_mut());
        }
        Ok(())
    }
}

/// The registry a Python graph runs with: every compiled kind, its own `ArrayInput` and the
/// Python node kinds defined so far.
pub fn registry(feeds: Option<Arc<ArrayInput>>) -> relume_core::Registry {
    let mut reg = relume_cli::registry();
    reg.add_dyn(feeds.unwrap_or_else(|| Arc::new(ArrayInput::new())));
    crate::pynode::sync(&mut reg);
    reg
}

#[pymethods]
impl Graph {
    #[new]
    #[pyo3(signature = (path = None, *, cache = None, no_disk_cache = false))]
    fn new(py: Python<'_>, path: Option<PathBuf>, cache: Option<PathBuf>, no_disk_cache: bool) -> PyResult<Self> {
        let feeds = Arc::new(ArrayInput::new());
        let reg = registry(Some(feeds.clone()));
        let graph = match path {
            Some(path) => relume_core::Graph::load(&path, &reg).map_err(|e| graph_errors(py, &e))?,
            // A graph to build: relative file parameters name files in the current folder.
            None => relume_core::Graph { base_dir: std::env::current_dir()?, ..Default::default() },
        };
        let mut engine = Engine::new(reg);
        if let Some((dir, _)) = relume_cli::cache_dir(cache.as_deref(), no_disk_cache) {
            engine = engine.with_disk_cache(dir);
        }
        Ok(Graph { graph, engine: Arc::new(engine), feeds })
    }

    /// The file the graph was read from.
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.graph.file.clone()
    }

    /// The nodes, in file order: dicts of `id`, `kind` and `params` (the values the file or
    /// an edit set; the others are at their defaults, which `relume.nodes()` lists).
    #[getter]
    fn nodes(&self, py: Python<'_>) -> PyResult<Vec<Py<PyAny>>> {
        self.graph
            .nodes
            .iter()
            .map(|n| {
                let d = PyDict::new(py);
                d.set_item("id", &n.id)?;
                d.set_item("kind", &n.kind)?;
                let params = PyDict::new(py);
                for (name, v) in &n.params {
                    params.set_item(name, param_to_py(py, v)?)?;
                }
                d.set_item("params", params)?;
                Ok(d.into_any().unbind())
            })
            .collect()
    }

    /// The names of the graph's outputs.
    #[getter]
    fn outputs(&self) -> Vec<String> {
        self.graph.outputs.iter().map(|o| o.name.clone()).collect()
    }

    /// Sets `node.param` to `value`, checked against the parameter's schema as `relume run
    /// --set` checks it: an unknown node, an unknown parameter (with the closest name), a
    /// value out of range or of the wrong type raise `GraphError` with `--set`'s message.
    fn set(&mut self, py: Python<'_>, assignment: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        self.sync()?;
        let reg = self.engine.registry().clone();
        self.graph.set_param_checked(&reg, assignment, |spec| py_to_param(spec, value)).map_err(|e| graph_error(py, &e))
    }

    /// The value of `node.param`: the one set, else its default.
    fn get(&self, py: Python<'_>, assignment: &str) -> PyResult<Py<PyAny>> {
        let bad = |m: String| graph_error(py, &relume_core::GraphError::new(m));
        let (id, name) = assignment.split_once('.').ok_or_else(|| bad(format!("`{assignment}` is not of the form node.param")))?;
        let spec = self.graph.param_spec(self.engine.registry(), id, name).map_err(|e| graph_error(py, &e))?;
        let node = self.graph.node(id).expect("param_spec found it");
        match node.params.iter().find(|(n, _)| n == name).map(|(_, v)| v).or(spec.default.as_ref()) {
            Some(v) => param_to_py(py, v),
            None => Ok(py.None()),
        }
    }

    /// Runs the graph (`outputs`: those names only; default all) and returns its outputs,
    /// metrics and report. The engine is kept: after `set`, the next run re-runs only what the
    /// edit reaches. The GIL is released while the run goes on; `progress(node, fraction)` is
    /// called from the calling thread as nodes advance; Ctrl-C cancels the run and raises
    /// `KeyboardInterrupt`.
    #[pyo3(signature = (outputs = None, *, progress = None))]
    fn run(&mut self, py: Python<'_>, outputs: Option<Vec<String>>, progress: Option<Py<PyAny>>) -> PyResult<crate::run::RunResult> {
        self.sync()?;
        crate::run::run(py, &self.graph, &self.engine, outputs, progress)
    }

    /// Sets every parameter that declares a test value to it: the graph at the size the
    /// tests and CI run it at (samples, resolutions and iterations turned down), in seconds.
    fn shrink_to_test_size(&mut self, py: Python<'_>) -> PyResult<()> {
        let reg = self.engine.registry().clone();
        self.graph.shrink_to_test_size(&reg).map_err(|e| graph_error(py, &e))
    }

    /// Adds a node of `kind` (`id`: a fresh one from the kind's name when left out), its
    /// parameters set from the keywords with `set`'s checks; returns the id. An unknown kind
    /// (with the closest name), a taken or malformed id, or a refused value raise `GraphError`
    /// and leave the graph as it was.
    #[pyo3(signature = (kind, *, id = None, **params))]
    fn add(&mut self, py: Python<'_>, kind: &str, id: Option<String>, params: Option<&Bound<'_, PyDict>>) -> PyResult<String> {
        self.sync()?;
        let reg = self.engine.registry().clone();
        let id = self.graph.add_node(&reg, kind, id.as_deref()).map_err(|e| graph_error(py, &e))?;
        for (name, value) in params.into_iter().flat_map(|d| d.iter()) {
            let name: String = name.extract()?;
            if let Err(e) = self.set(py, &format!("{id}.{name}"), &value) {
                self.graph.nodes.retain(|n| n.id != id);
                return Err(e);
            }
        }
        Ok(id)
    }

    /// Connects output port `source` (`node.port`) to input port `target`, replacing what fed
    /// it; the types must agree and no cycle may close (`GraphError` says why not).
    fn connect(&mut self, py: Python<'_>, source: &str, target: &str) -> PyResult<()> {
        self.sync()?;
        let reg = self.engine.registry().clone();
        let port = |s: &str| {
            relume_core::graph::PortRef::parse(s)
                .ok_or_else(|| graph_error(py, &relume_core::GraphError::new(format!("`{s}` is not of the form node.port"))))
        };
        let (from, to) = (port(source)?, port(target)?);
        self.graph.connect(&reg, from, to).map_err(|m| graph_error(py, &relume_core::GraphError::new(m)))
    }

    /// Feeds `array` (height × width × 3, × 4 or height × width; any real type, read as
    /// float32 linear RGB) to the image input `target` (`node.port`) through a node
    /// `<node>_<port>_array` of kind `ArrayInput`, added and connected the first time; returns
    /// its id. The array is copied; the cache knows it by the hash of its pixels, so feeding the
    /// same pixels again re-runs nothing. A graph with fed arrays runs only from this session.
    fn feed(&mut self, py: Python<'_>, target: &str, array: &Bound<'_, PyAny>) -> PyResult<String> {
        self.sync()?;
        let bad = |m: String| graph_error(py, &relume_core::GraphError::new(m));
        let to = relume_core::graph::PortRef::parse(target).ok_or_else(|| bad(format!("`{target}` is not of the form node.port")))?;
        let img = crate::images::from_numpy(array)?;
        let id = format!("{}_{}_array", to.node, to.port);
        let reg = self.engine.registry().clone();
        let added = self.graph.node(&id).is_none();
        if added {
            self.graph.add_node(&reg, crate::kinds::ARRAY_INPUT, Some(&id)).map_err(|e| graph_error(py, &e))?;
        }
        let from = relume_core::graph::PortRef::parse(&format!("{id}.image")).expect("a port name");
        if let Err(m) = self.graph.connect(&reg, from, to) {
            if added {
                self.graph.nodes.retain(|n| n.id != id);
            }
            return Err(bad(m));
        }
        let key = self.feeds.put(&id, img);
        self.graph
            .set_param_checked(&reg, &format!("{id}.key"), |_| Ok(relume_core::ParamValue::Text(key)))
            .map_err(|e| graph_error(py, &e))?;
        Ok(id)
    }

    /// Makes port `port` (`node.port`) the graph output `name`.
    fn output(&mut self, py: Python<'_>, name: &str, port: &str) -> PyResult<()> {
        let p = relume_core::graph::PortRef::parse(port)
            .ok_or_else(|| graph_error(py, &relume_core::GraphError::new(format!("`{port}` is not of the form node.port"))))?;
        if self.graph.node(&p.node).is_none() {
            return Err(graph_error(py, &relume_core::GraphError::new(format!("no node \"{}\" in the graph", p.node))));
        }
        self.graph.set_output(&p, name, true);
        Ok(())
    }

    /// The graph as the RON text the command line and the editor read.
    fn to_ron(&self) -> String {
        self.graph.to_ron()
    }

    /// Writes the graph to `path` (atomically: a reader never sees half a file). File
    /// parameters keep their text: relative ones name files beside the graph it was read from.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        relume_core::graph::write_atomic(&path, self.graph.to_ron().as_bytes())
            .map_err(|e| PyOSError::new_err(format!("cannot write {}: {e}", path.display())))
    }

    fn __repr__(&self) -> String {
        let file = self.graph.file.as_deref().map_or("(built in Python)".to_string(), |p: &Path| p.display().to_string());
        format!("<relume.Graph {file}: {} nodes, outputs {:?}>", self.graph.nodes.len(), self.outputs())
    }
}
