//! The spline geometry's stages: the spline space ([`Stage::Spline`]), the least-squares fit
//! ([`Stage::Fit`]), its certification ([`Stage::Validity`]) and, with `--fit energy`, the
//! energy minimisation ([`Stage::Energy`]).
//!
//! Input: the [`Job`] (mesh, topology, options, executor). Output: a [`SplineOutcome`], whose
//! space (with the certified blend's factors, when there are any) is certified valid on every
//! element; or an error, and nothing is sampled.
//!
//! Three paths, by geometry and fit:
//! - least squares ([`least_squares_pass`], shared with the job under mpirun): fit once,
//!   then the certified blend between the straight elevation and the fitted map
//!   ([`crate::validity::blend`]);
//! - `--fit energy` ([`fit_with_energy`]): fit, certified line search, energy; where the initial
//!   map is not certified, those elements are demoted to Q2 and the fit repeated, and when that
//!   does not give a certified start the least-squares fit is blended instead;
//! - the unfitted spline map ([`certify_initial`]): certified as it is, or refused.

use super::clock::Clock;
use super::misfit;
use super::share::{
    Blend, LeastSquares, WholeMesh, blend_within, finish_blend, fit_demoting_misfits,
    least_squares_pass,
};
use super::{CurveError, Geometry, Job};
use crate::energy::{EnergyError, EnergyInfo, EnergyParams};
use crate::fit::rotated::{Coupling, OnK};
use crate::fit::{
    CoupledRun, FitInfo, FitParams, FitSolve, FitSolver, FitTargets, NormalMatrix, SmoothTargets,
    Summing, TargetMap, fit_with_solver,
};
use crate::mesh::features::Features;
use crate::mesh::periodic::PeriodicPair;
use crate::mesh::{LinearMesh, Topology};
use crate::progress::{Progress, Stage};
use crate::solve::{CgError, CgInfo, CgParams};
use crate::spline::seam::{self, Glued, SeamView};
use crate::spline::{
    ElementRows, KnotSurfaceInfo, KnotWeights, Knots, Q2Reason, SplineSpace, kinks,
};
use crate::validity::blend::{Alone, BlendInfo, Blended, NetCache};
use crate::validity::certificate::{
    MAX_DEMOTION_ROUNDS, certify_mesh, demote_with_rings, uncertified,
};
use crate::validity::line_search::{CertifiedStep, acceptance_thresholds, certified_step};
use crate::validity::{DetBounds, LineSearchInfo, ValidityError};
use std::collections::HashMap;

/// What the spline space and the fit are built from.
pub(crate) struct SplineSetup {
    /// Sharp features found (`None` when there are none).
    pub features: Option<Features>,
    /// Elements made Q2 by feature creases and by kinks of boundary grid lines.
    crease: Vec<bool>,
    kinks: kinks::Kinks,
    /// Elements at sharp turns of interior grid lines ([`kinks::interior_kink_elements`]; empty
    /// where there are none to look for), made Q2 where [`SplineSetup::interior_kinks_q2`] is
    /// set (the passes' redo, `pipeline::passes::interior_kinks_if_fewer`).
    interior_kinks: Vec<bool>,
    /// Whether the spaces built make [`SplineSetup::interior_kinks`]' elements Q2.
    pub(crate) interior_kinks_q2: bool,
    /// The fit's parameters, with the features it keeps.
    pub(crate) fit_params: FitParams,
    /// The fit's smooth targets, shared by the fit and the blend's target map.
    pub(crate) targets: Option<SmoothTargets>,
    /// The blend's middle state carries the smooth boundary whatever the fit's own targets
    /// (with the paper's chord targets it is built with the default reconstruction).
    blend_targets: Option<SmoothTargets>,
    /// Knot weights of the spline space (`None`: uniform knots), fixed for all demotions.
    knot_weights: Option<Vec<KnotWeights>>,
    /// Elements made Q2 where knot surfaces are split (empty: none).
    knot_split: Vec<bool>,
    /// Figures of the knot surfaces.
    pub(crate) knot_info: KnotSurfaceInfo,
    /// The knot intervals used.
    pub(crate) knot_intervals: crate::spline::KnotIntervals,
    /// Spline passes run to choose the knots (`--knot-intervals auto`: 1 or 2).
    pub(crate) knot_passes: usize,
    /// Periodic seams identified in the spline space (`--periodic`,
    /// [`crate::spline::seam`]): the space is built on this glued mesh.
    pub(crate) seams: Option<Glued>,
    /// Why a periodic pair is not identified in the spline space (it is then made an exact
    /// image after sampling only, C⁰); `None` when every pair is, or there are none.
    pub(crate) seam_c0: std::sync::Mutex<Option<String>>,
    /// Putting a glued space back on the input failed: later spaces are built unglued.
    seams_failed: std::sync::atomic::AtomicBool,
    /// The input's topology with the glued seams interior ([`seam::interior_view`]): the
    /// features, kinks, smooth targets, fit, misfit checks and blend target map are built on
    /// it (`None`: on the input's). Kept when a later space cannot be put back on the input,
    /// since the targets were built on it: the seam is then fitted like the interior on both
    /// sides and made exact after sampling.
    view: Option<SeamView>,
}

