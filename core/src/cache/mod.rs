//! Results of node runs, kept by cache key: in memory (LRU under a byte budget) and on disk
//! when recomputing would cost more than loading (`worth_storing`).

mod disk;
mod lru;

pub use disk::DiskCache;
pub use lru::MemoryCache;

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
        self.deps.iter().all(|(path, h)| crate::content_hash(path).is_ok_and(|c| c == *h))
    }
}

/// Fixed cost of loading an entry from the disk cache (open, read, checksum), in ms.
pub const LOAD_FIXED_MS: f64 = 0.2;
/// Throughput of loading an entry (read, checksum, decode), in bytes per ms: 800 MB/s, the
/// slowest port type measured on the CI machine (a point tree of 200,000 nodes, 43 MB, loads
/// at 850–910 MB/s; images, points, receivers and radiance at 3–5 GB/s).
pub const LOAD_BYTES_PER_MS: f64 = 800_000.0;

/// What loading `bytes` of results from the disk cache costs, by the model above (ms).
pub fn load_cost_ms(bytes: usize) -> f64 {
    LOAD_FIXED_MS + bytes as f64 / LOAD_BYTES_PER_MS
}

/// The disk-caching rule: a result goes to disk when computing it took longer than loading it
/// would. Cheap nodes (a tone map, a sum of two images) are recomputed; expensive ones (a
/// path-traced image, a point tree, a gather) are loaded in a later process.
pub fn worth_storing(entry: &CacheEntry) -> bool {
    entry.compute_ms > load_cost_ms(entry.bytes())
}
