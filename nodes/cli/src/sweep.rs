//! `relume sweep`: runs a graph once per combination of parameter values, all through one
//! engine so every variant reuses what earlier ones computed, and writes error against time
//! as CSV and as a log-log plot, optionally next to a baseline's convergence curve (a numeric
//! parameter such as a path tracer's samples per pixel at 1, 2, 4, …). `--x` plots against a
//! varied parameter or a metric instead of time and `--series` draws one line per value of a
//! varied parameter (`axes.rs`), so error-against-rank and error-against-bytes figures come
//! from the same sweep.

mod axes;
pub(crate) mod csv_table;
mod replay;
mod rows;

use crate::args::GraphArgs;
use crate::error::CliError;
use crate::files::{prepare_file, prepare_out_dir};
use crate::interrupt::Watch;
use crate::plot::plot_log_log;
use crate::progress::Bars;
use crate::run::{refuse_files, run_error, CommandWrites};
pub(crate) use axes::{Plotted, XAxis};
use clap::Args;
use csv_table::{csv_line, CsvTable};
use relume_core::graph::{Output, PortRef};
use relume_core::{make_plan, Graph, Observer, ParamKind, Registry, RunOptions, RunReport};
pub(crate) use replay::replay;
use rows::{Row, Series, TimeAxis, Vary};
use std::collections::BTreeSet;
use std::path::PathBuf;

#[derive(Args)]
pub(crate) struct SweepArgs {
    #[command(flatten)]
    g: GraphArgs,
    /// Values to sweep: --vary node.param=a,b,c (repeatable; every combination runs, the first
    /// --vary changing slowest). Tuples keep their commas: --vary clean.color=(1,0,0),(0,1,0).
    /// Several parameters joined by `+` take the same values together:
    /// --vary tucker.n_wi+tucker.n_wo=4,8.
    #[arg(long = "vary", value_name = "NODE.PARAM=A,B,..", required_unless_present = "baseline")]
    varies: Vec<String>,
    /// Also run this numeric parameter at 1, 2, 4, … up to --baseline-max (the --vary
    /// parameters at their graph values): the baseline's own error-vs-time curve.
    #[arg(long, value_name = "NODE.PARAM")]
    baseline: Option<String>,
    /// Largest baseline value.
    #[arg(long, value_name = "N", default_value_t = 256)]
    baseline_max: i64,
    /// A speed-up at equal error the method should reach over the baseline (at least 1):
    /// the plot draws the baseline's curve at 1/GOAL of its times, dashed (a method point on
    /// or left of it reaches the goal), and `relume results` says in the headline row whether
    /// it is met or by how much it falls short.
    #[arg(long, value_name = "GOAL", requires = "baseline", value_parser = parse_goal)]
    goal: Option<f64>,
    /// Folder for the CSV and the plot.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// CSV file (default: OUT/sweep.csv).
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Plot file, PNG (default: the CSV's path with extension .png, i.e. OUT/sweep.png).
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Error metric on the plot's y axis.
    #[arg(long, default_value = "rel_mse")]
    metric: String,
    /// Node whose metric is plotted (default: the first node, in graph order, reporting it).
    #[arg(long, value_name = "NODE")]
    error_node: Option<String>,
    /// Node whose metric is plotted for the baseline rows (default: the same as --error-node);
    /// the baseline often has its own error node (a path tracer against the same reference).
    #[arg(long, value_name = "NODE", requires = "baseline")]
    baseline_error_node: Option<String>,
    /// x axis: `pipeline` = what the plotted image costs in full (the compute time of every
    /// node feeding the error node's `image` but not its `reference`, cached or not);
    /// `ran` = the wall time of the nodes that ran in the variant (cached nodes cost 0).
    #[arg(long, value_enum, default_value = "pipeline")]
    time: TimeAxis,
    /// x axis of the plot instead of time: a CSV column, i.e. a varied parameter
    /// (`tucker.n_wi`), a metric as `node.metric` (`t1.compressed_bytes`), or `time_ms` /
    /// `pipeline_ms`.
    #[arg(long = "x", value_name = "COLUMN")]
    x: Option<String>,
    /// One line per value of this varied parameter (the method's rows), in the order of its
    /// --vary list, instead of one line for all of them.
    #[arg(long, value_name = "NODE.PARAM")]
    series: Option<String>,
    /// No progress bars and no table.
    #[arg(long, short)]
    quiet: bool,
}

/// With a baseline on a time axis, each method row's speed-up at equal error as
/// `relume results` reads it off the baseline's curve, and the goal's verdict: a line each.
fn speed_ups(p: &Plotted, t: &CsvTable) -> Vec<String> {
    if p.baseline.is_none() || !matches!(p.x, XAxis::Time(_)) {
        return Vec::new();
    }
    p.rows(t, "method")
        .filter_map(|r| {
            let variant = t.text(r, "variant");
            let [error, time, baseline_time, speed, goal] = crate::results::tables::headline(p, t, variant).ok()?;
            let goal = if p.goal.is_some() { format!("; goal {goal}") } else { String::new() };
            let error = error.replace('`', "");
            Some(format!("{variant}: {speed} at equal error ({error} in {time}; the baseline {baseline_time}){goal}"))
        })
        .collect()
}

/// `--goal`: a finite speed-up of at least 1.
fn parse_goal(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(g) if g.is_finite() && g >= 1.0 => Ok(g),
        _ => Err(format!("`{s}` is no speed-up: give a number of at least 1")),
    }
}