impl SplineSetup {
    /// The setup of `job` with its periodic seams glued already (the job's head,
    /// [`super::head::glue_seams`]), so that everything fitted to the boundary sees them as
    /// interior, and why some pair stays apart; on a rank's part of a distributed mesh,
    /// `share` makes its smooth targets the whole mesh's ([`crate::fit::InheritShare`]).
    pub(crate) fn with_seams(
        job: &Job,
        (seams, seam_c0): (Option<Glued>, Option<String>),
        share: Option<&dyn crate::fit::InheritShare>,
    ) -> Result<Self, CurveError> {
        let view = seams
            .as_ref()
            .map(|g| seam::interior_view(job.mesh, job.topo, g));
        let (options, mesh) = (job.options, job.mesh);
        let topo = view.as_ref().map_or(job.topo, |v| &v.topo);
        let features = Some(options.features.detect(mesh, topo)?).filter(|f| !f.is_empty());
        let used = features.as_ref().filter(|_| !options.features.ignore);
        let crease = used.map_or_else(Vec::new, |f| {
            let mut c = f.crease_elements(topo);
            let along = f.curved_feature_elements(mesh, topo);
            c.iter_mut().zip(&along).for_each(|(c, &a)| *c |= a);
            c
        });
        let mut fit_params = FitParams {
            features: used.cloned().map(std::sync::Arc::new),
            weights: options
                .fit
                .weights
                .for_knots(options.knots.intervals == crate::spline::KnotIntervals::Graded),
            ..options.fit.clone()
        };
        // With the smooth fit, elements at kinks of the boundary grid lines start as Q2;
        // vertices on sharp features are left to the feature handling.
        let kinks = match options.fit.targets {
            FitTargets::Smooth(p) if options.geometry == Geometry::SplineFitted => {
                let mut exclude = kinks::feature_vertices(mesh, topo, p.feature_angle_deg);
                if let Some(f) = used {
                    for (x, &m) in exclude.iter_mut().zip(&f.vertex_mask) {
                        *x |= m;
                    }
                }
                // A wall's fan is cut at a seam (it goes on on the other side): no kink.
                if let Some(v) = &view {
                    for (x, &m) in exclude.iter_mut().zip(&v.seam_ends) {
                        *x |= m;
                    }
                }
                kinks::detect(mesh, topo, p.kink_angle_deg, &exclude)
            }
            _ => kinks::Kinks::default(),
        };
        // And elements at sharp turns of the interior grid lines.
        let interior_kinks = match options.fit.targets {
            FitTargets::Smooth(p) if options.geometry == Geometry::SplineFitted => {
                kinks::interior_kink_elements(mesh, topo, p.interior_kink_angle_deg)
            }
            _ => Vec::new(),
        };
        let fitted = options.geometry == Geometry::SplineFitted;
        // The walls' models at a seam are fitted over both sides.
        let partners = view.as_ref().map_or((&[][..], &[][..]), |v| {
            (&v.wall_partners[..], &v.seam_links[..])
        });
        let targets = if fitted {
            crate::fit::smooth_targets_shared(mesh, topo, &fit_params, share, partners)
        } else {
            None
        };
        // The fit weighs thin rims' corners as their models classify them (across seams too).
        if let (Some(t), Some(f)) = (&targets, fit_params.features.as_mut()) {
            std::sync::Arc::make_mut(f).thin_rim = t.thin_rim_mask();
        }
        let blend_targets = match (&targets, fitted) {
            (None, true) => crate::fit::smooth_targets_shared(
                mesh,
                topo,
                &FitParams {
                    targets: FitTargets::Smooth(Default::default()),
                    ..fit_params.clone()
                },
                share,
                partners,
            ),
            _ => None,
        };
        // With glued seams the knot surfaces run across them (one ratio on both sides).
        let knots = match &seams {
            Some(g) => seam::knot_weights(mesh, g, &options.knots),
            None => SplineSpace::knot_weights(mesh, job.topo, &options.knots),
        };
        Ok(SplineSetup {
            features,
            crease,
            kinks,
            interior_kinks,
            interior_kinks_q2: false,
            fit_params,
            targets,
            blend_targets,
            knot_weights: knots.weights,
            knot_split: knots.split,
            knot_info: knots.info,
            knot_intervals: options.knots.intervals,
            knot_passes: 1,
            seams,
            seam_c0: std::sync::Mutex::new(seam_c0),
            seams_failed: std::sync::atomic::AtomicBool::new(false),
            view,
        })
    }

    /// Puts `knots` of `intervals` in place of the setup's knots and returns those (the
    /// features, kinks and targets do not depend on the knots). With glued seams, `knots`
    /// must be measured on the glued mesh (the passes' survey, [`super::passes::Passes::survey`]).
    pub(crate) fn set_knots(
        &mut self,
        intervals: crate::spline::KnotIntervals,
        knots: Knots,
        weights: crate::fit::FitWeights,
    ) -> Knots {
        // The fit's weights depend on the knots too (`FitWeights::for_knots`).
        self.fit_params.weights =
            weights.for_knots(intervals == crate::spline::KnotIntervals::Graded);
        let old = Knots {
            weights: self.knot_weights.take(),
            split: std::mem::take(&mut self.knot_split),
            info: self.knot_info,
        };
        self.knot_weights = knots.weights;
        self.knot_split = knots.split;
        self.knot_info = knots.info;
        self.knot_intervals = intervals;
        old
    }

    /// The rows of the input's boundary facets of [`SplineSetup::topo`]'s (`None`: all).
    pub(crate) fn boundary_rows(&self) -> Option<&[u32]> {
        self.view.as_ref().map(|v| &v.boundary_rows[..])
    }

    /// The topology the boundary is fitted on: the input's with the glued seams interior.
    pub(crate) fn topo<'a>(&'a self, job: &Job<'a>) -> &'a Topology {
        self.view.as_ref().map_or(job.topo, |v| &v.topo)
    }

    /// The seams as glued for the spline space, unless identifying them failed.
    pub(crate) fn live_seams(&self) -> Option<&Glued> {
        let failed = self.seams_failed.load(std::sync::atomic::Ordering::Relaxed);
        self.seams.as_ref().filter(|_| !failed)
    }

    /// The mesh and topology whose entities the blend's factors live on: the glued ones when
    /// the seams are identified (one factor per seam entity, so the blend stays C¹ there).
    pub(crate) fn entity_mesh<'a>(&'a self, job: &Job<'a>) -> (&'a LinearMesh, &'a Topology) {
        match self.live_seams() {
            Some(g) => (&g.mesh, &g.topo),
            None => (job.mesh, job.topo),
        }
    }

    /// `c1` when every periodic pair is identified in the spline space, else `c0`, with why.
    pub(crate) fn seam_continuity(&self) -> (&'static str, Option<String>) {
        let why = self.seam_c0.lock().expect("not poisoned").clone();
        match (self.live_seams(), why) {
            (Some(_), None) => ("c1", None),
            (_, why) => ("c0", why),
        }
    }

    /// Per element of this process's mesh, whether it is at a sharp turn of an interior grid
    /// line ([`kinks::interior_kink_elements`]; empty where there are none to look for).
    pub(crate) fn interior_kinks(&self) -> &[bool] {
        &self.interior_kinks
    }

    /// The features the fit keeps (none with `--ignore-features`).
    pub(crate) fn used_features(&self) -> Option<&Features> {
        self.fit_params.features.as_deref()
    }

    /// The spline space with the Q2 elements of creases, kinks and `demote`.
    pub(crate) fn build(&self, job: &Job, demote: &[bool]) -> SplineSpace {
        self.build_with_misfits(job, demote, &[])
    }

    /// [`SplineSetup::build`] with the boundary misfits of earlier fits (`misfit`) made Q2 too.
    pub(crate) fn build_with_misfits(
        &self,
        job: &Job,
        demote: &[bool],
        misfit: &[bool],
    ) -> SplineSpace {
        let marks = [
            (&self.crease[..], Q2Reason::FeatureCrease),
            (&self.kinks.elements[..], Q2Reason::BoundaryKink),
            (
                if self.interior_kinks_q2 {
                    &self.interior_kinks[..]
                } else {
                    &[]
                },
                Q2Reason::InteriorKink,
            ),
            (demote, Q2Reason::InvalidSplineMap),
            (misfit, Q2Reason::BoundaryMisfit),
            (&self.knot_split[..], Q2Reason::KnotSplit),
        ];
        if let Some(g) = self.live_seams() {
            // Built on the glued mesh, then put back on the input's elements.
            let weights = self.knot_weights.as_deref();
            let mut space = SplineSpace::build_with_knots(&g.mesh, &g.topo, &marks, weights);
            match seam::unwrap(&mut space, job.mesh, job.topo, g) {
                Ok(_) => return space,
                Err(why) => {
                    self.seams_failed
                        .store(true, std::sync::atomic::Ordering::Relaxed);
                    *self.seam_c0.lock().expect("not poisoned") = Some(why);
                }
            }
        }
        if self.seams.is_some() && self.knot_weights.is_some() {
            // The setup's graded knots run across the seams: the sides apart need the
            // input's own knot surfaces (their split elements made Q2 as well).
            let own = SplineSpace::knot_weights(job.mesh, job.topo, &job.options.knots);
            let marks = [&marks[..], &[(&own.split[..], Q2Reason::KnotSplit)]].concat();
            return SplineSpace::build_with_knots(
                job.mesh,
                job.topo,
                &marks,
                own.weights.as_deref(),
            );
        }
        SplineSpace::build_with_knots(job.mesh, job.topo, &marks, self.knot_weights.as_deref())
    }

    /// The target map of the certified blend (its middle state).
    pub(crate) fn target_map<'a>(&'a self, job: &Job<'a>) -> TargetMap<'a> {
        TargetMap {
            mesh: job.mesh,
            topo: self.topo(job),
            smooth: self.targets.as_ref().or(self.blend_targets.as_ref()),
        }
    }
}

