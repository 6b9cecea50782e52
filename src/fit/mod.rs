//! Least-squares fit of the spline control points to the input mesh (paper §2.3, eq. 3–9).
//!
//! Input: a spline space ([`FitSpace`]: control points C0 and the Bézier extraction E_e of every
//! element), the linear mesh and its topology, and [`FitParams`]. Output: fitted control points
//! C* and a [`FitInfo`].
//!
//! **Objective** Q = D + R over the 3^d sample points u_i ∈ {0, ½, 1}^d of every element:
//! * D = Σ_e Σ_i w^d_i ‖x_e(u_i) − P_e(u_i)‖², P_e the input element's multilinear map (its
//!   vertices at corners, points on straight edges/faces at midpoints);
//! * R = Σ_e Σ_i w^r_i Σ_j ‖∂_j x_e(u_i) − ∂_j x⁰_e(u_i)‖², x⁰ the initial IGA map (frames kept).
//!
//! The weights multiply the **squared** residuals (paper eq. 3), consistently in D and R; the
//! matrix form with rows scaled by √w gives the same normal equations. With x_e(u) = b(u)ᵀ E_e C
//! the normal equations are K C = F with K = Σ_e E_eᵀ G_e E_e,
//! G_e = Σ_i w^d_i b_i b_iᵀ + Σ_i w^r_i Σ_j b'_ij b'_ijᵀ, one SPD matrix for the three
//! coordinates. They are solved for the displacement δ = C − C0 (K δ = F − K C0), which keeps
//! the right-hand side small and the iteration well scaled, by preconditioned CG
//! ([`crate::solve::pcg`]: block Jacobi on aggregates by default, symmetric block Gauss–Seidel
//! on colour-ordered aggregates or point Jacobi on request) on the assembled matrix.
//!
//! **Targets.** [`FitTargets::Chords`] is the paper's P_e. [`FitTargets::Smooth`] moves the
//! midpoint targets (edge midpoints, face and cell centres) from the chords onto a local
//! second-order reconstruction of the smooth boundary ([`smooth`]), which makes the fitted
//! boundary third-order accurate instead of second where the spline space can follow the
//! input's boundary grid; where the grid lines kink, the caller makes the elements there Q2
//! ([`crate::spline::kinks`], [`SmoothParams::kink_angle_deg`]).

pub mod assembly;
pub mod features;
pub mod jumps;
mod normal_matrix;
pub mod partial;
mod rhs;
pub mod rotated;
pub mod smooth;

use crate::params::{ParamError, above, in_range};
pub use normal_matrix::{
    ElementBlocks, MatrixFree, NormalMatrix, extraordinary_reweighted, extraordinary_vertices,
    mask_level, size_levels,
};
use normal_matrix::{control_point_scales, sample_weight};
pub use smooth::{InheritShare, RECORD_LEN, SmoothParams, SmoothTargets};

use crate::math::BezierNet;
use crate::math::bernstein::bernstein2;
use crate::math::linalg::DVec3;
use crate::mesh::{LinearMesh, Topology};
use crate::solve::{CgError, CgInfo, CgParams, LinOp};
use rayon::prelude::*;
use std::collections::HashMap;

/// A space of quadratic Bézier elements driven by global control points.
pub trait FitSpace: Sync {
    fn dim(&self) -> usize;
    fn n_elements(&self) -> usize;
    fn control_points(&self) -> &[[f64; 3]];
    /// Explicit rows of E_e: Bernstein point i (index 9z + 3y + x) is Σ weights · C\[cols\]
    /// over `offsets[i]..offsets[i+1]`.
    fn element_rows(
        &self,
        e: usize,
        offsets: &mut Vec<usize>,
        cols: &mut Vec<u32>,
        weights: &mut Vec<f64>,
    );
    /// Bernstein net of element `e` for the control points `cps`.
    fn bezier_net_with(&self, e: usize, cps: &[[f64; 3]]) -> BezierNet;
    /// The constant part of element `e`'s net (its periodic seam offsets): the net is
    /// E_e C plus this. `None` (the default): none.
    fn net_shift(&self, _e: usize) -> Option<BezierNet> {
        None
    }
    /// The control points element `e` sees rotated across a periodic seam, with their
    /// rotations ([`crate::spline::Extraction::frames`]): the element's net takes R P for
    /// such a point P, so the fit couples the coordinates there ([`rotated`]). `None` (the
    /// default): none.
    fn frames(&self, _e: usize) -> Option<&[crate::spline::extraction::SeamFrame]> {
        None
    }
    /// Whether some element has [`FitSpace::frames`].
    fn has_frames(&self) -> bool {
        false
    }
    /// When E_e is a matrix shared by every element with the same key times the selection of
    /// 3^d distinct control points (in local-node order), return the key and write the
    /// control points into `ids`; the assembly then computes one local matrix per key.
    /// `None` (the default) always works.
    fn element_pattern(&self, _e: usize, _ids: &mut Vec<u32>) -> Option<u64> {
        None
    }
    /// When E_e = (M_z ⊗ M_y ⊗ M_x) times the selection of 3^d distinct control points (in
    /// local-node order), whatever the matrices (graded knots give every element its own),
    /// return the three 3 × 3 matrices (x, y, z; the identity for z in 2D) and write the
    /// control points into `ids`: the assembly then forms the local matrix from them without
    /// expanding E_e's rows. `None` (the default) always works.
    fn element_factors(&self, _e: usize, _ids: &mut Vec<u32>) -> Option<[[[f64; 3]; 3]; 3]> {
        None
    }
    /// Append E_eᵀ f to `out` as (control point, value) pairs (a control point may repeat),
    /// for f one 3-vector per Bernstein point. The default expands the explicit rows.
    fn add_transposed(&self, e: usize, f: &BezierNet, out: &mut Vec<(u32, [f64; 3])>) {
        let (mut offsets, mut cols, mut weights) = (Vec::new(), Vec::new(), Vec::new());
        self.element_rows(e, &mut offsets, &mut cols, &mut weights);
        for i in 0..offsets.len() - 1 {
            for k in offsets[i]..offsets[i + 1] {
                out.push((cols[k], (DVec3::from(f[i]) * weights[k]).into()));
            }
        }
    }
}

