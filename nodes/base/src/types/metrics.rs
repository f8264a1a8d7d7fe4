//! `Metrics`: named quality figures (error against a reference and the like).

use relume_core::PortValue;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
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

/// Disk encoding: serde through postcard; the figures are a list in report order, so the
/// bytes are deterministic.
impl PortValue for Metrics {
    const NAME: &'static str = "Metrics";
    const COLOR: [u8; 3] = [120, 200, 120];
    const DOC: &'static str = "named quality figures";

    fn byte_size(&self) -> usize {
        self.0.iter().map(|(k, _)| k.len() + 8).sum()
    }
    relume_core::serde_codec!();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_through_the_disk_encoding() {
        let m = Metrics(vec![("mse".into(), 0.25), ("psnr_db".into(), f64::INFINITY)]);
        assert_eq!(Metrics::decode(&m.encode()).unwrap(), m);
        assert_eq!(m.encode(), m.clone().encode(), "deterministic");
        assert!(Metrics::decode(&m.encode()[..5]).is_none(), "truncated payload is refused");
        let nan = Metrics(vec![("x".into(), f64::NAN)]);
        assert!(Metrics::decode(&nan.encode()).unwrap().get("x").unwrap().is_nan());
        assert!(m.to_json().contains("null"), "infinite PSNR is written as null");
    }
}
