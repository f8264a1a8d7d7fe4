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

impl NodeReport {
    /// A node's line with only its times: the rest empty (tools that price runs, and tests).
    pub fn timed(id: &str, status: &'static str, wall_ms: f64, compute_ms: f64) -> NodeReport {
        NodeReport {
            id: id.into(),
            kind: String::new(),
            status,
            cache: None,
            wall_ms,
            compute_ms,
            bytes: 0,
            key: String::new(),
            metrics: BTreeMap::new(),
            notes: Vec::new(),
            shards: None,
        }
    }
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

/// Peak resident set size (None where unavailable): the kernel's high-water mark, VmHWM
/// of /proc/self/status, read through a handle opened once into a buffer on the stack (an
/// interactive edit pays for this on every run: opening the file and reading it into a
/// string took 72 µs of a 7 ms orbit). `getrusage`'s `ru_maxrss`, one system call, is not
/// the same figure: it keeps the peak of whatever process exec'd this one (116 MB under
/// `cargo test` against a VmHWM of 71 MB).
pub fn peak_rss_bytes() -> Option<u64> {
    static STATUS: std::sync::OnceLock<Option<std::fs::File>> = std::sync::OnceLock::new();
    let file = STATUS.get_or_init(|| std::fs::File::open("/proc/self/status").ok()).as_ref()?;
    let mut buf = [0u8; 4096];
    let n = read_at_start(file, &mut buf)?;
    vm_hwm(std::str::from_utf8(&buf[..n]).ok()?)
}

/// Reads `file` from its start into `buf` in one call (the kernel writes a /proc file's text
/// anew for every read; the line sought lies in its first kilobyte): the bytes read.
#[cfg(unix)]
fn read_at_start(file: &std::fs::File, buf: &mut [u8]) -> Option<usize> {
    use std::os::unix::fs::FileExt;
    file.read_at(buf, 0).ok()
}

#[cfg(not(unix))]
fn read_at_start(_: &std::fs::File, _: &mut [u8]) -> Option<usize> {
    None
}

/// The VmHWM line of a /proc status text, in bytes.
fn vm_hwm(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
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
        // Between two plain reads of the high-water mark (which only grows, whatever the
        // other tests' threads allocate meanwhile), read through the kept handle twice.
        let plain = || vm_hwm(&std::fs::read_to_string("/proc/self/status").unwrap()).unwrap();
        let before = plain();
        let (first, second) = (peak_rss_bytes().expect("/proc answers on Linux"), peak_rss_bytes().unwrap());
        let after = plain();
        assert!(before >= 64 << 20, "{before}");
        assert!(before <= first && first <= second && second <= after, "{before} ≤ {first} ≤ {second} ≤ {after}");
    }

    #[test]
    fn the_high_water_line_is_read_in_kilobytes_and_its_absence_is_none() {
        assert_eq!(vm_hwm("Name:\trelume\nVmPeak:\t  999 kB\nVmHWM:\t    1234 kB\nVmRSS:\t 1 kB\n"), Some(1234 * 1024));
        assert_eq!(vm_hwm("Name:\trelume\n"), None);
        assert_eq!(vm_hwm("VmHWM:\t lots kB\n"), None);
    }
}
