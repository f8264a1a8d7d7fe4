//! Edits of the core graph as the editor makes them: add and remove nodes, connect with a type
//! and cycle check, disconnect, mark outputs. The core `Graph` is the document; the node-graph
//! widget only shows it.

use relume_core::graph::{Edge, NodeDecl, PortRef};
use relume_core::ron::Pos;
use relume_core::{Graph, ParamValue, Registry};

/// A fresh node id from the kind's name: `gaussian_blur`, `gaussian_blur_2`, … (core's).
pub fn unique_id(graph: &Graph, kind: &str) -> String {
    graph.unique_id(kind)
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

/// Inserts a copy of node `after` (same kind and parameters, then `params` set) between it and
/// what read its outputs: what read `after.out` now reads the copy's, which reads `after.out`
/// through `input` (one stroke after another in a chain of brush nodes). Returns the copy's id.
pub fn insert_copy_after(graph: &mut Graph, after: &str, out: &str, input: &str, params: Vec<(&str, ParamValue)>) -> Option<String> {
    let mut decl = graph.node(after)?.clone();
    let id = unique_id(graph, &decl.kind);
    decl.id = id.clone();
    graph.nodes.push(decl);
    for (name, v) in params {
        graph.set_param(&id, name, v);
    }
    for e in graph.edges.iter_mut().filter(|e| e.from.node == after && e.from.port == out) {
        e.from.node = id.clone();
    }
    for o in graph.outputs.iter_mut().filter(|o| o.port.node == after && o.port.port == out) {
        o.port.node = id.clone();
    }
    let from = PortRef { node: after.into(), port: out.into() };
    graph.edges.push(Edge { from, to: PortRef { node: id.clone(), port: input.into() }, pos: Pos::default() });
    let [x, y] = position(graph, after);
    graph.editor.positions.push((id.clone(), [x + 40.0, y + 90.0]));
    Some(id)
}

/// Connects `from` to `to` (replacing what fed `to`), after `check_connect` (core's).
pub fn connect(graph: &mut Graph, reg: &Registry, from: PortRef, to: PortRef) -> Result<(), String> {
    graph.connect(reg, from, to)
}

/// Removes the edge into `to`, if any.
pub fn disconnect(graph: &mut Graph, to: &PortRef) -> bool {
    let before = graph.edges.len();
    graph.edges.retain(|e| &e.to != to);
    before != graph.edges.len()
}

/// Makes `port` a graph output named `name`, or (with `on` false) removes the outputs naming it
/// (core's).
pub fn set_output(graph: &mut Graph, port: &PortRef, name: &str, on: bool) {
    graph.set_output(port, name, on)
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

/// Places the nodes that have no layout position (a graph written by hand or by a script, with
/// no `editor` section) in columns by depth, sources on the left, each column in file order,
/// instead of stacking them all at the origin. A node takes as much of its column as its ports
/// need (the widget draws one line a port), so tall nodes do not cover the next. Nodes that
/// have a position keep it.
pub fn lay_out_unplaced(graph: &mut Graph, reg: &Registry) {
    const COLUMN: f64 = 280.0;
    const ROW: f64 = 160.0;
    // A node's height in layout units: title and state lines, then one line a port.
    let height = |kind: &str| {
        let ports = reg.node(kind).map_or(0, |k| k.ports().inputs.len() + k.ports().outputs.len());
        (110.0 + 26.0 * ports as f64).max(ROW)
    };
    let placed: std::collections::HashSet<&str> = graph.editor.positions.iter().map(|(n, _)| n.as_str()).collect();
    if graph.nodes.iter().all(|n| placed.contains(n.id.as_str())) {
        return;
    }
    // Depth: the longest path from a source, relaxed once per node (a cycle cannot load).
    let index = graph.index();
    let mut depth = vec![0usize; graph.nodes.len()];
    for _ in 0..graph.nodes.len() {
        let mut changed = false;
        for e in &graph.edges {
            let (Some(&a), Some(&b)) = (index.get(e.from.node.as_str()), index.get(e.to.node.as_str())) else { continue };
            if depth[b] < depth[a] + 1 {
                depth[b] = depth[a] + 1;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let mut tops = std::collections::HashMap::new();
    let unplaced: Vec<(String, [f64; 2])> = graph
        .nodes
        .iter()
        .enumerate()
        .filter(|(_, n)| !placed.contains(n.id.as_str()))
        .map(|(i, n)| {
            let top = tops.entry(depth[i]).or_insert(0.0);
            let at = [depth[i] as f64 * COLUMN, *top];
            *top += height(&n.kind);
            (n.id.clone(), at)
        })
        .collect();
    graph.editor.positions.extend(unplaced);
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

    #[test]
    fn a_graph_without_positions_is_laid_out_in_columns_by_depth() {
        let (mut g, reg) = graph();
        g.editor.positions.clear();
        lay_out_unplaced(&mut g, &reg);
        let at = |id: &str| position(&g, id);
        // clean, noisy → sum → median → blur → error, tonemap; ImageError's five ports take
        // more than the smallest row.
        assert_eq!((at("clean"), at("noisy")), ([0.0, 0.0], [0.0, 160.0]));
        assert_eq!((at("sum"), at("median"), at("blur")), ([280.0, 0.0], [560.0, 0.0], [840.0, 0.0]));
        assert_eq!((at("error"), at("tonemap")), ([1120.0, 0.0], [1120.0, 110.0 + 26.0 * 4.0]));
        let distinct: std::collections::HashSet<[u64; 2]> = g.nodes.iter().map(|n| at(&n.id).map(f64::to_bits)).collect();
        assert_eq!(distinct.len(), g.nodes.len(), "no two nodes share a place");
        // Placed nodes keep their place; the laid-out graph is left alone.
        let before = g.editor.positions.clone();
        lay_out_unplaced(&mut g, &reg);
        assert_eq!(g.editor.positions, before);
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