/// The periodic pairs among `pairs` glued for the spline space (translations and rotations;
/// the energy minimisation sees rotated points through their frames as the fit does,
/// [`crate::energy`]), and why some pair stays apart (for the report), if one does: the
/// job's rule ([`super::head::glue_seams`]) on the whole mesh.
fn glue_seams(job: &Job, pairs: &[PeriodicPair]) -> (Option<Glued>, Option<String>) {
    super::head::glue_seams(&super::head::OneProcess, pairs, |rotations| {
        seam::glue_share(job.mesh, pairs, None, rotations)
    })
}

/// The certified spline geometry and the report's figures of how it was reached.
pub(super) struct SplineOutcome {
    /// The space and its control points (the fitted map, or the initial one, unfitted).
    pub space: SplineSpace,
    /// The certified blend's factors (least-squares fits): the map to sample is
    /// [`Blended`] of these; `None` samples `space` itself.
    pub blend_factors: Option<Vec<f32>>,
    /// The blend search's nets, for sampling the same blend (taken by the sample stage).
    pub blend_nets: Option<NetCache>,
    pub fit: Option<FitInfo>,
    pub blend: Option<BlendInfo>,
    pub line_search: Option<LineSearchInfo>,
    /// Step of the certified search (see `CurveReport::line_search_alpha`).
    pub alpha: Option<f64>,
    pub invalid_at_full_step: usize,
    pub damped_points: usize,
    pub min_det_bound: Option<f64>,
    pub demoted: usize,
    pub energy: Option<EnergyInfo>,
    pub energy_skipped: Option<String>,
}

impl SplineOutcome {
    /// A blended least-squares fit: the report's search figures are the blend's.
    fn blended(
        space: SplineSpace,
        (factors, nets): (Vec<f32>, NetCache),
        fit: FitInfo,
        blend: BlendInfo,
        demoted: usize,
        energy_skipped: Option<String>,
    ) -> Self {
        SplineOutcome {
            space,
            blend_factors: Some(factors),
            blend_nets: Some(nets),
            fit: Some(fit),
            line_search: None,
            alpha: Some(0.5 * blend.min_factor),
            invalid_at_full_step: blend.invalid_at_full_step,
            damped_points: blend.reduced_points,
            min_det_bound: Some(blend.min_det_lower_bound),
            blend: Some(blend),
            demoted,
            energy: None,
            energy_skipped,
        }
    }
}

/// With `--knot-intervals auto`: the share of the elements the certified blend may hold back
/// with uniform knots before the spline is redone with graded knots.
pub const AUTO_MAX_HELD_BACK: f64 = 0.1;

/// With `--knot-intervals auto`: graded knots are kept when their blend holds back at most
/// this share of the elements uniform knots' holds back.
pub const AUTO_MIN_GAIN: f64 = 0.5;

/// With `--knot-intervals auto`, after the uniform pass: whether its blend, holding back
/// `held` of the mesh's `elements`, holds back too many ([`AUTO_MAX_HELD_BACK`]) for the
/// uniform knots to be kept without trying graded ones.
pub(crate) fn auto_holds_back_too_many(held: usize, elements: usize) -> bool {
    held as f64 > AUTO_MAX_HELD_BACK * elements as f64
}

/// With `--knot-intervals auto`, after both passes: whether graded knots, holding back
/// `graded` elements against uniform knots' `uniform`, are kept ([`AUTO_MIN_GAIN`]).
///
/// Graded knots only where they keep decisively more of the spline: on meshes that are not
/// graded (O-grids of smooth shapes) they hold back nearly as many elements or more (level-2
/// O-grid cylinder: 672 against 800 of 1,536), and the uniform spline's boundary is the better
/// one there (4.7× Gmsh-with-CAD's max error against 26×); on graded meshes they hold back a
/// third or less of uniform knots' (`git show 81dad3f:BENCHMARKS.md`, "Graded knot intervals").
pub(crate) fn auto_graded_is_decisive(graded: usize, uniform: usize) -> bool {
    graded as f64 <= AUTO_MIN_GAIN * uniform as f64
}

/// With `--knot-intervals auto`: graded knots are kept only where their fitted boundary is at
/// most this many times as far from the smooth boundary as uniform knots' (RMS).
pub const AUTO_BOUNDARY_SLACK: f64 = 1.1;

/// With `--knot-intervals auto`: fitted boundaries whose RMS distance from the smooth boundary
/// is at most this share of the bounding-box diagonal count as on it
/// ([`auto_graded_keeps_the_boundary`]).
///
/// Why: where the spline space holds the boundary exactly (2D meshes, whose boundary curves
/// the fit reproduces), both passes' distances are the solver's rounding (example.msh with
/// `--fit-solver cg --cg-tol 1e-10`: graded knots' 2.7e-15 of the diagonal, uniform knots'
/// 3.9e-15), and their ratio changes with the order of the sums (0.68 serially, 1.5 on 2
/// ranks, which then kept uniform knots).
pub const AUTO_BOUNDARY_FLOOR: f64 = 1e-9;

/// With `--knot-intervals auto`, after both passes: whether graded knots, whose fitted map's
/// boundary is `graded` (RMS distance from the target map, [`misfit::boundary_sq_sum`],
/// relative to the bounding-box diagonal) against uniform knots' `uniform`, keep the boundary
/// ([`AUTO_BOUNDARY_SLACK`], both raised to [`AUTO_BOUNDARY_FLOOR`]: below it the two are
/// rounding, not distances); graded knots are kept where they also hold back decisively fewer
/// ([`auto_graded_is_decisive`]).
///
/// Why: holding back fewer elements is not a better output where the spline kept is further
/// off the wall. On the level-2 O-grid cylinder (`scripts/fidelity_shapes.py`) the graded
/// knots of the surfaces crossing the wall come from the cells inside, not from the wall's
/// uniform spacing: graded knots hold back 352 of 1,536 elements against uniform knots' 800,
/// but their fitted boundary is 1.33× as far from the smooth boundary (0.0194 against 0.0146
/// of the chords' distance), and the output's RMS distance from the exact cylinder 16.9×
/// Gmsh-with-CAD's against 3.6×. On the graded grids where `auto` runs both passes (O- and
/// C-grids, sphere_r6, beam-sphere, example.msh) graded knots' fitted boundary is as close
/// or closer (0.12–1.0× uniform knots').
pub(crate) fn auto_graded_keeps_the_boundary(graded: f64, uniform: f64) -> bool {
    graded.max(AUTO_BOUNDARY_FLOOR) <= AUTO_BOUNDARY_SLACK * uniform.max(AUTO_BOUNDARY_FLOOR)
}

