//! Matrix-free linear operators and their algebra.
//!
//! A [`LinearOperator`] maps vectors of length [`ncols`](LinearOperator::ncols) to vectors of length
//! [`nrows`](LinearOperator::nrows). Implementors write two kernels, the forward product y = Ax and
//! the adjoint product x = A*y, each overwriting a caller-provided output with the help of an
//! optional caller-provided scratch buffer. Everything else is derived:
//!
//! * the checked entry points [`apply`](LinearOperator::apply),
//!   [`apply_adjoint`](LinearOperator::apply_adjoint) and their `_with_scratch` forms, which verify
//!   every length and panic with a message naming both lengths when a buffer is wrong;
//! * the combinators of [`OperatorExt`] (composition, adjoint view, scaling, sums and differences,
//!   the normal operator) and the stacks ([`VStack`], [`HStack`], [`BlockDiag`]), whose adjoints are
//!   built from the adjoints of their parts and whose shapes are checked when the expression is
//!   built;
//! * [`to_dense`](LinearOperator::to_dense), [`dot_test`] and [`operator_norm`].
//!
//! `&A`, `Box<A>` and `Arc<A>` are operators whenever `A` is, and the trait is object safe, so
//! expressions can be assembled at run time from `Box<dyn LinearOperator<T>>`.
//!
//! # Example
//! ```
//! use rdlidar::operator::{Diagonal, Gradient2D, LinearOperator, OperatorExt, dot_test};
//!
//! # fn main() -> rdlidar::Result<()> {
//! // The TV-like operator ∇·D on a 4×5 grid, and its normal operator D*∇*∇D.
//! let d = Diagonal::new((0..20).map(|i| 1.0 + i as f64).collect())?;
//! let grad = Gradient2D::<f64>::new(4, 5)?;
//! let op = grad.compose(d)?;
//! assert_eq!((op.nrows(), op.ncols()), (40, 20));
//! let report = dot_test(&op, 7)?;
//! assert!(report.gap < 1e-12);
//!
//! let normal = op.normal();
//! let x: Vec<f64> = (0..20).map(|i| 1.0 / (1.0 + i as f64)).collect(); // D·x is constant
//! let mut y = vec![0.0; 20];
//! normal.apply(&x, &mut y); // and a constant image has zero gradient
//! assert!(y.iter().all(|v| v.abs() < 1e-12));
//! # Ok(())
//! # }
//! ```

mod algebra;
mod basic;
mod convolve;
mod counted;
mod gradient;
mod matrix;
mod norm;
mod part;
pub(crate) mod pixel;
mod stack;
mod testing;

use std::sync::Arc;

use ndarray::Array2;

pub use algebra::{Adjoint, Compose, Normal, Scaled, Sum};
pub use basic::{Diagonal, Identity, Restriction, Zero};
pub use convolve::{ConvMethod, ConvMode, Convolve1D};
pub use counted::{Applies, Counted};
pub use gradient::Gradient2D;
pub use matrix::{DenseMatrix, NalgebraMatrix, SparseMatrix};
pub use norm::{operator_norm, NormEstimate, NormStop, PowerIteration};
pub(crate) use part::sum_over;
pub use part::Part;
pub use pixel::{check_pixels, PixelColumns, VoxelOperator};
pub use stack::{BlockDiag, HStack, VStack};
pub use testing::{catalogue, dot_test, dot_test_sweep, DotTest, DotTestReport, SweepRow};

use crate::error::Result;
use crate::real::Real;
use crate::space::{Space, WHOLE};

/// A boxed operator, for expressions assembled at run time.
pub type BoxedOperator<T> = Box<dyn LinearOperator<T>>;

/// A linear map from `T^ncols` to `T^nrows`, applied without forming its matrix.
///
/// # Implementing
/// Write [`nrows`](Self::nrows), [`ncols`](Self::ncols) and the two kernels
/// [`forward_kernel`](Self::forward_kernel) and [`adjoint_kernel`](Self::adjoint_kernel); declare
/// [`scratch_len`](Self::scratch_len) if the kernels need working space. The kernels receive
/// buffers whose lengths have been checked (`x.len() == ncols`, `y.len() == nrows`,
/// `scratch.len() >= scratch_len`), must overwrite their whole output, and may leave anything in
/// the scratch buffer. Check the adjoint with [`dot_test`] (see `docs/operators.md`).
///
/// # Using
/// Call [`apply`](Self::apply) and [`apply_adjoint`](Self::apply_adjoint) (they allocate the
/// scratch buffer if one is needed), or their `_with_scratch` forms with a buffer allocated once,
/// which never allocate. Do not call the kernels directly.
///
/// # Panics
/// The `apply*` methods panic when a buffer has the wrong length, with a message that names the
/// expected and the given length. Such a mismatch is a programming error; shapes of user data are
/// checked when operators are built, and reported as [`Error`](crate::Error)s.
pub trait LinearOperator<T: Real>: Send + Sync {
    /// Length of the output of [`apply`](Self::apply) (rows of the matrix).
    fn nrows(&self) -> usize;

