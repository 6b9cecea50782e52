//! The `curve` job's tail over a process's share of the output: sample, quality and the
//! report built from the stages' outcomes, one sequence for the serial job and the job under
//! mpirun alike.
//!
//! Input: a [`JobShare`] (how this process samples its part of the certified map, measures
//! the quality of the whole output and gathers the stages' outcomes over the whole mesh) and
//! the stage clock. Output: the process's sampled output and the [`CurveReport`] (`output`
//! empty: set when written).
//!
//! The serial job is the identity share (`pipeline::WholeJob`): it samples every element,
//! with `--snap-boundary`, `--method elastic` and periodic seams after sampling, and its
//! outcomes are its own. A rank under mpirun samples its own elements in global node tags
//! (the seams made exact images there too), measures the quality reduced over the ranks and
//! sums its outcomes with the other ranks'.
//!
//! Invariant: the report is [`CurveReport::build`]'s of the whole mesh's outcomes, its
//! `timings` the clock's at the end with `total` since `start`.

use super::clock::Clock;
use super::{CurveError, CurveOptions, CurveReport, Outcomes};
use crate::deviation::BoundaryDeviation;
use crate::progress::Stage;
use std::path::Path;
use std::time::Instant;

/// What differs between the processes of a job after its spline. Every method is collective
/// over the job's processes.
pub(crate) trait JobShare {
    /// This process's sampled output (the serial job's whole mesh, or a rank's share).
    type Output;
    /// The order-P nodes of this process's elements of the certified map, with what follows
    /// sampling (snap, elastic analogy, periodic seams), each on its stage of `clock`.
    fn sample(&mut self, clock: &mut Clock) -> Result<Self::Output, CurveError>;
    /// The whole output's smallest sampled scaled Jacobian (every element must have det J > 0
    /// on the lattice of order 2P) and its boundary distances from the input.
    fn quality(&mut self, output: &Self::Output) -> Result<(f64, BoundaryDeviation), CurveError>;
    /// The stages' outcomes over the whole mesh, `clock` the stages' so far.
    fn outcomes(
        &mut self,
        output: &Self::Output,
        quality: (f64, BoundaryDeviation),
        clock: &Clock,
    ) -> Outcomes;
}

/// The job's tail on `share`: sample, quality (timed as [`Stage::Quality`]), the outcomes, and
/// the report of `input` with `options` (`total` the seconds since `start`).
pub(crate) fn finish_job<S: JobShare>(
    share: &mut S,
    input: &Path,
    options: &CurveOptions,
    mut clock: Clock,
    start: Instant,
) -> Result<(S::Output, CurveReport), CurveError> {
    clock.check()?;
    let output = share.sample(&mut clock)?;
    clock.check()?;
    let quality = clock.run(Stage::Quality, || share.quality(&output))?;
    let outcomes = share.outcomes(&output, quality, &clock);
    clock.set(Stage::Total, start.elapsed().as_secs_f64());
    let gpu_traffic = clock.gpu_traffic();
    let mut report = CurveReport::build(input, options, outcomes, clock.into_timings());
    report.gpu_traffic = gpu_traffic;
    Ok((output, report))
}
