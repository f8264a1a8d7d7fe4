//! `relume run`, `relume plan` and `relume check`.

use crate::args::{CheckArgs, RunArgs};
use crate::early_writes::EarlyWrites;
use crate::error::CliError;
use crate::files::{prepare_file, prepare_out_dir, write_refusals};
use crate::interrupt::Watch;
use crate::outputs::planned_outputs;
use crate::progress::Bars;
use relume_base::image::exr_layers::layers_path;
use relume_core::shard::ShardPeers;
use relume_core::{
    make_plan, Graph, GraphErrors, PlanAction, Registry, RunError, RunFiles, RunOptions, ShardMode, WritePolicy, WriteRoots,
};
use std::path::{Path, PathBuf};

/// The ids of the sharded nodes a run of `outputs` needs (what processes other than 0 run).
pub(crate) fn sharded_nodes(reg: &Registry, graph: &Graph, outputs: Option<&[String]>) -> Result<Vec<String>, CliError> {
    let plan = make_plan(graph, reg, outputs).map_err(CliError::graph)?;
    Ok(plan
        .order
        .iter()
        .map(|&i| &graph.nodes[i])
        .filter(|n| reg.node(&n.kind).is_some_and(|k| k.sharded().is_some()))
        .map(|n| n.id.clone())
        .collect())
}

/// Runs the graph; with `peers`, as one process of several sharing its sharded nodes (process
/// 0 runs the whole graph and writes the outputs; the others run only the sharded nodes and
/// what they need, and write nothing).
pub(crate) fn run_graph(reg: &Registry, a: &RunArgs, peers: Option<&dyn ShardPeers>) -> Result<(), CliError> {
    let graph = a.g.load(reg)?;
    no_outputs(&graph)?;
    let writer = peers.is_none_or(|p| p.process() == 0);
    // Everything the run will write is checked before it runs: the output folder, the
    // report's folder, and where the graph's own output files go.
    if writer {
        prepare_out_dir("--out", &a.out)?;
        if let Some(path) = &a.report {
            prepare_file("--report", path)?;
        }
    }
    let writes = a.g.write_policy(&a.out);
    let command = CommandWrites {
        out: writer.then_some(a.out.as_path()),
        exr_layers: a.exr_layers,
        files: a.report.iter().map(|r| (r.clone(), "--report")).collect(),
    };
    refuse_files(reg, &graph, a.g.requested().as_deref(), &writes, &a.g.read_policy(), &command)?;
    let (engine, cache_note) = a.g.engine_for_writing(reg);
    let watch = Watch::new();
    let bars = (!a.quiet).then(Bars::new);
    let (outputs, nodes) = match peers {
        Some(_) if !writer => (Some(Vec::new()), sharded_nodes(reg, &graph, a.g.requested().as_deref())?),
        _ => (a.g.requested(), Vec::new()),
    };
    // The process that writes writes each output as soon as it exists; the others only watch.
    let early = EarlyWrites::new(&a.out, bars.as_ref(), writer);
    let opts = RunOptions {
        outputs,
        nodes,
        shards: peers.map_or(ShardMode::All, ShardMode::Peers),
        observer: Some(&early),
        cancel: watch.token.clone(),
        writes,

        ..Default::default()
    };
    let result = engine.run(&graph, &opts).map_err(|e| run_error(&graph, e));
    drop(opts);
    let finished = result.as_ref().ok().map(|r| early.finish(&r.outputs));
    drop(bars);
    let mut result = result?;
    // What the run says of itself (a disk cache that could not store results, …), once, on
    // stderr; the note of a cache unwritable from the start was said before the run.
    for n in &result.report.notes {
        say_err!("warning: {n}");
    }
    result.report.notes.extend(cache_note);
    if !writer {
        if !a.quiet {
            say_part!("{}", result.report.table());
        }
        return Ok(());
    }
    let mut files = finished.expect("a run that succeeded").map_err(CliError::run)?;
    if a.exr_layers {
        let path =
            relume_base::image::exr_layers::write_run_layers(reg, &graph, &result.outputs, &a.out, a.exr_half).map_err(CliError::run)?;
        files.push(path);
    }
    if let Some(path) = &a.report {
        relume_core::graph::write_atomic(path, result.report.to_json().as_bytes())
            .map_err(|e| CliError::run(format!("cannot write report {}: {e}", path.display())))?;
    }
    if watch.interrupted() {
        return Err(CliError::interrupted("interrupted: the run had finished; its outputs were written"));
    }
    if !a.quiet {
        say_part!("{}", result.report.table());
        for f in files {
            say!("wrote {}", f.display());
        }
        if let Some(path) = &a.report {
            say!("report {}", path.display());
        }
    }
    Ok(())
}

/// The command-line error for a failed run: graph problems and requests over a limit are bad
/// input (exit 2), a node failing is a failed run (exit 1), Ctrl-C exits 130. A node's error
/// names the graph file and the line where the node is written.
/// A graph with nodes but no outputs would run nothing (runs are demand-driven) and say
/// nothing: refused, with what to add.
fn no_outputs(graph: &Graph) -> Result<(), CliError> {
    if graph.outputs.is_empty() && !graph.nodes.is_empty() {
        let file = graph.file.as_ref().map(|f| format!("{}: ", f.display())).unwrap_or_default();
        return Err(CliError::graph(format!(
            "{file}the graph names no outputs, so nothing would run (a run computes what its outputs need); add e.g. `outputs: {{ \"image\": \"{}.image\" }}`",
            graph.nodes.last().map(|n| n.id.as_str()).unwrap_or("node")
        )));
    }
    Ok(())
}

