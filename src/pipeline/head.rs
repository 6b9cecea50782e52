//! The `curve` job's head over a process's share of the input: the reductions that make a
//! process's figures the whole mesh's, the agreement on a stage that may fail on one process,
//! the input's smallest scaled Jacobian, the refusal of `--periodic-pyfr-names` without a
//! pair, the periodic seams glued in the spline space and the spline (the setup of uniform
//! knots, then the passes), one sequence for the serial job and the job under mpirun alike.
//!
//! Input: a [`Reduction`] (the serial job: one process, [`OneProcess`]; a rank: its
//! communicator) and the mesh the process holds. Output: the whole mesh's figures, the same
//! on every process. What stays a process's own, behind the job: reading (the serial
//! readers, or a rank's share with its ghost rings), the topology's check (the whole mesh's,
//! or the entities of a rank's own elements), the periodic pairs' resolution (over the
//! ranks: gathered sides) and the gluing of the mesh a process holds ([`glue_seams`]'s
//! `glue`), the smooth targets' inheritance across the ranks ([`crate::fit::InheritShare`]).
//!
//! Invariant: every method of a [`Reduction`] is collective: every process calls it in the
//! same order, and every process ends with the same answer.

use super::clock::Clock;
use super::passes::{Passes, spline_passes};
use super::spline::SplineSetup;
use super::{CurveError, Job};
use crate::mesh::LinearMesh;
use crate::mesh::periodic::PeriodicPair;
use crate::progress::Stage;
use crate::spline::KnotIntervals;
use crate::spline::seam::Glued;
use std::path::Path;

/// A reduction over the processes of a job ([`Reduction::reduce`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Reduce {
    Sum,
    Min,
    Max,
}

/// How the processes of a job make their figures the whole mesh's. Every method is
/// collective.
pub(crate) trait Reduction {
    /// `v` reduced element-wise by `op` over the job's processes, in place (one process: left
    /// as it is).
    fn reduce(&self, op: Reduce, v: &mut [f64]);
    /// The lowest process whose stage failed (`failed`: this one's did), when any did.
    fn lowest_failed(&self, failed: bool) -> Option<usize>;
    /// Whether `ok` holds on every process.
    fn all(&self, ok: bool) -> bool {
        let mut v = [f64::from(u8::from(ok))];
        self.reduce(Reduce::Min, &mut v);
        v[0] > 0.0
    }
    /// The whole mesh's bounding-box diagonal (the processes' boxes of `mesh` reduced).
    fn diagonal(&self, mesh: &LinearMesh) -> f64 {
        let (mut lo, mut hi) = mesh.bounding_box();
        self.reduce(Reduce::Min, &mut lo);
        self.reduce(Reduce::Max, &mut hi);
        crate::math::linalg::box_diagonal(lo, hi)
    }
    /// The input's smallest scaled Jacobian over the whole mesh (the processes' meshes), NaN
    /// without any element.
    fn input_min_scaled_jacobian(&self, mesh: &LinearMesh) -> f64 {
        let mut v = [mesh.min_scaled_jacobian().map_or(f64::INFINITY, |m| m.0)];
        self.reduce(Reduce::Min, &mut v);
        if v[0] == f64::INFINITY {
            f64::NAN
        } else {
            v[0]
        }
    }
}

/// The serial job's reduction: one process.
pub(crate) struct OneProcess;

impl Reduction for OneProcess {
    fn reduce(&self, _: Reduce, _: &mut [f64]) {}
    fn lowest_failed(&self, failed: bool) -> Option<usize> {
        failed.then_some(0)
    }
}

/// A stage's outcome `r` on this process, agreed over the processes: unchanged when no process
/// failed; else an error on every process (its own, or a line naming the lowest failing
/// process), so that no process goes on into a collective the failed ones will not join.
pub(crate) fn agreed<T, R: Reduction + ?Sized>(
    reduction: &R,
    r: Result<T, CurveError>,
) -> Result<T, CurveError> {
    match (reduction.lowest_failed(r.is_err()), r) {
        (Some(q), Ok(_)) => Err(CurveError::Options(format!("stopped: rank {q} failed"))),
        (_, r) => r,
    }
}

