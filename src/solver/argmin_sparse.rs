//! FISTA, IHT and CoSaMP driven by argmin's `Executor`, so argmin's observers, time limits and
//! checkpointing apply. Each `next_iter` performs one iteration of the native solver (the same
//! code, so the iterates agree to the last bit).

use std::collections::VecDeque;
use std::ops::ControlFlow;

use argmin::core::{IterState, Problem, Solver, State, TerminationReason, TerminationStatus, KV};
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::linalg::norm2_sq;
use crate::operator::{Counted, LinearOperator};
use crate::real::Real;

use super::argmin_cgls::count_applies;
use super::cosamp::CosampIteration;
use super::fista::FistaIteration;
use super::iht::IhtIteration;
use super::iteration::{Iteration, Progress, StoppingRecord};
use super::{CosampParams, FistaParams, IhtParams, LinearLeastSquares, Stopping};

/// The argmin state of [`ArgminFista`], [`ArgminIht`] and [`ArgminCosamp`]: the parameter is the
/// iterate x, the cost the solver's objective. The same type as [`CglsState`](super::CglsState).
pub type SparseState<T> = IterState<Vec<T>, (), (), (), (), f64>;

/// The operator and the measurements of an undamped problem.
fn operands<'a, T, A: ?Sized>(
    problem: &Problem<LinearLeastSquares<'a, T, A>>,
    solver: &str,
) -> Result<(&'a A, &'a [T]), Error> {
    let lls = problem
        .problem
        .as_ref()
        .ok_or_else(|| Error::param("problem", "missing"))?;
    if lls.damp != 0.0 {
        return Err(Error::param(
            "damp",
            format!(
                "{solver} works on the undamped ½‖Ax − y‖²: the problem's damp must be 0, got {}",
                lls.damp
            ),
        ));
    }
    Ok((lls.op, lls.y))
}

/// The native solver's convergence rules, apart from its limits (`max_iter` and `time_limit`
/// are left to the executor).
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Rules {
    stopping: StoppingRecord,
    /// The last `window + 1` objectives, for the stagnation rule.
    objectives: VecDeque<f64>,
}

impl Rules {
    /// Records an iteration; `true` when the solver's own test or one of the residual, change and
    /// stagnation rules holds.
    fn met(&mut self, p: &Progress) -> bool {
        let mut stagnated = false;
        if let Some((rel, window)) = self.stopping.stagnation {
            self.objectives.push_back(p.objective);
            if self.objectives.len() > window + 1 {
                self.objectives.pop_front();
            }
            if let (true, Some(&old), Some(&new)) = (
                self.objectives.len() == window + 1,
                self.objectives.front(),
                self.objectives.back(),
            ) {
                stagnated = (old - new) <= rel * old.abs().max(f64::MIN_POSITIVE);
            }
        }
        p.converged
            || stagnated
            || self.stopping.rel_residual.is_some_and(|t| p.residual <= t)
            || self.stopping.rel_change.is_some_and(|t| p.change <= t)
    }
}

/// The part of an argmin solver that steps a native iteration.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Driver<I> {
    rules: Rules,
    /// `None` before `init`, and after an `init` that found nothing to iterate.
    iteration: Option<I>,
    /// Whether [`Iteration::prepare`] has run for the next update.
    prepared: bool,
    /// Whether the run has converged.
    converged: bool,
}

impl<I> Driver<I> {
    fn new(stopping: Stopping) -> Self {
        Driver {
            rules: Rules {
                stopping: stopping.into(),
                objectives: VecDeque::new(),
            },
            iteration: None,
            prepared: false,
            converged: false,
        }
    }

