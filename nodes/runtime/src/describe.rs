//! A small builder for node descriptions, so each node's `main` reads like its documentation.

use evseg_schemas::Message;
use evseg_schemas::describe::{InputPort, NodeDescription, OutputPort, Param};

/// Builds a [`NodeDescription`].
pub struct Describe(NodeDescription);

impl Describe {
    /// Starts a description of `binary` doing `summary`.
    pub fn new(binary: &str, summary: &str) -> Self {
        Self(NodeDescription {
            binary: binary.into(),
            summary: summary.into(),
            inputs: vec![],
            outputs: vec![],
            params: vec![],
        })
    }

    /// A required input port taking `T`.
    pub fn input<T: Message>(mut self, name: &str, doc: &str) -> Self {
        self.0.inputs.push(InputPort {
            name: name.into(),
            schema: T::SCHEMA.into(),
            optional: false,
            doc: doc.into(),
        });
        self
    }

    /// An optional input port taking `T`.
    pub fn optional_input<T: Message>(mut self, name: &str, doc: &str) -> Self {
        self.0.inputs.push(InputPort {
            name: name.into(),
            schema: T::SCHEMA.into(),
            optional: true,
            doc: doc.into(),
        });
        self
    }

    /// An output port publishing `T`.
    pub fn output<T: Message>(mut self, name: &str, doc: &str) -> Self {
        self.0.outputs.push(OutputPort {
            name: name.into(),
            schema: T::SCHEMA.into(),
            doc: doc.into(),
        });
        self
    }

    /// A parameter with a default (`serde_json::Value::Null`: optional, no value unless given).
    pub fn param(mut self, name: &str, default: impl Into<serde_json::Value>, doc: &str) -> Self {
        self.0.params.push(Param {
            name: name.into(),
            default: default.into(),
            required: false,
            doc: doc.into(),
        });
        self
    }

    /// A parameter the graph must give (any JSON type, not null).
    pub fn required(mut self, name: &str, doc: &str) -> Self {
        self.0.params.push(Param {
            name: name.into(),
            default: serde_json::Value::Null,
            required: true,
            doc: doc.into(),
        });
        self
    }

    /// The finished description.
    pub fn build(self) -> NodeDescription {
        self.0
    }
}
