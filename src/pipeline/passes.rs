//! The spline passes of the job's knot intervals, for the serial job and the job under mpirun
//! alike: which passes run, the bound on `auto`'s uniform pass, the choice between the passes
//! and the warm start of the second.
//!
//! Input: a [`Passes`] (how this process surveys the whole mesh's knot surfaces, turns the
//! survey into its knots and runs one pass, space, fit and certified blend, on its elements:
//! the serial job on the whole mesh, a rank on its share), the [`Job`] (options as asked) and
//! the [`SplineSetup`] of uniform knots. Output: the pass kept; the setup ends with that pass's
//! knots and fit weights (with or without the extraordinary midpoint weight's refit), and
//! `knot_passes` counts the passes run to choose the knots.
//!
//! Invariant: every decision is taken on whole-mesh figures (the survey's graded share and
//! largest |ln ratio|, the blends' held-back counts and the fitted and output boundaries' RMS
//! distances over every process), so every process of
//! a job decides alike and the choice is the serial run's on any number of processes.

use super::clock::Clock;
use super::head::{Reduce, Reduction};
use super::misfit;
use super::spline::{
    Demoted, SplineSetup, auto_graded_is_decisive, auto_graded_keeps_the_boundary,
    auto_holds_back_too_many, demotes_by_default, demotion_is_refused_beforehand,
    demotion_keeps_the_boundary, demotion_marks, extraordinary_refit_is_kept,
    extraordinary_refit_most, fitted_boundary_sq_sum, interior_kinks_keep_the_boundary,
    output_boundary_sq_sum,
};
use super::{CurveError, Job};
use crate::progress::Stage;
use crate::spline::{
    AUTO_GRADED_SHARE, AUTO_MIN_LOG_RATIO, KnotIntervals, KnotParams, Knots, SplineSpace,
};

/// The whole mesh's knot figures `auto` decides on (the serial [`crate::spline::KnotSurvey`],
/// or its assembly over ranks).
pub(crate) trait KnotFigures {
    /// [`crate::spline::KnotSurfaceInfo::graded_share`] of the whole mesh.
    fn graded_share(&self) -> f64;
    /// The largest |measured ln ratio| of an interior facet of the whole mesh.
    fn max_abs_log_ratio(&self) -> f64;
}

impl KnotFigures for crate::spline::KnotSurvey {
    fn graded_share(&self) -> f64 {
        self.graded_share
    }
    fn max_abs_log_ratio(&self) -> f64 {
        self.max_abs_log_ratio
    }
}