    /// Length of the input of [`apply`](Self::apply) (columns of the matrix).
    fn ncols(&self) -> usize;

    /// Number of scalars of working space the kernels need (0 by default).
    fn scratch_len(&self) -> usize {
        0
    }

    /// Kernel of y = A·x. Lengths are checked by the caller; `y` is overwritten.
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]);

    /// Kernel of x = A*·y. Lengths are checked by the caller; `x` is overwritten.
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]);

    /// A short description of the operator, e.g. `"Compose(Diagonal(5), Identity(5))"`.
    fn describe(&self) -> String {
        format!("Operator({}x{})", self.nrows(), self.ncols())
    }

    /// The operator restricted to `columns`: A·Rᵀ, whose input holds one value per listed column
    /// (in the given order, repeats allowed) and whose output is A's. Solvers that work on a
    /// support (least squares on a few columns) apply this instead of A.
    ///
    /// By default the composition of A with the adjoint of a [`Restriction`], which applies the
    /// whole of A in both directions. Operators whose columns are cheaper to apply a few at a time
    /// override it; the result must equal the default up to round-off.
    ///
    /// # Errors
    /// [`Error::IndexOutOfBounds`](crate::Error::IndexOutOfBounds) for a column not below
    /// [`ncols`](Self::ncols).
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(basic::ColumnRestriction::new(self, columns)?))
    }

    /// The same operator applied in single precision, for iterations whose accuracy is bounded
    /// far above `f32`'s rounding (message passing, whose iterates are decided at its noise
    /// level): the same matrix with its values rounded to `f32`, at about half the cost of a
    /// wider type's applications. `None` by default, and for an operator that already computes
    /// in `f32` (there is nothing to gain).
    fn single(&self) -> Option<Box<dyn LinearOperator<f32> + '_>> {
        None
    }

    /// The space of the operator's input, the unknowns: [`Whole`](crate::space::Whole) by
    /// default. An operator whose input is this process's part of unknowns split across
    /// processes returns the space that combines the parts; the solvers compute every inner
    /// product, norm and global selection over the unknowns through it
    /// ([`crate::space`]). Its restrictions keep the space.
    fn space(&self) -> &dyn Space {
        &WHOLE
    }

    /// y = A·x, overwriting `y`. Allocates the scratch buffer when one is needed.
    ///
    /// # Panics
    /// If `x.len() != ncols` or `y.len() != nrows`.
    #[track_caller]
    fn apply(&self, x: &[T], y: &mut [T]) {
        check_len("apply: input x", self.ncols(), x.len());
        check_len("apply: output y", self.nrows(), y.len());
        let mut scratch = vec![T::zero(); self.scratch_len()];
        self.forward_kernel(x, y, &mut scratch);
    }

    /// x = A*·y, overwriting `x`. Allocates the scratch buffer when one is needed.
    ///
    /// # Panics
    /// If `y.len() != nrows` or `x.len() != ncols`.
    #[track_caller]
    fn apply_adjoint(&self, y: &[T], x: &mut [T]) {
        check_len("apply_adjoint: input y", self.nrows(), y.len());
        check_len("apply_adjoint: output x", self.ncols(), x.len());
        let mut scratch = vec![T::zero(); self.scratch_len()];
        self.adjoint_kernel(y, x, &mut scratch);
    }

    /// y = A·x with caller-provided working space; never allocates.
    ///
    /// # Panics
    /// If `x.len() != ncols`, `y.len() != nrows` or `scratch.len() < scratch_len()`.
    #[track_caller]
    fn apply_with_scratch(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        check_len("apply: input x", self.ncols(), x.len());
        check_len("apply: output y", self.nrows(), y.len());
        check_scratch(self.scratch_len(), scratch.len());
        self.forward_kernel(x, y, scratch);
    }

    /// x = A*·y with caller-provided working space; never allocates.
    ///
    /// # Panics
    /// If `y.len() != nrows`, `x.len() != ncols` or `scratch.len() < scratch_len()`.
    #[track_caller]
    fn apply_adjoint_with_scratch(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        check_len("apply_adjoint: input y", self.nrows(), y.len());
        check_len("apply_adjoint: output x", self.ncols(), x.len());
        check_scratch(self.scratch_len(), scratch.len());
        self.adjoint_kernel(y, x, scratch);
    }

    /// The operator's matrix, `nrows × ncols`, built column by column (or row by row through the
    /// adjoint when that takes fewer applications). Meant for tests and small problems.
    fn to_dense(&self) -> Array2<T> {
        let (m, n) = (self.nrows(), self.ncols());
        let mut out = Array2::<T>::zeros((m, n));
        let mut scratch = vec![T::zero(); self.scratch_len()];
        if n <= m {
            let mut e = vec![T::zero(); n];
            let mut col = vec![T::zero(); m];
            for j in 0..n {
                e[j] = T::one();
                self.forward_kernel(&e, &mut col, &mut scratch);
                e[j] = T::zero();
                out.column_mut(j)
                    .iter_mut()
                    .zip(&col)
                    .for_each(|(o, &c)| *o = c);
            }
        } else {
            let mut e = vec![T::zero(); m];
            let mut row = vec![T::zero(); n];
            for i in 0..m {
                e[i] = T::one();
                self.adjoint_kernel(&e, &mut row, &mut scratch);
                e[i] = T::zero();
                out.row_mut(i)
                    .iter_mut()
                    .zip(&row)
                    .for_each(|(o, &r)| *o = r);
            }
        }
        out
    }
}

