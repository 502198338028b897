//! The scalar types the crate computes with.

use std::fmt::{Debug, Display, LowerExp};
use std::iter::Sum;

use num_traits::Float;

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// A real floating-point scalar: implemented for `f32` and `f64` only.
///
/// It gathers what the operators and solvers need from [`num_traits::Float`], [`rustfft::FftNum`]
/// (FFT convolution), [`ndarray::ScalarOperand`] and [`nalgebra::Scalar`] (matrix wrappers), plus
/// lossless widening to `f64` and narrowing from it. Long sums in the crate are accumulated in
/// `f64` whatever `T` is.
///
/// `Float` and `FftNum` both bring an `abs` method: in generic code write `Float::abs(x)` (or work in
/// `f64` through [`Real::as_f64`]).
pub trait Real:
    Float
    + rustfft::FftNum
    + ndarray::ScalarOperand
    + nalgebra::Scalar
    + Default
    + Display
    + LowerExp
    + Debug
    + Sum
    + Send
    + Sync
    + 'static
    + sealed::Sealed
    + crate::simd::Wide
{
    /// Name of the type, `"f32"` or `"f64"`.
    const NAME: &'static str;
    /// Machine epsilon.
    const EPS: f64;
    /// Default tolerance of [`crate::operator::dot_test`] for operators in this precision.
    const DOT_TEST_TOL: f64;

    /// Widens to `f64` (exact).
    fn as_f64(self) -> f64;
    /// Narrows from `f64` (rounds to nearest).
    fn of_f64(v: f64) -> Self;
}

impl Real for f32 {
    const NAME: &'static str = "f32";
    const EPS: f64 = f32::EPSILON as f64;
    const DOT_TEST_TOL: f64 = 1e-4;
    #[inline(always)]
    fn as_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn of_f64(v: f64) -> Self {
        v as f32
    }
}

impl Real for f64 {
    const NAME: &'static str = "f64";
    const EPS: f64 = f64::EPSILON;
    const DOT_TEST_TOL: f64 = 1e-10;
    #[inline(always)]
    fn as_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn of_f64(v: f64) -> Self {
        v
    }
}
