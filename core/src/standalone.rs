//! Running one node outside a graph: unit tests of nodes and kernel benchmarks.

use crate::cache::CacheEntry;
use crate::ctx::{CancelToken, RunCtx};
use crate::io::Io;
use crate::node::{Node, NodeError};
use crate::params::{ParamValue, ParamValues, Params};
use crate::port::Value;
use std::path::Path;

/// Checks `params` against the node's schema (as the graph loader does), fills defaults and
/// runs the node on `inputs` (in declared order). Parameter problems come back as
/// `NodeError::Param`.
pub fn run_standalone<N: Node>(
    node: &N,
    params: &[(&str, ParamValue)],
    base_dir: &Path,
    inputs: &[Value],
) -> Result<CacheEntry, NodeError> {
    let schema = N::Params::schema();
    let mut explicit = Vec::new();
    for (name, v) in params {
        let spec = schema.get(name).ok_or_else(|| NodeError::param(name, "unknown parameter"))?;
        explicit.push((name.to_string(), spec.check(v).map_err(|m| NodeError::param(name, m))?));
    }
    let values = ParamValues::resolve(&schema, &explicit, base_dir).map_err(|m| NodeError::param(m[0], "missing required parameter"))?;
    let ports = N::ports();
    if inputs.len() != ports.inputs.len() {
        return Err(NodeError::failed(format!("{} takes {} inputs, {} given", N::KIND, ports.inputs.len(), inputs.len())));
    }
    let cancel = CancelToken::new();
    let cx = RunCtx::new(N::KIND, &cancel, None);
    let mut io = Io::new(&ports, inputs);
    node.run(&N::Params::from_values(&values), &mut io, &cx)?;
    let outputs = io.finish()?;
    let (metrics, notes, deps) = cx.take();
    Ok(CacheEntry { outputs, metrics, notes, deps, compute_ms: 0.0 })
}