/// Nodes whose cost counts toward the plotted image: upstream of the error node's `image`
/// input and not upstream of its `reference` input (the reference is the yardstick, not part
/// of the method). Without those inputs: everything upstream of the node.
fn pipeline_nodes(g: &Graph, error_node: &str) -> std::collections::HashSet<String> {
    let upstream = |start: Vec<String>| {
        let mut seen = std::collections::HashSet::new();
        let mut stack = start;
        while let Some(id) = stack.pop() {
            if seen.insert(id.clone()) {
                stack.extend(g.edges_into(&id).map(|e| e.from.node.clone()));
            }
        }
        seen
    };
    let from = |port: &str| g.edges_into(error_node).filter(|e| e.to.port == port).map(|e| e.from.node.clone()).collect::<Vec<_>>();
    let (image, reference) = (from("image"), from("reference"));
    if image.is_empty() {
        let mut all = upstream(vec![error_node.to_string()]);
        all.remove(error_node);
        return all;
    }
    let r = upstream(reference);
    upstream(image).into_iter().filter(|n| !r.contains(n)).collect()
}

/// One graph to run: the base graph with some parameters changed.
struct Variant {
    series: Series,
    /// `node.param=value` of what was changed, space-separated.
    label: String,
    graph: Graph,
}

pub(crate) fn sweep(reg: &Registry, a: &SweepArgs) -> Result<(), CliError> {
    let mut base = a.g.load(reg)?;
    add_port_outputs(reg, &mut base, &a.g.outputs)?;
    let varies = a.varies.iter().map(|s| parse_vary(s)).collect::<Result<Vec<_>, _>>()?;
    let mut variants = method_variants(reg, &base, &varies)?;
    let mut columns: Vec<String> = varies.iter().flat_map(|v| v.targets.iter().cloned()).collect();
    if let Some(b) = &a.baseline {
        variants.extend(baseline_variants(reg, &base, b, a.baseline_max)?);
        if !columns.contains(b) {
            columns.push(b.clone());
        }
    }
    if let Some(id) = &a.error_node {
        if base.node(id).is_none() {
            let ids: Vec<&str> = base.nodes.iter().map(|n| n.id.as_str()).collect();
            return Err(CliError::graph(format!("--error-node {id}: no node \"{id}\" in the graph (it has: {})", ids.join(", "))));
        }
    }

    // Everything checkable is checked before the first variant runs: the metric, the
    // folders and files the sweep writes, and where the graph's own output files go.
    check_metric(reg, &base, &a.metric, a.error_node.as_deref(), a.g.requested().as_deref())?;
    let x_axis = axes::XAxis::parse(a.x.as_deref(), a.time, &columns, &base, reg)?;
    let series = a.series.as_deref().map(|s| axes::series_vary(s, &varies)).transpose()?;
    if let Some(id) = &a.baseline_error_node {
        if base.node(id).is_none() {
            let ids: Vec<&str> = base.nodes.iter().map(|n| n.id.as_str()).collect();
            return Err(CliError::graph(format!("--baseline-error-node {id}: no node \"{id}\" in the graph (it has: {})", ids.join(", "))));
        }
        check_metric(reg, &base, &a.metric, Some(id), a.g.requested().as_deref())?;
    }
    let csv_path = a.csv.clone().unwrap_or_else(|| a.out.join("sweep.csv"));
    let plot_path = a.plot.clone().unwrap_or_else(|| csv_path.with_extension("png"));
    prepare_out_dir("--out", &a.out)?;
    prepare_file(if a.csv.is_some() { "--csv" } else { "the CSV file" }, &csv_path)?;
    prepare_file(if a.plot.is_some() { "--plot" } else { "the plot file" }, &plot_path)?;
    let writes = a.g.write_policy(&a.out);
    for v in &variants {
        let command =
            CommandWrites { files: vec![(csv_path.clone(), "the CSV file"), (plot_path.clone(), "the plot file")], ..Default::default() };
        refuse_files(reg, &v.graph, a.g.requested().as_deref(), &writes, &a.g.read_policy(), &command)
            .map_err(|e| CliError::graph(format!("{} variant {}: {}", v.series.as_str(), v.label, e.msg)))?;
    }

    // One node at a time (each still uses every core inside): a node's time is then its own,
    // not shared with whatever else ran beside it, which the time axis depends on.
    let (engine, _) = a.g.engine_for_writing(reg);
    let engine = engine.with_parallelism(1);
    let watch = Watch::new();
    let mut rows: Vec<Row> = Vec::with_capacity(variants.len());
    let mut error_node: Option<String> = None;
    let count = variants.len();
    for (i, v) in variants.into_iter().enumerate() {
        if !a.quiet {
            say_err!("sweep {}/{count}: {} {}", i + 1, v.series.as_str(), v.label);
        }
        let bars = (!a.quiet).then(Bars::new);
        let opts = RunOptions {
            outputs: a.g.requested(),
            observer: bars.as_ref().map(|b| b as &dyn Observer),
            cancel: watch.token.clone(),
            writes: writes.clone(),
            ..Default::default()
        };
        let result = engine.run(&v.graph, &opts).map_err(|e| {
            let mut e = run_error(&v.graph, e);
            e.msg = if e.code == super::interrupt::EXIT_CODE {
                format!("interrupted: the sweep was cancelled in variant {} of {count}; no CSV or plot was written", i + 1)
            } else {
                format!("{} variant {}: {}", v.series.as_str(), v.label, e.msg)
            };
            e
        })?;
        drop(bars);
        if error_node.is_none() {
            // Every variant has the same nodes and outputs: the first run tells whether the
            // metric exists, before the rest of the sweep is spent.
            error_node = Some(find_error_node(&base, &result.report, &a.metric, a.error_node.as_deref())?);
        }
        let params = columns.iter().map(|c| param_text(reg, &v.graph, c)).collect();
        let time_ms = result.report.nodes.iter().filter(|n| n.status == "ran").fold(0.0, |t, n| t + n.wall_ms);
        rows.push(Row { series: v.series, label: v.label, params, time_ms, pipeline_ms: 0.0, report: result.report });
    }
    let error_node = error_node.expect("a sweep runs at least one variant");
    if watch.interrupted() {
        return Err(CliError::interrupted("interrupted: the sweep was cancelled after its last variant; no CSV or plot was written"));
    }
    let baseline_node = a.baseline_error_node.clone().unwrap_or_else(|| error_node.clone());
    if base.node(&baseline_node).is_none() {
        return Err(CliError::graph(format!("--baseline-error-node {baseline_node}: no such node in the graph")));
    }
    let (method_cost, baseline_cost) = (pipeline_nodes(&base, &error_node), pipeline_nodes(&base, &baseline_node));
    for r in &mut rows {
        let nodes = if r.series == Series::Baseline { &baseline_cost } else { &method_cost };
        r.pipeline_ms = r.report.nodes.iter().filter(|n| nodes.contains(&n.id)).map(|n| n.compute_ms).sum();
    }
    let csv = write_csv(&base, &columns, &rows);
    if let Some(dir) = csv_path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| CliError::run(format!("cannot create {}: {e}", dir.display())))?;
    }
    relume_core::graph::write_atomic(&csv_path, csv.as_bytes())
        .map_err(|e| CliError::run(format!("cannot write {}: {e}", csv_path.display())))?;

    let title = a.g.graph.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_else(|| a.g.graph.display().to_string());
    let plotted = Plotted {
        x: x_axis,
        series,
        varies,
        error_node: error_node.clone(),
        metric: a.metric.clone(),
        baseline: a.baseline.clone().map(|b| (b, baseline_node)),
        goal: a.goal,
        title,
    };
    // Drawn from the CSV as written, as `relume results` draws it.
    let written = CsvTable::parse(&csv).map_err(|e| CliError::run(format!("the CSV just written does not read back: {e}")))?;
    let warnings = plot_log_log(&plot_path, &plotted.axes(), &plotted.curves(&written)).map_err(CliError::run)?;
    for w in warnings {
        say_err!("warning: {w}");
    }
    if plotted.x == XAxis::Time(TimeAxis::Ran) && rows.iter().any(|r| r.time_ms <= 0.0) && !a.quiet {
        say_err!(
            "note: variants whose nodes all came from the cache cost 0 ms; to time every variant from scratch use --no-disk-cache or a fresh --cache folder"
        );
    }

    if !a.quiet {
        say_part!("{}", table(&rows, &error_node, &a.metric));
        for line in speed_ups(&plotted, &written) {
            say!("{line}");
        }
        say!("wrote {}", csv_path.display());
        say!("wrote {}", plot_path.display());
    }
    Ok(())
}

