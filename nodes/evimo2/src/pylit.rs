//! A parser for Python literals (the text `repr()` of a dict produces), and the value tree that both
//! the literal and the pickled form of EVIMO2's `meta` are converted to.
//!
//! Accepted: dicts, lists, tuples (including `(x,)` and `()`), strings with single or double quotes
//! (and `r`/`b`/`u` prefixes, the usual backslash escapes, adjacent-literal concatenation), integers
//! (any size up to `i128`; larger ones become floats), floats with exponents, `nan`/`inf` (as
//! `repr` writes them, also `float('nan')`), `True`, `False`, `None`. Trailing commas are allowed.
//! The same parser reads `.npy` headers.

use std::fmt;

/// A Python value as far as EVIMO2 metadata needs it.
#[derive(Debug, Clone, PartialEq)]
pub enum PyValue {
    /// `None`.
    None,
    /// `True` / `False`.
    Bool(bool),
    /// An integer.
    Int(i128),
    /// A float.
    Float(f64),
    /// A unicode string.
    Str(String),
    /// A bytes string.
    Bytes(Vec<u8>),
    /// A list.
    List(Vec<PyValue>),
    /// A tuple.
    Tuple(Vec<PyValue>),
    /// A dict, in file order (pickle path: key order of the decoder).
    Dict(Vec<(PyValue, PyValue)>),
}

impl PyValue {
    /// Looks up a string key in a dict; `None` for a missing key or a non-dict. A key written twice
    /// in a literal gives the last value, as in Python.
    pub fn get(&self, key: &str) -> Option<&PyValue> {
        match self {
            PyValue::Dict(items) => items.iter().rev().find_map(|(k, v)| match k {
                PyValue::Str(s) if s == key => Some(v),
                _ => None,
            }),
            _ => None,
        }
    }

    /// The value as a float (ints and bools convert).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            PyValue::Float(f) => Some(*f),
            PyValue::Int(i) => Some(*i as f64),
            PyValue::Bool(b) => Some(f64::from(u8::from(*b))),
            _ => None,
        }
    }

    /// The value as an integer (floats with an integral value convert).
    pub fn as_i128(&self) -> Option<i128> {
        match self {
            PyValue::Int(i) => Some(*i),
            PyValue::Bool(b) => Some(i128::from(*b)),
            PyValue::Float(f) if f.fract() == 0.0 && f.abs() < 1e38 => Some(*f as i128),
            _ => None,
        }
    }

    /// The value as a string slice.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            PyValue::Str(s) => Some(s),
            _ => None,
        }
    }

    /// Items of a list or tuple.
    pub fn as_seq(&self) -> Option<&[PyValue]> {
        match self {
            PyValue::List(v) | PyValue::Tuple(v) => Some(v),
            _ => None,
        }
    }

    /// A short name of the value's Python type, for error messages.
    pub fn type_name(&self) -> &'static str {
        match self {
            PyValue::None => "None",
            PyValue::Bool(_) => "bool",
            PyValue::Int(_) => "int",
            PyValue::Float(_) => "float",
            PyValue::Str(_) => "str",
            PyValue::Bytes(_) => "bytes",
            PyValue::List(_) => "list",
            PyValue::Tuple(_) => "tuple",
            PyValue::Dict(_) => "dict",
        }
    }
}

