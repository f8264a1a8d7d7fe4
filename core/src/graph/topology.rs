//! The graph's topology on petgraph: a stable directed graph whose node `i` is `graph.nodes[i]`
//! (so it is keyed by node id through the graph), edges as the file lists them. Cycles,
//! topological order and reachability are petgraph's algorithms, not hand-written traversals.

use super::Graph;
use petgraph::algo;
use petgraph::stable_graph::{NodeIndex, StableDiGraph};
use petgraph::visit::{Dfs, NodeFiltered, Reversed, Walker};
use std::collections::HashMap;

/// Nodes and edges of a `Graph`, by index into `graph.nodes`.
pub struct Topology {
    g: StableDiGraph<(), ()>,
}

impl Topology {
    pub fn new(graph: &Graph) -> Self {
        let mut g = StableDiGraph::with_capacity(graph.nodes.len(), graph.edges.len());
        for _ in &graph.nodes {
            g.add_node(());
        }
        let index: HashMap<&str, usize> = graph.nodes.iter().enumerate().map(|(i, n)| (n.id.as_str(), i)).collect();
        for e in &graph.edges {
            if let (Some(&a), Some(&b)) = (index.get(e.from.node.as_str()), index.get(e.to.node.as_str())) {
                g.add_edge(NodeIndex::new(a), NodeIndex::new(b), ());
            }
        }
        Topology { g }
    }

    /// A cycle, as node indices starting at the one listed first in the file, if any.
    pub fn cycle(&self) -> Option<Vec<usize>> {
        let start = algo::toposort(&self.g, None).err()?.node_id();
        // The shortest way back to `start` through one of its successors closes the cycle.
        let back = self
            .g
            .neighbors(start)
            .filter_map(|s| if s == start { Some((0, vec![s])) } else { algo::astar(&self.g, s, |n| n == start, |_| 1, |_| 0) })
            .min_by_key(|(len, _)| *len)?;
        // `back.1` runs from the successor to `start` itself: drop that repeated end.
        let mut cycle: Vec<usize> = std::iter::once(start).chain(back.1).map(NodeIndex::index).collect();
        cycle.pop();
        let first = (0..cycle.len()).min_by_key(|&k| cycle[k]).unwrap_or(0);
        cycle.rotate_left(first);
        Some(cycle)
    }

    /// Nodes from which one of `targets` can be reached (the targets included): what a
    /// demand-driven run must evaluate.
    pub fn upstream_of(&self, targets: &[usize]) -> Vec<bool> {
        let rev = Reversed(&self.g);
        let mut seen = vec![false; self.g.node_count()];
        for &t in targets {
            for n in Dfs::new(rev, NodeIndex::new(t)).iter(rev) {
                seen[n.index()] = true;
            }
        }
        seen
    }

    /// Nodes reachable from `from` (itself included): what an edit of `from` makes stale.
    pub fn downstream_of(&self, from: usize) -> Vec<bool> {
        let mut seen = vec![false; self.g.node_count()];
        for n in Dfs::new(&self.g, NodeIndex::new(from)).iter(&self.g) {
            seen[n.index()] = true;
        }
        seen
    }

    /// Whether `to` can be reached from `from` along edges (a node reaches itself).
    pub fn reaches(&self, from: usize, to: usize) -> bool {
        algo::has_path_connecting(&self.g, NodeIndex::new(from), NodeIndex::new(to), None)
    }

    /// The nodes with `keep[i]` in an order where every node comes after its inputs, or the
    /// index of a node on a cycle among them.
    pub fn order(&self, keep: &[bool]) -> Result<Vec<usize>, usize> {
        let sub = NodeFiltered::from_fn(&self.g, |n: NodeIndex| keep[n.index()]);
        algo::toposort(&sub, None).map(|v| v.into_iter().map(NodeIndex::index).collect()).map_err(|c| c.node_id().index())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(nodes: &[&str], edges: &[(&str, &str)]) -> Graph {
        let n: String = nodes.iter().map(|id| format!("\"{id}\": (kind: \"K\", params: ()),")).collect();
        let e: String = edges.iter().map(|(a, b)| format!("(\"{a}.out\", \"{b}.in\"),")).collect();
        Graph::parse(&format!("(version: 1, nodes: {{ {n} }}, edges: [ {e} ])"), None).unwrap()
    }

    #[test]
    fn a_cycle_is_named_from_the_node_listed_first_and_self_loops_count() {
        let g = graph(&["x", "a", "b", "c"], &[("x", "a"), ("b", "c"), ("c", "a"), ("a", "b")]);
        assert_eq!(g.find_cycle().unwrap(), ["a", "b", "c"]);
        assert_eq!(graph(&["a", "b"], &[("a", "b"), ("b", "b")]).find_cycle().unwrap(), ["b"]);
        assert!(graph(&["a", "b", "c"], &[("a", "b"), ("a", "c"), ("b", "c")]).find_cycle().is_none());
    }

    #[test]
    fn order_puts_inputs_first_and_reachability_follows_edges() {
        let g = graph(&["d", "c", "b", "a", "lone"], &[("a", "b"), ("b", "c"), ("a", "c"), ("c", "d")]);
        let t = g.topology();
        let order = t.order(&[true; 5]).unwrap();
        let pos = |id: &str| order.iter().position(|&i| g.nodes[i].id == id).unwrap();
        assert!(pos("a") < pos("b") && pos("b") < pos("c") && pos("c") < pos("d"));
        let need = t.upstream_of(&[g.node_index("c").unwrap()]);
        let needed: Vec<&str> = g.nodes.iter().zip(&need).filter(|(_, n)| **n).map(|(d, _)| d.id.as_str()).collect();
        assert_eq!(needed, ["c", "b", "a"]);
        assert_eq!(g.downstream("b"), ["b", "c", "d"]);
        assert_eq!(g.upstream("c"), ["a", "b", "c"]);
        assert!(g.upstream("zz").is_empty());
        assert!(g.reaches("a", "d") && !g.reaches("d", "a") && g.reaches("lone", "lone"));
        assert_eq!(t.order(&[true, true, true, false, false]).unwrap().len(), 3, "a subset is ordered alone");
    }
}
