//! The graph model: nodes with explicit parameters, typed edges, named outputs and the
//! editor's layout (which never enters a cache key).

mod edit;
mod load;
mod migrate;
mod save;
mod topology;
mod validate;

pub use migrate::{Migration, MIGRATIONS};
pub use save::write_atomic;
pub use topology::Topology;

use crate::error::GraphError;
use crate::params::ParamValue;
use crate::registry::Registry;
use crate::ron::Pos;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The most nodes a graph file may hold. Pipelines have tens; a generated graph of a study
/// would have thousands at most. Past this a file is refused on loading, before any of the
/// work that grows with its size.
pub const MAX_NODES: usize = 100_000;

/// The graph file format version this build writes.
pub const FORMAT_VERSION: u32 = 1;

/// `node.port`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct PortRef {
    pub node: String,
    pub port: String,
}

impl PortRef {
    pub fn parse(s: &str) -> Option<PortRef> {
        let (node, port) = s.split_once('.')?;
        if !is_valid_id(node) || !is_valid_id(port) {
            return None;
        }
        Some(PortRef { node: node.into(), port: port.into() })
    }
}

impl std::fmt::Display for PortRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}", self.node, self.port)
    }
}

/// Node ids and port names: letters, digits, `_` and `-`.
pub fn is_valid_id(s: &str) -> bool {
    !s.is_empty() && s.chars().all(|c| c.is_alphanumeric() || c == '_' || c == '-')
}

/// One node as written in the file: only the parameters given explicitly.
#[derive(Clone, Debug)]
pub struct NodeDecl {
    pub id: String,
    pub kind: String,
    pub params: Vec<(String, ParamValue)>,
    /// Where the node and each explicit parameter were written (default for nodes made in code).
    pub pos: Pos,
    pub param_pos: Vec<Pos>,
}

impl NodeDecl {
    pub fn new(id: &str, kind: &str) -> Self {
        NodeDecl { id: id.into(), kind: kind.into(), params: Vec::new(), pos: Pos::default(), param_pos: Vec::new() }
    }
    pub fn param(&self, name: &str) -> Option<&ParamValue> {
        self.params.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }
    fn param_pos(&self, name: &str) -> Pos {
        self.params.iter().position(|(n, _)| n == name).and_then(|i| self.param_pos.get(i).copied()).unwrap_or(self.pos)
    }
}

#[derive(Clone, Debug)]
pub struct Edge {
    pub from: PortRef,
    pub to: PortRef,
    pub pos: Pos,
}

#[derive(Clone, Debug)]
pub struct Output {
    pub name: String,
    pub port: PortRef,
    pub pos: Pos,
}

/// Layout for the visual editor. Never part of a cache key.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EditorSection {
    pub positions: Vec<(String, [f64; 2])>,
}

#[derive(Clone, Debug, Default)]
pub struct Graph {
    pub nodes: Vec<NodeDecl>,
    pub edges: Vec<Edge>,
    pub outputs: Vec<Output>,
    pub editor: EditorSection,
    /// The file it was read from (for messages).
    pub file: Option<PathBuf>,
    /// Folder that relative file parameters resolve against.
    pub base_dir: PathBuf,
}

impl Graph {
    pub fn node(&self, id: &str) -> Option<&NodeDecl> {
        self.nodes.iter().find(|n| n.id == id)
    }
    pub fn node_index(&self, id: &str) -> Option<usize> {
        self.nodes.iter().position(|n| n.id == id)
    }

