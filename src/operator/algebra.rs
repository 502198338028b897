//! Composition, adjoint view, scaling, sums and the normal operator.

use crate::error::{Error, Result};
use crate::linalg::{axpy, scale};
use crate::real::Real;

use super::LinearOperator;

/// The product `A·B` (apply `B`, then `A`). Adjoint: `B*·A*`.
#[derive(Debug, Clone)]
pub struct Compose<A, B> {
    a: A,
    b: B,
}

impl<A, B> Compose<A, B> {
    /// Builds `a · b`.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if `a.ncols() != b.nrows()`.
    pub fn new<T: Real>(a: A, b: B) -> Result<Self>
    where
        A: LinearOperator<T>,
        B: LinearOperator<T>,
    {
        if a.ncols() != b.nrows() {
            return Err(Error::shape(
                format!(
                    "compose: columns of {} vs rows of {}",
                    a.describe(),
                    b.describe()
                ),
                a.ncols(),
                b.nrows(),
            ));
        }
        Ok(Compose { a, b })
    }

    /// The two factors `(a, b)` of `a · b`.
    pub fn into_parts(self) -> (A, B) {
        (self.a, self.b)
    }
}

impl<T: Real, A: LinearOperator<T>, B: LinearOperator<T>> LinearOperator<T> for Compose<A, B> {
    fn nrows(&self) -> usize {
        self.a.nrows()
    }
    fn ncols(&self) -> usize {
        self.b.ncols()
    }
    fn scratch_len(&self) -> usize {
        self.b.nrows() + self.a.scratch_len().max(self.b.scratch_len())
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        let (mid, rest) = scratch.split_at_mut(self.b.nrows());
        self.b.forward_kernel(x, mid, rest);
        self.a.forward_kernel(mid, y, rest);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        let (mid, rest) = scratch.split_at_mut(self.b.nrows());
        self.a.adjoint_kernel(y, mid, rest);
        self.b.adjoint_kernel(mid, x, rest);
    }
    fn describe(&self) -> String {
        format!("Compose({}, {})", self.a.describe(), self.b.describe())
    }
}

/// The adjoint view `A*` of an operator: its forward kernel is `A`'s adjoint kernel and vice versa.
#[derive(Debug, Clone)]
pub struct Adjoint<A>(A);

impl<A> Adjoint<A> {
    /// Wraps `a` as `a*`.
    pub fn new(a: A) -> Self {
        Adjoint(a)
    }

    /// The adjoint of the adjoint: the original operator, unwrapped. This inherent method takes
    /// precedence over [`OperatorExt::adjoint`](super::OperatorExt::adjoint), so `a.adjoint()
    /// .adjoint()` has the type of `a`.
    pub fn adjoint(self) -> A {
        self.0
    }

    /// The wrapped operator.
    pub fn inner(&self) -> &A {
        &self.0
    }
}

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for Adjoint<A> {
    fn nrows(&self) -> usize {
        self.0.ncols()
    }
    fn ncols(&self) -> usize {
        self.0.nrows()
    }
    fn scratch_len(&self) -> usize {
        self.0.scratch_len()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        self.0.adjoint_kernel(x, y, scratch)
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        self.0.forward_kernel(y, x, scratch)
    }
    fn describe(&self) -> String {
        format!("Adjoint({})", self.0.describe())
    }
}

/// `α·A` for a finite real α. Adjoint: `α·A*`.
#[derive(Debug, Clone)]
pub struct Scaled<A, T> {
    a: A,
    alpha: T,
}

impl<A, T: Real> Scaled<A, T> {
    /// Builds `alpha · a`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `alpha` is NaN or infinite.
    pub fn new(a: A, alpha: T) -> Result<Self> {
        if !alpha.is_finite() {
            return Err(Error::param(
                "alpha",
                format!(
                    "scale factor must be finite, got {}",
                    crate::units::number(alpha)
                ),
            ));
        }
        Ok(Scaled { a, alpha })
    }

