//! The one way port values are written to bytes: serde through postcard (`serde_codec!`), with
//! flat arrays of plain words written as one byte string (`pod_vec`, `byte_vec`) so that a
//! large array costs a length and a copy, not one serde call per number.

pub mod byte_vec;
pub mod pod_vec;

/// Encodes a value (deterministic for types without hash maps).
pub fn to_bytes<T: serde::Serialize>(v: &T) -> Vec<u8> {
    postcard::to_stdvec(v).expect("port values serialise to memory")
}
/// The fingerprint `PortValue::fingerprint` gives by default — the hash of the type name
/// and the encoding — without building the encoding: one pass counts its bytes (the
/// hash takes the length first), a second streams them into the hasher. The same hash,
/// no copy of a large value into fresh memory.
pub fn fingerprint<T: serde::Serialize>(name: &str, v: &T) -> crate::hash::Hash {
    let len = postcard::serialize_with_flavor(v, Count(0)).expect("port values serialise");
    let mut h = crate::hash::Hasher::new();
    h.str(name).u64(len as u64);
    postcard::serialize_with_flavor(v, Stream(&mut h)).expect("port values serialise");
    h.finish()
}

/// Counts the bytes of an encoding.
struct Count(usize);

impl postcard::ser_flavors::Flavor for Count {
    type Output = usize;
    fn try_extend(&mut self, data: &[u8]) -> postcard::Result<()> {
        self.0 += data.len();
        Ok(())
    }
    fn try_push(&mut self, _: u8) -> postcard::Result<()> {
        self.0 += 1;
        Ok(())
    }
    fn finalize(self) -> postcard::Result<usize> {
        Ok(self.0)
    }
}

/// Feeds an encoding into a hasher as it is written.
struct Stream<'a>(&'a mut crate::hash::Hasher);

impl postcard::ser_flavors::Flavor for Stream<'_> {
    type Output = ();
    fn try_extend(&mut self, data: &[u8]) -> postcard::Result<()> {
        self.0.raw(data);
        Ok(())
    }
    fn try_push(&mut self, b: u8) -> postcard::Result<()> {
        self.0.raw(&[b]);
        Ok(())
    }
    fn finalize(self) -> postcard::Result<()> {
        Ok(())
    }
}

/// Decodes a value; `None` for malformed or trailing bytes.
pub fn from_bytes<T: serde::de::DeserializeOwned>(b: &[u8]) -> Option<T> {
    match postcard::take_from_bytes(b) {
        Ok((v, [])) => Some(v),
        _ => None,
    }
}