/// What differs between the jobs that run spline passes: where the elements are and how
/// their figures are summed. Every method is collective over the job's processes; the
/// measures of the whole mesh (the boundary distances, the demotion, the reweighted count)
/// are provided once over the narrow methods that differ ([`Passes::owned`],
/// [`Reduction::reduce`], [`Passes::unite`]).
pub(crate) trait Passes: Reduction {
    /// One pass's outcome (its fitted space and, unless it stopped early, its blend).
    type Pass;
    /// The whole mesh's knot survey.
    type Survey: KnotFigures;
    /// Elements of the whole mesh.
    fn elements(&self) -> usize;
    /// The whole mesh's knot survey (on the glued mesh where `setup` glues seams), timed as
    /// the spline stage.
    fn survey(&mut self, setup: &SplineSetup, clock: &mut Clock) -> Self::Survey;
    /// This process's knots of `params` from `survey`, timed as the spline stage.
    fn knots(
        &mut self,
        setup: &SplineSetup,
        clock: &mut Clock,
        survey: Self::Survey,
        params: &KnotParams,
    ) -> Knots;
    /// One pass of `job` on `setup`: the space (with the elements of `demote` Q2), the fit
    /// (started from `previous`'s fitted control points where given) and the certificate of
    /// the job's path; with `most`, the certified blend is given up once it holds back more
    /// than `most` elements.
    fn run(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        previous: Option<&Self::Pass>,
        most: Option<usize>,
        demote: Option<&Demoted>,
    ) -> Result<Self::Pass, CurveError>;
    /// Elements `pass` holds back over the whole mesh (its blend's; with `--fit energy`, the
    /// elements its least-squares fit's full step leaves uncertified): `Ok` when it ran to its
    /// end, else `Err` with the lower bound at which it stopped.
    fn held(pass: &Self::Pass) -> Result<usize, usize>;
    /// A pass that stopped early, its blend run to its end (on its own space: the setup's
    /// knots may be another pass's).
    fn finish(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        pass: Self::Pass,
    ) -> Result<Self::Pass, CurveError>;
    /// This process's own elements: the first `owned` of its mesh (the serial job's every
    /// element; a rank's own elements, before its ghosts). Every element of the whole mesh is
    /// one process's own.
    fn owned(&self, job: &Job) -> usize;
    /// `marks` (on this process's elements) made the union of every process's marks, element
    /// by element of the whole mesh; returns how many elements of the whole mesh are marked.
    fn unite(&self, marks: &mut [bool]) -> usize;
    /// `pass`'s space with its fitted control points.
    fn space(pass: &Self::Pass) -> &SplineSpace;
    /// The certified blend's factors of `pass` run to its end (none without a blend).
    fn factors(pass: &Self::Pass) -> &[f32];
    /// The elements of the whole mesh whose initial spline map on `setup` is not certified,
    /// demoted in rounds ([`demotion_marks`], each process certifying its own elements
    /// ([`Passes::owned`]) and the rounds' marks united over the processes
    /// ([`Passes::unite`])), as marks on this process's elements; timed as the validity stage.
    fn demotion(&mut self, job: &Job, setup: &SplineSetup, clock: &mut Clock) -> Option<Demoted> {
        clock.run(Stage::Validity, || demotion_marks(job, setup, &*self))
    }
    /// The RMS of the squared distances `(sum, n)` of this process's own boundary sides summed
    /// over the processes (each boundary side once: a rank's ghosts' outer sides are no
    /// boundary), relative to the whole mesh's bounding-box diagonal.
    fn whole_rms(&self, job: &Job, (sum, n): (f64, usize)) -> f64 {
        let mut v = [sum, n as f64];
        self.reduce(Reduce::Sum, &mut v);
        misfit::rms(v[0], v[1] as usize) / self.diagonal(job.mesh)
    }
    /// RMS distance of `pass`'s fitted boundary from the smooth boundary (the target map's)
    /// over the whole mesh ([`super::misfit::boundary_sq_sum`]), relative to the whole mesh's
    /// bounding-box diagonal, timed as the validity stage.
    fn boundary_rms(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        pass: &Self::Pass,
    ) -> f64 {
        let owned = self.owned(job);
        clock.run(Stage::Validity, || {
            let own = fitted_boundary_sq_sum(job, setup, Self::space(pass), |e| e < owned);
            self.whole_rms(job, own)
        })
    }
    /// RMS distance of `pass`'s output boundary (its certified blend run to its end) from
    /// `reference`'s fitted boundary over the whole mesh ([`super::spline::output_boundary_sq_sum`]),
    /// relative to the whole mesh's bounding-box diagonal, timed as the validity stage; the
    /// nearest points sought up to `reach` beyond each side ([`misfit::boundary_sq_sum_reaching`]).
    fn output_boundary_shift(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        pass: &Self::Pass,
        reference: &Self::Pass,
        reach: f64,
    ) -> f64 {
        let owned = self.owned(job);
        let (space, factors) = (Self::space(pass), Self::factors(pass));
        clock.run(Stage::Validity, || {
            let reference = Self::space(reference);
            let own =
                output_boundary_sq_sum(job, setup, space, factors, reference, reach, |e| e < owned);
            self.whole_rms(job, own)
        })
    }
    /// RMS distance of the target map's boundary from `reference`'s fitted boundary over the
    /// boundary sides of `demote`'s elements, the squares summed over them and divided by the
    /// whole mesh's boundary samples, relative to the whole mesh's bounding-box diagonal and
    /// timed as the validity stage: the part of a demotion redo's
    /// [`Passes::output_boundary_shift`] that those sides make where they stay on the target
    /// map ([`demotion_is_refused_beforehand`]).
    fn demoted_boundary_shift(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        reference: &Self::Pass,
        demote: &Demoted,
    ) -> f64 {
        let owned = self.owned(job);
        clock.run(Stage::Validity, || {
            let topo = setup.topo(job);
            let target_map = setup.target_map(job);
            let marked = |e: usize| e < owned && demote.marks[e];
            let (sum, _) =
                misfit::boundary_sq_sum(topo, &target_map, Self::space(reference), &marked);
            let n = misfit::boundary_samples(topo, &|e| e < owned);
            self.whole_rms(job, (sum, n))
        })
    }
    /// Whether the second pass starts from the first one's fit.
    fn warm_start(&self) -> bool {
        true
    }
    /// Elements of the whole mesh at a sharp turn of an interior grid line
    /// ([`SplineSetup::interior_kinks`]): this process's own elements' (a rank's ghost ring
    /// holds every element at its own elements' vertices), summed over the processes.
    fn interior_kinks(&mut self, job: &Job, setup: &SplineSetup) -> usize {
        let marks = setup.interior_kinks();
        let own = self.owned(job).min(marks.len());
        let mut v = [marks[..own].iter().filter(|&&k| k).count() as f64];
        self.reduce(Reduce::Sum, &mut v);
        v[0] as usize
    }
    /// Elements of the whole mesh whose interior midpoints the extraordinary midpoint weight
    /// raises under `setup`'s fit weights ([`crate::fit::extraordinary_reweighted`]): this
    /// process's own elements' (a rank's ghost rings hold every element of their two rings),
    /// summed over the processes.
    fn reweighted(&mut self, job: &Job, setup: &SplineSetup) -> usize {
        let fit = &setup.fit_params;
        let r = crate::fit::extraordinary_reweighted(
            job.mesh,
            setup.topo(job),
            &fit.weights,
            fit.features.as_deref(),
        );
        let mut v = [r[..self.owned(job)].iter().filter(|&&r| r).count() as f64];
        self.reduce(Reduce::Sum, &mut v);
        v[0] as usize
    }
}

