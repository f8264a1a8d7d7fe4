//! The open graph file: the core `Graph`, where it lives, what is on disk, undo and redo,
//! and the recovery file that keeps unsaved work when the editor dies.

use relume_core::{Graph, Registry};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// How many edits undo remembers.
const UNDO_DEPTH: usize = 200;
/// Edits of one kind on one target closer together than this merge into one undo step
/// (a slider drag is one step, not sixty).
const MERGE_WINDOW: Duration = Duration::from_millis(800);

pub struct Document {
    pub graph: Graph,
    /// `None` for a graph never saved.
    pub path: Option<PathBuf>,
    /// The canonical text last read or written; the document is dirty when it differs.
    saved_text: String,
    undo: Vec<Graph>,
    redo: Vec<Graph>,
    /// The tag and time of the last edit, for merging.
    last_edit: Option<(String, Instant)>,
    /// Edits with the last edit's tag merge into its step whatever the time between them,
    /// until `seal` (a drag in the viewer, a brush stroke: one undo step each).
    held: bool,
    /// Bumped on every change of the graph (edit, undo, redo, load).
    pub revision: u64,
}

impl Document {
    /// An empty, untitled graph resolving relative paths against the working folder.
    pub fn new() -> Self {
        let graph = Graph { base_dir: std::env::current_dir().unwrap_or_default(), ..Graph::default() };
        let saved_text = graph.to_ron();
        Document { graph, path: None, saved_text, undo: Vec::new(), redo: Vec::new(), last_edit: None, held: false, revision: 0 }
    }

    /// Opens a graph file, validating it against the registry.
    pub fn open(path: &Path, reg: &Registry) -> Result<Self, String> {
        let mut graph = Graph::load(path, reg).map_err(|e| e.to_string())?;
        // A graph without layout positions is laid out the same way each time it opens, so
        // the layout alone does not mark it as changed.
        crate::edit::lay_out_unplaced(&mut graph, reg);
        let saved_text = graph.to_ron();
        Ok(Document {
            graph,
            path: Some(path.to_path_buf()),
            saved_text,
            undo: Vec::new(),
            redo: Vec::new(),
            last_edit: None,
            held: false,
            revision: 0,
        })
    }

    pub fn title(&self) -> String {
        let name = self.path.as_ref().and_then(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned());
        format!("{}{}", name.unwrap_or_else(|| "untitled".into()), if self.is_dirty() { " *" } else { "" })
    }

    /// Whether the graph differs from what is on disk.
    pub fn is_dirty(&self) -> bool {
        self.graph.to_ron() != self.saved_text
    }

    /// Applies an edit as one undo step; `tag` names what it touches (e.g. `param:blur.sigma`)
    /// so that quick repeats of the same edit merge into one step.
    pub fn edit<R>(&mut self, tag: &str, f: impl FnOnce(&mut Graph) -> R) -> R {
        let now = Instant::now();
        let merge = matches!(&self.last_edit, Some((t, at)) if t == tag && (self.held || now.duration_since(*at) < MERGE_WINDOW));
        if !merge {
            self.undo.push(self.graph.clone());
            if self.undo.len() > UNDO_DEPTH {
                self.undo.remove(0);
            }
        }
        self.redo.clear();
        self.last_edit = Some((tag.to_string(), now));
        self.revision += 1;
        f(&mut self.graph)
    }

    /// Ends merging: the next edit starts a new undo step even with the same tag.
    pub fn seal(&mut self) {
        self.last_edit = None;
        self.held = false;
    }

    /// Keeps merging edits with the last edit's tag into one step until `seal`.
    pub fn hold(&mut self) {
        self.held = self.last_edit.is_some();
    }

    pub fn can_undo(&self) -> bool {
        !self.undo.is_empty()
    }
    pub fn can_redo(&self) -> bool {
        !self.redo.is_empty()
    }

    pub fn undo(&mut self) -> bool {
        let Some(prev) = self.undo.pop() else { return false };
        self.redo.push(std::mem::replace(&mut self.graph, prev));
        self.last_edit = None;
        self.revision += 1;
        true
    }

    pub fn redo(&mut self) -> bool {
        let Some(next) = self.redo.pop() else { return false };
        self.undo.push(std::mem::replace(&mut self.graph, next));
        self.last_edit = None;
        self.revision += 1;
        true
    }

    /// Saves to the document's path atomically and removes the recovery file.
    pub fn save(&mut self) -> Result<(), String> {
        let path = self.path.clone().ok_or("the graph has no file yet: use Save As")?;
        self.save_as(&path)
    }

