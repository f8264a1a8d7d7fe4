//! The exceptions: a graph the engine refuses (`GraphError`, a `ValueError` carrying file,
//! line, column, node and parameter where there are some) and a run that failed (`RunError`).

use pyo3::prelude::*;

pyo3::create_exception!(relume, GraphError, pyo3::exceptions::PyValueError, "A graph or a parameter value the engine refuses: the message `relume run` prints, with `file`, `line`, `column`, `node` and `param` where it has them.");
pyo3::create_exception!(relume, RunError, pyo3::exceptions::PyRuntimeError, "A run that failed: the node that failed, its kind and why.");

/// One engine error as a `GraphError`, its parts as attributes.
pub fn graph_error(py: Python<'_>, e: &relume_core::GraphError) -> PyErr {
    let err = GraphError::new_err(e.to_string());
    let v = err.value(py);
    let file = e.file.as_ref().map(|f| f.display().to_string());
    let (line, column) = e.pos.map_or((None, None), |p| (Some(p.line), Some(p.col)));
    for (name, value) in
        [("file", file.into_pyobject(py)), ("node", e.node.clone().into_pyobject(py)), ("param", e.param.clone().into_pyobject(py))]
    {
        let _ = value.map(|x| v.setattr(name, x));
    }
    let _ = v.setattr("line", line);
    let _ = v.setattr("column", column);
    err
}

/// Several engine errors (a graph file with more than one problem): the first's parts, all
/// the messages.
pub fn graph_errors(py: Python<'_>, e: &relume_core::GraphErrors) -> PyErr {
    match e.0.as_slice() {
        [one] => graph_error(py, one),
        [first, ..] => {
            let err = graph_error(py, first);
            let _ = err.value(py).setattr("args", (e.to_string(),));
            err
        }
        [] => GraphError::new_err("the graph was refused"),
    }
}
