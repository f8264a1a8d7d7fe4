//! `relume run --workers HOSTFILE --process I` and `relume run --processes N`: several
//! processes (on workstations, or on one machine) share the work of the graph's sharded nodes
//! over timely-dataflow. Every process loads the same graph; each computes its share of every
//! sharded node's chunks, and the partials reach the other processes (as bytes, or as cache
//! keys with `--shared-cache`). Process 0 runs the whole graph and writes the outputs.
//!
//! timely stops every process when one dies; `--processes` then re-runs them, and the shard
//! cache makes that a resume: chunks already in the cache are not computed again.

mod launch;
mod net;
mod peers;

pub(crate) use launch::launch;

use crate::args::RunArgs;
use crate::error::CliError;
use crate::run::run_graph;
use relume_core::Registry;
use std::sync::Arc;
use std::time::Duration;

/// The addresses of a host file: one `host:port` per line, blank lines and `#` comments
/// skipped.
pub(crate) fn read_hostfile(path: &std::path::Path) -> Result<Vec<String>, CliError> {
    let bytes = relume_core::read_input(path).map_err(|e| CliError::graph(format!("--workers {}: {e}", path.display())))?;
    let text = String::from_utf8(bytes).map_err(|_| CliError::graph(format!("--workers {}: not a text file", path.display())))?;
    let mut hosts = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let ok = line.rsplit_once(':').is_some_and(|(h, p)| !h.is_empty() && p.parse::<u16>().is_ok_and(|p| p > 0));
        if !ok {
            return Err(CliError::graph(format!("--workers {}:{}: `{line}` is not host:port", path.display(), n + 1)));
        }
        hosts.push(line.to_string());
    }
    if hosts.is_empty() {
        return Err(CliError::graph(format!("--workers {}: no host:port lines", path.display())));
    }
    Ok(hosts)
}

/// One process of a `--workers` run.
pub(crate) fn run_process(reg: &Registry, a: &RunArgs) -> Result<(), CliError> {
    let c = &a.cluster;
    let (path, process) = (c.workers.as_ref().expect("--workers"), c.process.expect("--process"));
    let hosts = read_hostfile(path)?;
    if process >= hosts.len() {
        return Err(CliError::graph(format!(
            "--process {process}: {} lists {} processes (0 to {})",
            path.display(),
            hosts.len(),
            hosts.len() - 1
        )));
    }
    // Load and check the graph before connecting: a bad graph fails at once, in every process.
    a.g.load(reg)?;
    let bridge = Arc::new(peers::Bridge::new(process, hosts.len(), c.shared_cache));
    let net = net::start(hosts, process, bridge.clone(), Duration::from_secs(c.connect_timeout)).map_err(CliError::run)?;
    let result = run_graph(reg, a, Some(bridge.as_ref()));
    match (result, net.finish(Duration::from_secs(c.connect_timeout.max(30)))) {
        (Err(e), _) => Err(e),
        (Ok(()), Err(why)) => {
            Err(CliError::run(format!("process {process}: the run finished, but shutting down with the others failed: {why}")))
        }
        (Ok(()), Ok(())) => Ok(()),
    }
}