/// Splits `node.param=a,b,c` at commas outside brackets and quotes.
fn parse_vary(s: &str) -> Result<Vary, CliError> {
    let (target, list) = s.split_once('=').ok_or_else(|| CliError::graph(format!("--vary {s}: expected node.param=a,b,c")))?;
    let targets: Vec<String> = target.split('+').map(|t| t.trim().to_string()).collect();
    if let Some(t) = targets.iter().find(|t| !t.contains('.')) {
        return Err(CliError::graph(format!("--vary {s}: `{t}` is not of the form node.param")));
    }
    let target = target.trim();
    let values = split_top_level(list);
    if values.iter().all(|v| v.is_empty()) {
        return Err(CliError::graph(format!("--vary {s}: no values given (expected {target}=a,b,c)")));
    }
    if values.iter().any(|v| v.is_empty()) {
        return Err(CliError::graph(format!("--vary {s}: an empty value in the list")));
    }
    Ok(Vary { targets, values })
}

fn split_top_level(list: &str) -> Vec<String> {
    let (mut out, mut cur, mut depth, mut quoted) = (Vec::new(), String::new(), 0i32, false);
    let mut chars = list.chars();
    while let Some(c) = chars.next() {
        match c {
            '"' => quoted = !quoted,
            '\\' if quoted => {
                cur.push(c);
                if let Some(n) = chars.next() {
                    cur.push(n);
                }
                continue;
            }
            '(' | '[' | '{' if !quoted => depth += 1,
            ')' | ']' | '}' if !quoted => depth -= 1,
            ',' if !quoted && depth == 0 => {
                out.push(cur.trim().to_string());
                cur.clear();
                continue;
            }
            _ => {}
        }
        cur.push(c);
    }
    out.push(cur.trim().to_string());
    out
}

