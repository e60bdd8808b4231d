//! A YAML value tree in which every value and every mapping key carries its source position,
//! built from the events of `saphyr-parser`.
//!
//! Scalars are resolved with the YAML 1.2 core schema (null, true/false, integers, floats,
//! strings); quoted scalars are always strings. Anchors and aliases work (an alias is a copy of
//! the anchored value, keeping the anchor's positions). Duplicate keys, non-scalar keys,
//! unsupported tags and more than one document are errors. Syntax errors stop parsing: they are
//! reported at the parser's position and no tree is returned.

use std::borrow::Cow;
use std::collections::HashMap;

use saphyr_parser::{Event, Marker, Parser, ScalarStyle, Tag};

use crate::diagnostic::{Problems, Span};

/// Deepest nesting of lists and mappings accepted. A graph file needs about 6 levels; the limit
/// only keeps hostile input from exhausting the stack (our own choice, not a YAML rule).
pub(crate) const MAX_DEPTH: usize = 64;

/// Most values (counting every scalar, list and mapping, with aliases expanded) accepted in one
/// file. A graph file has a few hundred; the limit stops "billion laughs" alias bombs (our own
/// choice, not a YAML rule).
pub(crate) const MAX_VALUES: usize = 100_000;

/// A YAML value.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Value {
    Null,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Seq(Vec<Node>),
    Map(Vec<Entry>),
}

/// A value and where it starts.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Node {
    pub value: Value,
    pub at: Span,
}

impl Node {
    /// Short text of the value for messages: `got a string "abc"`.
    pub(crate) fn describe(&self) -> String {
        match &self.value {
            Value::Null => "null".to_string(),
            Value::Bool(b) => format!("the boolean {b}"),
            Value::Int(i) => format!("the integer {i}"),
            Value::Float(x) => format!("the number {x}"),
            Value::Str(s) => format!("the string {s:?}"),
            Value::Seq(_) => "a list".to_string(),
            Value::Map(_) => "a mapping".to_string(),
        }
    }
}

/// One `key: value` pair of a mapping. Keys are the scalar's text.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Entry {
    pub key: String,
    pub key_at: Span,
    pub value: Node,
}

/// Position of a saphyr marker (line 1-based, column 0-based) as a 1-based [`Span`].
fn span_of(marker: &Marker) -> Span {
    Span::new(marker.line().max(1), marker.col() + 1)
}

enum KeyState {
    /// The next completed value is a key.
    Expect,
    /// A key was read; the next completed value is its value.
    Have(String, Span),
    /// The key was not a scalar (already reported); drop the next value.
    Bad,
}

enum Open {
    Seq(Vec<Node>),
    Map(Vec<Entry>, KeyState),
}

struct Frame {
    at: Span,
    anchor: usize,
    open: Open,
    /// The bracket that opened a flow collection (`[` or `{`); `None` for block style.
    flow: Option<char>,
}

/// Builds the tree from parser events.
struct Builder<'p> {
    problems: &'p mut Problems,
    stack: Vec<Frame>,
    root: Option<Node>,
    anchors: HashMap<usize, Node>,
    values: usize,
}

