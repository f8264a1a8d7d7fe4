//! Typed ports: the `PortValue` trait a data type implements, the type-erased `Value` the
//! executor moves around, and the port declarations of a node (`inputs!` / `outputs!`).

use crate::error::NodeError;
use crate::hash::{Hash, Hasher};
use std::any::{Any, TypeId};
use std::sync::{Arc, OnceLock};

/// A type that can flow along an edge. Registered by name; the editor colours ports with
/// `COLOR`. Every port type has a disk encoding (`encode` / `decode`: serde through postcard
/// with [`serde_codec!`](crate::serde_codec), or `bytemuck` for flat arrays), so any node may
/// be disk-cached; its fingerprint is by default the hash of that encoding, i.e. of everything
/// that identifies its content.
pub trait PortValue: Any + Send + Sync + Sized {
    const NAME: &'static str;
    const COLOR: [u8; 3];
    /// One line for the catalogue.
    const DOC: &'static str = "";
    /// Bytes held in memory (for the cache budget and the report).
    fn byte_size(&self) -> usize;
    /// The disk encoding: deterministic (same value, same bytes).
    fn encode(&self) -> Vec<u8>;
    /// The inverse of `encode`; `None` for bytes it did not write (never a panic).
    fn decode(bytes: &[u8]) -> Option<Self>;
    /// The size the memory model sees (`memory.rs`): bytes, and pixel dimensions where the
    /// value has them (an image; a scene's camera).
    fn size(&self) -> crate::memory::PortSize {
        crate::memory::PortSize::bytes(self.byte_size() as u64)
    }
    /// Hash of the content: by default of the type name and the encoding.
    fn fingerprint(&self) -> Hash {
        Hasher::new().str(Self::NAME).bytes(&self.encode()).finish()
    }
}

/// Implements `PortValue::encode` / `decode` with serde through postcard, inside an
/// `impl PortValue for T` block of a type that derives `Serialize` and `Deserialize`.
#[macro_export]
macro_rules! serde_codec {
    () => {
        fn encode(&self) -> Vec<u8> {
            $crate::codec::to_bytes(self)
        }
        fn decode(bytes: &[u8]) -> Option<Self> {
            $crate::codec::from_bytes(bytes)
        }
        fn fingerprint(&self) -> $crate::Hash {
            $crate::codec::fingerprint(Self::NAME, self)
        }
    };
    // Decoding keeps only values that pass `$check` (`fn(&Self) -> bool`): a loader that
    // never hands on an inconsistent value.
    (check $check:path) => {
        $crate::serde_codec!(check $check, own fingerprint);
        fn fingerprint(&self) -> $crate::Hash {
            $crate::codec::fingerprint(Self::NAME, self)
        }
    };
    // As `check`, for a type that computes its fingerprint its own way (faster than hashing
    // the encoding, e.g. straight from a flat array); the impl block then writes it.
    (check $check:path, own fingerprint) => {
        fn encode(&self) -> Vec<u8> {
            $crate::codec::to_bytes(self)
        }
        fn decode(bytes: &[u8]) -> Option<Self> {
            $crate::codec::from_bytes::<Self>(bytes).filter($check)
        }
    };
}

type EncodeFn = fn(&(dyn Any + Send + Sync)) -> Vec<u8>;
type DecodeFn = fn(&[u8], Hash) -> Option<Value>;

fn encode_erased<T: PortValue>(v: &(dyn Any + Send + Sync)) -> Vec<u8> {
    v.downcast_ref::<T>().expect("a Value holds its declared type").encode()
}

fn decode_erased<T: PortValue>(bytes: &[u8], fingerprint: Hash) -> Option<Value> {
    T::decode(bytes).map(|v| Value::with_fingerprint(v, fingerprint))
}

type HashFn = fn(&(dyn Any + Send + Sync)) -> Hash;

fn hash_erased<T: PortValue>(v: &(dyn Any + Send + Sync)) -> Hash {
    v.downcast_ref::<T>().expect("a Value holds its declared type").fingerprint()
}

