//! The `relume` command line: run, plan, check, nodes, sweep, shard, slurm.

mod catalog;
mod cluster;
mod interrupt;
mod outputs;
mod plot;
mod progress;
mod run;
mod shard;
mod slurm;
mod sweep;

use clap::{Args, Parser, Subcommand};
use relume_core::{Graph, GraphError, ParamKind, ParamValue, Registry, WritePolicy, WriteRoots};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(name = "relume", version, about = "Data-flow node graphs for global-illumination research")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run a graph: write every image output as OUT/NAME.exr and OUT/NAME.png, print a table.
    Run(RunArgs),
    /// Show what a run would do: which nodes would run, which are cached, and why.
    Plan(CheckArgs),
    /// Load and type-check a graph without running it.
    Check(CheckArgs),
    /// List node kinds with their ports and parameter schemas.
    Nodes {
        /// Show only this kind.
        kind: Option<String>,
    },
    /// Run a graph once per combination of --vary values (one engine, cache shared) and write
    /// error against time as CSV and a log-log plot, optionally with a --baseline curve.
    Sweep(sweep::SweepArgs),
    /// Run one shard of a sharded node (PathTrace, DirectLight, …) into the disk cache: the
    /// shard given by --index/--shards or by Slurm's SLURM_ARRAY_TASK_ID/COUNT. A later
    /// `relume run` on the same cache gathers the shards.
    Shard(shard::ShardArgs),
    /// Write (and with --submit, submit) a Slurm array job running the shards of a node, and
    /// a gather job that runs the graph once they have all succeeded.
    Slurm(slurm::SlurmArgs),
}

#[derive(Args, Clone)]
pub(crate) struct GraphArgs {
    /// The graph file (.ron).
    graph: PathBuf,
    /// Override a parameter: --set node.param=value (repeatable).
    #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
    sets: Vec<String>,
    /// Produce only these outputs (repeatable; default: all).
    #[arg(long = "output", value_name = "NAME")]
    outputs: Vec<String>,
    /// Disk cache folder (default: $RELUME_CACHE or .relume-cache).
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Do not read or write the disk cache.
    #[arg(long)]
    no_disk_cache: bool,
    /// Write every result to the disk cache, not only those that cost more to compute than
    /// to load (a cache that other machines or later sweeps must not recompute anything from).
    #[arg(long)]
    cache_all: bool,
    /// What one run may hold in memory at once, e.g. `8G` or `512M` (default: 80 % of the
    /// machine's memory). A run whose estimate is larger is refused before anything runs.
    #[arg(long, value_name = "BYTES", value_parser = parse_budget)]
    memory_budget: Option<u64>,
    /// Threads each node's inner loops may use (default: one per core).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// Let the graph's output-file parameters (SaveImage's `path`) write anywhere. Without
    /// it they may write only below the graph file's folder and the output folder (--out): a
    /// graph from someone else cannot overwrite files elsewhere.
    #[arg(long)]
    allow_writes_anywhere: bool,
}

/// `relume check` and `relume plan`.
#[derive(Args)]
pub(crate) struct CheckArgs {
    #[command(flatten)]
    g: GraphArgs,
    /// The output folder a run would use (output-file parameters are checked against it).
    #[arg(long, default_value = "out")]
    out: PathBuf,
}

#[derive(Args)]
pub(crate) struct RunArgs {
    #[command(flatten)]
    g: GraphArgs,
    /// Folder for the outputs.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// Write the JSON run report here.
    #[arg(long)]
    report: Option<PathBuf>,
    /// No progress bars and no table.
    #[arg(long, short)]
    quiet: bool,
    /// Also write every image output of the run as a layer of one multi-layer EXR,
    /// `OUT/GRAPH.layers.exr` (`image.R/G/B`, `variance.R/G/B`, …), with the graph, each
    /// layer's node and its parameters in the header.
    #[arg(long)]
    exr_layers: bool,
    /// Half floats in the multi-layer EXR (default: full 32-bit floats).
    #[arg(long, requires = "exr_layers")]
    exr_half: bool,
    #[command(flatten)]
    cluster: cluster::ClusterArgs,
}

/// An error for the user and the exit code that goes with it.
pub(crate) struct CliError {
    pub code: i32,
    pub msg: String,
}

impl CliError {
    pub fn graph(msg: impl ToString) -> Self {
        CliError { code: 2, msg: msg.to_string() }
    }
    pub fn run(msg: impl ToString) -> Self {
        CliError { code: 1, msg: msg.to_string() }
    }
    /// Stopped by Ctrl-C (exit code 130, as a shell reports SIGINT).
    pub fn interrupted(msg: impl ToString) -> Self {
        CliError { code: interrupt::EXIT_CODE, msg: msg.to_string() }
    }
}

/// The command line this process was started with (`--processes` starts copies of it).
static COMMAND_LINE: std::sync::OnceLock<Vec<std::ffi::OsString>> = std::sync::OnceLock::new();

pub(crate) fn command_line() -> Vec<std::ffi::OsString> {
    COMMAND_LINE.get().cloned().unwrap_or_else(|| std::env::args_os().collect())
}

