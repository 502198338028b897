//! Conjugate gradients on the normal equations (CGLS), with Tikhonov damping.

use crate::error::{Error, Result};
use crate::linalg::{axpy, dot};
use crate::operator::{Counted, LinearOperator};
use crate::real::Real;

use super::{check_problem, Monitor, Observer, Report, Stopping, Termination};

/// Parameters of [`cgls`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CglsParams {
    /// λ ≥ 0 of the damped problem min ‖Ax − y‖² + λ‖x‖².
    pub damp: f64,
    /// Stopping rules; the residual is the normal-equation residual
    /// ‖Aᵀ(y − Ax) − λx‖ relative to its value at the initial x.
    pub stopping: Stopping,
}

impl Default for CglsParams {
    fn default() -> Self {
        CglsParams {
            damp: 0.0,
            stopping: Stopping::default(),
        }
    }
}

/// Solves min ‖Ax − y‖² + λ‖x‖² by CGLS (Hestenes–Stiefel conjugate gradients applied to
/// (AᵀA + λI)x = Aᵀy without forming AᵀA), starting from `x`.
///
/// Each iteration costs one forward and one adjoint application and a few vector operations;
/// inner products are accumulated in `f64` whatever `T` is. In exact arithmetic the iterates
/// minimize the objective over growing Krylov subspaces, so the residual decreases monotonically.
///
/// # Errors
/// [`Error::InvalidParameter`] for a negative or non-finite λ or invalid stopping rules;
/// [`Error::ShapeMismatch`] / [`Error::NonFinite`] for inputs that do not fit the operator or are
/// not finite; [`Error::Breakdown`] if a search direction has zero curvature or the iteration
/// produces non-finite values.
pub fn cgls<T, A, O>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &CglsParams,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    const NAME: &str = "cgls";
    params.stopping.validate()?;
    if !(params.damp.is_finite() && params.damp >= 0.0) {
        return Err(Error::param(
            "damp",
            format!("λ must be finite and ≥ 0, got {}", params.damp),
        ));
    }
    let (m, n) = (op.nrows(), op.ncols());
    check_problem(NAME, m, n, y, x)?;
    let op = Counted::new(op);
    let lambda = params.damp;
    let lam_t = T::of_f64(lambda);
    let mut scratch = vec![T::zero(); op.scratch_len()];
    let mut monitor = Monitor::new(NAME, params.stopping, observer);

    // r = y − Ax, s = Aᵀr − λx, p = s.
    let mut r = vec![T::zero(); m];
    op.apply_with_scratch(x, &mut r, &mut scratch);
    r.iter_mut().zip(y).for_each(|(ri, &yi)| *ri = yi - *ri);
    let mut s = vec![T::zero(); n];
    op.apply_adjoint_with_scratch(&r, &mut s, &mut scratch);
    axpy(-lam_t, x, &mut s);
    let mut p = s.clone();
    let mut q = vec![T::zero(); m];
    let mut gamma = dot(&s, &s);
    let gamma0 = gamma;
    if gamma0 == 0.0 {
        return Ok(monitor.finish(0, Termination::ZeroResidual, &op));
    }
    let mut it = 0;
    loop {
        it += 1;
        op.apply_with_scratch(&p, &mut q, &mut scratch);
        let pp = dot(&p, &p);
        let delta = dot(&q, &q) + lambda * pp;
        if !(delta.is_finite() && delta > 0.0) {
            return Err(Error::Breakdown {
                solver: NAME,
                reason: format!("search direction with curvature {delta} at iteration {it}"),
            });
        }
        let alpha = gamma / delta;
        axpy(T::of_f64(alpha), &p, x);
        axpy(T::of_f64(-alpha), &q, &mut r);
        op.apply_adjoint_with_scratch(&r, &mut s, &mut scratch);
        axpy(-lam_t, x, &mut s);
        let gamma_new = dot(&s, &s);
        if !gamma_new.is_finite() {
            return Err(Error::Breakdown {
                solver: NAME,
                reason: format!("non-finite residual at iteration {it}"),
            });
        }
        let xx = dot(x, x);
        let change = if xx > 0.0 {
            alpha * (pp / xx).sqrt()
        } else {
            0.0
        };
        let objective = 0.5 * (dot(&r, &r) + lambda * xx);
        let residual = (gamma_new / gamma0).sqrt();
        if let Some(t) = monitor.step(it, residual, objective, change, x) {
            return Ok(monitor.finish(it, t, &op));
        }
        if gamma_new == 0.0 {
            return Ok(monitor.finish(it, Termination::Converged, &op));
        }
        let beta = T::of_f64(gamma_new / gamma);
        p.iter_mut()
            .zip(&s)
            .for_each(|(pi, &si)| *pi = si + beta * *pi);
        gamma = gamma_new;
    }
}