/// The spline passes of `job`'s knot intervals on `setup` (built with uniform knots): uniform
/// or graded knots as asked, one pass; `--knot-intervals auto` (see
/// [`super::spline::curve_spline`] for the rules) decides in one pass where it can:
/// 1. graded knots at once where the survey's graded share reaches [`AUTO_GRADED_SHARE`];
/// 2. else uniform knots, kept where the blend holds back at most
///    [`super::spline::AUTO_MAX_HELD_BACK`] of the elements (or graded knots are all but
///    uniform: no facet's |ln ratio| reaches [`AUTO_MIN_LOG_RATIO`]). The uniform blend stops
///    once it holds back more than that: its count so far is a lower bound of its end's;
/// 3. else a second pass with graded knots from the uniform fit, kept when decisive
///    ([`auto_graded_is_decisive`]) against the uniform count and its fitted boundary is as
///    close to the smooth boundary as the uniform fit's ([`auto_graded_keeps_the_boundary`],
///    on [`Passes::boundary_rms`]): against the lower bound first, and only when that does
///    not decide is the uniform blend run to its end, so the choice and the output are those
///    of the full passes.
///
/// With `--fit energy` (no blend) a pass holds back the elements its least-squares fit's full
/// step leaves uncertified ([`Passes::held`]): the energy starts from a shortened or damped
/// step there, so uniform knots that leave many of them (the 3D annular sector: 96 of 144)
/// are weighed against graded knots as the blend's counts are.
///
/// These passes fit without [`crate::fit::FitWeights::extraordinary_midpoint`]. Where the
/// pass kept holds back more than [`super::spline::AUTO_MAX_HELD_BACK`] of the elements and
/// the weight raises some element's midpoints ([`Passes::reweighted`]), it is fitted once
/// more with the weight, on its knots and from its fit, and the refit kept by
/// [`extraordinary_refit_is_kept`]; the setup ends with the weights of the pass kept.
///
/// Then, with `--demote-uncertified` or by default where the pass kept holds back too many
/// ([`demotes_by_default`]), the pass kept is redone with the elements whose initial map is
/// not certified Q2 from the start ([`demote_before_fit_if_fewer`]; by default kept only
/// where it keeps the boundary). Where no demoted pass is kept, and the pass kept still holds
/// back too many, the elements at sharp turns of interior grid lines are made Q2 in a redo
/// ([`interior_kinks_if_fewer`]): after the demotion, so that the demotion's results (and the
/// ranks' agreement with the serial run under `--demote-uncertified`) stand wherever it acts.
pub(crate) fn spline_passes<P: Passes>(
    p: &mut P,
    job: &Job,
    setup: &mut SplineSetup,
    clock: &mut Clock,
) -> Result<P::Pass, CurveError> {
    let kept = weighted_passes(p, job, setup, clock)?;
    match demote_before_fit_if_fewer(p, job, setup, clock, kept)? {
        Demotion::Redone(pass) => Ok(pass),
        Demotion::Kept(kept) => interior_kinks_if_fewer(p, job, setup, clock, kept),
    }
}

/// What [`demote_before_fit_if_fewer`] returns: the redone pass with the demoted elements Q2,
/// or the pass it was given.
enum Demotion<T> {
    Redone(T),
    Kept(T),
}

