//! The node trait, its type-erased form, node errors and the doc-comment macro.

use crate::ctx::RunCtx;
use crate::io::Io;
use crate::params::{ParamValues, Params, Schema};
use crate::port::Ports;
use std::fmt;

/// Where a node's results may be kept between runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Caching {
    /// In the memory cache only.
    Memory,
    /// In memory and, when the engine has a disk cache, on disk.
    Disk,
    /// Never cached: the node has a side effect (writes a file) and runs every time it is needed.
    Never,
}

/// The doc comment of a node type, available at run time (the editor tooltip, `relume nodes`).
/// Implemented by `node_doc!`.
pub trait Documented {
    const DOC: &'static str;
}

/// Declares a node struct with its doc comment and implements `Documented` from it:
/// ```ignore
/// relume_core::node_doc! {
///     /// Blurs an image with a separable Gaussian.
///     pub struct GaussianBlur;
/// }
/// ```
#[macro_export]
macro_rules! node_doc {
    ($(#[doc = $doc:literal])* $vis:vis struct $name:ident;) => {
        $(#[doc = $doc])*
        #[derive(Clone, Copy, Debug, Default)]
        $vis struct $name;
        impl $crate::Documented for $name {
            const DOC: &'static str = concat!($($doc, "\n"),*);
        }
    };
}

/// A stage of a pipeline. One file per node; see ARCHITECTURE.md.
pub trait Node: Documented + Send + Sync + 'static {
    const KIND: &'static str;
    /// Bump when the output for the same inputs and parameters changes.
    const VERSION: u32;
    /// Palette category in the editor (e.g. "image", "scene").
    const CATEGORY: &'static str;
    const CACHING: Caching = Caching::Memory;
    type Params: Params;
    fn ports() -> Ports;
    fn run(&self, p: &Self::Params, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError>;
}

/// Why a node did not produce its outputs.
#[derive(Clone, Debug, PartialEq)]
pub enum NodeError {
    Cancelled,
    /// A parameter's value cannot be used (beyond what the schema's range catches).
    Param {
        name: String,
        msg: String,
    },
    /// An input cannot be used (sizes disagree, data is not finite, …).
    Input {
        port: String,
        msg: String,
    },
    /// The node is declared but its algorithm is not finished.
    NotImplemented(&'static str),
    Failed(String),
}

impl NodeError {
    pub fn param(name: &str, msg: impl Into<String>) -> Self {
        NodeError::Param { name: name.into(), msg: msg.into() }
    }
    pub fn input(port: &str, msg: impl Into<String>) -> Self {
        NodeError::Input { port: port.into(), msg: msg.into() }
    }
    pub fn failed(msg: impl Into<String>) -> Self {
        NodeError::Failed(msg.into())
    }
}

impl fmt::Display for NodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NodeError::Cancelled => f.write_str("cancelled"),
            NodeError::Param { name, msg } => write!(f, "parameter `{name}`: {msg}"),
            NodeError::Input { port, msg } => write!(f, "input `{port}`: {msg}"),
            NodeError::NotImplemented(what) => write!(f, "not implemented yet: {what}"),
            NodeError::Failed(msg) => f.write_str(msg),
        }
    }
}

impl std::error::Error for NodeError {}

/// A node kind behind a trait object, as the registry and executor hold it.
pub trait DynNode: Send + Sync {
    fn kind(&self) -> &'static str;
    fn version(&self) -> u32;
    fn category(&self) -> &'static str;
    /// The doc comment with the leading space of each line removed.
    fn doc(&self) -> &str;
    fn ports(&self) -> &Ports;
    fn schema(&self) -> &Schema;
    fn caching(&self) -> Caching;
    fn run(&self, params: &ParamValues, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError>;
}

pub(crate) struct NodeEntry<N: Node> {
    node: N,
    ports: Ports,
    schema: Schema,
    doc: String,
}

impl<N: Node> NodeEntry<N> {
    pub(crate) fn new(node: N) -> Self {
        let doc = N::DOC.lines().map(|l| l.strip_prefix(' ').unwrap_or(l)).collect::<Vec<_>>().join("\n").trim().to_string();
        NodeEntry { node, ports: N::ports(), schema: N::Params::schema(), doc }
    }
}

impl<N: Node> DynNode for NodeEntry<N> {
    fn kind(&self) -> &'static str {
        N::KIND
    }
    fn version(&self) -> u32 {
        N::VERSION
    }
    fn category(&self) -> &'static str {
        N::CATEGORY
    }
    fn doc(&self) -> &str {
        &self.doc
    }
    fn ports(&self) -> &Ports {
        &self.ports
    }
    fn schema(&self) -> &Schema {
        &self.schema
    }
    fn caching(&self) -> Caching {
        N::CACHING
    }
    fn run(&self, params: &ParamValues, io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        let p = N::Params::from_values(params);
        self.node.run(&p, io, cx)
    }
}
