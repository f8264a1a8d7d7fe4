//! In-memory LRU cache with a byte budget, and a bound on the results kept per node.

use super::CacheEntry;
use crate::hash::Hash;
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::Arc;

/// Results of one graph node kept at most (`put_for`): an edit makes a new result of every
/// node it reaches, and an orbit or a slider dragged through many values would otherwise
/// fill the budget with results no one asks for again. Freed as they go, their memory is
/// reused by the next edit's results instead of the kernel handing out (and zeroing) fresh
/// pages for every one until the budget is full.
pub const RESULTS_PER_NODE: usize = 8;

/// Results of one graph node kept whatever their size: the newest and the one before, so that
/// an edit undone or toggled finds both values.
pub const RESULTS_KEPT_WHATEVER_SIZE: usize = 2;

/// The share of the budget one node's results may hold beyond `RESULTS_KEPT_WHATEVER_SIZE`
/// (one part in this many): a node that writes tens of megabytes (a voxel volume, an octree,
/// a point tree) keeps its two latest results, so from the third edit on its memory is freed
/// and reused instead of taking fresh pages until `RESULTS_PER_NODE` results are held.
pub const NODE_BUDGET_SHARE: usize = 64;

pub struct MemoryCache {
    budget: usize,
    used: usize,
    tick: u64,
    map: HashMap<Hash, (Arc<CacheEntry>, u64)>,
    lru: BTreeMap<u64, Hash>,
    /// Per node, the keys of its results, oldest first.
    per_node: HashMap<String, VecDeque<Hash>>,
}

impl MemoryCache {
    pub fn new(budget_bytes: usize) -> Self {
        MemoryCache { budget: budget_bytes, used: 0, tick: 0, map: HashMap::new(), lru: BTreeMap::new(), per_node: HashMap::new() }
    }

    /// As `get`, for a result of graph node `node`: found, it counts as the node's newest.
    pub fn get_for(&mut self, node: &str, key: &Hash) -> Option<Arc<CacheEntry>> {
        let found = self.get(key)?;
        if let Some(keys) = self.per_node.get_mut(node) {
            if let Some(at) = keys.iter().position(|k| k == key) {
                keys.remove(at);
                keys.push_back(*key);
            }
        }
        Some(found)
    }

    /// As `put`, for a result of graph node `node`: its oldest results go while it has more
    /// than `RESULTS_PER_NODE`, or more than `RESULTS_KEPT_WHATEVER_SIZE` holding together
    /// over 1/`NODE_BUDGET_SHARE` of the budget (the same result twice counts once, as the
    /// newest).
    pub fn put_for(&mut self, node: &str, key: Hash, entry: Arc<CacheEntry>) {
        self.put(key, entry);
        let keys = self.per_node.entry(node.to_string()).or_default();
        keys.retain(|k| *k != key);
        keys.push_back(key);
        // Keys the budget evicted meanwhile are dropped here too.
        let map = &self.map;
        keys.retain(|k| map.contains_key(k));
        let share = self.budget / NODE_BUDGET_SHARE;
        let held =
            |keys: &VecDeque<Hash>, map: &HashMap<Hash, (Arc<CacheEntry>, u64)>| keys.iter().map(|k| map[k].0.bytes()).sum::<usize>();
        while keys.len() > RESULTS_PER_NODE || (keys.len() > RESULTS_KEPT_WHATEVER_SIZE && held(keys, &self.map) > share) {
            let old = keys.pop_front().expect("more than the bound");
            if let Some((e, t)) = self.map.remove(&old) {
                self.used -= e.bytes();
                self.lru.remove(&t);
            }
        }
    }

    pub fn get(&mut self, key: &Hash) -> Option<Arc<CacheEntry>> {
        self.tick += 1;
        let tick = self.tick;
        let (entry, t) = self.map.get_mut(key)?;
        self.lru.remove(t);
        *t = tick;
        self.lru.insert(tick, *key);
        Some(entry.clone())
    }

    /// Peeks without touching the LRU order.
    pub fn contains(&self, key: &Hash) -> Option<&Arc<CacheEntry>> {
        self.map.get(key).map(|(e, _)| e)
    }

    /// Inserts, evicting least recently used entries to stay under budget. An entry larger
    /// than the whole budget is not kept.
    pub fn put(&mut self, key: Hash, entry: Arc<CacheEntry>) {
        let size = entry.bytes();
        if size > self.budget {
            return;
        }
        self.remove(&key);
        while self.used + size > self.budget {
            let Some((_, victim)) = self.lru.pop_first() else { break };
            if let Some((e, _)) = self.map.remove(&victim) {
                self.used -= e.bytes();
            }
        }
        self.tick += 1;
        self.used += size;
        self.lru.insert(self.tick, key);
        self.map.insert(key, (entry, self.tick));
    }