/// `--periodic-pyfr-names` names the groups of the periodic pairs: refused where the job
/// resolved none (`pairs`, the whole mesh's).
pub(crate) fn check_pyfr_names(
    input: &Path,
    pyfr_names: bool,
    pairs: &[PeriodicPair],
) -> Result<(), CurveError> {
    if pyfr_names && pairs.is_empty() {
        return Err(CurveError::Periodic {
            input: input.to_owned(),
            source: crate::mesh::periodic::PeriodicError {
                spec: "--periodic-pyfr-names".into(),
                what: "the mesh has no periodic pair to name: give one with --periodic A:B (or in a Gmsh input's $Periodic section)".into(),
            },
        });
    }
    Ok(())
}

/// The seams of `pairs` (the whole mesh's) glued in the spline space, and why some pair stays
/// apart: every pair where the glued mesh is manifold on every process, else the translation
/// pairs alone (the rotation pairs apart), else none. `glue(rotations)` glues the mesh this
/// process holds (`rotations`: the rotation pairs too); `across`: the mesh a process holds
/// runs across the seams (a rank's share read through them; not Gmsh's partitioned inputs),
/// otherwise nothing is glued. Every process glues alike or none does.
pub(crate) fn glue_seams<R: Reduction + ?Sized>(
    reduction: &R,
    pairs: &[PeriodicPair],
    across: bool,
    glue: impl Fn(bool) -> Option<Glued>,
) -> (Option<Glued>, Option<String>) {
    if pairs.is_empty() {
        return (None, None);
    }
    let translations = pairs.iter().any(|p| p.transform.is_translation());
    let rotations = pairs.iter().any(|p| !p.transform.is_translation());
    let glued = if across {
        let all = glue(true);
        let everywhere = reduction.all(all.is_some());
        match all.filter(|_| everywhere) {
            Some(g) => Some((g, true)),
            None if rotations && translations => glue(false).map(|g| (g, false)),
            None => None,
        }
    } else {
        None
    };
    let everywhere = reduction.all(glued.is_some());
    let glued = glued.filter(|_| everywhere);
    let why = match &glued {
        Some((_, true)) => None,
        _ if !across => Some(
            "under mpirun the seams of a partitioned input are not identified in the spline space",
        ),
        None if translations => Some("the mesh with its translation pairs glued is not manifold"),
        _ => Some("the mesh with its rotation pairs glued is not manifold"),
    };
    (glued.map(|(g, _)| g), why.map(str::to_string))
}

/// The job's spline on the process's passes `p`: the setup of uniform knots with `seams`
/// glued (on a rank's share, `inherit` makes its smooth targets the whole mesh's), agreed over
/// the processes, then the spline passes ([`spline_passes`]: graded ones are put in place once
/// surveyed; the features, kinks and targets do not depend on the knots). Returns the setup
/// (the pass kept's knots and weights) and the pass kept.
pub(crate) fn spline_job<P: Passes>(
    p: &mut P,
    job: &Job,
    clock: &mut Clock,
    seams: (Option<Glued>, Option<String>),
    inherit: Option<&dyn crate::fit::InheritShare>,
) -> Result<(SplineSetup, P::Pass), CurveError> {
    let uniform = job.options.with_knots(KnotIntervals::Uniform);
    let uniform_job = Job {
        options: &uniform,
        ..*job
    };
    let mut setup = clock.run(Stage::Spline, || {
        agreed(p, SplineSetup::with_seams(&uniform_job, seams, inherit))
    })?;
    let pass = spline_passes(p, job, &mut setup, clock)?;
    Ok((setup, pass))
}