    fn init<'a, T, A>(
        &mut self,
        params: Option<&I::Params>,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        mut state: SparseState<T>,
    ) -> Result<(SparseState<T>, Option<KV>), argmin::core::Error>
    where
        T: Real,
        A: LinearOperator<T> + ?Sized,
        I: Iteration<T>,
    {
        let mut x = state.take_param().ok_or_else(|| {
            Error::param(
                "param",
                format!("{} needs an initial x (configure `param`)", I::NAME),
            )
        })?;
        let (op, y) = operands(problem, I::NAME)?;
        let params = params.ok_or_else(|| {
            Error::param(
                "params",
                "the parameters are not serialized: a deserialized solver can only resume a run",
            )
        })?;
        let op = Counted::new(op);
        let started = I::start(&op, y, &mut x, params);
        let cost = match started {
            Ok(ControlFlow::Continue(mut iteration)) => {
                // The work before the first update, unless the executor allows no iteration.
                self.prepared = state.get_iter() < state.get_max_iters();
                self.converged = self.prepared && iteration.prepare(&op);
                let cost = iteration.objective();
                self.iteration = Some(iteration);
                Ok(cost)
            }
            // Zero measurements or a zero operator: x is a solution and Ax = 0, so the objective
            // is ½‖y‖².
            Ok(ControlFlow::Break(_)) => {
                self.converged = true;
                Ok(0.5 * norm2_sq(y))
            }
            Err(e) => Err(e),
        };
        count_applies(problem, op.forward_count(), op.adjoint_count());
        Ok((state.param(x).cost(cost?), None))
    }

    /// Iteration `iter + 1` (the executor has completed `iter`), updating `x`. `None` when the
    /// work before the update shows that x is a solution already, which can only happen when a
    /// run continues past the iteration limit it was prepared for (the work is then done here,
    /// and the executor counts one iteration more than the native solver would).
    fn advance<T, A>(
        &mut self,
        op: &A,
        y: &[T],
        x: &mut [T],
        iter: u64,
        max_iters: u64,
    ) -> Result<Option<Progress>, Error>
    where
        T: Real,
        A: LinearOperator<T> + ?Sized,
        I: Iteration<T>,
    {
        let iteration = self
            .iteration
            .as_mut()
            .ok_or_else(|| Error::param("state", "no iteration to continue"))?;
        if !self.prepared && iteration.prepare(op) {
            self.converged = true;
            return Ok(None);
        }
        let p = iteration.step(op, y, x, (iter + 1) as usize)?;
        self.converged = self.rules.met(&p);
        // Like the native solver, prepare the next update only when there is one.
        self.prepared = !self.converged && iter + 1 < max_iters;
        if self.prepared {
            self.converged = iteration.prepare(op);
        }
        Ok(Some(p))
    }

    fn next_iter<'a, T, A>(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        mut state: SparseState<T>,
    ) -> Result<(SparseState<T>, Option<KV>), argmin::core::Error>
    where
        T: Real,
        A: LinearOperator<T> + ?Sized,
        I: Iteration<T>,
    {
        let mut x = state
            .take_param()
            .ok_or_else(|| Error::param("param", "no current x"))?;
        let (op, y) = operands(problem, I::NAME)?;
        let op = Counted::new(op);
        let advanced = self.advance(&op, y, &mut x, state.get_iter(), state.get_max_iters());
        count_applies(problem, op.forward_count(), op.adjoint_count());
        match advanced? {
            Some(p) => {
                let kv = argmin::kv!("residual" => p.residual; "change" => p.change;);
                Ok((state.param(x).cost(p.objective), Some(kv)))
            }
            None => Ok((
                state
                    .param(x)
                    .terminate_with(TerminationReason::SolverConverged),
                None,
            )),
        }
    }

    fn terminate(&self) -> TerminationStatus {
        if self.converged {
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
        } else {
            TerminationStatus::NotTerminated
        }
    }
}

/// FISTA (see [`fista`](super::fista)) as an argmin [`Solver`] on a [`LinearLeastSquares`]
/// problem with `damp` 0: it minimizes ½‖Ax − y‖² + λ‖x‖₁ with λ, the step, the sign
/// constraint and the restart rule of its [`FistaParams`], one FISTA iteration per `next_iter`.
///
/// `init` does what [`fista`](super::fista) does before its first iteration (‖Aᵀy‖∞ for a
/// relative λ, the power iteration) and `next_iter` one iteration, with the same arithmetic, so
/// the iterates are those of the native solver. Operator applications are added to argmin's
/// counters `operator_forward` and `operator_adjoint`; the cost is the lasso objective, and the
/// key-value log has the relative residual ‖Ax − y‖ / ‖y‖ (`residual`) and the relative change
/// of x (`change`).
///
/// The run ends with `SolverConverged` when a residual, change or stagnation rule of
/// [`FistaParams::stopping`] holds, or after `init` when the native solver would not iterate
/// (y = 0, or a zero operator). `stopping.max_iter` and `stopping.time_limit` are not used: the
/// executor's `max_iters` and `timeout` limit the run. The solver is serializable for argmin's
/// checkpoints; its parameters are only needed by `init` and are not serialized, so a
/// deserialized solver resumes a run but cannot start one.
///
/// # Example
/// ```
/// use argmin::core::{Executor, State};
/// use rdlidar::operator::DenseMatrix;
/// use rdlidar::solver::{ArgminFista, FistaParams, Lambda, LinearLeastSquares};
///
/// let a = DenseMatrix::new(ndarray::array![[1.0, 0.0], [0.0, 1.0]]).unwrap();
/// let y = [3.0, 0.5];
/// let problem = LinearLeastSquares { op: &a, y: &y, damp: 0.0 };
/// let params = FistaParams { lambda: Lambda::Absolute(1.0), ..FistaParams::default() };
/// let result = Executor::new(problem, ArgminFista::new(params).unwrap())
///     .configure(|s| s.param(vec![0.0, 0.0]).max_iters(100))
///     .run()
///     .unwrap();
/// // Soft thresholding of y at λ = 1.
/// let x: &Vec<f64> = result.state().get_param().unwrap();
/// assert!((x[0] - 2.0).abs() < 1e-6 && x[1] == 0.0);
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ArgminFista<T> {
    #[serde(skip)]
    params: Option<FistaParams>,
    driver: Driver<FistaIteration<T>>,
}