/// The pass kept by the knot choice, refitted with the extraordinary midpoint weight
/// ([`crate::fit::FitWeights::extraordinary_midpoint`]; see
/// [`super::passes::spline_passes`]): whether the refit, holding back `refit` of the mesh's
/// `elements` against the pass's `held`, is kept: where it holds back at most
/// [`AUTO_MAX_HELD_BACK`] of the elements, or at most [`AUTO_MIN_GAIN`] as many as the pass
/// (the rules of the knot choice: the spline kept, or decisively more of it).
///
/// Why not wherever it holds back fewer: the weight keeps the spline near extraordinary
/// vertices and edges, but where the spline kept is not valid enough to be kept anyway, the
/// elements it keeps lie further from the wall than the blend's (the level-2 O-grid cylinder,
/// `scripts/fidelity_shapes.py`: 800 → 672 of 1,536 held back, max boundary error 4.68× →
/// 5.99× Gmsh-with-CAD's). Kept on hsphere8 (24 → 11 %), sphere_r6 (15 → 8 %); the knots are
/// chosen without the weight, which kept uniform knots' spline on the level-2 disk and
/// beam-sphere and so cost them their graded knots (disk: max error 1.02× → 5.45×).
pub(crate) fn extraordinary_refit_is_kept(refit: usize, held: usize, elements: usize) -> bool {
    refit < held
        && (!auto_holds_back_too_many(refit, elements) || auto_graded_is_decisive(refit, held))
}

/// The most elements a refit of [`extraordinary_refit_is_kept`] may hold back to be kept,
/// where the pass holds back `held` > [`AUTO_MAX_HELD_BACK`] of the mesh's `elements`.
pub(crate) fn extraordinary_refit_most(held: usize, elements: usize) -> usize {
    let most = (AUTO_MAX_HELD_BACK * elements as f64)
        .floor()
        .max((AUTO_MIN_GAIN * held as f64).floor()) as usize;
    most.min(held.saturating_sub(1))
}

/// Without `--demote-uncertified`: the demotion redo is kept only where its output boundary is
/// at most this many times as far from the pass kept's fitted boundary as the pass kept's own
/// output ([`demotion_keeps_the_boundary`]).
pub const DEMOTION_BOUNDARY_SLACK: f64 = 1.1;

/// Without `--demote-uncertified`, after the demotion redo: whether the redone pass, whose
/// output boundary is `redone` (RMS distance from the pass kept's fitted boundary relative to
/// the bounding-box diagonal, [`super::passes::Passes::output_boundary_shift`]) against the
/// pass kept's own output's `kept`, keeps the boundary ([`DEMOTION_BOUNDARY_SLACK`], both
/// raised to [`AUTO_BOUNDARY_FLOOR`]).
///
/// Why: the demoted elements' boundary is the target map's (Q2), no longer the least-squares
/// spline's, and the spline fitted across many elements' targets can be much the closer to the
/// smooth surface. On the level-2 O-grid torus (`scripts/fidelity_shapes.py`, 1,536 hexes) the
/// uniform pass holds back 1,024 elements, but only halfway to the target map (factor 1.5),
/// for the quality guard, not validity; the initial map is uncertified around the inner
/// equator and the demotion rounds spread to 1,408 elements, every boundary side among them:
/// 0 held back, but the boundary's RMS distance from the exact torus went from 4.1× to 11.6×
/// Gmsh-with-CAD's (max 16.0×). Held-back counts alone do not see it: the demoted boundary
/// lies on the target map.
pub(crate) fn demotion_keeps_the_boundary(redone: f64, kept: f64) -> bool {
    redone.max(AUTO_BOUNDARY_FLOOR) <= DEMOTION_BOUNDARY_SLACK * kept.max(AUTO_BOUNDARY_FLOOR)
}

/// After the interior kinks' redo (`pipeline::passes::interior_kinks_if_fewer`): whether it
/// keeps the boundary. Its output boundary's RMS distance from the pass kept's fitted boundary
/// (`redone`) may exceed the pass kept's own output's (`kept`, as
/// [`demotion_keeps_the_boundary`]) by at most [`INTERIOR_KINK_BOUNDARY_SHARE`] of the pass
/// kept's fitted boundary's RMS distance from the smooth boundary (`fitted`): a move within
/// how far the least-squares spline itself is from the surface. Why not the demotion's rule
/// alone: where the pass kept holds back no boundary side (hsphere8) its own output's shift is
/// 0, and the redo's Q2 elements, whose boundary sides are their smooth targets, moved the
/// boundary by 1.02e-6 of the diagonal against the fit's 1.30e-6 from the smooth boundary
/// (its boundary vertices' largest distance from the input's, 4.53e-5, unchanged).
pub(crate) fn interior_kinks_keep_the_boundary(redone: f64, kept: f64, fitted: f64) -> bool {
    demotion_keeps_the_boundary(redone, kept)
        || redone <= kept + INTERIOR_KINK_BOUNDARY_SHARE * fitted
}

/// Share of the pass kept's fitted boundary distance from the smooth boundary by which the
/// interior kinks' redo may move the output boundary ([`interior_kinks_keep_the_boundary`]).
pub(crate) const INTERIOR_KINK_BOUNDARY_SHARE: f64 = 1.0;

/// Without `--demote-uncertified`, before the demotion redo: whether it is refused without
/// running it, where `demoted` (the target map's boundary against the pass kept's fitted
/// boundary over the demoted elements' sides, [`super::passes::Passes::demoted_boundary_shift`])
/// already fails [`demotion_keeps_the_boundary`] against the pass kept's own output's `kept`.
///
/// Why: the redo's output on a demoted element's boundary is the target map wherever its
/// blend does not hold that boundary back below the target map (a Q2 element's boundary
/// Bernstein points are its targets; the blend between target and fit leaves them there), and
/// its other sides add to the sum: its output boundary shift is then at least `demoted`, and
/// the guard would refuse it. Below the target map the blend moves towards the straight
/// chords, further from the fit. Measured on the four meshes the redo runs on by default:
/// on the level-2 O-grid torus and cylinder the demoted sides' part of the redone output's
/// shift is `demoted` to seven digits (2.867809e-5 and 6.732913e-5 of the diagonal, against
/// the pass kept's 0 and 1.686e-5: both refused beforehand), on spheremesh01 as well
/// (3.700957e-2 against 3.871e-2: run, and kept); on naca0012_omg the redo holds back demoted
/// elements and their part is larger (1.34e-4 against `demoted`'s 3.0e-5; the pass kept's
/// 1.725e-4: run, and kept). The torus saves its second fit (the demotion spread to 1,408
/// of 1,536 elements, every boundary side among them).
pub(crate) fn demotion_is_refused_beforehand(demoted: f64, kept: f64) -> bool {
    !demotion_keeps_the_boundary(demoted, kept)
}

