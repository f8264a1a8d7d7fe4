//! The whole-run memory check (see `memory.rs`): estimates propagated through the plan, what
//! is held at once in plan order, and the refusal message.

use crate::graph::Graph;
use crate::memory::{fmt_bytes, MemoryEstimate, PortSize};
use crate::params::ParamValues;
use crate::plan::Plan;
use crate::registry::Registry;

/// The estimate of a planned run, node by node in plan order.
pub struct RunEstimate {
    /// (node index, its estimate).
    pub nodes: Vec<(usize, MemoryEstimate)>,
    /// The most held at once, and the node running then.
    pub peak: u64,
    pub peak_node: Option<usize>,
}

/// How many needed nodes read each node's outputs.
pub(crate) fn consumers(plan: &Plan) -> Vec<usize> {
    let mut n = vec![0; plan.needed.len()];
    for &i in &plan.order {
        for &(s, _) in &plan.sources[i] {
            n[s] += 1;
        }
    }
    n
}

/// Nodes whose outputs the run returns (held to the end).
pub(crate) fn output_nodes(plan: &Plan) -> Vec<bool> {
    let mut o = vec![false; plan.needed.len()];
    for (_, n, _) in &plan.outputs {
        o[*n] = true;
    }
    o
}

/// Estimates, before running anything, what the plan will hold at once: each node's estimate
/// from its parameters and its inputs' estimated sizes, then a walk in plan order that keeps a
/// result until its last reader has run (or to the end, for outputs).
pub fn estimate(registry: &Registry, graph: &Graph, plan: &Plan) -> RunEstimate {
    let mut sizes: Vec<Vec<Option<PortSize>>> = vec![Vec::new(); graph.nodes.len()];
    let mut nodes = Vec::with_capacity(plan.order.len());
    for &i in &plan.order {
        let kind = registry.node(&graph.nodes[i].kind).expect("validated graph");
        let inputs: Vec<Option<PortSize>> = plan.sources[i].iter().map(|&(s, o)| sizes[s].get(o).copied().flatten()).collect();
        let est = ParamValues::resolve(kind.schema(), &graph.nodes[i].params, &graph.base_dir)
            .ok()
            .and_then(|p| kind.memory(&p, &inputs).ok())
            .unwrap_or_else(|| MemoryEstimate::unknown(kind.ports().outputs.len()));
        sizes[i] = est.outputs.clone();
        nodes.push((i, est));
    }
    let (mut remaining, keep) = (consumers(plan), output_nodes(plan));
    let (mut held, mut peak, mut peak_node) = (0u64, 0u64, None);
    for (i, est) in &nodes {
        let now = held + est.working + est.output_bytes();
        if now > peak {
            (peak, peak_node) = (now, Some(*i));
        }
        held += est.output_bytes();
        for &(s, _) in &plan.sources[*i] {
            remaining[s] -= 1;
            if remaining[s] == 0 && !keep[s] {
                held -= sizes[s].iter().flatten().map(|x| x.bytes).sum::<u64>();
            }
        }
    }
    RunEstimate { nodes, peak, peak_node }
}

impl RunEstimate {
    /// The refusal, when the peak exceeds `budget` (set by `source`): the total, the node at
    /// the peak, and the largest estimates per node.
    pub fn refusal(&self, graph: &Graph, budget: u64, source: &str) -> Option<String> {
        (self.peak > budget).then(|| {
            let mut per: Vec<(u64, String)> = self
                .nodes
                .iter()
                .filter(|(_, e)| e.working + e.output_bytes() > 0)
                .map(|(i, e)| {
                    let n = &graph.nodes[*i];
                    (
                        e.working + e.output_bytes(),
                        format!("\"{}\" ({}) {} (outputs {}, working {})", n.id, n.kind, fmt_bytes(e.working + e.output_bytes()), fmt_bytes(e.output_bytes()), fmt_bytes(e.working)),
                    )
                })
                .collect();
            per.sort_by_key(|p| std::cmp::Reverse(p.0));
            let at = self.peak_node.map(|i| format!(" while \"{}\" runs", graph.nodes[i].id)).unwrap_or_default();
            format!(
                "the run would hold about {} at once{at}, over the memory budget of {} ({source}); estimates: {}. Lower the resolution or sample counts, or raise the budget with --memory-budget",
                fmt_bytes(self.peak),
                fmt_bytes(budget),
                per.iter().take(6).map(|p| p.1.as_str()).collect::<Vec<_>>().join("; ")
            )
        })
    }
}
