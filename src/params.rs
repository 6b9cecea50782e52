//! Validation of every numeric option before any work, in the library (so a caller of
//! [`crate::pipeline::curve`] or [`crate::compare::compare`] is refused as the command line is).
//!
//! Input: the option structs of the jobs. Output: `Ok(())` or a [`ParamError`] naming the
//! option (by its command-line spelling) and the value.
//!
//! Invariants: every `f64` option is finite (NaN and infinities are refused) and inside a
//! range in which the job means something; every count is at least 1 where 0 would silently
//! do nothing or something else. Fit weights are bounded by [`MAX_WEIGHT`], so the
//! normal-equation matrix cannot overflow (weights multiply squared residuals).

use crate::compare::CompareOptions;
use crate::fit::{FitParams, FitTargets};
use crate::mesh::features::FeatureParams;
use crate::pipeline::{CurveOptions, Method};
use crate::sample::MAX_ORDER;
use crate::solve::CgParams;

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

/// Largest fit weight; weights are relative, so this is no practical limit, but 1e308 would
/// overflow the assembled matrix.
pub const MAX_WEIGHT: f64 = 1e12;

/// Most elements the `generate` command makes (memory grows linearly, see docs/reliability.md).
pub const MAX_GENERATED_ELEMENTS: usize = 10_000_000;

fn err(option: &'static str, value: impl ToString, what: impl Into<String>) -> ParamError {
    ParamError {
        option,
        value: value.to_string(),
        what: what.into(),
    }
}

/// A number as a person writes it: `1e308`, `NaN`, `0.5`, `180`.
fn num(v: f64) -> String {
    let a = v.abs();
    if v.is_finite() && a != 0.0 && !(1e-4..1e6).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// `lo ≤ v ≤ hi`, and finite.
fn in_range(option: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), ParamError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(err(
            option,
            num(v),
            format!("must be a number in [{}, {}]", num(lo), num(hi)),
        ))
    }
}

/// `lo < v ≤ hi`, and finite.
fn above(option: &'static str, v: f64, lo: f64, hi: f64) -> Result<(), ParamError> {
    if v.is_finite() && v > lo && v <= hi {
        Ok(())
    } else {
        Err(err(
            option,
            num(v),
            format!("must be a number in ({}, {}]", num(lo), num(hi)),
        ))
    }
}

/// Sharp-feature detection parameters.
pub fn check_features(p: &FeatureParams) -> Result<(), ParamError> {
    in_range("--feature-angle", p.angle_deg, 0.0, 180.0)
}

/// CG tolerances and iteration limit.
pub fn check_cg(p: &CgParams) -> Result<(), ParamError> {
    above("--cg-tol", p.rel_tol, 0.0, 1.0)?;
    in_range("CG absolute tolerance", p.abs_tol, 0.0, f64::MAX)?;
    if p.max_iters == 0 {
        return Err(err("CG iterations", 0, "must be at least 1"));
    }
    Ok(())
}

/// Fit weights, CG and smooth-target parameters.
pub fn check_fit(p: &FitParams) -> Result<(), ParamError> {
    let w = &p.weights;
    for (option, v) in [
        ("--w-corner", w.corner),
        ("--w-boundary-corner", w.boundary_corner),
        ("--w-midpoint", w.midpoint),
        ("--w-frame-corner", w.frame_corner),
        ("--w-frame-midpoint", w.frame_midpoint),
        ("--w-feature", w.feature),
    ] {
        in_range(option, v, 0.0, MAX_WEIGHT)?;
    }
    check_cg(&p.cg)?;
    if let FitTargets::Smooth(s) = &p.targets {
        above("--kink-angle", s.kink_angle_deg, 0.0, 360.0)?;
        in_range("smooth feature angle", s.feature_angle_deg, 0.0, 180.0)?;
        in_range("smooth decay", s.decay, 0.0, 1e6)?;
    }
    Ok(())
}

