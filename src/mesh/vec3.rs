//! 3-vector helpers on `[f64; 3]` for the code that still computes on arrays: the smooth
//! boundary targets (`fit/smooth*.rs`) and the validity blend (`validity/blend*.rs`). They
//! are thin wrappers over glam's `DVec3` ([`crate::math::linalg`]),
//! whose `dot`, `cross` and `length` round exactly like the written-out formulas; new code
//! should compute on `DVec3` directly and keep arrays at its storage boundary.

use crate::math::linalg::DVec3;

pub(crate) fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    (DVec3::from(a) + DVec3::from(b)).into()
}
pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    (DVec3::from(a) - DVec3::from(b)).into()
}
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    DVec3::from(a).dot(DVec3::from(b))
}
pub(crate) fn norm(a: [f64; 3]) -> f64 {
    DVec3::from(a).length()
}
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    DVec3::from(a).cross(DVec3::from(b)).into()
}
