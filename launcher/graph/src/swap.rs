//! Replacing the binary of one node in a graph file's text, for A/B comparisons: the edit is
//! made where the file says `run:`, so the result is checked by [`crate::check_str`] like any
//! hand-written graph (ports, parameters and types of the new binary included).
//!
//! [`swap_adapted`] also fits the graph to the new binary where that is safe, each change with
//! a note: the old binary's parameters the new one does not declare are removed, and optional
//! inputs of other nodes that read an output the new binary does not publish are left
//! unwired. Everything else (a required input left unfed, a port of another type) is left to
//! the checker, which reports it with file, line and column.

use crate::Resolver;
use crate::diagnostic::{Problems, Span};
use crate::{GraphError, raw, yaml};

/// `text` (the graph file `file_name`) with node `node`'s `run:` value replaced by `binary`.
/// Errors: the text does not parse, there is no node `node`, or its `run:` value is not a plain
/// or quoted scalar on one line.
pub fn swap_binary(file_name: &str, text: &str, node: &str, binary: &str) -> Result<String, GraphError> {
    let mut problems = Problems::new(file_name);
    let at = yaml::parse(text, &mut problems).and_then(|root| {
        let g = raw::read(&root, &mut problems)?;
        g.nodes
            .iter()
            .find(|n| n.id.as_ref().is_some_and(|id| id.value == node))
            .and_then(|n| n.run.as_ref().map(|r| (r.at, r.value.clone())))
    });
    let Some((span, old)) = at else {
        if problems.is_empty() {
            problems.error(Span::new(1, 1), format!("no node `{node}` with a `run:` to swap"));
        }
        return Err(GraphError::Invalid(problems.into_sorted()));
    };
    let mut out = String::with_capacity(text.len() + binary.len());
    for (i, line) in text.split_inclusive('\n').enumerate() {
        if i + 1 != span.line {
            out.push_str(line);
            continue;
        }
        let start = byte_at(line, span.column).unwrap_or(line.len());
        let rest = &line[start..];
        let len = if rest.starts_with(&old) {
            old.len()
        } else if (rest.starts_with('"') || rest.starts_with('\'')) && rest[1..].starts_with(&old) {
            old.len() + 2
        } else {
            let mut p = Problems::new(file_name);
            p.error(
                span,
                format!("cannot swap `{old}`: write it as a plain or quoted value on one line"),
            );
            return Err(GraphError::Invalid(p.into_sorted()));
        };
        out.push_str(&line[..start]);
        out.push_str(binary);
        out.push_str(&line[start + len..]);
    }
    Ok(out)
}

/// A graph text after [`swap_adapted`].
#[derive(Debug, Clone, PartialEq)]
pub struct AdaptedSwap {
    /// The graph text: the new `run:` value and the removals.
    pub text: String,
    /// One line per removal: `file:line:column`, what was removed and why.
    pub notes: Vec<String>,
}

/// One mapping entry to remove: its key and value positions, and the note that says why.
struct Removal {
    key_at: Span,
    value_at: Span,
    /// Entries in its mapping (a block mapping keeps at least one).
    siblings: usize,
    note: String,
}