/// Sample-point weights (they multiply squared residuals).
#[deny(missing_docs)]
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FitWeights {
    /// Position weight at element corners on interior vertices.
    pub corner: f64,
    /// Position weight at element corners on boundary vertices.
    pub boundary_corner: f64,
    /// Position weight at edge/face midpoints and element centres inside the mesh.
    pub midpoint: f64,
    /// Position weight at the midpoints and centres of "deep" elements: those with no vertex
    /// on an element that touches the boundary (`None`: [`FitWeights::midpoint`] with uniform
    /// knots, [`GRADED_DEEP_MIDPOINT`] with graded ones; resolved by
    /// [`FitWeights::for_knots`]).
    pub deep_midpoint: Option<f64>,
    /// Position weight at the interior midpoints and centres of the elements without a
    /// boundary corner within two element rings of an extraordinary vertex or edge
    /// ([`extraordinary_vertices`]), where it is larger than their [`FitWeights::midpoint`] or
    /// [`FitWeights::deep_midpoint`]: the poly-spline is not C¹ there, and the weak interior
    /// weight of the smooth preset lets the fit bend those elements between their corners.
    /// The pipeline's passes fit without it and refit with it only where the pass kept holds
    /// back too many elements (`pipeline::passes::spline_passes`).
    pub extraordinary_midpoint: f64,
    /// Position weight at midpoints of edges, faces and cells whose corners are all boundary
    /// vertices: the boundary sides' midpoints, where the smooth targets lie on the surface,
    /// and the few interior edges, faces or cells spanned by boundary vertices alone.
    pub boundary_midpoint: f64,
    /// Frame (first derivative) weight at corners.
    pub frame_corner: f64,
    /// Frame weight at midpoints and centres.
    pub frame_midpoint: f64,
    /// Position weight at element corners on sharp-feature vertices when the fit is given
    /// [`FitParams::features`]; it keeps the feature curves close to the input's feature
    /// polylines.
    pub feature: f64,
}

impl FitWeights {
    /// The paper's position-only example: w = 1 interior corners, 10 boundary corners,
    /// 0.5 midpoints, no frame term.
    pub fn position() -> Self {
        FitWeights {
            corner: 1.0,
            boundary_corner: 10.0,
            midpoint: 0.5,
            deep_midpoint: None,
            extraordinary_midpoint: 0.5,
            boundary_midpoint: 0.5,
            frame_corner: 0.0,
            frame_midpoint: 0.0,
            feature: 10.0,
        }
    }
    /// Weights of the smooth-boundary mode (`--fit smooth`, used with
    /// [`FitTargets::Smooth`]): no frame term (the frames of the initial map follow the chords
    /// and would pull the boundary back towards them), interior corners 1, and the boundary
    /// weighted against the interior more than in the paper's example, since the smooth
    /// targets lie on the reconstructed surface: boundary midpoints 1 and interior ones 0.05
    /// (with 0.5 everywhere the interior samples, which follow the input's straight rows where
    /// they kink, as at an O-grid's spokes, pull the boundary off the surface: O-grid disk 7×
    /// Gmsh-with-CAD's RMS and 11× its max, 4× and 4.5× with these); boundary corners 20 (the
    /// position preset's ratio 20 : 1 to the boundary midpoints, so the boundary vertices stay
    /// as close to the input's); sharp-feature samples 100 (a C¹ spline across a rim otherwise
    /// bends the rim's neighbours off the side: O-grid cylinder 35× → 9× Gmsh-with-CAD's max).
    pub fn smooth() -> Self {
        FitWeights {
            corner: 1.0,
            boundary_corner: 20.0,
            midpoint: 0.05,
            deep_midpoint: None,
            extraordinary_midpoint: EXTRAORDINARY_MIDPOINT,
            boundary_midpoint: 1.0,
            frame_corner: 0.0,
            frame_midpoint: 0.0,
            feature: 100.0,
        }
    }
    /// The paper's position + frame example: w^r = 1 everywhere, w^d = 0 at midpoints,
    /// corners as in [`FitWeights::position`].
    pub fn frame() -> Self {
        FitWeights {
            corner: 1.0,
            boundary_corner: 10.0,
            midpoint: 0.0,
            deep_midpoint: None,
            extraordinary_midpoint: 0.0,
            boundary_midpoint: 0.0,
            frame_corner: 1.0,
            frame_midpoint: 1.0,
            feature: 10.0,
        }
    }

    /// The weights with [`FitWeights::deep_midpoint`] resolved for the knot intervals in use
    /// (`graded`): an explicit value is kept; otherwise uniform knots take
    /// [`FitWeights::midpoint`] and graded ones the larger of it and [`GRADED_DEEP_MIDPOINT`]
    /// (a preset without midpoint samples, `midpoint` 0, keeps 0).
    ///
    /// Why: a ring away from the boundary the straight map is what the fit should reproduce,
    /// and graded knots can (a graded grid is in their space), so there the midpoints weigh
    /// more than the corners; the weak 0.05 of the smooth preset is for the boundary's
    /// neighbours, whose interior samples would pull the wall off the surface. With 0.05
    /// everywhere the graded spline is free to bend the inner cells between their corners,
    /// and the quality guard throws it away there (n0012: 12 % held back, 6 % with 3;
    /// NACA4412: 15 % and a 19.4° max facet angle, 9 % and 10.8°; `BENCHMARKS.md`, "Graded
    /// knot intervals"). Not for uniform knots: the torus O-grid's wall then loses (9.2×
    /// against 4.0× Gmsh-with-CAD's max error with 0.5). Not next to the boundary either:
    /// weighting every element without a boundary corner holds back fewer on the balls but
    /// raises NACA4412's max facet angle to 27.9° at its far field.
    pub fn for_knots(mut self, graded: bool) -> Self {
        if self.deep_midpoint.is_none() {
            self.deep_midpoint = Some(if graded && self.midpoint > 0.0 {
                self.midpoint.max(GRADED_DEEP_MIDPOINT)
            } else {
                self.midpoint
            });
        }
        self
    }
}

