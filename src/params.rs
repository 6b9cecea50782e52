//! The vocabulary of option checks: [`ParamError`] and the range tests every options struct
//! uses to validate itself.
//!
//! Each options struct checks its own fields with a `check` method beside its definition
//! (`FeatureParams::check`, `CgParams::check`, `FitParams::check`, `LineSearchParams::check`,
//! `ElasticParams::check`, `EnergyParams::check`, `OutputOptions::check`), and the jobs check
//! all of theirs before any work (`CurveOptions::check`, `CompareOptions::check`), so a caller of
//! the library is refused as the command line is; the command line only parses.
//!
//! Output: `Ok(())` or a [`ParamError`] naming the option (by its command-line spelling) and the
//! value. Invariants of every check: each `f64` option is finite (NaN and infinities are
//! refused) and inside a range in which the job means something; every count is at least 1
//! where 0 would silently do nothing or something else.

/// An option value outside its range.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{option} {value}: {what}")]
pub struct ParamError {
    /// The option as the command line spells it, e.g. `--cg-tol`.
    pub option: &'static str,
    /// The value given, as text.
    pub value: String,
    /// The range or rule it breaks.
    pub what: String,
}

impl ParamError {
    pub fn new(option: &'static str, value: impl ToString, what: impl Into<String>) -> Self {
        ParamError {
            option,
            value: value.to_string(),
            what: what.into(),
        }
    }
}

/// A number as a person writes it: `1e308`, `NaN`, `0.5`, `180`.
pub fn num(v: f64) -> String {
    let a = v.abs();
    if v.is_finite() && a != 0.0 && !(1e-4..1e6).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// `lo ≤ v ≤ hi`, and finite.
pub fn in_range(option: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), ParamError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(ParamError::new(
            option,
            num(v),
            format!("must be a number in [{}, {}]", num(lo), num(hi)),
        ))
    }
}

/// `lo < v ≤ hi`, and finite.
pub fn above(option: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), ParamError> {
    if v.is_finite() && v > lo && v <= hi {
        Ok(())
    } else {
        Err(ParamError::new(
            option,
            num(v),
            format!("must be a number in ({}, {}]", num(lo), num(hi)),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_refuse_nan_and_name_the_option() {
        assert!(in_range("--x", 0.5, 0.0, 1.0).is_ok());
        assert!(in_range("--x", 0.0, 0.0, 1.0).is_ok());
        assert!(above("--x", 0.0, 0.0, 1.0).is_err());
        let e = in_range("--x", f64::NAN, 0.0, 1.0).unwrap_err();
        assert_eq!(e.to_string(), "--x NaN: must be a number in [0, 1]");
        let e = above("--y", 1e308, 0.0, 1e12).unwrap_err();
        assert_eq!(e.to_string(), "--y 1e308: must be a number in (0, 1e12]");
    }
}
