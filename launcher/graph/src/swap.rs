//! Replacing the binary of one node in a graph file's text, for A/B comparisons: the edit is
//! made where the file says `run:`, so the result is checked by [`crate::check_str`] like any
//! hand-written graph (ports, parameters and types of the new binary included).

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
        let start: usize = line
            .char_indices()
            .nth(span.column - 1)
            .map_or(line.len(), |(b, _)| b);
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
    fn an_unknown_node_is_an_error_naming_the_file() {
        let e = swap_binary("g.yaml", G, "zz", "x").unwrap_err().to_string();
        assert!(e.contains("g.yaml") && e.contains("zz"), "{e}");
    }
}
