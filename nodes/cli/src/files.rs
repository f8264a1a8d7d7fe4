//! What a command checks before it runs about the files it will write: output folders and
//! files that can be written, and output-file parameters that stay inside the allowed folders.

use crate::error::CliError;
use relume_core::{Graph, GraphError, ParamKind, ParamValue, Registry, WritePolicy, WriteRoots};
use std::path::Path;

/// The output-file parameters (`ParamKind::OutputFile`, e.g. SaveImage's `path`) of the nodes
/// `ids` that would write outside the folders `policy` allows, as errors naming the file, line,
/// node and parameter: checked before anything runs (the node checks again when it writes).
pub(crate) fn write_refusals<'g>(
    reg: &Registry,
    graph: &'g Graph,
    ids: impl IntoIterator<Item = &'g str>,
    policy: &WritePolicy,
) -> Vec<GraphError> {
    let roots = WriteRoots::new(policy, &graph.base_dir);
    let mut errs = Vec::new();
    for id in ids {
        let Some(decl) = graph.node(id) else { continue };
        let Some(kind) = reg.node(&decl.kind) else { continue };
        for spec in kind.schema().0.iter().filter(|s| s.kind == ParamKind::OutputFile) {
            let Some(ParamValue::Text(text)) = decl.param(spec.name).or(spec.default.as_ref()) else { continue };
            if let Err(m) = roots.check(&graph.base_dir.join(text)) {
                let at = decl.params.iter().position(|(n, _)| n == spec.name).and_then(|k| decl.param_pos.get(k).copied());
                let mut e = GraphError::new(m).at(at.unwrap_or(decl.pos)).node(&decl.id).param(spec.name);
                e.file = graph.file.clone();
                errs.push(e);
            }
        }
    }
    errs
}

/// Makes sure `dir` (the value of `flag`) is a folder outputs can be written to, before
/// anything runs: creates it when missing, refuses a file, and checks that it can be written in.
pub(crate) fn prepare_out_dir(flag: &str, dir: &Path) -> Result<(), CliError> {
    if dir.exists() && !dir.is_dir() {
        return Err(CliError::graph(format!(
            "{flag} {}: this is a file; {flag} names the folder the outputs are written to (created when missing): give a folder",
            dir.display()
        )));
    }
    std::fs::create_dir_all(dir).map_err(|e| CliError::graph(format!("{flag} {}: cannot create the folder: {e}", dir.display())))?;
    probe_write(dir).map_err(|e| CliError::graph(format!("{flag} {}: cannot write in this folder: {e}", dir.display())))
}

/// Makes sure the file `path` (the value of `flag`, written at the end of the command) can be
/// written, before anything runs: its folder is created when missing; a folder at the path
/// itself, or a folder that cannot be created or written in, is refused.
pub(crate) fn prepare_file(flag: &str, path: &Path) -> Result<(), CliError> {
    if path.is_dir() {
        return Err(CliError::graph(format!("{flag} {}: this is a folder; give the path of a file to write", path.display())));
    }
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)
        .map_err(|e| CliError::graph(format!("{flag} {}: cannot create its folder {}: {e}", path.display(), dir.display())))?;
    probe_write(dir).map_err(|e| CliError::graph(format!("{flag} {}: cannot write in its folder {}: {e}", path.display(), dir.display())))
}

/// Writes and removes a small file in `dir`.
fn probe_write(dir: &Path) -> std::io::Result<()> {
    // Unique per call: two runs in one process (tests, the editor) may probe one folder at once.
    static N: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let probe = dir.join(format!(".relume-write-probe.{}.{n}.tmp", std::process::id()));
    std::fs::write(&probe, b"relume")?;
    std::fs::remove_file(&probe)
}
