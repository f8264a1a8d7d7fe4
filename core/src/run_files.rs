//! The files a run reads and writes, listed before it runs, so that no write lands on a file
//! the run reads (its graph, a scene, a mesh, a texture, an input image) or on another write
//! of the same run.

use crate::ctx::{resolve_write_path, WriteRoots};
use crate::error::{GraphError, GraphErrors};
use crate::graph::Graph;
use crate::params::{ParamKind, ParamValue};
use crate::plan::Plan;
use crate::registry::Registry;
use std::path::{Path, PathBuf};

/// A file and who names it (for the message): `node "save" parameter path`, `--report`, ….
#[derive(Clone, Debug, PartialEq)]
pub struct RunFile {
    /// Where the file lands, resolved as a write would resolve it (symbolic links followed).
    pub path: PathBuf,
    pub who: String,
    /// The graph node that names it, for the error's position.
    node: Option<String>,
    param: Option<String>,
}

impl RunFile {
    /// An error about this file, placed at the node and parameter that name it (or led by
    /// who names it, a command-line flag).
    fn error(&self, msg: String, graph: &Graph) -> GraphError {
        let msg = if self.node.is_some() { msg } else { format!("{}: {msg}", self.who) };
        let mut e = GraphError::new(msg);
        if let Some(id) = &self.node {
            let decl = graph.node(id);
            let at = decl.and_then(|d| {
                let k = d.params.iter().position(|(n, _)| Some(n) == self.param.as_ref())?;
                d.param_pos.get(k).copied()
            });
            e = e.node(id);
            if let Some(pos) = at.or(decl.map(|d| d.pos)) {
                e = e.at(pos);
            }
            if let Some(p) = &self.param {
                e = e.param(p);
            }
        }
        e.file = graph.file.clone();
        e
    }
}

/// The reads and writes of one run.
#[derive(Clone, Debug, Default)]
pub struct RunFiles {
    pub reads: Vec<RunFile>,
    pub writes: Vec<RunFile>,
}

impl RunFiles {
    /// The graph file, and the file parameters of the planned nodes: input files and the files
    /// they name (`ParamSpec::also_reads`: a scene's meshes and maps) are reads; output files
    /// are writes.
    pub fn of_plan(graph: &Graph, reg: &Registry, plan: &Plan) -> RunFiles {
        let mut files = RunFiles::default();
        if let Some(f) = &graph.file {
            files.read(f, "the graph file");
        }
        for &i in &plan.order {
            let decl = &graph.nodes[i];
            let Some(kind) = reg.node(&decl.kind) else { continue };
            let schema = kind.schema();
            let who = |p: &str| format!("node \"{}\" ({}) parameter `{p}`", decl.id, decl.kind);
            for spec in &schema.0 {
                let Some(ParamValue::Text(text)) = decl.param(spec.name).or(spec.default.as_ref()) else { continue };
                let path = graph.base_dir.join(text);
                let file = RunFile {
                    path: resolve_write_path(&path),
                    who: who(spec.name),
                    node: Some(decl.id.clone()),
                    param: Some(spec.name.to_string()),
                };
                match spec.kind {
                    ParamKind::InputFile => {
                        // The files it names (a scene's meshes and maps) are read too.
                        for p in spec.also_reads.map(|list| (list.0)(&path)).unwrap_or_default() {
                            let who = format!("{}, which names it", file.who);
                            files.reads.push(RunFile { path: resolve_write_path(&p), who, ..file.clone() });
                        }
                        files.reads.push(file);
                    }
                    ParamKind::OutputFile => files.writes.push(file),
                    _ => {}
                }
            }
        }
        files
    }

    /// Adds a file the caller reads.
    pub fn read(&mut self, path: &Path, who: &str) {
        self.reads.push(RunFile { path: resolve_write_path(path), who: who.into(), node: None, param: None });
    }

    /// Adds a file the caller writes (`--report`, an output written to the output folder).
    pub fn write(&mut self, path: &Path, who: &str) {
        self.writes.push(RunFile { path: resolve_write_path(path), who: who.into(), node: None, param: None });
    }

    /// Every write that lands on a file the run reads or on an earlier write, as an error
    /// naming both; empty when the run's files are apart.
    pub fn clashes(&self, graph: &Graph) -> Vec<GraphError> {
        let mut errs = Vec::new();
        for (k, w) in self.writes.iter().enumerate() {
            let what = if let Some(r) = self.reads.iter().find(|r| r.path == w.path) {
                format!("writing {} would overwrite a file this run reads ({})", w.path.display(), r.who)
            } else if let Some(o) = self.writes[..k].iter().find(|o| o.path == w.path) {
                format!("{} writes {} too, so one would overwrite the other", o.who, w.path.display())
            } else {
                continue;
            };
            errs.push(w.error(format!("{what}; write it elsewhere"), graph));
        }
        errs
    }

    /// Every file the run reads that is not there (a misspelt input image, a scene's missing
    /// mesh), as an error naming who reads it: what `check` says before a run would fail.
    pub fn missing(&self, graph: &Graph) -> Vec<GraphError> {
        self.reads
            .iter()
            .filter(|r| !r.path.exists())
            .map(|r| r.error(format!("reads {}, which does not exist", r.path.display()), graph))
            .collect()
    }

    /// Every file a node reads (an input file, a scene's mesh or map) that lies outside the
    /// folders `roots` allows, symbolic links followed, as an error naming the file and the
    /// folders: so that a graph from someone else cannot read `/etc/passwd` or a link to it.
    /// The graph file itself is the caller's choice and not looked at.
    pub fn outside(&self, graph: &Graph, roots: &WriteRoots) -> Vec<GraphError> {
        let Some(folders) = roots.folders() else { return Vec::new() };
        let list: Vec<String> = folders.iter().map(|r| r.display().to_string()).collect();
        self.reads
            .iter()
            .filter(|r| r.node.is_some() && !folders.iter().any(|f| r.path.starts_with(f)))
            .map(|r| {
                let msg = format!(
                    "refusing to read {}: it is outside the folders this run may read from ({}); move it below one of them, \
                     or name its folder with `--read-from DIR`, or, if you trust this graph, allow it with `--allow-reads-anywhere`",
                    r.path.display(),
                    list.join(", ")
                );
                r.error(msg, graph)
            })
            .collect()
    }

    /// `clashes` as a result.
    pub fn check(&self, graph: &Graph) -> Result<(), GraphErrors> {
        let errs = self.clashes(graph);
        if errs.is_empty() {
            Ok(())
        } else {
            Err(GraphErrors(errs))
        }
    }
}