/// [`swap_binary`], then the graph fitted to `binary`'s description (asked of `resolver`):
/// parameters of `node` that `binary` does not declare are removed, and inputs of other nodes
/// that read an output of `node` that `binary` does not publish are removed where the port is
/// optional (its consumer runs without it). Only entries whose value is a scalar on the key's
/// line are removed (block `key: value` lines, or entries of a one-line flow mapping), and a
/// block mapping keeps at least one entry; anything else stays for the checker to report. When
/// `binary` cannot be described, the text is the plain swap (the checker reports that too).
pub fn swap_adapted(
    file_name: &str,
    text: &str,
    node: &str,
    binary: &str,
    resolver: Resolver<'_>,
) -> Result<AdaptedSwap, GraphError> {
    let swapped = swap_binary(file_name, text, node, binary)?;
    let Ok(desc) = resolver(binary) else {
        return Ok(AdaptedSwap {
            text: swapped,
            notes: Vec::new(),
        });
    };
    let mut problems = Problems::new(file_name);
    let mut removals = Vec::new();
    if let Some(root) = yaml::parse(&swapped, &mut problems)
        && let Some(g) = raw::read(&root, &mut problems)
    {
        for n in &g.nodes {
            let Some(id) = n.id.as_ref().map(|i| i.value.as_str()) else {
                continue;
            };
            if id == node {
                let params = n.params.unwrap_or(&[]);
                for e in params.iter().filter(|e| desc.param(&e.key).is_none()) {
                    removals.push(Removal {
                        key_at: e.key_at,
                        value_at: e.value.at,
                        siblings: params.len(),
                        note: format!(
                            "parameter `{}` of node `{node}` removed: `{binary}` has no such parameter",
                            e.key
                        ),
                    });
                }
                continue;
            }
            let consumer = n.run.as_ref().and_then(|r| resolver(&r.value).ok());
            for input in n.inputs.iter().filter(|i| !i.feedback) {
                let Some((producer, output)) = input.from.value.split_once('/') else {
                    continue;
                };
                let optional = consumer
                    .as_ref()
                    .and_then(|c| c.input(&input.port.value))
                    .is_some_and(|p| p.optional);
                if producer == node && desc.output(output).is_none() && optional {
                    removals.push(Removal {
                        key_at: input.port.at,
                        value_at: input.from.at,
                        siblings: n.named_ports.as_ref().map_or(0, Vec::len),
                        note: format!(
                            "optional input `{}` of node `{id}` left unwired: `{binary}` does not publish `{output}`",
                            input.port.value
                        ),
                    });
                }
            }
        }
    }
    // Right to left, bottom to top: earlier positions stay valid.
    removals.sort_by_key(|r| std::cmp::Reverse((r.key_at.line, r.key_at.column)));
    let mut text = swapped;
    let mut notes = Vec::new();
    for r in removals {
        if let Some(t) = remove_entry(&text, &r) {
            text = t;
            notes.push(format!(
                "{file_name}:{}:{}: {}",
                r.key_at.line, r.key_at.column, r.note
            ));
        }
    }
    notes.reverse();
    Ok(AdaptedSwap { text, notes })
}

/// Byte offset of 1-based character column `column` in `line`.
fn byte_at(line: &str, column: usize) -> Option<usize> {
    if column == 0 {
        return None;
    }
    line.char_indices()
        .map(|(b, _)| b)
        .chain(std::iter::once(line.len()))
        .nth(column - 1)
}