/// Default interior weight of the midpoints of elements a ring away from the boundary under graded
/// knots ([`FitWeights::for_knots`]).
pub const GRADED_DEEP_MIDPOINT: f64 = 3.0;

/// Default interior midpoint weight of the smooth preset near extraordinary vertices and
/// edges ([`FitWeights::extraordinary_midpoint`]), the one that holds back fewest elements on
/// the real meshes with extraordinary lines (`BENCHMARKS.md`, "Midpoint weight at
/// extraordinary vertices"): 1–2.5 left hsphere8's min scaled Jacobian below the 0.805 of
/// 0.05 (0.743–0.797) and 4 or more held back more of it (28 % and up against 11 % with 3).
/// The pipeline chooses the knots without it and refits the pass kept with it where that
/// pass holds back too many (`pipeline::passes::spline_passes`).
pub const EXTRAORDINARY_MIDPOINT: f64 = 3.0;

/// The fit presets of the command line (`--fit`): which weights and targets the least-squares
/// fit uses, and whether the energy minimisation follows it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitPreset {
    /// No fit: sample the initial spline map.
    None,
    /// The paper's position weights (least squares, then a certified line search).
    Position,
    /// The paper's position + frame weights.
    Frame,
    /// Midpoint targets from a local reconstruction of the smooth boundary instead of the
    /// straight chords (more accurate curved boundaries).
    Smooth,
    /// `smooth`, then the element degeneration energy minimised under the det J certificate
    /// (paper §2.4, docs/energy.md).
    Energy,
}

impl FitPreset {
    /// The preset's weights (the command line overrides single ones).
    pub fn weights(self) -> FitWeights {
        match self {
            FitPreset::Frame => FitWeights::frame(),
            FitPreset::Smooth | FitPreset::Energy => FitWeights::smooth(),
            FitPreset::None | FitPreset::Position => FitWeights::position(),
        }
    }
    /// Whether the midpoint targets come from the smooth-boundary reconstruction.
    pub fn smooth_targets(self) -> bool {
        matches!(self, FitPreset::Smooth | FitPreset::Energy)
    }
}

/// Where the position targets of midpoint samples come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FitTargets {
    /// The input's multilinear map (midpoints on straight edges/faces), as in the paper.
    #[default]
    Chords,
    /// Midpoints moved onto a local reconstruction of the smooth boundary ([`smooth`]).
    Smooth(SmoothParams),
}

/// How the fit's normal equations are solved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FitSolver {
    /// Sparse Cholesky for systems of at most [`FitSolver::DIRECT_2D`] (2D) or
    /// [`FitSolver::DIRECT_3D`] (3D) control points on the CPU backend, CG otherwise. Both
    /// solve the same system; CG stops at `--cg-tol`, the factorisation at rounding. Where a
    /// CG stands in for the factorisation (the coupled fit across rotation seams, serially and
    /// under mpirun; every fit under mpirun) it runs to [`DIRECT_CG_TOL`]
    /// ([`FitSolver::cg_params`]).
    #[default]
    Auto,
    /// Preconditioned CG ([`crate::solve`]) on any size and backend.
    Cg,
    /// Sparse Cholesky ([`crate::solve::direct`]) on any size, on the CPU.
    Cholesky,
}

impl FitSolver {
    /// Largest 2D system [`FitSolver::Auto`] factors. Measured per `curve` run (both fits of
    /// the post-fit Q2 round), CG against Cholesky: example.msh (2.1k control points) 55
    /// against 17 ms, the ball (1.4k) 22 against 10, n0012 (3.8k) 14 against 11, hole8170
    /// (11k) 108 against 87; the structured 15-16k meshes, where CG needs few iterations,
    /// went the other way (NACA4412 .inp 37 against 45, the turbine 76 against 105).
    pub const DIRECT_2D: usize = 12_000;
    /// Largest 3D system [`FitSolver::Auto`] factors: 3D fill grows as n², and from 1.7k
    /// control points (mfem/cylinder-hex, hsphere8, libmesh ex9, beam-sphere) the two were
    /// within 15 % of each other; the 765 of su2 cylinder were solved in 8 against 14 ms, and
    /// its 1,193 (the Q2 elements along its curved feature edges) in 14 against 32 ms (fit
    /// CG stage, medians of 9 runs; 0.080 against 0.089 s of CPU for the whole run).
    pub const DIRECT_3D: usize = 1_500;

    /// Whether this choice factors a `dim`-D system of `unknowns` control points; `cpu` says
    /// whether the CG would run on the CPU (automatic choice keeps a GPU solve on the GPU).
    pub fn factors(self, dim: usize, unknowns: usize, cpu: bool) -> bool {
        match self {
            FitSolver::Cg => false,
            FitSolver::Cholesky => true,
            FitSolver::Auto => {
                cpu && unknowns
                    <= if dim == 2 {
                        Self::DIRECT_2D
                    } else {
                        Self::DIRECT_3D
                    }
            }
        }
    }