    pub fn remove(&mut self, key: &Hash) {
        if let Some((e, t)) = self.map.remove(key) {
            self.used -= e.bytes();
            self.lru.remove(&t);
        }
    }

    pub fn clear(&mut self) {
        self.map.clear();
        self.lru.clear();
        self.per_node.clear();
        self.used = 0;
    }

    pub fn used_bytes(&self) -> usize {
        self.used
    }

    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::port::{PortValue, Value};

    struct Blob(Vec<u8>);
    impl PortValue for Blob {
        const NAME: &'static str = "Blob";
        const COLOR: [u8; 3] = [0, 0, 0];
        fn byte_size(&self) -> usize {
            self.0.len()
        }
        fn encode(&self) -> Vec<u8> {
            self.0.clone()
        }
        fn decode(b: &[u8]) -> Option<Self> {
            Some(Blob(b.to_vec()))
        }
    }

    fn entry(n: usize) -> Arc<CacheEntry> {
        Arc::new(CacheEntry { outputs: vec![Value::new(Blob(vec![0; n]))], metrics: vec![], notes: vec![], deps: vec![], compute_ms: 0.0 })
    }

    #[test]
    fn least_recently_used_entries_go_first_and_the_budget_holds() {
        let mut c = MemoryCache::new(100);
        let k = |i: u8| Hash([i; 32]);
        c.put(k(1), entry(40));
        c.put(k(2), entry(40));
        assert!(c.get(&k(1)).is_some()); // 2 is now the oldest
        c.put(k(3), entry(40));
        assert!(c.contains(&k(2)).is_none());
        assert!(c.contains(&k(1)).is_some() && c.contains(&k(3)).is_some());
        assert_eq!(c.used_bytes(), 80);
        c.put(k(4), entry(500));
        assert!(c.contains(&k(4)).is_none(), "larger than the budget: not kept");
    }

    #[test]
    fn a_node_keeps_its_latest_results_and_leaves_the_others_alone() {
        let mut c = MemoryCache::new(1 << 20);
        let k = |i: u8| Hash([i; 32]);
        c.put_for("other", k(200), entry(10));
        for i in 0..20 {
            c.put_for("camera", k(i), entry(10));
            // Asked for again, an early result counts as new.
            if i == 10 {
                c.put_for("camera", k(3), entry(10));
            }
        }
        let kept: Vec<u8> = (0..20).filter(|&i| c.contains(&k(i)).is_some()).collect();
        assert_eq!(kept, (12..20).collect::<Vec<u8>>());
        assert!(c.contains(&k(200)).is_some(), "another node's result stays");
        assert_eq!(c.used_bytes(), 10 * (RESULTS_PER_NODE + 1));
        assert_eq!(c.len(), RESULTS_PER_NODE + 1);
        c.put_for("tiny", k(201), entry(10));
        c.put_for("tiny", k(201), entry(10));
        assert_eq!(c.len(), RESULTS_PER_NODE + 2, "the same result twice is one");
    }

    #[test]
    fn a_node_of_large_results_keeps_its_latest_two() {
        let budget = 64 * 1000;
        let mut c = MemoryCache::new(budget);
        let k = |i: u8| Hash([i; 32]);
        // 400 bytes a result: the node's share (1,000 bytes) holds two and a half of them.
        for i in 0..6 {
            c.put_for("volume", k(i), entry(400));
        }
        let kept: Vec<u8> = (0..6).filter(|&i| c.contains(&k(i)).is_some()).collect();
        assert_eq!(kept, vec![4, 5], "the newest two, though over the node's share together");
        // Small results fill up to the count bound as before.
        for i in 10..30 {
            c.put_for("camera", k(i), entry(100));
        }
        assert_eq!((10..30).filter(|&i| c.contains(&k(i)).is_some()).count(), 8.min(budget / NODE_BUDGET_SHARE / 100));
        // Two results larger than the share each are both kept.
        c.put_for("octree", k(40), entry(3000));
        c.put_for("octree", k(41), entry(3000));
        assert!(c.contains(&k(40)).is_some() && c.contains(&k(41)).is_some());
        c.put_for("octree", k(42), entry(3000));
        assert!(c.contains(&k(40)).is_none() && c.contains(&k(42)).is_some());
        assert_eq!(c.used_bytes(), 2 * 400 + 8 * 100 + 2 * 3000);
    }
}