/// `text` without the mapping entry `r`, or `None` where its layout is not one that
/// [`swap_adapted`] edits.
fn remove_entry(text: &str, r: &Removal) -> Option<String> {
    if r.value_at.line != r.key_at.line {
        return None;
    }
    let lines: Vec<&str> = text.split_inclusive('\n').collect();
    let li = r.key_at.line.checked_sub(1)?;
    let line = *lines.get(li)?;
    let kb = byte_at(line, r.key_at.column)?;
    let vb = byte_at(line, r.value_at.column)?;
    if vb < kb {
        return None;
    }
    let prefix = line[..kb].trim_end();
    let new_line = if prefix.is_empty() {
        // A block entry: the whole line, unless it is its mapping's only entry or a nested
        // value continues on the next lines.
        let indent = kb;
        let next = lines[li + 1..]
            .iter()
            .find(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
        let continues = next.is_some_and(|l| l.len() - l.trim_start().len() > indent);
        if r.siblings < 2 || continues || matches!(line[vb..].chars().next(), Some('[' | '{' | '|' | '>')) {
            return None;
        }
        String::new()
    } else if prefix.ends_with('{') || prefix.ends_with(',') {
        let ve = vb + scalar_len(&line[vb..])?;
        let after = &line[ve..];
        let rest = after.trim_start();
        if let Some(tail) = rest.strip_prefix(',') {
            // Up to the next entry.
            let next = ve + (after.len() - rest.len()) + 1 + (tail.len() - tail.trim_start().len());
            format!("{}{}", &line[..kb], &line[next..])
        } else if rest.starts_with('}') {
            // The last entry: from the comma before it (none when it is the only one).
            let start = if prefix.ends_with(',') {
                prefix.len() - 1
            } else {
                kb
            };
            format!("{}{}", &line[..start], &line[ve..])
        } else {
            return None;
        }
    } else {
        return None;
    };
    let mut out = String::with_capacity(text.len());
    for (i, l) in lines.iter().enumerate() {
        out.push_str(if i == li { &new_line } else { l });
    }
    Some(out)
}

/// Length (bytes) of the flow scalar at the start of `s`: a quoted string with its quotes, or
/// plain text up to `,`, `}` or the line's end, without trailing spaces. `None` for a nested
/// `[` or `{` value or an unclosed quote.
fn scalar_len(s: &str) -> Option<usize> {
    match s.chars().next()? {
        '[' | '{' => None,
        q @ ('"' | '\'') => {
            let mut escaped = false;
            for (i, c) in s.char_indices().skip(1) {
                if q == '"' && c == '\\' && !escaped {
                    escaped = true;
                    continue;
                }
                if c == q && !escaped {
                    return Some(i + 1);
                }
                escaped = false;
            }
            None
        }
        _ => {
            let end = s.find([',', '}', '\n', '#']).unwrap_or(s.len());
            Some(s[..end].trim_end().len())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: &str = "name: g\nnodes:\n  - id: a\n    run: evseg-source\n  - { id: b, run: \"evseg-slicer\", inputs: { events: a/events } }\n";

    #[test]
    fn swaps_plain_and_quoted_values_in_place() {
        let s = swap_binary("g.yaml", G, "a", "my-source").unwrap();
        assert!(s.contains("    run: my-source\n"), "{s}");
        let s = swap_binary("g.yaml", G, "b", "my-slicer").unwrap();
        assert!(s.contains("{ id: b, run: my-slicer, inputs"), "{s}");
        assert_eq!(s.lines().count(), G.lines().count());
    }

    #[test]
    fn malformed_yaml_is_an_error_naming_the_file_and_line() {
        let bad = "name: g\nnodes:\n  - id: f\n    run: fit\n    params: { a: 1\n";
        let e = swap_adapted("g.yaml", bad, "f", "learned", &describe)
            .unwrap_err()
            .to_string();
        assert!(e.contains("g.yaml:"), "{e}");
    }

    #[test]
    fn an_unknown_node_is_an_error_naming_the_file() {
        let e = swap_binary("g.yaml", G, "zz", "x").unwrap_err().to_string();
        assert!(e.contains("g.yaml") && e.contains("zz"), "{e}");
    }

    use evseg_schemas::describe::{InputPort, NodeDescription, OutputPort, Param};

    fn port(name: &str, optional: bool) -> InputPort {
        InputPort {
            name: name.into(),
            schema: "evseg.NormalFlow".into(),
            optional,
            doc: String::new(),
        }
    }

    fn output(name: &str) -> OutputPort {
        OutputPort {
            name: name.into(),
            schema: "evseg.NormalFlow".into(),
            doc: String::new(),
        }
    }

    fn param(name: &str) -> Param {
        Param {
            name: name.into(),
            default: serde_json::json!(0.0),
            required: false,
            doc: String::new(),
        }
    }

    /// `fit` publishes `flow` and `wide_flow` and has parameters `a` and `b`; `learned`
    /// publishes `flow` only and has `a`; `user` reads `flow` (required) and `wide`
    /// (optional).
    fn describe(binary: &str) -> Result<NodeDescription, String> {
        let d = |outputs: Vec<OutputPort>, inputs: Vec<InputPort>, params: Vec<Param>| NodeDescription {
            binary: binary.into(),
            summary: String::new(),
            inputs,
            outputs,
            params,
        };
        match binary {
            "fit" => Ok(d(
                vec![output("flow"), output("wide_flow")],
                vec![],
                vec![param("a"), param("b")],
            )),
            "learned" => Ok(d(vec![output("flow")], vec![], vec![param("a")])),
            "user" => Ok(d(vec![], vec![port("flow", false), port("wide", true)], vec![])),
            _ => Err("not found".into()),
        }
    }

    const FLOW: &str = "name: g\nnodes:\n  - id: f\n    run: fit\n    params: { a: 1.0, b: 2 }\n  - id: u\n    run: user\n    inputs:\n      flow: f/flow\n      wide: f/wide_flow\n";

    #[test]
    fn an_adapted_swap_drops_unknown_parameters_and_unwires_optional_inputs_with_notes() {
        let s = swap_adapted("g.yaml", FLOW, "f", "learned", &describe).unwrap();
        assert_eq!(
            s.text,
            "name: g\nnodes:\n  - id: f\n    run: learned\n    params: { a: 1.0 }\n  - id: u\n    run: user\n    inputs:\n      flow: f/flow\n"
        );
        assert_eq!(s.notes.len(), 2, "{:?}", s.notes);
        assert!(
            s.notes[0].starts_with("g.yaml:5:23: parameter `b` of node `f` removed"),
            "{:?}",
            s.notes
        );
        assert!(
            s.notes[1].starts_with("g.yaml:10:7: optional input `wide` of node `u` left unwired"),
            "{:?}",
            s.notes
        );
        // The same binary changes nothing.
        let same = swap_adapted("g.yaml", FLOW, "f", "fit", &describe).unwrap();
        assert_eq!((same.text.as_str(), same.notes.len()), (FLOW, 0));
    }

    #[test]
    fn flow_entries_are_removed_wherever_they_stand_and_block_lines_only_with_a_sibling() {
        let t = "name: g\nnodes:\n  - id: f\n    run: fit\n    params: { b: \"x, y\", a: 1 }\n  - { id: u, run: user, inputs: { wide: f/wide_flow, flow: f/flow } }\n";
        let s = swap_adapted("g.yaml", t, "f", "learned", &describe).unwrap();
        assert!(s.text.contains("    params: { a: 1 }\n"), "{}", s.text);
        assert!(s.text.contains("inputs: { flow: f/flow } }"), "{}", s.text);
        let t = "name: g\nnodes:\n  - id: f\n    run: fit\n    params: { a: 1, b: 2 }\n  - id: u\n    run: user\n    inputs:\n      wide: f/wide_flow\n";
        // `wide` is the only entry of a block mapping: left for the checker (which then
        // reports the missing required `flow` and the unpublished output together).
        let s = swap_adapted("g.yaml", t, "f", "learned", &describe).unwrap();
        assert!(s.text.contains("      wide: f/wide_flow\n"), "{}", s.text);
        assert_eq!(s.notes.len(), 1, "{:?}", s.notes);
        // A required input is never unwired.
        let t = "name: g\nnodes:\n  - id: f\n    run: fit\n  - id: u\n    run: user\n    inputs:\n      flow: f/wide_flow\n      wide: f/flow\n";
        let s = swap_adapted("g.yaml", t, "f", "learned", &describe).unwrap();
        assert!(s.text.contains("flow: f/wide_flow"), "{}", s.text);
        assert!(s.notes.is_empty(), "{:?}", s.notes);
        // An unknown binary: the plain swap.
        let s = swap_adapted("g.yaml", FLOW, "f", "nope", &describe).unwrap();
        assert_eq!(s.text, swap_binary("g.yaml", FLOW, "f", "nope").unwrap());
    }
}