    /// The CG parameters of a solve of a `dim`-D system of `unknowns` control points that
    /// this choice would factor on the CPU ([`FitSolver::factors`]) but that runs CG: `cg`
    /// with its tolerance tightened to [`DIRECT_CG_TOL`], so that it gives the
    /// factorisation's solution (the fit across rotation seams, whose coupled CG the factor
    /// only preconditions serially and K's block-Jacobi pair under mpirun, and every fit
    /// under mpirun, whose ranks run CG where the serial run factors); `cg` itself where the
    /// choice runs CG anyway.
    pub fn cg_params(self, dim: usize, unknowns: usize, cg: &CgParams) -> CgParams {
        let mut cg = *cg;
        if self.factors(dim, unknowns, true) {
            cg.rel_tol = cg.rel_tol.min(DIRECT_CG_TOL);
        }
        cg
    }
}

/// The relative residual of a CG standing in for the fit's sparse Cholesky
/// ([`FitSolver::cg_params`]). At the default `--cg-tol` (1e-6) the rotation-periodic
/// sectors' coupled fit, preconditioned by K's factor serially and by K's block-Jacobi pair
/// on the ranks, stopped up to 8e-7 of the diagonal apart (30° sector, 12 × 6 × 1 hexes,
/// uniform knots); at 1e-10 both are the direct solution to well below that (6e-11), for a
/// few iterations more (16 → 21 serially, 35 → 56 on the ranks, 90° sector).
pub const DIRECT_CG_TOL: f64 = 1e-10;

/// Fit parameters.
#[derive(Clone, Debug)]
pub struct FitParams {
    pub weights: FitWeights,
    /// CG or sparse Cholesky ([`FitSolver`]); distributed runs always use CG (to
    /// [`DIRECT_CG_TOL`] where the serial run factors).
    pub solver: FitSolver,
    pub cg: CgParams,
    pub targets: FitTargets,
    /// Sharp features of the input: smooth targets are reconstructed per patch and feature
    /// samples get [`FitWeights::feature`] (see [`features`]). `None` treats the boundary as
    /// one smooth surface.
    pub features: Option<std::sync::Arc<crate::mesh::features::Features>>,
    /// Weight W of the fitted map's kinks at C⁰ facets against moving control points
    /// ([`jumps`], `--facet-smoothing`); 0 (the default): the fit's control points are kept
    /// as they are.
    pub facet_smoothing: f64,
}

impl FitParams {
    /// The smooth-boundary mode: [`FitWeights::smooth`] with [`FitTargets::Smooth`].
    pub fn smooth() -> Self {
        FitParams {
            weights: FitWeights::smooth(),
            targets: FitTargets::Smooth(SmoothParams::default()),
            ..Default::default()
        }
    }
}

impl Default for FitParams {
    fn default() -> Self {
        FitParams {
            weights: FitWeights::position(),
            solver: FitSolver::default(),
            cg: CgParams {
                rel_tol: FIT_CG_TOL,
                ..CgParams::default()
            },
            targets: FitTargets::Chords,
            features: None,
            facet_smoothing: 0.0,
        }
    }
}

/// Default relative tolerance of the fit's CG (`--cg-tol`). The fitted map feeds threshold
/// decisions (the blend's accepted elements, the post-fit Q2 choice), and where the CG stops
/// depends on its preconditioner, which under MPI is each rank's block Jacobi: at 1e-6 the
/// outputs of 1, 2 and 4 ranks differ by up to 2.8e-6 of the bounding-box diagonal on a
/// generated cylinder of 1.5k hexes (4.2e-7 at 32k), and by 1.5e-4 at 292k hexes where
/// borderline blend decisions flipped. At `--cg-tol 1e-8` they agree to 2e-8 (1.5k), 6e-9
/// (32k) and 2.4e-9 (149k), with the same decisions, but the fit takes about half again the
/// iterations (a serial 100k-hex `curve` 2.8 s → 3.8 s), so 1e-6 stays the default.
///
/// Nor is a looser tolerance free. At 1e-5 the fit's CG takes about three quarters of the
/// iterations (52,728-hex cylinder 77 → 57, acoustics_mesh3d 105 → 82), and the written
/// nodes move by 2e-4 of their element's shortest edge on the cylinder and most real meshes,
/// but where the blend's decisions are borderline they flip: trixi NACA4412_2.msh holds back
/// 1,474 elements instead of 1,472 and a node moves by 0.28 of its element's edge, the su2
/// turbine 1,021 instead of 1,027 with its smallest scaled Jacobian 0.22253 instead of 0.22273.
pub const FIT_CG_TOL: f64 = 1e-6;

/// Largest fit weight; weights are relative, so this is no practical limit, but 1e308 would
/// overflow the assembled matrix (weights multiply squared residuals).
pub const MAX_WEIGHT: f64 = 1e12;

/// `--kink-angle`: degrees in (0, 360] (180 and above turn the kink test off). The command line
/// checks it with every fit, though only the smooth targets use it.
pub fn check_kink_angle(deg: f64) -> Result<(), ParamError> {
    above("--kink-angle", deg, 0.0, 360.0)
}

/// `--interior-kink-angle`: degrees in (0, 360] (180 and above turn the interior kinks off),
/// checked with every fit as [`check_kink_angle`].
pub fn check_interior_kink_angle(deg: f64) -> Result<(), ParamError> {
    above("--interior-kink-angle", deg, 0.0, 360.0)
}