/// The cartesian product of the --vary lists, first list outermost.
fn method_variants(reg: &Registry, base: &Graph, varies: &[Vary]) -> Result<Vec<Variant>, CliError> {
    if varies.is_empty() {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    let mut idx = vec![0usize; varies.len()];
    loop {
        let mut graph = base.clone();
        let mut label = Vec::new();
        for (v, &i) in varies.iter().zip(&idx) {
            let value = &v.values[i];
            for t in &v.targets {
                graph.set_param_text(reg, t, value).map_err(|e| CliError::graph(format!("--vary {t}={value}: {e}")))?;
                label.push(format!("{t}={value}"));
            }
        }
        out.push(Variant { series: Series::Method, label: label.join(" "), graph });
        // Odometer: the last list turns fastest.
        let mut k = varies.len();
        loop {
            if k == 0 {
                return Ok(out);
            }
            k -= 1;
            idx[k] += 1;
            if idx[k] < varies[k].values.len() {
                break;
            }
            idx[k] = 0;
        }
    }
}

/// The base graph with the numeric parameter `target` at 1, 2, 4, … ≤ `max`.
fn baseline_variants(reg: &Registry, base: &Graph, target: &str, max: i64) -> Result<Vec<Variant>, CliError> {
    let flag = format!("--baseline {target}");
    let (id, name) = target.split_once('.').ok_or_else(|| CliError::graph(format!("{flag}: expected node.param")))?;
    let node = base.node(id).ok_or_else(|| CliError::graph(format!("{flag}: no node \"{id}\" in the graph")))?;
    let kind = reg.node(&node.kind).ok_or_else(|| CliError::graph(format!("{flag}: unknown node kind \"{}\"", node.kind)))?;
    let spec = kind.schema().get(name).ok_or_else(|| {
        let names: Vec<_> = kind.schema().0.iter().map(|p| p.name).collect();
        CliError::graph(format!("{flag}: {} has no parameter `{name}` (it has: {})", node.kind, names.join(", ")))
    })?;
    if !matches!(spec.kind, ParamKind::Int { .. } | ParamKind::Float { .. }) {
        return Err(CliError::graph(format!("{flag}: the baseline parameter must be a number; `{name}` is {}", spec.kind.type_name())));
    }
    if max < 1 {
        return Err(CliError::graph(format!("--baseline-max {max}: must be at least 1")));
    }
    let mut out = Vec::new();
    let mut n = 1i64;
    while n <= max {
        let mut graph = base.clone();
        graph
            .set_param_text(reg, target, &n.to_string())
            .map_err(|e| CliError::graph(format!("{flag} at {n}: {e} (lower --baseline-max)")))?;
        out.push(Variant { series: Series::Baseline, label: format!("{target}={n}"), graph });
        n = match n.checked_mul(2) {
            Some(m) => m,
            None => break,
        };
    }
    Ok(out)
}

/// A parameter's value in `graph` (its schema default when the graph leaves it out).
fn param_text(reg: &Registry, graph: &Graph, target: &str) -> String {
    let Some((id, name)) = target.split_once('.') else { return String::new() };
    let Some(node) = graph.node(id) else { return String::new() };
    if let Some(v) = node.param(name) {
        return v.to_text();
    }
    reg.node(&node.kind).and_then(|k| k.schema().get(name)).and_then(|s| s.default.as_ref()).map(|v| v.to_text()).unwrap_or_default()
}

/// Adds `--output node.port` for a port the graph does not name as an output, so that a sweep
/// can stop at an intermediate node (a precompute's metrics) without running what follows.
fn add_port_outputs(reg: &Registry, g: &mut Graph, requested: &[String]) -> Result<(), CliError> {
    for name in requested {
        if g.outputs.iter().any(|o| &o.name == name) {
            continue;
        }
        let Some((id, port)) = name.split_once('.') else { continue }; // the planner lists the outputs
        let node = g.node(id).ok_or_else(|| CliError::graph(format!("--output {name}: no output and no node \"{id}\" of that name")))?;
        let kind = reg.node(&node.kind).ok_or_else(|| CliError::graph(format!("--output {name}: unknown node kind \"{}\"", node.kind)))?;
        let ports: Vec<&str> = kind.ports().outputs.iter().map(|p| p.name).collect();
        if !ports.contains(&port) {
            return Err(CliError::graph(format!("--output {name}: {} has no output `{port}` (it has: {})", node.kind, ports.join(", "))));
        }
        let port = PortRef { node: id.to_string(), port: port.to_string() };
        g.outputs.push(Output { name: name.clone(), port, pos: Default::default() });
    }
    Ok(())
}

/// Refuses, before anything runs, a `--metric` that the error node (or, without
/// --error-node, every node the requested outputs need) does not report, listing those that
/// exist (each kind's declared `metrics`).
fn check_metric(reg: &Registry, graph: &Graph, metric: &str, wanted: Option<&str>, outputs: Option<&[String]>) -> Result<(), CliError> {
    let reported_metrics = |kind: &str| reg.node(kind).map_or(&[][..], |k| k.metrics());
    let ids: Vec<&str> = match wanted {
        Some(id) => vec![id],
        None => match make_plan(graph, reg, outputs) {
            // In graph order, as `find_error_node` searches.
            Ok(plan) => graph.nodes.iter().enumerate().filter(|(i, _)| plan.order.contains(i)).map(|(_, n)| n.id.as_str()).collect(),
            Err(_) => return Ok(()), // the run reports the graph's problem
        },
    };
    let nodes: Vec<_> = ids.iter().filter_map(|id| graph.node(id)).collect();
    if nodes.iter().any(|n| reported_metrics(&n.kind).contains(&metric)) {
        return Ok(());
    }
    let all: Vec<String> = nodes.iter().flat_map(|n| reported_metrics(&n.kind).iter().map(move |m| format!("{}.{m}", n.id))).collect();
    let names: Vec<&str> = nodes.iter().flat_map(|n| reported_metrics(&n.kind).iter().copied()).collect();
    let near = relume_core::closest(metric, names).map(|m| format!("did you mean `{m}`? ")).unwrap_or_default();
    Err(CliError::graph(match (wanted, nodes.first()) {
        (Some(id), Some(n)) if reported_metrics(&n.kind).is_empty() => {
            format!(
                "--metric {metric}: node \"{id}\" ({}) reports no metric; name a node that reports it (an ImageError or a ZTest)",
                n.kind
            )
        }
        (Some(id), Some(n)) => format!(
            "--metric {metric}: node \"{id}\" ({}) does not report it; {near}it reports: {}",
            n.kind,
            reported_metrics(&n.kind).join(", ")
        ),
        _ if all.is_empty() => format!("--metric {metric}: no node the outputs need reports any metric"),
        _ => format!("--metric {metric}: no node the outputs need reports it; {near}metrics reported: {}", all.join(", ")),
    }))
}

/// The node whose `metric` is plotted: `wanted`, checked, or the first in graph order
/// reporting it. A metric nobody reports is an error that lists the ones that exist.
fn find_error_node(graph: &Graph, report: &RunReport, metric: &str, wanted: Option<&str>) -> Result<String, CliError> {
    let available = || {
        let all: Vec<String> =
            in_graph_order(graph, report).iter().flat_map(|n| n.metrics.keys().map(move |m| format!("{}.{m}", n.id))).collect();
        if all.is_empty() {
            "no node reports any metric".to_string()
        } else {
            format!("metrics reported: {}", all.join(", "))
        }
    };
    match wanted {
        Some(id) => match report.node(id) {
            Some(n) if n.metrics.contains_key(metric) => Ok(id.to_string()),
            Some(_) => Err(CliError::graph(format!("--metric {metric}: node \"{id}\" does not report it ({})", available()))),
            None => Err(CliError::graph(format!("--error-node {id}: the node is not needed for the requested outputs"))),
        },
        None => in_graph_order(graph, report)
            .into_iter()
            .find(|n| n.metrics.contains_key(metric))
            .map(|n| n.id.clone())
            .ok_or_else(|| CliError::graph(format!("--metric {metric}: no node reports it ({})", available()))),
    }
}

/// The report's nodes in the graph file's order (the report lists them as they completed).
fn in_graph_order<'r>(graph: &Graph, report: &'r RunReport) -> Vec<&'r relume_core::NodeReport> {
    graph.nodes.iter().filter_map(|d| report.node(&d.id)).collect()
}

