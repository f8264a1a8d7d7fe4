//! The engine's own time for an edit, measured from Rust inside the module: the yardstick the
//! Python overhead is measured against (`docs/guide/python.md`), in the same process and run.

use crate::errors::{graph_error, graph_errors};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use relume_core::{Engine, ParamValue, RunOptions};
use std::path::PathBuf;
use std::time::Instant;

/// Loads `path` (no disk cache), runs `outputs` once, then for each of `values` sets
/// `assignment` to it and runs again, all in Rust with the GIL released; the milliseconds of
/// each set-and-run.
#[pyfunction]
#[pyo3(signature = (path, assignment, values, outputs = None))]
pub fn _time_edits(py: Python<'_>, path: PathBuf, assignment: &str, values: Vec<f64>, outputs: Option<Vec<String>>) -> PyResult<Vec<f64>> {
    let reg = relume_cli::registry();
    let mut graph = relume_core::Graph::load(&path, &reg).map_err(|e| graph_errors(py, &e))?;
    let engine = Engine::new(reg);
    let opts = RunOptions { outputs, ..Default::default() };
    let run = |g: &relume_core::Graph| engine.run(g, &opts).map(|_| ()).map_err(|e| PyRuntimeError::new_err(e.to_string()));
    run(&graph)?;
    let mut times = Vec::with_capacity(values.len());
    for v in values {
        let t0 = Instant::now();
        graph.set_param_checked(engine.registry(), assignment, |_| Ok(ParamValue::Float(v))).map_err(|e| graph_error(py, &e))?;
        py.detach(|| run(&graph))?;
        times.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    Ok(times)
}
