//! Content hashes of the files a run reads (file parameters, files a node depends on),
//! remembered while a file's size and modification time stay as they were: every run checks
//! them, and reading and hashing a scene's mesh and sky again on each camera edit cost a
//! measurable part of an interactive edit. A file is remembered only once its modification
//! time lies [`SETTLED`] in the past (git's "racy" rule): a write within the file system's
//! timestamp granularity of the remembered one could otherwise keep size and time alike.

use crate::hash::Hash;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, SystemTime};

/// How old a file's modification time must be before its hash is remembered.
pub const SETTLED: Duration = Duration::from_secs(2);

/// What a file looked like when its content was hashed.
#[derive(Clone, Copy, PartialEq, Eq)]
struct Stamp {
    len: u64,
    modified: SystemTime,
}

static KNOWN: Mutex<Option<HashMap<PathBuf, (Stamp, Hash)>>> = Mutex::new(None);

/// `Hash::of_bytes` of the file's content (read through `read_input`, so folders and pipes
/// are refused), from memory when the file has not changed since it was last hashed.
pub fn content_hash(path: &Path) -> std::io::Result<Hash> {
    let meta = std::fs::metadata(path)?;
    let stamp = meta.modified().ok().map(|modified| Stamp { len: meta.len(), modified });
    if let Some(s) = stamp {
        if let Some((known, h)) = KNOWN.lock().unwrap().as_ref().and_then(|m| m.get(path)) {
            if *known == s {
                return Ok(*h);
            }
        }
    }
    let h = Hash::of_bytes(&crate::read_input(path)?);
    let settled = stamp.filter(|s| SystemTime::now().duration_since(s.modified).is_ok_and(|age| age >= SETTLED));
    let mut known = KNOWN.lock().unwrap();
    let map = known.get_or_insert_with(HashMap::new);
    match settled {
        Some(s) => {
            map.insert(path.to_path_buf(), (s, h));
        }
        None => {
            map.remove(path);
        }
    }
    Ok(h)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set_age(path: &Path, age: Duration) {
        let f = std::fs::File::options().write(true).open(path).expect("opens");
        f.set_modified(SystemTime::now() - age).expect("sets the time");
    }

    #[test]
    fn a_changed_file_hashes_anew_even_at_the_same_size_and_time() {
        let dir = std::env::temp_dir().join(format!("relume-file-hash-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("folder");
        let path = dir.join("a.txt");
        std::fs::write(&path, b"first").expect("writes");
        // A fresh file is not remembered: rewriting it at once with the same size is seen.
        assert_eq!(content_hash(&path).unwrap(), Hash::of_bytes(b"first"));
        std::fs::write(&path, b"other").expect("writes");
        assert_eq!(content_hash(&path).unwrap(), Hash::of_bytes(b"other"));
        // A settled file is remembered; a later write moves its time and is seen.
        set_age(&path, Duration::from_secs(10));
        assert_eq!(content_hash(&path).unwrap(), Hash::of_bytes(b"other"));
        assert!(KNOWN.lock().unwrap().as_ref().unwrap().contains_key(&path));
        std::fs::write(&path, b"third").expect("writes");
        assert_eq!(content_hash(&path).unwrap(), Hash::of_bytes(b"third"));
        // Settled again at another time and size: hashed anew, then remembered.
        std::fs::write(&path, b"fourth!").expect("writes");
        set_age(&path, Duration::from_secs(10));
        assert_eq!(content_hash(&path).unwrap(), Hash::of_bytes(b"fourth!"));
        assert!(content_hash(&dir).is_err(), "a folder is refused");
        std::fs::remove_dir_all(&dir).ok();
    }
}
