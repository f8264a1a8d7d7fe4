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
        let kind = node.kind();
        assert!(self.nodes.insert(kind, node).is_none(), "node kind {kind} registered twice");
        self
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

    /// Kinds whose name is closest to `kind` (for "did you mean").
    pub fn suggest(&self, kind: &str) -> Option<&'static str> {
        let lower = kind.to_lowercase();
        self.nodes.keys().copied().find(|k| {
            let kl = k.to_lowercase();
            kl == lower || kl.contains(&lower) || lower.contains(&kl)
        })
    }
}
