//! The command line's shared arguments: the graph and how to run it (`GraphArgs`), `check` /
//! `plan` (`CheckArgs`), `run` (`RunArgs`) and its multi-process options (`ClusterArgs`), and
//! what they build: the graph with its `--set`s, the engine and its disk cache.

use crate::error::CliError;
use clap::Args;
use relume_core::{Graph, Registry, WritePolicy};
use std::path::{Path, PathBuf};

#[derive(Args, Clone)]
pub(crate) struct GraphArgs {
    /// The graph file (.ron).
    pub(crate) graph: PathBuf,
    /// Override a parameter: --set node.param=value (repeatable).
    #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
    pub(crate) sets: Vec<String>,
    /// Produce only these outputs (repeatable; default: all).
    #[arg(long = "output", value_name = "NAME")]
    pub(crate) outputs: Vec<String>,
    /// Disk cache folder (default: $RELUME_CACHE or .relume-cache).
    #[arg(long)]
    pub(crate) cache: Option<PathBuf>,
    /// Do not read or write the disk cache.
    #[arg(long)]
    pub(crate) no_disk_cache: bool,
    /// Write every result to the disk cache, not only those that cost more to compute than
    /// to load (a cache that other machines or later sweeps must not recompute anything from).
    #[arg(long)]
    pub(crate) cache_all: bool,
    /// What one run may hold in memory at once, e.g. `8G` or `512M` (default: 80 % of the
    /// smallest of physical memory, the cgroup's limit, `ulimit -v`/`-d` and Slurm's --mem;
    /// `relume plan` says which). A run whose estimate is larger is refused before anything
    /// runs.
    #[arg(long, value_name = "BYTES", value_parser = parse_budget)]
    pub(crate) memory_budget: Option<u64>,
    /// Threads each node's inner loops may use (default: one per core; at most
    /// `MAX_THREADS`).
    #[arg(long, value_name = "N", value_parser = parse_threads)]
    pub(crate) threads: Option<usize>,
    /// Let the graph's output-file parameters (SaveImage's `path`) write anywhere. Without
    /// it they may write only below the graph file's folder and the output folder (--out): a
    /// graph from someone else cannot overwrite files elsewhere.
    #[arg(long)]
    pub(crate) allow_writes_anywhere: bool,
    /// A folder the graph's nodes may read files from besides the graph file's own (repeat
    /// for several): input images, scenes and the meshes and maps they name.
    #[arg(long, value_name = "DIR")]
    pub(crate) read_from: Vec<PathBuf>,
    /// Let the graph's nodes read files anywhere. Without it they may read only below the
    /// graph file's folder and the folders given with --read-from: a graph from someone else
    /// cannot read (and quote in an error) a file elsewhere.
    #[arg(long)]
    pub(crate) allow_reads_anywhere: bool,
}

/// `relume check` and `relume plan`.
#[derive(Args)]
pub(crate) struct CheckArgs {
    #[command(flatten)]
    pub(crate) g: GraphArgs,
    /// The output folder a run would use (output-file parameters are checked against it).
    #[arg(long, default_value = "out")]
    pub(crate) out: PathBuf,
}

#[derive(Args)]
pub(crate) struct RunArgs {
    #[command(flatten)]
    pub(crate) g: GraphArgs,
    /// Folder for the outputs.
    #[arg(long, default_value = "out")]
    pub(crate) out: PathBuf,
    /// Write the JSON run report here.
    #[arg(long)]
    pub(crate) report: Option<PathBuf>,
    /// No progress bars and no table.
    #[arg(long, short)]
    pub(crate) quiet: bool,
    /// Also write every image output of the run as a layer of one multi-layer EXR,
    /// `OUT/GRAPH.layers.exr` (`image.R/G/B`, `variance.R/G/B`, …), with the graph, each
    /// layer's node and its parameters in the header.
    #[arg(long)]
    pub(crate) exr_layers: bool,
    /// Half floats in the multi-layer EXR (default: full 32-bit floats).
    #[arg(long, requires = "exr_layers")]
    pub(crate) exr_half: bool,
    #[command(flatten)]
    pub(crate) cluster: ClusterArgs,
}