pub(crate) fn run_error(graph: &Graph, e: RunError) -> CliError {
    match e {
        RunError::Graph(g) => CliError::graph(g),
        RunError::Cancelled => CliError::interrupted(
            "interrupted: the run was cancelled; nothing was written (results of the nodes that finished are kept in the cache)",
        ),
        RunError::Node { id, kind, error } => {
            let at = match (&graph.file, graph.node(&id)) {
                (Some(f), Some(n)) => format!("{}:{}:{}: ", f.display(), n.pos.line, n.pos.col),
                (Some(f), None) => format!("{}: ", f.display()),
                _ => String::new(),
            };
            if error.is_over_limit() {
                CliError::graph(format!("{at}node \"{id}\" ({kind}) refused: {error}; ask for less (a smaller size or count)"))
            } else {
                CliError::run(format!("{at}node \"{id}\" ({kind}) failed: {error}"))
            }
        }
    }
}

/// Refuses, before running, output-file parameters of the needed nodes that would write
/// outside the folders allowed (exit 2, naming file, line, node and parameter).
/// What a command writes besides the graph's own output files.
#[derive(Default)]
pub(crate) struct CommandWrites<'a> {
    /// The folder the graph's outputs are written to (`relume run --out`), when they are.
    pub out: Option<&'a Path>,
    /// `--exr-layers`: one multi-layer EXR in `out` too.
    pub exr_layers: bool,
    /// Other files, each with the flag that names it.
    pub files: Vec<(PathBuf, &'static str)>,
}

/// Refuses, before anything runs, a graph output file outside the folders the run may write
/// to, a file a node reads outside the folders it may read from, and any write (a node's
/// output file, an output written to `--out`, `--report`, …) onto a file the run reads or onto
/// another of its writes.
pub(crate) fn refuse_files(
    reg: &Registry,
    graph: &Graph,
    outputs: Option<&[String]>,
    writes: &WritePolicy,
    reads: &WritePolicy,
    command: &CommandWrites,
) -> Result<(), CliError> {
    // A graph the planner refuses is reported by the run itself, with the same message.
    let Ok(plan) = make_plan(graph, reg, outputs) else { return Ok(()) };
    let mut errs = write_refusals(reg, graph, plan.order.iter().map(|&i| graph.nodes[i].id.as_str()), writes);
    let mut files = RunFiles::of_plan(graph, reg, &plan);
    if let Some(out) = command.out {
        for (name, path) in planned_outputs(reg, graph, &plan, out) {
            files.write(&path, &format!("output \"{name}\""));
        }
        if command.exr_layers {
            files.write(&layers_path(graph, out), "--exr-layers");
        }
    }
    for (path, flag) in &command.files {
        files.write(path, flag);
    }
    errs.extend(files.outside(graph, &WriteRoots::new(reads, &graph.base_dir)));
    errs.extend(files.clashes(graph));
    if errs.is_empty() {
        Ok(())
    } else {
        Err(CliError::graph(GraphErrors(errs)))
    }
}

pub(crate) fn plan(reg: &Registry, a: &CheckArgs) -> Result<(), CliError> {
    let graph = a.g.load(reg)?;
    let engine = a.g.engine(reg);
    let lines = engine.explain(&graph, a.g.requested().as_deref()).map_err(CliError::graph)?;
    refuse_files(reg, &graph, a.g.requested().as_deref(), &a.g.write_policy(&a.out), &a.g.read_policy(), &CommandWrites::default())?;
    let (mut run, mut cached) = (0, 0);
    for l in &lines {
        let what = match l.action {
            PlanAction::Run => {
                run += 1;
                "run"
            }
            PlanAction::Cached => {
                cached += 1;
                "cached"
            }
            PlanAction::Skip => "skip",
        };
        say!("{what:<7} {:<20} {:<16} {}", l.id, l.kind, l.reason);
    }
    say!("{run} to run, {cached} cached");
    say!("memory budget {} ({})", relume_core::memory::fmt_bytes(engine.run_budget()), engine.budget_source());
    Ok(())
}

pub(crate) fn check(reg: &Registry, a: &CheckArgs) -> Result<(), CliError> {
    let graph = a.g.load(reg)?;
    let mut errs = graph.unconnected_inputs_of(reg, graph.nodes.iter().map(|n| n.id.as_str()));
    errs.extend(write_refusals(reg, &graph, graph.nodes.iter().map(|n| n.id.as_str()), &a.g.write_policy(&a.out)));
    // The files the planned run reads and writes: each read there, no write onto a read or
    // onto another write (a run would refuse or fail on these only later).
    if let Ok(plan) = make_plan(&graph, reg, a.g.requested().as_deref()) {
        let files = RunFiles::of_plan(&graph, reg, &plan);
        errs.extend(files.outside(&graph, &WriteRoots::new(&a.g.read_policy(), &graph.base_dir)));
        errs.extend(files.missing(&graph));
        errs.extend(files.clashes(&graph));
    }
    if !errs.is_empty() {
        errs.sort_by_key(|e| e.pos.map(|p| (p.line, p.col)).unwrap_or((u32::MAX, 0)));
        return Err(CliError::graph(GraphErrors(errs)));
    }
    no_outputs(&graph)?;
    // The memory model's refusal, as `run` would give it.
    a.g.engine(reg).plan(&graph, a.g.requested().as_deref()).map_err(CliError::graph)?;
    let outs: Vec<_> = graph.outputs.iter().map(|o| o.name.as_str()).collect();
    say!("ok: {} nodes, {} edges, outputs: {}", graph.nodes.len(), graph.edges.len(), outs.join(", "));
    Ok(())
}
