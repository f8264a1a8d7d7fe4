//! The native module of the `relume` Python package (`relume._relume`): graphs loaded and
//! validated as the command line does, parameters set with `--set`'s checks and messages,
//! runs through the same engine and disk cache, images as numpy arrays. The Python side
//! (`python/relume/`) re-exports it and adds what is easier written in Python.

mod errors;
mod feed;
mod graph;
mod images;
mod kinds;
mod pynode;
mod run;
mod timing;
mod values;

use pyo3::prelude::*;

/// The catalogue: every node kind the registry knows (the Python ones defined so far too), as dicts (kind, category, version,
/// doc, inputs, outputs, params, metrics).
#[pyfunction]
fn nodes(py: Python<'_>) -> PyResult<Vec<Py<PyAny>>> {
    let reg = graph::registry(None);
    reg.nodes().map(|n| values::node_kind(py, n.as_ref())).collect()
}

#[pymodule]
fn _relume(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("GraphError", m.py().get_type::<errors::GraphError>())?;
    m.add("RunError", m.py().get_type::<errors::RunError>())?;
    m.add_class::<graph::Graph>()?;
    m.add_class::<run::RunResult>()?;
    m.add_function(wrap_pyfunction!(nodes, m)?)?;
    m.add_function(wrap_pyfunction!(images::read_image, m)?)?;
    m.add_function(wrap_pyfunction!(images::write_image, m)?)?;
    m.add_function(wrap_pyfunction!(timing::_time_edits, m)?)?;
    m.add_function(wrap_pyfunction!(pynode::_define_node, m)?)?;
    Ok(())
}
