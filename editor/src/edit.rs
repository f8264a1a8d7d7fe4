//! Edits of the core graph as the editor makes them: add and remove nodes, connect with a type
//! and cycle check, disconnect, mark outputs. The core `Graph` is the document; the node-graph
//! widget only shows it.

use relume_core::graph::{Edge, NodeDecl, Output, PortRef};
use relume_core::ron::Pos;
use relume_core::{Graph, Registry};

/// A fresh node id from the kind's name: `gaussian_blur`, `gaussian_blur_2`, ….
pub fn unique_id(graph: &Graph, kind: &str) -> String {
    let mut base = String::new();
    for (i, c) in kind.chars().enumerate() {
        if c.is_uppercase() && i > 0 {
            base.push('_');
        }
        base.extend(c.to_lowercase());
    }
    if graph.node(&base).is_none() {
        return base;
    }
    (2..).map(|n| format!("{base}_{n}")).find(|id| graph.node(id).is_none()).expect("unbounded")
}

/// Adds a node of `kind` with default parameters at `pos`; returns its id.
pub fn add_node(graph: &mut Graph, kind: &str, pos: [f64; 2]) -> String {
    let id = unique_id(graph, kind);
    graph.nodes.push(NodeDecl::new(&id, kind));
    graph.editor.positions.push((id.clone(), pos));
    id
}

/// Removes a node with its edges, the outputs naming it and its layout.
pub fn remove_node(graph: &mut Graph, id: &str) {
    graph.nodes.retain(|n| n.id != id);
    graph.edges.retain(|e| e.from.node != id && e.to.node != id);
    graph.outputs.retain(|o| o.port.node != id);
    graph.editor.positions.retain(|(n, _)| n != id);
}

/// Why a connection is refused, in words for the status line (core's check: types and cycles).
pub fn check_connect(graph: &Graph, reg: &Registry, from: &PortRef, to: &PortRef) -> Result<(), String> {
    graph.check_connection(reg, from, to)
}

/// Every node downstream of `id` (itself included).
pub fn downstream(graph: &Graph, id: &str) -> Vec<String> {
    graph.downstream(id)
}

/// Connects `from` to `to` (replacing what fed `to`), after `check_connect`.
pub fn connect(graph: &mut Graph, reg: &Registry, from: PortRef, to: PortRef) -> Result<(), String> {
    check_connect(graph, reg, &from, &to)?;
    match graph.edges.iter_mut().find(|e| e.to == to) {
        Some(e) => e.from = from,
        None => graph.edges.push(Edge { from, to, pos: Pos::default() }),
    }
    Ok(())
}

/// Removes the edge into `to`, if any.
pub fn disconnect(graph: &mut Graph, to: &PortRef) -> bool {
    let before = graph.edges.len();
    graph.edges.retain(|e| &e.to != to);
    before != graph.edges.len()
}

/// Makes `port` a graph output named `name`, or (with `on` false) removes the outputs naming it.
pub fn set_output(graph: &mut Graph, port: &PortRef, name: &str, on: bool) {
    graph.outputs.retain(|o| &o.port != port && (!on || o.name != name));
    if on {
        graph.outputs.push(Output { name: name.to_string(), port: port.clone(), pos: Pos::default() });
    }
}

/// A fresh output name for a port: the port's name if free, else `node_port`.
pub fn output_name(graph: &Graph, port: &PortRef) -> String {
    let free = |n: &str| !graph.outputs.iter().any(|o| o.name == n);
    if free(&port.port) {
        return port.port.clone();
    }
    let joined = format!("{}_{}", port.node, port.port);
    if free(&joined) {
        return joined;
    }
    (2..).map(|i| format!("{joined}_{i}")).find(|n| free(n)).expect("unbounded")
}

/// Removes an explicit parameter so that the schema's default applies again.
pub fn reset_param(graph: &mut Graph, id: &str, name: &str) {
    if let Some(n) = graph.nodes.iter_mut().find(|n| n.id == id) {
        if let Some(i) = n.params.iter().position(|(p, _)| p == name) {
            n.params.remove(i);
            if i < n.param_pos.len() {
                n.param_pos.remove(i);
            }
        }
    }
}

/// The layout position of a node (origin when it has none).
pub fn position(graph: &Graph, id: &str) -> [f64; 2] {
    graph.editor.positions.iter().find(|(n, _)| n == id).map(|(_, p)| *p).unwrap_or([0.0, 0.0])
}

pub fn set_position(graph: &mut Graph, id: &str, pos: [f64; 2]) {
    match graph.editor.positions.iter_mut().find(|(n, _)| n == id) {
        Some(slot) => slot.1 = pos,
        None => graph.editor.positions.push((id.to_string(), pos)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph() -> (Graph, Registry) {
        let reg = crate::registry();
        let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../graphs/filters.ron")).unwrap();
        (Graph::parse(&text, None).unwrap(), reg)
    }

    fn p(s: &str) -> PortRef {
        PortRef::parse(s).unwrap()
    }

    #[test]
    fn ids_are_snake_case_and_unique() {
        let (mut g, _) = graph();
        assert_eq!(add_node(&mut g, "GaussianBlur", [0.0, 0.0]), "gaussian_blur");
        assert_eq!(add_node(&mut g, "GaussianBlur", [0.0, 0.0]), "gaussian_blur_2");
        assert_eq!(unique_id(&g, "Combine"), "combine");
    }

    #[test]
    fn connecting_different_types_or_a_cycle_is_refused() {
        let (mut g, reg) = graph();
        let err = connect(&mut g, &reg, p("error.metrics"), p("tonemap.image")).unwrap_err();
        assert!(err.contains("port types differ"), "{err}");
        let err = connect(&mut g, &reg, p("blur.image"), p("median.image")).unwrap_err();
        assert!(err.contains("cycle"), "{err}");
        let edges = g.edges.len();
        connect(&mut g, &reg, p("sum.image"), p("tonemap.image")).unwrap();
        assert_eq!(g.edges.len(), edges, "an input keeps one edge: the new one replaces the old");
        assert!(g.validate(&reg).is_ok());
    }

    #[test]
    fn removing_a_node_drops_its_edges_outputs_and_layout() {
        let (mut g, reg) = graph();
        remove_node(&mut g, "tonemap");
        assert!(g.node("tonemap").is_none());
        assert!(!g.edges.iter().any(|e| e.to.node == "tonemap"));
        assert!(!g.outputs.iter().any(|o| o.name == "image"));
        assert!(g.validate(&reg).is_ok());
    }

    #[test]
    fn downstream_follows_edges() {
        let (g, _) = graph();
        assert_eq!(downstream(&g, "median"), ["blur", "error", "median", "tonemap"]);
        assert_eq!(downstream(&g, "tonemap"), ["tonemap"]);
    }

    #[test]
    fn outputs_get_free_names() {
        let (mut g, _) = graph();
        let port = p("blur.image");
        let name = output_name(&g, &port);
        assert_eq!(name, "blur_image");
        set_output(&mut g, &port, &name, true);
        assert!(g.outputs.iter().any(|o| o.name == "blur_image"));
        set_output(&mut g, &port, &name, false);
        assert!(!g.outputs.iter().any(|o| o.port == port));
    }
}
