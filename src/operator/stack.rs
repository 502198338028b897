//! Vertical and horizontal stacks and block-diagonal operators.
//!
//! Each holds a `Vec` of operators of one type; use `Box<dyn LinearOperator<T>>`
//! ([`BoxedOperator`](super::BoxedOperator)) to stack operators of different types.

use crate::error::{Error, Result};
use crate::linalg::axpy;
use crate::real::Real;

use super::LinearOperator;

fn offsets(lens: impl Iterator<Item = usize>) -> Vec<usize> {
    let mut out = vec![0];
    for l in lens {
        out.push(out.last().copied().unwrap_or(0) + l);
    }
    out
}

fn describe_all<T: Real, A: LinearOperator<T>>(kind: &str, ops: &[A]) -> String {
    let parts: Vec<String> = ops.iter().map(|o| o.describe()).collect();
    format!("{kind}[{}]", parts.join(", "))
}

fn nonempty<A>(kind: &'static str, ops: &[A]) -> Result<()> {
    if ops.is_empty() {
        return Err(Error::param(kind, "needs at least one operator"));
    }
    Ok(())
}

/// The vertical stack `[A₀; A₁; …]`: every block sees the same input and the outputs are
/// concatenated. Adjoint: `Σᵢ Aᵢ* yᵢ`.
#[derive(Debug, Clone)]
pub struct VStack<A> {
    ops: Vec<A>,
    rows: Vec<usize>,
}

impl<A> VStack<A> {
    /// Stacks `ops` vertically.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an empty list, [`Error::ShapeMismatch`] if the operators
    /// differ in their number of columns.
    pub fn new<T: Real>(ops: Vec<A>) -> Result<Self>
    where
        A: LinearOperator<T>,
    {
        nonempty("vstack", &ops)?;
        let n = ops[0].ncols();
        for (i, op) in ops.iter().enumerate().skip(1) {
            if op.ncols() != n {
                return Err(Error::shape(
                    format!(
                        "vstack: columns of block {i} ({}) vs block 0",
                        op.describe()
                    ),
                    n,
                    op.ncols(),
                ));
            }
        }
        let rows = offsets(ops.iter().map(|o| o.nrows()));
        Ok(VStack { ops, rows })
    }

    /// The stacked operators.
    pub fn blocks(&self) -> &[A] {
        &self.ops
    }
}

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for VStack<A> {
    fn nrows(&self) -> usize {
        *self.rows.last().unwrap_or(&0)
    }
    fn ncols(&self) -> usize {
        self.ops[0].ncols()
    }
    fn scratch_len(&self) -> usize {
        let own = if self.ops.len() > 1 { self.ncols() } else { 0 };
        own + self.ops.iter().map(|o| o.scratch_len()).max().unwrap_or(0)
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        for (op, w) in self.ops.iter().zip(self.rows.windows(2)) {
            op.forward_kernel(x, &mut y[w[0]..w[1]], scratch);
        }
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        let n = self.ncols();
        let (first, rest_ops) = self.ops.split_first().expect("non-empty by construction");
        if rest_ops.is_empty() {
            first.adjoint_kernel(&y[self.rows[0]..self.rows[1]], x, scratch);
            return;
        }
        let (tmp, rest) = scratch.split_at_mut(n);
        first.adjoint_kernel(&y[self.rows[0]..self.rows[1]], x, rest);
        for (op, w) in rest_ops.iter().zip(self.rows[1..].windows(2)) {
            op.adjoint_kernel(&y[w[0]..w[1]], tmp, rest);
            axpy(T::one(), tmp, x);
        }
    }
    fn describe(&self) -> String {
        describe_all("VStack", &self.ops)
    }
}

/// The horizontal stack `[A₀ A₁ …]`: the input is split into consecutive blocks and the outputs are
/// summed. Adjoint: the vertical stack of the `Aᵢ*`.
#[derive(Debug, Clone)]
pub struct HStack<A> {
    ops: Vec<A>,
    cols: Vec<usize>,
}

