//! Node self-descriptions: what a node binary prints for `--describe` (JSON), and what the
//! launcher checks a graph against.

use serde::{Deserialize, Serialize};

/// One input port.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputPort {
    /// Port name, as used in graph.yaml `inputs:`.
    pub name: String,
    /// Schema name of the messages it takes.
    pub schema: String,
    /// True when the graph may leave it unconnected.
    #[serde(default)]
    pub optional: bool,
    /// What it is for.
    #[serde(default)]
    pub doc: String,
}

/// One output port.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutputPort {
    /// Port name, as used in graph.yaml `outputs:` and in `node/output` references.
    pub name: String,
    /// Schema name of the messages it publishes.
    pub schema: String,
    /// What it is for.
    #[serde(default)]
    pub doc: String,
}

/// One parameter with its default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Param {
    /// Parameter name, as used in graph.yaml `params:`.
    pub name: String,
    /// Default value (JSON). `null` means "no value unless given" (any type is then accepted);
    /// otherwise a given value must have the default's JSON type.
    pub default: serde_json::Value,
    /// True when the graph must give a (non-null) value.
    #[serde(default)]
    pub required: bool,
    /// Meaning, unit, and where the default comes from.
    #[serde(default)]
    pub doc: String,
}

/// What `<node binary> --describe` prints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NodeDescription {
    /// Binary name (`evseg-slicer`, ...).
    pub binary: String,
    /// One line on what the node does.
    pub summary: String,
    /// Input ports.
    pub inputs: Vec<InputPort>,
    /// Output ports.
    pub outputs: Vec<OutputPort>,
    /// Parameters.
    pub params: Vec<Param>,
}

impl NodeDescription {
    /// The input port called `name`.
    pub fn input(&self, name: &str) -> Option<&InputPort> {
        self.inputs.iter().find(|p| p.name == name)
    }

    /// The output port called `name`.
    pub fn output(&self, name: &str) -> Option<&OutputPort> {
        self.outputs.iter().find(|p| p.name == name)
    }

    /// The parameter called `name`.
    pub fn param(&self, name: &str) -> Option<&Param> {
        self.params.iter().find(|p| p.name == name)
    }
}
