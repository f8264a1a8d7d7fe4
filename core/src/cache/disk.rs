//! On-disk cache: one file per key, written atomically (temp + rename), checksummed with
//! blake3. A missing, truncated or corrupt file is a miss; two processes may share a folder
//! (each writes its own temporary file; rename replaces whole files).

use super::CacheEntry;
use crate::graph::write_atomic;
use crate::hash::Hash;
use crate::port::PortDecl;
use crate::registry::Registry;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"RELUMEC3";

pub struct DiskCache {
    dir: PathBuf,
}

impl DiskCache {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        DiskCache { dir: dir.into() }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn path_of(&self, key: &Hash) -> PathBuf {
        let hex = key.hex();
        self.dir.join(&hex[..2]).join(format!("{hex}.rlc"))
    }

    /// Writes an entry.
    pub fn put(&self, key: &Hash, entry: &CacheEntry, decls: &[PortDecl]) -> std::io::Result<()> {
        let payloads: Vec<Vec<u8>> = entry.outputs.iter().map(|v| v.encode()).collect();
        let mut buf = Vec::new();
        buf.extend_from_slice(MAGIC);
        buf.extend_from_slice(&key.0);
        put_u32(&mut buf, entry.outputs.len() as u32);
        for ((v, d), p) in entry.outputs.iter().zip(decls).zip(&payloads) {
            put_str(&mut buf, d.name);
            put_str(&mut buf, v.type_name());
            buf.extend_from_slice(&v.fingerprint().0);
            put_u64(&mut buf, p.len() as u64);
        }
        put_u32(&mut buf, entry.metrics.len() as u32);
        for (name, x) in &entry.metrics {
            put_str(&mut buf, name);
            put_u64(&mut buf, x.to_bits());
        }
        put_u32(&mut buf, entry.notes.len() as u32);
        for n in &entry.notes {
            put_str(&mut buf, n);
        }
        put_u32(&mut buf, entry.deps.len() as u32);
        for (path, h) in &entry.deps {
            put_str(&mut buf, &path.to_string_lossy());
            buf.extend_from_slice(&h.0);
        }
        put_u64(&mut buf, entry.compute_ms.to_bits());
        for p in &payloads {
            buf.extend_from_slice(p);
        }
        let sum = Hash::of_bytes(&buf);
        buf.extend_from_slice(&sum.0);
        let path = self.path_of(key);
        std::fs::create_dir_all(path.parent().unwrap())?;
        write_atomic(&path, &buf)
    }

    /// Reads an entry whose outputs must match `decls`; any defect is a miss.
    pub fn get(&self, key: &Hash, decls: &[PortDecl], reg: &Registry) -> Option<CacheEntry> {
        let bytes = std::fs::read(self.path_of(key)).ok()?;
        decode(&bytes, key, decls, reg)
    }
}

fn decode(bytes: &[u8], key: &Hash, decls: &[PortDecl], reg: &Registry) -> Option<CacheEntry> {
    if bytes.len() < MAGIC.len() + 64 {
        return None;
    }
    let (body, sum) = bytes.split_at(bytes.len() - 32);
    if Hash::of_bytes(body).0 != sum {
        return None;
    }
    let mut r = Reader { b: body, at: 0 };
    if r.take(8)? != MAGIC || r.take(32)? != key.0 {
        return None;
    }
    let n = r.u32()? as usize;
    if n != decls.len() {
        return None;
    }
    let mut heads = Vec::with_capacity(n);
    for d in decls {
        let (name, ty) = (r.str()?, r.str()?);
        let fp: [u8; 32] = r.take(32)?.try_into().ok()?;
        let len = r.u64()? as usize;
        if name != d.name || ty != d.ty.name {
            return None;
        }
        heads.push((fp, len));
    }
    let metrics = (0..r.u32()?).map(|_| Some((r.str()?, f64::from_bits(r.u64()?)))).collect::<Option<Vec<_>>>()?;
    let notes = (0..r.u32()?).map(|_| r.str()).collect::<Option<Vec<_>>>()?;
    let deps = (0..r.u32()?).map(|_| Some((PathBuf::from(r.str()?), Hash(r.take(32)?.try_into().ok()?)))).collect::<Option<Vec<_>>>()?;
    let compute_ms = f64::from_bits(r.u64()?);
    let mut outputs = Vec::with_capacity(n);
    for ((fp, len), d) in heads.into_iter().zip(decls) {
        let info = reg.port_type(d.ty.name)?;
        // The entry's checksum vouches for the stored fingerprint.
        outputs.push((info.decode)(r.take(len)?, Hash(fp))?);
    }
    (r.at == body.len()).then_some(CacheEntry { outputs, metrics, notes, deps, compute_ms })
}

fn put_u32(b: &mut Vec<u8>, v: u32) {
    b.extend_from_slice(&v.to_le_bytes());
}
fn put_u64(b: &mut Vec<u8>, v: u64) {
    b.extend_from_slice(&v.to_le_bytes());
}
fn put_str(b: &mut Vec<u8>, s: &str) {
    put_u32(b, s.len() as u32);
    b.extend_from_slice(s.as_bytes());
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.at.checked_add(n)?;
        let s = self.b.get(self.at..end)?;
        self.at = end;
        Some(s)
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn str(&mut self) -> Option<String> {
        let n = self.u32()? as usize;
        String::from_utf8(self.take(n)?.to_vec()).ok()
    }
}
