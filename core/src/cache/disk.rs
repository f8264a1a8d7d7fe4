//! On-disk cache: one file per key, written atomically (temp + rename), checksummed with
//! blake3. A missing, truncated or corrupt file is a miss; two processes may share a folder
//! (each writes its own temporary file; rename replaces whole files). A process stopped in the
//! middle of a write leaves its temporary file behind: opening a cache removes those that are
//! stale (`sweep_stale_temp_files`).

use super::CacheEntry;
use crate::graph::write_atomic;
use crate::hash::Hash;
use crate::port::PortDecl;
use crate::registry::Registry;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

const MAGIC: &[u8; 8] = b"RELUMEC3";

/// A temporary file older than this is stale whoever wrote it: writing one entry takes
/// seconds, not minutes.
pub const STALE_TEMP_AGE: Duration = Duration::from_secs(15 * 60);
/// A temporary file of a writer that is no longer running (its process id, which the file's
/// name carries, is gone) is stale once this old (younger ones are left alone: the writer may
/// run on another machine or in another process namespace sharing the folder).
pub const DEAD_WRITER_TEMP_AGE: Duration = Duration::from_secs(60);

pub struct DiskCache {
    dir: PathBuf,
    /// What went wrong since the last `take_notes`, to be said once per run.
    problems: std::sync::Mutex<Problems>,
}

/// Failed writes and entries that were not regular files: counted, the first of each kept.
#[derive(Default)]
struct Problems {
    failed_writes: u64,
    first_failure: Option<String>,
    irregular: u64,
    first_irregular: Option<PathBuf>,
    /// `check_writable` found the cache unwritable and the caller said so.
    unwritable_said: bool,
}

impl DiskCache {
    /// Opens the cache in `dir` (created on the first write), removing stale temporary files
    /// that interrupted writes left behind.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        let cache = DiskCache { dir: dir.into(), problems: Default::default() };
        cache.sweep_stale_temp_files(SystemTime::now());
        cache
    }

    /// Whether entries can be written here: creates the folder and writes and removes a probe
    /// file. `Err` says why not, as a sentence (the folder is a file, is read-only, …).
    /// The failure is remembered: the writes that fail afterwards for the same reason are not
    /// said again by `take_notes`.
    pub fn check_writable(&self) -> Result<(), String> {
        let r = self.probe_writable();
        self.problems.lock().unwrap().unwritable_said = r.is_err();
        r
    }

    fn probe_writable(&self) -> Result<(), String> {
        let dir = &self.dir;
        if dir.exists() && !dir.is_dir() {
            return Err(format!("{} is a file, not a folder", dir.display()));
        }
        std::fs::create_dir_all(dir).map_err(|e| format!("cannot create the folder {}: {e}", dir.display()))?;
        let probe = dir.join(format!(".write-probe.{}.tmp", std::process::id()));
        std::fs::write(&probe, b"relume").map_err(|e| format!("cannot write in {}: {e}", dir.display()))?;
        let _ = std::fs::remove_file(&probe);
        Ok(())
    }

    /// Removes the temporary files relume itself leaves in the cache — an entry's
    /// (`.KEY.rlc.PID.N.tmp` in a key folder, see `write_atomic`) and the write probe's
    /// (`.write-probe.PID.tmp` at the top) — that are stale at time `now`: older than
    /// `STALE_TEMP_AGE`, or older than `DEAD_WRITER_TEMP_AGE` and written by a process that is
    /// no longer running. Returns how many it removed. A fresh file of a live writer is never
    /// touched, nor any file of another name or in another folder: a cache may share its folder
    /// (`--cache .`, a scratch space) with other programs and their temporary files.
    pub fn sweep_stale_temp_files(&self, now: SystemTime) -> usize {
        let mut removed = 0;
        let Ok(top) = std::fs::read_dir(&self.dir) else { return 0 };
        let mut folders = vec![(self.dir.clone(), true)];
        folders.extend(
            top.flatten()
                .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()) && is_key_folder(&e.file_name().to_string_lossy()))
                .map(|e| (e.path(), false)),
        );
        for (folder, is_top) in folders {
            let Ok(entries) = std::fs::read_dir(&folder) else { continue };
            for e in entries.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                if !(is_own_temp(&name, is_top) && e.file_type().is_ok_and(|t| t.is_file())) {
                    continue;
                }
                let Some(age) = e.metadata().ok().and_then(|m| m.modified().ok()).and_then(|t| now.duration_since(t).ok()) else {
                    continue;
                };
                let stale = age > STALE_TEMP_AGE || (age > DEAD_WRITER_TEMP_AGE && writer_pid(&name).is_some_and(|p| !process_alive(p)));
                if stale && std::fs::remove_file(e.path()).is_ok() {
                    removed += 1;
                }
            }
        }
        removed
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn path_of(&self, key: &Hash) -> PathBuf {
        let hex = key.hex();
        self.dir.join(&hex[..2]).join(format!("{hex}.rlc"))
    }

    /// Writes an entry; a failure (a full disk, a folder made read-only meanwhile) is counted
    /// for `take_notes` as well as returned.
    pub fn put(&self, key: &Hash, entry: &CacheEntry, decls: &[PortDecl]) -> std::io::Result<()> {
        let r = self.write_entry(key, entry, decls);
        let mut p = self.problems.lock().unwrap();
        if let (Err(e), false) = (&r, p.unwritable_said) {
            p.failed_writes += 1;
            p.first_failure.get_or_insert_with(|| format!("{}: {e}", self.path_of(key).display()));
        }
        r
    }

    /// What went wrong since the last call, as sentences for the run report (each kind said
    /// once, with a count and the first case), and forgets it.
    pub fn take_notes(&self) -> Vec<String> {
        let p = {
            let mut held = self.problems.lock().unwrap();
            let unwritable_said = held.unwritable_said;
            std::mem::replace(&mut *held, Problems { unwritable_said, ..Default::default() })
        };
        let mut notes = Vec::new();
        if let Some(first) = p.first_failure {
            notes.push(format!(
                "the disk cache {} could not store {} result(s) (the first: {first}); later runs will compute them again",
                self.dir.display(),
                p.failed_writes
            ));
        }
        if let Some(first) = p.first_irregular {
            notes.push(format!(
                "the disk cache {} holds {} entr(ies) that are not regular files (the first: {}); they were read as missing, and a new result replaces them",
                self.dir.display(),
                p.irregular,
                first.display()
            ));
        }
        notes
    }

    fn write_entry(&self, key: &Hash, entry: &CacheEntry, decls: &[PortDecl]) -> std::io::Result<()> {
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
        let path = self.path_of(key);
        let bytes = match read_regular(&path) {
            Read::Bytes(b) => b,
            Read::Missing => return None,
            Read::NotRegular => {
                let mut p = self.problems.lock().unwrap();
                p.irregular += 1;
                p.first_irregular.get_or_insert(path);
                return None;
            }
        };
        decode(&bytes, key, decls, reg)
    }
}

