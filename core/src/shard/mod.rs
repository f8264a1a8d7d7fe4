//! The shard contract: a node whose work splits over an index range (pixels, vertices,
//! photons) declares how many work items it has, how to run items `[a, b)` into a partial
//! result, and how partial results gather (concatenated in item order, or summed in chunk
//! order). The items are cut into chunks of a fixed size that depends only on the node's
//! inputs and parameters, never on how many machines share the work; each chunk's partial is
//! an ordinary cache entry keyed by the node's key and the chunk's item range
//! ([`partial_key`]). So:
//!
//! - the gathered result has the same bytes for any number of shards, and unsharded (an
//!   unsharded run computes the same chunks and gathers them the same way);
//! - a shard is a contiguous run of chunks ([`ShardSpec::shard_chunks`]); a re-run after a
//!   failure finds the finished chunks in the cache and computes only the missing ones;
//! - two machines that compute the same chunk write the same bytes to a shared cache folder.
//!
//! A sharded node is written as `#[node(category = "…", sharded)]` on an `impl` with
//! `fn shard`, `fn run_items` and `fn gather` instead of `fn run` (see [`Sharded`]). The
//! engine runs it by [`ShardMode`]: every chunk here, one shard of one node (`relume shard`,
//! a Slurm array task), or this process's share with the rest from peer processes
//! ([`ShardPeers`], the timely back-end).

use crate::ctx::{CancelToken, RunCtx};
use crate::error::NodeError;
use crate::hash::{Hash, Hasher};
use crate::node::Node;
use crate::params::ParamValues;
use crate::port::{InputPorts, OutputPorts, PortDecl, PortValue, Value};
use serde::Serialize;
use std::collections::BTreeMap;
use std::ops::Range;

mod run;
mod spec;

pub use spec::{DynSharded, ShardSpec};

