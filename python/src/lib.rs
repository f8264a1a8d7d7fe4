//! The native module of the `relume` Python package (`relume._relume`): graphs loaded and
//! validated as the command line does, parameters set with `--set`'s checks and messages,
//! runs through the same engine and disk cache, images as numpy arrays. The Python side
//! (`python/relume/`) re-exports it and adds what is easier written in Python.
//!
//! The crate is a Python extension module: it links against the interpreter that imports it,
//! so its example is Python, not Rust. `python/tests/test_crate_doc.py` runs the block below
//! (the package installed as `pip install ./python`, from the repository root):
//!
//! ```python
//! import relume
//!
//! g = relume.Graph.load("graphs/filters.ron", no_disk_cache=True)
//! g.set("blur.sigma", 1.5)                 # checked against the parameter's schema
//! r = g.run()
//! image = r.images["image"]                # numpy float32, height × width × 3, linear RGB
//! assert image.ndim == 3 and image.shape[2] == 3
//! g.set("tonemap.exposure", 1.0)           # an edit downstream of the blur
//! assert "blur" not in g.run().ran         # re-runs only what the edit reaches
//! try:
//!     g.set("blur.sigma", -1.0)            # out of the stated range
//! except relume.GraphError as e:
//!     assert "sigma" in str(e)
//! else:
//!     raise AssertionError("a negative sigma was accepted")
//! ```

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