/// Without `--demote-uncertified`, the demotion redo runs by default only on meshes of at most
/// this many elements ([`demotes_by_default`]).
pub const DEFAULT_DEMOTION_MAX_ELEMENTS: usize = 5_000;

/// Without `--demote-uncertified`: whether the pass kept, holding back `held` of the mesh's
/// `elements`, is redone with its uncertified elements Q2 before the fit
/// ([`super::passes::spline_passes`]): where it holds back more than [`AUTO_MAX_HELD_BACK`]
/// of the elements, on meshes of at most [`DEFAULT_DEMOTION_MAX_ELEMENTS`].
///
/// Why: on every real mesh whose initial spline map is uncertified somewhere the demoted pass
/// holds back fewer (naca0012_omg 48 → 38 of 450, spheremesh01 84 → 40 of 113,
/// n0012_113-33 226 → 144 of 3,584, NACA4412_2.msh 1,472 → 1,260 of 14,336), but the redo
/// is a whole second pass: only where the spline kept falls short of the target, and not on
/// large meshes, where it costs 1.8× the job (NACA4412_2.msh, 14,336 hexes); the option asks
/// for it there. Meshes whose initial map is certified everywhere pay one certificate of it.
pub(crate) fn demotes_by_default(held: usize, elements: usize) -> bool {
    elements <= DEFAULT_DEMOTION_MAX_ELEMENTS && auto_holds_back_too_many(held, elements)
}

/// The spline geometry's stages (the job's geometry is not [`Geometry::Straight`]); the
/// periodic pairs among `periodic` are identified in the spline space where they can be.
///
/// `--knot-intervals auto` decides in one spline pass (space, fit, certified blend) where it
/// can:
/// 1. the graded knot surfaces are measured first (no fit): where at least
///    [`crate::spline::AUTO_GRADED_SHARE`] of the interior facets lie on consistently graded
///    surfaces ([`KnotSurfaceInfo::graded_share`]: a boundary-layer grid, which a C¹ map with
///    uniform knots cannot follow), the spline is run once, with graded knots;
/// 2. otherwise once with uniform knots, kept where the blend holds back at most
///    [`AUTO_MAX_HELD_BACK`] of the elements;
/// 3. otherwise a second pass with graded knots, kept when its blend holds back at most
///    [`AUTO_MIN_GAIN`] as many elements and its fitted boundary is as close to the smooth
///    boundary ([`auto_graded_keeps_the_boundary`]; the one case with two passes); not where no
///    interior facet's measured |ln ratio| reaches [`crate::spline::AUTO_MIN_LOG_RATIO`]
///    (graded knots all but uniform: they do not hold back half as many).
///
/// The uniform pass's blend stops as soon as it holds back more than
/// [`AUTO_MAX_HELD_BACK`] of the elements
/// ([`crate::validity::blend::blend_search_at_most`]: its count so far is a lower bound of
/// the final one). Graded knots holding back at most [`AUTO_MIN_GAIN`] of
/// that bound are then kept at once; otherwise the uniform blend is run to its end and the
/// rule applied to its count, so the choice and the output are those of the full passes.
/// The passes and the choice are [`super::passes::spline_passes`], which the job under
/// mpirun runs too.
///
/// Both passes share the setup (features, kinks, smooth targets: they do not depend on the
/// knots); the setup names the knots used and the passes run (`knot_passes`). With glued
/// periodic seams the knot surfaces are surveyed on the glued mesh ([`seam::knot_survey`]),
/// for the choice and the graded knots alike.
pub(super) fn curve_spline(
    job: &Job,
    clock: &mut Clock,
    periodic: &[PeriodicPair],
) -> Result<(SplineSetup, SplineOutcome), CurveError> {
    let seams = clock.run(Stage::Spline, || glue_seams(job, periodic));
    let mut whole = Whole {
        job,
        warm_start: periodic.is_empty(),
    };
    let (setup, pass) = super::head::spline_job(&mut whole, job, clock, seams, None)?;
    match pass {
        First::Done(outcome) => Ok((setup, outcome)),
        First::Exceeded(_) => unreachable!("the pass kept ran to its end"),
    }
}

/// The elements `--demote-uncertified` makes Q2 before the fit ([`demotion_marks`]).
pub(crate) struct Demoted {
    /// Marks on this process's elements (its own and, under mpirun, its ghosts).
    pub marks: Vec<bool>,
    /// Elements marked in the whole mesh.
    pub count: usize,
}

/// `--demote-uncertified`: the elements whose initial spline map on `setup` (its knots) is
/// not certified valid, demoted to Q2 in rounds as `--fit energy` demotes them
/// ([`demote_with_rings`]: after the first round with their vertex rings) until every
/// element's initial map is certified; `None` when none is uncertified, or some still is after
/// [`MAX_DEMOTION_ROUNDS`]. Each process certifies its own elements
/// ([`super::passes::Passes::owned`]) and every round's marks are united over the processes
/// ([`super::passes::Passes::unite`]), so every process takes the same marks and rounds as the
/// serial job. Only the elements whose initial net changed are certified again.
pub(crate) fn demotion_marks<P: super::passes::Passes + ?Sized>(
    job: &Job,
    setup: &SplineSetup,
    share: &P,
) -> Option<Demoted> {
    use rayon::prelude::*;
    let n = job.mesh.n_elements();
    let own: Vec<usize> = (0..share.owned(job)).collect();
    let own = &own[..];
    let mut demote = vec![false; n];
    let mut space = setup.build(job, &demote);
    let mut bad = vec![false; n];
    for (&e, b) in own.iter().zip(initially_uncertified(job, &space, own)) {
        bad[e] = b;
    }
    for round in 0..MAX_DEMOTION_ROUNDS {
        let now: Vec<usize> = own.iter().copied().filter(|&e| bad[e]).collect();
        let mut fresh = vec![false; n];
        let is_q2 = |e: usize| !space.is_spline(e);
        demote_with_rings(job.mesh, job.topo, &now, round, &is_q2, &mut fresh);
        // No element of the whole mesh uncertified: the marks so far are the demotion.
        if share.unite(&mut fresh) == 0 {
            let count = share.unite(&mut demote);
            return (count > 0).then_some(Demoted {
                marks: demote,
                count,
            });
        }
        for (d, f) in demote.iter_mut().zip(&fresh) {
            *d |= f;
        }
        let next = setup.build(job, &demote);
        // Only an element whose initial net changed can change its certificate.
        let changed: Vec<usize> = own
            .par_iter()
            .copied()
            .filter(|&e| next.element_bezier(e) != space.element_bezier(e))
            .collect();
        for (&e, b) in changed
            .iter()
            .zip(initially_uncertified(job, &next, &changed))
        {
            bad[e] = b;
        }
        space = next;
    }
    if share.unite(&mut bad) > 0 {
        return None;
    }
    let count = share.unite(&mut demote);
    (count > 0).then_some(Demoted {
        marks: demote,
        count,
    })
}

/// The serial job's passes ([`super::passes`]): every element in this process.
struct Whole<'a> {
    job: &'a Job<'a>,
    /// The graded pass starts from the uniform fit; not with periodic pairs, whose second
    /// pass starts from C0 as under mpirun, so the periodic outputs stay the same there.
    warm_start: bool,
}

