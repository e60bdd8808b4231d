//! Malformed input never panics: it gives diagnostics with sane positions.

mod common;

use common::{VALID, resolver, text};
use evseg_graph::{GraphError, check_str};

/// Checks `input`; panics (failing the test, showing the input) if checking panics, accepts no
/// diagnostics, or points outside the text.
fn must_not_panic(input: &str) -> Result<(), Vec<evseg_graph::Diagnostic>> {
    let outcome = std::panic::catch_unwind(|| check_str("m.yaml", input, &resolver));
    let result = outcome.unwrap_or_else(|_| panic!("checking panicked on {input:?}"));
    match result {
        Ok(_) => Ok(()),
        Err(GraphError::Invalid(found)) => {
            assert!(!found.is_empty(), "refused without a diagnostic: {input:?}");
            let lines = input.split('\n').count();
            for d in &found {
                assert!(
                    d.line >= 1 && d.line <= lines && d.column >= 1,
                    "{d} outside {input:?}"
                );
            }
            Err(found)
        }
        Err(e) => panic!("unexpected error {e} for {input:?}"),
    }
}

#[test]
fn tabs_brackets_quotes_and_blobs_are_errors() {
    for bad in [
        "name: x\nnodes:\n\t- id: a\n",
        "name: x\nnodes: [\n",
        "name: x\nnodes: [{ id: a, run: evseg-source\n",
        "name: \"unterminated\nnodes: []\n",
        "name: x\nnodes:\n  - id: a\n   run: b\n",
        "\u{0}\u{1}\u{2}\u{7f}\u{fffd}\u{fffd}PK\u{3}\u{4}\u{14}",
        "%YAML 9.9\n--- x\n",
        "]]]]",
        "&a [*a]",
        ": : :",
    ] {
        let found = must_not_panic(bad).expect_err(bad);
        assert!(!found[0].message.is_empty());
    }
}

#[test]
fn the_blob_error_names_a_position() {
    // A zip header pasted as text: the parser stops at the first control character.
    let found = must_not_panic("PK\u{3}\u{4}\u{14}\u{0}\u{8}\u{0}").expect_err("blob");
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].line, 1);
}

/// A small deterministic generator (xorshift64*), so failures reproduce.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

const ALPHABET: &[char] = &[
    ' ', ' ', '\n', '\t', ':', '-', '[', ']', '{', '}', ',', '"', '\'', '&', '*', '!', '#', '|', '>', '?',
    '%', '@', '`', '/', 'a', '0', '.', '\0', 'é', '\u{feff}', '~',
];

#[test]
fn mutated_graphs_never_panic() {
    let base: Vec<char> = text(VALID).chars().collect();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let (mut accepted, mut refused) = (0, 0);
    for _ in 0..3000 {
        let mut chars = base.clone();
        for _ in 0..1 + rng.below(4) {
            let at = rng.below(chars.len());
            match rng.below(3) {
                0 => {
                    chars.remove(at);
                }
                1 => chars.insert(at, ALPHABET[rng.below(ALPHABET.len())]),
                _ => chars[at] = ALPHABET[rng.below(ALPHABET.len())],
            }
        }
        let input: String = chars.into_iter().collect();
        match must_not_panic(&input) {
            Ok(()) => accepted += 1,
            Err(_) => refused += 1,
        }
    }
    // Small edits hit comments and spaces sometimes, but most must be caught.
    assert!(
        refused > 1500 && accepted > 0,
        "accepted {accepted}, refused {refused}"
    );
}

#[test]
fn random_text_never_panics() {
    let mut rng = Rng(42);
    for _ in 0..3000 {
        let len = rng.below(200);
        let input: String = (0..len).map(|_| ALPHABET[rng.below(ALPHABET.len())]).collect();
        let _ = must_not_panic(&input);
    }
}
