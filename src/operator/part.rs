//! One process's part of an operator whose unknowns are split across processes.

use std::sync::Arc;

use crate::error::Result;
use crate::real::Real;
use crate::space::Space;

use super::{LinearOperator, VoxelOperator};

/// This process's part A_r of an operator A = [A₁ … A_R] whose columns (the unknowns) are split
/// across R processes, as pylops-mpi's `MPIHStack` splits them: every process holds its own
/// block `inner`, a whole operator of its unknowns alone, and the measurements whole.
///
/// - forward: y = Σ_r A_r x_r, the local product summed over the parts through `space` (a
///   collective: every part applies it together);
/// - adjoint: x_r = A_rᵀ y, local;
/// - restrictions to columns, and the per-pixel column queries of [`VoxelOperator`], those of
///   `inner` (local, without applying the other parts);
/// - [`space`](LinearOperator::space): `space`, so that the solvers compute every inner product,
///   norm and selection over the whole unknowns.
///
/// The solvers of [`crate::solver`] and the reconstructions of `recon` run on it unchanged and
/// give every part its share of the whole problem's solution. With a whole space it is `inner`.
/// The sums run in `f64` whatever `T` is.
#[derive(Clone)]
pub struct Part<A> {
    inner: A,
    space: Arc<dyn Space>,
}

impl<A> Part<A> {
    /// `inner`, this process's block, with the space that combines the parts.
    pub fn new(inner: A, space: Arc<dyn Space>) -> Self {
        Self { inner, space }
    }

    /// This process's block.
    pub fn inner(&self) -> &A {
        &self.inner
    }

    /// The space that combines the parts.
    pub fn shared_space(&self) -> &Arc<dyn Space> {
        &self.space
    }

    /// Sums `y`, this part's share of the measurements, over the parts.
    pub(crate) fn sum_parts<T: Real>(&self, y: &mut [T]) {
        sum_over(&*self.space, y);
    }
}

/// Sums `y` over the parts of `space` in `f64`.
pub(crate) fn sum_over<T: Real>(space: &dyn Space, y: &mut [T]) {
    if space.parts() == 1 {
        return;
    }
    let mut wide: Vec<f64> = y.iter().map(|v| v.as_f64()).collect();
    space.sum(&mut wide);
    y.iter_mut()
        .zip(&wide)
        .for_each(|(v, &w)| *v = T::of_f64(w));
}

impl<A> std::fmt::Debug for Part<A> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Part")
            .field("parts", &self.space.parts())
            .finish_non_exhaustive()
    }
}

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for Part<A> {
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
        self.inner.forward_kernel(x, y, scratch);
        self.sum_parts(y);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        self.inner.adjoint_kernel(y, x, scratch);
    }
    fn describe(&self) -> String {
        format!(
            "Part({}, one of {})",
            self.inner.describe(),
            self.space.parts()
        )
    }
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(Part::new(
            self.inner.restrict_columns(columns)?,
            Arc::clone(&self.space),
        )))
    }
    fn space(&self) -> &dyn Space {
        &*self.space
    }
}

/// The column queries are `inner`'s: its columns are this part's unknowns.
impl<T: Real, A: VoxelOperator<T>> VoxelOperator<T> for Part<A> {
    fn column_len(&self) -> usize {
        self.inner.column_len()
    }
    fn columns_per_bin(&self) -> usize {
        self.inner.columns_per_bin()
    }
    fn correlate(&self, r: &[T], u: &mut [T]) {
        self.inner.correlate(r, u)
    }
    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        self.inner.self_correlations(voxels)
    }
    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        self.inner.pixel_gram(pixel)
    }
    fn uniform_pixel_gram(&self) -> bool {
        self.inner.uniform_pixel_gram()
    }
    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        self.inner.column_norms(columns)
    }
    /// A column is one unknown's: this part's operator holds all of it (no collective).
    fn column(&self, c: usize) -> (usize, Vec<f64>) {
        self.inner.column(c)
    }
    fn structured_columns(&self) -> bool {
        self.inner.structured_columns()
    }
}