/// Parses `text`. Returns `None` (with an error in `problems`) on a syntax error, and `None`
/// without an error when the file holds no document.
pub(crate) fn parse(text: &str, problems: &mut Problems) -> Option<Node> {
    let mut builder = Builder {
        problems,
        stack: Vec::new(),
        root: None,
        anchors: HashMap::new(),
        values: 0,
    };
    let mut parser = Parser::new_from_str(text);
    let mut documents = 0usize;
    let end = end_of(text);
    while let Some(next) = parser.next_event() {
        let (event, span) = match next {
            Ok(ok) => ok,
            Err(e) => {
                builder.syntax_error(text, e.marker(), e.info());
                return None;
            }
        };
        // Empty values (`key:` with nothing after it) are placed at the next token, which can be
        // the end of input after the last line; keep every position inside the text.
        let at = span_of(&span.start).min(end);
        let ok = match event {
            Event::Nothing | Event::StreamStart | Event::DocumentEnd => true,
            Event::StreamEnd => break,
            Event::DocumentStart(_) => {
                documents += 1;
                if documents > 1 {
                    builder.problems.error(
                        at,
                        "a graph file holds one YAML document; found a second one here",
                    );
                    return None;
                }
                true
            }
            Event::Alias(id) => builder.alias(id, at),
            Event::Scalar(text, style, anchor, tag) => builder.scalar(text, style, anchor, tag, at),
            Event::SequenceStart(anchor, tag) => {
                let flow = (span.end.index() > span.start.index()).then_some('[');
                builder.start(Open::Seq(Vec::new()), anchor, tag, "seq", at, flow)
            }
            Event::MappingStart(anchor, tag) => {
                let flow = (span.end.index() > span.start.index()).then_some('{');
                builder.start(
                    Open::Map(Vec::new(), KeyState::Expect),
                    anchor,
                    tag,
                    "map",
                    at,
                    flow,
                )
            }
            Event::SequenceEnd | Event::MappingEnd => builder.end(),
        };
        if !ok {
            return None;
        }
    }
    builder.root
}

