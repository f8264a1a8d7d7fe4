//! Results of node runs, kept by cache key: in memory (LRU under a byte budget) and, for nodes
//! that opt in, on disk.

mod disk;
mod memory;

pub use disk::DiskCache;
pub use memory::MemoryCache;

use crate::hash::Hash;
use crate::port::Value;
use std::path::PathBuf;

/// Everything a node's run produced: outputs in declaration order, metrics and notes.
#[derive(Clone, Debug)]
pub struct CacheEntry {
    pub outputs: Vec<Value>,
    pub metrics: Vec<(String, f64)>,
    pub notes: Vec<String>,
    /// Files the node read beyond its file parameters (an OBJ named inside a scene file),
    /// with their content hashes: the entry is valid only while they are unchanged.
    pub deps: Vec<(PathBuf, Hash)>,
    /// How long the node took when it ran (ms), kept so that a cached result still says what
    /// it cost (error-against-time sweeps count the whole pipeline).
    pub compute_ms: f64,
}

impl CacheEntry {
    pub fn bytes(&self) -> usize {
        self.outputs.iter().map(Value::byte_size).sum()
    }

    /// Whether every file dependency still has the recorded content.
    pub fn deps_unchanged(&self) -> bool {
        self.deps.iter().all(|(path, h)| std::fs::read(path).is_ok_and(|b| Hash::of_bytes(&b) == *h))
    }
}
