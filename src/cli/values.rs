//! The command line's spelling of the library's enumerated options: one clap `ValueEnum` per
//! option, mapped to the library's type (the library carries no clap types).
//!
//! Input: the words clap accepts (`--fit smooth`, `--msh-version 2.2`, `generate ogrid`).
//! Output: the library's values, through `From`. Invariant: each enum here lists, in the same
//! order, the variants of the library type it maps to, and the mapping is exhaustive both ways
//! where the library type is plain, so a variant added to the library and not here fails to
//! compile; the help texts are the command line's own.

use polyspline::elastic::ElasticPreconditioner as LibElasticPreconditioner;
use polyspline::elastic::ElasticSolver as LibElasticSolver;
use polyspline::energy::EnergySolver as LibEnergySolver;
use polyspline::exec::gpu::{BackendChoice as LibBackendChoice, Precision as LibPrecision};
use polyspline::fit::{FitPreset as LibFitPreset, FitSolver as LibFitSolver};
use polyspline::io::gmsh_write::MshVersion as LibMshVersion;
use polyspline::io::vtu_write::VtuEncoding as LibVtuEncoding;
use polyspline::mesh::generate::boundary_layer::Wall;
use polyspline::mesh::generate::{Kind, Shape};
use polyspline::solve::CgPreconditioner as LibCgPreconditioner;
use polyspline::solve::block_jacobi::DEFAULT_BLOCK;
use polyspline::spline::KnotIntervals as LibKnotIntervals;
use polyspline::validity::LineSearchMode as LibLineSearchMode;

/// A `ValueEnum` with the variants of a plain library enum, and `From` both ways.
macro_rules! value_enum {
    ($(#[$meta:meta])* $name:ident => $lib:ident { $($(#[$vmeta:meta])* $variant:ident,)* }) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
        pub(super) enum $name {
            $($(#[$vmeta])* $variant,)*
        }

        impl From<$name> for $lib {
            fn from(value: $name) -> $lib {
                match value {
                    $($name::$variant => $lib::$variant,)*
                }
            }
        }

        impl From<$lib> for $name {
            fn from(value: $lib) -> $name {
                match value {
                    $($lib::$variant => $name::$variant,)*
                }
            }
        }
    };
}

value_enum! {
    /// `curve --fit`.
    FitPreset => LibFitPreset {
        #[value(help = "No fit: sample the initial spline map")]
        None,
        #[value(help = "The paper's position weights (least squares, then a certified line search)")]
        Position,
        #[value(help = "The paper's position + frame weights")]
        Frame,
        #[value(help = "Midpoint targets from a local reconstruction of the smooth boundary instead \
            of the straight chords (more accurate curved boundaries)")]
        Smooth,
        #[value(help = "`smooth`, then the element degeneration energy minimised under the det J \
            certificate (paper §2.4, docs/energy.md)")]
        Energy,
    }
}

value_enum! {
    /// `curve --knot-intervals`.
    KnotIntervals => LibKnotIntervals {
        #[value(help = "Every knot interval 1 (the paper's construction)")]
        Uniform,
        #[value(help = "Knot intervals from the cells' extents, one ratio per knot surface: \
            graded (boundary-layer) grids are reproduced exactly and stay C¹")]
        Graded,
        #[value(help = "Graded where at least 30 % of the interior facets lie on \
            consistently graded knot surfaces (boundary-layer grids; one spline pass), else \
            uniform, and graded where the certified blend then holds back more than a tenth \
            of the elements and graded knots hold back at most half as many with a fitted \
            boundary within 1.1× of uniform knots' (a second pass; the report's \
            `knot_intervals` and `knot_passes` name the knots used and the passes; \
            the same choice under mpirun)")]
        Auto,
    }
}

value_enum! {
    /// `curve --fit-solver`.
    FitSolver => LibFitSolver {
        #[value(help = "Sparse Cholesky for systems of at most [`FitSolver::DIRECT_2D`] (2D) or \
            [`FitSolver::DIRECT_3D`] (3D) control points on the CPU backend, CG otherwise. Both \
            solve the same system; CG stops at `--cg-tol`, the factorisation at rounding")]
        Auto,
        #[value(help = "Preconditioned CG ([`crate::solve`]) on any size and backend")]
        Cg,
        #[value(help = "Sparse Cholesky ([`crate::solve::direct`]) on any size, on the CPU")]
        Cholesky,
    }
}

value_enum! {
    /// `curve --energy-solver`.
    EnergySolver => LibEnergySolver {
        #[value(help = "Global L-BFGS with a certified Armijo line search")]
        Lbfgs,
        #[value(help = "Coloured local Newton (one control point at a time, a colour in parallel)")]
        Colored,
    }
}

value_enum! {
    /// `--elastic-preconditioner`.
    ElasticPreconditioner => LibElasticPreconditioner {
        #[value(help = "The inverse of the diagonal of K")]
        Jacobi,
        #[value(help = "The inverse of each node's d×d diagonal block of K (couples a node's \
            components, which matters as ν → 0.5)")]
        BlockJacobi,
        #[value(help = "Symmetric block Gauss–Seidel: a forward then a backward sweep over the \
            nodes with the d×d diagonal blocks inverted (SSOR with ω = 1; sequential, about one \
            matrix product)")]
        BlockSgs,
    }
}

value_enum! {
    /// `curve --elastic-solver`, `compare --elastic-solver`.
    ElasticSolver => LibElasticSolver {
        #[value(help = "Sparse Cholesky when its factor stays under 2.4e8 entries, CG otherwise")]
        Auto,
        #[value(help = "Preconditioned CG (--elastic-preconditioner)")]
        Cg,
        #[value(help = "Sparse Cholesky whatever the size of its factor")]
        Cholesky,
    }
}

value_enum! {
    /// `curve --line-search`.
    LineSearchMode => LibLineSearchMode {
        #[value(help = "One α for all control points (paper §2.3)")]
        Global,
        #[value(help = "A factor per control point, halved only around elements that are not certified")]
        Local,
    }
}

value_enum! {
    /// `--precision`.
    Precision => LibPrecision {
        #[value(help = "f32 everywhere (portable); accuracy from element-anchored coordinates and \
            displacement unknowns with f64 residuals on the CPU")]
        F32,
        #[value(help = "f64 (needs `SHADER_F64`; lavapipe has it, Metal has not)")]
        F64,
    }
}

value_enum! {
    /// `--backend`.
    BackendChoice => LibBackendChoice {
        #[value(help = "A hardware GPU when there is one, the CPU otherwise (never a software adapter)")]
        Auto,
        #[value(help = "The CPU reference path")]
        Cpu,
        #[value(help = "Any GPU adapter, a software one such as lavapipe included; an error without one")]
        Gpu,
    }
}

value_enum! {
    /// `curve --vtu-encoding`.
    VtuEncoding => LibVtuEncoding {
        Ascii,
        Base64,
        Appended,
    }
}

value_enum! {
    /// `curve --msh-version`.
    MshVersion => LibMshVersion {
        #[value(name = "4.1")]
        V41,
        #[value(name = "2.2")]
        V22,
    }
}

/// `curve --cg-preconditioner`: block Jacobi with the library's default aggregate size.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum CgPreconditioner {
    Jacobi,
    BlockJacobi,
    BlockSgs,
    BlockJacobiPair,
    BlockJacobiLines,
}

