//! Each output written the moment it exists: the run announces a graph output as soon as its
//! node finishes (or is found in a cache), and this observer writes its files then, so a run
//! whose reference or error takes minutes shows its picture first. The progress bars hear
//! every event too.

use crate::outputs::write_outputs;
use crate::progress::Bars;
use relume_core::{Event, Observer, Value};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The outputs written so far, by name, with their files; or the first write that failed.
type Written = Result<Vec<(String, Vec<PathBuf>)>, String>;

pub(crate) struct EarlyWrites<'a> {
    dir: &'a Path,
    /// False in the processes of a multi-process run that do not write (they only watch).
    writes: bool,
    bars: Option<&'a Bars>,
    written: Mutex<Written>,
}

impl<'a> EarlyWrites<'a> {
    pub fn new(dir: &'a Path, bars: Option<&'a Bars>, writes: bool) -> Self {
        EarlyWrites { dir, writes, bars, written: Mutex::new(Ok(Vec::new())) }
    }

    /// Writes what the run did not announce (none, when it ended well) and returns every
    /// file written, in the order of `outputs`.
    pub fn finish(self, outputs: &[(String, Value)]) -> Result<Vec<PathBuf>, String> {
        if !self.writes {
            return Ok(Vec::new());
        }
        let mut written = self.written.into_inner().unwrap()?;
        let missing: Vec<(String, Value)> = outputs.iter().filter(|(n, _)| !written.iter().any(|(w, _)| w == n)).cloned().collect();
        for (name, v) in missing {
            let files = write_outputs(self.dir, std::slice::from_ref(&(name.clone(), v)))?;
            written.push((name, files));
        }
        Ok(outputs.iter().flat_map(|(n, _)| written.iter().filter(move |(w, _)| w == n).flat_map(|(_, f)| f.clone())).collect())
    }
}

impl Observer for EarlyWrites<'_> {
    fn event(&self, e: &Event<'_>) {
        if let Some(b) = self.bars {
            b.event(e);
        }
        let Event::Output { name, value } = *e else { return };
        if !self.writes {
            return;
        }
        let mut written = self.written.lock().unwrap();
        let Ok(list) = written.as_mut() else { return };
        if list.iter().any(|(n, _)| n == name) {
            return;
        }
        match write_outputs(self.dir, &[(name.to_string(), value.clone())]) {
            Ok(files) => {
                if let (Some(b), Some(first)) = (self.bars, files.first()) {
                    b.note(&format!("ready: {}", first.display()));
                }
                list.push((name.to_string(), files));
            }
            Err(m) => *written = Err(m),
        }
    }
}
