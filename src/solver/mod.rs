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

mod argmin;
mod backprojection;
mod cgls;
mod cosamp;
mod fista;
mod iht;
mod iteration;
mod pixelwise;
#[cfg(feature = "progress")]
mod progress;
mod stopping;
mod tv;

use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

pub use argmin::{
    ArgminCgls, ArgminCosamp, ArgminFista, ArgminIht, ArgminSolver, ArgminState, LinearLeastSquares,
};
pub use backprojection::{
    backprojection, select_peaks, Backprojection, BackprojectionResult, PeakSelection, Threshold,
};
pub use cgls::{cgls, CglsIteration, CglsParams};
pub use cosamp::{cosamp, CosampIteration, CosampParams};
pub use fista::{fista, FistaIteration, FistaParams, Lambda, Restart, StepRule};
pub use iht::{iht, IhtIteration, IhtParams, IhtStep};
pub use iteration::{solve, solve_with, Iteration, Iterative, Progress};
pub use pixelwise::{
    model_based, refine_surfaces, reflector_amp, tv_depth, ModelBasedParams, RefineParams,
    ReflectorAmpParams, TvDepthParams,
};
#[cfg(feature = "progress")]
pub use progress::ProgressObserver;
pub use stopping::{Stagnation, Stopping};
pub use tv::{tv_denoise, TvNorm, TvParams, TvSteps};

use stopping::StopRules;

use crate::error::{Error, Result};
use crate::linalg::dist2_sq;
use crate::operator::{operator_norm, PowerIteration};
use crate::operator::{Applies, Counted};
use crate::real::Real;

/// Why a solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
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

impl Termination {
    /// Every termination, in a fixed order (to number them, e.g. to send them between
    /// processes).
    pub const ALL: [Termination; 8] = [
        Termination::MaxIterations,
        Termination::Residual,
        Termination::Change,
        Termination::Stagnation,
        Termination::TimeLimit,
        Termination::Observer,
        Termination::Converged,
        Termination::ZeroResidual,
    ];
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

/// What a solver did. Serialized with its fields' names, the time as `solver_seconds`.
#[derive(Debug, Clone, PartialEq, Serialize)]
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
    /// Applications, in either direction, of the operator restricted to a few columns
    /// ([`LinearOperator::restrict_columns`](crate::operator::LinearOperator::restrict_columns))
    /// or of its sparse forward, when the solver counts them apart: for the lidar operator each
    /// costs O(support × K_p) instead of a full application's O(M·N·K). Solvers that do not
    /// count them apart include them in the forward and adjoint counts.
    pub support_applies: usize,
    /// Wall-clock time.
    #[serde(
        rename = "solver_seconds",
        serialize_with = "crate::units::serialize_seconds"
    )]
    pub elapsed: Duration,
}

impl Report {
    /// Appends a later run to this one: counts, histories and time are added, the termination
    /// and the solver's name become the later run's.
    pub fn absorb(&mut self, later: Report) {
        self.absorb_applies(&later);
        self.solver = later.solver;
        self.iterations += later.iterations;
        self.termination = later.termination;
        self.residual_history.extend(later.residual_history);
        self.objective_history.extend(later.objective_history);
    }

    /// The report of `solver` before any iteration: what a method with no iterations (a
    /// backprojection) starts from when later steps add their work.
    pub fn empty(solver: &'static str) -> Report {
        Report {
            solver,
            iterations: 0,
            termination: Termination::Converged,
            residual_history: Vec::new(),
            objective_history: Vec::new(),
            forward_applies: 0,
            adjoint_applies: 0,
            support_applies: 0,
            elapsed: Duration::ZERO,
        }
    }

    /// Adds the apply counts and the time of a subsidiary run (a refinement step) to this one,
    /// leaving the iterations, histories and termination as they are.
    pub fn absorb_applies(&mut self, other: &Report) {
        self.add_applies(other.applies());
        self.elapsed += other.elapsed;
    }

    /// Its applications.
    pub fn applies(&self) -> Applies {
        Applies {
            forward: self.forward_applies,
            adjoint: self.adjoint_applies,
            support: self.support_applies,
        }
    }

    /// The apply counts become `applies`: those a counter ([`Counted::applies`]) saw of every
    /// application of a composite solver's parts.
    pub fn set_applies(&mut self, applies: Applies) {
        self.forward_applies = applies.forward;
        self.adjoint_applies = applies.adjoint;
        self.support_applies = applies.support;
    }

    /// Adds `applies`: work done for this run outside its solver (a residual measured
    /// afterwards, counted by a [`Counted`] wrapper), or by a run whose report is not at hand.
    pub fn add_applies(&mut self, applies: Applies) {
        self.set_applies(self.applies() + applies);
    }

    /// Every application counted, full and support ones alike.
    pub fn total_applies(&self) -> usize {
        self.forward_applies + self.adjoint_applies + self.support_applies
    }
}

/// The shared bookkeeping of an iterative run: histories, stopping rules, the observer.
pub(crate) struct Monitor<'o, T, O: Observer<T> + ?Sized> {
    solver: &'static str,
    rules: StopRules,
    observer: &'o mut O,
    start: Instant,
    residuals: Vec<f64>,
    objectives: Vec<f64>,
    _t: std::marker::PhantomData<T>,
}

