//! Reconstruction algorithms on any [`LinearOperator`](crate::operator::LinearOperator).
//!
//! Every iterative solver shares one interface (in the spirit of faer's and argmin's):
//!
//! * a parameter struct with validated defaults, containing a [`Stopping`] rule set (iteration
//!   limit, relative residual, relative change of x, objective stagnation, wall-clock limit);
//! * a warm start from the `x` passed in;
//! * an [`Observer`] called after every iteration with an [`IterationInfo`], which may stop the run
//!   (progress bars, traces and user early stops are observers; `()` observes nothing);
//! * a [`Report`] with the iterations done, the [`Termination`] reason, the residual and objective
//!   histories, the operator-apply counts and the elapsed time.
//!
//! Reaching the iteration limit is a termination reason, not an error; invalid parameters,
//! mismatched shapes, non-finite data and numerical breakdowns are [`Error`]s.

mod argmin_cgls;
mod backprojection;
mod cgls;

use std::time::{Duration, Instant};

pub use argmin_cgls::{ArgminCgls, CglsState, LinearLeastSquares};
pub use backprojection::{backprojection, Backprojection, BackprojectionResult, Threshold};
pub use cgls::{cgls, CglsParams};

use crate::error::{Error, Result};
use crate::real::Real;

/// When an iterative solver stops. Criteria set to `None` are off.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stopping {
    /// Maximum number of iterations (at least 1).
    pub max_iter: usize,
    /// Stop when the solver's residual measure, relative to its initial value, is at most this.
    pub rel_residual: Option<f64>,
    /// Stop when ‖x_k − x_{k−1}‖ / ‖x_k‖ is at most this.
    pub rel_change: Option<f64>,
    /// Stop when the objective improved by less than `rel` (relative) over the last `window`
    /// iterations.
    pub stagnation: Option<Stagnation>,
    /// Stop after this much wall-clock time (checked after each iteration).
    pub time_limit: Option<Duration>,
}

/// Objective stagnation: relative improvement below `rel` over `window` iterations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stagnation {
    /// Relative improvement threshold.
    pub rel: f64,
    /// Number of iterations it is measured over.
    pub window: usize,
}

impl Default for Stopping {
    fn default() -> Self {
        Stopping {
            max_iter: 100,
            rel_residual: Some(1e-6),
            rel_change: None,
            stagnation: None,
            time_limit: None,
        }
    }
}

impl Stopping {
    /// Only an iteration limit.
    pub fn iterations(max_iter: usize) -> Self {
        Stopping {
            max_iter,
            rel_residual: None,
            ..Stopping::default()
        }
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the field.
    pub fn validate(&self) -> Result<()> {
        if self.max_iter == 0 {
            return Err(Error::param("max_iter", "must be at least 1"));
        }
        let positive = |name: &'static str, v: Option<f64>| match v {
            Some(t) if !(t.is_finite() && t >= 0.0) => Err(Error::param(
                name,
                format!("must be a finite number ≥ 0, got {t}"),
            )),
            _ => Ok(()),
        };
        positive("rel_residual", self.rel_residual)?;
        positive("rel_change", self.rel_change)?;
        if let Some(s) = self.stagnation {
            positive("stagnation.rel", Some(s.rel))?;
            if s.window == 0 {
                return Err(Error::param("stagnation.window", "must be at least 1"));
            }
        }
        Ok(())
    }
}

/// Why a solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Termination {
    /// The iteration limit was reached.
    MaxIterations,
    /// The relative residual fell below its tolerance.
    Residual,
    /// The relative change of x fell below its tolerance.
    Change,
    /// The objective stagnated.
    Stagnation,
    /// The wall-clock limit was reached.
    TimeLimit,
    /// The observer asked to stop.
    Observer,
    /// The solver's own convergence test held (e.g. an unchanged support).
    Converged,
    /// Nothing to do: the data or the initial residual is exactly zero.
    ZeroResidual,
}

/// What an observer sees after each iteration.
#[derive(Debug)]
pub struct IterationInfo<'a, T> {
    /// Iterations completed (1 after the first).
    pub iteration: usize,
    /// The solver's residual measure, relative to its initial value.
    pub residual: f64,
    /// The objective value (solver-specific; NaN when not computed).
    pub objective: f64,
    /// ‖x_k − x_{k−1}‖ / ‖x_k‖ (NaN when not computed).
    pub change: f64,
    /// The current iterate.
    pub x: &'a [T],
    /// Time since the solver started.
    pub elapsed: Duration,
}

/// Whether to go on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// Continue iterating.
    Continue,
    /// Stop now ([`Termination::Observer`]).
    Stop,
}