impl From<CgPreconditioner> for LibCgPreconditioner {
    fn from(value: CgPreconditioner) -> Self {
        match value {
            CgPreconditioner::Jacobi => LibCgPreconditioner::Jacobi,
            CgPreconditioner::BlockJacobi => LibCgPreconditioner::BlockJacobi {
                size: DEFAULT_BLOCK,
            },
            CgPreconditioner::BlockSgs => LibCgPreconditioner::BlockSgs {
                size: DEFAULT_BLOCK,
            },
            CgPreconditioner::BlockJacobiPair => LibCgPreconditioner::BlockJacobiPair {
                size: DEFAULT_BLOCK,
            },
            CgPreconditioner::BlockJacobiLines => LibCgPreconditioner::BlockJacobiLines {
                size: DEFAULT_BLOCK,
            },
        }
    }
}

impl From<LibCgPreconditioner> for CgPreconditioner {
    fn from(value: LibCgPreconditioner) -> Self {
        match value {
            LibCgPreconditioner::Jacobi => CgPreconditioner::Jacobi,
            LibCgPreconditioner::BlockJacobi { .. } => CgPreconditioner::BlockJacobi,
            LibCgPreconditioner::BlockSgs { .. } => CgPreconditioner::BlockSgs,
            LibCgPreconditioner::BlockJacobiPair { .. } => CgPreconditioner::BlockJacobiPair,
            LibCgPreconditioner::BlockJacobiLines { .. } => CgPreconditioner::BlockJacobiLines,
        }
    }
}

/// `curve --method`: the elastic method's material and solver come from their own options.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum Method {
    Iga,
    Elastic,
}

/// `generate SHAPE`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum GenerateShape {
    #[value(help = "2D butterfly disc (valence-3 vertices)")]
    Disc,
    #[value(help = "The disc extruded along z: a solid cylinder of height 2 (valence-3 edges)")]
    Cylinder,
    #[value(help = "The disc revolved into a torus (major radius 3, tube radius 1)")]
    Torus,
    #[value(help = "Boundary-layer O-grid around `--wall`")]
    Ogrid,
    #[value(help = "Boundary-layer C-grid around a NACA 00xx airfoil with a wake cut")]
    Cgrid,
    #[value(
        help = "Periodic channel over a bump `--bump` (x-periodic, $Periodic pair periodic_left:periodic_right)"
    )]
    Channel,
    #[value(
        help = "Annular sector of `--sector` degrees between r = 1 and 2 (rotation-periodic, periodic_lo:periodic_hi)"
    )]
    Sector,
}

impl From<GenerateShape> for Shape {
    fn from(value: GenerateShape) -> Self {
        match value {
            GenerateShape::Disc => Shape::Benchmark(Kind::Disc),
            GenerateShape::Cylinder => Shape::Benchmark(Kind::Cylinder),
            GenerateShape::Torus => Shape::Benchmark(Kind::Torus),
            GenerateShape::Ogrid => Shape::Ogrid,
            GenerateShape::Cgrid => Shape::Cgrid,
            GenerateShape::Channel => Shape::Channel,
            GenerateShape::Sector => Shape::Sector,
        }
    }
}

/// `generate --wall`, each with its default thickness.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum WallShape {
    #[value(help = "Semi-axes 1 and `--thickness` (chord 2)")]
    Ellipse,
    #[value(help = "Radius 1 (chord 2)")]
    Circle,
    #[value(help = "NACA 00xx of chord 1, thickness `--thickness`, closed trailing edge")]
    Naca,
}

impl From<WallShape> for Wall {
    fn from(value: WallShape) -> Self {
        match value {
            WallShape::Ellipse => Wall::ELLIPSE,
            WallShape::Circle => Wall::Circle,
            WallShape::Naca => Wall::NACA_0012,
        }
    }
}
