//! Progress of the `curve` job's stages, reported through a callback (never printed by the
//! library itself).
//!
//! The pipeline calls [`Progress::started`] and [`Progress::finished`] around every [`Stage`]
//! it runs (the names of the report's `timings`), and [`Progress::cg`] on every CG iteration of
//! the fit; it asks [`Progress::cancelled`] between stages and stops when told. [`Silent`]
//! ignores them; [`Terminal`] draws an indicatif spinner on stderr naming
//! the running stage (announced by the pipeline as it starts, so the label is the stage that
//! really runs), and stays off when stderr is not a terminal.

use std::io::IsTerminal;
use std::time::Duration;

/// A stage of the `curve` job. [`Stage::key`] names it in the report's `timings` (and the
/// order of the variants is the order the stages run in); stages marked "part" are not run on
/// their own but are the measured share of the stage before them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Stage {
    /// Reading the input file.
    Read,
    /// Topology and the curvability checks.
    Topology,
    /// Features, kinks, smooth targets and the spline space (and its rebuilds after demotion).
    Spline,
    /// Under mpirun only: the ranks' shares of the spline space's control points (their halo).
    Partition,
    /// The least-squares fit (every round).
    Fit,
    /// Part of [`Stage::Fit`]: assembling the normal equations.
    FitAssembly,
    /// Part of [`Stage::Fit`]: the CG solve.
    FitCg,
    /// Certification: the certified blend or line search, demotion rounds, the final bound.
    Validity,
    /// The degeneration-energy minimisation (`--fit energy`).
    Energy,
    /// Sampling the order-P Lagrange nodes.
    Sample,
    /// Snapping boundary vertex nodes onto the input vertices.
    Snap,
    /// The straight order-P mesh the elastic analogy starts from.
    ElasticSample,
    /// The elastic analogy.
    Elastic,
    /// Part of [`Stage::Elastic`]: assembly.
    ElasticAssembly,
    /// Part of [`Stage::Elastic`]: the CG solve.
    ElasticCg,
    /// The certificate of the elastic mesh's Lagrange elements.
    ElasticValidity,
    /// Periodic seams: the image sides' nodes made the transform of the master sides', the
    /// touched elements certified again.
    Periodic,
    /// Sampled quality and boundary distances of the output.
    Quality,
    /// Writing the output file.
    Write,
    /// The whole job.
    Total,
}

impl Stage {
    /// The name in the report's `timings`.
    pub fn key(self) -> &'static str {
        match self {
            Stage::Read => "read",
            Stage::Topology => "topology",
            Stage::Spline => "spline",
            Stage::Partition => "partition",
            Stage::Fit => "fit",
            Stage::FitAssembly => "fit_assembly",
            Stage::FitCg => "fit_cg",
            Stage::Validity => "validity",
            Stage::Energy => "energy",
            Stage::Sample => "sample",
            Stage::Snap => "snap",
            Stage::ElasticSample => "elastic_sample",
            Stage::Elastic => "elastic",
            Stage::ElasticAssembly => "elastic_assembly",
            Stage::ElasticCg => "elastic_cg",
            Stage::ElasticValidity => "elastic_validity",
            Stage::Periodic => "periodic",
            Stage::Quality => "quality",
            Stage::Write => "write",
            Stage::Total => "total",
        }
    }

    /// What the terminal shows while the stage runs.
    pub fn label(self) -> &'static str {
        match self {
            Stage::Read => "reading",
            Stage::Topology => "topology",
            Stage::Spline => "spline space",
            Stage::Partition => "partition",
            Stage::Fit | Stage::FitAssembly | Stage::FitCg => "fit",
            Stage::Validity | Stage::ElasticValidity => "certificate",
            Stage::Energy => "energy",
            Stage::Sample => "sampling",
            Stage::Snap => "snapping boundary vertices",
            Stage::ElasticSample | Stage::Elastic | Stage::ElasticAssembly | Stage::ElasticCg => {
                "elastic analogy"
            }
            Stage::Periodic => "periodic seams",
            Stage::Quality => "quality",
            Stage::Write => "writing",
            Stage::Total => "working",
        }
    }
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.key())
    }
}

/// Receiver of stage progress.
pub trait Progress: Sync {
    /// `stage` begins (it may run again later: the fit and the certificate repeat after a
    /// demotion round).
    fn started(&self, _stage: Stage) {}
    /// `stage` has ended.
    fn finished(&self, _stage: Stage) {}
    /// The fit's CG solve reached `iteration` with relative residual `rel_residual`.
    fn cg(&self, _iteration: usize, _rel_residual: f64) {}
    /// The elastic analogy's CG solve reached `iteration` with relative residual `rel_residual`.
    fn elastic_cg(&self, _iteration: usize, _rel_residual: f64) {}
    /// Whether the caller wants the job to stop: asked between stages (after every
    /// [`Progress::finished`] and between the rounds of the fit and the certificate), where
    /// the job then ends with `CurveError::Cancelled` and writes nothing.
    fn cancelled(&self) -> bool {
        false
    }
}

/// No progress output.
pub struct Silent;

impl Progress for Silent {}

/// An indicatif spinner on stderr with the running stage and the elapsed time; hidden when
/// stderr is not a terminal or `quiet` is set. Short jobs finish before the first redraw
/// (4 per second) and leave nothing behind: the spinner is cleared at the end.
pub struct Terminal {
    bar: indicatif::ProgressBar,
}

impl Terminal {
    pub fn new(quiet: bool) -> Self {
        let bar = if quiet || !std::io::stderr().is_terminal() {
            indicatif::ProgressBar::hidden()
        } else {
            let bar = indicatif::ProgressBar::with_draw_target(
                None,
                indicatif::ProgressDrawTarget::stderr_with_hz(4),
            );
            bar.set_style(
                indicatif::ProgressStyle::with_template("{spinner} [{elapsed}] {msg}")
                    .expect("valid template"),
            );
            bar.enable_steady_tick(Duration::from_millis(250));
            bar
        };
        bar.set_message("reading");
        Terminal { bar }
    }

    /// Remove the spinner (call before printing the summary).
    pub fn clear(&self) {
        self.bar.finish_and_clear();
    }
}

impl Progress for Terminal {
    fn started(&self, stage: Stage) {
        self.bar.set_message(stage.label());
    }
    fn cg(&self, iteration: usize, rel_residual: f64) {
        self.bar.set_message(format!(
            "fit: CG iteration {iteration}, relative residual {rel_residual:.1e}"
        ));
    }
    fn elastic_cg(&self, iteration: usize, rel_residual: f64) {
        self.bar.set_message(format!(
            "elastic analogy: CG iteration {iteration}, relative residual {rel_residual:.1e}"
        ));
    }
}

impl Drop for Terminal {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}