/// A unit suffix for the axis label, from the metric's name.
/// `series,variant,<params>,time_ms,pipeline_ms,total_ms,peak_rss_bytes,<node.metric>…,ms:<node>…,bytes:<node>…,date,machine,threads,commit`
/// (`bytes:` the node's outputs, cached or not).
fn write_csv(graph: &Graph, columns: &[String], rows: &[Row]) -> String {
    // Metric and node columns: every one any row has, in graph order (metrics by name).
    let mut metrics: Vec<(String, String)> = Vec::new();
    let mut nodes: Vec<String> = Vec::new();
    for d in &graph.nodes {
        let mut names = BTreeSet::new();
        let mut seen = false;
        for r in rows {
            if let Some(n) = r.report.node(&d.id) {
                seen = true;
                names.extend(n.metrics.keys().cloned());
            }
        }
        metrics.extend(names.into_iter().map(|m| (d.id.clone(), m)));
        if seen {
            nodes.push(d.id.clone());
        }
    }
    let mut header: Vec<String> = vec!["series".into(), "variant".into()];
    header.extend(columns.iter().cloned());
    header.extend(["time_ms", "pipeline_ms", "total_ms", "peak_rss_bytes"].map(String::from));
    header.extend(metrics.iter().map(|(n, m)| format!("{n}.{m}")));
    header.extend(nodes.iter().map(|n| format!("ms:{n}")));
    header.extend(nodes.iter().map(|n| format!("bytes:{n}")));
    header.extend(crate::provenance::COLUMNS.map(String::from));
    let provenance = crate::provenance::cells();
    let mut out = csv_line(&header);
    for r in rows {
        let mut cells: Vec<String> = vec![r.series.as_str().into(), r.label.clone()];
        cells.extend(r.params.iter().cloned());
        cells.push(format!("{:.4}", r.time_ms));
        cells.push(format!("{:.4}", r.pipeline_ms));
        cells.push(format!("{:.4}", r.report.total_ms));
        // The process's peak resident memory when the variant ended (the largest so far).
        cells.push(r.report.peak_rss_bytes.map(|b| b.to_string()).unwrap_or_default());
        for (n, m) in &metrics {
            cells.push(r.report.node(n).and_then(|n| n.metrics.get(m)).map(|v| v.to_string()).unwrap_or_default());
        }
        for n in &nodes {
            // Time spent running the node in this variant; 0 when it came from the cache.
            cells.push(
                r.report.node(n).map(|n| if n.status == "ran" { format!("{:.4}", n.wall_ms) } else { "0".to_string() }).unwrap_or_default(),
            );
        }
        for n in &nodes {
            cells.push(r.report.node(n).map(|n| n.bytes.to_string()).unwrap_or_default());
        }
        cells.extend(provenance.iter().cloned());
        out.push_str(&csv_line(&cells));
    }
    out
}