    /// Saves to `path` atomically (write, sync, rename); relative file parameters keep
    /// resolving against the folder they were written for only when it is the same folder.
    pub fn save_as(&mut self, path: &Path) -> Result<(), String> {
        let text = self.graph.to_ron();
        relume_core::graph::write_atomic(path, text.as_bytes()).map_err(|e| format!("cannot save {}: {e}", path.display()))?;
        if let Some(old) = self.path.as_ref().filter(|p| p.as_path() != path) {
            let _ = std::fs::remove_file(recovery_path(Some(old)));
        }
        let _ = std::fs::remove_file(recovery_path(Some(path)));
        self.path = Some(path.to_path_buf());
        self.graph.file = Some(path.to_path_buf());
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            self.graph.base_dir = dir.to_path_buf();
        }
        self.saved_text = text;
        Ok(())
    }

    /// Writes the unsaved graph beside its file (or in the working folder when untitled).
    pub fn write_recovery(&self) -> std::io::Result<PathBuf> {
        let path = recovery_path(self.path.as_deref());
        relume_core::graph::write_atomic(&path, self.graph.to_ron().as_bytes())?;
        Ok(path)
    }

    /// Removes the recovery file (after a save or a deliberate discard).
    pub fn drop_recovery(&self) {
        let _ = std::fs::remove_file(recovery_path(self.path.as_deref()));
    }

    /// Replaces the graph with the recovery file's content as one undoable edit.
    pub fn restore_recovery(&mut self, reg: &Registry) -> Result<(), String> {
        let path = recovery_path(self.path.as_deref());
        let text = std::fs::read_to_string(&path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        let mut g = Graph::parse(&text, Some(&path)).map_err(|e| e.to_string())?;
        g.validate(reg).map_err(|e| e.to_string())?;
        g.file = self.graph.file.clone();
        g.base_dir = self.graph.base_dir.clone();
        self.edit("recover", |graph| *graph = g);
        self.seal();
        Ok(())
    }

    /// A recovery file for this document that differs from the saved graph.
    pub fn pending_recovery(&self) -> Option<PathBuf> {
        let path = recovery_path(self.path.as_deref());
        let text = std::fs::read_to_string(&path).ok()?;
        (text != self.saved_text).then_some(path)
    }
}

impl Default for Document {
    fn default() -> Self {
        Self::new()
    }
}

/// `dir/.name.ron.recovery` beside the file, or `./.untitled.ron.recovery`.
pub fn recovery_path(path: Option<&Path>) -> PathBuf {
    match path {
        Some(p) => {
            let name = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            p.with_file_name(format!(".{name}.recovery"))
        }
        None => PathBuf::from(".untitled.ron.recovery"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::edit;

    fn doc_in(dir: &Path) -> (Document, Registry) {
        let reg = crate::registry();
        let src = concat!(env!("CARGO_MANIFEST_DIR"), "/../graphs/filters.ron");
        let path = dir.join("filters.ron");
        std::fs::copy(src, &path).unwrap();
        (Document::open(&path, &reg).unwrap(), reg)
    }

    #[test]
    fn undo_redo_and_merging() {
        let dir = tempfile::tempdir().unwrap();
        let (mut doc, _) = doc_in(dir.path());
        let before = doc.graph.to_ron();
        for s in [0.9, 1.0, 1.1] {
            doc.edit("param:blur.sigma", |g| g.set_param("blur", "sigma", relume_core::ParamValue::Float(s)));
        }
        assert!(doc.is_dirty());
        assert!(doc.undo(), "three quick edits of one parameter are one step");
        assert_eq!(doc.graph.to_ron(), before);
        assert!(!doc.can_undo());
        assert!(doc.redo());
        assert_eq!(doc.graph.param_text("blur", "sigma"), "1.1");
        doc.seal();
        doc.edit("add", |g| edit::add_node(g, "Tonemap", [0.0, 0.0]));
        doc.undo();
        assert_eq!(doc.graph.param_text("blur", "sigma"), "1.1");
    }

    #[test]
    fn save_is_clean_and_recovery_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let (mut doc, reg) = doc_in(dir.path());
        doc.edit("param:blur.sigma", |g| g.set_param("blur", "sigma", relume_core::ParamValue::Float(2.0)));
        let rec = doc.write_recovery().unwrap();
        assert!(rec.exists());
        let reopened = Document::open(doc.path.as_ref().unwrap(), &reg).unwrap();
        assert!(reopened.pending_recovery().is_some(), "the recovery differs from the file on disk");
        let mut reopened = reopened;
        reopened.restore_recovery(&reg).unwrap();
        assert_eq!(reopened.graph.param_text("blur", "sigma"), "2.0");
        doc.save().unwrap();
        assert!(!doc.is_dirty());
        assert!(!rec.exists(), "saving removes the recovery file");
        let on_disk = std::fs::read_to_string(doc.path.as_ref().unwrap()).unwrap();
        assert_eq!(on_disk, doc.graph.to_ron());
    }

    trait ParamText {
        fn param_text(&self, id: &str, name: &str) -> String;
    }
    impl ParamText for Graph {
        fn param_text(&self, id: &str, name: &str) -> String {
            self.node(id).and_then(|n| n.param(name)).map(|v| v.to_text()).unwrap_or_default()
        }
    }
}
