//! Running one node outside a graph: unit tests of nodes, kernel benchmarks, hand-made
//! stiff cases.

use crate::cache::CacheEntry;
use crate::ctx::{CancelToken, Observer, RunCtx};
use crate::error::NodeError;
use crate::node::{DynNode, Node, NodeEntry};
use crate::params::{ParamValue, ParamValues};
use crate::port::Value;
use crate::registry::Registry;
use std::path::Path;

/// Checks `params` against the node's schema (as the graph loader does), fills defaults and
/// runs the node on `inputs` (in declared order). Parameter problems come back as
/// `NodeError::Param`.
pub fn run_standalone<N: Node>(params: &[(&str, ParamValue)], base_dir: &Path, inputs: &[Value]) -> Result<CacheEntry, NodeError> {
    run_standalone_with::<N>(&CancelToken::new(), None, params, base_dir, inputs)
}

/// As `run_standalone`, with a cancellation token and an observer (cancellation tests).
pub fn run_standalone_with<N: Node>(
    cancel: &CancelToken,
    observer: Option<&dyn Observer>,
    params: &[(&str, ParamValue)],
    base_dir: &Path,
    inputs: &[Value],
) -> Result<CacheEntry, NodeError> {
    run_dyn(&NodeEntry::<N>::new(), cancel, observer, params, base_dir, inputs)
}

/// As `run_standalone` for a registered kind named at run time.
pub fn run_kind(
    reg: &Registry,
    kind: &str,
    params: &[(&str, ParamValue)],
    base_dir: &Path,
    inputs: &[Value],
) -> Result<CacheEntry, NodeError> {
    let node = reg.node(kind).ok_or_else(|| NodeError::failed(format!("no node kind \"{kind}\" is registered")))?;
    run_dyn(node.as_ref(), &CancelToken::new(), None, params, base_dir, inputs)
}

fn run_dyn(
    node: &dyn DynNode,
    cancel: &CancelToken,
    observer: Option<&dyn Observer>,
    params: &[(&str, ParamValue)],
    base_dir: &Path,
    inputs: &[Value],
) -> Result<CacheEntry, NodeError> {
    let schema = node.schema();
    let mut explicit = Vec::new();
    for (name, v) in params {
        let spec = schema.get(name).ok_or_else(|| NodeError::param(name, "unknown parameter"))?;
        explicit.push((name.to_string(), spec.check(v).map_err(|m| NodeError::param(name, m))?));
    }
    let values = ParamValues::resolve(schema, &explicit, base_dir).map_err(|m| NodeError::param(m[0], "missing required parameter"))?;
    let n_in = node.ports().inputs.len();
    if inputs.len() != n_in {
        return Err(NodeError::failed(format!("{} takes {n_in} inputs, {} given", node.kind(), inputs.len())));
    }
    let cx = RunCtx::new(node.kind(), cancel, observer);
    let outputs = node.run(&values, inputs, &cx)?;
    let (metrics, notes, deps) = cx.take();
    Ok(CacheEntry { outputs, metrics, notes, deps, compute_ms: 0.0 })
}