    /// The scale factor.
    pub fn alpha(&self) -> T {
        self.alpha
    }
}

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for Scaled<A, T> {
    fn nrows(&self) -> usize {
        self.a.nrows()
    }
    fn ncols(&self) -> usize {
        self.a.ncols()
    }
    fn scratch_len(&self) -> usize {
        self.a.scratch_len()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        self.a.forward_kernel(x, y, scratch);
        scale(self.alpha, y);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        self.a.adjoint_kernel(y, x, scratch);
        scale(self.alpha, x);
    }
    fn describe(&self) -> String {
        format!("Scaled({}, {})", self.alpha, self.a.describe())
    }
}

/// `A + β·B` (β = 1 for a sum, −1 for a difference). Adjoint: `A* + β·B*`.
#[derive(Debug, Clone)]
pub struct Sum<A, B, T> {
    a: A,
    b: B,
    beta: T,
}

impl<A, B, T: Real> Sum<A, B, T> {
    /// Builds `a + beta · b`.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if the shapes differ, [`Error::InvalidParameter`] if `beta` is not
    /// finite.
    pub fn new(a: A, b: B, beta: T) -> Result<Self>
    where
        A: LinearOperator<T>,
        B: LinearOperator<T>,
    {
        if a.nrows() != b.nrows() {
            return Err(Error::shape(
                format!("sum: rows of {} vs rows of {}", a.describe(), b.describe()),
                a.nrows(),
                b.nrows(),
            ));
        }
        if a.ncols() != b.ncols() {
            return Err(Error::shape(
                format!(
                    "sum: columns of {} vs columns of {}",
                    a.describe(),
                    b.describe()
                ),
                a.ncols(),
                b.ncols(),
            ));
        }
        if !beta.is_finite() {
            return Err(Error::param(
                "beta",
                format!(
                    "coefficient must be finite, got {}",
                    crate::units::number(beta)
                ),
            ));
        }
        Ok(Sum { a, b, beta })
    }
}

impl<T: Real, A: LinearOperator<T>, B: LinearOperator<T>> LinearOperator<T> for Sum<A, B, T> {
    fn nrows(&self) -> usize {
        self.a.nrows()
    }
    fn ncols(&self) -> usize {
        self.a.ncols()
    }
    fn scratch_len(&self) -> usize {
        self.a.nrows().max(self.a.ncols()) + self.a.scratch_len().max(self.b.scratch_len())
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        let (tmp, rest) = scratch.split_at_mut(self.a.nrows().max(self.a.ncols()));
        let tmp = &mut tmp[..y.len()];
        self.a.forward_kernel(x, y, rest);
        self.b.forward_kernel(x, tmp, rest);
        axpy(self.beta, tmp, y);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        let (tmp, rest) = scratch.split_at_mut(self.a.nrows().max(self.a.ncols()));
        let tmp = &mut tmp[..x.len()];
        self.a.adjoint_kernel(y, x, rest);
        self.b.adjoint_kernel(y, tmp, rest);
        axpy(self.beta, tmp, x);
    }
    fn describe(&self) -> String {
        if self.beta == T::one() {
            format!("Sum({}, {})", self.a.describe(), self.b.describe())
        } else if self.beta == -T::one() {
            format!("Difference({}, {})", self.a.describe(), self.b.describe())
        } else {
            format!(
                "Sum({}, {}·{})",
                self.a.describe(),
                self.beta,
                self.b.describe()
            )
        }
    }
}

/// The normal operator `A*A`: square (`ncols × ncols`) and self-adjoint.
#[derive(Debug, Clone)]
pub struct Normal<A>(A);

impl<A> Normal<A> {
    /// Builds `a* a`.
    pub fn new(a: A) -> Self {
        Normal(a)
    }

    /// The operator `A` of `A*A`.
    pub fn inner(&self) -> &A {
        &self.0
    }
}

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for Normal<A> {
    fn nrows(&self) -> usize {
        self.0.ncols()
    }
    fn ncols(&self) -> usize {
        self.0.ncols()
    }
    fn scratch_len(&self) -> usize {
        self.0.nrows() + self.0.scratch_len()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        let (mid, rest) = scratch.split_at_mut(self.0.nrows());
        self.0.forward_kernel(x, mid, rest);
        self.0.adjoint_kernel(mid, y, rest);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        self.forward_kernel(y, x, scratch)
    }
    fn describe(&self) -> String {
        format!("Normal({})", self.0.describe())
    }
}
