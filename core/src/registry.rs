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
    pub fn add<N: Node>(&mut self, node: N) -> &mut Self {
        let entry = NodeEntry::new(node);
        for p in entry.ports().inputs.iter().chain(&entry.ports().outputs) {
            self.add_port_type(p.ty.clone());
        }
        assert!(self.nodes.insert(N::KIND, Arc::new(entry)).is_none(), "node kind {} registered twice", N::KIND);
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
