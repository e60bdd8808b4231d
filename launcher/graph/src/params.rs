//! Node parameters: YAML values converted to JSON and checked against the binary's description.

use std::collections::BTreeMap;

use evseg_schemas::describe::NodeDescription;
use serde_json::{Map, Number, Value as Json};

use crate::diagnostic::{Problems, Span, did_you_mean, name_list};
use crate::yaml::{Entry, Node, Value};

/// The JSON type of a value, as named in messages.
fn json_kind(value: &Json) -> &'static str {
    match value {
        Json::Null => "null",
        Json::Bool(_) => "a boolean",
        Json::Number(_) => "a number",
        Json::String(_) => "a string",
        Json::Array(_) => "a list",
        Json::Object(_) => "a mapping",
    }
}

/// Converts a YAML value to JSON. Mapping keys come out sorted so the result does not depend
/// on the order in the file. Infinite and NaN numbers (no JSON form) are reported.
pub(crate) fn to_json(node: &Node, p: &mut Problems) -> Option<Json> {
    Some(match &node.value {
        Value::Null => Json::Null,
        Value::Bool(b) => Json::Bool(*b),
        Value::Int(i) => Json::Number(Number::from(*i)),
        Value::Float(x) => match Number::from_f64(*x) {
            Some(n) => Json::Number(n),
            None => {
                p.error(
                    node.at,
                    format!("{x} cannot be a parameter value: JSON has no infinity or NaN"),
                );
                return None;
            }
        },
        Value::Str(s) => Json::String(s.clone()),
        Value::Seq(items) => {
            let mut out = Vec::with_capacity(items.len());
            let mut ok = true;
            for item in items {
                match to_json(item, p) {
                    Some(v) => out.push(v),
                    None => ok = false,
                }
            }
            if !ok {
                return None;
            }
            Json::Array(out)
        }
        Value::Map(entries) => {
            let mut sorted: Vec<&Entry> = entries.iter().collect();
            sorted.sort_by(|a, b| a.key.cmp(&b.key));
            let mut out = Map::new();
            let mut ok = true;
            for entry in sorted {
                match to_json(&entry.value, p) {
                    Some(v) => {
                        out.insert(entry.key.clone(), v);
                    }
                    None => ok = false,
                }
            }
            if !ok {
                return None;
            }
            Json::Object(out)
        }
    })
}

/// The parameters of a node: the values given (checked against `description`) plus defaults
/// for the rest, in the description's order, and the position of each given key.
/// `anchor` is where a missing required parameter is reported (the node's id). `given` is
/// `None` when `params:` could not be read (then missing parameters are not reported).
pub(crate) fn resolve(
    given: Option<&[Entry]>,
    description: &NodeDescription,
    node_name: &str,
    anchor: Span,
    p: &mut Problems,
) -> (Map<String, Json>, BTreeMap<String, Span>) {
    let names: Vec<&str> = description.params.iter().map(|d| d.name.as_str()).collect();
    let mut values: BTreeMap<&str, Json> = BTreeMap::new();
    let mut spans = BTreeMap::new();
    for entry in given.unwrap_or_default() {
        let Some(declared) = description.param(&entry.key) else {
            p.error(
                entry.key_at,
                format!(
                    "unknown parameter `{}` for `{}`; its parameters: {}{}",
                    entry.key,
                    description.binary,
                    name_list(&names),
                    did_you_mean(&entry.key, &names)
                ),
            );
            continue;
        };
        spans.insert(entry.key.clone(), entry.key_at);
        let Some(value) = to_json(&entry.value, p) else {
            continue;
        };
        let expected = json_kind(&declared.default);
        if declared.default.is_null() {
            if value.is_null() && declared.required {
                p.error(
                    entry.value.at,
                    format!("parameter `{}` is required and cannot be null", entry.key),
                );
                continue;
            }
        } else if json_kind(&value) != expected {
            p.error(
                entry.value.at,
                format!(
                    "parameter `{}` takes {expected} (its default is {}), got {}",
                    entry.key,
                    declared.default,
                    json_kind(&value)
                ),
            );
            continue;
        }
        values.insert(declared.name.as_str(), value);
    }
    let mut out = Map::new();
    for declared in &description.params {
        match values.remove(declared.name.as_str()) {
            Some(value) => {
                out.insert(declared.name.clone(), value);
            }
            None if declared.required => {
                if given.is_some() && !spans.contains_key(&declared.name) {
                    p.error(
                        anchor,
                        format!(
                            "node `{node_name}` needs parameter `{}` (`{}` has no default for it){}",
                            declared.name,
                            description.binary,
                            if declared.doc.is_empty() {
                                String::new()
                            } else {
                                format!(": {}", declared.doc)
                            }
                        ),
                    );
                }
            }
            None => {
                out.insert(declared.name.clone(), declared.default.clone());
            }
        }
    }
    (out, spans)
}