impl FitParams {
    /// Weights (bounded by [`MAX_WEIGHT`]), CG and smooth-target parameters.
    pub fn check(&self) -> Result<(), ParamError> {
        let w = &self.weights;
        for (option, v) in [
            ("--w-corner", w.corner),
            ("--w-boundary-corner", w.boundary_corner),
            ("--w-midpoint", w.midpoint),
            ("--w-deep-midpoint", w.deep_midpoint.unwrap_or(0.0)),
            ("--w-extraordinary-midpoint", w.extraordinary_midpoint),
            ("--w-boundary-midpoint", w.boundary_midpoint),
            ("--w-frame-corner", w.frame_corner),
            ("--w-frame-midpoint", w.frame_midpoint),
            ("--w-feature", w.feature),
        ] {
            in_range(option, v, 0.0, MAX_WEIGHT)?;
        }
        self.cg.check()?;
        if let FitTargets::Smooth(s) = &self.targets {
            check_kink_angle(s.kink_angle_deg)?;
            check_interior_kink_angle(s.interior_kink_angle_deg)?;
            in_range("smooth feature angle", s.feature_angle_deg, 0.0, 180.0)?;
            in_range("smooth decay", s.decay, 0.0, 1e6)?;
        }
        Ok(())
    }
}

/// The weight of the kinks at C⁰ facets ([`FitParams::facet_smoothing`]) that brings the mean
/// facet angle of the real meshes with many Q2 elements (unstructured_refined_ball,
/// acoustics_mesh3d) under 0.7× the straight elevation's without holding back more elements
/// (0.01 leaves acoustics at 0.701×; 0.02 holds back 59 instead of 40 of spheremesh01's 113).
/// Not the default: the ranks do not run it, and where nearly every facet is C⁰ its solve
/// costs as much as the fit (70degCone 2.9× the job's CPU time; acoustics 1.6×, the
/// 52,728-hex cylinder 1.13×).
pub const FACET_SMOOTHING: f64 = 0.015;

/// What the fit did.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FitInfo {
    /// The solver that ran: [`FitSolver::Cg`] or [`FitSolver::Cholesky`] (0 iterations).
    pub solver: FitSolver,
    pub cg: CgInfo,
    pub unknowns: usize,
    pub nonzeros: usize,
    pub assembly_seconds: f64,
    pub solve_seconds: f64,
    /// How the coupled solve across rotation seams ran ([`FitSolve`]); `None` when the fit
    /// does not couple the coordinates.
    pub coupled: Option<CoupledRun>,
    /// What lowering the kinks at C⁰ facets did ([`jumps`]); `None` when it did not run.
    pub facet_jumps: Option<jumps::JumpInfo>,
}

/// Where the fit's coupled CG across rotation seams ran and what preconditioned it: always an
/// approximation of K⁻¹ ⊗ I₃ ([`rotated::OnK`]), whatever `--cg-preconditioner` asks for the
/// uncoupled fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct CoupledRun {
    /// `cpu`, or a device's executor name.
    pub device: &'static str,
    pub preconditioner: rotated::OnK,
}

impl CoupledRun {
    /// The coupled CG on the CPU ([`rotated::solve`]) with `preconditioner`.
    pub fn cpu(preconditioner: rotated::OnK) -> Self {
        CoupledRun {
            device: "cpu",
            preconditioner,
        }
    }
}

/// How the fit's normal equations are solved: K δ = b (the three coordinates apart) and,
/// across rotation seams, (K ⊗ I₃ + C) δ = b ([`rotated`]). Every closure
/// `FnOnce(NormalMatrix, &b, &mut δ, &CgParams)` is one, its coupled solve the CPU's.
pub trait FitSolve: Sized {
    /// K δ = `b` from `delta`; the solve owns K.
    fn solve(
        self,
        k: NormalMatrix,
        b: &[[f64; 3]],
        delta: &mut [[f64; 3]],
        cg: &CgParams,
    ) -> Result<CgInfo, CgError>;

    /// (K ⊗ I₃ + C) δ = `b` from `delta`; `factor`: whether the fit would factor K on the CPU
    /// ([`FitSolver::factors`]), where this solve then preconditions by K's factor (else by
    /// K's block-Jacobi pair). Returns the CG's figures, where it ran and its preconditioner.
    /// By default [`rotated::solve`] on the CPU.
    fn solve_coupled(
        self,
        k: NormalMatrix,
        c: &rotated::Coupling,
        b: &[[f64; 3]],
        delta: &mut [[f64; 3]],
        cg: &CgParams,
        factor: bool,
    ) -> Result<(CgInfo, CoupledRun), CgError> {
        let on_k = if factor {
            rotated::OnK::Factor
        } else {
            rotated::OnK::BlockJacobiPair
        };
        let info = rotated::solve(&k, c, b, delta, cg, on_k, &mut |_, _| {})?;
        Ok((info, CoupledRun::cpu(on_k)))
    }
}

impl<F> FitSolve for F
where
    F: FnOnce(NormalMatrix, &[[f64; 3]], &mut [[f64; 3]], &CgParams) -> Result<CgInfo, CgError>,
{
    fn solve(
        self,
        k: NormalMatrix,
        b: &[[f64; 3]],
        delta: &mut [[f64; 3]],
        cg: &CgParams,
    ) -> Result<CgInfo, CgError> {
        self(k, b, delta, cg)
    }
}

/// Assemble K and the right-hand side of the displacement system (F − K C0).
pub fn assemble(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    assemble_with_targets(space, mesh, topo, w, None)
}

/// [`assemble`] with the midpoint targets moved by `smooth` (None: the chords).
pub fn assemble_with_targets(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
    smooth: Option<&SmoothTargets>,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    assemble_with_features(space, mesh, topo, w, smooth, None)
}

/// The normal equations of the fit described by `params`: its targets (chords, or the smooth
/// reconstruction per feature patch), weights and features.
pub fn normal_equations(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    normal_equations_with(
        space,
        mesh,
        topo,
        params,
        smooth_targets(mesh, topo, params).as_ref(),
    )
}

