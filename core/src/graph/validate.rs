//! Checks a parsed graph against the registry: kinds, parameters, edge types, outputs, cycles.

use super::{Graph, PortRef};
use crate::error::{GraphError, GraphErrors};
use crate::registry::Registry;
use std::collections::HashMap;

impl Graph {
    /// Every problem a file can have that does not need running: unknown kinds, unknown,
    /// missing or out-of-range parameters, edges naming nothing or joining different types,
    /// inputs fed twice, outputs naming nothing, cycles, layout for unknown nodes.
    pub fn validate(&self, reg: &Registry) -> Result<(), GraphErrors> {
        let mut errs = Vec::new();
        let index = self.index();
        self.check_nodes(reg, &mut errs);
        self.check_edges(reg, &index, &mut errs);
        self.check_outputs(reg, &index, &mut errs);
        if let Some(cycle) = self.find_cycle() {
            let first = self.node(&cycle[0]).map(|n| n.pos).unwrap_or_default();
            errs.push(GraphError::new(format!("the edges form a cycle: {} → {}", cycle.join(" → "), cycle[0])).at(first).node(&cycle[0]));
        }
        for (id, _) in &self.editor.positions {
            if !index.contains_key(id.as_str()) {
                errs.push(GraphError::new("the editor section places a node that does not exist").node(id));
            }
        }
        if errs.is_empty() {
            Ok(())
        } else {
            errs.sort_by_key(|e| e.pos.map(|p| (p.line, p.col)).unwrap_or((u32::MAX, 0)));
            Err(GraphErrors(errs).with_file(&self.file))
        }
    }

    /// Inputs of node `id` that no edge feeds, as errors (needed before running it).
    pub fn unconnected_inputs(&self, reg: &Registry, id: &str) -> Vec<GraphError> {
        self.unconnected_inputs_of(reg, [id])
    }

