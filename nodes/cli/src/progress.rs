//! Progress bars (indicatif) for `relume run`: one bar for the whole run and one per node
//! that reports progress. Hidden when stderr is not a terminal.

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use relume_core::{Event, Observer};
use std::collections::HashMap;
use std::sync::Mutex;

pub(crate) struct Bars {
    multi: MultiProgress,
    total: Mutex<Option<ProgressBar>>,
    nodes: Mutex<HashMap<String, ProgressBar>>,
}

impl Bars {
    pub fn new() -> Self {
        Bars { multi: MultiProgress::new(), total: Mutex::new(None), nodes: Mutex::new(HashMap::new()) }
    }
}

impl Bars {
    /// A line above the bars (nothing when they are hidden: stderr is not a terminal).
    pub fn note(&self, line: &str) {
        let _ = self.multi.println(line);
    }
}

impl Observer for Bars {
    fn event(&self, e: &Event<'_>) {
        match *e {
            Event::Planned { nodes } => {
                let bar = self.multi.add(ProgressBar::new(nodes as u64));
                bar.set_style(
                    ProgressStyle::with_template("{prefix:>12} [{bar:30}] {pos}/{len} nodes {elapsed}").unwrap().progress_chars("=> "),
                );
                bar.set_prefix("run");
                *self.total.lock().unwrap() = Some(bar);
            }
            Event::Progress { id, fraction } => {
                let mut nodes = self.nodes.lock().unwrap();
                let bar = nodes.entry(id.to_string()).or_insert_with(|| {
                    let b = self.multi.add(ProgressBar::new(1000));
                    b.set_style(
                        ProgressStyle::with_template("{prefix:>12} [{bar:30}] {percent}% {elapsed} (eta {eta})")
                            .unwrap()
                            .progress_chars("=> "),
                    );
                    b.set_prefix(relume_core::printable(id).into_owned());
                    b
                });
                bar.set_position((fraction * 1000.0) as u64);
            }
            Event::Finished { id, .. } | Event::Failed { id, .. } => {
                if let Some(b) = self.nodes.lock().unwrap().remove(id) {
                    b.finish_and_clear();
                }
                if let Some(t) = self.total.lock().unwrap().as_ref() {
                    t.inc(1);
                }
            }
            Event::Started { .. } | Event::Partial { .. } | Event::Output { .. } => {}
        }
    }
}

impl Drop for Bars {
    fn drop(&mut self) {
        if let Some(t) = self.total.lock().unwrap().take() {
            t.finish_and_clear();
        }
    }
}