/// The smooth-boundary models of the fit described by `params` (`None` with chord targets).
pub fn smooth_targets(
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
) -> Option<SmoothTargets> {
    smooth_targets_shared(mesh, topo, params, None, (&[], &[]))
}

/// [`smooth_targets`] on a rank's part of a distributed mesh and with the walls'
/// continuations across periodic seams ([`SmoothTargets::build_shared`]; `share` `None`:
/// the whole mesh): `partners` the wall vertices' and `links` the seams' vertex pairs
/// ([`crate::spline::seam::SeamView`]; empty: none).
pub fn smooth_targets_shared(
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    share: Option<&dyn InheritShare>,
    (partners, links): smooth::SeamSides,
) -> Option<SmoothTargets> {
    match params.targets {
        FitTargets::Chords => None,
        FitTargets::Smooth(p) => Some(SmoothTargets::build_shared(
            mesh,
            topo,
            &p,
            params.features.as_deref(),
            share,
            partners,
            links,
        )),
    }
}

/// [`normal_equations`] with the smooth targets built already ([`smooth_targets`]).
pub fn normal_equations_with(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    smooth: Option<&SmoothTargets>,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    assemble_with_features(
        space,
        mesh,
        topo,
        &params.weights,
        smooth,
        params.features.as_deref(),
    )
}

/// The fit's targets as a conforming quadratic map: per element the multilinear lattice moved
/// by the smooth-target corrections (chords without them), interpolated at {0, ½, 1}^d and
/// written in Bernstein form. Every target depends only on its entity (its vertices and their
/// models), so neighbours agree on shared points. It is the straight elevation plus the
/// boundary's curvature carried into the layers next to it: the middle state of the certified
/// blend of the validity stage.
pub struct TargetMap<'a> {
    pub mesh: &'a LinearMesh,
    pub topo: &'a Topology,
    pub smooth: Option<&'a SmoothTargets>,
}

impl crate::math::BezierElements for TargetMap<'_> {
    fn dim(&self) -> usize {
        self.mesh.dim
    }
    fn n_elements(&self) -> usize {
        self.mesh.n_elements()
    }
    fn bezier_net(&self, e: usize) -> BezierNet {
        let dim = self.mesh.dim;
        let mut v = rhs::multilinear_lattice(dim, &self.mesh.element_coords(e));
        if let Some(t) = self.smooth {
            let shift = t.corrections_at(self.mesh, self.topo, e, &v);
            for (p, s) in v.iter_mut().zip(shift) {
                *p = (DVec3::from(*p) + DVec3::from(s)).into();
            }
        }
        // Values at {0, ½, 1} to Bernstein points, line by line: b₁ = 2 v(½) − (v₀ + v₁)/2.
        rhs::map_lines(dim, &mut v, |[a, m, c]| [a, m * 2.0 - (a + c) * 0.5, c]);
        v
    }
}

/// [`assemble_with_targets`] with the samples on the sharp `features` weighted by
/// [`FitWeights::feature`].
pub fn assemble_with_features(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
    smooth: Option<&SmoothTargets>,
    features: Option<&crate::mesh::features::Features>,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    assemble_on(space, mesh, topo, w, (smooth, features), Summing::Host)
}

/// Where the values of the fit's K are summed: by the host ([`assembly::assemble_matrix`]), or
/// left to the solver ([`assembly::assemble_deferred`]: a GPU executor sums them on its
/// device, and the host sums a row with the same bits only where it uses one).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Summing {
    Host,
    Solver,
}

fn assemble_on(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
    (smooth, features): (
        Option<&SmoothTargets>,
        Option<&crate::mesh::features::Features>,
    ),
    summing: Summing,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    let blocks = ElementBlocks::with_features(space, mesh, topo, w, features);
    let rhs = rhs::displacement_rhs(space, mesh, topo, w, &blocks.masks, smooth);
    let k = match summing {
        Summing::Host => assembly::assemble_matrix(space, &blocks),
        Summing::Solver => assembly::assemble_deferred(space, &blocks),
    };
    (k, rhs)
}

/// Solve the least-squares fit; returns the fitted control points C*.
pub fn fit(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    mut progress: impl FnMut(usize, f64),
) -> Result<(Vec<[f64; 3]>, FitInfo), CgError> {
    fit_with(space, mesh, topo, params, |k, rhs, delta, cg| {
        k.pcg(rhs, delta, cg, &mut progress)
    })
}

/// [`fit`] with the normal equations solved by `solve(matrix, rhs, delta, cg)`, which owns
/// the matrix (the unknowns are displacements from the initial control points, starting at
/// 0), e.g. an executor's `pcg` (the GPU's).
pub fn fit_with(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    solve: impl FnOnce(
        NormalMatrix,
        &[[f64; 3]],
        &mut [[f64; 3]],
        &crate::solve::CgParams,
    ) -> Result<crate::solve::CgInfo, CgError>,
) -> Result<(Vec<[f64; 3]>, FitInfo), CgError> {
    fit_with_targets(
        space,
        mesh,
        topo,
        params,
        smooth_targets(mesh, topo, params).as_ref(),
        solve,
    )
}

/// [`fit_with`] given the smooth targets ([`smooth_targets`]).
pub fn fit_with_targets(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    smooth: Option<&SmoothTargets>,
    solve: impl FnOnce(
        NormalMatrix,
        &[[f64; 3]],
        &mut [[f64; 3]],
        &crate::solve::CgParams,
    ) -> Result<crate::solve::CgInfo, CgError>,
) -> Result<(Vec<[f64; 3]>, FitInfo), CgError> {
    fit_with_targets_from(
        space,
        mesh,
        topo,
        params,
        smooth,
        (None, Summing::Host),
        solve,
    )
}