impl super::head::Reduction for Whole<'_> {
    fn reduce(&self, _: super::head::Reduce, _: &mut [f64]) {}
    fn lowest_failed(&self, failed: bool) -> Option<usize> {
        failed.then_some(0)
    }
}

impl super::passes::Passes for Whole<'_> {
    type Pass = First;
    type Survey = crate::spline::KnotSurvey;
    fn elements(&self) -> usize {
        self.job.mesh.n_elements()
    }
    fn survey(&mut self, setup: &SplineSetup, clock: &mut Clock) -> Self::Survey {
        let (mesh, topo) = (self.job.mesh, self.job.topo);
        clock.run(Stage::Spline, || match &setup.seams {
            Some(g) => seam::knot_survey(mesh, g),
            None => SplineSpace::knot_survey(mesh, topo),
        })
    }
    fn knots(
        &mut self,
        setup: &SplineSetup,
        clock: &mut Clock,
        survey: Self::Survey,
        params: &crate::spline::KnotParams,
    ) -> Knots {
        let topo = setup.seams.as_ref().map_or(self.job.topo, |g| &g.topo);
        clock.run(Stage::Spline, || {
            crate::spline::intervals::knot_weights_from(survey, topo, params)
        })
    }
    fn warm_start(&self) -> bool {
        self.warm_start
    }
    fn run(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        previous: Option<&First>,
        most: Option<usize>,
        demote: Option<&Demoted>,
    ) -> Result<First, CurveError> {
        spline_pass_within(job, setup, clock, previous.map(First::space), most, demote)
    }
    fn held(pass: &First) -> Result<usize, usize> {
        match pass {
            First::Done(o) => Ok(match (&o.blend, &o.energy) {
                // Before the scaled Jacobian's floor: the passes are weighed on the element
                // rules (`validity::blend`).
                (Some(b), _) => b.reduced_before_floor,
                // `--fit energy` starts from the least-squares fit's certified step: the
                // elements its full step leaves uncertified are held back from the fit there
                // (a shortened or damped step), as the blend's are.
                (None, Some(_)) => o.invalid_at_full_step,
                (None, None) => 0,
            }),
            First::Exceeded(pass) => match pass.blend {
                Err(at_least) => Err(at_least),
                Ok(_) => unreachable!("a pass given up has no blend"),
            },
        }
    }
    fn finish(
        &mut self,
        job: &Job,
        setup: &SplineSetup,
        clock: &mut Clock,
        pass: First,
    ) -> Result<First, CurveError> {
        let First::Exceeded(pass) = pass else {
            return Ok(pass);
        };
        let pass = finish_blend(&mut WholeMesh, job, setup, clock, pass)?;
        Ok(First::least_squares(pass))
    }
    fn owned(&self, job: &Job) -> usize {
        job.mesh.n_elements()
    }
    fn unite(&self, marks: &mut [bool]) -> usize {
        marks.iter().filter(|&&m| m).count()
    }
    fn space(pass: &First) -> &SplineSpace {
        pass.space()
    }
    fn factors(pass: &First) -> &[f32] {
        let First::Done(outcome) = pass else {
            unreachable!("a pass run to its end")
        };
        outcome.blend_factors.as_deref().unwrap_or(&[])
    }
}

/// The fitted map's boundary distance from the target map's, squared and summed over the
/// boundary sides of the elements `which` takes, and the count ([`misfit::boundary_sq_sum`]):
/// how closely a pass's spline space follows the smooth boundary before the blend.
pub(crate) fn fitted_boundary_sq_sum(
    job: &Job,
    setup: &SplineSetup,
    space: &SplineSpace,
    which: impl Fn(usize) -> bool + Sync,
) -> (f64, usize) {
    misfit::boundary_sq_sum(setup.topo(job), space, &setup.target_map(job), &which)
}

/// The output boundary of a pass (the certified blend of `factors` on `space`) against the
/// fitted boundary of `reference` (a pass's space with its fitted control points): squared
/// distance summed over the boundary sides of the elements `which` takes, and the count
/// ([`misfit::boundary_sq_sum`]); how far a pass's output leaves another pass's least-squares
/// boundary ([`super::passes::Passes::output_boundary_shift`]).
pub(crate) fn output_boundary_sq_sum(
    job: &Job,
    setup: &SplineSetup,
    space: &SplineSpace,
    factors: &[f32],
    reference: &SplineSpace,
    reach: f64,
    which: impl Fn(usize) -> bool + Sync,
) -> (f64, usize) {
    let target_map = setup.target_map(job);
    let (ids_mesh, ids_topo) = setup.entity_mesh(job);
    let blended = Blended::new(
        job.mesh,
        &target_map,
        space,
        ids_mesh,
        ids_topo,
        factors.to_vec(),
    )
    .with_geometry(job.mesh);
    misfit::boundary_sq_sum_reaching(setup.topo(job), &blended, reference, &which, reach)
}

/// A spline pass that may stop early ([`spline_pass_within`]): `auto`'s uniform pass.
// One value per pass, moved a few times: the size difference does not matter.
#[allow(clippy::large_enum_variant)]
enum First {
    /// Run to its end.
    Done(SplineOutcome),
    /// A least-squares pass whose blend held back more than the bound (`Err` with the count
    /// it held back at least) and was not run further: the fitted space and the fit's figures.
    Exceeded(LeastSquares<FitInfo>),
}

impl First {
    /// The pass's space with its fitted control points.
    fn space(&self) -> &SplineSpace {
        match self {
            First::Done(o) => &o.space,
            First::Exceeded(pass) => &pass.space,
        }
    }

    /// A least-squares pass: run to its end, or given up.
    fn least_squares(pass: LeastSquares<FitInfo>) -> First {
        match pass.blend {
            Ok((factors, blend)) => First::Done(SplineOutcome::blended(
                pass.space,
                factors,
                pass.fit,
                blend,
                pass.demoted,
                None,
            )),
            Err(_) => First::Exceeded(pass),
        }
    }
}

/// One spline pass on `setup`: the space, then the fit and certificate of the job's path;
/// with `most`, the least-squares path's blend is given up once it holds back more than
/// `most` elements ([`crate::validity::blend::blend_search_at_most`]): `auto`'s uniform pass
/// then needs only that count to go on to graded knots, not the blend's remaining rounds.
/// The elements of `demote` are Q2 from the start (least squares only: the pass of
/// [`least_squares_pass`], which the job under mpirun runs too).
fn spline_pass_within(
    job: &Job,
    setup: &SplineSetup,
    clock: &mut Clock,
    previous: Option<&SplineSpace>,
    most: Option<usize>,
    demote: Option<&Demoted>,
) -> Result<First, CurveError> {
    if let (Geometry::SplineFitted, None) = (job.options.geometry, &job.options.energy) {
        let pass = least_squares_pass(&mut WholeMesh, job, setup, clock, previous, most, demote)?;
        return Ok(First::least_squares(pass));
    }
    let marks = demote.map_or(&[][..], |d| &d.marks[..]);
    let space = clock.run(Stage::Spline, || setup.build(job, marks));
    clock.check()?;
    match &job.options.energy {
        Some(params) if job.options.geometry == Geometry::SplineFitted => {
            fit_with_energy(job, setup, clock, space, params).map(First::Done)
        }
        _ => certify_initial(job, clock, space).map(First::Done),
    }
}

