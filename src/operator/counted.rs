//! A wrapper that counts applications.

use std::sync::atomic::{AtomicUsize, Ordering};

use crate::error::Result;
use crate::real::Real;
use crate::space::Space;

use super::pixel::{
    column_by_apply, column_norms_by_applies, pixel_gram_by_applies, self_correlations_by_applies,
};
use super::{LinearOperator, VoxelOperator};

/// Applications of an operator, by kind ([`Counted`]): the one value in which every count of
/// applications is kept, added up and reported.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Applies {
    /// Forward applications of the whole operator.
    pub forward: usize,
    /// Adjoint applications of the whole operator (and correlations).
    pub adjoint: usize,
    /// Support applications: of a restriction to a few columns, or column queries.
    pub support: usize,
}

impl std::ops::AddAssign for Applies {
    fn add_assign(&mut self, other: Applies) {
        self.forward += other.forward;
        self.adjoint += other.adjoint;
        self.support += other.support;
    }
}

impl std::ops::Add for Applies {
    type Output = Applies;
    fn add(mut self, other: Applies) -> Applies {
        self += other;
        self
    }
}

impl std::iter::Sum for Applies {
    fn sum<I: Iterator<Item = Applies>>(iter: I) -> Applies {
        iter.fold(Applies::default(), |a, b| a + b)
    }
}

/// Wraps an operator and counts its applications (thread-safe), in three kinds:
///
/// * forward applications of the whole operator (its correlations of
///   [`VoxelOperator::correlate`] count as adjoint applications);
/// * adjoint applications of the whole operator;
/// * support applications: applications, in either direction, of a restriction to a few
///   columns ([`LinearOperator::restrict_columns`]), and the column queries of an operator whose
///   columns are [structured](VoxelOperator::structured_columns), one per call (a single
///   column, [`VoxelOperator::column`], costs one pass over its rows and is not counted). Column
///   queries answered by applications of the whole operator count as those applications.
///
/// Every solver reports its counts through it; tests use it to check that an algorithm applies
/// the operator as often as it claims.
#[derive(Debug)]
pub struct Counted<A> {
    inner: A,
    forward: AtomicUsize,
    adjoint: AtomicUsize,
    support: AtomicUsize,
}

impl<A> Counted<A> {
    /// Wraps `inner` with every counter at zero.
    pub fn new(inner: A) -> Self {
        Counted {
            inner,
            forward: AtomicUsize::new(0),
            adjoint: AtomicUsize::new(0),
            support: AtomicUsize::new(0),
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

    /// Number of support applications so far.
    pub fn support_count(&self) -> usize {
        self.support.load(Ordering::Relaxed)
    }

    /// Every count so far.
    pub fn applies(&self) -> Applies {
        Applies {
            forward: self.forward_count(),
            adjoint: self.adjoint_count(),
            support: self.support_count(),
        }
    }

    /// Counts one support application that the wrapped operator performs outside this wrapper
    /// (e.g. a sparse forward).
    pub fn count_support(&self) {
        self.support.fetch_add(1, Ordering::Relaxed);
    }

    /// Sets every counter back to zero.
    pub fn reset(&self) {
        self.forward.store(0, Ordering::Relaxed);
        self.adjoint.store(0, Ordering::Relaxed);
        self.support.store(0, Ordering::Relaxed);
    }

    /// The wrapped operator.
    pub fn inner(&self) -> &A {
        &self.inner
    }

    /// Unwraps the operator.
    pub fn into_inner(self) -> A {
        self.inner
    }

    /// `derived`, an operator the wrapped one derives whose applications cost as much as its own
    /// (e.g. the same operator with another pulse), counting into this wrapper's forward and
    /// adjoint counters.
    pub fn counting_full<'a, T: Real>(
        &'a self,
        derived: Box<dyn LinearOperator<T> + 'a>,
    ) -> Box<dyn LinearOperator<T> + 'a> {
        Box::new(CountedPart {
            inner: derived,
            forward: &self.forward,
            adjoint: &self.adjoint,
            support: &self.support,
        })
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
    fn space(&self) -> &dyn Space {
        self.inner.space()
    }
    /// The inner operator's single-precision twin, whose applications count as this one's.
    fn single(&self) -> Option<Box<dyn LinearOperator<f32> + '_>> {
        let twin = self.inner.single()?;
        Some(Box::new(CountedPart {
            inner: twin,
            forward: &self.forward,
            adjoint: &self.adjoint,
            support: &self.support,
        }))
    }
    /// The inner operator's restriction, whose applications count as support applications of
    /// this one.
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(CountedPart {
            inner: self.inner.restrict_columns(columns)?,
            forward: &self.support,
            adjoint: &self.support,
            support: &self.support,
        }))
    }
}

/// The per-pixel capability of the wrapped operator, every application counted: correlations as
/// adjoint applications, structured column queries as one support application each, the others
/// through this wrapper's own applications.
impl<T: Real, A: VoxelOperator<T>> VoxelOperator<T> for Counted<A> {
    fn column_len(&self) -> usize {
        self.inner.column_len()
    }
    fn columns_per_bin(&self) -> usize {
        self.inner.columns_per_bin()
    }
    fn correlate(&self, r: &[T], u: &mut [T]) {
        self.adjoint.fetch_add(1, Ordering::Relaxed);
        self.inner.correlate(r, u)
    }
    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        if self.inner.structured_columns() {
            self.count_support();
            self.inner.self_correlations(voxels)
        } else {
            self_correlations_by_applies(self, voxels)
        }
    }
    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        if self.inner.structured_columns() {
            self.count_support();
            self.inner.pixel_gram(pixel)
        } else {
            pixel_gram_by_applies(self, pixel)
        }
    }
    fn uniform_pixel_gram(&self) -> bool {
        self.inner.uniform_pixel_gram()
    }
    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        if self.inner.structured_columns() {
            self.count_support();
            self.inner.column_norms(columns)
        } else {
            column_norms_by_applies(self, columns)
        }
    }
    /// Not counted when the columns are structured (one column costs a pass over its K_p rows,
    /// far below a support application); else one forward application.
    fn column(&self, c: usize) -> (usize, Vec<f64>) {
        if self.inner.structured_columns() {
            self.inner.column(c)
        } else {
            column_by_apply(self, c)
        }
    }
    fn structured_columns(&self) -> bool {
        self.inner.structured_columns()
    }
}

/// An operator derived from a [`Counted`] one (a restriction, or the same operator with another
/// pulse), counting into its counters.
struct CountedPart<'a, T> {
    inner: Box<dyn LinearOperator<T> + 'a>,
    forward: &'a AtomicUsize,
    adjoint: &'a AtomicUsize,
    support: &'a AtomicUsize,
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
    fn space(&self) -> &dyn Space {
        self.inner.space()
    }
    fn single(&self) -> Option<Box<dyn LinearOperator<f32> + '_>> {
        let twin = self.inner.single()?;
        Some(Box::new(CountedPart {
            inner: twin,
            forward: self.forward,
            adjoint: self.adjoint,
            support: self.support,
        }))
    }
    /// A restriction of the part, whose applications count as support applications.
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(CountedPart {
            inner: self.inner.restrict_columns(columns)?,
            forward: self.support,
            adjoint: self.support,
            support: self.support,
        }))
    }
}
