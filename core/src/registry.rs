//! The explicit registry of node kinds and port types (no globals: build one and pass it on).

use crate::node::{DynNode, Node, NodeEntry};
use crate::port::PortTypeInfo;
use std::collections::BTreeMap;
use std::sync::Arc;

#[derive(Default, Clone)]
pub struct Registry {
    nodes: BTreeMap<&'static str, Arc<dyn DynNode>>,
    port_types: BTreeMap<&'static str, PortTypeInfo>,
}

impl Registry {
    pub fn new() -> Self {
        Self::default()
    }

    /// Registers a node kind and the port types its ports use. Panics on a duplicate kind or
    /// on two different Rust types registered under one port-type name (programming errors).
    pub fn add<N: Node>(&mut self) -> &mut Self {
        self.add_dyn(Arc::new(NodeEntry::<N>::new()))
    }

    /// Registers a node kind given in its type-erased form: a node that holds state of its own
    /// (the test harness's logging nodes), or one built at run time (a plugin).
    pub fn add_dyn(&mut self, node: Arc<dyn DynNode>) -> &mut Self {
        for p in node.ports().inputs.iter().chain(&node.ports().outputs) {
            self.add_port_type(p.ty.clone());
        }
        if let Some(s) = node.sharded() {
            self.add_port_type(s.partial_decl().ty);
        }
        let kind = node.kind();
        let names = &node.schema().0;
        if let Some((i, p)) = names.iter().enumerate().find(|(i, p)| names[..*i].iter().any(|q| q.name == p.name)) {
            panic!("node kind {kind} declares the parameter `{}` twice (the {i}th: a flattened group repeats it?)", p.name);
        }
        assert!(self.nodes.insert(kind, node).is_none(), "node kind {kind} registered twice");
        self
    }

    /// Removes a kind (one defined at run time, before its new definition is added); the
    /// removed entry.
    pub fn remove(&mut self, kind: &str) -> Option<Arc<dyn DynNode>> {
        self.nodes.remove(kind)
    }

    /// Registers a port type (done by `add` for every port a node declares).
    pub fn add_port_type(&mut self, info: PortTypeInfo) {
        if let Some(old) = self.port_types.get(info.name) {
            assert_eq!(old.type_id, info.type_id, "two Rust types registered as port type {}", info.name);
            return;
        }
        self.port_types.insert(info.name, info);
    }

    pub fn node(&self, kind: &str) -> Option<&Arc<dyn DynNode>> {
        self.nodes.get(kind)
    }

    pub fn nodes(&self) -> impl Iterator<Item = &Arc<dyn DynNode>> {
        self.nodes.values()
    }

    pub fn port_type(&self, name: &str) -> Option<&PortTypeInfo> {
        self.port_types.get(name)
    }

    pub fn port_types(&self) -> impl Iterator<Item = &PortTypeInfo> {
        self.port_types.values()
    }

    /// The kind whose name is closest to `kind` (for "did you mean"): see [`closest`].
    pub fn suggest(&self, kind: &str) -> Option<&'static str> {
        closest(kind, self.nodes.keys().copied())
    }
}

/// The candidate closest to `word` when one is close enough to be a slip (for "did you
/// mean"): case is ignored; a candidate qualifies when its edit distance (Levenshtein, in
/// characters) is at most 2 or at most a third of the longer name, or when one name contains
/// the other and the shorter has at least 4 characters (`Tonemapper` → `Tonemap`). The
/// smallest distance wins; ties go to the first candidate.
pub fn closest<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let w: Vec<char> = word.to_lowercase().chars().collect();
    let mut best: Option<(usize, &'a str)> = None;
    for c in candidates {
        let k: Vec<char> = c.to_lowercase().chars().collect();
        let d = levenshtein(&w, &k);
        let longer = w.len().max(k.len());
        let shorter = w.len().min(k.len());
        let (ws, ks): (String, String) = (w.iter().collect(), k.iter().collect());
        let contains = shorter >= 4 && (ws.contains(&ks) || ks.contains(&ws));
        let close = d <= 2 || 3 * d <= longer || contains;
        if close && d < longer && best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, c));
        }
    }
    best.map(|(_, c)| c)
}

/// Edit distance (insertions, deletions, substitutions) between two character strings.
fn levenshtein(a: &[char], b: &[char]) -> usize {
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.iter().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let up = row[j + 1];
            row[j + 1] = (diag + usize::from(ca != cb)).min(up + 1).min(row[j] + 1);
            diag = up;
        }
    }
    row[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suggestions_allow_slips_of_case_spelling_and_suffix_but_not_unrelated_names() {
        let kinds = ["GaussianBlur", "PathTrace", "Tonemap", "TestPattern", "LoadImage", "SaveImage"];
        for (typo, want) in [
            ("tonemap", "Tonemap"),
            ("PathTracer", "PathTrace"),
            ("Tonemapper", "Tonemap"),
            ("GausianBlur", "GaussianBlur"),
            ("gaussian_blur", "GaussianBlur"),
            ("LoadImg", "LoadImage"),
            ("SaveImag", "SaveImage"),
        ] {
            assert_eq!(closest(typo, kinds), Some(want), "{typo}");
        }
        for unrelated in ["Banana", "X", "Blur2000Ultra", ""] {
            assert_eq!(closest(unrelated, kinds), None, "{unrelated}");
        }
        assert_eq!(closest("sigam", ["sigma", "truncate"]), Some("sigma"));
        assert_eq!(closest("radius", ["sigma", "truncate"]), None);
        assert_eq!(levenshtein(&['a', 'b'], &[]), 2);
    }
}
