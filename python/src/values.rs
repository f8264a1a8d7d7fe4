//! Between Python values and the engine's: parameter values both ways (a Python value is read
//! as its parameter's schema asks, then checked as `--set` checks it), the catalogue's
//! entries, and a run's outputs.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use relume_base::types::{Image, Metrics};
use relume_core::{DynNode, ParamKind, ParamSpec, ParamValue, Value};

/// A parameter value as Python has it: numbers, booleans, strings (an enum variant's name
/// too) and tuples.
pub fn param_to_py(py: Python<'_>, v: &ParamValue) -> PyResult<Py<PyAny>> {
    Ok(match v {
        ParamValue::Float(f) => f.into_pyobject(py)?.into_any().unbind(),
        ParamValue::Int(i) => i.into_pyobject(py)?.into_any().unbind(),
        ParamValue::Bool(b) => b.into_pyobject(py)?.to_owned().into_any().unbind(),
        ParamValue::Text(s) | ParamValue::Ident(s) => s.into_pyobject(py)?.into_any().unbind(),
        ParamValue::Tuple(items) => {
            let items = items.iter().map(|x| param_to_py(py, x)).collect::<PyResult<Vec<_>>>()?;
            PyTuple::new(py, items)?.into_any().unbind()
        }
    })
}

/// A Python value as a value of parameter `spec`: a string is text, an enum variant's name,
/// or text to read as `--set` reads it (by the parameter's kind); a list or tuple is a tuple; what is neither a number, a
/// boolean, a string nor a sequence of them is refused with `--set`'s words.
pub fn py_to_param(spec: &ParamSpec, v: &Bound<'_, PyAny>) -> Result<ParamValue, String> {
    if let Ok(b) = v.cast::<pyo3::types::PyBool>() {
        return Ok(ParamValue::Bool(b.is_true()));
    }
    if let Ok(s) = v.extract::<String>() {
        // Text as itself, a variant's name as the variant; for any other parameter the string
        // is read as `--set` reads its text (so "2.5" is a number, and "wide" is refused with
        // its words).
        return match spec.kind {
            ParamKind::Text | ParamKind::InputFile | ParamKind::OutputFile => Ok(ParamValue::Text(s)),
            ParamKind::Enum(_) => Ok(ParamValue::Ident(s)),
            _ => spec.read_text(&s),
        };
    }
    if v.is_instance_of::<pyo3::types::PyInt>() {
        if let Ok(i) = v.extract::<i64>() {
            return Ok(ParamValue::Int(i));
        }
    }
    if let Ok(f) = v.extract::<f64>() {
        return Ok(ParamValue::Float(f));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() || v.hasattr("__array__").unwrap_or(false) {
        if let Ok(items) = v.try_iter() {
            let items = items.map(|x| x.map_err(|e| e.to_string()).and_then(|x| py_to_param(spec, &x))).collect::<Result<Vec<_>, _>>()?;
            return Ok(ParamValue::Tuple(items));
        }
    }
    let text = v.repr().map(|r| r.to_string()).unwrap_or_else(|_| "?".into());
    Err(format!("cannot read `{text}` as a value"))
}

/// A catalogue entry: kind, category, version, doc, ports, parameters with their schemas,
/// metrics.
pub fn node_kind(py: Python<'_>, n: &dyn DynNode) -> PyResult<Py<PyAny>> {
    let d = PyDict::new(py);
    d.set_item("kind", n.kind())?;
    d.set_item("category", n.category())?;
    d.set_item("version", n.version())?;
    d.set_item("doc", n.doc())?;
    for (key, ports) in [("inputs", &n.ports().inputs), ("outputs", &n.ports().outputs)] {
        let list = PyList::empty(py);
        for p in ports.iter() {
            let port = PyDict::new(py);
            port.set_item("name", p.name)?;
            port.set_item("type", p.ty.name)?;
            list.append(port)?;
        }
        d.set_item(key, list)?;
    }
    let params = PyList::empty(py);
    for p in &n.schema().0 {
        params.append(param_schema(py, p)?)?;
    }
    d.set_item("params", params)?;
    d.set_item("metrics", n.metrics().to_vec())?;
    Ok(d.into_any().unbind())
}

/// One parameter's schema: name, type, default (None: required), range or choices, the value
/// tests run it at (None: its own), unit, help.
fn param_schema<'py>(py: Python<'py>, p: &ParamSpec) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", p.name)?;
    d.set_item("type", p.kind.type_name())?;
    d.set_item("default", p.default.as_ref().map(|v| param_to_py(py, v)).transpose()?)?;
    match &p.kind {
        ParamKind::Float { min, max } | ParamKind::Rgb { min, max } => d.set_item("range", (*min, *max))?,
        ParamKind::Int { min, max } => d.set_item("range", (*min, *max))?,
        ParamKind::Enum(choices) => d.set_item("choices", choices.to_vec())?,
        _ => {}
    }
    d.set_item("test", p.test.as_ref().map(|v| param_to_py(py, v)).transpose()?)?;
    d.set_item("unit", p.unit)?;
    d.set_item("help", p.help)?;
    Ok(d)
}

/// A run's output as Python has it: an image as a float32 numpy array (height × width × 3),
/// metrics as a dict of floats; other port types (scenes, caches, …) as None.
pub fn output_to_py(py: Python<'_>, v: &Value) -> PyResult<Py<PyAny>> {
    if let Some(img) = v.get::<Image>() {
        return Ok(crate::images::to_numpy(py, img)?.into_any().unbind());
    }
    if let Some(m) = v.get::<Metrics>() {
        let d = PyDict::new(py);
        for (k, x) in &m.0 {
            d.set_item(k, *x)?;
        }
        return Ok(d.into_any().unbind());
    }
    Ok(py.None())
}