/// The pass kept (`kept`, on `setup`'s knots and weights), or, where its blend holds back more
/// than [`super::spline::AUTO_MAX_HELD_BACK`] of the elements and some element of the whole
/// mesh is at a sharp turn of an interior grid line ([`crate::spline::kinks::interior_kink_elements`],
/// counted by [`Passes::interior_kinks`]), the same pass with those elements Q2, started from
/// `kept`'s fit, when its blend holds back strictly fewer elements of the whole mesh and its
/// output boundary stays close to `kept`'s fitted boundary
/// ([`interior_kinks_keep_the_boundary`]). `setup` ends with the spaces of the pass returned.
///
/// Why: a C¹ spline cannot follow a grid line that turns by tens of degrees at one vertex. On
/// hsphere8's cubed-sphere shell the lines crossing the block arcs turn by 48° and 37° one and
/// two edges from the valence-3 line; the fit slides those elements' midpoints within each
/// shell layer by a tenth of their shortest edge, and the blend holds back 72 of 648 elements
/// (11.1 %) and leaves the mesh's min scaled Jacobian at 0.807 (input 0.864). With those
/// elements Q2 it holds back none and keeps 0.864. Only where too many are held back: on
/// sphere_r6 (8.4 % held back) the same elements Q2 hold back 6.5 % but raise its 99th
/// percentile facet angle above the straight elevation's + 1° (57.6° against 56.3°).
fn interior_kinks_if_fewer<P: Passes>(
    p: &mut P,
    job: &Job,
    setup: &mut SplineSetup,
    clock: &mut Clock,
    kept: P::Pass,
) -> Result<P::Pass, CurveError> {
    let options = job.options;
    let held = match P::held(&kept) {
        Ok(held) if auto_holds_back_too_many(held, p.elements()) => held,
        _ => return Ok(kept),
    };
    if options.geometry != super::Geometry::SplineFitted
        || options.energy.is_some()
        || p.interior_kinks(job, setup) == 0
    {
        return Ok(kept);
    }
    let knots = options.with_knots(setup.knot_intervals);
    let job = Job {
        options: &knots,
        ..*job
    };
    let before = p.output_boundary_shift(&job, setup, clock, &kept, &kept, misfit::SLIDE_REACH);
    setup.interior_kinks_q2 = true;
    // Given up once it holds back as many as the pass kept: that one stays.
    let redone = p.run(&job, setup, clock, Some(&kept), Some(held - 1), None)?;
    if matches!(P::held(&redone), Ok(fewer) if fewer < held) {
        let after =
            p.output_boundary_shift(&job, setup, clock, &redone, &kept, misfit::SLIDE_REACH);
        setup.interior_kinks_q2 = false;
        let fitted = p.boundary_rms(&job, setup, clock, &kept);
        if interior_kinks_keep_the_boundary(after, before, fitted) {
            setup.interior_kinks_q2 = true;
            return Ok(redone);
        }
    }
    setup.interior_kinks_q2 = false;
    Ok(kept)
}

/// The knot passes without the extraordinary midpoint weight, then its refit of the pass kept
/// ([`spline_passes`] before the demotion).
fn weighted_passes<P: Passes>(
    p: &mut P,
    job: &Job,
    setup: &mut SplineSetup,
    clock: &mut Clock,
) -> Result<P::Pass, CurveError> {
    // The knots are chosen without the extraordinary midpoint weight: it keeps more of the
    // uniform spline on O-grids, whose graded knots `auto` would then lose (see
    // `extraordinary_refit_is_kept`).
    let weight = job.options.fit.weights.extraordinary_midpoint;
    let mut off = job.options.clone();
    off.fit.weights.extraordinary_midpoint = 0.0;
    setup.fit_params.weights.extraordinary_midpoint = 0.0;
    let kept = knot_passes(
        p,
        &Job {
            options: &off,
            ..*job
        },
        setup,
        clock,
    )?;
    let n = p.elements();
    let least_squares = job.options.geometry == super::Geometry::SplineFitted
        && job.options.energy.is_none()
        && weight > 0.0;
    let held = match P::held(&kept) {
        Ok(held) if least_squares && auto_holds_back_too_many(held, n) => held,
        _ => return Ok(kept),
    };
    setup.fit_params.weights.extraordinary_midpoint = weight;
    if p.reweighted(job, setup) == 0 {
        setup.fit_params.weights.extraordinary_midpoint = 0.0;
        return Ok(kept);
    }
    let kept_options = job.options.with_knots(setup.knot_intervals);
    let kept_job = Job {
        options: &kept_options,
        ..*job
    };
    // Given up once it holds back more than it may to be kept.
    let most = extraordinary_refit_most(held, n);
    let previous = p.warm_start().then_some(&kept);
    let refit = p.run(&kept_job, setup, clock, previous, Some(most), None)?;
    match P::held(&refit) {
        Ok(h) if extraordinary_refit_is_kept(h, held, n) => Ok(refit),
        _ => {
            setup.fit_params.weights.extraordinary_midpoint = 0.0;
            Ok(kept)
        }
    }
}