    /// Reads, parses and validates a graph file against the registry.
    pub fn load(path: &Path, registry: &Registry) -> Result<Graph, crate::GraphErrors> {
        let text = crate::read_input(path)
            .and_then(|b| String::from_utf8(b).map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidData, "it is not UTF-8 text")))
            .map_err(|e| {
                crate::GraphErrors::one(GraphError::new(format!("cannot read graph: {e}"))).with_file(&Some(path.to_path_buf()))
            })?;
        let g = Graph::parse(&text, Some(path))?;
        g.validate(registry)?;
        Ok(g)
    }

    /// Sets one parameter from `node.param` and a value written as RON (or bare text for
    /// string and file parameters), checking it against the schema.
    pub fn set_param_text(&mut self, registry: &Registry, assignment: &str, value: &str) -> Result<(), GraphError> {
        self.set_param_checked(registry, assignment, |spec| spec.read_text(value))
    }

    /// Sets one parameter from `node.param` and a value made by `value` from the parameter's
    /// schema (a language binding's own value, read as the schema asks), checking it as
    /// `set_param_text` does, with the same messages.
    pub fn set_param_checked(
        &mut self,
        registry: &Registry,
        assignment: &str,
        value: impl FnOnce(&crate::params::ParamSpec) -> Result<ParamValue, String>,
    ) -> Result<(), GraphError> {
        let (id, name) =
            assignment.split_once('.').ok_or_else(|| GraphError::new(format!("`{assignment}` is not of the form node.param")))?;
        let spec = self.param_spec(registry, id, name)?;
        let parsed = value(spec).map_err(|m| GraphError::new(m).node(id).param(name))?;
        let checked = spec.check(&parsed).map_err(|m| GraphError::new(m).node(id).param(name))?;
        self.set_param(id, name, checked);
        Ok(())
    }

    /// The schema of parameter `name` of node `id`: errors say which node is missing, or which
    /// parameters the node has (with the closest name).
    pub fn param_spec<'r>(&self, registry: &'r Registry, id: &str, name: &str) -> Result<&'r crate::params::ParamSpec, GraphError> {
        let node = self.node(id).ok_or_else(|| GraphError::new(format!("no node \"{id}\" in the graph")))?;
        let kind = registry.node(&node.kind).ok_or_else(|| GraphError::new(format!("unknown node kind \"{}\"", node.kind)).node(id))?;
        kind.schema().get(name).ok_or_else(|| {
            let names: Vec<_> = kind.schema().0.iter().map(|p| p.name).collect();
            let near = crate::registry::closest(name, names.iter().copied()).map(|n| format!("did you mean `{n}`? ")).unwrap_or_default();
            GraphError::new(format!("{} has no parameter `{name}` ({near}it has: {})", node.kind, names.join(", "))).node(id)
        })
    }

    /// Sets every parameter that declares a test value (`#[param(test = …)]`) to it: the graph
    /// at test size, as the tests, CI and the benches' test mode run it. Nodes of a kind the
    /// registry does not know are left as they are (loading reports them).
    pub fn shrink_to_test_size(&mut self, registry: &Registry) -> Result<(), GraphError> {
        for i in 0..self.nodes.len() {
            let Some(kind) = registry.node(&self.nodes[i].kind) else { continue };
            for spec in &kind.schema().0 {
                if let Some(v) = &spec.test {
                    let id = self.nodes[i].id.clone();
                    let checked = spec.check(v).map_err(|m| GraphError::new(format!("test value: {m}")).node(&id).param(spec.name))?;
                    self.set_param(&id, spec.name, checked);
                }
            }
        }
        Ok(())
    }

    /// Sets an already-checked parameter value (replacing or appending).
    pub fn set_param(&mut self, id: &str, name: &str, value: ParamValue) {
        let Some(node) = self.nodes.iter_mut().find(|n| n.id == id) else { return };
        match node.params.iter_mut().find(|(n, _)| n == name) {
            Some(slot) => slot.1 = value,
            None => {
                node.params.push((name.to_string(), value));
                node.param_pos.push(node.pos);
            }
        }
    }

    /// Node positions in `nodes` by id: built once where a pass looks many nodes up
    /// (`node` walks the list).
    pub fn index(&self) -> HashMap<&str, usize> {
        self.nodes.iter().enumerate().map(|(i, n)| (n.id.as_str(), i)).collect()
    }

    /// Every edge by the input it feeds, (node id, port): what feeds an input, found at once.
    pub fn feeds(&self) -> HashMap<(&str, &str), &Edge> {
        self.edges.iter().map(|e| ((e.to.node.as_str(), e.to.port.as_str()), e)).collect()
    }

    /// Edges arriving at node `id`.
    pub fn edges_into<'a>(&'a self, id: &'a str) -> impl Iterator<Item = &'a Edge> + 'a {
        self.edges.iter().filter(move |e| e.to.node == id)
    }
}