#[derive(Args, Clone, Default)]
pub(crate) struct ClusterArgs {
    /// Run as one of several processes sharing the sharded nodes: HOSTFILE lists one
    /// `host:port` per line, in process order (`#` comments allowed); give --process too.
    #[arg(long, value_name = "HOSTFILE", requires = "process")]
    pub workers: Option<PathBuf>,
    /// This process's index in HOSTFILE, 0-based (process 0 writes the outputs).
    #[arg(long, value_name = "I", requires = "workers")]
    pub process: Option<usize>,
    /// Start N processes on this machine (127.0.0.1) sharing the sharded nodes and the cache
    /// folder; re-run them when one dies (--retries), resuming from the cache.
    #[arg(long, value_name = "N", conflicts_with = "workers")]
    pub processes: Option<usize>,
    /// Every process sees the same --cache folder (a network file system): partial results
    /// travel between processes as cache keys instead of bytes.
    #[arg(long)]
    pub shared_cache: bool,
    /// Seconds to wait for every process of the host file to connect.
    #[arg(long, value_name = "SECONDS", default_value_t = 60)]
    pub connect_timeout: u64,
    /// With --processes: how many times to re-run after a process died.
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub retries: u32,
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
            engine = engine.with_run_budget(b, "--memory-budget");
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
            say_err!(
                "warning: the disk cache {} ({from}) cannot be written: {why}; results will not be kept on disk for later runs \
                 (point --cache or RELUME_CACHE at a writable folder, or pass --no-disk-cache)",
                dir.display()
            );
            format!("the disk cache {} ({from}) could not be written: {why}; results were not kept on disk", dir.display())
        });
        (engine, note)
    }

    /// The disk cache folder and where it came from; `None` with --no-disk-cache.
    pub(crate) fn cache_dir(&self) -> Option<(PathBuf, &'static str)> {
        crate::cache_folder::cache_dir(self.cache.as_deref(), self.no_disk_cache)
    }

    pub(crate) fn disk_policy(&self) -> relume_core::DiskPolicy {
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

    /// Where the graph's nodes may read files: the graph's folder and the --read-from folders,
    /// or anywhere with --allow-reads-anywhere.
    pub(crate) fn read_policy(&self) -> WritePolicy {
        if self.allow_reads_anywhere {
            WritePolicy::Anywhere
        } else {
            WritePolicy::Within(self.read_from.clone())
        }
    }

    pub(crate) fn requested(&self) -> Option<Vec<String>> {
        (!self.outputs.is_empty()).then(|| self.outputs.clone())
    }
}

/// The most threads `--threads` takes: far past any machine's cores (threads beyond them
/// only add start-up and scheduling), and few enough that starting them stays quick.
pub(crate) const MAX_THREADS: usize = 1024;

/// `--threads`: 1 to `MAX_THREADS`.
fn parse_threads(s: &str) -> Result<usize, String> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    match s.trim().parse::<usize>() {
        Ok(0) => Err("at least 1 thread".into()),
        Ok(n) if n <= MAX_THREADS => Ok(n),
        Ok(_) => {
            Err(format!("at most {MAX_THREADS} threads (this machine has {cores} cores; more threads than cores make nothing faster)"))
        }
        Err(_) if !s.trim().is_empty() && s.trim().bytes().all(|b| b.is_ascii_digit()) => {
            Err(format!("too large: at most {MAX_THREADS} threads (this machine has {cores} cores)"))
        }
        Err(_) => Err(format!("`{s}` is not a whole number of threads")),
    }
}

/// `--memory-budget`: `8G`, `512MiB`, `1.5g` or bytes.
fn parse_budget(s: &str) -> Result<u64, String> {
    relume_core::memory::parse_bytes(s).ok_or_else(|| format!("`{s}` is not a size (write e.g. 8G, 512M or a number of bytes)"))
}

/// The command line this process was started with (`--processes` starts copies of it).
pub(crate) static COMMAND_LINE: std::sync::OnceLock<Vec<std::ffi::OsString>> = std::sync::OnceLock::new();

pub(crate) fn command_line() -> Vec<std::ffi::OsString> {
    COMMAND_LINE.get().cloned().unwrap_or_else(|| std::env::args_os().collect())
}