/// The pass kept (`kept`, on `setup`'s knots), or, with `--demote-uncertified` (without it,
/// with the IGA method where [`demotes_by_default`] on the whole mesh's count), where its
/// blend holds back elements and the initial spline map is not certified valid on some
/// element of the whole mesh, the same pass with those elements demoted to Q2 *before* the
/// fit ([`Passes::demotion`]: the demotion rounds of `--fit energy`), started from `kept`'s
/// fit, when its blend holds back strictly fewer elements of the whole mesh (a tie keeps the
/// pass as it was: its output is unchanged). Run by default (without the option), the redone
/// pass is kept only where its output boundary also stays as close to `kept`'s fitted
/// boundary as `kept`'s own output ([`Passes::output_boundary_shift`],
/// [`demotion_keeps_the_boundary`]), and the serial job does not run it where the demoted
/// elements' sides alone would be refused ([`Passes::demoted_boundary_shift`],
/// [`demotion_is_refused_beforehand`]). Every process
/// decides on the whole mesh's counts and distances, so alike and as the serial job.
///
/// Why: the blend's straight end is certified, but it holds back every element around an
/// area where the spline map cannot be valid whatever the fit (its initial map is
/// uncertified there, and the held-back factors spread to every Bernstein point those
/// elements share): on spheremesh01 84 of 113 elements held back, 40 with the area's
/// elements Q2 from the start. Not always: on sphere_r6 the Q2 area holds back more (966
/// against 688), hence the comparison. Both outputs are certified, so the one kept is. The
/// boundary: a demoted element's boundary is the target map's, no longer the least-squares
/// spline's; on the O-grid torus and cylinder of `scripts/fidelity_shapes.py` (level 2) the
/// redo holds back none where the pass kept holds back 1,024 and 800 of 1,536, but moves
/// their boundary off the fitted one (RMS 2.9e-5 and 6.7e-5 of the diagonal against 0 and
/// 1.7e-5) and further from the exact surface (torus: 4.1× → 11.6× Gmsh-with-CAD's RMS);
/// on naca0012_omg and spheremesh01 the redone output's boundary is the pass kept's (1.00×).
fn demote_before_fit_if_fewer<P: Passes>(
    p: &mut P,
    job: &Job,
    setup: &SplineSetup,
    clock: &mut Clock,
    kept: P::Pass,
) -> Result<Demotion<P::Pass>, CurveError> {
    let options = job.options;
    let Ok(held) = P::held(&kept) else {
        return Ok(Demotion::Kept(kept));
    };
    let asked = options.demote_uncertified
        || (matches!(options.method, super::Method::Iga) && demotes_by_default(held, p.elements()));
    if held == 0
        || !asked
        || options.geometry != super::Geometry::SplineFitted
        || options.energy.is_some()
    {
        return Ok(Demotion::Kept(kept));
    }
    // The pass kept's knots.
    let knots = options.with_knots(setup.knot_intervals);
    let job = Job {
        options: &knots,
        ..*job
    };
    let Some(demote) = p.demotion(&job, setup, clock) else {
        return Ok(Demotion::Kept(kept));
    };
    // By default the redo is judged against the pass kept's own output, and not run where its
    // demoted sides alone already move the boundary further.
    let guard = (!options.demote_uncertified)
        .then(|| p.output_boundary_shift(&job, setup, clock, &kept, &kept, 0.0));
    if let Some(before) = guard
        && demotion_is_refused_beforehand(
            p.demoted_boundary_shift(&job, setup, clock, &kept, &demote),
            before,
        )
    {
        return Ok(Demotion::Kept(kept));
    }
    // Given up once it holds back as many as the pass kept: that one stays.
    let redone = p.run(
        &job,
        setup,
        clock,
        Some(&kept),
        Some(held - 1),
        Some(&demote),
    )?;
    let fewer = matches!(P::held(&redone), Ok(fewer) if fewer < held);
    if !fewer {
        return Ok(Demotion::Kept(kept));
    }
    let Some(before) = guard else {
        return Ok(Demotion::Redone(redone));
    };
    let after = p.output_boundary_shift(&job, setup, clock, &redone, &kept, 0.0);
    Ok(if demotion_keeps_the_boundary(after, before) {
        Demotion::Redone(redone)
    } else {
        Demotion::Kept(kept)
    })
}

