//! The one error for a stage parameter out of its range, shared by every stage library's
//! parameter checks (the node binaries turn it into a clear message naming the parameter).

/// A parameter out of range: its name, its value and what is allowed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("parameter {name} = {value} is invalid: {why}")]
pub struct ParamError {
    /// Parameter name, as in graph.yaml.
    pub name: &'static str,
    /// Its value, printed.
    pub value: String,
    /// What is allowed.
    pub why: &'static str,
}

impl ParamError {
    /// The error for `name` with `value` and the rule `why` (a number that would print as a
    /// long string of digits, such as 1e200, is given in exponent form: [`short_number`]).
    pub fn new(name: &'static str, value: impl ToString, why: &'static str) -> Self {
        let text = value.to_string();
        let value = match text.parse::<f64>() {
            Ok(v) if text.len() > 16 => short_number(v),
            _ => text,
        };
        Self { name, value, why }
    }
}

/// `v` for a message: as Rust prints it between 1e-4 and 1e9 (and 0), else in exponent form,
/// so that `1e200` is not printed as a 201-digit number.
pub fn short_number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e9).contains(&v.abs()) {
        v.to_string()
    } else {
        format!("{v:e}")
    }
}

/// `Ok` when `v` is in [0, 1].
pub fn unit(name: &'static str, v: f64) -> Result<(), ParamError> {
    if (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(ParamError::new(name, v, "must be in [0, 1]"))
    }
}

/// `Ok` when `v` is finite and not negative.
pub fn finite_non_negative(name: &'static str, v: f64) -> Result<(), ParamError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(ParamError::new(name, v, "must be finite and >= 0"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(short_number(2.5), "2.5");
        assert_eq!(short_number(0.0), "0");
        assert_eq!(short_number(1e200), "1e200");
        assert_eq!(short_number(-3e-300), "-3e-300");
        assert_eq!(short_number(f64::NAN), "NaN");
        assert_eq!(
            ParamError::new("lambda", 1e200, "must be at most 1").to_string(),
            "parameter lambda = 1e200 is invalid: must be at most 1"
        );
        assert_eq!(ParamError::new("k", 0.25, "x").value, "0.25");
        assert_eq!(ParamError::new("k", "abc", "x").value, "abc");
    }

    #[test]
    fn ranges_and_message() {
        assert!(unit("a", 0.0).is_ok() && unit("a", 1.0).is_ok());
        assert!(unit("a", 1.5).is_err() && unit("a", f64::NAN).is_err());
        assert!(finite_non_negative("b", 0.0).is_ok());
        assert!(finite_non_negative("b", -1.0).is_err() && finite_non_negative("b", f64::INFINITY).is_err());
        assert_eq!(
            unit("warp_weight", 2.0).unwrap_err().to_string(),
            "parameter warp_weight = 2 is invalid: must be in [0, 1]"
        );
    }
}
