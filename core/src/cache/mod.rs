//! Results of node runs, kept by cache key: in memory (LRU under a byte budget) and, for nodes
//! that opt in, on disk.

mod disk;
mod memory;

pub use disk::DiskCache;
pub use memory::MemoryCache;

use crate::port::Value;

/// Everything a node's run produced: outputs in declaration order, metrics and notes.
#[derive(Clone, Debug)]
pub struct CacheEntry {
    pub outputs: Vec<Value>,
    pub metrics: Vec<(String, f64)>,
    pub notes: Vec<String>,
}

impl CacheEntry {
    pub fn bytes(&self) -> usize {
        self.outputs.iter().map(Value::byte_size).sum()
    }
}
