//! The node trait and its type-erased form.
//!
//! A node is one struct that derives `Params` (its fields are its parameters, its doc comment
//! the editor tooltip), its ports declared with `inputs!` / `outputs!`, and `#[node]` on the
//! `impl` holding `run`. See docs/guide/writing-a-node.md.

use crate::ctx::RunCtx;
use crate::error::NodeError;
use crate::memory::{MemoryEstimate, PortSize};
use crate::params::{ParamValues, Params, Schema};
use crate::port::{InputPorts, OutputPorts, Ports, Value};
use crate::shard::DynSharded;
use std::sync::Arc;

/// Where a node's results may be kept between runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Caching {
    /// The rule: always in the memory cache; also on disk (when the engine has a disk cache)
    /// whenever computing the result cost more than loading it would
    /// (see [`load_cost_ms`](crate::cache::load_cost_ms)).
    Auto,
    /// Never cached: the node has a side effect (writes a file) and runs every time it is needed.
    Never,
    /// As `Auto`, but the outputs are fingerprinted by the run's cache key instead of by
    /// hashing their content: for the per-edit nodes of an interactive pipeline, whose
    /// megabytes of output change with every edit (hashing them would cost a noticeable part
    /// of a frame, and an unchanged output, the one thing content hashing would catch, does
    /// not happen there); and for large outputs that change whenever their inputs do (a
    /// point hierarchy of hundreds of megabytes, whose hash costs a good part of its build).
    /// What this gives up is only the early cut-off when a re-run reproduces the same bytes.
    Keyed,
}

/// The doc comment of a node type, available at run time (the editor tooltip, `relume nodes`).
/// Implemented by `derive(Params)`.
pub trait Documented {
    const DOC: &'static str;
}

/// A stage of a pipeline: its parameters are `Self` (`derive(Params)`), its ports the
/// `Inputs` / `Outputs` structs. Implemented by `#[node]`; see docs/ARCHITECTURE.md.
pub trait Node: Params + Documented + Send + Sync + 'static {
    const KIND: &'static str;
    /// Bump when the output for the same inputs and parameters changes.
    const VERSION: u32;
    /// Palette category in the editor (e.g. "image", "scene").
    const CATEGORY: &'static str;
    const CACHING: Caching;
    /// The names of the metrics a run may record with `cx.metric` (what a sweep may put on
    /// its error axis), declared with `#[node(metrics = […])]`; the executor refuses a run
    /// that records a name not listed.
    const METRICS: &'static [&'static str] = &[];
    type Inputs<'a>: InputPorts<'a>;
    type Outputs: OutputPorts;
    fn run(&self, inputs: Self::Inputs<'_>, cx: &RunCtx) -> Result<Self::Outputs, NodeError>;
    /// What a run will hold, from the parameters and the input sizes (`None` where not known
    /// before running upstream): see `memory.rs`. Nodes that allocate much state it; the
    /// default knows nothing.
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        let _ = inputs;
        MemoryEstimate::unknown(Self::Outputs::decls().len())
    }
    /// The run's work against other runs of the same kind, from the parameters and the input
    /// sizes (a renderer: the samples it traces): of two ready runs of one kind, one needing at
    /// most a quarter of the other's work runs first and alone, so that its result (a preview
    /// beside its ground truth) comes out sooner. `None` (the default): not known.
    fn work(&self, inputs: &[Option<PortSize>]) -> Option<f64> {
        let _ = inputs;
        None
    }
    /// The node's shard contract when it has one (`#[node(…, sharded)]`, see `shard.rs`).
    fn sharded() -> Option<Arc<dyn DynSharded>> {
        None
    }
}

/// The port declarations of a node type.
pub fn ports_of<N: Node>() -> Ports {
    Ports { inputs: <N::Inputs<'static> as InputPorts<'static>>::decls(), outputs: N::Outputs::decls() }
}

/// Builds the node from checked parameter values and runs it on `inputs` (declared order).
pub fn run_typed<N: Node>(params: &ParamValues, inputs: &[Value], cx: &RunCtx) -> Result<Vec<Value>, NodeError> {
    let node = N::from_values(params)?;
    let inputs = N::Inputs::from_values(inputs)?;
    Ok(node.run(inputs, cx)?.into_values())
}

/// A node kind behind a trait object, as the registry and executor hold it.
pub trait DynNode: Send + Sync {
    fn kind(&self) -> &'static str;
    fn version(&self) -> u32;
    fn category(&self) -> &'static str;
    /// The doc comment with the leading space of each line removed.
    fn doc(&self) -> &str;
    fn ports(&self) -> &Ports;
    fn schema(&self) -> &Schema;
    fn caching(&self) -> Caching;
    /// The metric names a run may record (`Node::METRICS`).
    fn metrics(&self) -> &'static [&'static str] {
        &[]
    }
    /// Runs the node; outputs in declaration order.
    fn run(&self, params: &ParamValues, inputs: &[Value], cx: &RunCtx) -> Result<Vec<Value>, NodeError>;
    /// The node's memory estimate for these parameters and input sizes.
    fn memory(&self, params: &ParamValues, inputs: &[Option<PortSize>]) -> Result<MemoryEstimate, NodeError> {
        let _ = (params, inputs);
        Ok(MemoryEstimate::unknown(self.ports().outputs.len()))
    }
    /// The run's work against other runs of its kind (`Node::work`); `None` where not known.
    fn work(&self, params: &ParamValues, inputs: &[Option<PortSize>]) -> Option<f64> {
        let _ = (params, inputs);
        None
    }
    /// The shard contract of a node whose work splits over items; `None` for most nodes.
    fn sharded(&self) -> Option<&dyn DynSharded> {
        None
    }
    /// For a kind defined at run time (a function written in Python), a hash of its
    /// definition (the function's source): part of every cache key of the kind, so that an
    /// edited definition gives new results. `None` for compiled kinds, whose `version` says it.
    fn definition(&self) -> Option<crate::Hash> {
        None
    }
}

pub(crate) struct NodeEntry<N: Node> {
    ports: Ports,
    schema: Schema,
    doc: String,
    sharded: Option<Arc<dyn DynSharded>>,
    _node: std::marker::PhantomData<fn() -> N>,
}

impl<N: Node> NodeEntry<N> {
    pub(crate) fn new() -> Self {
        let doc = N::DOC.lines().map(|l| l.strip_prefix(' ').unwrap_or(l)).collect::<Vec<_>>().join("\n").trim().to_string();
        NodeEntry { ports: ports_of::<N>(), schema: N::schema(), doc, sharded: N::sharded(), _node: std::marker::PhantomData }
    }
}

impl<N: Node> DynNode for NodeEntry<N> {
    fn kind(&self) -> &'static str {
        N::KIND
    }
    fn version(&self) -> u32 {
        N::VERSION
    }
    fn category(&self) -> &'static str {
        N::CATEGORY
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
        N::CACHING
    }
    fn metrics(&self) -> &'static [&'static str] {
        N::METRICS
    }
    fn run(&self, params: &ParamValues, inputs: &[Value], cx: &RunCtx) -> Result<Vec<Value>, NodeError> {
        run_typed::<N>(params, inputs, cx)
    }
    fn memory(&self, params: &ParamValues, inputs: &[Option<PortSize>]) -> Result<MemoryEstimate, NodeError> {
        Ok(N::from_values(params)?.memory(inputs))
    }
    fn work(&self, params: &ParamValues, inputs: &[Option<PortSize>]) -> Option<f64> {
        N::from_values(params).ok()?.work(inputs)
    }
    fn sharded(&self) -> Option<&dyn DynSharded> {
        self.sharded.as_deref()
    }
}
