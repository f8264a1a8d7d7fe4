//! `relume shard`: one shard of one sharded node, into the disk cache (a Slurm array task, or
//! any process given `--index`). The gather is a plain `relume run` on the same cache folder:
//! it finds every chunk there and computes only those that are missing.

use crate::args::GraphArgs;
use crate::error::CliError;
use crate::files::prepare_file;
use crate::interrupt::Watch;
use crate::progress::Bars;
use crate::run::run_error;
use clap::Args;
use relume_core::{Graph, Observer, Registry, RunOptions, ShardMode};
use std::path::PathBuf;

#[derive(Args)]
pub(crate) struct ShardArgs {
    #[command(flatten)]
    pub g: GraphArgs,
    /// The sharded node (PathTrace, DirectLight, …) whose shard to run.
    #[arg(long, value_name = "ID")]
    pub node: String,
    /// How many shards the node's chunks are split into (default: $SLURM_ARRAY_TASK_COUNT).
    #[arg(long, value_name = "N")]
    pub shards: Option<u64>,
    /// Which shard to run, 0-based (default: $SLURM_ARRAY_TASK_ID).
    #[arg(long, value_name = "I")]
    pub index: Option<u64>,
    /// Write the JSON run report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// No progress bars and no summary.
    #[arg(long, short)]
    pub quiet: bool,
}

/// The value `v` of the environment variable `name` as a count or index, or what is wrong with it.
fn whole_number(name: &str, v: &str) -> Result<u64, CliError> {
    v.trim().parse().map_err(|_| {
        let why = match v.trim().parse::<i128>() {
            Ok(n) if n < 0 => "must be ≥ 0".to_string(),
            Ok(_) => format!("is too large (at most {})", u64::MAX),
            Err(_) => "is not a whole number".to_string(),
        };
        CliError::graph(format!("{name}={v} {why}"))
    })
}

/// The shard's index and count from the flags or Slurm's environment.
pub(crate) fn shard_place(index: Option<u64>, shards: Option<u64>) -> Result<(u64, u64), CliError> {
    let env = |name: &str| -> Result<Option<u64>, CliError> {
        match std::env::var(name) {
            Ok(v) => whole_number(name, &v).map(Some),
            Err(_) => Ok(None),
        }
    };
    let index = match index {
        Some(i) => i,
        None => env("SLURM_ARRAY_TASK_ID")?
            .ok_or_else(|| CliError::graph("which shard? give --index I, or run inside a Slurm array job (SLURM_ARRAY_TASK_ID)"))?,
    };
    let count = match shards {
        Some(n) => n,
        None => env("SLURM_ARRAY_TASK_COUNT")?
            .ok_or_else(|| CliError::graph("how many shards? give --shards N, or run inside a Slurm array job (SLURM_ARRAY_TASK_COUNT)"))?,
    };
    if count == 0 {
        return Err(CliError::graph("--shards must be at least 1"));
    }
    if index >= count {
        return Err(CliError::graph(format!("shard index {index} is out of range: there are {count} shards (0 to {})", count - 1)));
    }
    Ok((index, count))
}

/// Refuses a node id that is not in the graph or not sharded, naming the sharded ones.
pub(crate) fn check_sharded_node(reg: &Registry, graph: &Graph, id: &str) -> Result<(), CliError> {
    let sharded: Vec<&str> =
        graph.nodes.iter().filter(|n| reg.node(&n.kind).is_some_and(|k| k.sharded().is_some())).map(|n| n.id.as_str()).collect();
    let list = if sharded.is_empty() { "the graph has none".to_string() } else { format!("sharded nodes: {}", sharded.join(", ")) };
    match graph.node(id) {
        None => Err(CliError::graph(format!("--node {id}: no node \"{id}\" in the graph ({list})"))),
        Some(n) if !sharded.contains(&id) => {
            Err(CliError::graph(format!("--node {id}: {} does not split its work into shards ({list})", n.kind)))
        }
        Some(_) => Ok(()),
    }
}

pub(crate) fn shard(reg: &Registry, a: &ShardArgs) -> Result<(), CliError> {
    let graph = a.g.load(reg)?;
    let (index, count) = shard_place(a.index, a.shards)?;
    check_sharded_node(reg, &graph, &a.node)?;
    if let Some(path) = &a.report {
        prepare_file("--report", path)?;
    }
    let (engine, cache_note) = a.g.engine_for_writing(reg);
    let Some(disk) = engine.disk() else {
        return Err(CliError::graph("a shard's results are kept only in the disk cache: drop --no-disk-cache and give --cache DIR"));
    };
    if let Some(why) = cache_note {
        return Err(CliError::run(format!("a shard needs a disk cache it can write: {why}")));
    }
    let cache_dir = disk.dir().to_path_buf();
    let watch = Watch::new();
    let bars = (!a.quiet).then(Bars::new);
    let opts = RunOptions {
        outputs: Some(Vec::new()),
        nodes: vec![a.node.clone()],
        shards: ShardMode::One { node: &a.node, index, count },
        observer: bars.as_ref().map(|b| b as &dyn Observer),
        cancel: watch.token.clone(),
        writes: a.g.write_policy(&cache_dir),

        ..Default::default()
    };
    let result = engine.run(&graph, &opts).map_err(|e| run_error(&graph, e));
    drop(bars);
    let result = result?;
    if let Some(path) = &a.report {
        relume_core::graph::write_atomic(path, result.report.to_json().as_bytes())
            .map_err(|e| CliError::run(format!("cannot write report {}: {e}", path.display())))?;
    }
    if !a.quiet {
        let node = result.report.node(&a.node).expect("the shard's node ran or was cached");
        match &node.shards {
            Some(s) => say!(
                "shard {index} of {count} of \"{}\": {} of {} chunks ({} cached, {} ran in {:.1} s) into {}",
                a.node,
                s.here,
                s.chunks,
                s.cached,
                s.ran,
                s.ran_ms / 1e3,
                cache_dir.display()
            ),
            None => say!("\"{}\" is already in the cache {} whole: nothing to do", a.node, cache_dir.display()),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::whole_number;

    #[test]
    fn a_slurm_index_says_what_is_wrong_with_it() {
        assert_eq!(whole_number("SLURM_ARRAY_TASK_ID", " 7 ").unwrap(), 7);
        let msg = |v: &str| whole_number("SLURM_ARRAY_TASK_ID", v).unwrap_err().msg;
        assert_eq!(msg("-1"), "SLURM_ARRAY_TASK_ID=-1 must be ≥ 0");
        assert_eq!(msg("99999999999999999999"), "SLURM_ARRAY_TASK_ID=99999999999999999999 is too large (at most 18446744073709551615)");
        assert_eq!(msg("x1"), "SLURM_ARRAY_TASK_ID=x1 is not a whole number");
    }
}