/// The knot passes of [`spline_passes`], on the job's weights as given.
fn knot_passes<P: Passes>(
    p: &mut P,
    job: &Job,
    setup: &mut SplineSetup,
    clock: &mut Clock,
) -> Result<P::Pass, CurveError> {
    let options = job.options;
    let weights = options.fit.weights;
    let (uniform, graded) = (
        options.with_knots(KnotIntervals::Uniform),
        options.with_knots(KnotIntervals::Graded),
    );
    let uniform_job = Job {
        options: &uniform,
        ..*job
    };
    let graded_job = Job {
        options: &graded,
        ..*job
    };
    // The features, kinks and targets of the setup do not depend on the knots: graded ones
    // are put in its place.
    let graded_pass = |p: &mut P, setup: &mut SplineSetup, clock: &mut Clock, survey| {
        let knots = p.knots(setup, clock, survey, &graded.knots);
        setup.set_knots(KnotIntervals::Graded, knots, weights);
        p.run(&graded_job, setup, clock, None, None, None)
    };
    match options.knots.intervals {
        KnotIntervals::Uniform => return p.run(&uniform_job, setup, clock, None, None, None),
        KnotIntervals::Graded => {
            let survey = p.survey(setup, clock);
            return graded_pass(p, setup, clock, survey);
        }
        KnotIntervals::Auto => {}
    }
    let survey = p.survey(setup, clock);
    if survey.graded_share() >= AUTO_GRADED_SHARE {
        return graded_pass(p, setup, clock, survey);
    }
    // Graded knots all but uniform: a second pass would not hold back half as many.
    let near_uniform = survey.max_abs_log_ratio() < AUTO_MIN_LOG_RATIO;
    // Not held through the uniform pass: the fit's peak would carry it (+0.56 GB on the 1M
    // cylinder); the rare second pass measures the surfaces again.
    drop(survey);
    let n = p.elements();
    let most = (super::spline::AUTO_MAX_HELD_BACK * n as f64).floor() as usize;
    let first = p.run(
        &uniform_job,
        setup,
        clock,
        None,
        (!near_uniform).then_some(most),
        None,
    )?;
    match P::held(&first) {
        Ok(held) if near_uniform || !auto_holds_back_too_many(held, n) => return Ok(first),
        _ => {}
    }
    let survey = p.survey(setup, clock);
    let knots = p.knots(setup, clock, survey, &graded.knots);
    let uniform_knots = setup.set_knots(KnotIntervals::Graded, knots, weights);
    setup.knot_passes = 2;
    // The graded fit starts from the uniform one where the two spaces share control points
    // (every entity's but the knot splits'): fewer CG iterations than from C0.
    let previous = p.warm_start().then_some(&first);
    let second = p.run(&graded_job, setup, clock, previous, None, None)?;
    let graded_held = P::held(&second).expect("an unbounded pass runs to its end");
    // Measured only where the counts alone would keep graded knots, the uniform fit's once
    // (the target map does not depend on the knots).
    let mut uniform_boundary = None;
    let mut keeps_boundary =
        |p: &mut P, setup: &SplineSetup, clock: &mut Clock, first: &P::Pass| {
            let uniform =
                *uniform_boundary.get_or_insert_with(|| p.boundary_rms(job, setup, clock, first));
            auto_graded_keeps_the_boundary(p.boundary_rms(job, setup, clock, &second), uniform)
        };
    let first = match P::held(&first) {
        Ok(_) => first,
        // Decisive against a lower bound of the uniform count: decisive against the count.
        Err(at_least)
            if auto_graded_is_decisive(graded_held, at_least)
                && keeps_boundary(p, setup, clock, &first) =>
        {
            return Ok(second);
        }
        Err(_) => p.finish(&uniform_job, setup, clock, first)?,
    };
    let uniform_held = P::held(&first).expect("a finished pass ran to its end");
    if auto_graded_is_decisive(graded_held, uniform_held) && keeps_boundary(p, setup, clock, &first)
    {
        return Ok(second);
    }
    setup.set_knots(KnotIntervals::Uniform, uniform_knots, weights);
    Ok(first)
}