/// Writes the value as a Python literal that `ast.literal_eval`/`eval` reads back to the same value.
impl fmt::Display for PyValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PyValue::None => f.write_str("None"),
            PyValue::Bool(true) => f.write_str("True"),
            PyValue::Bool(false) => f.write_str("False"),
            PyValue::Int(i) => write!(f, "{i}"),
            PyValue::Float(x) => {
                if x.is_nan() {
                    f.write_str("nan")
                } else if x.is_infinite() {
                    f.write_str(if *x > 0.0 { "inf" } else { "-inf" })
                } else if x.fract() == 0.0 && x.abs() < 1e16 {
                    write!(f, "{x:.1}")
                } else {
                    // Rust's `{:?}` prints the shortest string that round-trips, like Python's repr.
                    write!(f, "{x:?}")
                }
            }
            PyValue::Str(s) => {
                f.write_str("'")?;
                for c in s.chars() {
                    match c {
                        '\'' => f.write_str("\\'")?,
                        '\\' => f.write_str("\\\\")?,
                        '\n' => f.write_str("\\n")?,
                        '\r' => f.write_str("\\r")?,
                        '\t' => f.write_str("\\t")?,
                        c if (c as u32) < 0x20 || c as u32 == 0x7f => write!(f, "\\x{:02x}", c as u32)?,
                        c => write!(f, "{c}")?,
                    }
                }
                f.write_str("'")
            }
            PyValue::Bytes(b) => {
                f.write_str("b'")?;
                for &byte in b {
                    match byte {
                        b'\'' => f.write_str("\\'")?,
                        b'\\' => f.write_str("\\\\")?,
                        0x20..=0x7e => write!(f, "{}", byte as char)?,
                        _ => write!(f, "\\x{byte:02x}")?,
                    }
                }
                f.write_str("'")
            }
            PyValue::List(items) => {
                f.write_str("[")?;
                write_items(f, items)?;
                f.write_str("]")
            }
            PyValue::Tuple(items) => {
                f.write_str("(")?;
                write_items(f, items)?;
                if items.len() == 1 {
                    f.write_str(",")?;
                }
                f.write_str(")")
            }
            PyValue::Dict(items) => {
                f.write_str("{")?;
                for (i, (k, v)) in items.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{k}: {v}")?;
                }
                f.write_str("}")
            }
        }
    }
}

fn write_items(f: &mut fmt::Formatter<'_>, items: &[PyValue]) -> fmt::Result {
    for (i, v) in items.iter().enumerate() {
        if i > 0 {
            f.write_str(", ")?;
        }
        write!(f, "{v}")?;
    }
    Ok(())
}

/// A syntax error at a character offset of the parsed text.
#[derive(Debug, Clone, PartialEq)]
pub struct LiteralError {
    /// Offset in characters from the start of the text.
    pub offset: usize,
    /// What was wrong.
    pub message: String,
}

impl fmt::Display for LiteralError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "at character {}: {}", self.offset, self.message)
    }
}

/// Maximum nesting of containers; deeper input is rejected instead of overflowing the stack.
/// EVIMO2 meta nests 6 levels; 200 is far above any real file.
const MAX_DEPTH: usize = 200;

/// Parses one Python literal; only whitespace may follow it.
pub fn parse(text: &str) -> Result<PyValue, LiteralError> {
    let mut p = Parser {
        chars: text.chars().collect(),
        pos: 0,
    };
    let v = p.value(0)?;
    p.skip_ws();
    if p.pos < p.chars.len() {
        return Err(p.err("unexpected text after the value"));
    }
    Ok(v)
}

struct Parser {
    chars: Vec<char>,
    pos: usize,
}

impl Parser {
    fn err(&self, message: impl Into<String>) -> LiteralError {
        LiteralError {
            offset: self.pos,
            message: message.into(),
        }
    }

    fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).copied()
    }

    fn skip_ws(&mut self) {
        while let Some(c) = self.peek() {
            if c.is_whitespace() || c == '\\' && self.chars.get(self.pos + 1) == Some(&'\n') {
                self.pos += if c == '\\' { 2 } else { 1 };
            } else {
                break;
            }
        }
    }

    fn value(&mut self, depth: usize) -> Result<PyValue, LiteralError> {
        if depth > MAX_DEPTH {
            return Err(self.err("nesting too deep"));
        }
        self.skip_ws();
        let Some(c) = self.peek() else {
            return Err(self.err("unexpected end of text, expected a value"));
        };
        match c {
            '{' => self.dict(depth),
            '[' => {
                self.pos += 1;
                Ok(PyValue::List(self.items(']', depth)?.0))
            }
            '(' => {
                self.pos += 1;
                let (items, trailing_comma) = self.items(')', depth)?;
                if items.len() == 1 && !trailing_comma {
                    // A parenthesised expression, not a tuple.
                    Ok(items.into_iter().next().unwrap_or(PyValue::None))
                } else {
                    Ok(PyValue::Tuple(items))
                }
            }
            '\'' | '"' => self.strings(),
            '-' | '+' | '.' | '0'..='9' => self.number(),
            c if c.is_alphabetic() || c == '_' => {
                // A string prefix, a keyword or float('nan')-style call.
                let start = self.pos;
                while self.peek().is_some_and(|c| c.is_alphanumeric() || c == '_') {
                    self.pos += 1;
                }
                let word: String = self.chars[start..self.pos].iter().collect();
                if matches!(self.peek(), Some('\'' | '"'))
                    && word.len() <= 2
                    && word.chars().all(|c| "rRbBuU".contains(c))
                {
                    self.pos = start;
                    return self.strings();
                }
                match word.as_str() {
                    "None" => Ok(PyValue::None),
                    "True" => Ok(PyValue::Bool(true)),
                    "False" => Ok(PyValue::Bool(false)),
                    "nan" | "NaN" => Ok(PyValue::Float(f64::NAN)),
                    "inf" | "Infinity" => Ok(PyValue::Float(f64::INFINITY)),
                    "float" => self.float_call(start),
                    _ => {
                        self.pos = start;
                        Err(self.err(format!("unknown name '{word}'")))
                    }
                }
            }
            other => Err(self.err(format!("unexpected character '{other}'"))),
        }
    }

    /// `float('nan')`, `float("-inf")` after the word `float`.
    fn float_call(&mut self, start: usize) -> Result<PyValue, LiteralError> {
        self.skip_ws();
        if self.peek() != Some('(') {
            self.pos = start;
            return Err(self.err("unknown name 'float'"));
        }
        self.pos += 1;
        let arg = self.value(1)?;
        self.skip_ws();
        if self.peek() != Some(')') {
            return Err(self.err("expected ')' to close float(...)"));
        }
        self.pos += 1;
        let text = match &arg {
            PyValue::Str(s) => s.trim().to_ascii_lowercase(),
            PyValue::Int(i) => return Ok(PyValue::Float(*i as f64)),
            PyValue::Float(f) => return Ok(PyValue::Float(*f)),
            _ => return Err(self.err("float() of an unsupported value")),
        };
        let v = match text.as_str() {
            "nan" | "+nan" | "-nan" => f64::NAN,
            "inf" | "+inf" | "infinity" => f64::INFINITY,
            "-inf" | "-infinity" => f64::NEG_INFINITY,
            t => t
                .parse::<f64>()
                .map_err(|_| self.err(format!("float('{t}') is not a number")))?,
        };
        Ok(PyValue::Float(v))
    }

    /// Items up to `close`; returns them and whether a trailing comma was present.
    fn items(&mut self, close: char, depth: usize) -> Result<(Vec<PyValue>, bool), LiteralError> {
        let mut items = Vec::new();
        let mut trailing_comma = false;
        loop {
            self.skip_ws();
            if self.peek() == Some(close) {
                self.pos += 1;
                return Ok((items, trailing_comma));
            }
            items.push(self.value(depth + 1)?);
            self.skip_ws();
            match self.peek() {
                Some(',') => {
                    self.pos += 1;
                    trailing_comma = true;
                }
                Some(c) if c == close => {
                    trailing_comma = false;
                }
                Some(c) => return Err(self.err(format!("expected ',' or '{close}', found '{c}'"))),
                None => return Err(self.err(format!("unexpected end of text, expected '{close}'"))),
            }
        }
    }

    fn dict(&mut self, depth: usize) -> Result<PyValue, LiteralError> {
        self.pos += 1; // '{'
        let mut items = Vec::new();
        loop {
            self.skip_ws();
            if self.peek() == Some('}') {
                self.pos += 1;
                return Ok(PyValue::Dict(items));
            }
            let key = self.value(depth + 1)?;
            if matches!(key, PyValue::List(_) | PyValue::Dict(_)) {
                return Err(self.err(format!("unhashable dict key of type {}", key.type_name())));
            }
            self.skip_ws();
            if self.peek() != Some(':') {
                return Err(self.err("expected ':' after a dict key"));
            }
            self.pos += 1;
            let value = self.value(depth + 1)?;
            items.push((key, value));
            self.skip_ws();
            match self.peek() {
                Some(',') => self.pos += 1,
                Some('}') => {}
                Some(c) => return Err(self.err(format!("expected ',' or '}}', found '{c}'"))),
                None => return Err(self.err("unexpected end of text, expected '}'")),
            }
        }
    }

    /// One or more adjacent string literals (Python concatenates them).
    fn strings(&mut self) -> Result<PyValue, LiteralError> {
        let first = self.string()?;
        let mut result = first;
        loop {
            let save = self.pos;
            self.skip_ws();
            let next_is_string = match self.peek() {
                Some('\'' | '"') => true,
                Some(c) if "rRbBuU".contains(c) => {
                    let mut i = self.pos;
                    while i < self.chars.len() && "rRbBuU".contains(self.chars[i]) && i - self.pos < 2 {
                        i += 1;
                    }
                    matches!(self.chars.get(i), Some('\'' | '"'))
                }
                _ => false,
            };
            if !next_is_string {
                self.pos = save;
                return Ok(result);
            }
            let next = self.string()?;
            result = match (result, next) {
                (PyValue::Str(a), PyValue::Str(b)) => PyValue::Str(a + &b),
                (PyValue::Bytes(mut a), PyValue::Bytes(b)) => {
                    a.extend(b);
                    PyValue::Bytes(a)
                }
                _ => return Err(self.err("cannot concatenate str and bytes literals")),
            };
        }
    }

    fn string(&mut self) -> Result<PyValue, LiteralError> {
        let mut raw = false;
        let mut bytes = false;
        while let Some(c) = self.peek() {
            match c {
                'r' | 'R' => raw = true,
                'b' | 'B' => bytes = true,
                'u' | 'U' => {}
                _ => break,
            }
            self.pos += 1;
        }
        let start = self.pos;
        let Some(quote) = self.peek().filter(|c| *c == '\'' || *c == '"') else {
            return Err(self.err("expected a quote"));
        };
        let triple =
            self.chars.get(self.pos + 1) == Some(&quote) && self.chars.get(self.pos + 2) == Some(&quote);
        self.pos += if triple { 3 } else { 1 };
        let mut out = String::new();
        loop {
            let Some(c) = self.peek() else {
                self.pos = start;
                return Err(self.err("unterminated string"));
            };
            if c == quote {
                if !triple {
                    self.pos += 1;
                    break;
                }
                if self.chars.get(self.pos + 1) == Some(&quote)
                    && self.chars.get(self.pos + 2) == Some(&quote)
                {
                    self.pos += 3;
                    break;
                }
            }
            if c == '\n' && !triple {
                return Err(self.err("newline inside a string"));
            }
            if c == '\\' {
                if raw {
                    out.push('\\');
                    self.pos += 1;
                    if let Some(n) = self.peek() {
                        out.push(n);
                        self.pos += 1;
                    }
                    continue;
                }
                self.pos += 1;
                self.escape(&mut out, bytes)?;
                continue;
            }
            out.push(c);
            self.pos += 1;
        }
        if bytes {
            let mut b = Vec::with_capacity(out.len());
            for c in out.chars() {
                let code = c as u32;
                if code > 0xff {
                    return Err(self.err("non-ASCII character in a bytes literal"));
                }
                b.push(code as u8);
            }
            Ok(PyValue::Bytes(b))
        } else {
            Ok(PyValue::Str(out))
        }
    }

    /// After a backslash: appends the escaped character(s).
    fn escape(&mut self, out: &mut String, bytes: bool) -> Result<(), LiteralError> {
        let Some(c) = self.peek() else {
            return Err(self.err("backslash at end of text"));
        };
        self.pos += 1;
        match c {
            '\n' => {}
            '\\' => out.push('\\'),
            '\'' => out.push('\''),
            '"' => out.push('"'),
            'a' => out.push('\x07'),
            'b' => out.push('\x08'),
            'f' => out.push('\x0c'),
            'n' => out.push('\n'),
            'r' => out.push('\r'),
            't' => out.push('\t'),
            'v' => out.push('\x0b'),
            '0'..='7' => {
                let mut v = c.to_digit(8).unwrap_or(0);
                for _ in 0..2 {
                    match self.peek().and_then(|d| d.to_digit(8)) {
                        Some(d) => {
                            v = v * 8 + d;
                            self.pos += 1;
                        }
                        None => break,
                    }
                }
                out.push(self.code_point(v)?);
            }
            'x' => {
                let v = self.hex_digits(2)?;
                out.push(self.code_point(v)?);
            }
            'u' if !bytes => {
                let v = self.hex_digits(4)?;
                out.push(self.code_point(v)?);
            }
            'U' if !bytes => {
                let v = self.hex_digits(8)?;
                out.push(self.code_point(v)?);
            }
            other => {
                // Python keeps unknown escapes as they are.
                out.push('\\');
                out.push(other);
            }
        }
        Ok(())
    }

    fn hex_digits(&mut self, n: usize) -> Result<u32, LiteralError> {
        let mut v = 0u32;
        for _ in 0..n {
            let Some(d) = self.peek().and_then(|c| c.to_digit(16)) else {
                return Err(self.err(format!("expected {n} hex digits in an escape")));
            };
            v = v * 16 + d;
            self.pos += 1;
        }
        Ok(v)
    }

    fn code_point(&self, v: u32) -> Result<char, LiteralError> {
        char::from_u32(v).ok_or_else(|| self.err(format!("invalid code point {v:#x} in an escape")))
    }

    fn number(&mut self) -> Result<PyValue, LiteralError> {
        let start = self.pos;
        let mut negative = false;
        if let Some(sign @ ('-' | '+')) = self.peek() {
            negative = sign == '-';
            self.pos += 1;
            self.skip_ws();
            // -inf, -nan, -float('inf')
            if self.peek().is_some_and(|c| c.is_alphabetic()) {
                let v = self.value(1)?;
                return match v {
                    PyValue::Float(f) => Ok(PyValue::Float(if negative { -f } else { f })),
                    _ => {
                        self.pos = start;
                        Err(self.err("a sign must be followed by a number"))
                    }
                };
            }
        }
        let digits_start = self.pos;
        let mut is_float = false;
        let prefixed = self.peek() == Some('0')
            && matches!(
                self.chars.get(self.pos + 1),
                Some('x' | 'X' | 'o' | 'O' | 'b' | 'B')
            );
        if prefixed {
            self.pos += 2;
            while self.peek().is_some_and(|c| c.is_ascii_hexdigit() || c == '_') {
                self.pos += 1;
            }
        }
        while let Some(c) = self.peek().filter(|_| !prefixed) {
            match c {
                '0'..='9' | '_' => self.pos += 1,
                '.' => {
                    is_float = true;
                    self.pos += 1;
                }
                'e' | 'E' => {
                    is_float = true;
                    self.pos += 1;
                    if let Some('+' | '-') = self.peek() {
                        self.pos += 1;
                    }
                }
                _ => break,
            }
        }
        let text: String = self.chars[digits_start..self.pos]
            .iter()
            .filter(|c| **c != '_')
            .collect();
        if text.is_empty() {
            self.pos = start;
            return Err(self.err("expected a number"));
        }
        let lower = text.to_ascii_lowercase();
        let radix = if lower.starts_with("0x") {
            Some(16)
        } else if lower.starts_with("0o") {
            Some(8)
        } else if lower.starts_with("0b") {
            Some(2)
        } else {
            None
        };
        if let Some(radix) = radix {
            let v = i128::from_str_radix(&text[2..], radix).map_err(|_| {
                let mut e = self.err(format!("malformed integer '{text}'"));
                e.offset = start;
                e
            })?;
            return Ok(PyValue::Int(if negative { -v } else { v }));
        }
        let bad = |p: &Self| {
            let mut e = p.err(format!("malformed number '{text}'"));
            e.offset = start;
            e
        };
        if is_float {
            let v: f64 = text.parse().map_err(|_| bad(self))?;
            Ok(PyValue::Float(if negative { -v } else { v }))
        } else {
            match text.parse::<i128>() {
                Ok(v) => Ok(PyValue::Int(if negative { -v } else { v })),
                Err(_) if text.chars().all(|c| c.is_ascii_digit()) => {
                    // Too large for i128: keep its magnitude as a float.
                    let v: f64 = text.parse().map_err(|_| bad(self))?;
                    Ok(PyValue::Float(if negative { -v } else { v }))
                }
                Err(_) => Err(bad(self)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(x: &str) -> PyValue {
        PyValue::Str(x.to_string())
    }

    #[test]
    fn npy_header_with_trailing_comma() {
        let v = parse("{'descr': '<f8', 'fortran_order': False, 'shape': (3, 2), }  \n").unwrap();
        assert_eq!(v.get("descr"), Some(&s("<f8")));
        assert_eq!(v.get("fortran_order"), Some(&PyValue::Bool(false)));
        assert_eq!(
            v.get("shape"),
            Some(&PyValue::Tuple(vec![PyValue::Int(3), PyValue::Int(2)]))
        );
        let one = parse("{'shape': (7,)}").unwrap();
        assert_eq!(one.get("shape"), Some(&PyValue::Tuple(vec![PyValue::Int(7)])));
        let zero = parse("{'shape': ()}").unwrap();
        assert_eq!(zero.get("shape"), Some(&PyValue::Tuple(vec![])));
    }

    #[test]
    fn scalars_and_escapes() {
        assert_eq!(parse("-1.5e-3").unwrap(), PyValue::Float(-1.5e-3));
        assert_eq!(parse("2E+2").unwrap(), PyValue::Float(200.0));
        assert_eq!(
            parse("18446744073709551615").unwrap(),
            PyValue::Int(18446744073709551615)
        );
        assert_eq!(parse("-42").unwrap(), PyValue::Int(-42));
        assert!(matches!(parse("nan").unwrap(), PyValue::Float(f) if f.is_nan()));
        assert_eq!(parse("-inf").unwrap(), PyValue::Float(f64::NEG_INFINITY));
        assert_eq!(parse("float('inf')").unwrap(), PyValue::Float(f64::INFINITY));
        assert_eq!(parse(r#""it's""#).unwrap(), s("it's"));
        assert_eq!(parse(r"'a\'b\\c\n\x41\u00e9'").unwrap(), s("a'b\\c\nAé"));
        assert_eq!(parse("'ab' \"cd\"").unwrap(), s("abcd"));
        assert_eq!(parse("b'\\x00z'").unwrap(), PyValue::Bytes(vec![0, b'z']));
        assert_eq!(parse("(5)").unwrap(), PyValue::Int(5));
        assert_eq!(
            parse("[None, True, False]").unwrap().as_seq().map(|v| v.len()),
            Some(3)
        );
    }

    #[test]
    fn display_round_trips() {
        let v = PyValue::Dict(vec![
            (
                s("a'b"),
                PyValue::List(vec![PyValue::Float(0.1), PyValue::Float(3.0), PyValue::Int(-7)]),
            ),
            (s("t"), PyValue::Tuple(vec![PyValue::None])),
            (s("x"), PyValue::Float(1e-300)),
            (PyValue::Int(3), PyValue::Bool(true)),
        ]);
        assert_eq!(parse(&v.to_string()).unwrap(), v);
    }

    #[test]
    fn errors_have_offsets() {
        let e = parse("{'a': 1,, }").unwrap_err();
        assert_eq!(e.offset, 8);
        let e = parse("{'a': [1, 2}").unwrap_err();
        assert_eq!(e.offset, 11);
        assert!(parse("'unterminated").is_err());
        assert!(parse("{'a': foo}").is_err());
        assert!(parse("").is_err());
        assert!(parse("1 2").is_err());
        assert!(parse(&"[".repeat(10_000)).is_err());
    }
}
