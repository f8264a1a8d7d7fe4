//! relume-core: the data-flow node-graph framework under relume.
//!
//! Typed ports ([`PortValue`]), parameter schemas ([`Schema`]), an explicit [`Registry`],
//! the RON graph format ([`Graph`]), a demand-driven planner ([`make_plan`]), a concurrent
//! executor with an incremental cache ([`Engine`]) and the run report ([`RunReport`]).
//! No rendering code lives here.
//!
//! A graph is text; the registry says which node kinds exist, and a graph naming one it does
//! not know is refused before anything runs, with the kind's name (the node crates register
//! kinds; docs/guide/writing-a-node.md writes one):
//!
//! ```
//! use relume_core::{Graph, Registry};
//!
//! let g = Graph::parse(r#"(version: 1, nodes: { "a": (kind: "Nothing") }, outputs: { "x": "a.out" })"#, None).unwrap();
//! assert_eq!(g.nodes.len(), 1);
//! let refused = g.validate(&Registry::new()).unwrap_err();
//! assert!(refused.to_string().contains("Nothing"), "{refused}");
//! ```

mod budget;
pub mod cache;
pub mod codec;
mod ctx;
mod error;
mod exec;
mod explain;
mod file_hash;
pub mod graph;
mod hash;
mod input_file;
pub mod limits;
pub mod memory;
mod node;
mod params;
mod plan;
mod port;
mod printable;
mod registry;
mod report;
pub mod ron;
mod run_files;
pub mod shard;
mod standalone;

pub use budget::RunEstimate;
pub use ctx::{resolve_write_path, CancelToken, Event, NodeStatus, Observer, RunCtx, WritePolicy, WriteRoots};
pub use error::{GraphError, GraphErrors, NodeError};
pub use exec::{DiskPolicy, Engine, RunError, RunOptions, RunResult};
pub use explain::{PlanAction, PlanLine};
pub use file_hash::content_hash;
pub use graph::{Graph, FORMAT_VERSION};
pub use hash::{Hash, Hasher};
pub use input_file::read_input;
pub use memory::{MemoryEstimate, PortSize};
pub use node::{ports_of, run_typed, Caching, Documented, DynNode, Node};
pub use params::{FileList, ParamEnum, ParamKind, ParamSpec, ParamValue, ParamValues, Params, Schema};
pub use plan::{make_plan, Plan};
pub use port::{input_at, InputPorts, OutputPorts, PortDecl, PortTypeInfo, PortValue, Ports, Value};
pub use printable::{clipped, printable};
pub use relume_macros::{node, params, ParamEnum, Params};

// Lets the derive macros name `::relume_core` inside this crate's own tests.
extern crate self as relume_core;
pub use registry::{closest, Registry};
pub use report::{NodeReport, RunReport};
pub use run_files::{RunFile, RunFiles};
pub use shard::{ShardMode, ShardSpec, Sharded};
pub use standalone::{run_kind, run_standalone, run_standalone_with};