impl<A> HStack<A> {
    /// Stacks `ops` horizontally.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an empty list, [`Error::ShapeMismatch`] if the operators
    /// differ in their number of rows.
    pub fn new<T: Real>(ops: Vec<A>) -> Result<Self>
    where
        A: LinearOperator<T>,
    {
        nonempty("hstack", &ops)?;
        let m = ops[0].nrows();
        for (i, op) in ops.iter().enumerate().skip(1) {
            if op.nrows() != m {
                return Err(Error::shape(
                    format!("hstack: rows of block {i} ({}) vs block 0", op.describe()),
                    m,
                    op.nrows(),
                ));
            }
        }
        let cols = offsets(ops.iter().map(|o| o.ncols()));
        Ok(HStack { ops, cols })
    }

    /// The stacked operators.
    pub fn blocks(&self) -> &[A] {
        &self.ops
    }
}

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for HStack<A> {
    fn nrows(&self) -> usize {
        self.ops[0].nrows()
    }
    fn ncols(&self) -> usize {
        *self.cols.last().unwrap_or(&0)
    }
    fn scratch_len(&self) -> usize {
        let own = if self.ops.len() > 1 { self.nrows() } else { 0 };
        own + self.ops.iter().map(|o| o.scratch_len()).max().unwrap_or(0)
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        let m = self.nrows();
        let (first, rest_ops) = self.ops.split_first().expect("non-empty by construction");
        if rest_ops.is_empty() {
            first.forward_kernel(&x[self.cols[0]..self.cols[1]], y, scratch);
            return;
        }
        let (tmp, rest) = scratch.split_at_mut(m);
        first.forward_kernel(&x[self.cols[0]..self.cols[1]], y, rest);
        for (op, w) in rest_ops.iter().zip(self.cols[1..].windows(2)) {
            op.forward_kernel(&x[w[0]..w[1]], tmp, rest);
            axpy(T::one(), tmp, y);
        }
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        for (op, w) in self.ops.iter().zip(self.cols.windows(2)) {
            op.adjoint_kernel(y, &mut x[w[0]..w[1]], scratch);
        }
    }
    fn describe(&self) -> String {
        describe_all("HStack", &self.ops)
    }
}

/// The block-diagonal operator `diag(A₀, A₁, …)`: input and output are split into consecutive
/// blocks, block i maps input block i to output block i. Adjoint: `diag(A₀*, A₁*, …)`.
#[derive(Debug, Clone)]
pub struct BlockDiag<A> {
    ops: Vec<A>,
    rows: Vec<usize>,
    cols: Vec<usize>,
}

impl<A> BlockDiag<A> {
    /// The block-diagonal operator of `ops`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an empty list.
    pub fn new<T: Real>(ops: Vec<A>) -> Result<Self>
    where
        A: LinearOperator<T>,
    {
        nonempty("block_diag", &ops)?;
        let rows = offsets(ops.iter().map(|o| o.nrows()));
        let cols = offsets(ops.iter().map(|o| o.ncols()));
        Ok(BlockDiag { ops, rows, cols })
    }

    /// The diagonal blocks.
    pub fn blocks(&self) -> &[A] {
        &self.ops
    }
}

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for BlockDiag<A> {
    fn nrows(&self) -> usize {
        *self.rows.last().unwrap_or(&0)
    }
    fn ncols(&self) -> usize {
        *self.cols.last().unwrap_or(&0)
    }
    fn scratch_len(&self) -> usize {
        self.ops.iter().map(|o| o.scratch_len()).max().unwrap_or(0)
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        for (i, op) in self.ops.iter().enumerate() {
            op.forward_kernel(
                &x[self.cols[i]..self.cols[i + 1]],
                &mut y[self.rows[i]..self.rows[i + 1]],
                scratch,
            );
        }
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        for (i, op) in self.ops.iter().enumerate() {
            op.adjoint_kernel(
                &y[self.rows[i]..self.rows[i + 1]],
                &mut x[self.cols[i]..self.cols[i + 1]],
                scratch,
            );
        }
    }
    fn describe(&self) -> String {
        describe_all("BlockDiag", &self.ops)
    }
}
