//! Serde of a `Vec` of plain 4-byte words (`f32`, `u32`, `Vec3`, `[u32; 3]`, …) as one byte
//! string, little-endian: `#[serde(with = "relume_core::codec::pod_vec")]`. Through postcard that is the
//! length and a copy of the array, instead of one serde call per number.

use bytemuck::Pod;
use serde::{de, Deserializer, Serializer};
use std::borrow::Cow;
use std::marker::PhantomData;

/// The words of `v` as little-endian bytes (a view on little-endian machines).
fn le_bytes<T: Pod>(v: &[T]) -> Cow<'_, [u8]> {
    debug_assert_eq!(std::mem::size_of::<T>() % 4, 0);
    let b: &[u8] = bytemuck::cast_slice(v);
    if cfg!(target_endian = "little") {
        Cow::Borrowed(b)
    } else {
        Cow::Owned(b.chunks_exact(4).flat_map(|w| [w[3], w[2], w[1], w[0]]).collect())
    }
}

pub fn serialize<T: Pod, S: Serializer>(v: &[T], s: S) -> Result<S::Ok, S::Error> {
    s.serialize_bytes(&le_bytes(v))
}

/// A borrowed slice serialised as `serialize` does, for hand-written `Serialize` impls.
pub struct Slice<'a, T>(pub &'a [T]);

impl<T: Pod> serde::Serialize for Slice<'_, T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        serialize(self.0, s)
    }
}

/// Copies little-endian bytes into a new `Vec<T>`; `None` unless they are whole elements.
pub fn from_le_bytes<T: Pod>(b: &[u8]) -> Option<Vec<T>> {
    let size = std::mem::size_of::<T>();
    if size == 0 || !b.len().is_multiple_of(size) {
        return None;
    }
    // Copied byte-wise: `b` need not be aligned for T.
    let mut v = vec![T::zeroed(); b.len() / size];
    // The new array's pages are not touched yet: a large one can still land on large pages.
    crate::memory::huge_pages(&v);
    bytemuck::cast_slice_mut::<T, u8>(&mut v).copy_from_slice(b);
    if cfg!(target_endian = "big") {
        bytemuck::cast_slice_mut::<T, u8>(&mut v).chunks_exact_mut(4).for_each(<[u8]>::reverse);
    }
    Some(v)
}

struct V<T>(PhantomData<T>);

impl<T: Pod> de::Visitor<'_> for V<T> {
    type Value = Vec<T>;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "bytes holding whole {}-byte elements", std::mem::size_of::<T>())
    }
    fn visit_bytes<E: de::Error>(self, b: &[u8]) -> Result<Vec<T>, E> {
        from_le_bytes(b).ok_or_else(|| E::invalid_length(b.len(), &self))
    }
}

pub fn deserialize<'de, T: Pod, D: Deserializer<'de>>(d: D) -> Result<Vec<T>, D::Error> {
    d.deserialize_bytes(V(PhantomData))
}
