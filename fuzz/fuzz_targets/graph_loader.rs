//! The graph loader: RON text → `Graph::parse` → `validate` against every registered node
//! kind, as `relume check` does. Any input must give `Ok` or an error message, never a panic,
//! a stack overflow or a hang.
#![no_main]

use libfuzzer_sys::fuzz_target;
use relume_core::{Graph, Registry};
use std::path::Path;
use std::sync::OnceLock;

static REGISTRY: OnceLock<Registry> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let reg = REGISTRY.get_or_init(relume_cli::registry);
    let result = Graph::parse(text, Some(Path::new("fuzz.ron"))).and_then(|g| g.validate(reg));
    if let Err(e) = result {
        // Rendering the message is part of loading: it must not panic either.
        let _ = e.to_string();
    }
});
