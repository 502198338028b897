//! Cancellation: an operator that stops working once a flag is raised, so that any solver
//! running on it (its observed iterations and the unobserved work between them: the norm
//! estimate, support pursuits, least-squares refits) ends within one application.
//!
//! Once the flag is raised every application writes zeros, which makes the rest of a solver's
//! work take no time; what the solver returns then means nothing, and the caller that raised
//! the flag discards it (`Acquisition::reconstruct_cancellable` of `rdlidar::acquisition`
//! returns [`Error::Cancelled`](crate::Error::Cancelled)).
//!
//! ```
//! use std::sync::atomic::{AtomicBool, Ordering};
//! use rdlidar::lidar::Cancellable;
//! use rdlidar::operator::{Identity, LinearOperator};
//!
//! let flag = AtomicBool::new(false);
//! let id = Identity::new(3);
//! let op = Cancellable::new(&id, &flag);
//! let mut y = [0.0f64; 3];
//! op.apply(&[1.0, 2.0, 3.0], &mut y);
//! assert_eq!(y, [1.0, 2.0, 3.0]);
//! flag.store(true, Ordering::Relaxed);
//! op.apply(&[1.0, 2.0, 3.0], &mut y);
//! assert_eq!(y, [0.0; 3]);
//! ```

use std::ops::Deref;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::Result;
use crate::operator::{LinearOperator, VoxelOperator};
use crate::real::Real;

use super::geometry::{Geometry, Regime};
use super::measurement::LidarOperator;

/// An operator (`P` derefs to it: a reference or a box) whose applications write zeros once
/// `flag` is raised.
#[derive(Debug)]
pub struct Cancellable<'f, P> {
    inner: P,
    flag: &'f AtomicBool,
}

impl<'f, P> Cancellable<'f, P> {
    /// `inner`, cancelled by `flag`.
    pub fn new(inner: P, flag: &'f AtomicBool) -> Self {
        Cancellable { inner, flag }
    }

    /// Whether the flag is raised.
    pub fn cancelled(&self) -> bool {
        self.flag.load(Ordering::Relaxed)
    }
}

impl<'f, T, P> LinearOperator<T> for Cancellable<'f, P>
where
    T: Real,
    P: Deref + Send + Sync,
    P::Target: LinearOperator<T>,
{
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
        if self.cancelled() {
            y.fill(T::zero());
        } else {
            self.inner.forward_kernel(x, y, scratch);
        }
    }

    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        if self.cancelled() {
            x.fill(T::zero());
        } else {
            self.inner.adjoint_kernel(y, x, scratch);
        }
    }

    fn describe(&self) -> String {
        format!("Cancellable({})", self.inner.describe())
    }

    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<T> + '_>> {
        Ok(Box::new(Cancellable {
            inner: self.inner.restrict_columns(columns)?,
            flag: self.flag,
        }))
    }

    fn space(&self) -> &dyn crate::space::Space {
        self.inner.space()
    }

    fn single(&self) -> Option<Box<dyn LinearOperator<f32> + '_>> {
        Some(Box::new(Cancellable {
            inner: self.inner.single()?,
            flag: self.flag,
        }))
    }
}

impl<'f, T, P> VoxelOperator<T> for Cancellable<'f, P>
where
    T: Real,
    P: Deref + Send + Sync,
    P::Target: VoxelOperator<T>,
{
    fn column_len(&self) -> usize {
        self.inner.column_len()
    }

    fn columns_per_bin(&self) -> usize {
        self.inner.columns_per_bin()
    }

    fn correlate(&self, r: &[T], u: &mut [T]) {
        if self.cancelled() {
            u.fill(T::zero());
        } else {
            self.inner.correlate(r, u);
        }
    }

    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        if self.cancelled() {
            return vec![0.0; voxels.len() * self.column_len()];
        }
        self.inner.self_correlations(voxels)
    }

    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        if self.cancelled() {
            let ks = self.column_len();
            return vec![0.0; ks * ks];
        }
        self.inner.pixel_gram(pixel)
    }

    fn uniform_pixel_gram(&self) -> bool {
        self.inner.uniform_pixel_gram()
    }

    fn structured_columns(&self) -> bool {
        self.inner.structured_columns()
    }

    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        if self.cancelled() {
            return vec![0.0; columns.len()];
        }
        self.inner.column_norms(columns)
    }

    fn column(&self, c: usize) -> (usize, Vec<f64>) {
        if self.cancelled() {
            return (0, Vec::new());
        }
        self.inner.column(c)
    }
}

impl<'f, T, P> LidarOperator<T> for Cancellable<'f, P>
where
    T: Real,
    P: Deref + Send + Sync,
    P::Target: LidarOperator<T>,
{
    fn geometry(&self) -> Geometry {
        self.inner.geometry()
    }

    fn pulse(&self) -> &[T] {
        self.inner.pulse()
    }

    fn code_sets(&self) -> usize {
        self.inner.code_sets()
    }

    fn apply_sparse(&self, x: &[T], y: &mut [T]) {
        if self.cancelled() {
            y.fill(T::zero());
        } else {
            self.inner.apply_sparse(x, y);
        }
    }

    fn zero_mean_operator(&self) -> Box<dyn LinearOperator<T> + '_> {
        Box::new(Cancellable {
            inner: self.inner.zero_mean_operator(),
            flag: self.flag,
        })
    }

    fn observed_pixels(&self) -> Option<Vec<bool>> {
        self.inner.observed_pixels()
    }

    fn whole_code_sets(&self) -> Option<Vec<&std::sync::Arc<super::Codes>>> {
        self.inner.whole_code_sets()
    }

    fn gathered_code_sets(&self) -> Option<crate::Result<Vec<std::sync::Arc<super::Codes>>>> {
        self.inner.gathered_code_sets()
    }

    fn row_weights(&self) -> Option<&[T]> {
        self.inner.row_weights()
    }

    fn regime(&self) -> Regime {
        self.inner.regime()
    }
}