/// [`fit_with_targets`] with the CG started from the control points `start` (one per control
/// point of `space`) instead of from the space's initial control points: a nearby solution,
/// such as the fit of a slightly different space, saves iterations. The stopping test is
/// relative to the right-hand side as from a cold start, so the result meets the same
/// tolerance. `summing` says where K's values are summed.
pub fn fit_with_targets_from(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    smooth: Option<&SmoothTargets>,
    (start, summing): (Option<&[[f64; 3]]>, Summing),
    solve: impl FnOnce(
        NormalMatrix,
        &[[f64; 3]],
        &mut [[f64; 3]],
        &crate::solve::CgParams,
    ) -> Result<crate::solve::CgInfo, CgError>,
) -> Result<(Vec<[f64; 3]>, FitInfo), CgError> {
    fit_with_solver(space, mesh, topo, params, smooth, (start, summing), solve)
}

/// [`fit_with_targets_from`] with the normal equations, coupled across rotation seams or
/// not, solved by `solver` ([`FitSolve`]).
pub fn fit_with_solver(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    smooth: Option<&SmoothTargets>,
    (start, summing): (Option<&[[f64; 3]]>, Summing),
    solver: impl FitSolve,
) -> Result<(Vec<[f64; 3]>, FitInfo), CgError> {
    let t = std::time::Instant::now();
    let features = params.features.as_deref();
    let targets = (smooth, features);
    let (mut k, mut rhs) = assemble_on(space, mesh, topo, &params.weights, targets, summing);
    // Across rotation seams the coordinates are coupled ([`rotated`]).
    let mut coupling = space.has_frames().then(|| {
        let features = params.features.as_deref();
        let blocks = ElementBlocks::with_features(space, mesh, topo, &params.weights, features);
        rotated::Coupling::of(space, &blocks).expect("a space with frames")
    });
    let scale = control_point_scales(space, &size_levels(mesh));
    if let Some(d) = &scale {
        k.scale_symmetric(d);
        if let Some(c) = &mut coupling {
            c.scale_symmetric(d);
        }
        for (r, &d) in rhs.iter_mut().zip(d) {
            *r = r.map(|x| d * x);
        }
    }
    let assembly_seconds = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    // The unknowns are displacements from the initial control points, scaled like K.
    let mut delta = match start {
        Some(start) => {
            assert_eq!(start.len(), k.n(), "one start per control point");
            space
                .control_points()
                .iter()
                .zip(start)
                .enumerate()
                .map(|(i, (c, x))| {
                    let d = scale.as_ref().map_or(1.0, |d| d[i]);
                    std::array::from_fn(|a| (x[a] - c[a]) / d)
                })
                .collect()
        }
        None => vec![[0.0; 3]; k.n()],
    };
    if start.is_some() {
        keep_closer_starts(&k, &rhs, &mut delta);
    }
    if params.cg.preconditioner.with_lines() && coupling.is_none() {
        k.set_lines(control_point_lines(space));
    }
    // The solve takes K (the CPU's blocked solvers release it as they reorder it).
    let (unknowns, nonzeros) = (k.n(), k.indices().len());
    let (cg, coupled) = match &coupling {
        // On the CPU, factored as the fit would factor K ([`rotated`]), and then run to the
        // factorisation's accuracy (on a device too).
        Some(c) => {
            let factor = params.solver.factors(space.dim(), k.n(), true);
            let cg = params.solver.cg_params(space.dim(), k.n(), &params.cg);
            let (info, device) = solver.solve_coupled(k, c, &rhs, &mut delta, &cg, factor)?;
            (info, Some(device))
        }
        None => (solver.solve(k, &rhs, &mut delta, &params.cg)?, None),
    };
    if let Some(d) = &scale {
        for (x, &d) in delta.iter_mut().zip(d) {
            *x = x.map(|x| d * x);
        }
    }
    let solve_seconds = t.elapsed().as_secs_f64();
    let c: Vec<[f64; 3]> = space
        .control_points()
        .iter()
        .zip(&delta)
        .map(|(c, d)| [c[0] + d[0], c[1] + d[1], c[2] + d[2]])
        .collect();
    Ok((
        c,
        FitInfo {
            solver: FitSolver::Cg,
            cg,
            unknowns,
            nonzeros,
            assembly_seconds,
            solve_seconds,
            coupled,
            facet_jumps: None,
        },
    ))
}

/// The lattice lines of `space`'s control points ([`crate::solve::lines`]), from the
/// stencils of its elements whose local nodes are distinct plain control points.
pub fn control_point_lines(space: &dyn FitSpace) -> crate::solve::lines::Lines {
    let len = if space.dim() == 3 { 27 } else { 9 };
    let (mut ids, mut stencils) = (Vec::new(), Vec::new());
    for e in 0..space.n_elements() {
        if space.element_factors(e, &mut ids).is_some() && ids.len() == len {
            stencils.extend_from_slice(&ids);
        }
    }
    crate::solve::lines::Lines::from_stencils(
        space.control_points().len(),
        stencils.chunks_exact(len),
    )
}

/// Zero every component of the start `delta` whose residual ‖rhs − K δ‖ is not below the
/// cold start's ‖rhs‖. Where a component's right-hand side is rounding noise (the normal
/// direction of a planar mesh or extrusion), a carried start's residual is rounding of K's
/// size, far above it, and the test relative to ‖rhs‖ could never be met.
fn keep_closer_starts(k: &NormalMatrix, rhs: &[[f64; 3]], delta: &mut [[f64; 3]]) {
    let mut kd = vec![[0.0; 3]; rhs.len()];
    k.apply(delta, &mut kd);
    let norms = start_norms(rhs.iter().zip(&kd));
    zero_farther_components(&norms, delta);
}

