//! Load-time errors that name the file, line, node and parameter, and run-time node errors.

use crate::ron::Pos;
use std::fmt;
use std::path::PathBuf;

/// One problem in a graph file.
#[derive(Clone, Debug, PartialEq)]
pub struct GraphError {
    pub file: Option<PathBuf>,
    pub pos: Option<Pos>,
    pub node: Option<String>,
    pub param: Option<String>,
    pub msg: String,
}

impl GraphError {
    pub fn new(msg: impl Into<String>) -> Self {
        GraphError { file: None, pos: None, node: None, param: None, msg: msg.into() }
    }
    pub fn at(mut self, pos: Pos) -> Self {
        self.pos = Some(pos);
        self
    }
    pub fn node(mut self, id: &str) -> Self {
        self.node = Some(id.to_string());
        self
    }
    pub fn param(mut self, name: &str) -> Self {
        self.param = Some(name.to_string());
        self
    }
}

impl fmt::Display for GraphError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.file, &self.pos) {
            (Some(file), Some(p)) => write!(f, "{}:{}:{}: ", file.display(), p.line, p.col)?,
            (Some(file), None) => write!(f, "{}: ", file.display())?,
            (None, Some(p)) => write!(f, "line {}:{}: ", p.line, p.col)?,
            (None, None) => {}
        }
        if let Some(n) = &self.node {
            write!(f, "node \"{n}\": ")?;
        }
        if let Some(p) = &self.param {
            write!(f, "parameter `{p}`: ")?;
        }
        f.write_str(&self.msg)
    }
}

/// All problems found in one graph, in file order.
#[derive(Clone, Debug, PartialEq)]
pub struct GraphErrors(pub Vec<GraphError>);

impl GraphErrors {
    pub fn one(e: GraphError) -> Self {
        GraphErrors(vec![e])
    }
    pub(crate) fn with_file(mut self, file: &Option<PathBuf>) -> Self {
        for e in &mut self.0 {
            e.file = e.file.take().or_else(|| file.clone());
        }
        self
    }
}

impl fmt::Display for GraphErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("\n")?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for GraphErrors {}

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
    /// A request over a limit (an image or point count past what may be allocated, a
    /// memory budget), refused before allocating. Bad input like an out-of-range parameter:
    /// the command line exits 2 for it. `param` names the parameter to lower, where one is to blame.
    OverLimit {
        param: Option<String>,
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
    /// A request over a limit, refused before allocating (see `OverLimit`).
    pub fn over_limit(msg: impl Into<String>) -> Self {
        NodeError::OverLimit { param: None, msg: msg.into() }
    }
    /// As `over_limit`, blaming parameter `name`.
    pub fn over_limit_param(name: &str, msg: impl Into<String>) -> Self {
        NodeError::OverLimit { param: Some(name.into()), msg: msg.into() }
    }
    /// Whether this is the refusal of a request over a limit: bad input the person fixes by
    /// asking for less, not a failure of the run (the command line exits 2 for it).
    pub fn is_over_limit(&self) -> bool {
        matches!(self, NodeError::OverLimit { .. })
    }
}

impl fmt::Display for NodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NodeError::Cancelled => f.write_str("cancelled"),
            NodeError::Param { name, msg } => write!(f, "parameter `{name}`: {msg}"),
            NodeError::Input { port, msg } => write!(f, "input `{port}`: {msg}"),
            NodeError::OverLimit { param: Some(name), msg } => write!(f, "parameter `{name}`: {msg}"),
            NodeError::OverLimit { param: None, msg } => f.write_str(msg),
            NodeError::NotImplemented(what) => write!(f, "not implemented yet: {what}"),
            NodeError::Failed(msg) => f.write_str(msg),
        }
    }
}

impl std::error::Error for NodeError {}
