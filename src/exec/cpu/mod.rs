//! CPU twins of the WGSL kernels in `shaders/`: one file per shader, same name, same loop
//! structure, inputs in the shader's binding order, generic over the shader's `real` (f32 or
//! f64). They exist to cross-check the GPU bit for bit in structure; the reference for
//! correctness stays the f64 CPU pipeline (`sample`, `validity`, `solve`), and the tests also
//! check both against independent oracles.

pub mod assemble;
pub mod cg;
pub mod coupling;
pub mod dot;
pub mod evaluate;
pub mod executor;
pub mod jacobian_check;
pub mod local_newton;
pub mod spmv;

use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

/// The shaders' `real`: f32 or f64.
pub trait Real:
    Copy
    + Default
    + PartialOrd
    + Send
    + Sync
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + std::fmt::Debug
    + 'static
{
    fn of(x: f64) -> Self;
    fn to_f64(self) -> f64;
    fn abs(self) -> Self;
    fn min(self, o: Self) -> Self;
    fn max(self, o: Self) -> Self;
}

macro_rules! real {
    ($t:ty) => {
        impl Real for $t {
            fn of(x: f64) -> Self {
                x as $t
            }
            fn to_f64(self) -> f64 {
                self as f64
            }
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            fn min(self, o: Self) -> Self {
                <$t>::min(self, o)
            }
            fn max(self, o: Self) -> Self {
                <$t>::max(self, o)
            }
        }
    };
}
real!(f32);
real!(f64);

/// A WGSL `vec4<real>`.
pub type Vec4<T> = [T; 4];
