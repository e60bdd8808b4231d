//! Diagnostics: an error message tied to a file, line and column, printed the way compilers do
//! (`file:line:column: error: message`) so editors can jump to it.

use std::fmt;

use serde::{Deserialize, Serialize};

/// A position in a source file. Both numbers are 1-based; the column counts characters (not
/// bytes) from the start of the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize)]
pub struct Span {
    /// Line number, 1-based.
    pub line: usize,
    /// Column number in characters, 1-based.
    pub column: usize,
}

impl Span {
    /// The position at `line`, `column` (both 1-based).
    pub fn new(line: usize, column: usize) -> Self {
        Self { line, column }
    }
}

impl fmt::Display for Span {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.column)
    }
}

/// One error found in a graph file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Diagnostic {
    /// File name as given by the caller (usually the path of graph.yaml).
    pub file: String,
    /// Line number, 1-based.
    pub line: usize,
    /// Column number in characters, 1-based.
    pub column: usize,
    /// What is wrong, and where useful what would be right.
    pub message: String,
}

impl Diagnostic {
    /// A diagnostic for `file` at `at`.
    pub fn new(file: &str, at: Span, message: impl Into<String>) -> Self {
        Self {
            file: file.to_string(),
            line: at.line,
            column: at.column,
            message: message.into(),
        }
    }

    /// The position this diagnostic points at.
    pub fn span(&self) -> Span {
        Span::new(self.line, self.column)
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}:{}: error: {}",
            self.file, self.line, self.column, self.message
        )
    }
}

/// Collects the diagnostics of one file while it is being checked.
#[derive(Debug)]
pub(crate) struct Problems {
    file: String,
    found: Vec<Diagnostic>,
}

impl Problems {
    pub(crate) fn new(file: &str) -> Self {
        Self {
            file: file.to_string(),
            found: Vec::new(),
        }
    }

    /// Records an error at `at`.
    pub(crate) fn error(&mut self, at: Span, message: impl Into<String>) {
        self.found.push(Diagnostic::new(&self.file, at, message));
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.found.is_empty()
    }

    pub(crate) fn file(&self) -> &str {
        &self.file
    }

    /// All diagnostics in file order (line, then column; stable for equal positions).
    pub(crate) fn into_sorted(mut self) -> Vec<Diagnostic> {
        self.found.sort_by_key(|d| (d.line, d.column));
        self.found
    }
}

/// `a, b, c` with each name in backticks, or `(none)` when empty.
pub(crate) fn name_list<S: AsRef<str>>(names: &[S]) -> String {
    if names.is_empty() {
        return "(none)".to_string();
    }
    names
        .iter()
        .map(|n| format!("`{}`", n.as_ref()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// ` (did you mean `x`?)` when one of `candidates` is close to `wrong`, else an empty string.
pub(crate) fn did_you_mean<S: AsRef<str>>(wrong: &str, candidates: &[S]) -> String {
    let best = candidates
        .iter()
        .map(|c| (edit_distance(wrong, c.as_ref()), c.as_ref()))
        .filter(|(d, c)| *d > 0 && *d <= (c.chars().count() / 3).max(1))
        .min_by_key(|(d, _)| *d);
    match best {
        Some((_, c)) => format!(" (did you mean `{c}`?)"),
        None => String::new(),
    }
}

/// Edit distance in characters where inserting, deleting, substituting a character or swapping
/// two neighbours costs 1 (optimal string alignment), so `mdoe` is 1 away from `mode`.
fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let width = b.len() + 1;
    let mut d = vec![0usize; (a.len() + 1) * width];
    for i in 0..=a.len() {
        d[i * width] = i;
    }
    for (j, cell) in d.iter_mut().enumerate().take(width) {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut best = (d[(i - 1) * width + j] + 1)
                .min(d[i * width + j - 1] + 1)
                .min(d[(i - 1) * width + j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(d[(i - 2) * width + j - 2] + 1);
            }
            d[i * width + j] = best;
        }
    }
    d[a.len() * width + b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_is_compiler_style() {
        let d = Diagnostic::new("g.yaml", Span::new(3, 7), "bad");
        assert_eq!(d.to_string(), "g.yaml:3:7: error: bad");
    }

    #[test]
    fn edit_distances() {
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("window", "window"), 0);
        assert_eq!(edit_distance("mdoe", "mode"), 1);
        assert_eq!(edit_distance("truht", "truth"), 1);
        assert_eq!(
            did_you_mean("windw", &["window", "queue"]),
            " (did you mean `window`?)"
        );
        assert_eq!(did_you_mean("xyz", &["window", "queue"]), "");
    }

    #[test]
    fn sorted_by_position() {
        let mut p = Problems::new("f");
        p.error(Span::new(5, 1), "b");
        p.error(Span::new(2, 9), "a");
        p.error(Span::new(5, 1), "c");
        let msgs: Vec<_> = p.into_sorted().into_iter().map(|d| d.message).collect();
        assert_eq!(msgs, ["a", "b", "c"]);
    }
}