/// The bytes of `path` when it is a regular file, read up to the size it has; `None` for
/// anything else. An entry replaced by a link to `/dev/zero` would otherwise be read until
/// memory runs out, and a FIFO would block the run; the next write of that key replaces the
/// link or FIFO itself (`write_atomic` renames over the name, never writes through it).
fn read_regular(path: &Path) -> Read {
    use std::io::Read as _;
    let Ok(named) = std::fs::symlink_metadata(path) else { return Read::Missing };
    if !named.file_type().is_file() {
        return Read::NotRegular;
    }
    let Ok(f) = std::fs::File::open(path) else { return Read::Missing };
    let Ok(opened) = f.metadata() else { return Read::Missing };
    if !opened.file_type().is_file() {
        return Read::NotRegular;
    }
    let mut bytes = Vec::new();
    match f.take(opened.len()).read_to_end(&mut bytes) {
        Ok(_) => Read::Bytes(bytes),
        Err(_) => Read::Missing,
    }
}

/// What `read_regular` found.
enum Read {
    Bytes(Vec<u8>),
    /// Not there, or not readable (a miss like any other).
    Missing,
    /// A link, a device, a FIFO or a folder where an entry should be.
    NotRegular,
}

/// Whether `name` is a folder of entries: the first two hex digits of the keys in it.
fn is_key_folder(name: &str) -> bool {
    name.len() == 2 && name.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// Whether `name` is one of relume's own temporary files: at the top of the cache the write
/// probe's `.write-probe.PID.tmp`, in a key folder an entry's `.KEY.rlc.PID.N.tmp` (KEY 64 hex
/// digits).
fn is_own_temp(name: &str, at_top: bool) -> bool {
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let Some(stem) = name.strip_prefix('.').and_then(|n| n.strip_suffix(".tmp")) else { return false };
    if at_top {
        return stem.strip_prefix("write-probe.").is_some_and(digits);
    }
    let parts: Vec<&str> = stem.split('.').collect();
    matches!(parts.as_slice(), [key, "rlc", pid, n]
        if key.len() == 64 && key.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b)) && digits(pid) && digits(n))
}

