//! Canonical RON text of a graph and atomic saving (write a temporary file, then rename).

use super::{Graph, FORMAT_VERSION};
use crate::ron::{write_f64, write_str};
use std::io::Write;
use std::path::Path;

impl Graph {
    /// The canonical text: a file written by this function reads back and writes out
    /// byte-identical.
    pub fn to_ron(&self) -> String {
        let mut s = String::new();
        s.push_str("Graph(\n");
        s.push_str(&format!("    version: {FORMAT_VERSION},\n"));
        s.push_str("    nodes: {");
        for n in &self.nodes {
            s.push_str("\n        ");
            write_str(&mut s, &n.id);
            s.push_str(": (kind: ");
            write_str(&mut s, &n.kind);
            s.push_str(", params: (");
            for (i, (name, v)) in n.params.iter().enumerate() {
                if i > 0 {
                    s.push_str(", ");
                }
                s.push_str(name);
                s.push_str(": ");
                v.write(&mut s);
            }
            s.push_str(")),");
        }
        s.push_str(if self.nodes.is_empty() { "},\n" } else { "\n    },\n" });
        s.push_str("    edges: [");
        for e in &self.edges {
            s.push_str("\n        (");
            write_str(&mut s, &e.from.to_string());
            s.push_str(", ");
            write_str(&mut s, &e.to.to_string());
            s.push_str("),");
        }
        s.push_str(if self.edges.is_empty() { "],\n" } else { "\n    ],\n" });
        s.push_str("    outputs: {");
        for o in &self.outputs {
            s.push_str("\n        ");
            write_str(&mut s, &o.name);
            s.push_str(": ");
            write_str(&mut s, &o.port.to_string());
            s.push(',');
        }
        s.push_str(if self.outputs.is_empty() { "},\n" } else { "\n    },\n" });
        s.push_str("    editor: (positions: {");
        for (id, [x, y]) in &self.editor.positions {
            s.push_str("\n        ");
            write_str(&mut s, id);
            s.push_str(": (");
            write_f64(&mut s, *x);
            s.push_str(", ");
            write_f64(&mut s, *y);
            s.push_str("),");
        }
        s.push_str(if self.editor.positions.is_empty() { "}),\n" } else { "\n    }),\n" });
        s.push_str(")\n");
        s
    }

    /// Saves atomically: the old file is replaced only once the new one is fully written.
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        write_atomic(path, self.to_ron().as_bytes())
    }
}

/// Writes `bytes` to a temporary file beside `path`, syncs it and renames it over `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.{}.tmp", std::process::id(), unique()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

fn unique() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.subsec_nanos() as u64).unwrap_or(0);
    (COUNTER.fetch_add(1, Ordering::Relaxed) << 32) ^ nanos
}