impl<T: Real> ArgminFista<T> {
    /// A solver with these parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for parameters [`fista`](super::fista) rejects.
    pub fn new(params: FistaParams) -> Result<Self, Error> {
        params.validate()?;
        Ok(ArgminFista {
            params: Some(params),
            driver: Driver::new(params.stopping),
        })
    }
}

impl<'a, T, A> Solver<LinearLeastSquares<'a, T, A>, SparseState<T>> for ArgminFista<T>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
{
    fn name(&self) -> &str {
        "FISTA"
    }

    fn init(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        state: SparseState<T>,
    ) -> Result<(SparseState<T>, Option<KV>), argmin::core::Error> {
        self.driver.init(self.params.as_ref(), problem, state)
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        state: SparseState<T>,
    ) -> Result<(SparseState<T>, Option<KV>), argmin::core::Error> {
        self.driver.next_iter(problem, state)
    }

    fn terminate(&mut self, _state: &SparseState<T>) -> TerminationStatus {
        self.driver.terminate()
    }
}

/// Iterative hard thresholding (see [`iht`](super::iht)) as an argmin [`Solver`] on a
/// [`LinearLeastSquares`] problem with `damp` 0: it looks for an s-sparse minimizer of
/// ½‖Ax − y‖² with the sparsity and step rule of its [`IhtParams`], one IHT iteration per
/// `next_iter`.
///
/// `init` does what [`iht`](super::iht) does before its first iteration (pruning the warm start
/// to s entries, the power iteration of a fixed step) and `next_iter` one iteration, with the
/// same arithmetic, so the iterates are those of the native solver. The gradient an iteration
/// starts from is computed at the end of the previous one (or in `init`), only when the
/// executor allows another iteration, so the apply counts in argmin's counters
/// `operator_forward` and `operator_adjoint` equal the native solver's. The cost is ½‖Ax − y‖²;
/// the key-value log has the relative residual (`residual`) and the relative change of x
/// (`change`).
///
/// The run ends with `SolverConverged` under the native solver's convergence rules: an
/// unchanged support with a change of at most [`IhtParams::fixed_point_tol`], a zero gradient,
/// or a residual, change or stagnation rule of [`IhtParams::stopping`]; also after `init` when
/// the native solver would not iterate (y = 0, or a zero operator with the fixed step).
/// `stopping.max_iter` and `stopping.time_limit` are not used: the executor's `max_iters` and
/// `timeout` limit the run. The solver is serializable for argmin's checkpoints; its parameters
/// are only needed by `init` and are not serialized, so a deserialized solver resumes a run but
/// cannot start one.
///
/// # Example
/// ```
/// use argmin::core::{Executor, State, TerminationReason, TerminationStatus};
/// use rdlidar::operator::DenseMatrix;
/// use rdlidar::solver::{ArgminIht, IhtParams, LinearLeastSquares};
///
/// let a = DenseMatrix::new(ndarray::array![[1.0, 0.2, 0.0], [0.0, 1.0, 0.3]]).unwrap();
/// let y = [0.4, 2.0]; // A · (0, 2, 0)
/// let problem = LinearLeastSquares { op: &a, y: &y, damp: 0.0 };
/// let result = Executor::new(problem, ArgminIht::new(IhtParams::new(1)).unwrap())
///     .configure(|s| s.param(vec![0.0; 3]).max_iters(100))
///     .run()
///     .unwrap();
/// let x: &Vec<f64> = result.state().get_param().unwrap();
/// assert!(x[0] == 0.0 && (x[1] - 2.0).abs() < 1e-6 && x[2] == 0.0);
/// assert_eq!(
///     result.state().get_termination_status(),
///     &TerminationStatus::Terminated(TerminationReason::SolverConverged)
/// );
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ArgminIht<T> {
    #[serde(skip)]
    params: Option<IhtParams>,
    driver: Driver<IhtIteration<T>>,
}

impl<T: Real> ArgminIht<T> {
    /// A solver with these parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for parameters [`iht`](super::iht) rejects; a sparsity above
    /// the number of unknowns is reported by `init`, which knows the operator.
    pub fn new(params: IhtParams) -> Result<Self, Error> {
        params.validate_settings()?;
        check_nonzero_sparsity(params.sparsity)?;
        Ok(ArgminIht {
            params: Some(params),
            driver: Driver::new(params.stopping),
        })
    }
}