/// A node whose work splits over items (see the module doc). Implemented by
/// `#[node(…, sharded)]` from the `impl`'s `shard`, `run_items` and `gather`; its `Node::run`
/// is [`run_all`].
pub trait Sharded: Node {
    /// What running a range of items gives (rows of an image with their counters, a partial
    /// sum); it needs a disk encoding like any port value.
    type Partial: PortValue;
    /// The items and the chunk size for these inputs.
    fn shard(&self, inputs: &Self::Inputs<'_>) -> Result<ShardSpec, NodeError>;
    /// Runs items `items` (one chunk) into a partial result. It must depend only on the
    /// inputs, the parameters and the item range; metrics and notes belong in `gather` (a
    /// partial may come from the cache or another machine).
    fn run_items(&self, inputs: &Self::Inputs<'_>, items: Range<u64>, cx: &RunCtx) -> Result<Self::Partial, NodeError>;
    /// Gathers the partials of every chunk, in chunk order, into the node's outputs.
    fn gather(&self, inputs: &Self::Inputs<'_>, parts: &[&Self::Partial], cx: &RunCtx) -> Result<Self::Outputs, NodeError>;
}

/// Runs every chunk in order and gathers: what a sharded node does outside an engine
/// (`run_standalone`, the node's own tests), with the same bytes as any sharded run.
pub fn run_all<N: Sharded>(node: &N, inputs: &N::Inputs<'_>, cx: &RunCtx) -> Result<N::Outputs, NodeError> {
    let spec = node.shard(inputs)?;
    let n = spec.chunks();
    let mut parts = Vec::with_capacity(n as usize);
    for k in 0..n {
        cx.set_outer(k as f64 / n as f64, (k + 1) as f64 / n as f64);
        cx.check()?;
        parts.push(node.run_items(inputs, spec.chunk_items(k), cx)?);
    }
    cx.set_outer(1.0, 1.0);
    node.gather(inputs, &parts.iter().collect::<Vec<_>>(), cx)
}

/// The cache key of the partial result of items `items` of the node whose key is `node_key`.
pub fn partial_key(node_key: &Hash, items: &Range<u64>) -> Hash {
    Hasher::new().str("relume-shard-v1").hash(node_key).u64(items.start).u64(items.end).finish()
}

/// The type-erased form of a [`Sharded`] node (built by `#[node(…, sharded)]`).
pub struct ShardEntry<N>(std::marker::PhantomData<fn() -> N>);

impl<N: Sharded> ShardEntry<N> {
    pub fn new() -> Self {
        ShardEntry(std::marker::PhantomData)
    }
}

impl<N: Sharded> Default for ShardEntry<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<N: Sharded> DynSharded for ShardEntry<N> {
    fn spec(&self, params: &ParamValues, inputs: &[Value]) -> Result<ShardSpec, NodeError> {
        N::from_values(params)?.shard(&N::Inputs::from_values(inputs)?)
    }
    fn run_items(&self, params: &ParamValues, inputs: &[Value], items: Range<u64>, cx: &RunCtx) -> Result<Value, NodeError> {
        Ok(Value::new(N::from_values(params)?.run_items(&N::Inputs::from_values(inputs)?, items, cx)?))
    }
    fn gather(&self, params: &ParamValues, inputs: &[Value], parts: &[Value], cx: &RunCtx) -> Result<Vec<Value>, NodeError> {
        let typed: Vec<&N::Partial> = parts
            .iter()
            .map(|v| v.get::<N::Partial>().ok_or_else(|| NodeError::failed(format!("a partial result holds {}", v.type_name()))))
            .collect::<Result<_, _>>()?;
        Ok(N::from_values(params)?.gather(&N::Inputs::from_values(inputs)?, &typed, cx)?.into_values())
    }
    fn partial_decl(&self) -> PortDecl {
        PortDecl::of::<N::Partial>("partial")
    }
}

/// Which chunks of sharded nodes a run computes.
#[derive(Clone, Copy, Default)]
pub enum ShardMode<'a> {
    /// Every chunk, here (those in the cache are loaded), then the gather: a normal run.
    #[default]
    All,
    /// Only shard `index` of `count` of node `node` (`relume shard`, one Slurm array task):
    /// its chunks go to the disk cache, nothing is gathered and the run stops at that node.
    /// Other sharded nodes upstream of it run whole.
    One { node: &'a str, index: u64, count: u64 },
    /// This process's share of every sharded node; the other chunks arrive from the peer
    /// processes (the timely back-end), and every process gathers.
    Peers(&'a dyn ShardPeers),
}

/// A partial result on its way between processes.
#[derive(Clone, Debug)]
pub enum ShardPayload {
    /// Its cache key: every process sees the same disk cache folder, which holds it.
    Key(Hash),
    /// Its disk encoding.
    Bytes(Vec<u8>),
}

/// One chunk's partial result of one node, sent by the process that computed (or loaded) it.
#[derive(Clone, Debug)]
pub struct ShardMessage {
    /// The key of the sharded node (the same on every process for the same graph and inputs).
    pub node_key: Hash,
    pub chunk: u64,
    /// The sending process.
    pub from: usize,
    /// Whether the sender found it in its cache (else it ran it, taking `ms`).
    pub cached: bool,
    pub ms: f64,
    pub payload: ShardPayload,
}

/// The other processes of a multi-process run, as a sharded node's runner sees them.
pub trait ShardPeers: Send + Sync {
    /// This process's index, 0-based.
    fn process(&self) -> usize;
    fn processes(&self) -> usize;
    /// Whether all processes share the disk cache folder (partials then travel as keys).
    fn shared_cache(&self) -> bool;
    /// Sends a partial this process holds to every other process.
    fn send(&self, msg: ShardMessage) -> Result<(), NodeError>;
    /// The next partial from another process for the node whose key is `node_key`; blocks
    /// until one arrives, the run is cancelled, or the peers are gone (an error).
    fn recv(&self, node_key: &Hash, cancel: &CancelToken) -> Result<ShardMessage, NodeError>;
}

/// Where a sharded node's chunks came from in one run (the report's `shards`).
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct ShardStats {
    /// All chunks of the node, and its work items.
    pub chunks: u64,
    pub items: u64,
    /// Chunks this process was to provide (all of them unless sharded across processes).
    pub here: u64,
    /// Of those, found in the cache and computed.
    pub cached: u64,
    pub ran: u64,
    /// Compute time of the chunks run here, in total and for the slowest one (ms).
    pub ran_ms: f64,
    pub max_chunk_ms: f64,
    /// What the chunks found in the cache took to compute where they ran (ms; recorded in
    /// their cache entries: a Slurm gather reports what its array tasks spent).
    pub cached_ms: f64,
    /// Chunks received from other processes, by process index: how many, of which cached
    /// there, and their compute time there (ms).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub received: BTreeMap<usize, PeerShards>,
    /// `Some((index, count))` for a `relume shard` run of one shard.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard: Option<(u64, u64)>,
}

impl ShardStats {
    /// One line for the run table: `shards 16 chunks: here 5 (4 cached (3.70 s when computed),
    /// 1 ran, 0.93 s); process 1: 5 (3 cached, 1.67 s)`.
    pub fn summary(&self) -> String {
        let mut s = match self.shard {
            Some((i, n)) => format!("shard {i} of {n}: {} of {} chunks (", self.here, self.chunks),
            None => format!("shards {} chunks: here {} (", self.chunks, self.here),
        };
        s.push_str(&format!(
            "{} cached ({:.2} s when computed), {} ran, {:.2} s)",
            self.cached,
            self.cached_ms / 1e3,
            self.ran,
            self.ran_ms / 1e3
        ));
        for (p, r) in &self.received {
            s.push_str(&format!("; process {p}: {} ({} cached, {:.2} s)", r.chunks, r.cached, r.ran_ms / 1e3));
        }
        s
    }
}

/// Chunks received from one peer process.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct PeerShards {
    pub chunks: u64,
    pub cached: u64,
    pub ran_ms: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_cover_the_items_once_and_shards_cover_the_chunks_once() {
        for (items, chunk) in [(0u64, 4u64), (1, 4), (10, 3), (12, 3), (1000, 7)] {
            let s = ShardSpec::new(items, chunk);
            let covered: Vec<u64> = (0..s.chunks()).flat_map(|k| s.chunk_items(k)).collect();
            assert_eq!(covered, (0..items).collect::<Vec<_>>());
            for count in 1..=6 {
                let chunks: Vec<u64> = (0..count).flat_map(|i| s.shard_chunks(i, count)).collect();
                assert_eq!(chunks, (0..s.chunks()).collect::<Vec<_>>(), "{items} {chunk} {count}");
                let sizes: Vec<u64> = (0..count).map(|i| s.shard_chunks(i, count).count() as u64).collect();
                assert!(sizes.iter().max().unwrap() - sizes.iter().min().unwrap() <= 1, "{sizes:?}");
            }
        }
    }

    #[test]
    fn partial_keys_differ_by_node_and_range() {
        let (a, b) = (Hash::of_bytes(b"a"), Hash::of_bytes(b"b"));
        assert_ne!(partial_key(&a, &(0..4)), partial_key(&b, &(0..4)));
        assert_ne!(partial_key(&a, &(0..4)), partial_key(&a, &(4..8)));
        assert_ne!(partial_key(&a, &(0..4)), partial_key(&a, &(0..5)));
        assert_eq!(partial_key(&a, &(0..4)), partial_key(&a, &(0..4)));
    }
}