/// Every option of the `curve` job (the order range is checked here too, with the option's
/// own name: `--order` or `--subdivide`).
pub fn check_curve(o: &CurveOptions) -> Result<(), ParamError> {
    if !(1..=MAX_ORDER).contains(&o.order) {
        return Err(err(
            "--order",
            o.order,
            format!("must be in 1..={MAX_ORDER}"),
        ));
    }
    if let Some(k) = o.subdivide
        && !(1..=MAX_ORDER).contains(&k)
    {
        return Err(err(
            "--subdivide",
            k,
            format!("must be in 1..={MAX_ORDER} (sub-elements per edge)"),
        ));
    }
    check_fit(&o.fit)?;
    check_features(&o.features.params)?;
    let ls = &o.line_search;
    in_range("--min-det-fraction", ls.min_det_fraction, 0.0, 1.0)?;
    in_range("--min-quality-fraction", ls.min_quality_fraction, 0.0, 1.0)?;
    in_range(
        "--percentile-quality-fraction",
        ls.percentile_quality_fraction,
        0.0,
        1.0,
    )?;
    above("line-search tolerance", ls.tolerance, 0.0, 1.0)?;
    if ls.max_bisections > 1000 {
        return Err(err(
            "--max-bisections",
            ls.max_bisections,
            "must be at most 1000",
        ));
    }
    if let Method::Elastic(e) = &o.method {
        if !(e.young.is_finite() && e.young > 0.0) {
            return Err(err(
                "--young",
                num(e.young),
                "Young's modulus must be positive and finite",
            ));
        }
        if !(e.poisson.is_finite() && e.poisson > -1.0 && e.poisson < 0.5) {
            return Err(err(
                "--poisson",
                num(e.poisson),
                "Poisson's ratio must be in (-1, 0.5)",
            ));
        }
        check_cg(&e.cg)?;
    }
    if let Some(e) = &o.energy {
        in_range("--energy-weight", e.weight, 0.0, 1e12)?;
        in_range("--energy-tol", e.rel_tol, 0.0, 1.0)?;
        in_range("--energy-sweep-tol", e.sweep_tol, 0.0, 1.0)?;
        in_range("energy gradient tolerance", e.grad_tol, 0.0, 1.0)?;
    }
    Ok(())
}

/// Every option of the `compare` job.
pub fn check_compare(o: &CompareOptions) -> Result<(), ParamError> {
    check_curve(&o.base)?;
    check_curve(&CurveOptions {
        method: Method::Elastic(o.elastic),
        ..o.base.clone()
    })
}

/// `generate --elements N`: at least 1, at most [`MAX_GENERATED_ELEMENTS`].
pub fn check_generated_elements(n: usize) -> Result<(), ParamError> {
    if n == 0 || n > MAX_GENERATED_ELEMENTS {
        return Err(err(
            "--elements",
            n,
            format!("must be in 1..={MAX_GENERATED_ELEMENTS}"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_options_are_refused() {
        let mut o = CurveOptions::default();
        check_curve(&o).unwrap();
        o.fit.cg.rel_tol = f64::NAN;
        assert_eq!(check_curve(&o).unwrap_err().option, "--cg-tol");
        let mut o = CurveOptions::default();
        o.line_search.min_det_fraction = f64::NAN;
        assert_eq!(check_curve(&o).unwrap_err().option, "--min-det-fraction");
        let mut o = CurveOptions::default();
        o.features.params.angle_deg = f64::NAN;
        assert_eq!(check_curve(&o).unwrap_err().option, "--feature-angle");
        let mut o = CurveOptions::default();
        o.fit.weights.corner = 1e308;
        assert_eq!(check_curve(&o).unwrap_err().option, "--w-corner");
        let o = CurveOptions {
            order: 1,
            subdivide: Some(0),
            ..Default::default()
        };
        assert_eq!(check_curve(&o).unwrap_err().option, "--subdivide");
        assert!(check_generated_elements(0).is_err());
        assert!(check_generated_elements(MAX_GENERATED_ELEMENTS + 1).is_err());
    }
}
