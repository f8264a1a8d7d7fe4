//! The `relume` command line: run, plan, check, nodes, sweep, results, shard, slurm.
//!
//! [`registry`] holds every node kind; a graph file loads against it and runs through an
//! engine as `relume run` runs it (without the files and the table):
//!
//! ```
//! use relume_core::{Engine, Graph, RunOptions};
//!
//! let reg = relume_cli::registry();
//! let g = Graph::load(std::path::Path::new("../../graphs/filters.ron"), &reg).unwrap();
//! let run = Engine::new(reg).run(&g, &RunOptions::default()).unwrap();
//! assert!(run.output("image").is_some());
//! ```

#[macro_use]
mod terminal;

mod args;
mod cache_folder;
mod catalog;
mod catalog_markdown;
mod cluster;
mod early_writes;
mod error;
mod files;
mod interrupt;
mod outputs;
mod plot;
mod progress;
mod provenance;
mod results;
mod run;
mod shard;
mod slurm;
mod sweep;

pub use cache_folder::cache_dir;

/// A registry with every node kind: the base's and each pipeline's.
pub fn registry() -> Registry {
    let mut r = relume_base::registry();
    relume_pbgi::register(&mut r);
    relume_ptt::register(&mut r);
    relume_relight::register(&mut r);
    relume_volume::register(&mut r);
    r
}

use args::{CheckArgs, RunArgs, COMMAND_LINE};
use clap::{Parser, Subcommand};
use relume_core::Registry;

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
        /// Print the catalogue as one Markdown page (docs/reference/nodes.md is this output).
        #[arg(long)]
        markdown: bool,
    },
    /// Run a graph once per combination of --vary values (one engine, cache shared) and write
    /// error against time as CSV and a log-log plot, optionally with a --baseline curve.
    Sweep(sweep::SweepArgs),
    /// Draw the book's results pages from the committed sweeps: each sweep's plot and table
    /// from its CSV and the command that measured it (`--check`: fail where they differ).
    Results(results::ResultsArgs),
    /// Run one shard of a sharded node (PathTrace, DirectLight, …) into the disk cache: the
    /// shard given by --index/--shards or by Slurm's SLURM_ARRAY_TASK_ID/COUNT. A later
    /// `relume run` on the same cache gathers the shards.
    Shard(shard::ShardArgs),
    /// Write (and with --submit, submit) a Slurm array job running the shards of a node, and
    /// a gather job that runs the graph once they have all succeeded.
    Slurm(slurm::SlurmArgs),
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
        Cmd::Run(a) if a.cluster.processes.is_some() => cluster::launch(&reg, &a),
        Cmd::Run(a) if a.cluster.workers.is_some() => cluster::run_process(&reg, &a),
        Cmd::Run(a) => run::run_graph(&reg, &a, None),
        Cmd::Plan(a) => run::plan(&reg, &a),
        Cmd::Check(a) => run::check(&reg, &a),
        Cmd::Nodes { kind, markdown } => catalog::print(&reg, kind.as_deref(), markdown),
        Cmd::Sweep(a) => sweep::sweep(&reg, &a),
        Cmd::Results(a) => results::results(&a),
        Cmd::Shard(a) => shard::shard(&reg, &a),
        Cmd::Slurm(a) => slurm::slurm(&reg, &a),
    };
    match result {
        Ok(()) => 0,
        Err(e) if e.code == interrupt::EXIT_CODE => {
            say_err!("{}", e.msg);
            e.code
        }
        Err(e) => {
            say_err!("error: {}", e.msg);
            e.code
        }
    }
}