/// Entry point of the binary; returns the process exit code.
pub fn main() -> i32 {
    interrupt::install();
    main_from(std::env::args_os())
}

/// Runs the command line on the given arguments (the first is the program name).
pub fn main_from<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let args: Vec<std::ffi::OsString> = args.into_iter().map(Into::into).collect();
    let _ = COMMAND_LINE.set(args.clone());
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { 2 } else { 0 };
        }
    };
    let reg = crate::registry();
    let result = match cli.cmd {
        Cmd::Run(a) => run::run(&reg, &a),
        Cmd::Plan(a) => run::plan(&reg, &a),
        Cmd::Check(a) => run::check(&reg, &a),
        Cmd::Nodes { kind } => catalog::print(&reg, kind.as_deref()),
        Cmd::Sweep(a) => sweep::sweep(&reg, &a),
        Cmd::Shard(a) => shard::shard(&reg, &a),
        Cmd::Slurm(a) => slurm::slurm(&reg, &a),
    };
    match result {
        Ok(()) => 0,
        Err(e) if e.code == interrupt::EXIT_CODE => {
            eprintln!("{}", e.msg);
            e.code
        }
        Err(e) => {
            eprintln!("error: {}", e.msg);
            e.code
        }
    }
}

impl GraphArgs {
    /// Loads the graph and applies `--set` overrides.
    pub(crate) fn load(&self, reg: &Registry) -> Result<Graph, CliError> {
        let mut g = Graph::load(&self.graph, reg).map_err(CliError::graph)?;
        for s in &self.sets {
            let (lhs, value) = s.split_once('=').ok_or_else(|| CliError::graph(format!("--set {s}: expected node.param=value")))?;
            g.set_param_text(reg, lhs, value).map_err(|e| CliError::graph(format!("--set {s}: {e}")))?;
        }
        Ok(g)
    }

    /// The engine for `plan`: reads the disk cache, writes nothing.
    pub(crate) fn engine(&self, reg: &Registry) -> relume_core::Engine {
        let mut engine = relume_core::Engine::new(reg.clone());
        if let Some(b) = self.memory_budget {
            engine = engine.with_run_budget(b);
        }
        if let Some(t) = self.threads {
            engine = engine.with_threads(t);
        }
        match self.cache_dir() {
            None => engine,
            Some((dir, _)) => engine.with_disk_cache(dir).with_disk_policy(self.disk_policy()),
        }
    }

    /// The engine for `run` and `sweep`, and the note for the report when its disk cache
    /// cannot be written: said once on stderr, before anything runs (results are then kept in
    /// memory only; entries already there are still read).
    pub(crate) fn engine_for_writing(&self, reg: &Registry) -> (relume_core::Engine, Option<String>) {
        let engine = self.engine(reg);
        let Some((dir, from)) = self.cache_dir() else { return (engine, None) };
        let problem = engine.disk().map(|d| d.check_writable()).and_then(Result::err);
        let note = problem.map(|why| {
            eprintln!(
                "warning: the disk cache {} ({from}) cannot be written: {why}; results will not be kept on disk for later runs \
                 (point --cache or RELUME_CACHE at a writable folder, or pass --no-disk-cache)",
                dir.display()
            );
            format!("the disk cache {} ({from}) could not be written: {why}; results were not kept on disk", dir.display())
        });
        (engine, note)
    }

    /// The disk cache folder and where it came from; `None` with --no-disk-cache.
    fn cache_dir(&self) -> Option<(PathBuf, &'static str)> {
        if self.no_disk_cache {
            return None;
        }
        Some(match (&self.cache, std::env::var_os("RELUME_CACHE")) {
            (Some(d), _) => (d.clone(), "from --cache"),
            (None, Some(d)) => (PathBuf::from(d), "from RELUME_CACHE"),
            (None, None) => (Path::new(".relume-cache").to_path_buf(), "the default"),
        })
    }

    fn disk_policy(&self) -> relume_core::DiskPolicy {
        if self.cache_all {
            relume_core::DiskPolicy::Always
        } else {
            relume_core::DiskPolicy::WhenCheaperToLoad
        }
    }

    /// Where the graph's output-file parameters may write: the graph's folder and `out`, or
    /// anywhere with --allow-writes-anywhere.
    pub(crate) fn write_policy(&self, out: &Path) -> WritePolicy {
        if self.allow_writes_anywhere {
            WritePolicy::Anywhere
        } else {
            WritePolicy::Within(vec![out.to_path_buf()])
        }
    }

    pub(crate) fn requested(&self) -> Option<Vec<String>> {
        (!self.outputs.is_empty()).then(|| self.outputs.clone())
    }
}

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

/// `--memory-budget`: `8G`, `512MiB`, `1.5g` or bytes.
fn parse_budget(s: &str) -> Result<u64, String> {
    relume_core::memory::parse_bytes(s).ok_or_else(|| format!("`{s}` is not a size (write e.g. 8G, 512M or a number of bytes)"))
}
