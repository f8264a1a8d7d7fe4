//! Demand-driven planning: only the nodes the requested outputs reach, in dependency order.

use crate::error::{GraphError, GraphErrors};
use crate::graph::Graph;
use crate::registry::Registry;
use std::collections::HashMap;

/// What a run will evaluate.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Indices into `graph.nodes`, each after all of its inputs (petgraph's topological sort).
    pub order: Vec<usize>,
    /// For every graph node: per declared input, the (node index, output index) feeding it.
    pub sources: Vec<Vec<(usize, usize)>>,
    /// Requested outputs: name, node index, output index.
    pub outputs: Vec<(String, usize, usize)>,
    /// `needed[i]`: node i is in the plan.
    pub needed: Vec<bool>,
}

/// Plans the given outputs (all of the graph's outputs when `requested` is `None`).
/// The graph must have passed `validate`.
pub fn make_plan(graph: &Graph, reg: &Registry, requested: Option<&[String]>) -> Result<Plan, GraphErrors> {
    make_plan_for(graph, reg, requested, &[])
}

/// As [`make_plan`], also running the nodes with ids `nodes` (and what they need).
pub fn make_plan_for(graph: &Graph, reg: &Registry, requested: Option<&[String]>, nodes: &[String]) -> Result<Plan, GraphErrors> {
    let index: HashMap<&str, usize> = graph.nodes.iter().enumerate().map(|(i, n)| (n.id.as_str(), i)).collect();
    let kind = |i: usize| reg.node(&graph.nodes[i].kind).expect("validated graph");
    let mut errs = Vec::new();

    let mut outputs = Vec::new();
    let names: Vec<String> = match requested {
        Some(r) => r.to_vec(),
        None => graph.outputs.iter().map(|o| o.name.clone()).collect(),
    };
    for name in &names {
        match graph.outputs.iter().find(|o| &o.name == name) {
            Some(o) => {
                let ni = index[o.port.node.as_str()];
                let oi = kind(ni).ports().outputs.iter().position(|p| p.name == o.port.port).expect("validated");
                outputs.push((name.clone(), ni, oi));
            }
            None => {
                let have: Vec<_> = graph.outputs.iter().map(|o| o.name.as_str()).collect();
                errs.push(GraphError::new(format!("no output \"{name}\" in the graph (outputs: {})", have.join(", "))));
            }
        }
    }

    let feeds = graph.feeds();
    let mut sources = vec![Vec::new(); graph.nodes.len()];
    for (i, n) in graph.nodes.iter().enumerate() {
        let Some(k) = reg.node(&n.kind) else { continue };
        sources[i] = k
            .ports()
            .inputs
            .iter()
            .map(|p| {
                feeds
                    .get(&(n.id.as_str(), p.name))
                    .map(|e| {
                        let src = index[e.from.node.as_str()];
                        (src, kind(src).ports().outputs.iter().position(|q| q.name == e.from.port).expect("validated"))
                    })
                    .unwrap_or((usize::MAX, 0))
            })
            .collect();
    }

    // Demand: every node upstream of a requested output (petgraph, reversed edges).
    let topology = graph.topology();
    let mut roots: Vec<usize> = outputs.iter().map(|o| o.1).collect();
    for id in nodes {
        match index.get(id.as_str()) {
            Some(&i) => roots.push(i),
            None => {
                let hint = crate::registry::closest(id, graph.nodes.iter().map(|n| n.id.as_str()));
                errs.push(GraphError::new(format!(
                    "no node \"{id}\" in the graph{}",
                    hint.map(|h| format!(" (did you mean \"{h}\"?)")).unwrap_or_default()
                )));
            }
        }
    }
    if !errs.is_empty() {
        return Err(GraphErrors(errs).with_file(&graph.file));
    }
    let needed = topology.upstream_of(&roots);
    let unfed = (0..graph.nodes.len()).filter(|&i| needed[i] && sources[i].iter().any(|s| s.0 == usize::MAX));
    errs.extend(graph.unconnected_inputs_of(reg, unfed.map(|i| graph.nodes[i].id.as_str())));
    if !errs.is_empty() {
        return Err(GraphErrors(errs).with_file(&graph.file));
    }
    let order = topology.order(&needed).map_err(|i| {
        GraphErrors::one(GraphError::new(format!("the needed nodes form a cycle through \"{}\"", graph.nodes[i].id))).with_file(&graph.file)
    })?;
    Ok(Plan { order, sources, outputs, needed })
}
