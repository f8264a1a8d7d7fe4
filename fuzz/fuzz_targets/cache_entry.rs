//! The disk cache's entry decoder: the input is a node kind's name, a line break and the body
//! of an entry (what follows the magic and the key), written as the entry of a fixed key with a
//! correct checksum appended, so that the fuzzer reaches past the checksum into the header,
//! the metrics, notes and dependencies, and each port type's payload; then read back with that
//! kind's output ports, as a run does. Any input must give an entry or a miss, never a panic,
//! an allocation past the input's size or a hang.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relume_core::cache::DiskCache;
use relume_core::{Hash, Registry};
use std::sync::OnceLock;

/// The entry format's first bytes (`cache/disk.rs`).
const MAGIC: &[u8; 8] = b"RELUMEC3";

static STATE: OnceLock<(Registry, tempfile::TempDir, DiskCache)> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let (reg, _dir, cache) = STATE.get_or_init(|| {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let cache = DiskCache::new(dir.path());
        (relume_cli::registry(), dir, cache)
    });
    let Some(split) = data.iter().position(|&b| b == b'\n') else { return };
    let Ok(kind) = std::str::from_utf8(&data[..split]) else { return };
    let Some(node) = reg.node(kind) else { return };
    let key = Hash([7; 32]);
    let mut entry = MAGIC.to_vec();
    entry.extend_from_slice(&key.0);
    entry.extend_from_slice(&data[split + 1..]);
    let sum = Hash::of_bytes(&entry);
    entry.extend_from_slice(&sum.0);
    let path = cache.path_of(&key);
    std::fs::create_dir_all(path.parent().expect("a key folder")).expect("make the key folder");
    std::fs::write(&path, &entry).expect("write the entry");
    if let Some(e) = cache.get(&key, &node.ports().outputs, reg) {
        assert_eq!(e.outputs.len(), node.ports().outputs.len());
    }
});