impl Builder<'_> {
    /// Reports a syntax error at the parser's position, with two hints the parser does not give:
    /// a tab is reported where it is (the parser points at the scalar before it), and an open
    /// flow bracket is named (an unclosed `[` is only noticed lines later).
    fn syntax_error(&mut self, text: &str, marker: &Marker, info: &str) {
        // The parser may place an end-of-input error after the last line; keep it in the text.
        let mut at = span_of(marker).min(end_of(text));
        let mut message = format!("YAML syntax error: {info}");
        if info.contains("tab") {
            // From the start of the error's line: the parser may point just after the tab.
            let line_start = marker.index().saturating_sub(marker.col());
            if let Some(tab) = position_of_char(text, line_start, '\t') {
                at = tab;
            }
            message += " (YAML does not allow tabs for indentation; use spaces)";
        }
        if let Some(frame) = self.stack.iter().rev().find(|f| f.flow.is_some()) {
            let (open, close) = if frame.flow == Some('[') {
                ('[', ']')
            } else {
                ('{', '}')
            };
            message += &format!(
                "; the `{open}` opened at line {}, column {} may lack its `{close}`",
                frame.at.line, frame.at.column
            );
        }
        self.problems.error(at, message);
    }

    /// Counts `n` more values against [`MAX_VALUES`]; false (with an error) when over.
    fn spend(&mut self, n: usize, at: Span) -> bool {
        self.values += n;
        if self.values > MAX_VALUES {
            self.problems.error(
                at,
                format!("too many values (more than {MAX_VALUES}, counting what aliases expand to)"),
            );
            return false;
        }
        true
    }

    fn alias(&mut self, id: usize, at: Span) -> bool {
        let node = match self.anchors.get(&id) {
            Some(anchored) => {
                let mut copy = anchored.clone();
                relocate_top(&mut copy, at);
                copy
            }
            None => {
                self.problems
                    .error(at, "this alias refers to an anchor that is not defined before it");
                Node {
                    value: Value::Null,
                    at,
                }
            }
        };
        if !self.spend(count_values(&node), at) {
            return false;
        }
        self.complete(node, None);
        true
    }

    fn scalar(
        &mut self,
        text: Cow<'_, str>,
        style: ScalarStyle,
        anchor: usize,
        tag: Option<Cow<'_, Tag>>,
        at: Span,
    ) -> bool {
        if !self.spend(1, at) {
            return false;
        }
        let value = match tag {
            None if style == ScalarStyle::Plain => resolve_plain(&text),
            None => Value::Str(text.to_string()),
            Some(tag) => self.tagged_scalar(&text, &tag, at),
        };
        let node = Node { value, at };
        if anchor > 0 {
            self.anchors.insert(anchor, node.clone());
        }
        self.complete(node, Some(text.into_owned()));
        true
    }

    fn tagged_scalar(&mut self, text: &str, tag: &Tag, at: Span) -> Value {
        if !tag.is_yaml_core_schema() {
            self.problems
                .error(at, format!("YAML tag `{tag}` is not supported here"));
            return resolve_plain(text);
        }
        let resolved = resolve_plain(text);
        let fits = match tag.suffix.as_str() {
            "str" => return Value::Str(text.to_string()),
            "null" => matches!(resolved, Value::Null),
            "bool" => matches!(resolved, Value::Bool(_)),
            "int" => matches!(resolved, Value::Int(_)),
            "float" => {
                if let Value::Int(i) = resolved {
                    return Value::Float(i as f64);
                }
                matches!(resolved, Value::Float(_))
            }
            _ => {
                self.problems.error(
                    at,
                    format!("YAML tag `!!{}` is not supported on a scalar", tag.suffix),
                );
                return resolved;
            }
        };
        if !fits {
            self.problems
                .error(at, format!("`{text}` is not a valid `!!{}` value", tag.suffix));
        }
        resolved
    }

    fn start(
        &mut self,
        open: Open,
        anchor: usize,
        tag: Option<Cow<'_, Tag>>,
        core: &str,
        at: Span,
        flow: Option<char>,
    ) -> bool {
        if let Some(tag) = tag
            && !(tag.is_yaml_core_schema() && tag.suffix == core)
        {
            self.problems
                .error(at, format!("YAML tag `{tag}` is not supported here"));
        }
        if self.stack.len() >= MAX_DEPTH {
            self.problems.error(
                at,
                format!("lists and mappings are nested deeper than {MAX_DEPTH} levels"),
            );
            return false;
        }
        if !self.spend(1, at) {
            return false;
        }
        self.stack.push(Frame {
            at,
            anchor,
            open,
            flow,
        });
        true
    }

    fn end(&mut self) -> bool {
        let Some(frame) = self.stack.pop() else {
            // The parser never ends a collection it did not start; nothing to close.
            return true;
        };
        let value = match frame.open {
            Open::Seq(items) => Value::Seq(items),
            Open::Map(entries, key) => {
                if let KeyState::Have(_, key_at) = key {
                    // A key without a value cannot come out of the parser (it emits a null);
                    // guard anyway rather than lose the key silently.
                    self.problems.error(key_at, "this key has no value");
                }
                Value::Map(entries)
            }
        };
        let node = Node { value, at: frame.at };
        if frame.anchor > 0 {
            self.anchors.insert(frame.anchor, node.clone());
        }
        self.complete(node, None);
        true
    }

    /// Hands a finished value to the enclosing list or mapping (or makes it the root).
    /// `scalar_text` is the source text when the value is a scalar (used when it is a key).
    fn complete(&mut self, node: Node, scalar_text: Option<String>) {
        let Some(frame) = self.stack.last_mut() else {
            self.root = Some(node);
            return;
        };
        match &mut frame.open {
            Open::Seq(items) => items.push(node),
            Open::Map(entries, key) => {
                *key = match std::mem::replace(key, KeyState::Expect) {
                    KeyState::Expect => match scalar_text {
                        Some(text) => KeyState::Have(text, node.at),
                        None => {
                            self.problems
                                .error(node.at, "mapping keys must be plain names, not lists or mappings");
                            KeyState::Bad
                        }
                    },
                    KeyState::Have(key, key_at) => {
                        if let Some(first) = entries.iter().find(|e| e.key == key) {
                            let line = first.key_at.line;
                            self.problems.error(
                                key_at,
                                format!("duplicate key `{key}` (first given at line {line})"),
                            );
                        } else {
                            entries.push(Entry {
                                key,
                                key_at,
                                value: node,
                            });
                        }
                        KeyState::Expect
                    }
                    KeyState::Bad => KeyState::Expect,
                };
            }
        }
    }
}

/// An alias's copy is reported where the alias is, at its top level; inner values keep the
/// anchor's positions (the text they come from).
fn relocate_top(node: &mut Node, at: Span) {
    node.at = at;
}

/// Position of the first `wanted` character at or after character index `from`.
fn position_of_char(text: &str, from: usize, wanted: char) -> Option<Span> {
    let (mut line, mut column) = (1, 1);
    for (i, c) in text.chars().enumerate() {
        if i >= from && c == wanted {
            return Some(Span::new(line, column));
        }
        if c == '\n' {
            line += 1;
            column = 1;
        } else {
            column += 1;
        }
    }
    None
}

