//! The names the package's own node kinds share.

/// The category Python-defined kinds (and fed arrays) show under in the catalogue.
pub const CATEGORY: &str = "python";

/// The kind of the node `Graph.feed` adds.
pub const ARRAY_INPUT: &str = "ArrayInput";
