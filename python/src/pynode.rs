//! Nodes written in Python: a function decorated with `relume.node` becomes a node kind whose
//! ports carry images (numpy arrays) or metrics (dicts of floats) and whose parameters are the
//! function's keyword arguments, checked as any node's. Its cache key holds a hash of the
//! function's source, so editing the function re-runs it, and an unchanged function with
//! unchanged parameters and inputs is taken from the cache like any other node. Such kinds
//! exist only in the Python process that defined them: a graph using one runs from Python.

use crate::images::from_numpy;
use crate::kinds::CATEGORY;
use crate::values::{output_to_py, param_to_py};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use relume_base::types::{Image, Metrics};
use relume_core::{Caching, DynNode, Hash, Hasher, NodeError, ParamValues, PortDecl, PortTypeInfo, Ports, Registry, RunCtx, Schema, Value};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

/// The kinds defined in this process, by name: every graph's registry takes them in before it
/// loads, edits or runs (`sync`).
static DEFINED: Mutex<BTreeMap<&'static str, Arc<PyNode>>> = Mutex::new(BTreeMap::new());

/// A node kind whose `run` calls a Python function.
pub struct PyNode {
    kind: &'static str,
    doc: String,
    ports: Ports,
    schema: Schema,
    definition: Hash,
    func: Py<PyAny>,
}

fn leak(s: String) -> &'static str {
    // Kind, port and parameter names live as long as the registry that holds them, which the
    // engine keeps for the process: a definition leaks its few names once.
    Box::leak(s.into_boxed_str())
}

fn port(name: String, ty: &str) -> PyResult<PortDecl> {
    let ty = match ty {
        "Image" => PortTypeInfo::of::<Image>(),
        "Metrics" => PortTypeInfo::of::<Metrics>(),
        other => return Err(PyValueError::new_err(format!("port `{name}`: a Python node's ports are Image or Metrics, not {other}"))),
    };
    Ok(PortDecl { name: leak(name), ty })
}

fn is_identifier(s: &str) -> bool {
    let mut c = s.chars();
    c.next().is_some_and(|f| f.is_ascii_alphabetic() || f == '_') && c.all(|x| x.is_ascii_alphanumeric() || x == '_')
}

/// One parameter of a Python node: its default gives its type (bool, int, float, str); numbers
/// take an optional `(min, max)` range.
fn add_param(schema: Schema, name: &'static str, default: &Bound<'_, PyAny>, range: Option<(f64, f64)>) -> PyResult<Schema> {
    let (lo, hi) = range.unwrap_or((f64::MIN, f64::MAX));
    if lo > hi || lo.is_nan() || hi.is_nan() {
        return Err(PyValueError::new_err(format!("parameter `{name}`: the range [{lo}, {hi}] is empty")));
    }
    let schema = if let Ok(b) = default.cast::<pyo3::types::PyBool>() {
        schema.bool(name, b.is_true())
    } else if default.is_instance_of::<pyo3::types::PyInt>() {
        let d: i64 = default.extract()?;
        let (lo, hi) = range.map_or((i64::MIN, i64::MAX), |(a, b)| (a.ceil() as i64, b.floor() as i64));
        schema.int(name, d, lo, hi)
    } else if let Ok(d) = default.extract::<f64>() {
        schema.float(name, d, lo, hi)
    } else if let Ok(d) = default.extract::<String>() {
        schema.text(name, &d)
    } else {
        return Err(PyValueError::new_err(format!(
            "parameter `{name}`: a Python node's parameters default to a bool, an int, a float or a str, not {}",
            default.repr()?
        )));
    };
    // The default must lie in its own range.
    let spec = schema.get(name).expect("just added");
    spec.check(spec.default.as_ref().expect("has a default")).map_err(|m| PyValueError::new_err(format!("parameter `{name}`: {m}")))?;
    Ok(schema)
}

