//! CoSaMP: compressive sampling matching pursuit, with matrix-free least squares on the support.

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::linalg::{dot, norm2};
use crate::operator::LinearOperator;
use crate::real::Real;
use crate::space;

use super::iteration::{fit_scratch, refresh_residual, solve, Iteration, Iterative, Progress};
use super::{
    cgls, check_problem, check_sparsity, check_tolerance, support, CglsParams, Observer, Report,
    Stopping, Termination,
};

/// Parameters of [`cosamp`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CosampParams {
    /// The number s of nonzeros kept (1 ≤ s ≤ number of unknowns).
    pub sparsity: usize,
    /// The inner least-squares solve on the merged support (at most 3s unknowns, warm-started from
    /// the current x): its damping and its stopping rules (iteration limit, tolerance on the
    /// normal-equation residual). A few iterations often suffice: the next outer iteration
    /// continues from where they stopped.
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

    /// Checks every setting that needs no operator (all but the sparsity's upper bound).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the setting.
    pub fn validate(&self) -> Result<()> {
        self.stopping.validate()?;
        self.inner.stopping.validate()?;
        if !(self.inner.damp.is_finite() && self.inner.damp >= 0.0) {
            return Err(Error::param(
                "inner.damp",
                format!(
                    "must be finite and ≥ 0, got {}",
                    crate::units::number(self.inner.damp)
                ),
            ));
        }
        check_tolerance("fixed_point_tol", self.fixed_point_tol)
    }

    /// [`CosampParams::validate`], and the sparsity against the `unknowns` of a problem.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the setting.
    pub fn validate_for(&self, unknowns: usize) -> Result<()> {
        self.validate()?;
        check_sparsity(self.sparsity, unknowns)
    }
}

/// Sorted union of two index lists.
fn union(a: &[usize], b: &[usize]) -> Vec<usize> {
    let mut out: Vec<usize> = a.iter().chain(b).copied().collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// The state of [`cosamp`] between iterations: the forward product and residual of x, its
/// support and the proxy.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CosampIteration<T> {
    sparsity: usize,
    fixed_point_tol: f64,
    /// The damping and the stopping rules of the inner [`CglsParams`].
    inner_damp: f64,
    inner_stopping: Stopping,
    /// ‖y‖.
    ynorm: f64,
    ax: Vec<T>,
    /// y − Ax.
    r: Vec<T>,
    /// Aᵀr, computed by `prepare`.
    u: Vec<T>,
    xn: Vec<T>,
    supp: Vec<usize>,
    #[serde(skip, default = "Vec::new")]
    scratch: Vec<T>,
}

impl<T: Real> Iterative<T> for CosampIteration<T> {
    const NAME: &'static str = "cosamp";
    type Params = CosampParams;

    fn stopping(params: &CosampParams) -> Stopping {
        params.stopping
    }

    fn check_params(params: &CosampParams) -> Result<()> {
        params.validate()?;
        super::check_nonzero_sparsity(params.sparsity)
    }
}

impl<T: Real, A: LinearOperator<T> + ?Sized> Iteration<T, A> for CosampIteration<T> {
    fn start(
        op: &A,
        y: &[T],
        x: &mut [T],
        params: &CosampParams,
    ) -> Result<ControlFlow<Termination, Self>> {
        let (m, n) = (op.nrows(), op.ncols());
        let space = op.space();
        params.validate_for(space::count(space, n))?;
        check_problem(Self::NAME, space, m, n, y, x)?;
        let ynorm = norm2(y);
        if ynorm == 0.0 {
            x.fill(T::zero());
            return Ok(ControlFlow::Break(Termination::ZeroResidual));
        }
        space::hard_threshold(space, x, params.sparsity);
        let mut scratch = vec![T::zero(); op.scratch_len()];
        let mut ax = vec![T::zero(); m];
        op.apply_with_scratch(x, &mut ax, &mut scratch);
        let r: Vec<T> = y.iter().zip(&ax).map(|(&a, &b)| a - b).collect();
        Ok(ControlFlow::Continue(CosampIteration {
            sparsity: params.sparsity,
            fixed_point_tol: params.fixed_point_tol,
            inner_damp: params.inner.damp,
            inner_stopping: params.inner.stopping,
            ynorm,
            ax,
            r,
            u: vec![T::zero(); n],
            xn: vec![T::zero(); n],
            supp: support(x),
            scratch,
        }))
    }

    /// The proxy u = Aᵀ(y − Ax); x solves the problem when it is exactly zero.
    fn prepare(&mut self, op: &A) -> Option<Termination> {
        fit_scratch(&mut self.scratch, op);
        op.apply_adjoint_with_scratch(&self.r, &mut self.u, &mut self.scratch);
        space::all(op.space(), self.u.iter().all(|&v| v == T::zero()))
            .then_some(Termination::Converged)
    }

    fn step(&mut self, op: &A, y: &[T], x: &mut [T], it: usize) -> Result<Progress> {
        fit_scratch(&mut self.scratch, op);
        let space = op.space();
        let s = self.sparsity;
        let merged = union(&space::largest_indices(space, &self.u, 2 * s), &self.supp);
        let mut b: Vec<T> = merged.iter().map(|&i| x[i]).collect();
        let restricted = op.restrict_columns(merged.clone())?;
        let inner = CglsParams {
            damp: self.inner_damp,
            stopping: self.inner_stopping,
        };
        cgls(&restricted, y, &mut b, &inner, &mut ()).map_err(|e| match e {
            Error::Breakdown { reason, .. } => Error::Breakdown {
                solver: Self::NAME,
                reason: format!("inner least squares at iteration {it}: {reason}"),
            },
            other => other,
        })?;
        space::hard_threshold(restricted.space(), &mut b, s);
        self.xn.fill(T::zero());
        for (&i, &v) in merged.iter().zip(&b) {
            self.xn[i] = v;
        }
        op.apply_with_scratch(&self.xn, &mut self.ax, &mut self.scratch);
        let change = space::relative_change(space, &self.xn, x);
        let new_supp = support(&self.xn);
        let same_support = space::all(space, new_supp == self.supp);
        x.copy_from_slice(&self.xn);
        self.supp = new_supp;
        let rr = refresh_residual(Self::NAME, it, y, &self.ax, &mut self.r)?;
        let converged = same_support && change <= self.fixed_point_tol;
        Ok(Progress::least_squares(rr, self.ynorm, change, converged))
    }

    fn objective(&self) -> f64 {
        0.5 * dot(&self.r, &self.r)
    }
}

/// Finds an s-sparse x approximately minimizing ½‖Ax − y‖² by CoSaMP (Needell & Tropp 2009),
/// starting from `x`. Each iteration
///
/// 1. forms the proxy u = Aᵀr of the residual r = y − Ax (one adjoint application),
/// 2. merges the indices of the 2s largest |uᵢ| with the support of x into T,
/// 3. solves min_b ‖A R_Tᵀ b − y‖² by [`cgls`] (warm-started from x on T), where A·R_Tᵀ is
///    A restricted to the columns T by [`LinearOperator::restrict_columns`]: by default A
///    composed with the adjoint of the [`Restriction`](crate::operator::Restriction) to T (A is
///    only ever applied, never stored as a submatrix); operators with a cheaper restriction
///    provide it (the lidar operator's costs O(|T|·K_p) per application instead of a full
///    adjoint),
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
    solve::<T, A, O, CosampIteration<T>>(op, y, x, params, observer)
}