impl<'a, T, A> Solver<LinearLeastSquares<'a, T, A>, SparseState<T>> for ArgminIht<T>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
{
    fn name(&self) -> &str {
        "IHT"
    }

    fn init(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        state: SparseState<T>,
    ) -> Result<(SparseState<T>, Option<KV>), argmin::core::Error> {
        self.driver.init(self.params.as_ref(), problem, state)
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        state: SparseState<T>,
    ) -> Result<(SparseState<T>, Option<KV>), argmin::core::Error> {
        self.driver.next_iter(problem, state)
    }

    fn terminate(&mut self, _state: &SparseState<T>) -> TerminationStatus {
        self.driver.terminate()
    }
}

/// CoSaMP (see [`cosamp`](super::cosamp)) as an argmin [`Solver`] on a [`LinearLeastSquares`]
/// problem with `damp` 0: it looks for an s-sparse minimizer of ½‖Ax − y‖² with the sparsity and
/// inner least-squares settings of its [`CosampParams`], one CoSaMP iteration per `next_iter`.
///
/// `init` prunes the warm start to s entries as [`cosamp`](super::cosamp) does, and `next_iter`
/// performs one iteration with the same arithmetic, so the iterates are those of the native
/// solver. The proxy Aᵀr an iteration starts from is computed at the end of the previous one (or
/// in `init`), only when the executor allows another iteration, so the apply counts in argmin's
/// counters `operator_forward` and `operator_adjoint` (including those of the inner CGLS solves)
/// equal the native solver's. The cost is ½‖Ax − y‖²; the key-value log has the relative residual
/// (`residual`) and the relative change of x (`change`).
///
/// The run ends with `SolverConverged` under the native solver's convergence rules: an
/// unchanged support with a change of at most [`CosampParams::fixed_point_tol`], a zero proxy, or
/// a residual, change or stagnation rule of [`CosampParams::stopping`]; also after `init` when
/// y = 0. `stopping.max_iter` and `stopping.time_limit` are not used: the executor's `max_iters`
/// and `timeout` limit the run. The solver is serializable for argmin's checkpoints; its
/// parameters are only needed by `init` and are not serialized, so a deserialized solver resumes
/// a run but cannot start one.
///
/// # Example
/// ```
/// use argmin::core::{Executor, State};
/// use rdlidar::operator::DenseMatrix;
/// use rdlidar::solver::{ArgminCosamp, CosampParams, LinearLeastSquares};
///
/// let a = DenseMatrix::new(ndarray::array![[1.0, 0.2, 0.0], [0.0, 1.0, 0.3]]).unwrap();
/// let y = [0.4, 2.0]; // A · (0, 2, 0)
/// let problem = LinearLeastSquares { op: &a, y: &y, damp: 0.0 };
/// let result = Executor::new(problem, ArgminCosamp::new(CosampParams::new(1)).unwrap())
///     .configure(|s| s.param(vec![0.0; 3]).max_iters(20))
///     .run()
///     .unwrap();
/// let x: &Vec<f64> = result.state().get_param().unwrap();
/// assert!(x[0] == 0.0 && (x[1] - 2.0).abs() < 1e-6 && x[2] == 0.0);
/// assert!(result.problem().counts["operator_adjoint"] > 0);
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ArgminCosamp<T> {
    #[serde(skip)]
    params: Option<CosampParams>,
    driver: Driver<CosampIteration<T>>,
}

impl<T: Real> ArgminCosamp<T> {
    /// A solver with these parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for parameters [`cosamp`](super::cosamp) rejects; a sparsity
    /// above the number of unknowns is reported by `init`, which knows the operator.
    pub fn new(params: CosampParams) -> Result<Self, Error> {
        params.validate_settings()?;
        check_nonzero_sparsity(params.sparsity)?;
        Ok(ArgminCosamp {
            params: Some(params),
            driver: Driver::new(params.stopping),
        })
    }
}

impl<'a, T, A> Solver<LinearLeastSquares<'a, T, A>, SparseState<T>> for ArgminCosamp<T>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
{
    fn name(&self) -> &str {
        "CoSaMP"
    }

    fn init(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        state: SparseState<T>,
    ) -> Result<(SparseState<T>, Option<KV>), argmin::core::Error> {
        self.driver.init(self.params.as_ref(), problem, state)
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        state: SparseState<T>,
    ) -> Result<(SparseState<T>, Option<KV>), argmin::core::Error> {
        self.driver.next_iter(problem, state)
    }

    fn terminate(&mut self, _state: &SparseState<T>) -> TerminationStatus {
        self.driver.terminate()
    }
}

/// The part of the sparsity check that needs no operator.
fn check_nonzero_sparsity(sparsity: usize) -> Result<(), Error> {
    if sparsity == 0 {
        return Err(Error::param("sparsity", "must be at least 1, got 0"));
    }
    Ok(())
}
