//! A process's share of the `curve` job's spline pass: the one sequence of a least-squares
//! pass (space, fit, misfit rounds, certified blend) for the serial job and the job under
//! mpirun alike.
//!
//! Input: a [`Share`] (how this process fits its elements, finds the misfit sides of the
//! whole mesh and runs its part of the certified blend), the [`Job`] and the
//! [`SplineSetup`]. Output: a [`LeastSquares`] pass: the fitted space, the share's fit
//! figures and the blend's factors, nets and figures (or the lower bound at which a bounded
//! blend stopped).
//!
//! The serial job is the identity share: every element is its own, the misfit sides are its
//! own, the blend judges every element ([`Alone`]). A rank under mpirun (the distributed job's
//! implementation) fits its own rows with the distributed CG, gathers the whole boundary's
//! misfit sides and judges its own elements in the blend's rounds, agreed over the ranks.
//!
//! Invariant: every decision of the sequence (another misfit round, the blend's rounds and its
//! bound) is taken on whole-mesh figures, so every process of a job takes it alike and as the
//! serial job does.

use super::clock::Clock;
use super::misfit;
use super::spline::{Demoted, SplineSetup, carry_over};
use super::{CurveError, Job, LineSearchMode};
use crate::fit::SmoothTargets;
use crate::progress::Stage;
use crate::spline::SplineSpace;
use crate::validity::blend::{
    Alone, BlendInfo, BlendShare, Blended, Bounded, NetCache, blend_search_shared,
    blend_search_shared_at_most,
};

/// The certified blend's factors and nets (for sampling the same blend) and its figures.
pub(crate) type Blend = ((Vec<f32>, NetCache), BlendInfo);

/// What differs between the processes that run a least-squares pass. Every method is
/// collective over the job's processes.
pub(crate) trait Share {
    /// The fit's figures of this process (the serial fit's, or a rank's CG, halo and
    /// stored entries).
    type Fit;
    /// The least-squares control points of `space` (its own are left as they are), started
    /// from `start` (one per control point) where given, timed as [`Stage::Fit`] with its
    /// parts; `round` is 0 for a pass's first fit and k for the refit of its k-th misfit
    /// round.
    fn fit(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        space: &SplineSpace,
        start: Option<&[[f64; 3]]>,
        round: usize,
    ) -> Result<(Vec<[f64; 3]>, Self::Fit), CurveError>;
    /// The spline elements of this process's mesh whose boundary sides stay far off their
    /// smooth targets under the control points `fitted` of `space`, found over the whole
    /// mesh's boundary ([`misfit::marked_sides`]); `None` when the whole mesh has none.
    fn misfit_marks(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        space: &SplineSpace,
        fitted: &[[f64; 3]],
        targets: &SmoothTargets,
    ) -> Option<Vec<bool>>;
    /// The certified blend of this process's part of `space` (fitted), with `most` given up
    /// once the whole mesh holds back more than `most` elements (`Ok(Err(at_least))`); every
    /// process stops alike, on an error too.
    fn blend(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        space: &SplineSpace,
        most: Option<usize>,
    ) -> Result<Result<Blend, usize>, CurveError>;
}

/// One least-squares pass ([`least_squares_pass`]).
pub(crate) struct LeastSquares<F> {
    /// The space with its fitted control points.
    pub space: SplineSpace,
    /// The share's fit figures.
    pub fit: F,
    /// The certified blend, or the elements of the whole mesh it held back at least when it
    /// was given up.
    pub blend: Result<Blend, usize>,
    /// Elements of the whole mesh demoted to Q2 before the fit (`--demote-uncertified`).
    pub demoted: usize,
}

/// Least squares: the space of `setup` (the elements of `demote` Q2), one fit (started from
/// `previous`'s fitted control points where given) with its misfit rounds
/// ([`fit_demoting_misfits`]), then the certified blend from the straight elevation to it
/// (valid for every input whose straight elevation is certified); with `most`, the blend is
/// given up once it holds back more than `most` elements ([`Share::blend`]).
pub(crate) fn least_squares_pass<S: Share>(
    share: &mut S,
    job: &Job,
    setup: &SplineSetup,
    clock: &mut Clock,
    previous: Option<&SplineSpace>,
    most: Option<usize>,
    demote: Option<&Demoted>,
) -> Result<LeastSquares<S::Fit>, CurveError> {
    let marks = demote.map_or(&[][..], |d| &d.marks[..]);
    let mut space = clock.run(Stage::Spline, || setup.build(job, marks));
    clock.check()?;
    let mut misfit = Vec::new();
    let start = previous.map(|p| carry_over(p, &p.control_points, &space));
    let (c_star, fit) = fit_demoting_misfits(
        share,
        job,
        setup,
        clock,
        &mut space,
        marks,
        &mut misfit,
        start,
    )?;
    clock.check()?;
    space.control_points = c_star;
    let blend = clock.run(Stage::Validity, || share.blend(job, setup, &space, most))?;
    Ok(LeastSquares {
        space,
        fit,
        blend,
        demoted: demote.map_or(0, |d| d.count),
    })
}

