//! The operator-norm estimate: power iteration on AᵀA.

use crate::error::{Error, Result};
use crate::linalg::norm2;
use crate::real::Real;
use crate::space;

use super::testing::{check_rng, gaussian_vector, NORM_STREAM};
use super::LinearOperator;

/// Settings of [`operator_norm`].
#[derive(Debug, Clone, Copy)]
pub struct PowerIteration {
    /// Maximum number of iterations (each one forward and one adjoint application).
    pub max_iter: usize,
    /// Stop when the estimate changes by at most `tol` relative to itself.
    pub tol: f64,
    /// Seed of the random start vector.
    pub seed: u64,
}

impl Default for PowerIteration {
    fn default() -> Self {
        PowerIteration {
            max_iter: 200,
            tol: 1e-6,
            seed: 0,
        }
    }
}

/// Why [`operator_norm`] stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NormStop {
    /// The relative change of the estimate fell below the tolerance.
    Converged,
    /// The iteration limit was reached first.
    MaxIterations,
    /// A·v = 0 for the start vector or an iterate: the estimate is 0.
    ZeroOperator,
}

/// The result of [`operator_norm`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormEstimate {
    /// The estimate of ‖A‖₂ (largest singular value), a lower bound up to rounding.
    pub value: f64,
    /// Iterations performed.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: NormStop,
}

/// Estimates ‖A‖₂ by power iteration on A*A.
///
/// Each iteration maps the unit vector v to A*A·v and reports σ = ‖A·v‖ (the square root of the
/// Rayleigh quotient of A*A), which never exceeds ‖A‖₂ and converges to it at the rate
/// (σ₂/σ₁)^{2k} when the top singular value is simple.
///
/// # Errors
/// [`Error::InvalidParameter`] if `max_iter` is zero or `tol` is not a positive finite number;
/// [`Error::NonFinite`] if the operator produced NaN or infinite values.
pub fn operator_norm<T: Real, A: LinearOperator<T> + ?Sized>(
    op: &A,
    params: &PowerIteration,
) -> Result<NormEstimate> {
    if params.max_iter == 0 {
        return Err(Error::param("max_iter", "must be at least 1"));
    }
    if !(params.tol.is_finite() && params.tol > 0.0) {
        return Err(Error::param(
            "tol",
            format!("must be a positive finite number, got {}", params.tol),
        ));
    }
    let (m, n) = (op.nrows(), op.ncols());
    // Over unknowns split into parts: the whole vector's count and this part's first index.
    let space = op.space();
    let (total, offset) = (space::count(space, n), space.offset(n));
    let zero = NormEstimate {
        value: 0.0,
        iterations: 0,
        stop: NormStop::ZeroOperator,
    };
    if m == 0 || total == 0 {
        return Ok(zero);
    }
    // The start vector of the whole, so that every split starts from the same one.
    let mut rng = check_rng(params.seed, NORM_STREAM);
    let mut v: Vec<T> = gaussian_vector(total, &mut rng);
    v.drain(..offset);
    v.truncate(n);
    let nv = space::norm2(space, &v);
    v.iter_mut().for_each(|e| *e = T::of_f64(e.as_f64() / nv));
    let mut av = vec![T::zero(); m];
    let mut scratch = vec![T::zero(); op.scratch_len()];
    let mut prev = 0.0f64;
    for it in 1..=params.max_iter {
        op.apply_with_scratch(&v, &mut av, &mut scratch);
        let sigma = norm2(&av);
        if !sigma.is_finite() {
            return Err(Error::NonFinite {
                what: format!("operator output during power iteration {it}"),
            });
        }
        if sigma == 0.0 {
            return Ok(NormEstimate {
                iterations: it,
                ..zero
            });
        }
        op.apply_adjoint_with_scratch(&av, &mut v, &mut scratch);
        let nu = space::norm2(space, &v);
        if !nu.is_finite() || nu == 0.0 {
            return Err(Error::NonFinite {
                what: format!("adjoint output during power iteration {it}"),
            });
        }
        v.iter_mut().for_each(|e| *e = T::of_f64(e.as_f64() / nu));
        if it > 1 && (sigma - prev).abs() <= params.tol * sigma {
            return Ok(NormEstimate {
                value: sigma,
                iterations: it,
                stop: NormStop::Converged,
            });
        }
        prev = sigma;
    }
    Ok(NormEstimate {
        value: prev,
        iterations: params.max_iter,
        stop: NormStop::MaxIterations,
    })
}
