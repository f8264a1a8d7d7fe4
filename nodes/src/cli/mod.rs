//! The `relume` command line: run, plan, check, nodes, sweep.

mod catalog;
mod outputs;
mod plot;
mod progress;
mod run;
mod sweep;

use clap::{Args, Parser, Subcommand};
use relume_core::{Graph, Registry};
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
    Plan(GraphArgs),
    /// Load and type-check a graph without running it.
    Check(GraphArgs),
    /// List node kinds with their ports and parameter schemas.
    Nodes {
        /// Show only this kind.
        kind: Option<String>,
    },
    /// Run a graph once per combination of --vary values (one engine, cache shared) and write
    /// error against time as CSV and a log-log plot, optionally with a --baseline curve.
    Sweep(sweep::SweepArgs),
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
}

/// Entry point of the binary; returns the process exit code.
pub fn main() -> i32 {
    main_from(std::env::args_os())
}

/// Runs the command line on the given arguments (the first is the program name).
pub fn main_from<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
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
    };
    match result {
        Ok(()) => 0,
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

    pub(crate) fn engine(&self, reg: &Registry) -> relume_core::Engine {
        let engine = relume_core::Engine::new(reg.clone());
        if self.no_disk_cache {
            return engine;
        }
        let dir = self
            .cache
            .clone()
            .or_else(|| std::env::var_os("RELUME_CACHE").map(PathBuf::from))
            .unwrap_or_else(|| Path::new(".relume-cache").to_path_buf());
        let policy = if self.cache_all { relume_core::DiskPolicy::Always } else { relume_core::DiskPolicy::WhenCheaperToLoad };
        engine.with_disk_cache(dir).with_disk_policy(policy)
    }

    pub(crate) fn requested(&self) -> Option<Vec<String>> {
        (!self.outputs.is_empty()).then(|| self.outputs.clone())
    }
}
