//! How the engine runs a sharded node: this process's chunks (each looked up in the disk
//! cache by its partial key, else computed and stored), the other chunks from peer processes
//! when there are any, then the gather in chunk order.

use super::{partial_key, DynSharded, ShardMessage, ShardMode, ShardPayload, ShardStats};
use crate::cache::CacheEntry;
use crate::ctx::RunCtx;
use crate::error::NodeError;
use crate::exec::{DiskPolicy, Engine};
use crate::hash::{Hash, Hasher};
use crate::params::ParamValues;
use crate::port::Value;
use std::time::Instant;

/// What running a sharded node gave: its outputs (none for a `ShardMode::One` run of this
/// node, which gathers nothing) and where its chunks came from.
pub(crate) struct ShardedRun {
    pub outputs: Option<Vec<Value>>,
    pub stats: ShardStats,
}

impl Engine {
    /// Runs the sharded node `id` (key `key`) under `mode`; see the module doc.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run_sharded(
        &self,
        sh: &dyn DynSharded,
        id: &str,
        params: &ParamValues,
        key: Hash,
        inputs: &[Value],
        cx: &RunCtx,
        mode: ShardMode,
    ) -> Result<ShardedRun, NodeError> {
        let spec = sh.spec(params, inputs)?;
        let n = spec.chunks();
        let (mine, one_shard, peers) = match mode {
            ShardMode::One { node, index, count } if node == id => (spec.shard_chunks(index, count), Some((index, count)), None),
            ShardMode::Peers(p) => (spec.shard_chunks(p.process() as u64, p.processes() as u64), None, Some(p)),
            _ => (0..n, None, None),
        };
        // A shard run and a multi-process run keep every chunk on disk (that is how the gather
        // or a re-run finds them); a normal run by the disk rule.
        let keep_all = mode_keeps_all(&mode) || self.disk_policy() == DiskPolicy::Always;
        let decl = [sh.partial_decl()];
        let mut stats = ShardStats { chunks: n, items: spec.items, here: mine.end - mine.start, shard: one_shard, ..Default::default() };
        let mut parts: Vec<Option<Value>> = vec![None; n as usize];
        let total = (mine.end - mine.start).max(1) as f64;
        for (done, k) in mine.clone().enumerate() {
            cx.check()?;
            let items = spec.chunk_items(k);
            let pk = partial_key(&key, &items);
            let (value, cached, ms) = match self.disk().and_then(|d| d.get(&pk, &decl, self.registry())) {
                Some(mut e) => (e.outputs.remove(0), true, e.compute_ms),
                None => {
                    cx.set_outer(done as f64 / total, (done + 1) as f64 / total);
                    cx.set_chunk(Some((items.clone(), spec.items)));
                    let t0 = Instant::now();
                    let v = sh.run_items(params, inputs, items.clone(), cx);
                    cx.set_chunk(None);
                    let v = v?;
                    let ms = t0.elapsed().as_secs_f64() * 1e3;
                    let entry =
                        CacheEntry { outputs: vec![v.clone()], metrics: Vec::new(), notes: Vec::new(), deps: Vec::new(), compute_ms: ms };
                    if let Some(d) = self.disk().filter(|_| !cx.memory_only() && (keep_all || crate::cache::worth_storing(&entry))) {
                        // A failed write only costs a recomputation later.
                        let _ = d.put(&pk, &entry, &decl);
                    }
                    (stats.ran, stats.ran_ms, stats.max_chunk_ms) = (stats.ran + 1, stats.ran_ms + ms, stats.max_chunk_ms.max(ms));
                    (v, false, ms)
                }
            };
            if cached {
                (stats.cached, stats.cached_ms) = (stats.cached + 1, stats.cached_ms + ms);
            }
            if cx.wants_partials() {
                cx.set_chunk(Some((items.clone(), spec.items)));
                cx.partial(value.clone());
                cx.set_chunk(None);
            }
            if let Some(p) = peers {
                let payload =
                    if p.shared_cache() && self.disk().is_some() { ShardPayload::Key(pk) } else { ShardPayload::Bytes(value.encode()) };
                p.send(ShardMessage { node_key: key, chunk: k, from: p.process(), cached, ms, payload })?;
            }
            parts[k as usize] = Some(value);
        }
        cx.set_outer(1.0, 1.0);
        if one_shard.is_some() {
            return Ok(ShardedRun { outputs: None, stats });
        }
        if let Some(p) = peers {
            let mut missing = parts.iter().filter(|v| v.is_none()).count();
            while missing > 0 {
                let msg = p.recv(&key, cx.cancel)?;
                let k = msg.chunk as usize;
                if k >= parts.len() || parts[k].is_some() {
                    continue;
                }
                parts[k] = Some(self.received(sh, &key, &spec.chunk_items(msg.chunk), &msg)?);
                let peer = stats.received.entry(msg.from).or_default();
                peer.chunks += 1;
                if msg.cached {
                    peer.cached += 1;
                } else {
                    peer.ran_ms += msg.ms;
                }
                missing -= 1;
            }
        }
        let parts: Vec<Value> = parts.into_iter().map(|v| v.expect("every chunk is here")).collect();
        Ok(ShardedRun { outputs: Some(sh.gather(params, inputs, &parts, cx)?), stats })
    }

    /// The partial a peer sent: loaded from the shared cache by key, or decoded (and kept in
    /// this process's cache, so that a re-run here need not wait for it again).
    fn received(&self, sh: &dyn DynSharded, key: &Hash, items: &std::ops::Range<u64>, msg: &ShardMessage) -> Result<Value, NodeError> {
        let decl = [sh.partial_decl()];
        let pk = partial_key(key, items);
        let from = msg.from;
        match &msg.payload {
            ShardPayload::Key(k) => {
                let found = (*k == pk).then(|| self.disk().and_then(|d| d.get(&pk, &decl, self.registry()))).flatten();
                found.map(|mut e| e.outputs.remove(0)).ok_or_else(|| {
                    let dir = self.disk().map(|d| d.dir().display().to_string()).unwrap_or_default();
                    NodeError::failed(format!(
                        "process {from} wrote chunk {} to the shared cache, but it is not in {dir}: is the cache folder really shared by every process? (run without --shared-cache to send results over the network)",
                        msg.chunk
                    ))
                })
            }
            ShardPayload::Bytes(b) => {
                let fp = Hasher::new().str(decl[0].ty.name).bytes(b).finish();
                let v = (decl[0].ty.decode)(b, fp).ok_or_else(|| {
                    NodeError::failed(format!("process {from} sent chunk {} in a form this build cannot read", msg.chunk))
                })?;
                if let Some(d) = self.disk() {
                    let entry = CacheEntry {
                        outputs: vec![v.clone()],
                        metrics: Vec::new(),
                        notes: Vec::new(),
                        deps: Vec::new(),
                        compute_ms: msg.ms,
                    };
                    let _ = d.put(&pk, &entry, &decl);
                }
                Ok(v)
            }
        }
    }
}

fn mode_keeps_all(mode: &ShardMode) -> bool {
    !matches!(mode, ShardMode::All)
}
