//! A wrapper that counts applications.

use std::sync::atomic::{AtomicUsize, Ordering};

use crate::error::Result;
use crate::real::Real;

use super::LinearOperator;

/// Wraps an operator and counts its forward and adjoint applications (thread-safe).
///
/// Solvers report operator-apply counts through it; tests use it to check that an algorithm applies
/// the operator as often as it claims.
#[derive(Debug)]
pub struct Counted<A> {
    inner: A,
    forward: AtomicUsize,
    adjoint: AtomicUsize,
}

impl<A> Counted<A> {
    /// Wraps `inner` with both counters at zero.
    pub fn new(inner: A) -> Self {
        Counted {
            inner,
            forward: AtomicUsize::new(0),
            adjoint: AtomicUsize::new(0),
        }
    }

    /// Number of forward applications so far.
    pub fn forward_count(&self) -> usize {
        self.forward.load(Ordering::Relaxed)
    }

    /// Number of adjoint applications so far.
    pub fn adjoint_count(&self) -> usize {
        self.adjoint.load(Ordering::Relaxed)
    }

    /// Sets both counters back to zero.
    pub fn reset(&self) {
        self.forward.store(0, Ordering::Relaxed);
        self.adjoint.store(0, Ordering::Relaxed);
    }

    /// The wrapped operator.
    pub fn inner(&self) -> &A {
        &self.inner
    }

    /// Unwraps the operator.
    pub fn into_inner(self) -> A {
        self.inner
    }
}

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for Counted<A> {
    fn nrows(&self) -> usize {
        self.inner.nrows()
    }
    fn ncols(&self) -> usize {
        self.inner.ncols()
    }
    fn scratch_len(&self) -> usize {
        self.inner.scratch_len()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        self.forward.fetch_add(1, Ordering::Relaxed);
        self.inner.forward_kernel(x, y, scratch)
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        self.adjoint.fetch_add(1, Ordering::Relaxed);
        self.inner.adjoint_kernel(y, x, scratch)
    }
    fn describe(&self) -> String {
        format!("Counted({})", self.inner.describe())
    }
    /// The inner operator's restriction, whose applications count as applications of this one.
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(CountedPart {
            inner: self.inner.restrict_columns(columns)?,
            forward: &self.forward,
            adjoint: &self.adjoint,
        }))
    }
}

/// A restriction of a [`Counted`] operator, counting into its counters.
struct CountedPart<'a, T> {
    inner: Box<dyn LinearOperator<T> + 'a>,
    forward: &'a AtomicUsize,
    adjoint: &'a AtomicUsize,
}

impl<T: Real> LinearOperator<T> for CountedPart<'_, T> {
    fn nrows(&self) -> usize {
        self.inner.nrows()
    }
    fn ncols(&self) -> usize {
        self.inner.ncols()
    }
    fn scratch_len(&self) -> usize {
        self.inner.scratch_len()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        self.forward.fetch_add(1, Ordering::Relaxed);
        self.inner.forward_kernel(x, y, scratch)
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        self.adjoint.fetch_add(1, Ordering::Relaxed);
        self.inner.adjoint_kernel(y, x, scratch)
    }
    fn describe(&self) -> String {
        format!("Counted({})", self.inner.describe())
    }
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(CountedPart {
            inner: self.inner.restrict_columns(columns)?,
            forward: self.forward,
            adjoint: self.adjoint,
        }))
    }
}