/// Defines (or redefines) the Python node kind `kind`; called by the `relume.node` decorator.
/// `inputs` and `outputs`: (name, "Image" | "Metrics"); `params`: (name, default, range or
/// None, unit, help); `source`: the function's text, hashed into every cache key.
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn _define_node(
    kind: String,
    doc: String,
    inputs: Vec<(String, String)>,
    outputs: Vec<(String, String)>,
    params: Vec<(String, Bound<'_, PyAny>, Option<(f64, f64)>, String, String)>,
    source: String,
    func: Py<PyAny>,
) -> PyResult<()> {
    if !is_identifier(&kind) {
        return Err(PyValueError::new_err(format!("`{kind}` cannot name a node kind (letters, digits and _)")));
    }
    if relume_cli::registry().node(&kind).is_some() || kind == crate::kinds::ARRAY_INPUT {
        return Err(PyValueError::new_err(format!("`{kind}` is a built-in node kind: give the Python node another name")));
    }
    if outputs.is_empty() {
        return Err(PyValueError::new_err(format!("the Python node {kind} has no output")));
    }
    let mut names: Vec<&str> = Vec::new();
    for n in inputs.iter().chain(&outputs).map(|(n, _)| n).chain(params.iter().map(|p| &p.0)) {
        if !is_identifier(n) {
            return Err(PyValueError::new_err(format!("`{n}` cannot name a port or a parameter")));
        }
        if outputs.iter().filter(|(o, _)| o == n).count() > 1 {
            return Err(PyValueError::new_err(format!("the output `{n}` is declared twice")));
        }
        names.push(n);
    }
    let ports = Ports {
        inputs: inputs.into_iter().map(|(n, t)| port(n, &t)).collect::<PyResult<_>>()?,
        outputs: outputs.into_iter().map(|(n, t)| port(n, &t)).collect::<PyResult<_>>()?,
    };
    let mut schema = Schema::new();
    for (name, default, range, unit, help) in params {
        schema = add_param(schema, leak(name), &default, range)?.unit(leak(unit)).help(leak(help));
    }
    let mut h = Hasher::new();
    h.str("python node").str(&kind).str(&source);
    let mut defined = DEFINED.lock().unwrap();
    // A redefinition keeps the name already leaked.
    let kind = defined.keys().copied().find(|k| *k == kind).unwrap_or_else(|| leak(kind));
    let doc = doc.lines().map(str::trim).collect::<Vec<_>>().join("\n").trim().to_string();
    defined.insert(kind, Arc::new(PyNode { kind, doc, ports, schema, definition: h.finish(), func }));
    Ok(())
}

/// Brings `reg` up to date with the kinds defined so far: each new or redefined one replaces
/// what the registry had under its name.
pub fn sync(reg: &mut Registry) {
    for (kind, node) in DEFINED.lock().unwrap().iter() {
        let same = reg.node(kind).is_some_and(|have| std::ptr::addr_eq(Arc::as_ptr(have), Arc::as_ptr(node)));
        if !same {
            reg.remove(kind);
            reg.add_dyn(node.clone());
        }
    }
}

/// Whether any kind was defined since `reg` was last brought up to date.
pub fn stale(reg: &Registry) -> bool {
    DEFINED
        .lock()
        .unwrap()
        .iter()
        .any(|(kind, node)| !reg.node(kind).is_some_and(|have| std::ptr::addr_eq(Arc::as_ptr(have), Arc::as_ptr(node))))
}

/// A Python exception as the node's failure: its type, message and traceback.
fn failed(py: Python<'_>, e: PyErr) -> NodeError {
    let trace = e.traceback(py).and_then(|t| t.format().ok()).unwrap_or_default();
    NodeError::failed(format!("the Python function raised {e}\n{}", trace.trim_end()))
}

impl PyNode {
    /// One returned value as output `decl`: an array for an image, a dict of numbers (or one
    /// number, named after the port) for metrics.
    fn output(&self, decl: &PortDecl, x: &Bound<'_, PyAny>) -> Result<Value, NodeError> {
        let bad = |m: String| NodeError::failed(format!("output `{}`: {m}", decl.name));
        if decl.ty.name == "Image" {
            return from_numpy(x).map(Value::new).map_err(|e| bad(e.to_string()));
        }
        if let Ok(v) = x.extract::<f64>() {
            return Ok(Value::new(Metrics(vec![(decl.name.to_string(), v)])));
        }
        let d = x.cast::<PyDict>().map_err(|_| bad(format!("metrics are a dict of numbers or one number, not {}", x.get_type())))?;
        let mut m = Vec::with_capacity(d.len());
        for (k, v) in d.iter() {
            let (k, v): (String, f64) = (
                k.extract().map_err(|_| bad("a metric's name is a str".into()))?,
                v.extract().map_err(|_| bad("a metric is a number".into()))?,
            );
            m.push((k, v));
        }
        Ok(Value::new(Metrics(m)))
    }
}

impl DynNode for PyNode {
    fn kind(&self) -> &'static str {
        self.kind
    }
    fn version(&self) -> u32 {
        1
    }
    fn category(&self) -> &'static str {
        CATEGORY
    }
    fn doc(&self) -> &str {
        &self.doc
    }
    fn ports(&self) -> &Ports {
        &self.ports
    }
    fn schema(&self) -> &Schema {
        &self.schema
    }
    fn caching(&self) -> Caching {
        Caching::Auto
    }
    fn definition(&self) -> Option<Hash> {
        Some(self.definition)
    }
    /// Calls the function with the inputs and parameters as keyword arguments. One output: the
    /// value returned; several: a tuple in declared order or a dict by name.
    fn run(&self, params: &ParamValues, inputs: &[Value], cx: &RunCtx) -> Result<Vec<Value>, NodeError> {
        cx.check()?;
        Python::attach(|py| {
            let kwargs = PyDict::new(py);
            for (decl, v) in self.ports.inputs.iter().zip(inputs) {
                kwargs.set_item(decl.name, output_to_py(py, v).map_err(|e| failed(py, e))?).map_err(|e| failed(py, e))?;
            }
            for (name, v) in params.iter() {
                kwargs.set_item(name, param_to_py(py, v).map_err(|e| failed(py, e))?).map_err(|e| failed(py, e))?;
            }
            let out = self.func.bind(py).call((), Some(&kwargs)).map_err(|e| failed(py, e))?;
            let outs = &self.ports.outputs;
            if let [one] = outs.as_slice() {
                return Ok(vec![self.output(one, &out)?]);
            }
            if let Ok(d) = out.cast::<PyDict>() {
                return outs
                    .iter()
                    .map(|o| match d.get_item(o.name).map_err(|e| failed(py, e))? {
                        Some(x) => self.output(o, &x),
                        None => Err(NodeError::failed(format!("the returned dict has no output `{}`", o.name))),
                    })
                    .collect();
            }
            let t = out.cast::<PyTuple>().map_err(|_| {
                NodeError::failed(format!("a node with {} outputs returns a tuple or a dict, not {}", outs.len(), out.get_type()))
            })?;
            if t.len() != outs.len() {
                return Err(NodeError::failed(format!("{} values returned for {} outputs", t.len(), outs.len())));
            }
            outs.iter().zip(t.iter()).map(|(o, x)| self.output(o, &x)).collect()
        })
    }
}