/// Panics with a message naming both lengths.
#[cold]
#[inline(never)]
#[track_caller]
fn length_panic(what: &str, expected: usize, found: usize) -> ! {
    panic!("{what}: expected length {expected}, found length {found}")
}

#[inline]
#[track_caller]
pub(crate) fn check_len(what: &str, expected: usize, found: usize) {
    if expected != found {
        length_panic(what, expected, found);
    }
}

#[cold]
#[inline(never)]
#[track_caller]
fn scratch_panic(expected: usize, found: usize) -> ! {
    panic!("scratch buffer: expected length at least {expected}, found length {found}")
}

#[inline]
#[track_caller]
fn check_scratch(expected: usize, found: usize) {
    if found < expected {
        scratch_panic(expected, found);
    }
}

macro_rules! forward_impl {
    ($($ty:ty),*) => {$(
        impl<T: Real, A: LinearOperator<T> + ?Sized> LinearOperator<T> for $ty {
            #[inline]
            fn nrows(&self) -> usize {
                (**self).nrows()
            }
            #[inline]
            fn ncols(&self) -> usize {
                (**self).ncols()
            }
            #[inline]
            fn scratch_len(&self) -> usize {
                (**self).scratch_len()
            }
            #[inline]
            fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
                (**self).forward_kernel(x, y, scratch)
            }
            #[inline]
            fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
                (**self).adjoint_kernel(y, x, scratch)
            }
            fn describe(&self) -> String {
                (**self).describe()
            }
            fn restrict_columns(
                &self,
                columns: Vec<usize>,
            ) -> Result<Box<dyn LinearOperator<T> + '_>> {
                (**self).restrict_columns(columns)
            }
            fn space(&self) -> &dyn Space {
                (**self).space()
            }
            fn single(&self) -> Option<Box<dyn LinearOperator<f32> + '_>> {
                (**self).single()
            }
        }
    )*};
}
forward_impl!(&A, Box<A>, Arc<A>);

/// Builders of operator expressions, available on every sized operator.
///
/// Every combinator derives its adjoint from the adjoints of its parts; those that combine
/// operators check the shapes and return [`Error::ShapeMismatch`](crate::Error::ShapeMismatch)
/// when they do not fit. Pass `&a` instead of `a` to keep using `a` afterwards.
pub trait OperatorExt<T: Real>: LinearOperator<T> + Sized {
    /// `self · b`: apply `b`, then `self`.
    ///
    /// # Errors
    /// If `self.ncols() != b.nrows()`.
    fn compose<B: LinearOperator<T>>(self, b: B) -> Result<Compose<Self, B>> {
        Compose::new(self, b)
    }

    /// `b · self`: apply `self`, then `b`.
    ///
    /// # Errors
    /// If `b.ncols() != self.nrows()`.
    fn then<B: LinearOperator<T>>(self, b: B) -> Result<Compose<B, Self>> {
        Compose::new(b, self)
    }

    /// The adjoint view A*, sharing `self`. `Adjoint::adjoint` gives `self` back, so (A*)* is A
    /// itself, not a wrapper.
    fn adjoint(self) -> Adjoint<Self> {
        Adjoint::new(self)
    }

    /// `alpha · self`.
    ///
    /// # Errors
    /// If `alpha` is not finite.
    fn scaled(self, alpha: T) -> Result<Scaled<Self, T>> {
        Scaled::new(self, alpha)
    }

    /// `self + b`.
    ///
    /// # Errors
    /// If the shapes differ.
    fn plus<B: LinearOperator<T>>(self, b: B) -> Result<Sum<Self, B, T>> {
        Sum::new(self, b, T::one())
    }

    /// `self − b`.
    ///
    /// # Errors
    /// If the shapes differ.
    fn minus<B: LinearOperator<T>>(self, b: B) -> Result<Sum<Self, B, T>> {
        Sum::new(self, b, -T::one())
    }

    /// The normal operator A*A (square, self-adjoint, positive semi-definite).
    fn normal(self) -> Normal<Self> {
        Normal::new(self)
    }

    /// A wrapper that counts forward and adjoint applications.
    fn counted(self) -> Counted<Self> {
        Counted::new(self)
    }

    /// Boxes the operator as a trait object.
    fn boxed(self) -> BoxedOperator<T>
    where
        Self: 'static,
    {
        Box::new(self)
    }
}

impl<T: Real, A: LinearOperator<T>> OperatorExt<T> for A {}
