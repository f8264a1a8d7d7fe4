//! Building a graph from code, as the editor and the language bindings do: a node added under
//! a fresh or given id, a connection checked for type and cycle (replacing what fed the input),
//! an output named.

use super::{Edge, Graph, NodeDecl, Output, PortRef};
use crate::error::GraphError;
use crate::registry::Registry;
use crate::ron::Pos;

impl Graph {
    /// A fresh node id from the kind's name: `gaussian_blur`, `gaussian_blur_2`, ….
    pub fn unique_id(&self, kind: &str) -> String {
        let mut base = String::new();
        for (i, c) in kind.chars().enumerate() {
            if c.is_uppercase() && i > 0 {
                base.push('_');
            }
            base.extend(c.to_lowercase());
        }
        if self.node(&base).is_none() {
            return base;
        }
        (2..).map(|n| format!("{base}_{n}")).find(|id| self.node(id).is_none()).expect("unbounded")
    }

    /// Adds a node of `kind` with default parameters under `id` (a fresh one from the kind's
    /// name when `None`); returns the id. Refuses a kind the registry does not know (naming
    /// the closest), an id that is not a plain name, and one already taken.
    pub fn add_node(&mut self, registry: &Registry, kind: &str, id: Option<&str>) -> Result<String, GraphError> {
        if registry.node(kind).is_none() {
            let near = registry.suggest(kind).map(|k| format!(" (did you mean \"{k}\"?)")).unwrap_or_default();
            return Err(GraphError::new(format!("unknown node kind \"{kind}\"{near}")));
        }
        let id = id.map_or_else(|| self.unique_id(kind), str::to_string);
        if !super::is_valid_id(&id) {
            return Err(GraphError::new(format!("\"{id}\" is not a node id (letters, digits, `_` and `-`)")));
        }
        if self.node(&id).is_some() {
            return Err(GraphError::new(format!("a node \"{id}\" is already in the graph")).node(&id));
        }
        self.nodes.push(NodeDecl::new(&id, kind));
        Ok(id)
    }

    /// Connects `from` to `to`, replacing what fed `to`, after the core's check (both ports
    /// exist, their types agree, no cycle); the check's words when refused.
    pub fn connect(&mut self, registry: &Registry, from: PortRef, to: PortRef) -> Result<(), String> {
        self.check_connection(registry, &from, &to)?;
        match self.edges.iter_mut().find(|e| e.to == to) {
            Some(e) => e.from = from,
            None => self.edges.push(Edge { from, to, pos: Pos::default() }),
        }
        Ok(())
    }

    /// Makes `port` a graph output named `name` (replacing an output of that name), or with
    /// `on` false removes the outputs naming `port`.
    pub fn set_output(&mut self, port: &PortRef, name: &str, on: bool) {
        self.outputs.retain(|o| &o.port != port && (!on || o.name != name));
        if on {
            self.outputs.push(Output { name: name.to_string(), port: port.clone(), pos: Pos::default() });
        }
    }
}
