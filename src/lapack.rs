//! Dense LAPACK references through `ndarray-linalg` and the system OpenBLAS (feature `lapack`).
//!
//! These are the right tools for checking iterative solvers on dense systems too large for a
//! naive reference: least squares by divide-and-conquer SVD (`*gelsd`) and singular values
//! (`*gesvd`). Operators are materialized with [`LinearOperator::to_dense`].

use ndarray::{Array1, Array2};
use ndarray_linalg::{LeastSquaresSvd, SVD};

use crate::error::{Error, Result};
use crate::operator::LinearOperator;

fn lapack_err(e: ndarray_linalg::error::LinalgError) -> Error {
    Error::LinearAlgebra {
        reason: e.to_string(),
    }
}

/// The minimum-norm least-squares solution of A·x ≈ b for a dense `f64` matrix.
///
/// # Errors
/// [`Error::ShapeMismatch`] if `b.len() != a.nrows()`, [`Error::NonFinite`] for NaN or infinite
/// input, [`Error::LinearAlgebra`] if LAPACK fails.
pub fn lstsq(a: &Array2<f64>, b: &[f64]) -> Result<Vec<f64>> {
    if b.len() != a.nrows() {
        return Err(Error::shape(
            "lstsq: right-hand side vs rows of A",
            a.nrows(),
            b.len(),
        ));
    }
    if !a.iter().chain(b).all(|v| v.is_finite()) {
        return Err(Error::NonFinite {
            what: "lstsq input".into(),
        });
    }
    let a = a.as_standard_layout().to_owned();
    let res = a
        .least_squares(&Array1::from(b.to_vec()))
        .map_err(lapack_err)?;
    Ok(res.solution.to_vec())
}

/// The singular values of a dense `f64` matrix, largest first.
///
/// # Errors
/// [`Error::NonFinite`] for NaN or infinite input, [`Error::LinearAlgebra`] if LAPACK fails.
pub fn singular_values(a: &Array2<f64>) -> Result<Vec<f64>> {
    if !a.iter().all(|v| v.is_finite()) {
        return Err(Error::NonFinite {
            what: "singular_values input".into(),
        });
    }
    if a.is_empty() {
        return Ok(Vec::new());
    }
    let (_, s, _) = a.svd(false, false).map_err(lapack_err)?;
    Ok(s.to_vec())
}

/// The matrix of an `f64` operator and its singular values (for tests on small problems).
///
/// # Errors
/// As [`singular_values`].
pub fn operator_singular_values<A: LinearOperator<f64> + ?Sized>(op: &A) -> Result<Vec<f64>> {
    singular_values(&op.to_dense())
}