/// Per component, the squared norms of the residual `b − K δ` and of `b` (`[r²; b²]`) over
/// the rows given as `(b, K δ)` pairs: what [`keep_closer_starts`] judges a start by (a
/// distributed fit sums them over the rows' owners first).
pub(crate) fn start_norms<'a>(
    rows: impl Iterator<Item = (&'a [f64; 3], &'a [f64; 3])>,
) -> [f64; 6] {
    let mut norms = [0.0f64; 6];
    for (b, kd) in rows {
        for a in 0..3 {
            norms[a] += (b[a] - kd[a]).powi(2);
            norms[3 + a] += b[a] * b[a];
        }
    }
    norms
}

/// Zero every component of the start `delta` whose residual is not below the cold start's,
/// by the norms of [`start_norms`].
pub(crate) fn zero_farther_components(norms: &[f64; 6], delta: &mut [[f64; 3]]) {
    for a in (0..3).filter(|&a| norms[a] >= norms[3 + a]) {
        delta.iter_mut().for_each(|d| d[a] = 0.0);
    }
}

impl FitSpace for crate::spline::SplineSpace {
    fn dim(&self) -> usize {
        self.dim
    }
    fn n_elements(&self) -> usize {
        crate::spline::SplineSpace::n_elements(self)
    }
    fn control_points(&self) -> &[[f64; 3]] {
        &self.control_points
    }
    fn element_rows(
        &self,
        e: usize,
        offsets: &mut Vec<usize>,
        cols: &mut Vec<u32>,
        weights: &mut Vec<f64>,
    ) {
        // The caller's buffers, reused: the assembly asks for every element's rows on graded
        // meshes.
        let mut rows = crate::spline::ElementRows {
            offsets: std::mem::take(offsets),
            cols: std::mem::take(cols),
            weights: std::mem::take(weights),
        };
        self.extraction.rows(e, &mut rows);
        *offsets = rows.offsets;
        *cols = rows.cols;
        *weights = rows.weights;
    }
    fn bezier_net_with(&self, e: usize, cps: &[[f64; 3]]) -> BezierNet {
        self.element_bezier_with(e, cps)
    }
    fn net_shift(&self, e: usize) -> Option<BezierNet> {
        crate::spline::eval::shift_net(&self.extraction, e)
    }
    fn frames(&self, e: usize) -> Option<&[crate::spline::extraction::SeamFrame]> {
        self.extraction.frames(e)
    }
    fn has_frames(&self) -> bool {
        self.extraction.has_frames()
    }
    /// By sum factorisation: E_e = (M_z ⊗ M_y ⊗ M_x) N_e with N_e the local nodes' control
    /// point entries, so E_eᵀ f applies the transposed 1D matrices direction by direction
    /// (3 · 3^d · 3 multiply-adds each) and then N_eᵀ, instead of expanding the rows.
    fn add_transposed(&self, e: usize, f: &BezierNet, out: &mut Vec<(u32, [f64; 3])>) {
        let x = &self.extraction;
        let m = x.matrices(e);
        let n = x.n_local();
        let mut t = f.map(DVec3::from);
        for (d, md) in m.iter().enumerate().take(self.dim) {
            let stride = [1, 3, 9][d];
            let mut u = [DVec3::ZERO; 27];
            for (o, u) in u.iter_mut().enumerate().take(n) {
                let l = (o / stride) % 3;
                let base = o - l * stride;
                for (b, row) in md.iter().enumerate() {
                    let w = row[l];
                    if w != 0.0 {
                        *u += t[base + b * stride] * w;
                    }
                }
            }
            t = u;
        }
        let frames = x.frames(e);
        for (l, &node) in x.element_nodes(e).iter().enumerate() {
            for (g, w) in x.node_entries(node) {
                // A point seen rotated takes Rᵀ of its share ([`rotated`]).
                match frames.and_then(|f| f.iter().find(|f| f.0 == g)) {
                    Some((_, r)) => out.push((g, (rotated::rotate_back(r, t[l]) * w).into())),
                    None => out.push((g, (t[l] * w).into())),
                }
            }
        }
    }
    /// Elements whose local nodes are all plain control points (spline elements, and Q2
    /// elements made only of own nodes): E_e = (M_z ⊗ M_y ⊗ M_x) · selection, keyed by the
    /// three 1D operators.
    fn element_pattern(&self, e: usize, ids: &mut Vec<u32>) -> Option<u64> {
        let x = &self.extraction;
        // The key names the 1D operators only: graded rows get their own matrices.
        if !x.is_uniform(e) || !plain_distinct_nodes(self, e, ids) {
            return None;
        }
        Some(x.ops[e].iter().fold(0u64, |k, op| k * 8 + *op as u64))
    }
    fn element_factors(&self, e: usize, ids: &mut Vec<u32>) -> Option<[[[f64; 3]; 3]; 3]> {
        plain_distinct_nodes(self, e, ids).then(|| self.extraction.matrices(e))
    }
}

/// Whether element `e`'s local nodes are distinct plain control points (then written to
/// `ids`): the elements whose E_e is a Kronecker product times a selection.
fn plain_distinct_nodes(space: &crate::spline::SplineSpace, e: usize, ids: &mut Vec<u32>) -> bool {
    let x = &space.extraction;
    let nodes = x.element_nodes(e);
    if nodes.iter().any(|&n| n as usize >= x.n_control) {
        return false;
    }
    let mut sorted = [0u32; 27];
    let sorted = &mut sorted[..nodes.len()];
    sorted.copy_from_slice(nodes);
    sorted.sort_unstable();
    if sorted.windows(2).any(|w| w[0] == w[1]) {
        return false;
    }
    ids.clear();
    ids.extend_from_slice(nodes);
    true
}
