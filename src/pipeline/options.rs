//! The options of the `curve` job and their check: what to sample ([`Geometry`]), how the
//! interior is placed ([`Method`]), the fit, line search, features, output and executor
//! ([`CurveOptions`]).
//!
//! Input: the values a caller (the command line, `compare`, a library user) sets. Output:
//! [`CurveOptions::check`] refuses the first value out of range with a [`ParamError`] naming
//! the option as the command line spells it, before any work; each options struct checks its
//! own fields (`FitParams::check`, `LineSearchParams::check`, ...), this one what belongs to
//! the job (the order) and the order in which they are checked.

use crate::elastic::ElasticParams;
use crate::energy::EnergyParams;
use crate::exec::gpu::Backend;
use crate::fit::FitParams;
use crate::io::high_order::OutputOptions;
use crate::io::read_feature_edits;
use crate::mesh::features::{FeatureError, FeatureParams, Features};
use crate::mesh::{LinearMesh, MeshOptions, Topology};
use crate::params::ParamError;
use crate::sample::MAX_ORDER;
use crate::spline::KnotParams;
use crate::validity::{LineSearchMode, LineSearchParams};
use serde::Serialize;
use std::path::PathBuf;

/// What geometry to sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Geometry {
    /// The input's straight-sided (bilinear/trilinear) elements at the requested order.
    Straight,
    /// The spline map from the initial control points (vertex averages), not fitted.
    SplineInitial,
    /// The spline map fitted by least squares with these weights, then certified.
    SplineFitted,
}

/// How the interior of the curved mesh is placed.
#[derive(Clone, Copy, Debug)]
pub enum Method {
    /// Sample the (fitted) spline map everywhere (the paper's method).
    Iga,
    /// Sample the spline only on the boundary; move the interior nodes of the straight order-P
    /// mesh by linear elasticity (paper §2.5, the baseline).
    Elastic(ElasticParams),
}

impl Method {
    pub fn name(&self) -> &'static str {
        match self {
            Method::Iga => "iga",
            Method::Elastic(_) => "elastic",
        }
    }
}

/// Options of the `curve` job.
#[derive(Clone, Debug)]
pub struct CurveOptions {
    pub order: usize,
    /// Order 1 output split into `subdivide`^d elements per input element.
    pub subdivide: Option<usize>,
    pub geometry: Geometry,
    /// IGA everywhere, or the elastic analogy inside the IGA boundary.
    pub method: Method,
    /// Weights of the fit (used with [`Geometry::SplineFitted`]).
    pub fit: FitParams,
    /// Knot intervals of the spline space (`auto` by default, decided by the spline stages;
    /// under mpirun on the whole mesh, see `distributed::knots`).
    pub knots: KnotParams,
    pub line_search: LineSearchParams,
    pub line_search_mode: LineSearchMode,
    /// Move boundary vertex nodes back to the input vertices where that stays certified valid.
    pub snap_boundary: bool,
    /// Redo the least-squares pass with the elements whose initial spline map is not certified
    /// made Q2 before the fit, kept where its blend holds back fewer elements
    /// (`pipeline::passes`'s `demote_before_fit_if_fewer`, under mpirun too); without it the
    /// redo runs only where `pipeline::spline::demotes_by_default`, and is kept only where
    /// `pipeline::spline::demotion_keeps_the_boundary`.
    pub demote_uncertified: bool,
    /// Sharp features kept by the spline space and the fit (`docs/features.md`).
    pub features: FeatureOptions,
    pub mesh: MeshOptions,
    pub output: OutputOptions,
    /// Executor of sampling, certification and the CG solve.
    pub backend: Backend,
    /// After the certified least-squares fit, minimise the element degeneration energy
    /// ([`crate::energy`]); `None` (the default) keeps the least-squares result.
    pub energy: Option<EnergyParams>,
    /// Periodic boundary pairs (`--periodic`, `--periodic-pyfr-names`).
    pub periodic: PeriodicOptions,
}

/// Periodic boundary pairs: the written nodes of each image side are the transform of its
/// master side's (`crate::mesh::periodic`).
#[derive(Clone, Debug, Default)]
pub struct PeriodicOptions {
    /// `--periodic A:B`, in the order given.
    pub pairs: Vec<crate::mesh::periodic::PeriodicSpec>,
    /// Name pair i's groups `periodic_<i>_l` (master) and `periodic_<i>_r` (image), PyFR's
    /// convention, in the written mesh: the pairs of `pairs` and of the input's `$Periodic`
    /// (a mesh with neither is refused once read).
    pub pyfr_names: bool,
}

