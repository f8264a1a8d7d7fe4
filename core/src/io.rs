//! Typed access to a running node's inputs and outputs.

use crate::node::NodeError;
use crate::port::{PortValue, Ports, Value};

/// Inputs by port name (already resolved by the executor) and the outputs a node sets.
pub struct Io<'a> {
    ports: &'a Ports,
    inputs: &'a [Value],
    pub(crate) outputs: Vec<Option<Value>>,
}

impl<'a> Io<'a> {
    /// `inputs` are in the order of `ports.inputs`.
    pub fn new(ports: &'a Ports, inputs: &'a [Value]) -> Self {
        Io { ports, inputs, outputs: vec![None; ports.outputs.len()] }
    }

    /// The value on input `name`, as its declared type.
    pub fn input<T: PortValue>(&self, name: &str) -> Result<&T, NodeError> {
        let i = self.ports.inputs.iter().position(|p| p.name == name).ok_or_else(|| NodeError::input(name, "no such input port"))?;
        self.inputs[i].get::<T>().ok_or_else(|| NodeError::input(name, format!("holds {}, not {}", self.inputs[i].type_name(), T::NAME)))
    }

    /// Sets output `name`; its type must be the declared one.
    pub fn set<T: PortValue>(&mut self, name: &str, value: T) -> Result<(), NodeError> {
        let i = self
            .ports
            .outputs
            .iter()
            .position(|p| p.name == name)
            .ok_or_else(|| NodeError::failed(format!("node set undeclared output `{name}`")))?;
        if self.ports.outputs[i].ty.name != T::NAME {
            return Err(NodeError::failed(format!("output `{name}` is declared {}, node set {}", self.ports.outputs[i].ty.name, T::NAME)));
        }
        self.outputs[i] = Some(Value::new(value));
        Ok(())
    }

    /// All outputs, or an error naming the first one the node did not set.
    pub(crate) fn finish(self) -> Result<Vec<Value>, NodeError> {
        self.outputs
            .into_iter()
            .zip(&self.ports.outputs)
            .map(|(v, d)| v.ok_or_else(|| NodeError::failed(format!("node did not set its output `{}`", d.name))))
            .collect()
    }
}
