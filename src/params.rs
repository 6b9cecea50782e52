//! Validation of every option before any work, in the library (so a caller of
//! [`crate::pipeline::curve`] or [`crate::compare::compare`] is refused as the command line is;
//! the command line only parses).
//!
//! Input: the option structs of the jobs, or single option values of the commands that have no
//! job struct (`generate --elements`, `plot --width`, `--window`, `--label`). Output: `Ok(())`
//! (or the parsed value) or a [`ParamError`] naming the option (by its command-line spelling)
//! and the value.
//!
//! Invariants: every `f64` option is finite (NaN and infinities are refused) and inside a
//! range in which the job means something; every count is at least 1 where 0 would silently
//! do nothing or something else. Fit weights are bounded by [`MAX_WEIGHT`], so the
//! normal-equation matrix cannot overflow (weights multiply squared residuals).

use crate::compare::CompareOptions;
use crate::elastic::ElasticParams;
use crate::fit::{FitParams, FitTargets};
use crate::mesh::features::FeatureParams;
use crate::mesh::generate::Shape;
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

/// `--kink-angle`: degrees in (0, 360] (180 and above turn the kink test off). The command line
/// checks it with every fit, though only the smooth targets use it.
pub fn check_kink_angle(deg: f64) -> Result<(), ParamError> {
    above("--kink-angle", deg, 0.0, 360.0)
}

/// Fit weights, CG and smooth-target parameters.
pub fn check_fit(p: &FitParams) -> Result<(), ParamError> {
    let w = &p.weights;
    for (option, v) in [
        ("--w-corner", w.corner),
        ("--w-boundary-corner", w.boundary_corner),
        ("--w-midpoint", w.midpoint),
        ("--w-boundary-midpoint", w.boundary_midpoint),
        ("--w-frame-corner", w.frame_corner),
        ("--w-frame-midpoint", w.frame_midpoint),
        ("--w-feature", w.feature),
    ] {
        in_range(option, v, 0.0, MAX_WEIGHT)?;
    }
    check_cg(&p.cg)?;
    if let FitTargets::Smooth(s) = &p.targets {
        check_kink_angle(s.kink_angle_deg)?;
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
    let name = &o.output.volume_name;
    if name.is_empty() || name.contains(['"', '\n', '\r']) {
        return Err(err(
            "--volume-name",
            format!("{name:?}"),
            "must be non-empty, without quotes or line breaks",
        ));
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

/// `generate SHAPE [--elements N]`: the element count belongs to the benchmark shapes (the
/// boundary-layer grids take `--around` and `--across`, checked by their generators).
pub fn check_generate(shape: Shape, elements: Option<usize>) -> Result<(), ParamError> {
    match (shape, elements) {
        (Shape::Benchmark(_), Some(n)) => check_generated_elements(n),
        (Shape::Ogrid | Shape::Cgrid, Some(n)) => Err(err(
            "--elements",
            n,
            "applies to disc, cylinder and torus; ogrid and cgrid take --around and --across",
        )),
        (_, None) => Ok(()),
    }
}

/// `plot --width`: pixels in [16, 100000].
pub fn check_plot_width(width: f64) -> Result<(), ParamError> {
    if width.is_finite() && (16.0..=100_000.0).contains(&width) {
        Ok(())
    } else {
        Err(err(
            "--width",
            num(width),
            "must be a number of pixels in [16, 100000]",
        ))
    }
}

/// `plot --label`: at most one per drawn mesh.
pub fn check_plot_labels(labels: usize, meshes: usize) -> Result<(), ParamError> {
    if labels <= meshes {
        Ok(())
    } else {
        Err(err(
            "--label",
            format!("given {labels} times"),
            format!(
                "{meshes} meshes: give at most one label per mesh (MESH first, then each --overlay)"
            ),
        ))
    }
}

/// `plot --window X0,Y0,X1,Y1`: four finite numbers spanning a rectangle of non-zero size.
pub fn parse_window(text: &str) -> Result<[f64; 4], ParamError> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| err("--window", text, e.to_string()))?;
    match v[..] {
        [x0, y0, x1, y1] if x0 != x1 && y0 != y1 && v.iter().all(|x| x.is_finite()) => {
            Ok([x0, y0, x1, y1])
        }
        _ => Err(err(
            "--window",
            text,
            "give four numbers X0,Y0,X1,Y1 of a rectangle of non-zero size",
        )),
    }
}

/// `--method iga|elastic`; `elastic` carries default material and solver parameters, which
/// the caller replaces with its own.
impl clap::ValueEnum for Method {
    fn value_variants<'a>() -> &'a [Self] {
        static VARIANTS: std::sync::OnceLock<[Method; 2]> = std::sync::OnceLock::new();
        VARIANTS.get_or_init(|| [Method::Iga, Method::Elastic(ElasticParams::default())])
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
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
        let mut o = CurveOptions::default();
        o.output.volume_name = "a\"b".into();
        assert_eq!(check_curve(&o).unwrap_err().option, "--volume-name");
        assert!(check_generated_elements(0).is_err());
        assert!(check_generate(Shape::Ogrid, Some(100)).is_err());
        assert!(check_generate(Shape::Ogrid, None).is_ok());
        assert!(parse_window("0,0,1,1").is_ok());
        assert!(parse_window("0,0,0,1").is_err());
        assert!(parse_window("0,0,1").is_err());
        assert!(check_plot_width(f64::NAN).is_err());
        assert!(check_plot_labels(3, 2).is_err());
        assert!(check_generated_elements(MAX_GENERATED_ELEMENTS + 1).is_err());
    }
}