/// `--fit energy`: fit; take the full step when certified, else search towards the initial
/// map; then minimise the energy from there. Where the initial map itself is not certified
/// valid, those elements become constrained Q2 elements (the input's own shape) and the fit is
/// repeated; when that does not give a certified start, the energy is skipped and the
/// least-squares fit is blended with the straight elevation instead.
fn fit_with_energy(
    job: &Job,
    setup: &SplineSetup,
    clock: &mut Clock,
    mut space: SplineSpace,
    params: &EnergyParams,
) -> Result<SplineOutcome, CurveError> {
    let mut demote = vec![false; job.mesh.n_elements()];
    let mut misfit = Vec::new();
    for round in 0.. {
        clock.check()?;
        let (c_star, info) = fit_demoting_misfits(
            &mut WholeMesh,
            job,
            setup,
            clock,
            &mut space,
            &demote,
            &mut misfit,
            None,
        )?;
        clock.check()?;
        let (thresholds, step) = clock.run(Stage::Validity, || {
            let fraction = job.options.line_search.min_det_fraction;
            let thresholds =
                acceptance_thresholds(job.mesh, fraction, |t| certify_space(job, &space, t));
            let step = search(job, &space, &c_star, &thresholds);
            (thresholds, step)
        });
        let count = match step {
            Ok(step) => {
                let (c, energy) = clock
                    .run(Stage::Energy, || {
                        minimize_energy(job, setup, &space, params, &c_star, &thresholds, &step)
                    })
                    .map_err(|source| CurveError::Energy {
                        input: job.input.to_owned(),
                        source,
                    })?;
                space.control_points = c;
                let bound = clock.run(Stage::Validity, || {
                    min_lower(&certify_space(job, &space, &|_| 0.0))
                });
                return Ok(SplineOutcome {
                    space,
                    blend_factors: None,
                    blend_nets: None,
                    fit: Some(info),
                    blend: None,
                    line_search: step.global,
                    alpha: Some(step.alpha),
                    invalid_at_full_step: step.invalid_at_full_step,
                    damped_points: step.damped_control_points,
                    min_det_bound: Some(bound),
                    demoted: demote.iter().filter(|&&d| d).count(),
                    energy: Some(energy),
                    energy_skipped: None,
                });
            }
            Err(ValidityError::InitialInvalid { count, .. }) => count,
        };
        if round < MAX_DEMOTION_ROUNDS {
            space = clock.run(Stage::Validity, || {
                let bad = uncertified(&certify_space(job, &space, &|_| 0.0));
                let is_q2 = |e: usize| !space.is_spline(e);
                demote_with_rings(job.mesh, job.topo, &bad, round, &is_q2, &mut demote);
                setup.build_with_misfits(job, &demote, &misfit)
            });
            continue;
        }
        let skipped = format!(
            "the initial spline map is not certified valid on {count} element(s); the least-squares fit was blended with the straight elevation instead"
        );
        space.control_points = c_star;
        let (factors, blend) = clock.run(Stage::Validity, || blend(job, setup, &space))?;
        let demoted = demote.iter().filter(|&&d| d).count();
        return Ok(SplineOutcome::blended(
            space,
            factors,
            info,
            blend,
            demoted,
            Some(skipped),
        ));
    }
    unreachable!("the demotion rounds end in a return")
}

/// The unfitted map is what was asked for: certified as it is, or refused rather than changed.
fn certify_initial(
    job: &Job,
    clock: &mut Clock,
    space: SplineSpace,
) -> Result<SplineOutcome, CurveError> {
    let bounds = clock.run(Stage::Validity, || certify_space(job, &space, &|_| 0.0));
    let bad = uncertified(&bounds);
    if !bad.is_empty() {
        return Err(CurveError::invalid(
            job.input,
            "initial spline map (use --fit position to fit it)",
            &bad,
        ));
    }
    Ok(SplineOutcome {
        space,
        blend_factors: None,
        blend_nets: None,
        fit: None,
        blend: None,
        line_search: None,
        alpha: None,
        invalid_at_full_step: 0,
        damped_points: 0,
        min_det_bound: Some(min_lower(&bounds)),
        demoted: 0,
        energy: None,
        energy_skipped: None,
    })
}

/// The least-squares fit of the space's control points (planar patches projected back), timed
/// as [`Stage::Fit`] with its assembly and CG parts.
pub(super) fn fit(
    job: &Job,
    setup: &SplineSetup,
    clock: &mut Clock,
    space: &SplineSpace,
    start: Option<&[[f64; 3]]>,
) -> Result<(Vec<[f64; 3]>, FitInfo), CurveError> {
    let progress = clock.progress();
    let (c_star, info) = clock.run(Stage::Fit, || solve_fit(job, setup, space, start, progress))?;
    clock.add(Stage::FitAssembly, info.assembly_seconds);
    clock.add(Stage::FitCg, info.solve_seconds);
    Ok((c_star, info))
}

/// Control points of `to` taken from `from_points` (the control points of the space `from`)
/// where both spaces have a control point on the same entity, else `to`'s initial ones.
pub(crate) fn carry_over(
    from: &SplineSpace,
    from_points: &[[f64; 3]],
    to: &SplineSpace,
) -> Vec<[f64; 3]> {
    let at: HashMap<_, _> = from.control_point_keys.iter().zip(from_points).collect();
    to.control_point_keys
        .iter()
        .zip(&to.control_points)
        .map(|(k, &c)| at.get(k).map_or(c, |&&x| x))
        .collect()
}

fn solve_fit(
    job: &Job,
    setup: &SplineSetup,
    space: &SplineSpace,
    start: Option<&[[f64; 3]]>,
    progress: &dyn Progress,
) -> Result<(Vec<[f64; 3]>, FitInfo), CurveError> {
    let factors = setup.fit_params.solver.factors(
        job.topo.dim,
        space.control_points.len(),
        matches!(job.options.backend, crate::exec::gpu::Backend::Cpu),
    );
    // A device sums K's values itself: the host keeps only its structure.
    let summing = match job.executor.gpu() {
        Some(_) if !factors => Summing::Solver,
        _ => Summing::Host,
    };
    let (mut c_star, mut info) = fit_with_solver(
        space,
        job.mesh,
        setup.topo(job),
        &setup.fit_params,
        setup.targets.as_ref(),
        (start, summing),
        JobSolve {
            job,
            factors,
            progress,
        },
    )
    .map_err(|source| match source {
        crate::solve::CgError::Cancelled { .. } => CurveError::Cancelled,
        source => CurveError::Solve {
            input: job.input.to_owned(),
            source,
        },
    })?;
    // Across rotation seams the factor only preconditions the coupled CG.
    if factors && !space.extraction.has_frames() {
        info.solver = FitSolver::Cholesky;
    }
    if let Some(f) = setup.used_features() {
        crate::fit::features::project_onto_planes(space, setup.topo(job), f, &mut c_star);
    }
    // Not across periodic seams: elements with seam frames or offsets add no jumps, so the
    // seam's facets would keep kinks the interior's lose.
    let w = setup.fit_params.facet_smoothing;
    if w > 0.0 && setup.live_seams().is_none() {
        let is_spline = |e: usize| space.is_spline(e);
        let rules = &job.options.line_search;
        let guard = crate::fit::jumps::JumpGuard {
            min_quality_fraction: rules.min_quality_fraction,
            percentile_quality_fraction: rules.percentile_quality_fraction,
        };
        let t = std::time::Instant::now();
        let jumps = crate::fit::jumps::smooth_facet_jumps(
            space,
            job.mesh,
            job.topo,
            &is_spline,
            w,
            &guard,
            &mut c_star,
        )
        .map_err(|source| CurveError::Solve {
            input: job.input.to_owned(),
            source,
        })?;
        info.facet_jumps = Some(crate::fit::jumps::JumpInfo {
            seconds: t.elapsed().as_secs_f64(),
            ..jumps
        });
    }
    Ok((c_star, info))
}

