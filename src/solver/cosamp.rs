//! CoSaMP: compressive sampling matching pursuit, with matrix-free least squares on the support.

use crate::error::{Error, Result};
use crate::linalg::{dot, norm2};
use crate::operator::{Counted, LinearOperator, OperatorExt, Restriction};
use crate::real::Real;

use super::{
    cgls, check_problem, check_sparsity, check_tolerance, hard_threshold, largest_indices,
    relative_change, support, CglsParams, Monitor, Observer, Report, Stopping, Termination,
};

/// Parameters of [`cosamp`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CosampParams {
    /// The number s of nonzeros kept (1 ≤ s ≤ number of unknowns).
    pub sparsity: usize,
    /// The inner least-squares solve on the merged support (at most 3s unknowns): its damping and
    /// its stopping rules (iteration limit, tolerance on the normal-equation residual).
    pub inner: CglsParams,
    /// The run ends with [`Termination::Converged`] when an iteration leaves the support unchanged
    /// and changes x by at most this, relative: ‖x_k − x_{k−1}‖ ≤ tol · ‖x_k‖ (finite, ≥ 0).
    pub fixed_point_tol: f64,
    /// Stopping rules; the residual is ‖Ax − y‖ / ‖y‖ and the objective ½‖Ax − y‖².
    pub stopping: Stopping,
}

impl CosampParams {
    /// Sparsity `sparsity`; inner CGLS without damping, up to 50 iterations or a relative
    /// normal-equation residual of 1e-8; a fixed-point tolerance of 1e-6; at most 100 outer
    /// iterations, stopping when the relative residual reaches 1e-6.
    pub fn new(sparsity: usize) -> Self {
        CosampParams {
            sparsity,
            inner: CglsParams {
                damp: 0.0,
                stopping: Stopping {
                    max_iter: 50,
                    rel_residual: Some(1e-8),
                    ..Stopping::default()
                },
            },
            fixed_point_tol: 1e-6,
            stopping: Stopping::default(),
        }
    }

    fn validate(&self, n: usize) -> Result<()> {
        self.stopping.validate()?;
        self.inner.stopping.validate()?;
        if !(self.inner.damp.is_finite() && self.inner.damp >= 0.0) {
            return Err(Error::param(
                "inner.damp",
                format!("must be finite and ≥ 0, got {}", self.inner.damp),
            ));
        }
        check_tolerance("fixed_point_tol", self.fixed_point_tol)?;
        check_sparsity(self.sparsity, n)
    }
}

/// Sorted union of two index lists.
fn union(a: &[usize], b: &[usize]) -> Vec<usize> {
    let mut out: Vec<usize> = a.iter().chain(b).copied().collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// Finds an s-sparse x approximately minimizing ½‖Ax − y‖² by CoSaMP (Needell & Tropp 2009),
/// starting from `x`. Each iteration
///
/// 1. forms the proxy u = Aᵀr of the residual r = y − Ax (one adjoint application),
/// 2. merges the indices of the 2s largest |uᵢ| with the support of x into T,
/// 3. solves min_b ‖A R_Tᵀ b − y‖² by [`cgls`] (warm-started from x on T), where R_T is the
///    [`Restriction`] to T: the operator A·R_Tᵀ is built with the operator algebra, so A is
///    only ever applied, never stored as a submatrix,
/// 4. keeps the s largest entries of b as the new x and recomputes r (one forward application).
///
/// The run ends with [`Termination::Converged`] when an iteration keeps the support and changes x
/// by at most [`fixed_point_tol`](CosampParams::fixed_point_tol), or when the proxy is exactly
/// zero; the other reasons come from the [`Stopping`] rules, whose residual is ‖Ax − y‖ / ‖y‖.
/// The report's apply counts include the applications made by the inner CGLS solves.
///
/// The warm start is first pruned to its s largest entries. If y = 0, x is set to 0 (the
/// solution) and the run ends with [`Termination::ZeroResidual`] without applying the operator.
///
/// # References
/// * D. Needell, J. A. Tropp, *CoSaMP: Iterative signal recovery from incomplete and inaccurate
///   samples*, Applied and Computational Harmonic Analysis, 2009.
///
/// # Errors
/// [`Error::InvalidParameter`] if the sparsity is 0 or above the number of unknowns, or for
/// invalid tolerances, inner parameters or stopping rules; [`Error::ShapeMismatch`] /
/// [`Error::NonFinite`] for inputs that do not fit the operator or are not finite;
/// [`Error::Breakdown`] if the inner least-squares solve breaks down or the iteration produces
/// non-finite values.
pub fn cosamp<T, A, O>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &CosampParams,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    const NAME: &str = "cosamp";
    let (m, n) = (op.nrows(), op.ncols());
    params.validate(n)?;
    check_problem(NAME, m, n, y, x)?;
    let s = params.sparsity;
    let op = Counted::new(op);
    let mut monitor = Monitor::new(NAME, params.stopping, observer);
    let ynorm = norm2(y);
    if ynorm == 0.0 {
        x.fill(T::zero());
        return Ok(monitor.finish(0, Termination::ZeroResidual, &op));
    }
    hard_threshold(x, s);
    let mut scratch = vec![T::zero(); op.scratch_len()];
    let mut ax = vec![T::zero(); m];
    op.apply_with_scratch(x, &mut ax, &mut scratch);
    let mut r: Vec<T> = y.iter().zip(&ax).map(|(&a, &b)| a - b).collect();
    let mut u = vec![T::zero(); n];
    let mut xn = vec![T::zero(); n];
    let mut supp = support(x);
    let mut it = 0;
    loop {
        op.apply_adjoint_with_scratch(&r, &mut u, &mut scratch);
        if u.iter().all(|&v| v == T::zero()) {
            return Ok(monitor.finish(it, Termination::Converged, &op));
        }
        it += 1;
        let merged = union(&largest_indices(&u, 2 * s), &supp);
        let mut b: Vec<T> = merged.iter().map(|&i| x[i]).collect();
        let restricted = (&op).compose(Restriction::new(n, merged.clone())?.adjoint())?;
        cgls(&restricted, y, &mut b, &params.inner, &mut ()).map_err(|e| match e {
            Error::Breakdown { reason, .. } => Error::Breakdown {
                solver: NAME,
                reason: format!("inner least squares at iteration {it}: {reason}"),
            },
            other => other,
        })?;
        hard_threshold(&mut b, s);
        xn.fill(T::zero());
        for (&i, &v) in merged.iter().zip(&b) {
            xn[i] = v;
        }
        op.apply_with_scratch(&xn, &mut ax, &mut scratch);
        let change = relative_change(&xn, x);
        let new_supp = support(&xn);
        let same_support = new_supp == supp;
        x.copy_from_slice(&xn);
        supp = new_supp;
        for ((ri, &yi), &ai) in r.iter_mut().zip(y).zip(&ax) {
            *ri = yi - ai;
        }
        let rr = dot(&r, &r);
        if !rr.is_finite() {
            return Err(Error::Breakdown {
                solver: NAME,
                reason: format!("non-finite residual at iteration {it}"),
            });
        }
        let converged = same_support && change <= params.fixed_point_tol;
        match monitor.step(it, rr.sqrt() / ynorm, 0.5 * rr, change, x) {
            Some(Termination::MaxIterations) | None if converged => {
                return Ok(monitor.finish(it, Termination::Converged, &op));
            }
            Some(t) => return Ok(monitor.finish(it, t, &op)),
            None => {}
        }
    }
}
