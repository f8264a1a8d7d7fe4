//! Demand-driven planning: only the nodes the requested outputs reach, in dependency order.

use crate::error::{GraphError, GraphErrors};
use crate::graph::Graph;
use crate::registry::Registry;
use std::collections::{HashMap, VecDeque};

/// What a run will evaluate.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Indices into `graph.nodes`, each after all of its inputs (file order among equals).
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

    let mut sources = vec![Vec::new(); graph.nodes.len()];
    for (i, n) in graph.nodes.iter().enumerate() {
        let Some(k) = reg.node(&n.kind) else { continue };
        sources[i] = k
            .ports()
            .inputs
            .iter()
            .map(|p| {
                graph
                    .edges
                    .iter()
                    .find(|e| e.to.node == n.id && e.to.port == p.name)
                    .map(|e| {
                        let src = index[e.from.node.as_str()];
                        (src, kind(src).ports().outputs.iter().position(|q| q.name == e.from.port).expect("validated"))
                    })
                    .unwrap_or((usize::MAX, 0))
            })
            .collect();
    }

    // Reverse reachability from the requested outputs.
    let mut needed = vec![false; graph.nodes.len()];
    let mut stack: Vec<usize> = outputs.iter().map(|o| o.1).collect();
    while let Some(i) = stack.pop() {
        if std::mem::replace(&mut needed[i], true) {
            continue;
        }
        if sources[i].iter().any(|s| s.0 == usize::MAX) {
            errs.extend(graph.unconnected_inputs(reg, &graph.nodes[i].id));
        }
        stack.extend(sources[i].iter().map(|s| s.0).filter(|&s| s != usize::MAX));
    }
    if !errs.is_empty() {
        return Err(GraphErrors(errs).with_file(&graph.file));
    }

    // Kahn's algorithm over the needed nodes.
    let mut waiting: Vec<usize> = (0..graph.nodes.len()).map(|i| sources[i].len()).collect();
    let mut dependents = vec![Vec::new(); graph.nodes.len()];
    for i in (0..graph.nodes.len()).filter(|&i| needed[i]) {
        for s in &sources[i] {
            dependents[s.0].push(i);
        }
    }
    let mut queue: VecDeque<usize> = (0..graph.nodes.len()).filter(|&i| needed[i] && waiting[i] == 0).collect();
    let mut order = Vec::new();
    while let Some(i) = queue.pop_front() {
        order.push(i);
        for &d in &dependents[i] {
            waiting[d] -= 1;
            if waiting[d] == 0 {
                queue.push_back(d);
            }
        }
    }
    if order.len() != needed.iter().filter(|&&b| b).count() {
        return Err(GraphErrors::one(GraphError::new("the needed nodes form a cycle")).with_file(&graph.file));
    }
    Ok(Plan { order, sources, outputs, needed })
}