/// The fit's solve in a job: K factored where `factors`, else the executor's CG; across
/// rotation seams the executor's coupled CG, or, where `factors`, the CPU's preconditioned by
/// K's factor.
struct JobSolve<'a, 'j> {
    job: &'a Job<'j>,
    factors: bool,
    progress: &'a dyn Progress,
}

impl JobSolve<'_, '_> {
    /// The progress receiver as a CG monitor, asked every iteration, so a cancelled job stops
    /// within one iteration rather than at the end of the solve.
    fn monitor(&self) -> impl crate::solve::CgMonitor + '_ {
        crate::solve::Cancellable {
            progress: |i, r| self.progress.cg(i, r),
            cancelled: || self.progress.cancelled(),
        }
    }
}

impl FitSolve for JobSolve<'_, '_> {
    fn solve(
        self,
        k: NormalMatrix,
        rhs: &[[f64; 3]],
        x: &mut [[f64; 3]],
        cg: &CgParams,
    ) -> Result<CgInfo, CgError> {
        if self.factors {
            let (indptr, indices, data) = (k.indptr(), k.indices(), k.data());
            return crate::solve::direct::cholesky(
                indptr,
                indices,
                data,
                rhs,
                x,
                self.job.topo.dim,
            );
        }
        self.job.executor.pcg(k, rhs, x, cg, &mut self.monitor())
    }

    fn solve_coupled(
        self,
        k: NormalMatrix,
        c: &Coupling,
        rhs: &[[f64; 3]],
        x: &mut [[f64; 3]],
        cg: &CgParams,
        _: bool,
    ) -> Result<(CgInfo, CoupledRun), CgError> {
        if self.factors {
            let info =
                crate::fit::rotated::solve(&k, c, rhs, x, cg, OnK::Factor, &mut self.monitor())?;
            return Ok((info, CoupledRun::cpu(OnK::Factor)));
        }
        let executor = self.job.executor;
        let info = executor.pcg_coupled(k, c, rhs, x, cg, &mut self.monitor())?;
        let run = CoupledRun {
            device: executor.name(),
            preconditioner: executor.coupled_preconditioner(),
        };
        Ok((info, run))
    }
}

/// The certified blend from the straight elevation to the fitted map (`validity::blend`).
fn blend(job: &Job, setup: &SplineSetup, space: &SplineSpace) -> Result<Blend, CurveError> {
    let done = blend_within(job, setup, space, None, &Alone)?;
    Ok(done.expect("an unbounded blend runs to its end"))
}

/// Whether the space's current map is not certified valid on each of `elements` (the exact
/// certificate's decision, [`crate::validity::certify_screened`] at target 0), in order.
fn initially_uncertified(job: &Job, space: &SplineSpace, elements: &[usize]) -> Vec<bool> {
    let net = |e: usize| space.element_bezier(e);
    let depth = job.options.line_search.certificate_depth;
    let screened =
        crate::validity::certify_screened(job.executor, space.dim, elements, &net, depth, &|_| 0.0);
    screened
        .bounds
        .iter()
        .map(|b| !b.certified_positive())
        .collect()
}

/// Certified bounds of the space's current map, exact where at most `target(e)`
/// ([`certify_mesh`]).
fn certify_space(
    job: &Job,
    space: &SplineSpace,
    target: &(dyn Fn(usize) -> f64 + Sync),
) -> Vec<DetBounds> {
    let net = |e: usize| space.element_bezier(e);
    let depth = job.options.line_search.certificate_depth;
    certify_mesh(
        job.executor,
        space.dim,
        space.n_elements(),
        &net,
        depth,
        target,
    )
}

fn min_lower(bounds: &[DetBounds]) -> f64 {
    bounds.iter().map(|b| b.lower).fold(f64::INFINITY, f64::min)
}

/// The certified line search of the job's mode from the space's control points to `c_star`.
fn search(
    job: &Job,
    space: &SplineSpace,
    c_star: &[[f64; 3]],
    thresholds: &[f64],
) -> Result<CertifiedStep, ValidityError> {
    let net = |e: usize, cps: &[[f64; 3]]| space.element_bezier_with(e, cps);
    let support = |e: usize| {
        let mut rows = ElementRows::default();
        space.extraction.rows(e, &mut rows);
        let mut ids = rows.cols;
        ids.sort_unstable();
        ids.dedup();
        ids
    };
    certified_step(
        job.executor,
        job.options.line_search_mode,
        space.dim,
        space.n_elements(),
        net,
        support,
        &space.control_points,
        c_star,
        thresholds,
        &job.options.line_search,
    )
}

/// The energy minimisation of `--fit energy` from the certified least-squares step; the line
/// search's thresholds stay in force. Returns C and the minimiser's figures (C is certified by
/// the minimiser's acceptance test).
fn minimize_energy(
    job: &Job,
    setup: &SplineSetup,
    space: &SplineSpace,
    params: &EnergyParams,
    c_star: &[[f64; 3]],
    thresholds: &[f64],
    step: &CertifiedStep,
) -> Result<(Vec<[f64; 3]>, EnergyInfo), EnergyError> {
    use crate::energy::{Energy, Validity, minimize_on};
    let (mesh, topo, fit) = (job.mesh, setup.topo(job), &setup.fit_params);
    let start = &step.control_points;
    let smooth = setup.targets.as_ref();
    let energy = Energy::with_targets(space, mesh, topo, fit, smooth, c_star, params)?;
    let depth = job.options.line_search.certificate_depth;
    let validity = Validity::for_start(&energy, job.executor, depth, thresholds, start)?;
    let (mut c, info) = minimize_on(&energy, &validity, start, params, job.executor, &mut |_| {})?;
    // The energy moves control points off the planes of planar patches; put them back where
    // the result stays accepted (it is a small move: the start was on the planes).
    if let Some(f) = &fit.features {
        let mut projected = c.clone();
        crate::fit::features::project_onto_planes(space, topo, f, &mut projected);
        if validity.accepts(&energy, &projected) {
            c = projected;
        }
    }
    Ok((c, info))
}