impl Default for CurveOptions {
    /// The CLI's defaults: order 2, the smooth-boundary fit, local line search, CPU backend.
    fn default() -> Self {
        CurveOptions {
            order: 2,
            subdivide: None,
            geometry: Geometry::SplineFitted,
            method: Method::Iga,
            fit: FitParams::smooth(),
            knots: KnotParams::default(),
            line_search: LineSearchParams::default(),
            line_search_mode: LineSearchMode::Local,
            snap_boundary: false,
            demote_uncertified: false,
            features: Default::default(),
            mesh: MeshOptions::default(),
            output: OutputOptions::default(),
            backend: Backend::default(),
            energy: None,
            periodic: PeriodicOptions::default(),
        }
    }
}

impl CurveOptions {
    /// These options with the knot intervals `intervals` (`auto`'s passes).
    pub fn with_knots(&self, intervals: crate::spline::KnotIntervals) -> CurveOptions {
        CurveOptions {
            knots: crate::spline::KnotParams {
                intervals,
                ..self.knots
            },
            ..self.clone()
        }
    }

    /// Every option of the `curve` job, before any work (the order range is checked here too,
    /// with the option's own name: `--order` or `--subdivide`). The first option out of range
    /// is the error.
    pub fn check(&self) -> Result<(), ParamError> {
        if !(1..=MAX_ORDER).contains(&self.order) {
            return Err(ParamError::new(
                "--order",
                self.order,
                format!("must be in 1..={MAX_ORDER}"),
            ));
        }
        if let Some(k) = self.subdivide
            && !(1..=MAX_ORDER).contains(&k)
        {
            return Err(ParamError::new(
                "--subdivide",
                k,
                format!("must be in 1..={MAX_ORDER} (sub-elements per edge)"),
            ));
        }
        self.fit.check()?;
        self.knots.check()?;
        self.features.params.check()?;
        self.line_search.check()?;
        if let Method::Elastic(e) = &self.method {
            e.check()?;
        }
        self.output.check()?;
        if let Some(e) = &self.energy {
            e.check()?;
        }
        Ok(())
    }
}

/// Feature detection as the CLI asks for it: parameters and an optional edits file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FeatureOptions {
    pub params: FeatureParams,
    /// `--feature-edits FILE` (see [`read_feature_edits`]).
    pub edits: Option<PathBuf>,
    /// Detect and measure the features (reports), but let neither the spline space nor the fit
    /// use them: the smooth treatment, for comparisons.
    pub ignore: bool,
}

impl FeatureOptions {
    /// Read the edits file, if any, and detect the features of `mesh`.
    pub fn detect(&self, mesh: &LinearMesh, topo: &Topology) -> Result<Features, FeatureError> {
        self.params.check()?;
        match &self.edits {
            None => Ok(Features::detect_without_edits(mesh, topo, &self.params)),
            Some(path) => {
                Features::detect(mesh, topo, &self.params, &read_feature_edits(path)?, path)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_options_are_refused() {
        let mut o = CurveOptions::default();
        o.check().unwrap();
        o.fit.cg.rel_tol = f64::NAN;
        assert_eq!(o.check().unwrap_err().option, "--cg-tol");
        let mut o = CurveOptions::default();
        o.line_search.min_det_fraction = f64::NAN;
        assert_eq!(o.check().unwrap_err().option, "--min-det-fraction");
        let mut o = CurveOptions::default();
        o.features.params.angle_deg = f64::NAN;
        assert_eq!(o.check().unwrap_err().option, "--feature-angle");
        let mut o = CurveOptions::default();
        o.fit.weights.corner = 1e308;
        assert_eq!(o.check().unwrap_err().option, "--w-corner");
        let o = CurveOptions {
            order: 1,
            subdivide: Some(0),
            ..Default::default()
        };
        assert_eq!(o.check().unwrap_err().option, "--subdivide");
        let mut o = CurveOptions::default();
        o.output.volume_name = "a\"b".into();
        assert_eq!(o.check().unwrap_err().option, "--volume-name");
    }
}