/// The rows as a terminal table.
fn table(rows: &[Row], error_node: &str, metric: &str) -> String {
    let width = rows.iter().map(|r| r.label.len()).max().unwrap_or(0).max(7);
    let col = format!("{error_node}.{metric}");
    let mut s =
        format!("{:<8} {:<width$} {:>10} {:>10} {:>4} {:>6} {:>14}\n", "series", "variant", "time_ms", "total_ms", "ran", "cached", col);
    for r in rows {
        let m = r.report.node(error_node).and_then(|n| n.metrics.get(metric)).map(|v| format!("{v:.6e}")).unwrap_or_default();
        s.push_str(&format!(
            "{:<8} {:<width$} {:>10.2} {:>10.2} {:>4} {:>6} {:>14}\n",
            r.series.as_str(),
            r.label,
            r.time_ms,
            r.report.total_ms,
            r.report.ran,
            r.report.cached,
            m
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_console_says_each_rows_speed_up_and_the_goals_verdict() {
        // The method at 4 ms and 0.02; the baseline passes 0.02 at 5.3 ms: 1.32×.
        let csv = "series,variant,blur.sigma,pt.spp,time_ms,pipeline_ms,error.rel_mse,pt_error.rel_mse,date,machine,threads,commit\n\
            method,blur.sigma=1,1,4,5,4,0.02,0.5,d,m,2,c\n\
            baseline,pt.spp=1,1,1,3,2,0.5,0.1,d,m,2,c\n\
            baseline,pt.spp=2,1,2,6,8,0.5,0.01,d,m,2,c\n";
        let t = CsvTable::parse(csv).unwrap();
        let command = |extra: &str| {
            format!("relume sweep g.ron --vary blur.sigma=1 --baseline pt.spp --baseline-max 2 --error-node error --baseline-error-node pt_error{extra}")
        };
        let lines = speed_ups(&replay::replay(&command(" --goal 2"), &t).unwrap(), &t);
        assert_eq!(lines, ["blur.sigma=1: 1.32× at equal error (0.0200 (rel_mse) in 4.0 ms; the baseline 5.3 ms); goal ≥ 2×: 1.52× short"]);
        let lines = speed_ups(&replay::replay(&command(""), &t).unwrap(), &t);
        assert_eq!(lines, ["blur.sigma=1: 1.32× at equal error (0.0200 (rel_mse) in 4.0 ms; the baseline 5.3 ms)"]);
        let lines = speed_ups(&replay::replay(&command(" --x blur.sigma"), &t).unwrap(), &t);
        assert!(lines.is_empty(), "no speed-up off a time axis");
    }

    #[test]
    fn value_lists_split_at_top_level_commas_only() {
        assert_eq!(split_top_level("0.5, 1,2"), ["0.5", "1", "2"]);
        assert_eq!(split_top_level("(1,0,0),(0, 1, 0)"), ["(1,0,0)", "(0, 1, 0)"]);
        assert_eq!(split_top_level("\"a,b\",c"), ["\"a,b\"", "c"]);
    }

    #[test]
    fn vary_needs_a_target_and_non_empty_values() {
        assert!(parse_vary("blur.sigma=1,2").is_ok());
        for bad in ["blur.sigma", "blur.sigma=", "blur.sigma=1,,2", "sigma=1"] {
            assert_eq!(parse_vary(bad).err().map(|e| e.code), Some(2), "{bad}");
        }
    }

    /// The metric functions behind the quality and gather nodes produce exactly the names
    /// their kinds declare (in order: the sweep lists them so). Every other `cx.metric` is
    /// held to its kind's list by the executor, which refuses an undeclared name, on every
    /// graph the tests run.
    #[test]
    fn the_metric_functions_produce_the_declared_names() {
        use relume_base::types::Image;
        let reg = crate::registry();
        let declared = |kind: &str| reg.node(kind).unwrap().metrics().iter().map(|m| m.to_string()).collect::<Vec<_>>();
        let names = |m: relume_base::types::Metrics| m.0.into_iter().map(|(k, _)| k).collect::<Vec<_>>();
        let img = Image::from_fn(16, 16, |x, y| [x as f32 * 0.1, y as f32 * 0.1, 0.5]);
        assert_eq!(names(relume_base::image::image_error::error_metrics(&img, &img, 1.0, 0.01)), declared("ImageError"));
        let z = relume_base::image::z_test::z_test(&img, &img, &img, &img, 3.0).unwrap();
        assert_eq!(names(z.metrics()), declared("ZTest"));
        let gather = names(relume_pbgi::traversal::count_metrics(Default::default(), 1));
        assert_eq!(gather, declared("PbgiGather"));
        assert_eq!(gather, declared("WaveletGather"));
        assert_eq!([gather, vec!["clusters".to_string()]].concat(), declared("FactorizedGather"));
    }

    #[test]
    fn a_metric_no_node_declares_is_refused_with_the_declared_names() {
        let reg = crate::registry();
        let g = Graph::parse(
            r#"Graph(version: 1, nodes: {
                "a": (kind: "TestPattern", params: ()), "b": (kind: "TestPattern", params: ()),
                "error": (kind: "ImageError", params: ()),
            }, edges: [("a.image", "error.image"), ("b.image", "error.reference")], outputs: { "m": "error.metrics" })"#,
            None,
        )
        .unwrap();
        let e = check_metric(&reg, &g, "msee", None, None).err().unwrap().msg;
        assert!(e.contains("did you mean `mse`?") && e.contains("error.psnr_db"), "{e}");
        assert!(check_metric(&reg, &g, "ssim", None, None).is_ok());
        let e = check_metric(&reg, &g, "ssim", Some("a"), None).err().unwrap().msg;
        assert!(e.contains("reports no metric"), "{e}");
    }
}
