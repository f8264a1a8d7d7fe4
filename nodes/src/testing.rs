//! Helpers for the nodes' own unit tests.

use relume_core::{cache::CacheEntry, run_standalone, Node, NodeError, ParamValue, PortValue, Value};
use std::path::Path;

/// Runs a node with the given explicit parameters and inputs; returns its outputs.
pub fn run_node<N: Node>(node: N, params: &[(&str, ParamValue)], base_dir: &Path, inputs: Vec<Value>) -> Result<Vec<Value>, NodeError> {
    run_full(node, params, base_dir, inputs).map(|e| e.outputs)
}

/// As `run_node`, keeping metrics and notes.
pub fn run_full<N: Node>(node: N, params: &[(&str, ParamValue)], base_dir: &Path, inputs: Vec<Value>) -> Result<CacheEntry, NodeError> {
    run_standalone(&node, params, base_dir, &inputs)
}

/// Runs a node without file parameters on one or more values.
pub fn run_on<N: Node>(node: N, params: &[(&str, ParamValue)], inputs: Vec<Value>) -> Result<Vec<Value>, NodeError> {
    run_node(node, params, Path::new("."), inputs)
}

/// The first output as type T.
pub fn first<T: PortValue + Clone>(out: &[Value]) -> T {
    out[0].get::<T>().expect("output type").clone()
}

pub fn f(x: f64) -> ParamValue {
    ParamValue::Float(x)
}

pub fn i(x: i64) -> ParamValue {
    ParamValue::Int(x)
}

pub fn id(s: &str) -> ParamValue {
    ParamValue::Ident(s.into())
}
