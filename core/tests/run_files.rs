//! The engine refuses, before running anything, a graph whose output file is one of its input
//! files, one of the files an input names (`also_reads`), or another output file; a graph
//! that writes no file is not looked at.

use relume_core::{node, params, Engine, Graph, NodeError, PortValue, Registry, RunCtx, RunError, RunOptions};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Bytes on an edge.
#[derive(Clone, Debug, PartialEq)]
pub struct Bytes(Vec<u8>);

impl PortValue for Bytes {
    const NAME: &'static str = "Bytes";
    const COLOR: [u8; 3] = [9, 9, 9];
    fn byte_size(&self) -> usize {
        self.0.len()
    }
    fn encode(&self) -> Vec<u8> {
        self.0.clone()
    }
    fn decode(b: &[u8]) -> Option<Self> {
        Some(Bytes(b.to_vec()))
    }
}

static RUNS: AtomicUsize = AtomicUsize::new(0);

/// Every line of the file with a `.list` extension names another file beside it.
fn listed(path: &Path) -> Vec<PathBuf> {
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::read_to_string(path).map(|t| t.lines().map(|l| dir.join(l)).collect()).unwrap_or_default()
}

params! {
    /// Reads a file.
    pub struct Read {
        /// the file
        pub path: PathBuf, also_reads = listed;
    }
}

#[node(category = "test", outputs = [bytes])]
impl Read {
    fn run(&self, _cx: &RunCtx) -> Result<Bytes, NodeError> {
        RUNS.fetch_add(1, Ordering::SeqCst);
        Ok(Bytes(std::fs::read(&self.path).map_err(|e| NodeError::param("path", e.to_string()))?))
    }
}

params! {
    /// Writes a file.
    pub struct Write {
        /// the file
        pub path: PathBuf, output;
    }
}

#[node(category = "test", caching = Never, outputs = [bytes])]
impl Write {
    fn run(&self, bytes: &Bytes, _cx: &RunCtx) -> Result<Bytes, NodeError> {
        std::fs::write(&self.path, &bytes.0).map_err(|e| NodeError::param("path", e.to_string()))?;
        Ok(bytes.clone())
    }
}

fn engine() -> Engine {
    let mut reg = Registry::new();
    reg.add::<Read>().add::<Write>();
    Engine::new(reg)
}

fn graph(dir: &Path, read: &str, writes: &[&str]) -> Graph {
    let mut nodes = format!("\"r\": (kind: \"Read\", params: (path: \"{read}\")),");
    let mut edges = String::new();
    let mut outputs = String::new();
    for (k, w) in writes.iter().enumerate() {
        nodes += &format!("\"w{k}\": (kind: \"Write\", params: (path: \"{w}\")),");
        edges += &format!("(\"r.bytes\", \"w{k}.bytes\"),");
        outputs += &format!("\"o{k}\": \"w{k}.bytes\",");
    }
    let text = format!("Graph(version: 1, nodes: {{ {nodes} }}, edges: [{edges}], outputs: {{ {outputs} }})");
    let mut g = Graph::parse(&text, None).unwrap();
    g.base_dir = dir.to_path_buf();
    g
}

fn refusal(e: &Engine, g: &Graph) -> String {
    match e.run(g, &RunOptions::default()) {
        Err(RunError::Graph(errs)) => errs.to_string(),
        other => panic!("expected a refusal, got {:?}", other.map(|r| r.report.ran_ids().len())),
    }
}

#[test]
fn a_write_onto_a_read_or_onto_another_write_is_refused_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("in.txt"), "data").unwrap();
    std::fs::write(dir.path().join("a.list"), "in.txt\nnamed.txt\n").unwrap();
    std::fs::write(dir.path().join("named.txt"), "named").unwrap();
    let e = engine();
    let before = RUNS.load(Ordering::SeqCst);

    let msg = refusal(&e, &graph(dir.path(), "in.txt", &["in.txt"]));
    assert!(
        msg.contains("node \"w0\": parameter `path`: writing")
            && msg.contains("in.txt would overwrite a file this run reads (node \"r\" (Read) parameter `path`)"),
        "{msg}"
    );
    let msg = refusal(&e, &graph(dir.path(), "a.list", &["named.txt"]));
    assert!(msg.contains("named.txt would overwrite a file this run reads (node \"r\" (Read) parameter `path`, which names it)"), "{msg}");
    let msg = refusal(&e, &graph(dir.path(), "in.txt", &["out.txt", "sub/../out.txt"]));
    assert!(msg.contains("out.txt too, so one would overwrite the other"), "{msg}");
    assert_eq!(RUNS.load(Ordering::SeqCst), before, "nothing ran");
    assert_eq!(std::fs::read_to_string(dir.path().join("in.txt")).unwrap(), "data");

    // Apart, the run goes ahead.
    let r = e.run(&graph(dir.path(), "in.txt", &["out.txt"]), &RunOptions::default()).unwrap();
    assert_eq!(r.output("o0").unwrap().get::<Bytes>(), Some(&Bytes(b"data".to_vec())));
    assert_eq!(std::fs::read_to_string(dir.path().join("out.txt")).unwrap(), "data");
}