impl<'o, T: Real, O: Observer<T> + ?Sized> Monitor<'o, T, O> {
    pub(crate) fn new(solver: &'static str, stop: Stopping, observer: &'o mut O) -> Self {
        Monitor {
            solver,
            rules: StopRules::new(stop),
            observer,
            start: Instant::now(),
            residuals: Vec::new(),
            objectives: Vec::new(),
            _t: std::marker::PhantomData,
        }
    }

    /// Records iteration `it` and decides whether to stop. Checks, in order: the observer, the
    /// convergence rules (residual, change, stagnation), the limits (time, iterations).
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
        self.rules
            .converged(residual, objective, change)
            .or_else(|| self.rules.limit(it, info.elapsed))
    }

    /// The report of a run that ended after `iterations` for `termination`, with the apply
    /// counts of the solver's counting wrapper.
    pub(crate) fn finish<A: ?Sized>(
        self,
        iterations: usize,
        termination: Termination,
        op: &Counted<&A>,
    ) -> Report {
        Report {
            solver: self.solver,
            iterations,
            termination,
            residual_history: self.residuals,
            objective_history: self.objectives,
            forward_applies: op.forward_count(),
            adjoint_applies: op.adjoint_count(),
            support_applies: op.support_count(),
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

/// Checks that a solver's inputs fit the operator and are finite. The check is collective: when
/// the unknowns are split, a part whose own inputs pass learns that another part's did not.
pub(crate) fn check_problem<T: Real>(
    solver: &'static str,
    space: &dyn crate::space::Space,
    nrows: usize,
    ncols: usize,
    y: &[T],
    x: &[T],
) -> Result<()> {
    let local = check_part(solver, nrows, ncols, y, x);
    if crate::space::max(space, f64::from(u8::from(local.is_err()))) > 0.0 {
        local?;
        return Err(Error::param(
            "x",
            format!("{solver}: the inputs of another part of the unknowns are invalid"),
        ));
    }
    Ok(())
}

/// [`check_problem`] on this part.
fn check_part<T: Real>(
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

/// ‖y − Ax‖², accumulated in `f64` (one forward application).
pub(crate) fn residual_norm_sq<T: Real, A: crate::operator::LinearOperator<T> + ?Sized>(
    op: &A,
    y: &[T],
    x: &[T],
) -> f64 {
    let mut ax = vec![T::zero(); y.len()];
    op.apply(x, &mut ax);
    dist2_sq(y, &ax)
}

/// Indices of the nonzero entries, in increasing order.
pub(crate) fn support<T: Real>(v: &[T]) -> Vec<usize> {
    v.iter()
        .enumerate()
        .filter(|(_, x)| **x != T::zero())
        .map(|(i, _)| i)
        .collect()
}

/// Checks the settings of a step derived from the Lanczos estimate of ‖A‖.
pub(crate) fn validate_power_step(settings: &PowerIteration, margin: f64) -> Result<()> {
    if settings.max_iter == 0 {
        return Err(Error::param(
            "power_iteration.max_iter",
            "must be at least 1",
        ));
    }
    if !(settings.tol.is_finite() && settings.tol > 0.0) {
        return Err(Error::param(
            "power_iteration.tol",
            format!(
                "must be a positive finite number, got {}",
                crate::units::number(settings.tol)
            ),
        ));
    }
    if !(margin.is_finite() && margin >= 1.0) {
        return Err(Error::param(
            "margin",
            format!(
                "must be a finite number ≥ 1, got {}",
                crate::units::number(margin)
            ),
        ));
    }
    Ok(())
}

/// L = margin · σ², with σ the Lanczos estimate of ‖A‖₂ (a lower bound, hence the
/// margin); 0 when the operator maps the start vector to zero.
pub(crate) fn lipschitz_estimate<T: Real, A: crate::operator::LinearOperator<T> + ?Sized>(
    op: &A,
    settings: &PowerIteration,
    margin: f64,
) -> Result<f64> {
    let sigma = operator_norm(op, settings)?.value;
    let l = margin * sigma * sigma;
    if !l.is_finite() {
        return Err(Error::NonFinite {
            what: format!("Lipschitz constant from the operator norm estimate {sigma}"),
        });
    }
    Ok(l)
}

/// Checks a sparsity level against the number of unknowns.
pub(crate) fn check_sparsity(sparsity: usize, n: usize) -> Result<()> {
    if sparsity == 0 || sparsity > n {
        return Err(Error::param(
            "sparsity",
            format!("must be between 1 and the {n} unknowns, got {sparsity}"),
        ));
    }
    Ok(())
}

/// Checks that a tolerance is a finite number ≥ 0.
pub(crate) fn check_tolerance(name: &'static str, value: f64) -> Result<()> {
    if !(value.is_finite() && value >= 0.0) {
        return Err(Error::param(
            name,
            format!(
                "must be a finite number ≥ 0, got {}",
                crate::units::number(value)
            ),
        ));
    }
    Ok(())
}

/// The part of the sparsity check that needs no operator.
pub(crate) fn check_nonzero_sparsity(sparsity: usize) -> Result<()> {
    if sparsity == 0 {
        return Err(Error::param("sparsity", "must be at least 1, got 0"));
    }
    Ok(())
}