/// Called after every iteration.
pub trait Observer<T> {
    /// Looks at the iteration; returns [`Control::Stop`] to end the run.
    fn observe(&mut self, info: &IterationInfo<'_, T>) -> Control;
}

/// Observes nothing.
impl<T> Observer<T> for () {
    fn observe(&mut self, _: &IterationInfo<'_, T>) -> Control {
        Control::Continue
    }
}

/// Any `FnMut(&IterationInfo) -> Control` is an observer.
impl<T, F: FnMut(&IterationInfo<'_, T>) -> Control> Observer<T> for F {
    fn observe(&mut self, info: &IterationInfo<'_, T>) -> Control {
        self(info)
    }
}

/// What a solver did.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// The solver's name.
    pub solver: &'static str,
    /// Iterations performed.
    pub iterations: usize,
    /// Why it stopped.
    pub termination: Termination,
    /// Relative residual after each iteration.
    pub residual_history: Vec<f64>,
    /// Objective after each iteration (NaN where not computed).
    pub objective_history: Vec<f64>,
    /// Forward applications of the operator.
    pub forward_applies: usize,
    /// Adjoint applications of the operator.
    pub adjoint_applies: usize,
    /// Wall-clock time.
    pub elapsed: Duration,
}

/// The shared bookkeeping of an iterative run: histories, stopping rules, the observer.
pub(crate) struct Monitor<'o, T, O: Observer<T> + ?Sized> {
    stop: Stopping,
    observer: &'o mut O,
    start: Instant,
    residuals: Vec<f64>,
    objectives: Vec<f64>,
    _t: std::marker::PhantomData<T>,
}

impl<'o, T: Real, O: Observer<T> + ?Sized> Monitor<'o, T, O> {
    pub(crate) fn new(stop: Stopping, observer: &'o mut O) -> Self {
        Monitor {
            stop,
            observer,
            start: Instant::now(),
            residuals: Vec::new(),
            objectives: Vec::new(),
            _t: std::marker::PhantomData,
        }
    }

    /// Records iteration `it` and decides whether to stop. Checks, in order: the observer,
    /// residual, change, stagnation, time, iteration limit.
    pub(crate) fn step(
        &mut self,
        it: usize,
        residual: f64,
        objective: f64,
        change: f64,
        x: &[T],
    ) -> Option<Termination> {
        self.residuals.push(residual);
        self.objectives.push(objective);
        let info = IterationInfo {
            iteration: it,
            residual,
            objective,
            change,
            x,
            elapsed: self.start.elapsed(),
        };
        if self.observer.observe(&info) == Control::Stop {
            return Some(Termination::Observer);
        }
        if self.stop.rel_residual.is_some_and(|t| residual <= t) {
            return Some(Termination::Residual);
        }
        if self.stop.rel_change.is_some_and(|t| change <= t) {
            return Some(Termination::Change);
        }
        if let Some(s) = self.stop.stagnation {
            let n = self.objectives.len();
            if n > s.window {
                let (old, new) = (self.objectives[n - 1 - s.window], self.objectives[n - 1]);
                if (old - new) <= s.rel * old.abs().max(f64::MIN_POSITIVE) {
                    return Some(Termination::Stagnation);
                }
            }
        }
        if self.stop.time_limit.is_some_and(|t| info.elapsed >= t) {
            return Some(Termination::TimeLimit);
        }
        if it >= self.stop.max_iter {
            return Some(Termination::MaxIterations);
        }
        None
    }

    pub(crate) fn finish(
        self,
        solver: &'static str,
        iterations: usize,
        termination: Termination,
        forward_applies: usize,
        adjoint_applies: usize,
    ) -> Report {
        Report {
            solver,
            iterations,
            termination,
            residual_history: self.residuals,
            objective_history: self.objectives,
            forward_applies,
            adjoint_applies,
            elapsed: self.start.elapsed(),
        }
    }
}

/// Checks that measurements fit the operator's rows and are finite.
pub(crate) fn check_measurements<T: Real>(
    solver: &'static str,
    nrows: usize,
    y: &[T],
) -> Result<()> {
    if y.len() != nrows {
        return Err(Error::shape(
            format!("{solver}: measurements vs operator rows"),
            nrows,
            y.len(),
        ));
    }
    if let Some(i) = y.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFinite {
            what: format!("{solver}: measurement {i}"),
        });
    }
    Ok(())
}

/// Checks that a solver's inputs fit the operator and are finite.
pub(crate) fn check_problem<T: Real>(
    solver: &'static str,
    nrows: usize,
    ncols: usize,
    y: &[T],
    x: &[T],
) -> Result<()> {
    check_measurements(solver, nrows, y)?;
    if x.len() != ncols {
        return Err(Error::shape(
            format!("{solver}: x vs operator columns"),
            ncols,
            x.len(),
        ));
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFinite {
            what: format!("{solver}: initial x entry {i}"),
        });
    }
    Ok(())
}
