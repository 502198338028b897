//! Conjugate gradients on the normal equations (CGLS), with Tikhonov damping.

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::linalg::{axpy, dot};
use crate::operator::LinearOperator;
use crate::real::Real;
use crate::space;

use super::iteration::{fit_scratch, solve, Iteration, Iterative, Progress};
use super::{check_problem, Observer, Report, Stopping, Termination};

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

impl CglsParams {
    /// Checks λ and the stopping rules.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the field.
    pub fn validate(&self) -> Result<()> {
        self.stopping.validate()?;
        if !(self.damp.is_finite() && self.damp >= 0.0) {
            return Err(Error::param(
                "damp",
                format!(
                    "λ must be finite and ≥ 0, got {}",
                    crate::units::number(self.damp)
                ),
            ));
        }
        Ok(())
    }
}

/// The state of [`cgls`] between iterations: the residual r = y − Ax, the normal-equation
/// residual s = Aᵀr − λx, the search direction p and its image q = Ap.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CglsIteration<T> {
    damp: f64,
    r: Vec<T>,
    s: Vec<T>,
    p: Vec<T>,
    q: Vec<T>,
    /// ‖s‖² now and at the start.
    gamma: f64,
    gamma0: f64,
    /// The objective at x.
    objective: f64,
    #[serde(skip)]
    scratch: Vec<T>,
}

impl<T: Real> Iterative<T> for CglsIteration<T> {
    const NAME: &'static str = "cgls";
    type Params = CglsParams;

    fn stopping(params: &CglsParams) -> Stopping {
        params.stopping
    }

    fn check_params(params: &CglsParams) -> Result<()> {
        params.validate()
    }
}

impl<T: Real, A: LinearOperator<T> + ?Sized> Iteration<T, A> for CglsIteration<T> {
    fn start(
        op: &A,
        y: &[T],
        x: &mut [T],
        params: &CglsParams,
    ) -> Result<ControlFlow<Termination, Self>> {
        params.validate()?;
        let (m, n) = (op.nrows(), op.ncols());
        let space = op.space();
        check_problem(Self::NAME, space, m, n, y, x)?;
        let mut scratch = vec![T::zero(); op.scratch_len()];
        // r = y − Ax, s = Aᵀr − λx, p = s.
        let mut r = vec![T::zero(); m];
        op.apply_with_scratch(x, &mut r, &mut scratch);
        r.iter_mut().zip(y).for_each(|(ri, &yi)| *ri = yi - *ri);
        let mut s = vec![T::zero(); n];
        op.apply_adjoint_with_scratch(&r, &mut s, &mut scratch);
        axpy(T::of_f64(-params.damp), x, &mut s);
        let [gamma, xx] = space::sums(space, [dot(&s, &s), dot(x, x)]);
        if gamma == 0.0 {
            return Ok(ControlFlow::Break(Termination::ZeroResidual));
        }
        let objective = 0.5 * (dot(&r, &r) + params.damp * xx);
        Ok(ControlFlow::Continue(CglsIteration {
            damp: params.damp,
            p: s.clone(),
            q: vec![T::zero(); m],
            r,
            s,
            gamma,
            gamma0: gamma,
            objective,
            scratch,
        }))
    }

    fn step(&mut self, op: &A, _y: &[T], x: &mut [T], it: usize) -> Result<Progress> {
        fit_scratch(&mut self.scratch, op);
        let lambda = self.damp;
        let space = op.space();
        op.apply_with_scratch(&self.p, &mut self.q, &mut self.scratch);
        let pp = space::norm2_sq(space, &self.p);
        let delta = dot(&self.q, &self.q) + lambda * pp;
        if delta == 0.0 {
            // A·p is zero to the last bit, or p itself is: p lies in the span of Aᵀ's columns,
            // where A vanishes on nothing but zero, so the normal-equation residual has fallen
            // below what the precision resolves (A·p, or ‖p‖² itself, underflowed), and x is
            // as converged as the arithmetic allows. A direction of zero curvature ends the run;
            // it is not a breakdown.
            return Ok(Progress {
                residual: (self.gamma / self.gamma0).sqrt(),
                objective: self.objective,
                change: 0.0,
                ending: Some(Termination::Converged),
            });
        }
        if !(delta.is_finite() && delta > 0.0) {
            return Err(Error::Breakdown {
                solver: Self::NAME,
                reason: format!("search direction with curvature {delta} at iteration {it}"),
            });
        }
        let alpha = self.gamma / delta;
        axpy_step(alpha, &self.p, x);
        axpy_step(-alpha, &self.q, &mut self.r);
        op.apply_adjoint_with_scratch(&self.r, &mut self.s, &mut self.scratch);
        axpy(T::of_f64(-lambda), x, &mut self.s);
        let [gamma_new, xx] = space::sums(space, [dot(&self.s, &self.s), dot(x, x)]);
        if !gamma_new.is_finite() {
            return Err(Error::Breakdown {
                solver: Self::NAME,
                reason: format!("non-finite residual at iteration {it}"),
            });
        }
        let change = if xx > 0.0 {
            alpha * (pp / xx).sqrt()
        } else {
            0.0
        };
        self.objective = 0.5 * (dot(&self.r, &self.r) + lambda * xx);
        if gamma_new > 0.0 {
            let beta = T::of_f64(gamma_new / self.gamma);
            self.p
                .iter_mut()
                .zip(&self.s)
                .for_each(|(pi, &si)| *pi = si + beta * *pi);
        }
        self.gamma = gamma_new;
        Ok(Progress {
            residual: (gamma_new / self.gamma0).sqrt(),
            objective: self.objective,
            change,
            ending: (gamma_new == 0.0).then_some(Termination::Converged),
        })
    }

    fn objective(&self) -> f64 {
        self.objective
    }
}

/// y += a·x; the products formed in `f64` when `a` itself does not fit in `T` (the step of a
/// badly scaled problem in `f32`, whose products may still fit).
fn axpy_step<T: Real>(a: f64, x: &[T], y: &mut [T]) {
    let at = T::of_f64(a);
    if at.is_finite() {
        axpy(at, x, y);
    } else {
        for (yi, &xi) in y.iter_mut().zip(x) {
            *yi = *yi + T::of_f64(a * xi.as_f64());
        }
    }
}

/// Solves min ‖Ax − y‖² + λ‖x‖² by CGLS (Hestenes–Stiefel conjugate gradients applied to
/// (AᵀA + λI)x = Aᵀy without forming AᵀA), starting from `x`.
///
/// Each iteration costs one forward and one adjoint application and a few vector operations;
/// inner products are accumulated in `f64` whatever `T` is. In exact arithmetic the iterates
/// minimize the objective over growing Krylov subspaces, so the residual decreases monotonically.
/// The residual of the [`Stopping`] rules is the normal-equation residual ‖Aᵀ(y − Ax) − λx‖
/// relative to its value at the initial x; an exactly zero one ends the run as
/// [`Termination::Converged`] ([`Termination::ZeroResidual`] before the first iteration), and
/// so does one whose search direction A maps to exactly zero (the residual has fallen below what
/// the precision resolves: A·p underflowed). A step too large for `T` (a badly scaled problem in
/// `f32`) is applied with its products formed in `f64`.
///
/// # Errors
/// [`Error::InvalidParameter`] for a negative or non-finite λ or invalid stopping rules;
/// [`Error::ShapeMismatch`] / [`Error::NonFinite`] for inputs that do not fit the operator or are
/// not finite; [`Error::Breakdown`] if a search direction's curvature or the iteration's values
/// are not finite.
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
    solve::<T, A, O, CglsIteration<T>>(op, y, x, params, observer)
}