/// A value on a port, shared cheaply, with its fingerprint computed once: the hash of its
/// content, or (for the outputs of a `Caching::Keyed` node, set by the executor) of the key
/// of the run that made it.
#[derive(Clone)]
pub struct Value {
    data: Arc<dyn Any + Send + Sync>,
    type_name: &'static str,
    type_id: TypeId,
    fingerprint: OnceLock<Hash>,
    bytes: usize,
    size: crate::memory::PortSize,
    encode: EncodeFn,
    hash: HashFn,
}

impl Value {
    pub fn new<T: PortValue>(v: T) -> Value {
        let fp = v.fingerprint();
        Value::with_fingerprint(v, fp)
    }
    /// A value whose fingerprint is already known (read back from the disk cache, where the
    /// entry's checksum vouches for it).
    fn with_fingerprint<T: PortValue>(v: T, fingerprint: Hash) -> Value {
        let v = Value::unhashed(v);
        v.fingerprint.set(fingerprint).expect("a fresh value has no fingerprint yet");
        v
    }
    /// A node's output as `outputs!` hands it to the executor: its fingerprint is computed
    /// when first asked for, unless the executor gives it the run's key first.
    #[doc(hidden)]
    pub fn unhashed<T: PortValue>(v: T) -> Value {
        let (bytes, size) = (v.byte_size(), v.size());
        Value {
            data: Arc::new(v),
            type_name: T::NAME,
            type_id: TypeId::of::<T>(),
            fingerprint: OnceLock::new(),
            bytes,
            size,
            encode: encode_erased::<T>,
            hash: hash_erased::<T>,
        }
    }
    /// Fingerprints output `port` of a run by the run's cache `key` instead of its content
    /// (a node's output is a function of its key: same key, same bytes). No effect on a
    /// value already fingerprinted.
    pub(crate) fn fingerprint_by_key(&self, key: &Hash, port: usize) {
        let _ = self.fingerprint.set(Hasher::new().str("output of run").str(self.type_name).hash(key).u64(port as u64).finish());
    }
    pub fn get<T: PortValue>(&self) -> Option<&T> {
        self.data.downcast_ref::<T>()
    }
    pub fn type_name(&self) -> &'static str {
        self.type_name
    }
    pub fn type_id(&self) -> TypeId {
        self.type_id
    }
    pub fn fingerprint(&self) -> Hash {
        *self.fingerprint.get_or_init(|| (self.hash)(self.data.as_ref()))
    }
    pub fn byte_size(&self) -> usize {
        self.bytes
    }
    pub fn size(&self) -> crate::memory::PortSize {
        self.size
    }
    pub fn encode(&self) -> Vec<u8> {
        (self.encode)(self.data.as_ref())
    }
}

impl std::fmt::Debug for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Value({}, {:?}, {} B)", self.type_name, self.fingerprint(), self.bytes)
    }
}

/// A registered port type.
#[derive(Clone, Debug)]
pub struct PortTypeInfo {
    pub name: &'static str,
    pub color: [u8; 3],
    pub doc: &'static str,
    pub type_id: TypeId,
    /// Decodes a disk payload into a `Value` carrying the given fingerprint.
    pub decode: DecodeFn,
}

impl PortTypeInfo {
    pub fn of<T: PortValue>() -> Self {
        PortTypeInfo { name: T::NAME, color: T::COLOR, doc: T::DOC, type_id: TypeId::of::<T>(), decode: decode_erased::<T> }
    }
}

/// One declared input or output.
#[derive(Clone, Debug)]
pub struct PortDecl {
    pub name: &'static str,
    pub ty: PortTypeInfo,
}

impl PortDecl {
    pub fn of<T: PortValue>(name: &'static str) -> Self {
        PortDecl { name, ty: PortTypeInfo::of::<T>() }
    }
}

/// The inputs and outputs of a node kind, in declaration order.
#[derive(Clone, Debug, Default)]
pub struct Ports {
    pub inputs: Vec<PortDecl>,
    pub outputs: Vec<PortDecl>,
}

impl Ports {
    pub fn find_input(&self, name: &str) -> Option<&PortDecl> {
        self.inputs.iter().find(|p| p.name == name)
    }
    pub fn find_output(&self, name: &str) -> Option<&PortDecl> {
        self.outputs.iter().find(|p| p.name == name)
    }
}

