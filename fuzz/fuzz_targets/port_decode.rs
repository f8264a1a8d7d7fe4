//! Every port type's `decode`: the input is a port type's name, a line break and a payload.
//! Decoding must give a value or `None`, never a panic or an allocation past what the payload
//! can describe; a value it gives must encode to bytes that decode again to the same bytes
//! (the disk cache stores what `encode` gives and trusts `decode` to read it back).
#![no_main]

use libfuzzer_sys::fuzz_target;
use relume_core::{Hash, Registry};
use std::sync::OnceLock;

static REGISTRY: OnceLock<Registry> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let reg = REGISTRY.get_or_init(relume_cli::registry);
    let Some(split) = data.iter().position(|&b| b == b'\n') else { return };
    let Ok(name) = std::str::from_utf8(&data[..split]) else { return };
    let Some(info) = reg.port_type(name) else { return };
    let Some(v) = (info.decode)(&data[split + 1..], Hash::default()) else { return };
    let bytes = v.encode();
    let again = (info.decode)(&bytes, Hash::default()).expect("a value's own encoding decodes");
    assert_eq!(again.encode(), bytes, "{name}: encode ∘ decode is stable");
});
