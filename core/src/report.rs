//! The run report: per node time, cache status, bytes and metrics; written as JSON.

use serde::Serialize;
use std::collections::BTreeMap;

#[derive(Clone, Debug, Serialize)]
pub struct NodeReport {
    pub id: String,
    pub kind: String,
    /// "ran" or "cached".
    pub status: &'static str,
    /// "memory" or "disk" for cached nodes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cache: Option<&'static str>,
    /// Time spent on this node in this run (cache lookup for cached nodes).
    pub wall_ms: f64,
    /// Time the node took when it last ran (its own cost, cached or not).
    pub compute_ms: f64,
    /// Bytes of the node's outputs.
    pub bytes: usize,
    /// Cache key (hex).
    pub key: String,
    /// Quality figures the node reported (non-finite values are written as null).
    pub metrics: BTreeMap<String, f64>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// For a sharded node that ran: where its chunks came from (cache, here, other processes).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shards: Option<crate::shard::ShardStats>,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct RunReport {
    pub graph: String,
    pub total_ms: f64,
    /// Needed nodes in the order they completed.
    pub nodes: Vec<NodeReport>,
    pub ran: usize,
    pub cached: usize,
    /// Outputs delivered.
    pub outputs: Vec<String>,
    /// Bytes held by the memory cache after the run.
    pub memory_cache_bytes: usize,
    /// Peak resident memory of the process so far (Linux), in bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_rss_bytes: Option<u64>,
    /// Sentences about the run as a whole (a disk cache that cannot be written, …).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl RunReport {
    pub fn node(&self, id: &str) -> Option<&NodeReport> {
        self.nodes.iter().find(|n| n.id == id)
    }

    /// Ids of the nodes that ran (not cached), sorted.
    pub fn ran_ids(&self) -> Vec<&str> {
        let mut v: Vec<&str> = self.nodes.iter().filter(|n| n.status == "ran").map(|n| n.id.as_str()).collect();
        v.sort_unstable();
        v
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("report serialises")
    }

    /// A plain-text table for the terminal.
    pub fn table(&self) -> String {
        let mut s = format!("{:<20} {:<16} {:<7} {:>10} {:>12}  metrics\n", "node", "kind", "status", "ms", "bytes");
        for n in &self.nodes {
            let metrics: Vec<String> = n.metrics.iter().map(|(k, v)| format!("{k}={v:.6}")).collect();
            s.push_str(&format!(
                "{:<20} {:<16} {:<7} {:>10.2} {:>12}  {}\n",
                n.id,
                n.kind,
                n.status,
                n.wall_ms,
                n.bytes,
                metrics.join(" ")
            ));
            if let Some(sh) = &n.shards {
                s.push_str(&format!("{:<20} {}\n", "", sh.summary()));
            }
        }
        s.push_str(&format!("total {:.2} ms: {} ran, {} cached\n", self.total_ms, self.ran, self.cached));
        s
    }
}

/// Peak resident set size (None where unavailable), from `getrusage`: one system call,
/// where reading /proc/self/status (the same figure, VmHWM) took 72 µs of a 7 ms
/// interactive edit.
#[cfg(unix)]
pub fn peak_rss_bytes() -> Option<u64> {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: getrusage writes a `rusage` into the pointer it is given, which points to
    // one; it reads nothing from it.
    let usage = unsafe {
        if libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr()) != 0 {
            return None;
        }
        usage.assume_init()
    };
    // Kilobytes on Linux, bytes on macOS.
    let unit = if cfg!(target_os = "macos") { 1 } else { 1024 };
    u64::try_from(usage.ru_maxrss).ok().map(|v| v * unit)
}

#[cfg(not(unix))]
pub fn peak_rss_bytes() -> Option<u64> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(target_os = "linux")]
    #[test]
    fn the_peak_resident_size_is_the_kernels_high_water_mark() {
        // 64 MiB touched: the peak holds it.
        let big = vec![1u8; 64 << 20];
        assert_eq!(big.iter().step_by(4096).map(|&b| b as usize).sum::<usize>(), (64 << 20) / 4096);
        let peak = peak_rss_bytes().expect("getrusage answers on Linux");
        assert!(peak >= 64 << 20, "{peak}");
        // The same figure /proc gives (VmHWM), up to what this thread does in between.
        let status = std::fs::read_to_string("/proc/self/status").unwrap();
        let kb: u64 = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap().split_whitespace().nth(1).unwrap().parse().unwrap();
        assert!((kb * 1024).abs_diff(peak) < 8 << 20, "{peak} against VmHWM {kb} kB");
    }
}