/// The process id in a temporary file's name: `.NAME.PID.N.tmp` (`write_atomic`) or
/// `.write-probe.PID.tmp` (`check_writable`).
fn writer_pid(name: &str) -> Option<u32> {
    let parts: Vec<&str> = name.strip_suffix(".tmp")?.rsplit('.').collect();
    // rsplit: [N, PID, …] for write_atomic, [PID, "write-probe", …] for the probe.
    if parts.get(1) == Some(&"write-probe") {
        parts.first()?.parse().ok()
    } else {
        parts.get(1)?.parse().ok()
    }
}

/// Whether process `pid` runs on this machine. Where that cannot be known (no `/proc`), it
/// is taken to run, so that only age makes its files stale.
fn process_alive(pid: u32) -> bool {
    let proc = Path::new("/proc");
    !proc.join("self").exists() || proc.join(pid.to_string()).exists()
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A temporary file named as `write_atomic` names them, for writer `pid`, `age` old.
    fn temp_file(dir: &Path, pid: u32, age: Duration) -> PathBuf {
        let path = dir.join(format!(".{}.rlc.{pid}.{}.tmp", "ab".repeat(32), age.as_secs()));
        std::fs::write(&path, b"half an entry").unwrap();
        let f = std::fs::File::options().write(true).open(&path).unwrap();
        f.set_modified(SystemTime::now() - age).unwrap();
        path
    }

    #[test]
    fn opening_a_cache_removes_stale_temp_files_and_keeps_those_of_live_writers() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("ab");
        std::fs::create_dir_all(&sub).unwrap();
        let me = std::process::id();
        // A process id that is not running: past the largest one Linux hands out.
        let dead = 4_194_304 + 17;
        let old = temp_file(&sub, me, STALE_TEMP_AGE + Duration::from_secs(60));
        let dead_writer = temp_file(&sub, dead, DEAD_WRITER_TEMP_AGE + Duration::from_secs(30));
        let live_writer = temp_file(&sub, me, DEAD_WRITER_TEMP_AGE + Duration::from_secs(30));
        let fresh_of_dead = temp_file(&sub, dead, Duration::from_secs(1));
        let probe = dir.path().join(format!(".write-probe.{dead}.tmp"));
        std::fs::write(&probe, b"x").unwrap();
        std::fs::File::options().write(true).open(&probe).unwrap().set_modified(SystemTime::now() - STALE_TEMP_AGE * 2).unwrap();
        let entry = sub.join("abc.rlc");
        std::fs::write(&entry, b"not a temp file").unwrap();
        std::fs::File::options().write(true).open(&entry).unwrap().set_modified(SystemTime::now() - STALE_TEMP_AGE * 2).unwrap();

        let _cache = DiskCache::new(dir.path());
        assert!(!old.exists(), "older than {STALE_TEMP_AGE:?}: removed");
        assert!(!probe.exists(), "an old probe: removed");
        assert!(entry.exists(), "entries are never swept");
        assert!(live_writer.exists(), "a file of a running writer is kept");
        assert!(fresh_of_dead.exists(), "a fresh file is kept whoever wrote it");
        if Path::new("/proc/self").exists() {
            assert!(!dead_writer.exists(), "a writer that no longer runs: removed");
        }
        assert_eq!(writer_pid(".abc.rlc.4242.99.tmp"), Some(4242));
        assert_eq!(writer_pid(".write-probe.77.tmp"), Some(77));
    }

    #[test]
    fn an_entry_that_is_not_a_regular_file_is_a_miss_and_is_never_read() {
        let dir = tempfile::tempdir().unwrap();
        let cache = DiskCache::new(dir.path());
        let reg = Registry::new();
        let key = |b: u8| Hash([b; 32]);
        let place = |k: &Hash| {
            let p = cache.path_of(k);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            p
        };
        // A link to an endless device: read whole, it would fill memory.
        std::os::unix::fs::symlink("/dev/zero", place(&key(1))).unwrap();
        assert!(cache.get(&key(1), &[], &reg).is_none());
        // A FIFO no one writes: opening it for reading would block forever.
        let fifo = std::ffi::CString::new(place(&key(2)).into_os_string().into_encoded_bytes()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
        assert!(cache.get(&key(2), &[], &reg).is_none());
        // A link to a regular file is not an entry either: entries are written as files.
        let elsewhere = dir.path().join("elsewhere.rlc");
        std::fs::write(&elsewhere, b"RELUMEC3").unwrap();
        std::os::unix::fs::symlink(&elsewhere, place(&key(3))).unwrap();
        assert!(cache.get(&key(3), &[], &reg).is_none());
        assert!(matches!(read_regular(&elsewhere), Read::Bytes(b) if b == b"RELUMEC3"));
        // Said once, with the count and the first, then forgotten; a plain miss says nothing.
        assert!(cache.get(&key(4), &[], &reg).is_none());
        let notes = cache.take_notes();
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(
            notes[0].contains("holds 3 entr(ies) that are not regular files") && notes[0].contains(&place(&key(1)).display().to_string()),
            "{notes:?}"
        );
        assert!(cache.take_notes().is_empty());
    }

    #[test]
    fn a_write_that_fails_is_said_once_with_the_count_and_the_first_error() {
        let dir = tempfile::tempdir().unwrap();
        let cache = DiskCache::new(dir.path().join("c"));
        // Where the key folders should go, a file: every write fails, as on a full disk.
        std::fs::write(dir.path().join("c"), b"").unwrap();
        let entry = CacheEntry { outputs: vec![], metrics: vec![], notes: vec![], deps: vec![], compute_ms: 0.0 };
        for b in 0..3 {
            assert!(cache.put(&Hash([b; 32]), &entry, &[]).is_err());
        }
        let notes = cache.take_notes();
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(notes[0].contains("could not store 3 result(s)") && notes[0].contains("later runs will compute them again"), "{notes:?}");
        assert!(cache.take_notes().is_empty());
        // Once the caller has said the cache cannot be written, the failures it causes are not
        // said again.
        assert!(cache.check_writable().is_err());
        assert!(cache.put(&Hash([9; 32]), &entry, &[]).is_err());
        assert!(cache.take_notes().is_empty());
    }

    #[test]
    fn other_programs_temporary_files_are_never_swept() {
        let dir = tempfile::tempdir().unwrap();
        let old = SystemTime::now() - STALE_TEMP_AGE * 4;
        let key = "cd".repeat(32);
        let make = |path: PathBuf| {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, b"someone else's").unwrap();
            std::fs::File::options().write(true).open(&path).unwrap().set_modified(old).unwrap();
            path
        };
        // What `--cache .` or a shared scratch folder may hold besides relume's files.
        let theirs = [
            make(dir.path().join(".session.tmp")),
            make(dir.path().join(".notes.txt.4242.7.tmp")),
            make(dir.path().join(format!(".{key}.rlc.4242.7.tmp"))), // an entry's name, but not in a key folder
            make(dir.path().join("build").join(".out.1.2.tmp")),
            make(dir.path().join("xy").join(format!(".{key}.rlc.4242.7.tmp"))), // not a hex folder
            make(dir.path().join("cd").join(".other.rlc.4242.7.tmp")),
            make(dir.path().join("cd").join(format!(".{key}.rlc.x.7.tmp"))),
        ];
        let ours = make(dir.path().join("cd").join(format!(".{key}.rlc.4242.7.tmp")));
        let probe = make(dir.path().join(".write-probe.4242.tmp"));
        assert_eq!(DiskCache::new(dir.path()).sweep_stale_temp_files(SystemTime::now()), 0, "the first sweep ran on opening");
        for p in &theirs {
            assert!(p.exists(), "{} was swept", p.display());
        }
        assert!(!ours.exists() && !probe.exists(), "relume's own stale files are removed");
    }

    #[test]
    fn a_file_where_the_folder_should_be_is_not_writable() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("f");
        std::fs::write(&file, b"").unwrap();
        let e = DiskCache::new(&file).check_writable().unwrap_err();
        assert!(e.contains("is a file, not a folder"), "{e}");
        let e = DiskCache::new(file.join("sub")).check_writable().unwrap_err();
        assert!(e.contains("cannot create the folder"), "{e}");
        assert_eq!(DiskCache::new(dir.path().join("new")).check_writable(), Ok(()));
        assert!(std::fs::read_dir(dir.path().join("new")).unwrap().next().is_none(), "the probe is removed");
    }
}
