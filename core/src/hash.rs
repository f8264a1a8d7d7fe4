//! Content hashes and the canonical hasher used for cache keys and fingerprints (blake3).

use std::fmt;

/// A 256-bit blake3 hash: cache keys and output fingerprints.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct Hash(pub [u8; 32]);

impl Hash {
    /// Full lowercase hex.
    pub fn hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }
    /// First 12 hex digits, for tables and messages.
    pub fn short(&self) -> String {
        self.hex()[..12].to_string()
    }
    /// Hash of a byte slice.
    pub fn of_bytes(bytes: &[u8]) -> Hash {
        // blake3's tree hashing spreads a large input over the cores; the hash is the same.
        if bytes.len() >= 1 << 20 {
            let mut h = blake3::Hasher::new();
            h.update_rayon(bytes);
            return Hash(*h.finalize().as_bytes());
        }
        Hash(*blake3::hash(bytes).as_bytes())
    }
}

impl fmt::Debug for Hash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Hash({})", self.short())
    }
}

impl fmt::Display for Hash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.hex())
    }
}

/// Canonical, unambiguous hasher: every field is typed and length-prefixed, floats hash by bits.
pub struct Hasher(blake3::Hasher);

impl Default for Hasher {
    fn default() -> Self {
        Self::new()
    }
}

impl Hasher {
    pub fn new() -> Self {
        Hasher(blake3::Hasher::new())
    }
    pub fn tag(&mut self, t: u8) -> &mut Self {
        self.0.update(&[t]);
        self
    }
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.u64(s.len() as u64);
        self.0.update(s.as_bytes());
        self
    }
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u64(b.len() as u64);
        if b.len() >= 1 << 20 {
            self.0.update_rayon(b);
        } else {
            self.0.update(b);
        }
        self
    }
    /// Raw bytes without a length prefix (for streaming large payloads whose length was hashed).
    pub fn raw(&mut self, b: &[u8]) -> &mut Self {
        if b.len() >= 1 << 20 {
            self.0.update_rayon(b);
        } else {
            self.0.update(b);
        }
        self
    }
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.0.update(&v.to_le_bytes());
        self
    }
    pub fn i64(&mut self, v: i64) -> &mut Self {
        self.0.update(&v.to_le_bytes());
        self
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.0.update(&v.to_bits().to_le_bytes());
        self
    }
    pub fn f32s(&mut self, v: &[f32]) -> &mut Self {
        self.u64(v.len() as u64);
        let mut buf = Vec::with_capacity(4096);
        for chunk in v.chunks(1024) {
            buf.clear();
            for x in chunk {
                buf.extend_from_slice(&x.to_bits().to_le_bytes());
            }
            self.0.update(&buf);
        }
        self
    }
    pub fn hash(&mut self, h: &Hash) -> &mut Self {
        self.0.update(&h.0);
        self
    }
    pub fn finish(&self) -> Hash {
        Hash(*self.0.finalize().as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn length_prefixing_keeps_concatenations_apart() {
        let a = Hasher::new().str("ab").str("c").finish();
        let b = Hasher::new().str("a").str("bc").finish();
        assert_ne!(a, b);
    }

    #[test]
    fn floats_hash_by_bits_so_signed_zeros_differ() {
        let a = Hasher::new().f64(0.0).finish();
        let b = Hasher::new().f64(-0.0).finish();
        assert_ne!(a, b);
        assert_eq!(Hash::of_bytes(b"x").hex().len(), 64);
    }
}
