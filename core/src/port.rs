//! Typed ports: the `PortValue` trait a data type implements, the type-erased `Value` the
//! executor moves around, and the port declarations of a node.

use crate::hash::Hash;
use std::any::{Any, TypeId};
use std::sync::Arc;

/// A type that can flow along an edge. Registered by name; the editor colours ports with
/// `COLOR`; the cache identifies values by `fingerprint` and may store them on disk through
/// `encode`/`decode`.
pub trait PortValue: Any + Send + Sync + Sized {
    const NAME: &'static str;
    const COLOR: [u8; 3];
    /// One line for the catalogue.
    const DOC: &'static str = "";
    /// Hash of the content (or of something that identifies it, for very large values).
    fn fingerprint(&self) -> Hash;
    /// Bytes held in memory (for the cache budget and the report).
    fn byte_size(&self) -> usize;
    /// Disk encoding; `None` means the value is never written to the disk cache.
    fn encode(&self) -> Option<Vec<u8>> {
        None
    }
    fn decode(_bytes: &[u8]) -> Option<Self> {
        None
    }
}

type EncodeFn = fn(&(dyn Any + Send + Sync)) -> Option<Vec<u8>>;
type DecodeFn = fn(&[u8]) -> Option<Value>;

fn encode_erased<T: PortValue>(v: &(dyn Any + Send + Sync)) -> Option<Vec<u8>> {
    v.downcast_ref::<T>().and_then(T::encode)
}

fn decode_erased<T: PortValue>(bytes: &[u8]) -> Option<Value> {
    T::decode(bytes).map(Value::new)
}

/// A value on a port, shared cheaply, with its fingerprint computed once.
#[derive(Clone)]
pub struct Value {
    data: Arc<dyn Any + Send + Sync>,
    type_name: &'static str,
    type_id: TypeId,
    fingerprint: Hash,
    bytes: usize,
    encode: EncodeFn,
}

impl Value {
    pub fn new<T: PortValue>(v: T) -> Value {
        let fingerprint = v.fingerprint();
        let bytes = v.byte_size();
        Value { data: Arc::new(v), type_name: T::NAME, type_id: TypeId::of::<T>(), fingerprint, bytes, encode: encode_erased::<T> }
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
        self.fingerprint
    }
    pub fn byte_size(&self) -> usize {
        self.bytes
    }
    pub fn encode(&self) -> Option<Vec<u8>> {
        (self.encode)(self.data.as_ref())
    }
}

impl std::fmt::Debug for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Value({}, {:?}, {} B)", self.type_name, self.fingerprint, self.bytes)
    }
}

/// A registered port type.
#[derive(Clone, Debug)]
pub struct PortTypeInfo {
    pub name: &'static str,
    pub color: [u8; 3],
    pub doc: &'static str,
    pub type_id: TypeId,
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

/// The inputs and outputs of a node kind, in declaration order.
#[derive(Clone, Debug, Default)]
pub struct Ports {
    pub inputs: Vec<PortDecl>,
    pub outputs: Vec<PortDecl>,
}

impl Ports {
    pub fn new() -> Self {
        Ports::default()
    }
    pub fn input<T: PortValue>(mut self, name: &'static str) -> Self {
        self.inputs.push(PortDecl { name, ty: PortTypeInfo::of::<T>() });
        self
    }
    pub fn output<T: PortValue>(mut self, name: &'static str) -> Self {
        self.outputs.push(PortDecl { name, ty: PortTypeInfo::of::<T>() });
        self
    }
    pub fn find_input(&self, name: &str) -> Option<&PortDecl> {
        self.inputs.iter().find(|p| p.name == name)
    }
    pub fn find_output(&self, name: &str) -> Option<&PortDecl> {
        self.outputs.iter().find(|p| p.name == name)
    }
}
