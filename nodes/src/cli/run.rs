//! `relume run`, `relume plan` and `relume check`.

use super::{outputs::write_outputs, progress::Bars, CliError, GraphArgs, RunArgs};
use relume_core::{Observer, PlanAction, Registry, RunError, RunOptions};

pub(crate) fn run(reg: &Registry, a: &RunArgs) -> Result<(), CliError> {
    let graph = a.g.load(reg)?;
    let engine = a.g.engine(reg);
    let bars = (!a.quiet).then(Bars::new);
    let opts = RunOptions { outputs: a.g.requested(), observer: bars.as_ref().map(|b| b as &dyn Observer), ..Default::default() };
    let result = engine.run(&graph, &opts).map_err(|e| match e {
        RunError::Graph(g) => CliError::graph(g),
        other => CliError::run(other),
    })?;
    drop(bars);
    let mut files = write_outputs(&a.out, &result.outputs).map_err(CliError::run)?;
    if a.exr_layers {
        let path = crate::image::exr_layers::write_run_layers(reg, &graph, &result.outputs, &a.out, a.exr_half).map_err(CliError::run)?;
        files.push(path);
    }
    if let Some(path) = &a.report {
        relume_core::graph::write_atomic(path, result.report.to_json().as_bytes())
            .map_err(|e| CliError::run(format!("cannot write report {}: {e}", path.display())))?;
    }
    if !a.quiet {
        print!("{}", result.report.table());
        for f in files {
            println!("wrote {}", f.display());
        }
        if let Some(path) = &a.report {
            println!("report {}", path.display());
        }
    }
    Ok(())
}

pub(crate) fn plan(reg: &Registry, a: &GraphArgs) -> Result<(), CliError> {
    let graph = a.load(reg)?;
    let engine = a.engine(reg);
    let lines = engine.explain(&graph, a.requested().as_deref()).map_err(CliError::graph)?;
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
        println!("{what:<7} {:<20} {:<16} {}", l.id, l.kind, l.reason);
    }
    println!("{run} to run, {cached} cached");
    Ok(())
}

pub(crate) fn check(reg: &Registry, a: &GraphArgs) -> Result<(), CliError> {
    let graph = a.load(reg)?;
    let mut errs = Vec::new();
    for n in &graph.nodes {
        errs.extend(graph.unconnected_inputs(reg, &n.id));
    }
    if !errs.is_empty() {
        return Err(CliError::graph(relume_core::GraphErrors(errs).to_string()));
    }
    let outs: Vec<_> = graph.outputs.iter().map(|o| o.name.as_str()).collect();
    println!("ok: {} nodes, {} edges, outputs: {}", graph.nodes.len(), graph.edges.len(), outs.join(", "));
    Ok(())
}
