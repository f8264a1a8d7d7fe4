//! `relume plan`: what a run would do, what is cached, and why.

use crate::error::GraphErrors;
use crate::exec::Engine;
use crate::graph::Graph;
use crate::hash::Hash;
use crate::node::Caching;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlanAction {
    /// A cached result exists for the node's key.
    Cached,
    /// The node would run.
    Run,
    /// No requested output needs the node.
    Skip,
}

#[derive(Clone, Debug)]
pub struct PlanLine {
    pub id: String,
    pub kind: String,
    pub action: PlanAction,
    pub reason: String,
}

impl Engine {
    /// Walks the plan without running anything: a node is known cached when all of its inputs
    /// are known (cached) and a result for its key exists in memory or on disk.
    pub fn explain(&self, graph: &Graph, outputs: Option<&[String]>) -> Result<Vec<PlanLine>, GraphErrors> {
        let plan = self.plan(graph, outputs)?;
        let mut fps: Vec<Option<Vec<Hash>>> = vec![None; graph.nodes.len()];
        let mut lines = Vec::new();
        for &i in &plan.order {
            let decl = &graph.nodes[i];
            let kind = self.registry().node(&decl.kind).expect("validated");
            let line = |action, reason: String| PlanLine { id: decl.id.clone(), kind: decl.kind.clone(), action, reason };
            let inputs: Option<Vec<Hash>> = plan.sources[i].iter().map(|&(s, o)| fps[s].as_ref().map(|f| f[o])).collect();
            let Some(inputs) = inputs else {
                let up = plan.sources[i].iter().find(|&&(s, _)| fps[s].is_none()).map(|&(s, _)| graph.nodes[s].id.as_str()).unwrap_or("?");
                lines.push(line(
                    PlanAction::Run,
                    format!(
                        "its input from \"{up}\" will be computed (if that reproduces identical bytes, this node is reused from the cache)"
                    ),
                ));
                continue;
            };
            let prepared = self.prepare(graph, i, &inputs).map_err(|e| GraphErrors::one(e).with_file(&graph.file))?;
            if kind.caching() == Caching::Never {
                lines.push(line(PlanAction::Run, "has a side effect (writes a file): always runs".into()));
                continue;
            }
            match self.lookup(kind.as_ref(), &graph.nodes[i].id, &prepared.key) {
                Some((entry, status)) => {
                    fps[i] = Some(entry.outputs.iter().map(|v| v.fingerprint()).collect());
                    let place = if status == crate::ctx::NodeStatus::CachedDisk { "disk" } else { "memory" };
                    lines.push(line(PlanAction::Cached, format!("result for key {} is in the {place} cache", prepared.key.short())));
                }
                None => lines.push(line(
                    PlanAction::Run,
                    format!("no cached result for key {} (first run, or a parameter, input or file changed)", prepared.key.short()),
                )),
            }
        }
        for (i, decl) in graph.nodes.iter().enumerate() {
            if !plan.needed[i] {
                lines.push(PlanLine {
                    id: decl.id.clone(),
                    kind: decl.kind.clone(),
                    action: PlanAction::Skip,
                    reason: "not needed by the requested outputs".into(),
                });
            }
        }
        Ok(lines)
    }
}
