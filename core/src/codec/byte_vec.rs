//! Serde of a `Vec<u8>` as one byte string (`#[serde(with = "relume_core::codec::byte_vec")]`):
//! through postcard the length and a copy, instead of one serde call per byte; a large
//! array lands on large pages (`memory::huge_pages`).

use serde::{de, Deserializer, Serializer};

pub fn serialize<S: Serializer>(v: &[u8], s: S) -> Result<S::Ok, S::Error> {
    s.serialize_bytes(v)
}

struct V;

impl de::Visitor<'_> for V {
    type Value = Vec<u8>;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "bytes")
    }
    fn visit_bytes<E: de::Error>(self, b: &[u8]) -> Result<Vec<u8>, E> {
        let mut v = Vec::with_capacity(b.len());
        crate::memory::huge_pages(&v);
        v.extend_from_slice(b);
        Ok(v)
    }
}

pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
    d.deserialize_bytes(V)
}
