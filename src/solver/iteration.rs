//! The iteration protocol: an iterative solver's state as a value, set up once from the warm
//! start, stepped, then finished. [`solve`] is the one loop that owns the stopping rules, the
//! observer, the apply counts and the report of every iterative solver;
//! [`ArgminSolver`](super::ArgminSolver) steps the same value from argmin's `next_iter`, so both
//! drivers perform the same arithmetic.
//!
//! The protocol is generic over the operator: a solver states what it needs of it (any
//! [`LinearOperator`], or the per-pixel [`VoxelOperator`](crate::operator::VoxelOperator)), and
//! the loop hands it the operator wrapped in [`Counted`], which has every capability of the
//! operator it wraps.

use std::ops::ControlFlow;

use crate::error::{Error, Result};
use crate::operator::{Counted, LinearOperator};
use crate::real::Real;
use crate::space::{self, Space};

use super::{Monitor, Observer, Report, Stopping, Termination};

/// What one iteration reports.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    /// ‖Ax − y‖ / ‖y‖.
    pub residual: f64,
    /// The solver's objective.
    pub objective: f64,
    /// ‖x_k − x_{k−1}‖ / ‖x_k‖.
    pub change: f64,
    /// The solver's own reason to end the run, if any: [`Termination::Converged`] when its
    /// convergence test held (e.g. an unchanged support and a small change), or another
    /// (e.g. [`Termination::Stagnation`] for a solver that counts iterations without progress).
    pub ending: Option<Termination>,
}

impl Progress {
    /// The progress of an iteration whose objective is ½‖r‖² for the residual r with
    /// ‖r‖² = `rr`, relative to ‖y‖ = `ynorm`.
    pub fn least_squares(rr: f64, ynorm: f64, change: f64, converged: bool) -> Self {
        Progress {
            residual: rr.sqrt() / ynorm,
            objective: 0.5 * rr,
            change,
            ending: converged.then_some(Termination::Converged),
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

/// What an iterative solver is apart from the operator it runs on: its name, parameters and
/// stopping rules.
pub trait Iterative<T: Real> {
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
}

/// A solver's state between iterations: the protocol every iterative solver implements, on
/// operators of type `A` (the solver implements it for every `A` with the capability it needs).
pub trait Iteration<T: Real, A: ?Sized>: Iterative<T> + Sized {
    /// Validates the inputs and prepares the first iteration from the warm start `x` (which it
    /// may modify). Ends the run at once (`Break`) when there is nothing to iterate.
    fn start(
        op: &A,
        y: &[T],
        x: &mut [T],
        params: &Self::Params,
    ) -> Result<ControlFlow<Termination, Self>>;

    /// The work an iteration needs before its update (a gradient or proxy); a termination when
    /// that work shows the current x to be a solution, so that no iteration follows.
    fn prepare(&mut self, _op: &A) -> Option<Termination> {
        None
    }

    /// Iteration `it` (1-based): updates `x` in place.
    fn step(&mut self, op: &A, y: &[T], x: &mut [T], it: usize) -> Result<Progress>;

    /// The objective at the current x.
    fn objective(&self) -> f64;

    /// The solver's last word once the run has ended for `termination`, after `iterations`
    /// iterations: e.g. the best iterate instead of the last, or a final test of the
    /// amplitudes. Nothing by default.
    ///
    /// # Errors
    /// Those of the work it does.
    fn finish(&mut self, _op: &A, _y: &[T], _x: &mut [T], _termination: Termination) -> Result<()> {
        Ok(())
    }
}

/// The termination of an iteration whose progress is `p` and for which the stopping rules
/// decided `rules`: the solver's own ending takes precedence over the iteration limit.
pub(super) fn ending(rules: Option<Termination>, p: &Progress) -> Option<Termination> {
    match rules {
        Some(Termination::MaxIterations) | None if p.ending.is_some() => p.ending,
        other => other,
    }
}

/// Every ending, in the order [`agreed`] ranks them.
const ENDINGS: [Termination; 8] = [
    Termination::MaxIterations,
    Termination::Residual,
    Termination::Change,
    Termination::Stagnation,
    Termination::Converged,
    Termination::ZeroResidual,
    Termination::TimeLimit,
    Termination::Observer,
];

/// The ending of every part of split unknowns: a part's own observer or clock may end its run
/// alone (the other rules see the same reduced values in every part), and then every part ends
/// with it, with the last of [`ENDINGS`] any part reached. `local` itself when the space is
/// whole.
fn agreed(space: &dyn Space, local: Option<Termination>) -> Option<Termination> {
    if space.parts() == 1 {
        return local;
    }
    let code = local.map_or(0, |t| 1 + ENDINGS.iter().position(|&e| e == t).unwrap_or(0));
    match space::max(space, code as f64) as usize {
        0 => None,
        c => Some(ENDINGS[c - 1]),
    }
}

/// The native loop: `prepare`, `step`, and the [`Stopping`] rules with the observer, until one
/// of them ends the run; then `finish`. The solver's own ending takes precedence over the
/// iteration limit.
///
/// # Errors
/// Those of the iteration's `start`, `step` and `finish`.
pub fn solve<'a, T, A, O, I>(
    op: &'a A,
    y: &[T],
    x: &mut [T],
    params: &I::Params,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
    I: Iteration<T, Counted<&'a A>>,
{
    solve_with::<T, A, O, I>(op, y, x, params, observer).map(|(report, _)| report)
}

/// [`solve`], also returning the solver's final state (`None` when it ended before its first
/// iteration), for solvers whose state holds more than x (e.g. posteriors).
///
/// # Errors
/// Those of [`solve`].
pub fn solve_with<'a, T, A, O, I>(
    op: &'a A,
    y: &[T],
    x: &mut [T],
    params: &I::Params,
    observer: &mut O,
) -> Result<(Report, Option<I>)>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
    I: Iteration<T, Counted<&'a A>>,
{
    let op = Counted::new(op);
    let space = LinearOperator::space(&op);
    let mut monitor = Monitor::new(I::NAME, I::stopping(params), observer);
    let started = I::start(&op, y, x, params);
    // Over split unknowns every part starts, or none does.
    if space.parts() > 1 && !space::all(space, started.is_ok()) && started.is_ok() {
        return Err(Error::param(
            "parts",
            "another part of the split unknowns could not start the solver",
        ));
    }
    let mut run = match started? {
        ControlFlow::Continue(run) => run,
        ControlFlow::Break(termination) => return Ok((monitor.finish(0, termination, &op), None)),
    };
    let mut it = 0;
    let termination = loop {
        if let Some(t) = run.prepare(&op) {
            break t;
        }
        it += 1;
        let p = run.step(&op, y, x, it)?;
        let local = ending(monitor.step(it, p.residual, p.objective, p.change, x), &p);
        if let Some(t) = agreed(space, local) {
            break t;
        }
    };
    run.finish(&op, y, x, termination)?;
    Ok((monitor.finish(it, termination, &op), Some(run)))
}

/// Makes `scratch` the length `op` asks for (scratch is not serialized, so a deserialized
/// iteration starts without it).
pub(super) fn fit_scratch<T: Real, A: LinearOperator<T> + ?Sized>(scratch: &mut Vec<T>, op: &A) {
    let len = op.scratch_len();
    if scratch.len() != len {
        *scratch = vec![T::zero(); len];
    }
}
