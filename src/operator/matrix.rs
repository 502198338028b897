//! Explicit matrices as operators: ndarray, nalgebra and sprs.
//!
//! Products accumulate in `f64` whatever the element type, so an `f32` matrix gives the same result
//! as its `f64` copy up to the final rounding.

use ndarray::{Array2, ArrayView2, ShapeBuilder};

use crate::error::{Error, Result};
use crate::linalg;
use crate::real::Real;

use super::LinearOperator;

/// y = A·x for a strided view, each entry a dot product accumulated in `f64`.
fn gemv<T: Real>(a: ArrayView2<'_, T>, x: &[T], y: &mut [T]) {
    for (yi, row) in y.iter_mut().zip(a.rows()) {
        let s = match row.as_slice() {
            Some(r) => linalg::dot(r, x),
            None => row
                .iter()
                .zip(x)
                .fold(0.0f64, |s, (&a, &b)| s + a.as_f64() * b.as_f64()),
        };
        *yi = T::of_f64(s);
    }
}

fn check_finite<'a, T: Real>(what: &str, it: impl Iterator<Item = &'a T>) -> Result<()> {
    for (k, v) in it.enumerate() {
        if !v.is_finite() {
            return Err(Error::NonFinite {
                what: format!("{what} (stored entry {k} is {v})"),
            });
        }
    }
    Ok(())
}

/// An `ndarray` matrix (any memory layout) as an operator.
#[derive(Debug, Clone)]
pub struct DenseMatrix<T> {
    a: Array2<T>,
}

impl<T: Real> DenseMatrix<T> {
    /// Wraps `a`.
    ///
    /// # Errors
    /// [`Error::NonFinite`] if an entry is NaN or infinite.
    pub fn new(a: Array2<T>) -> Result<Self> {
        check_finite("dense matrix", a.iter())?;
        Ok(DenseMatrix { a })
    }

    /// The wrapped matrix.
    pub fn matrix(&self) -> &Array2<T> {
        &self.a
    }
}

impl<T: Real> LinearOperator<T> for DenseMatrix<T> {
    fn nrows(&self) -> usize {
        self.a.nrows()
    }
    fn ncols(&self) -> usize {
        self.a.ncols()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        gemv(self.a.view(), x, y);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        gemv(self.a.t(), y, x);
    }
    fn describe(&self) -> String {
        format!("DenseMatrix({}x{})", self.a.nrows(), self.a.ncols())
    }
    fn to_dense(&self) -> Array2<T> {
        self.a.clone()
    }
}

/// A `nalgebra` dynamic matrix as an operator.
#[derive(Debug, Clone)]
pub struct NalgebraMatrix<T: Real> {
    a: nalgebra::DMatrix<T>,
}

impl<T: Real> NalgebraMatrix<T> {
    /// Wraps `a`.
    ///
    /// # Errors
    /// [`Error::NonFinite`] if an entry is NaN or infinite.
    pub fn new(a: nalgebra::DMatrix<T>) -> Result<Self> {
        check_finite("nalgebra matrix", a.iter())?;
        Ok(NalgebraMatrix { a })
    }

    /// The wrapped matrix.
    pub fn matrix(&self) -> &nalgebra::DMatrix<T> {
        &self.a
    }

    fn view(&self) -> ArrayView2<'_, T> {
        // nalgebra stores its dynamic matrices contiguously in column-major order.
        ArrayView2::from_shape((self.a.nrows(), self.a.ncols()).f(), self.a.as_slice())
            .expect("a DMatrix is contiguous and column-major")
    }
}

impl<T: Real> LinearOperator<T> for NalgebraMatrix<T> {
    fn nrows(&self) -> usize {
        self.a.nrows()
    }
    fn ncols(&self) -> usize {
        self.a.ncols()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        gemv(self.view(), x, y);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        gemv(self.view().t(), y, x);
    }
    fn describe(&self) -> String {
        format!("NalgebraMatrix({}x{})", self.a.nrows(), self.a.ncols())
    }
}

/// Compressed rows: `ptr[i]..ptr[i+1]` index the entries of row i.
#[derive(Debug, Clone)]
struct Csr<T> {
    ptr: Vec<usize>,
    idx: Vec<usize>,
    val: Vec<T>,
}

impl<T: Real> Csr<T> {
    /// Rows of `nrows` built from `(row, col, value)` triplets (duplicates kept, they add up).
    fn from_triplets(nrows: usize, triplets: &[(usize, usize, T)]) -> Self {
        let mut ptr = vec![0usize; nrows + 1];
        for &(i, _, _) in triplets {
            ptr[i + 1] += 1;
        }
        for i in 0..nrows {
            ptr[i + 1] += ptr[i];
        }
        let mut next = ptr.clone();
        let mut idx = vec![0usize; triplets.len()];
        let mut val = vec![T::zero(); triplets.len()];
        for &(i, j, v) in triplets {
            idx[next[i]] = j;
            val[next[i]] = v;
            next[i] += 1;
        }
        Csr { ptr, idx, val }
    }

    fn matvec(&self, x: &[T], y: &mut [T]) {
        for (i, yi) in y.iter_mut().enumerate() {
            let r = self.ptr[i]..self.ptr[i + 1];
            let s = self.idx[r.clone()]
                .iter()
                .zip(&self.val[r])
                .fold(0.0f64, |s, (&j, &v)| s + v.as_f64() * x[j].as_f64());
            *yi = T::of_f64(s);
        }
    }
}

/// An `sprs` sparse matrix (CSR or CSC) as an operator.
///
/// Both A and Aᵀ are held in compressed-row form, so forward and adjoint are both gathers
/// (no scatter, no scratch) and cost O(nnz) each.
#[derive(Debug, Clone)]
pub struct SparseMatrix<T: Real> {
    a: sprs::CsMat<T>,
    rows: Csr<T>,
    cols: Csr<T>,
}

impl<T: Real> SparseMatrix<T> {
    /// Wraps `a`.
    ///
    /// # Errors
    /// [`Error::NonFinite`] if a stored entry is NaN or infinite.
    pub fn new(a: sprs::CsMat<T>) -> Result<Self> {
        check_finite("sparse matrix", a.data().iter())?;
        let trip: Vec<(usize, usize, T)> = a.iter().map(|(&v, (i, j))| (i, j, v)).collect();
        let rows = Csr::from_triplets(a.rows(), &trip);
        let trip_t: Vec<(usize, usize, T)> = trip.iter().map(|&(i, j, v)| (j, i, v)).collect();
        let cols = Csr::from_triplets(a.cols(), &trip_t);
        Ok(SparseMatrix { a, rows, cols })
    }

    /// The wrapped matrix.
    pub fn matrix(&self) -> &sprs::CsMat<T> {
        &self.a
    }
}

impl<T: Real> LinearOperator<T> for SparseMatrix<T> {
    fn nrows(&self) -> usize {
        self.a.rows()
    }
    fn ncols(&self) -> usize {
        self.a.cols()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], _: &mut [T]) {
        self.rows.matvec(x, y);
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], _: &mut [T]) {
        self.cols.matvec(y, x);
    }
    fn describe(&self) -> String {
        format!(
            "SparseMatrix({}x{}, nnz {})",
            self.a.rows(),
            self.a.cols(),
            self.a.nnz()
        )
    }
}
