//! `Metrics`: named quality figures (error against a reference and the like).

use relume_core::{Hash, Hasher, PortValue};

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Metrics(pub Vec<(String, f64)>);

impl Metrics {
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| *v)
    }
    /// As a JSON object (non-finite values become null).
    pub fn to_json(&self) -> String {
        let map: serde_json::Map<String, serde_json::Value> = self.0.iter().map(|(k, v)| (k.clone(), serde_json::json!(v))).collect();
        serde_json::to_string_pretty(&map).expect("serialises")
    }
}

impl PortValue for Metrics {
    const NAME: &'static str = "Metrics";
    const COLOR: [u8; 3] = [120, 200, 120];
    const DOC: &'static str = "named quality figures";

    fn fingerprint(&self) -> Hash {
        let mut h = Hasher::new();
        h.str(Self::NAME).u64(self.0.len() as u64);
        for (k, v) in &self.0 {
            h.str(k).f64(*v);
        }
        h.finish()
    }
    fn byte_size(&self) -> usize {
        self.0.iter().map(|(k, _)| k.len() + 8).sum()
    }
    fn encode(&self) -> Option<Vec<u8>> {
        let mut b = Vec::new();
        for (k, v) in &self.0 {
            b.extend_from_slice(&(k.len() as u32).to_le_bytes());
            b.extend_from_slice(k.as_bytes());
            b.extend_from_slice(&v.to_bits().to_le_bytes());
        }
        Some(b)
    }
    fn decode(mut b: &[u8]) -> Option<Self> {
        let mut out = Vec::new();
        while !b.is_empty() {
            let n = u32::from_le_bytes(b.get(0..4)?.try_into().ok()?) as usize;
            let k = String::from_utf8(b.get(4..4 + n)?.to_vec()).ok()?;
            let v = f64::from_bits(u64::from_le_bytes(b.get(4 + n..12 + n)?.try_into().ok()?));
            out.push((k, v));
            b = &b[12 + n..];
        }
        Some(Metrics(out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_through_the_disk_encoding() {
        let m = Metrics(vec![("mse".into(), 0.25), ("psnr_db".into(), f64::INFINITY)]);
        assert_eq!(Metrics::decode(&m.encode().unwrap()).unwrap(), m);
        assert!(m.to_json().contains("null"), "infinite PSNR is written as null");
    }
}
