//! What a sharded node exposes to the engine: how its work splits into chunks (`ShardSpec`)
//! and the type-erased calls that run and gather them (`DynSharded`, behind `DynNode::sharded`).

use crate::ctx::RunCtx;
use crate::error::NodeError;
use crate::params::ParamValues;
use crate::port::{PortDecl, Value};
use std::ops::Range;

/// How a sharded node's work splits: `items` work items in chunks of `chunk` items (the last
/// one shorter). The chunk size depends only on the node's inputs and parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShardSpec {
    pub items: u64,
    pub chunk: u64,
}

impl ShardSpec {
    pub fn new(items: u64, chunk: u64) -> Self {
        ShardSpec { items, chunk: chunk.max(1) }
    }
    /// Number of chunks.
    pub fn chunks(&self) -> u64 {
        self.items.div_ceil(self.chunk)
    }
    /// The items of chunk `k`.
    pub fn chunk_items(&self, k: u64) -> Range<u64> {
        (k * self.chunk).min(self.items)..((k + 1) * self.chunk).min(self.items)
    }
    /// The chunks of shard `index` of `count`: contiguous, in order, their numbers differing
    /// by at most one between shards (empty when there are more shards than chunks).
    pub fn shard_chunks(&self, index: u64, count: u64) -> Range<u64> {
        let (c, n) = (self.chunks() as u128, count.max(1) as u128);
        let i = (index as u128).min(n);
        ((i * c / n) as u64)..(((i + 1).min(n) * c / n) as u64)
    }
}

/// A sharded node kind behind a trait object (`DynNode::sharded`).
pub trait DynSharded: Send + Sync {
    fn spec(&self, params: &ParamValues, inputs: &[Value]) -> Result<ShardSpec, NodeError>;
    fn run_items(&self, params: &ParamValues, inputs: &[Value], items: Range<u64>, cx: &RunCtx) -> Result<Value, NodeError>;
    /// `parts`: one partial per chunk, in chunk order; outputs in declaration order.
    fn gather(&self, params: &ParamValues, inputs: &[Value], parts: &[Value], cx: &RunCtx) -> Result<Vec<Value>, NodeError>;
    /// The partial's type, as a port declaration (for the disk cache).
    fn partial_decl(&self) -> PortDecl;
}
