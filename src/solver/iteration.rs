//! The iteration protocol: an iterative solver's state as a value, set up once from the warm
//! start, then stepped. [`solve`] is the one loop that owns the stopping rules, the observer and
//! the report of every native solver ([`cgls`](super::cgls), [`fista`](super::fista),
//! [`iht`](super::iht), [`cosamp`](super::cosamp)); [`ArgminSolver`](super::ArgminSolver) steps
//! the same value from argmin's `next_iter`, so both drivers perform the same arithmetic.

use std::ops::ControlFlow;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::operator::{Counted, LinearOperator};
use crate::real::Real;

use super::{Monitor, Observer, Report, Stagnation, Stopping, Termination};

/// What one iteration reports.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    /// ‖Ax − y‖ / ‖y‖.
    pub residual: f64,
    /// The solver's objective.
    pub objective: f64,
    /// ‖x_k − x_{k−1}‖ / ‖x_k‖.
    pub change: f64,
    /// The solver's own convergence test held (e.g. an unchanged support and a small change).
    pub converged: bool,
}

impl Progress {
    /// The progress of an iteration whose objective is ½‖r‖² for the residual r with
    /// ‖r‖² = `rr`, relative to ‖y‖ = `ynorm`.
    pub fn least_squares(rr: f64, ynorm: f64, change: f64, converged: bool) -> Self {
        Progress {
            residual: rr.sqrt() / ynorm,
            objective: 0.5 * rr,
            change,
            converged,
        }
    }
}

/// Sets r = y − Ax from Ax and returns ‖r‖² (in `f64`).
///
/// # Errors
/// [`Error::Breakdown`](crate::Error::Breakdown) naming `solver` and the iteration when the
/// residual is not finite.
pub(super) fn refresh_residual<T: Real>(
    solver: &'static str,
    it: usize,
    y: &[T],
    ax: &[T],
    r: &mut [T],
) -> Result<f64> {
    for ((ri, &yi), &ai) in r.iter_mut().zip(y).zip(ax) {
        *ri = yi - ai;
    }
    let rr = crate::linalg::norm2_sq(r);
    if !rr.is_finite() {
        return Err(crate::Error::Breakdown {
            solver,
            reason: format!("non-finite residual at iteration {it}"),
        });
    }
    Ok(rr)
}

/// A solver's state between iterations: the protocol every iterative solver of this module
/// implements.
pub trait Iteration<T: Real>: Sized {
    /// The solver's name in reports and errors.
    const NAME: &'static str;
    /// The solver's parameters.
    type Params: Clone + std::fmt::Debug;

    /// The stopping rules in `params`.
    fn stopping(params: &Self::Params) -> Stopping;

    /// Checks what can be checked of `params` without the operator.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the field.
    fn check_params(params: &Self::Params) -> Result<()>;

    /// Validates the inputs and prepares the first iteration from the warm start `x` (which it
    /// may modify). Ends the run at once (`Break`) when there is nothing to iterate.
    fn start<A: LinearOperator<T> + ?Sized>(
        op: &A,
        y: &[T],
        x: &mut [T],
        params: &Self::Params,
    ) -> Result<ControlFlow<Termination, Self>>;

    /// The work an iteration needs before its update (a gradient or proxy); `true` when that
    /// work shows the current x to be a solution, so that no iteration follows.
    fn prepare<A: LinearOperator<T> + ?Sized>(&mut self, _op: &A) -> bool {
        false
    }

    /// Iteration `it` (1-based): updates `x` in place.
    fn step<A: LinearOperator<T> + ?Sized>(
        &mut self,
        op: &A,
        y: &[T],
        x: &mut [T],
        it: usize,
    ) -> Result<Progress>;

    /// The objective at the current x.
    fn objective(&self) -> f64;
}

/// The native loop: `prepare`, `step`, and the [`Stopping`] rules with the observer, until one
/// of them ends the run. The solver's own convergence takes precedence over the iteration limit.
///
/// # Errors
/// Those of the iteration's `start` and `step`.
pub fn solve<T, A, O, I>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &I::Params,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
    I: Iteration<T>,
{
    let op = Counted::new(op);
    let mut monitor = Monitor::new(I::NAME, I::stopping(params), observer);
    let mut run = match I::start(&op, y, x, params)? {
        ControlFlow::Continue(run) => run,
        ControlFlow::Break(termination) => return Ok(monitor.finish(0, termination, &op)),
    };
    let mut it = 0;
    loop {
        if run.prepare(&op) {
            return Ok(monitor.finish(it, Termination::Converged, &op));
        }
        it += 1;
        let p = run.step(&op, y, x, it)?;
        match monitor.step(it, p.residual, p.objective, p.change, x) {
            Some(Termination::MaxIterations) | None if p.converged => {
                return Ok(monitor.finish(it, Termination::Converged, &op));
            }
            Some(termination) => return Ok(monitor.finish(it, termination, &op)),
            None => {}
        }
    }
}

/// Makes `scratch` the length `op` asks for (scratch is not serialized, so a deserialized
/// iteration starts without it).
pub(super) fn fit_scratch<T: Real, A: LinearOperator<T> + ?Sized>(scratch: &mut Vec<T>, op: &A) {
    let len = op.scratch_len();
    if scratch.len() != len {
        *scratch = vec![T::zero(); len];
    }
}

/// [`Stopping`] in a serializable form.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(super) struct StoppingRecord {
    pub max_iter: usize,
    pub rel_residual: Option<f64>,
    pub rel_change: Option<f64>,
    /// (rel, window) of [`Stagnation`].
    pub stagnation: Option<(f64, usize)>,
    pub time_limit: Option<Duration>,
}

impl From<Stopping> for StoppingRecord {
    fn from(s: Stopping) -> Self {
        StoppingRecord {
            max_iter: s.max_iter,
            rel_residual: s.rel_residual,
            rel_change: s.rel_change,
            stagnation: s.stagnation.map(|g| (g.rel, g.window)),
            time_limit: s.time_limit,
        }
    }
}

impl From<StoppingRecord> for Stopping {
    fn from(s: StoppingRecord) -> Self {
        Stopping {
            max_iter: s.max_iter,
            rel_residual: s.rel_residual,
            rel_change: s.rel_change,
            stagnation: s.stagnation.map(|(rel, window)| Stagnation { rel, window }),
            time_limit: s.time_limit,
        }
    }
}