/// Position just after the last character of `text` (on its last line).
fn end_of(text: &str) -> Span {
    let last_line = text.rsplit('\n').next().unwrap_or("");
    Span::new(text.matches('\n').count() + 1, last_line.chars().count() + 1)
}

/// Number of values in `node` (itself included).
fn count_values(node: &Node) -> usize {
    1 + match &node.value {
        Value::Seq(items) => items.iter().map(count_values).sum(),
        Value::Map(entries) => entries.iter().map(|e| 1 + count_values(&e.value)).sum(),
        _ => 0,
    }
}

/// Resolves a plain (unquoted) scalar with the YAML 1.2 core schema.
fn resolve_plain(text: &str) -> Value {
    match text {
        "" | "~" | "null" | "Null" | "NULL" => return Value::Null,
        "true" | "True" | "TRUE" => return Value::Bool(true),
        "false" | "False" | "FALSE" => return Value::Bool(false),
        ".inf" | ".Inf" | ".INF" | "+.inf" | "+.Inf" | "+.INF" => return Value::Float(f64::INFINITY),
        "-.inf" | "-.Inf" | "-.INF" => return Value::Float(f64::NEG_INFINITY),
        ".nan" | ".NaN" | ".NAN" => return Value::Float(f64::NAN),
        _ => {}
    }
    let unsigned = text.strip_prefix(['-', '+']).unwrap_or(text);
    if is_digits(unsigned) {
        return match text.parse::<i64>() {
            Ok(i) => Value::Int(i),
            Err(_) => text
                .parse::<f64>()
                .map_or_else(|_| Value::Str(text.to_string()), Value::Float),
        };
    }
    for (prefix, radix) in [("0o", 8), ("0x", 16)] {
        if let Some(digits) = text.strip_prefix(prefix)
            && !digits.is_empty()
            && let Ok(i) = i64::from_str_radix(digits, radix)
        {
            return Value::Int(i);
        }
    }
    if is_core_float(text)
        && let Ok(x) = text.parse::<f64>()
    {
        return Value::Float(x);
    }
    Value::Str(text.to_string())
}

fn is_digits(s: &str) -> bool {
    !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())
}

