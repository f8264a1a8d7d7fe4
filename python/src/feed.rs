//! Arrays fed into a graph from Python (`Graph.feed`): each fed input gets a node of kind
//! `ArrayInput` whose one parameter, `key`, is the hash of the array's pixels, so the cache
//! sees a new array as a new value and the same array again as the same. The pixels stay in
//! the graph's `ArrayInput` entry, which only that Python graph has: a graph with fed arrays
//! runs from the Python session that fed them.

use crate::kinds::ARRAY_INPUT as KIND;
use relume_base::types::Image;
use relume_core::{Caching, DynNode, NodeError, ParamValues, PortDecl, PortValue, Ports, RunCtx, Schema, Value};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

/// The kind, one per Python graph, holding the arrays fed to it by feeding node.
pub struct ArrayInput {
    ports: Ports,
    schema: Schema,
    /// Feeding node id → (key, pixels): a new array fed to a node replaces its old one.
    arrays: Mutex<BTreeMap<String, (String, Arc<Image>)>>,
}

impl ArrayInput {
    pub fn new() -> Self {
        ArrayInput {
            ports: Ports { inputs: vec![], outputs: vec![PortDecl::of::<Image>("image")] },
            schema: Schema::new().text("key", "").help("the hash of the fed array's pixels (set by Graph.feed)"),
            arrays: Mutex::new(BTreeMap::new()),
        }
    }

    /// Keeps `img` as node `id`'s array; its key (the value `id.key` must be set to).
    pub fn put(&self, id: &str, img: Image) -> String {
        let key = img.fingerprint().hex();
        self.arrays.lock().unwrap().insert(id.to_string(), (key.clone(), Arc::new(img)));
        key
    }
}

impl DynNode for ArrayInput {
    fn kind(&self) -> &'static str {
        KIND
    }
    fn version(&self) -> u32 {
        1
    }
    fn category(&self) -> &'static str {
        crate::kinds::CATEGORY
    }
    fn doc(&self) -> &str {
        "A numpy array fed from Python with Graph.feed, as an image (linear RGB). Runs only in the Python session that fed it."
    }
    fn ports(&self) -> &Ports {
        &self.ports
    }
    fn schema(&self) -> &Schema {
        &self.schema
    }
    fn caching(&self) -> Caching {
        Caching::Auto
    }
    fn run(&self, params: &ParamValues, _inputs: &[Value], _cx: &RunCtx) -> Result<Vec<Value>, NodeError> {
        let key = params.text("key");
        let arrays = self.arrays.lock().unwrap();
        match arrays.values().find(|(k, _)| k == key) {
            Some((_, img)) => Ok(vec![Value::new((**img).clone())]),
            None => Err(NodeError::param(
                "key",
                "no array with this key was fed in this session: feed it with Graph.feed(\"node.port\", array) \
                 (a graph with fed arrays runs only from the Python session that fed them)",
            )),
        }
    }
}