    /// As `unconnected_inputs`, for each of the nodes `ids`, in one pass over the edges.
    pub fn unconnected_inputs_of<'a>(&self, reg: &Registry, ids: impl IntoIterator<Item = &'a str>) -> Vec<GraphError> {
        let (index, feeds) = (self.index(), self.feeds());
        let mut errs = Vec::new();
        for id in ids {
            let Some(n) = index.get(id).map(|&i| &self.nodes[i]) else { continue };
            let Some(kind) = reg.node(&n.kind) else { continue };
            for p in kind.ports().inputs.iter().filter(|p| !feeds.contains_key(&(id, p.name))) {
                let mut e = GraphError::new(format!("input `{}` ({}) is not connected", p.name, p.ty.name)).at(n.pos).node(id);
                e.file = self.file.clone();
                errs.push(e);
            }
        }
        errs
    }

    fn check_nodes(&self, reg: &Registry, errs: &mut Vec<GraphError>) {
        for n in &self.nodes {
            let Some(kind) = reg.node(&n.kind) else {
                let hint = reg.suggest(&n.kind).map(|k| format!(" (did you mean \"{k}\"?)")).unwrap_or_default();
                errs.push(
                    GraphError::new(format!("unknown node kind \"{}\"{hint}; `relume nodes` lists them", n.kind)).at(n.pos).node(&n.id),
                );
                continue;
            };
            let schema = kind.schema();
            for (name, v) in &n.params {
                let pos = n.param_pos(name);
                match schema.get(name) {
                    None => {
                        let names: Vec<_> = schema.0.iter().map(|p| p.name).collect();
                        let has = if names.is_empty() { "no parameters".to_string() } else { format!("parameters: {}", names.join(", ")) };
                        let has = match crate::registry::closest(name, names.iter().copied()) {
                            Some(near) => format!("did you mean `{near}`? it has {has}"),
                            None => format!("it has {has}"),
                        };
                        errs.push(GraphError::new(format!("unknown parameter for {} ({has})", n.kind)).at(pos).node(&n.id).param(name));
                    }
                    Some(spec) => {
                        if let Err(m) = spec.check(v) {
                            errs.push(GraphError::new(m).at(pos).node(&n.id).param(name));
                        }
                    }
                }
            }
            for spec in schema.0.iter().filter(|s| s.default.is_none()) {
                if n.param(spec.name).is_none() {
                    errs.push(
                        GraphError::new(format!("missing required parameter ({}: {})", spec.kind.type_name(), spec.help))
                            .at(n.pos)
                            .node(&n.id)
                            .param(spec.name),
                    );
                }
            }
        }
    }

    fn check_edges(&self, reg: &Registry, index: &HashMap<&str, usize>, errs: &mut Vec<GraphError>) {
        let mut fed: HashMap<(&str, &str), usize> = HashMap::new();
        for (i, e) in self.edges.iter().enumerate() {
            let from = self.port_type(reg, index, &e.from.node, &e.from.port, false);
            let to = self.port_type(reg, index, &e.to.node, &e.to.port, true);
            match (from, to) {
                (Ok(Some(a)), Ok(Some(b))) if a != b => errs.push(
                    GraphError::new(format!(
                        "edge {} → {} joins different types: output `{}` of \"{}\" is {a}, input `{}` of \"{}\" is {b}",
                        e.from, e.to, e.from.port, e.from.node, e.to.port, e.to.node
                    ))
                    .at(e.pos),
                ),
                (Err(m), _) | (_, Err(m)) => errs.push(GraphError::new(format!("edge {} → {}: {m}", e.from, e.to)).at(e.pos)),
                _ => {}
            }
            if let Some(first) = fed.insert((&e.to.node, &e.to.port), i) {
                errs.push(
                    GraphError::new(format!(
                        "input {} is fed twice (also by {} at line {})",
                        e.to, self.edges[first].from, self.edges[first].pos.line
                    ))
                    .at(e.pos),
                );
            }
        }
    }

    fn check_outputs(&self, reg: &Registry, index: &HashMap<&str, usize>, errs: &mut Vec<GraphError>) {
        for o in &self.outputs {
            if let Err(m) = self.port_type(reg, index, &o.port.node, &o.port.port, false) {
                errs.push(GraphError::new(format!("output \"{}\" names {}: {m}", o.name, o.port)).at(o.pos));
            }
        }
    }

    /// The type name of a port; `Ok(None)` when the node's kind is unknown (reported elsewhere).
    fn port_type(
        &self,
        reg: &Registry,
        index: &HashMap<&str, usize>,
        node: &str,
        port: &str,
        input: bool,
    ) -> Result<Option<&'static str>, String> {
        let n = index.get(node).map(|&i| &self.nodes[i]).ok_or_else(|| format!("there is no node \"{node}\""))?;
        let Some(kind) = reg.node(&n.kind) else { return Ok(None) };
        let ports = if input { &kind.ports().inputs } else { &kind.ports().outputs };
        match ports.iter().find(|p| p.name == port) {
            Some(p) => Ok(Some(p.ty.name)),
            None => {
                let names: Vec<_> = ports.iter().map(|p| p.name).collect();
                let dir = if input { "input" } else { "output" };
                Err(format!(
                    "{} \"{node}\" has no {dir} `{port}` ({dir}s: {})",
                    n.kind,
                    if names.is_empty() { "none".into() } else { names.join(", ") }
                ))
            }
        }
    }

    /// Whether an edge `from` → `to` may be added (the editor asks before connecting): both
    /// ports exist, their types agree, and the edge closes no cycle. The error is a sentence.
    pub fn check_connection(&self, reg: &Registry, from: &PortRef, to: &PortRef) -> Result<(), String> {
        let index = self.index();
        let kind_known = |node: &str| self.node(node).and_then(|n| reg.node(&n.kind)).is_some();
        for (r, input) in [(from, false), (to, true)] {
            if !kind_known(&r.node) {
                return Err(match self.node(&r.node) {
                    Some(n) => format!("unknown node kind \"{}\"", n.kind),
                    None => format!("there is no node \"{}\"", r.node),
                });
            }
            self.port_type(reg, &index, &r.node, &r.port, input)?;
        }
        let a = self.port_type(reg, &index, &from.node, &from.port, false)?.unwrap_or_default();
        let b = self.port_type(reg, &index, &to.node, &to.port, true)?.unwrap_or_default();
        if a != b {
            return Err(format!("cannot connect {from} ({a}) to {to} ({b}): the port types differ"));
        }
        if from.node == to.node || self.reaches(&to.node, &from.node) {
            return Err(format!("cannot connect {from} to {to}: it would make a cycle"));
        }
        Ok(())
    }

    /// Whether node `to` can be reached from node `from` along edges (a node reaches itself).
    pub fn reaches(&self, from: &str, to: &str) -> bool {
        match (self.node_index(from), self.node_index(to)) {
            (Some(a), Some(b)) => self.topology().reaches(a, b),
            _ => false,
        }
    }

    /// Every node downstream of `id`, itself included, sorted: what an edit of `id` makes stale.
    pub fn downstream(&self, id: &str) -> Vec<String> {
        let Some(i) = self.node_index(id) else { return Vec::new() };
        self.ids_where(self.topology().downstream_of(i))
    }

    /// Every node upstream of `id`, itself included, sorted: what a run of `id` needs.
    pub fn upstream(&self, id: &str) -> Vec<String> {
        let Some(i) = self.node_index(id) else { return Vec::new() };
        self.ids_where(self.topology().upstream_of(&[i]))
    }

    /// The ids of the nodes marked in `marks` (node order), sorted.
    fn ids_where(&self, marks: Vec<bool>) -> Vec<String> {
        let mut out: Vec<String> = self.nodes.iter().zip(marks).filter(|(_, m)| *m).map(|(n, _)| n.id.clone()).collect();
        out.sort();
        out
    }

    /// The graph's topology on petgraph.
    pub fn topology(&self) -> super::topology::Topology {
        super::topology::Topology::new(self)
    }

    /// A cycle as a list of node ids (starting at the one listed first), if the edges have one.
    pub fn find_cycle(&self) -> Option<Vec<String>> {
        Some(self.topology().cycle()?.into_iter().map(|i| self.nodes[i].id.clone()).collect())
    }
}
