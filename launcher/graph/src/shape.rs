//! Reading typed fields out of the YAML tree, reporting wrong types and unknown keys.

use crate::diagnostic::{Problems, Span, did_you_mean, name_list};
use crate::yaml::{Entry, Node, Value};

/// A value and where it is in the file.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Spanned<T> {
    pub value: T,
    pub at: Span,
}

/// The entries of a mapping whose keys have been checked against the allowed ones.
pub(crate) struct Fields<'a> {
    pub at: Span,
    entries: &'a [Entry],
}

impl<'a> Fields<'a> {
    /// The value of `key`, if given.
    pub(crate) fn get(&self, key: &str) -> Option<&'a Node> {
        self.entries.iter().find(|e| e.key == key).map(|e| &e.value)
    }
}

/// Reads `node` as a mapping called `what` ("a node", "the top level", ...) whose keys must be
/// among `allowed`. Unknown keys are reported (and ignored); `None` when it is not a mapping.
pub(crate) fn mapping<'a>(
    node: &'a Node,
    what: &str,
    allowed: &[&str],
    p: &mut Problems,
) -> Option<Fields<'a>> {
    let Value::Map(entries) = &node.value else {
        p.error(
            node.at,
            format!(
                "{what} must be a mapping with keys {}, got {}",
                name_list(allowed),
                node.describe()
            ),
        );
        return None;
    };
    for entry in entries {
        if !allowed.contains(&entry.key.as_str()) {
            p.error(
                entry.key_at,
                format!(
                    "unknown key `{}` in {what}; allowed keys: {}{}",
                    entry.key,
                    name_list(allowed),
                    did_you_mean(&entry.key, allowed)
                ),
            );
        }
    }
    Some(Fields { at: node.at, entries })
}

/// The entries of a mapping with free keys (parameters, inputs, machines).
pub(crate) fn entries<'a>(node: &'a Node, what: &str, p: &mut Problems) -> Option<&'a [Entry]> {
    match &node.value {
        Value::Map(entries) => Some(entries),
        _ => {
            p.error(
                node.at,
                format!("{what} must be a mapping, got {}", node.describe()),
            );
            None
        }
    }
}

/// A string value.
pub(crate) fn string(node: &Node, what: &str, p: &mut Problems) -> Option<Spanned<String>> {
    match &node.value {
        Value::Str(s) => Some(Spanned {
            value: s.clone(),
            at: node.at,
        }),
        Value::Int(_) | Value::Float(_) | Value::Bool(_) => {
            p.error(
                node.at,
                format!(
                    "{what} must be a string, got {} (quote it to use it as text)",
                    node.describe()
                ),
            );
            None
        }
        _ => {
            p.error(
                node.at,
                format!("{what} must be a string, got {}", node.describe()),
            );
            None
        }
    }
}

/// An integer in `min..=u32::MAX`.
pub(crate) fn count(node: &Node, what: &str, min: u32, p: &mut Problems) -> Option<u32> {
    match &node.value {
        Value::Int(i) if *i < i64::from(min) => {
            p.error(node.at, format!("{what} must be at least {min}, got {i}"));
            None
        }
        Value::Int(i) => match u32::try_from(*i) {
            Ok(n) => Some(n),
            Err(_) => {
                p.error(node.at, format!("{what} must be at most {}, got {i}", u32::MAX));
                None
            }
        },
        _ => {
            p.error(
                node.at,
                format!("{what} must be an integer >= {min}, got {}", node.describe()),
            );
            None
        }
    }
}

/// An integer in `min..=max`; the error names both ends.
pub(crate) fn count_in(node: &Node, what: &str, min: u64, max: u64, p: &mut Problems) -> Option<u64> {
    match &node.value {
        Value::Int(i) => match u64::try_from(*i) {
            Ok(n) if (min..=max).contains(&n) => Some(n),
            _ => {
                p.error(node.at, format!("{what} must be in {min}..={max}, got {i}"));
                None
            }
        },
        _ => {
            p.error(
                node.at,
                format!(
                    "{what} must be an integer in {min}..={max}, got {}",
                    node.describe()
                ),
            );
            None
        }
    }
}

/// A boolean (`true` / `false`).
pub(crate) fn boolean(node: &Node, what: &str, p: &mut Problems) -> Option<bool> {
    match &node.value {
        Value::Bool(b) => Some(*b),
        _ => {
            p.error(
                node.at,
                format!("{what} must be true or false, got {}", node.describe()),
            );
            None
        }
    }
}

/// A list of strings; wrong items are reported and left out.
pub(crate) fn string_list(node: &Node, what: &str, p: &mut Problems) -> Option<Vec<Spanned<String>>> {
    let Value::Seq(items) = &node.value else {
        p.error(
            node.at,
            format!("{what} must be a list of strings, got {}", node.describe()),
        );
        return None;
    };
    Some(
        items
            .iter()
            .filter_map(|item| string(item, &format!("each item of {what}"), p))
            .collect(),
    )
}
