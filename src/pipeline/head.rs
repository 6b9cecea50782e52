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
/// process holds (`rotations`: the rotation pairs too; a rank's share is read with its ghost
/// rings run on across the seams). Every process glues alike or none does.
pub(crate) fn glue_seams<R: Reduction + ?Sized>(
    reduction: &R,
    pairs: &[PeriodicPair],
    glue: impl Fn(bool) -> Option<Glued>,
) -> (Option<Glued>, Option<String>) {
    if pairs.is_empty() {
        return (None, None);
    }
    let translations = pairs.iter().any(|p| p.transform.is_translation());
    let rotations = pairs.iter().any(|p| !p.transform.is_translation());
    let all = glue(true);
    let everywhere = reduction.all(all.is_some());
    let glued = match all.filter(|_| everywhere) {
        Some(g) => Some((g, true)),
        None if rotations && translations => glue(false).map(|g| (g, false)),
        None => None,
    };
    let everywhere = reduction.all(glued.is_some());
    let glued = glued.filter(|_| everywhere);
    let why = match &glued {
        Some((_, true)) => None,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Topology;
    use crate::mesh::generate::grid_3d;
    use crate::mesh::periodic::{PeriodicSpec, Rigid};
    use std::sync::{Barrier, Mutex};

    /// A job of several processes as threads of one test: a reduction writes each member's
    /// values into its slot, waits for all, and every member reduces the slots in member
    /// order (what a communicator does across processes).
    struct Team {
        barrier: Barrier,
        slots: Mutex<Vec<Vec<f64>>>,
    }

    struct Member<'a> {
        team: &'a Team,
        rank: usize,
    }

    impl Reduction for Member<'_> {
        fn reduce(&self, op: Reduce, v: &mut [f64]) {
            self.team.slots.lock().unwrap()[self.rank] = v.to_vec();
            self.team.barrier.wait();
            {
                let slots = self.team.slots.lock().unwrap();
                for (i, x) in v.iter_mut().enumerate() {
                    let all = slots.iter().map(|s| s[i]);
                    *x = match op {
                        Reduce::Sum => all.sum(),
                        Reduce::Min => all.fold(f64::INFINITY, f64::min),
                        Reduce::Max => all.fold(f64::NEG_INFINITY, f64::max),
                    };
                }
            }
            // Nobody writes the next reduction's values before everyone has read these.
            self.team.barrier.wait();
        }

        fn lowest_failed(&self, failed: bool) -> Option<usize> {
            let mut v = [if failed {
                self.rank as f64
            } else {
                f64::INFINITY
            }];
            self.reduce(Reduce::Min, &mut v);
            v[0].is_finite().then_some(v[0] as usize)
        }
    }

    /// `f` on every member of a team of `n`, its results in member order.
    fn on_team<T: Send>(n: usize, f: impl Fn(&Member) -> T + Sync) -> Vec<T> {
        let team = Team {
            barrier: Barrier::new(n),
            slots: Mutex::new(vec![Vec::new(); n]),
        };
        std::thread::scope(|s| {
            let members: Vec<_> = (0..n)
                .map(|rank| {
                    let (team, f) = (&team, &f);
                    s.spawn(move || f(&Member { team, rank }))
                })
                .collect();
            members.into_iter().map(|m| m.join().unwrap()).collect()
        })
    }

    /// The hexes of a sheared grid on `xs` × [0, 1]² (x from `xs`): the same map on every
    /// vertex, so grids on two runs of `xs` that share a coordinate are the two halves of the
    /// grid on all of `xs`. The shear grows with x, so the worst element is at the largest x.
    fn sheared(xs: &[f64]) -> LinearMesh {
        let ys = [0.0, 0.4, 1.0];
        let mut m = grid_3d(xs, &ys, &ys);
        for p in &mut m.coords {
            p[1] += 0.3 * p[0] * p[0] * p[2];
            p[2] += 0.1 * p[0] * p[1];
        }
        m
    }

    const XS: [f64; 6] = [0.0, 0.3, 0.5, 0.8, 1.2, 1.5];

    /// The whole mesh's smallest scaled Jacobian and box diagonal, reduced over two halves of
    /// it (or three shares, one of them without elements), are the one-process figures of the
    /// whole mesh, bit for bit, on every process; no element anywhere is NaN.
    #[test]
    fn shares_reduce_to_the_whole_mesh_figures() {
        let whole = sheared(&XS);
        let want = (
            OneProcess.input_min_scaled_jacobian(&whole),
            OneProcess.diagonal(&whole),
        );
        // The minimum is not the first half's: a process that kept its own would differ.
        let first = OneProcess.input_min_scaled_jacobian(&sheared(&XS[..=2]));
        assert!(want.0 < 0.99 * first, "{want:?} vs {first}");
        let halves = [sheared(&XS[..=2]), sheared(&XS[2..])];
        let got = on_team(2, |m| {
            let mesh = &halves[m.rank];
            (m.input_min_scaled_jacobian(mesh), m.diagonal(mesh))
        });
        for g in &got {
            assert_eq!(g.0.to_bits(), want.0.to_bits(), "{got:?} vs {want:?}");
            assert_eq!(g.1.to_bits(), want.1.to_bits(), "{got:?} vs {want:?}");
        }
        // A third share holding vertices but no element takes no part in the minimum.
        let mut empty = sheared(&XS[1..=3]);
        empty.elements.clear();
        let shares = [sheared(&XS[..=2]), empty, sheared(&XS[2..])];
        let got = on_team(3, |m| m.input_min_scaled_jacobian(&shares[m.rank]));
        assert!(
            got.iter().all(|g| g.to_bits() == want.0.to_bits()),
            "{got:?}"
        );
        let mut none = sheared(&XS);
        none.elements.clear();
        assert!(OneProcess.input_min_scaled_jacobian(&none).is_nan());
        let got = on_team(2, |m| m.input_min_scaled_jacobian(&none));
        assert!(got.iter().all(|g| g.is_nan()), "{got:?}");
    }

    /// A stage that fails on some processes fails on all: the failed ones keep their own
    /// error, the others name the lowest failed process; with no failure every process keeps
    /// its outcome. One process: its own outcome.
    #[test]
    fn a_stage_failing_on_one_process_fails_on_every_process() {
        let outcome = |rank: usize, failing: &[usize]| -> Result<usize, CurveError> {
            if failing.contains(&rank) {
                Err(CurveError::Options(format!("own error of {rank}")))
            } else {
                Ok(10 + rank)
            }
        };
        for (failing, want) in [
            (&[][..], ["10", "11", "12"]),
            (
                &[1][..],
                [
                    "stopped: rank 1 failed",
                    "own error of 1",
                    "stopped: rank 1 failed",
                ],
            ),
            (
                &[2, 1][..],
                ["stopped: rank 1 failed", "own error of 1", "own error of 2"],
            ),
            (
                &[0][..],
                [
                    "own error of 0",
                    "stopped: rank 0 failed",
                    "stopped: rank 0 failed",
                ],
            ),
        ] {
            let got = on_team(3, |m| match agreed(m, outcome(m.rank, failing)) {
                Ok(v) => v.to_string(),
                Err(e) => e.to_string(),
            });
            assert_eq!(got, want, "failing {failing:?}");
        }
        assert_eq!(agreed(&OneProcess, outcome(0, &[])).unwrap(), 10);
        let own = agreed(&OneProcess, outcome(0, &[0])).unwrap_err();
        assert_eq!(own.to_string(), "own error of 0");
    }

    #[test]
    fn pyfr_names_are_refused_without_a_pair() {
        let input = Path::new("box.msh");
        let e = check_pyfr_names(input, true, &[]).unwrap_err().to_string();
        assert!(
            e.starts_with("box.msh") && e.contains("--periodic-pyfr-names"),
            "{e}"
        );
        assert!(check_pyfr_names(input, false, &[]).is_ok());
        let pair = periodic_pair(Rigid::translation([1.5, 0.0, 0.0]));
        assert!(check_pyfr_names(input, true, &[pair]).is_ok());
    }

    fn periodic_pair(transform: Rigid) -> PeriodicPair {
        PeriodicPair {
            spec: PeriodicSpec {
                master: "1".into(),
                slave: "2".into(),
                from_file: false,
            },
            master_tag: 1,
            slave_tag: 2,
            transform,
            vertex_map: Vec::new(),
            input_mismatch: 0.0,
        }
    }

    /// A glued mesh marked with the process that glued it and whether with the rotation
    /// pairs.
    fn marked(rank: usize, rotations: bool) -> Glued {
        let mesh = sheared(&XS[..=1]);
        Glued {
            topo: Topology::build(&mesh),
            mesh,
            translations: vec![[rank as f64, f64::from(u8::from(rotations)), 0.0]],
            rotations: Vec::new(),
            element_order: None,
        }
    }

    /// The glue of a process holding the shares `ranks`: it fails where one of them is among
    /// the failing ones (`fails`: with the rotation pairs, without them).
    fn fake_glue<'a>(
        ranks: &'a [usize],
        fails: (&'a [usize], &'a [usize]),
    ) -> impl Fn(bool) -> Option<Glued> + 'a {
        move |rotations| {
            let failing = if rotations { fails.0 } else { fails.1 };
            (!ranks.iter().any(|r| failing.contains(r))).then(|| marked(ranks[0], rotations))
        }
    }

    /// The seams' gluing rule decides alike on every process and as one process holding the
    /// whole mesh does, where the whole mesh glues iff every share does: all pairs where they
    /// glue everywhere; with rotation and translation pairs, the translations alone where the
    /// rotations fail on some process; nothing where that fails too, or with translations
    /// alone.
    #[test]
    fn the_seams_glue_alike_on_every_process_and_as_one_process() {
        let rotation = Rigid {
            rotation: [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            translation: [0.0; 3],
        };
        let translation = Rigid::translation([1.5, 0.0, 0.0]);
        let both = [periodic_pair(translation), periodic_pair(rotation)];
        let one = [periodic_pair(translation)];
        // (pairs, the processes where gluing with rotations / without them fails, what every
        // process keeps: the glue's `rotations` flag, or none, and why).
        type Case<'a> = (&'a [PeriodicPair], &'a [usize], &'a [usize]);
        let cases: [(Case, Option<bool>, Option<&str>); 6] = [
            ((&both, &[], &[]), Some(true), None),
            ((&both, &[1], &[]), Some(false), Some("rotation pairs")),
            ((&both, &[0], &[1]), None, Some("translation pairs")),
            ((&one, &[], &[]), Some(true), None),
            ((&one, &[1], &[]), None, Some("translation pairs")),
            ((&[], &[0, 1], &[0, 1]), None, None),
        ];
        for ((pairs, fail_all, fail_translations), want, why) in cases {
            let fails = (fail_all, fail_translations);
            let got = on_team(2, |m| {
                let (g, why) = glue_seams(m, pairs, fake_glue(&[m.rank], fails));
                (
                    g.map(|g| (g.translations[0][0], g.translations[0][1] > 0.0)),
                    why,
                )
            });
            let (whole, whole_why) = glue_seams(&OneProcess, pairs, fake_glue(&[0, 1], fails));
            let whole = whole.map(|g| g.translations[0][1] > 0.0);
            assert_eq!(whole, want, "{want:?} {why:?}");
            for (rank, (g, w)) in got.iter().enumerate() {
                // Each process keeps its own glued mesh.
                assert_eq!(g.map(|g| g.0), want.map(|_| rank as f64));
                assert_eq!(g.map(|g| g.1), want, "{why:?}");
                assert_eq!(w, &whole_why);
                match why {
                    Some(why) => assert!(w.as_deref().is_some_and(|w| w.contains(why)), "{w:?}"),
                    None => assert!(w.is_none(), "{w:?}"),
                }
            }
        }
    }
}
