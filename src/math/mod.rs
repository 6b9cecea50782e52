//! The foundation layer: polynomial bases, quadrature and small linear algebra that every
//! other module may use, and that uses nothing above it.
//!
//! * [`bernstein`]: quadratic Bernstein polynomials, the [`BezierNet`] of an element, the
//!   [`Lattice`] of its values at {0, ½, 1}^d, and the [`BezierElements`] trait through which
//!   the spline space, the straight input, the fit's targets and the validity blends hand
//!   their element maps to sampling and certification.
//! * [`lagrange`]: the equispaced Lagrange basis of order-p output elements.
//! * [`quadrature`]: Gauss–Legendre rules on \[0, 1\].
//! * [`reference`](mod@reference): the reference quad and hex, their corners, local sides and local edges.
//! * [`linalg`]: 3-vectors and 3×3 matrices on glam (`DVec3`, `DMat3`), with the formulas
//!   whose rounding the outputs depend on written out where glam's differ.
//!
//! Invariant of the whole layer: results are bit-for-bit those of the formulas as written
//! (summation order included), because certified outputs are compared byte for byte across
//! versions, backends and thread counts.

pub mod bernstein;
pub mod lagrange;
pub mod linalg;
pub mod quadrature;
pub mod reference;

pub use bernstein::{BezierElements, BezierNet, Lattice};