/// A node's inputs as one typed struct borrowing the values (declared with [`inputs!`](crate::inputs!)).
pub trait InputPorts<'a>: Sized {
    fn decls() -> Vec<PortDecl>;
    /// `values` in declaration order.
    fn from_values(values: &'a [Value]) -> Result<Self, NodeError>;
}

/// A node's outputs as one typed struct (declared with [`outputs!`](crate::outputs!)).
pub trait OutputPorts: Sized {
    fn decls() -> Vec<PortDecl>;
    /// The values in declaration order.
    fn into_values(self) -> Vec<Value>;
}

impl InputPorts<'_> for () {
    fn decls() -> Vec<PortDecl> {
        Vec::new()
    }
    fn from_values(_: &[Value]) -> Result<Self, NodeError> {
        Ok(())
    }
}

/// The value at `values[i]` as `T` (used by `inputs!`).
pub fn input_at<'a, T: PortValue>(values: &'a [Value], i: usize, name: &str) -> Result<&'a T, NodeError> {
    let v = values.get(i).ok_or_else(|| NodeError::input(name, "not given"))?;
    v.get::<T>().ok_or_else(|| NodeError::input(name, format!("holds {}, not {}", v.type_name(), T::NAME)))
}

/// Declares a node's input ports as a struct of references, each port named once:
/// `inputs!(pub BlurIn { /// the image to blur
/// image: Image });` gives `BlurIn<'a> { pub image: &'a Image }`.
#[macro_export]
macro_rules! inputs {
    ($(#[$sm:meta])* $vis:vis $name:ident { $($(#[$m:meta])* $port:ident : $ty:ty),+ $(,)? }) => {
        $(#[$sm])*
        $vis struct $name<'a> { $($(#[$m])* pub $port: &'a $ty,)+ }
        impl<'a> $crate::InputPorts<'a> for $name<'a> {
            fn decls() -> Vec<$crate::PortDecl> {
                vec![$($crate::PortDecl::of::<$ty>(stringify!($port))),+]
            }
            fn from_values(values: &'a [$crate::Value]) -> Result<Self, $crate::NodeError> {
                let mut i = 0usize;
                Ok($name { $($port: { i += 1; $crate::input_at::<$ty>(values, i - 1, stringify!($port))? },)+ })
            }
        }
    };
}

/// Declares a node's output ports as a struct of owned values, each port named once:
/// `outputs!(pub BlurOut { image: Image });`.
#[macro_export]
macro_rules! outputs {
    ($(#[$sm:meta])* $vis:vis $name:ident { $($(#[$m:meta])* $port:ident : $ty:ty),+ $(,)? }) => {
        $(#[$sm])*
        $vis struct $name { $($(#[$m])* pub $port: $ty,)+ }
        impl $crate::OutputPorts for $name {
            fn decls() -> Vec<$crate::PortDecl> {
                vec![$($crate::PortDecl::of::<$ty>(stringify!($port))),+]
            }
            fn into_values(self) -> Vec<$crate::Value> {
                vec![$($crate::Value::unhashed(self.$port)),+]
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::{Deserialize, Serialize};

    #[derive(Serialize, Deserialize)]
    struct Sample {
        name: String,
        big: Vec<u8>,
        small: Vec<f32>,
    }

    impl PortValue for Sample {
        const NAME: &'static str = "Sample";
        const COLOR: [u8; 3] = [0, 0, 0];
        fn byte_size(&self) -> usize {
            self.big.len() + self.small.len() * 4
        }
        crate::serde_codec!();
    }

    #[test]
    fn the_streamed_fingerprint_is_the_hash_of_the_encoding() {
        // Small and large (the hasher goes parallel from 1 MiB) payloads.
        for n in [0usize, 7, 3 << 20] {
            let v = Sample { name: "x".repeat(n % 5), big: (0..n).map(|k| (k * 31 % 251) as u8).collect(), small: vec![1.5, -0.0] };
            let want = Hasher::new().str(Sample::NAME).bytes(&v.encode()).finish();
            assert_eq!(v.fingerprint(), want, "{n} bytes");
        }
    }
}
