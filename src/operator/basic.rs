//! Identity, zero, diagonal and restriction operators.

use std::marker::PhantomData;

use crate::error::{Error, Result};
use crate::real::Real;

use super::LinearOperator;

/// The identity on `T^n`.
#[derive(Debug, Clone, Copy)]
pub struct Identity<T> {
    n: usize,
    _t: PhantomData<T>,
}

impl<T: Real> Identity<T> {
    /// The identity on vectors of length `n`.
    pub fn new(n: usize) -> Self {
        Identity { n, _t: PhantomData }
    }
}

impl<T: Real> LinearOperator<T> for Identity<T> {
    fn nrows(&self) -> usize {
        self.n
    }
    fn ncols(&self) -> usize {
        self.n
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        y.copy_from_slice(x);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        x.copy_from_slice(y);
    }
    fn describe(&self) -> String {
        format!("Identity({})", self.n)
    }
}

/// The zero map from `T^ncols` to `T^nrows`.
#[derive(Debug, Clone, Copy)]
pub struct Zero<T> {
    nrows: usize,
    ncols: usize,
    _t: PhantomData<T>,
}

impl<T: Real> Zero<T> {
    /// The zero operator with the given shape.
    pub fn new(nrows: usize, ncols: usize) -> Self {
        Zero {
            nrows,
            ncols,
            _t: PhantomData,
        }
    }
}

impl<T: Real> LinearOperator<T> for Zero<T> {
    fn nrows(&self) -> usize {
        self.nrows
    }
    fn ncols(&self) -> usize {
        self.ncols
    }
    fn forward_kernel(&self, _: &[T], y: &mut [T], _: &mut [T]) {
        y.fill(T::zero());
    }
    fn adjoint_kernel(&self, _: &[T], x: &mut [T], _: &mut [T]) {
        x.fill(T::zero());
    }
    fn describe(&self) -> String {
        format!("Zero({}x{})", self.nrows, self.ncols)
    }
}

/// Entrywise multiplication by a fixed real vector d: y = d ⊙ x. Self-adjoint.
#[derive(Debug, Clone)]
pub struct Diagonal<T> {
    d: Vec<T>,
}

impl<T: Real> Diagonal<T> {
    /// The diagonal operator with diagonal `d`.
    ///
    /// # Errors
    /// [`Error::NonFinite`] if an entry of `d` is NaN or infinite.
    pub fn new(d: Vec<T>) -> Result<Self> {
        if let Some(i) = d.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: format!("diagonal entry {i} ({})", d[i]),
            });
        }
        Ok(Diagonal { d })
    }

    /// The diagonal.
    pub fn diagonal(&self) -> &[T] {
        &self.d
    }
}

impl<T: Real> LinearOperator<T> for Diagonal<T> {
    fn nrows(&self) -> usize {
        self.d.len()
    }
    fn ncols(&self) -> usize {
        self.d.len()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        for ((yi, &xi), &di) in y.iter_mut().zip(x).zip(&self.d) {
            *yi = di * xi;
        }
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], s: &mut [T]) {
        self.forward_kernel(y, x, s)
    }
    fn describe(&self) -> String {
        format!("Diagonal({})", self.d.len())
    }
}

/// Selection of entries: `y[i] = x[idx[i]]`. Its adjoint embeds back, `x[idx[i]] += y[i]` starting from
/// zero, so repeated indices add up.
#[derive(Debug, Clone)]
pub struct Restriction<T> {
    n: usize,
    idx: Vec<usize>,
    _t: PhantomData<T>,
}

impl<T: Real> Restriction<T> {
    /// Selects the entries `idx` (in that order, repeats allowed) of vectors of length `n`.
    ///
    /// # Errors
    /// [`Error::IndexOutOfBounds`] if an index is not below `n`.
    pub fn new(n: usize, idx: Vec<usize>) -> Result<Self> {
        if let Some(&bad) = idx.iter().find(|&&i| i >= n) {
            return Err(Error::IndexOutOfBounds {
                context: "restriction indices",
                index: bad,
                len: n,
            });
        }
        Ok(Restriction {
            n,
            idx,
            _t: PhantomData,
        })
    }

    /// The selected indices.
    pub fn indices(&self) -> &[usize] {
        &self.idx
    }
}

impl<T: Real> LinearOperator<T> for Restriction<T> {
    fn nrows(&self) -> usize {
        self.idx.len()
    }
    fn ncols(&self) -> usize {
        self.n
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        for (yi, &j) in y.iter_mut().zip(&self.idx) {
            *yi = x[j];
        }
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        x.fill(T::zero());
        for (&yi, &j) in y.iter().zip(&self.idx) {
            x[j] = x[j] + yi;
        }
    }
    fn describe(&self) -> String {
        format!("Restriction({} of {})", self.idx.len(), self.n)
    }
}

/// `A·Rᵀ` for the [`Restriction`] R to some columns of A: the default
/// [`restrict_columns`](LinearOperator::restrict_columns). Forward: the input is scattered into a
/// full-length vector (repeats add up) and A applied; adjoint: A's adjoint, then the listed entries.
/// Restricting it again restricts A to the composed column list, so restrictions do not nest.
pub(super) struct ColumnRestriction<'a, A: ?Sized, T> {
    op: &'a A,
    r: Restriction<T>,
}

impl<'a, A: LinearOperator<T> + ?Sized, T: Real> ColumnRestriction<'a, A, T> {
    /// The restriction of `op` to `columns`.
    ///
    /// # Errors
    /// [`Error::IndexOutOfBounds`] for a column not below `op.ncols()`.
    pub(super) fn new(op: &'a A, columns: Vec<usize>) -> Result<Self> {
        Ok(ColumnRestriction {
            op,
            r: Restriction::new(op.ncols(), columns)?,
        })
    }
}

impl<A: LinearOperator<T> + ?Sized, T: Real> LinearOperator<T> for ColumnRestriction<'_, A, T> {
    /// The restricted unknowns are split as the operator's are.
    fn space(&self) -> &dyn crate::space::Space {
        self.op.space()
    }
    fn nrows(&self) -> usize {
        self.op.nrows()
    }
    fn ncols(&self) -> usize {
        self.r.idx.len()
    }
    fn scratch_len(&self) -> usize {
        self.r.n + self.op.scratch_len()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        let (full, rest) = scratch.split_at_mut(self.r.n);
        self.r.adjoint_kernel(x, full, &mut []);
        self.op.forward_kernel(full, y, rest);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        let (full, rest) = scratch.split_at_mut(self.r.n);
        self.op.adjoint_kernel(y, full, rest);
        self.r.forward_kernel(full, x, &mut []);
    }
    fn describe(&self) -> String {
        format!(
            "Compose({}, Adjoint({}))",
            self.op.describe(),
            self.r.describe()
        )
    }
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        let n = self.ncols();
        if let Some(&bad) = columns.iter().find(|&&c| c >= n) {
            return Err(Error::IndexOutOfBounds {
                context: "restriction indices",
                index: bad,
                len: n,
            });
        }
        let composed = columns.iter().map(|&c| self.r.idx[c]).collect();
        self.op.restrict_columns(composed)
    }
}