/// `pass`, its blend run to its end where it was given up (on its own space: the setup's knots
/// may be another pass's).
pub(crate) fn finish_blend<S: Share>(
    share: &mut S,
    job: &Job,
    setup: &SplineSetup,
    clock: &mut Clock,
    mut pass: LeastSquares<S::Fit>,
) -> Result<LeastSquares<S::Fit>, CurveError> {
    if pass.blend.is_err() {
        pass.blend = clock.run(Stage::Validity, || {
            share.blend(job, setup, &pass.space, None)
        })?;
    }
    Ok(pass)
}

/// The fit ([`Share::fit`]), then up to [`misfit::MISFIT_ROUNDS`] times: the spline elements
/// whose boundary side stays far off its smooth targets ([`Share::misfit_marks`]) join
/// `misfit` (marks per element, kept across calls), the space is rebuilt with them (and
/// `demote`) as Q2 and the fit repeated, started from the previous fit where the two spaces
/// share control points. Only with smooth targets and in 2D (on the 3D O-grid cylinder the
/// elements marked next to the sharp rims leave the boundary further off, not closer); the
/// rounds stop when no element of the whole mesh is marked. Returns the fitted control points
/// of `space` (left unfitted) and the last fit's figures.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit_demoting_misfits<S: Share>(
    share: &mut S,
    job: &Job,
    setup: &SplineSetup,
    clock: &mut Clock,
    space: &mut SplineSpace,
    demote: &[bool],
    misfit: &mut Vec<bool>,
    mut start: Option<Vec<[f64; 3]>>,
) -> Result<(Vec<[f64; 3]>, S::Fit), CurveError> {
    let mut round = 0;
    loop {
        clock.check()?;
        let (c_star, fit) = share.fit(job, setup, clock, space, start.as_deref(), round)?;
        let Some(targets) = setup.targets.as_ref() else {
            return Ok((c_star, fit));
        };
        if job.topo.dim != 2 || round == misfit::MISFIT_ROUNDS {
            return Ok((c_star, fit));
        }
        round += 1;
        let marks = clock.run(Stage::Spline, || {
            share.misfit_marks(job, setup, space, &c_star, targets)
        });
        let Some(marks) = marks else {
            return Ok((c_star, fit));
        };
        misfit.resize(job.mesh.n_elements(), false);
        for (m, x) in misfit.iter_mut().zip(marks) {
            *m |= x;
        }
        let previous = std::mem::replace(
            space,
            clock.run(Stage::Spline, || {
                setup.build_with_misfits(job, demote, misfit)
            }),
        );
        // The next fit starts from this one where the two spaces share control points (most
        // of the mesh: only the marked elements' entities change): 10-35 % fewer CG
        // iterations on the real 2D meshes, and under mpirun the serial refit's iterates.
        start = Some(carry_over(&previous, &c_star, space));
    }
}

/// The certified blend from the straight elevation to the fitted map of `space`
/// ([`crate::validity::blend`]), the elements judged as `judged` shares them ([`Alone`]: every
/// one here); with `most`, the number of elements held back (a lower bound) when the search
/// gives up on holding back more than `most`.
pub(crate) fn blend_within(
    job: &Job,
    setup: &SplineSetup,
    space: &SplineSpace,
    most: Option<usize>,
    judged: &dyn BlendShare,
) -> Result<Result<Blend, usize>, CurveError> {
    let target_map = setup.target_map(job);
    let (ids_mesh, ids_topo) = setup.entity_mesh(job);
    let mut blended = Blended::new(job.mesh, &target_map, space, ids_mesh, ids_topo, Vec::new())
        .with_geometry(job.mesh);
    let global = job.options.line_search_mode == LineSearchMode::Global;
    let params = job.options.line_search.blend(global);
    let certifier = job.executor;
    let searched = match most {
        None => blend_search_shared(certifier, &mut blended, &params, judged).map(Bounded::Done),
        Some(most) => blend_search_shared_at_most(certifier, &mut blended, &params, judged, most),
    }
    .map_err(|source| CurveError::Blend {
        input: job.input.to_owned(),
        source,
    })?;
    Ok(match searched {
        Bounded::Done(info) => {
            let factors = std::mem::take(&mut blended.factors);
            Ok(((factors, blended.into_cache()), info))
        }
        Bounded::Exceeded(at_least) => Err(at_least),
    })
}

/// The serial job's share: every element of the mesh is this process's.
pub(crate) struct WholeMesh;

impl Share for WholeMesh {
    type Fit = crate::fit::FitInfo;
    fn fit(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        space: &SplineSpace,
        start: Option<&[[f64; 3]]>,
        _round: usize,
    ) -> Result<(Vec<[f64; 3]>, Self::Fit), CurveError> {
        super::spline::fit(job, setup, clock, space, start)
    }
    fn misfit_marks(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        space: &SplineSpace,
        fitted: &[[f64; 3]],
        targets: &SmoothTargets,
    ) -> Option<Vec<bool>> {
        let marks = misfit::misfit_elements(job.mesh, setup.topo(job), space, fitted, targets);
        marks.contains(&true).then_some(marks)
    }
    fn blend(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        space: &SplineSpace,
        most: Option<usize>,
    ) -> Result<Result<Blend, usize>, CurveError> {
        blend_within(job, setup, space, most, &Alone)
    }
}