/// `[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?` (YAML 1.2 core schema float).
fn is_core_float(text: &str) -> bool {
    let s = text.strip_prefix(['-', '+']).unwrap_or(text);
    let (mantissa, exponent) = match s.find(['e', 'E']) {
        Some(i) => (&s[..i], Some(&s[i + 1..])),
        None => (s, None),
    };
    let mantissa_ok = match mantissa.split_once('.') {
        Some(("", frac)) => is_digits(frac),
        Some((int, frac)) => is_digits(int) && (frac.is_empty() || is_digits(frac)),
        None => is_digits(mantissa),
    };
    let exponent_ok = exponent.is_none_or(|e| is_digits(e.strip_prefix(['-', '+']).unwrap_or(e)));
    mantissa_ok && exponent_ok
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_ok(text: &str) -> Node {
        let mut p = Problems::new("t");
        let node = parse(text, &mut p);
        assert!(p.is_empty(), "{:?}", p.into_sorted());
        node.unwrap_or_else(|| panic!("no document in {text:?}"))
    }

    fn errors(text: &str) -> Vec<(usize, usize, String)> {
        let mut p = Problems::new("t");
        let _ = parse(text, &mut p);
        p.into_sorted()
            .into_iter()
            .map(|d| (d.line, d.column, d.message))
            .collect()
    }

    #[test]
    fn core_schema_scalars() {
        assert_eq!(resolve_plain("~"), Value::Null);
        assert_eq!(resolve_plain("True"), Value::Bool(true));
        assert_eq!(resolve_plain("-12"), Value::Int(-12));
        assert_eq!(resolve_plain("0x1F"), Value::Int(31));
        assert_eq!(resolve_plain("0o17"), Value::Int(15));
        assert_eq!(resolve_plain("1.5e3"), Value::Float(1500.0));
        assert_eq!(resolve_plain(".5"), Value::Float(0.5));
        assert_eq!(resolve_plain("3."), Value::Float(3.0));
        assert_eq!(resolve_plain("-.inf"), Value::Float(f64::NEG_INFINITY));
        // Rust's f64 parser accepts these; YAML's core schema does not.
        assert_eq!(resolve_plain("inf"), Value::Str("inf".into()));
        assert_eq!(resolve_plain("nan"), Value::Str("nan".into()));
        assert_eq!(resolve_plain("1e"), Value::Str("1e".into()));
        assert_eq!(resolve_plain("yes"), Value::Str("yes".into()));
        assert_eq!(resolve_plain("source/events"), Value::Str("source/events".into()));
    }

    #[test]
    fn positions_of_keys_and_values() {
        let root = parse_ok("name: x\nnodes:\n  - id: a\n    params: { k: '1' }\n");
        let Value::Map(top) = &root.value else {
            panic!("not a map")
        };
        assert_eq!((top[1].key.as_str(), top[1].key_at), ("nodes", Span::new(2, 1)));
        let Value::Seq(nodes) = &top[1].value.value else {
            panic!("not a seq")
        };
        assert_eq!(nodes[0].at, Span::new(3, 5));
        let Value::Map(node) = &nodes[0].value else {
            panic!("not a map")
        };
        assert_eq!(node[0].value.at, Span::new(3, 9));
        let Value::Map(params) = &node[1].value.value else {
            panic!("not a map")
        };
        assert_eq!(
            params[0].value,
            Node {
                value: Value::Str("1".into()),
                at: Span::new(4, 18)
            }
        );
    }

    #[test]
    fn aliases_copy_the_anchored_value() {
        let root = parse_ok("a: &p { k: 1 }\nb: *p\n");
        let Value::Map(top) = &root.value else {
            panic!("not a map")
        };
        assert_eq!(top[1].value.at, Span::new(2, 4));
        assert_eq!(top[0].value.value, top[1].value.value);
    }

    #[test]
    fn duplicate_and_complex_keys() {
        assert_eq!(
            errors("a: 1\nb: 2\na: 3\n"),
            [(3, 1, "duplicate key `a` (first given at line 1)".into())]
        );
        let e = errors("? [a]\n: 1\n");
        assert_eq!(e.len(), 1);
        assert!(e[0].2.contains("plain names"), "{e:?}");
    }

    #[test]
    fn syntax_errors_have_positions() {
        let e = errors("name: x\nnodes:\n\t- id: a\n");
        assert_eq!((e[0].0, e[0].1), (3, 1));
        assert!(e[0].2.contains("tabs"), "{e:?}");
        let e = errors("nodes: [a, b\n");
        assert_eq!(e.len(), 1);
        assert!(e[0].2.starts_with("YAML syntax error"), "{e:?}");
    }

    #[test]
    fn second_document_and_tags() {
        assert_eq!(errors("a: 1\n---\nb: 2\n")[0].0, 2);
        assert!(errors("a: !foo 1\n")[0].2.contains("not supported"));
        assert!(errors("a: !!int x\n")[0].2.contains("not a valid `!!int`"));
        let root = parse_ok("a: !!str 5\n");
        let Value::Map(top) = &root.value else {
            panic!("not a map")
        };
        assert_eq!(top[0].value.value, Value::Str("5".into()));
    }

    #[test]
    fn limits_stop_hostile_input() {
        let deep = "[".repeat(100);
        let e = errors(&deep);
        assert!(e[0].2.contains("nested deeper"), "{e:?}");
        let mut bomb = String::from("a: &a [x, x, x, x, x, x, x, x, x, x]\n");
        for i in 0..8 {
            let prev = if i == 0 {
                "a".to_string()
            } else {
                format!("a{}", i - 1)
            };
            bomb += &format!(
                "a{i}: &a{i} [*{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}, *{prev}]\n"
            );
        }
        let e = errors(&bomb);
        assert!(e.iter().any(|d| d.2.contains("too many values")), "{e:?}");
    }

    #[test]
    fn empty_file_has_no_document() {
        let mut p = Problems::new("t");
        assert!(parse("# nothing\n", &mut p).is_none());
        assert!(p.is_empty());
    }
}
