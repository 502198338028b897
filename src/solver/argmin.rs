//! Every iterative solver of the [`Iteration`] protocol driven by argmin's `Executor`, so that
//! argmin's observers, time limits and checkpointing apply: one adapter, [`ArgminSolver`], whose
//! `next_iter` steps the native solver's iteration (the same code, so the iterates agree to the
//! last bit).

use std::ops::ControlFlow;

use argmin::core::{IterState, Problem, Solver, State, TerminationReason, TerminationStatus, KV};
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::linalg::norm2_sq;
use crate::operator::{Counted, LinearOperator};
use crate::real::Real;

use super::iteration::{ending, Iteration, Iterative, Progress};
use super::stopping::StopRules;
use super::{CglsIteration, CosampIteration, FistaIteration, IhtIteration, Stopping, Termination};

/// The least-squares data term ½‖Ax − y‖² of a problem, as an argmin problem. Each solver adds
/// its own terms through its parameters (CGLS its damping λ‖x‖², FISTA its ℓ1 penalty, IHT and
/// CoSaMP their sparsity constraint).
#[derive(Debug, Clone, Copy)]
pub struct LinearLeastSquares<'a, T, A: ?Sized> {
    /// The operator A.
    pub op: &'a A,
    /// The measurements y.
    pub y: &'a [T],
}

/// The argmin state of an [`ArgminSolver`]: the parameter is the iterate x, the cost the
/// solver's objective.
pub type ArgminState<T> = IterState<Vec<T>, (), (), (), (), f64>;

/// The operator and the measurements of the problem.
fn operands<'a, T, A: ?Sized>(
    problem: &Problem<LinearLeastSquares<'a, T, A>>,
) -> Result<(&'a A, &'a [T]), Error> {
    let lls = problem
        .problem
        .as_ref()
        .ok_or_else(|| Error::param("problem", "missing"))?;
    Ok((lls.op, lls.y))
}

/// Adds the applications counted by `op` to argmin's per-problem counters (`operator_forward`,
/// `operator_adjoint`, `operator_support`).
fn count_applies<O, A>(problem: &mut Problem<O>, op: &Counted<A>) {
    for (name, applies) in [
        ("operator_forward", op.forward_count()),
        ("operator_adjoint", op.adjoint_count()),
        ("operator_support", op.support_count()),
    ] {
        *problem.counts.entry(name).or_insert(0) += applies as u64;
    }
}

/// The part of an argmin solver that steps a native iteration.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Driver<I> {
    /// The convergence rules (the limits, `max_iter` and `time_limit`, are the executor's).
    rules: StopRules,
    /// `None` before `init`, and after an `init` that found nothing to iterate.
    iteration: Option<I>,
    /// Whether [`Iteration::prepare`] has run for the next update.
    prepared: bool,
    /// Why the run ends, once the solver or its rules have ended it.
    ended: Option<Termination>,
}

impl<I> Driver<I> {
    fn new(stopping: Stopping) -> Self {
        Driver {
            rules: StopRules::new(stopping),
            iteration: None,
            prepared: false,
            ended: None,
        }
    }

    /// Iteration `iter + 1` (the executor has completed `iter`), updating `x`. `None` when the
    /// work before the update shows that x is a solution already, which can only happen when a
    /// run continues past the iteration limit it was prepared for (the work is then done here,
    /// and the executor counts one iteration more than the native solver would). The solver's
    /// finishing step runs when the run ends here or reaches `max_iters`.
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
        A: ?Sized,
        I: Iteration<T, A>,
    {
        let iteration = self
            .iteration
            .as_mut()
            .ok_or_else(|| Error::param("state", "no iteration to continue"))?;
        if !self.prepared {
            if let Some(t) = iteration.prepare(op) {
                self.ended = Some(t);
                iteration.finish(op, y, x, t)?;
                return Ok(None);
            }
        }
        let p = iteration.step(op, y, x, (iter + 1) as usize)?;
        let last = iter + 1 >= max_iters;
        self.ended = ending(
            self.rules
                .converged(p.residual, p.objective, p.change)
                .or(last.then_some(Termination::MaxIterations)),
            &p,
        );
        // Like the native solver, prepare the next update only when there is one.
        self.prepared = self.ended.is_none();
        if self.prepared {
            self.ended = iteration.prepare(op);
        }
        if let Some(t) = self.ended {
            iteration.finish(op, y, x, t)?;
        }
        Ok(Some(p))
    }

    fn terminate(&self) -> TerminationStatus {
        match self.ended {
            Some(Termination::MaxIterations) | None => TerminationStatus::NotTerminated,
            Some(_) => TerminationStatus::Terminated(TerminationReason::SolverConverged),
        }
    }
}

/// A native iterative solver (any [`Iteration`]) as an argmin [`Solver`] on a
/// [`LinearLeastSquares`] problem, one native iteration per `next_iter`.
///
/// `init` does what the native solver does before its first iteration (e.g. FISTA's λ from
/// ‖Aᵀy‖∞ and its norm estimate, the pruning of a greedy solver's warm start) and `next_iter`
/// one iteration with the same arithmetic, so the iterates are those of the native solver. The
/// work an iteration starts from (a gradient or proxy) is done at the end of the previous one
/// only when the executor allows another iteration, so the apply counts added to argmin's
/// counters `operator_forward`, `operator_adjoint` and `operator_support` (applications of the
/// operator restricted to a support) equal the native solver's. The cost is the solver's
/// objective; the key-value log has the relative residual (`residual`) and the relative change
/// of x (`change`).
///
/// The run ends with `SolverConverged` when the solver's own ending or a residual, change or
/// stagnation rule of its [`Stopping`] holds (tested as the native loop tests them), or
/// after `init` when the native solver would not iterate (y = 0, a zero operator). The
/// iteration's `finish` runs when the run ends, at `max_iters` included, as it does in the
/// native loop. `stopping.max_iter` and `stopping.time_limit` are
/// not used: the executor's `max_iters` and `timeout` limit the run. The solver is serializable
/// for argmin's checkpoints; its parameters are only needed by `init` and are not serialized, so
/// a deserialized solver resumes a run but cannot start one.
///
/// # Example
/// ```
/// use argmin::core::{Executor, State};
/// use rdlidar::operator::DenseMatrix;
/// use rdlidar::solver::{ArgminFista, FistaParams, Lambda, LinearLeastSquares};
///
/// let a = DenseMatrix::new(ndarray::array![[1.0, 0.0], [0.0, 1.0]]).unwrap();
/// let y = [3.0, 0.5];
/// let problem = LinearLeastSquares { op: &a, y: &y };
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
#[serde(bound(serialize = "I: Serialize", deserialize = "I: Deserialize<'de>"))]
pub struct ArgminSolver<T, I: Iterative<T>>
where
    T: Real,
{
    #[serde(skip)]
    params: Option<I::Params>,
    driver: Driver<I>,
    #[serde(skip)]
    _t: std::marker::PhantomData<T>,
}

impl<T: Real, I: Iterative<T>> ArgminSolver<T, I> {
    /// A solver with these parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for parameters the native solver rejects; what needs the
    /// operator (e.g. a sparsity above the number of unknowns) is reported by `init`.
    pub fn new(params: I::Params) -> Result<Self, Error> {
        I::check_params(&params)?;
        Ok(ArgminSolver {
            driver: Driver::new(I::stopping(&params)),
            params: Some(params),
            _t: std::marker::PhantomData,
        })
    }
}

impl<'a, T, A, I> Solver<LinearLeastSquares<'a, T, A>, ArgminState<T>> for ArgminSolver<T, I>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
    I: Iteration<T, Counted<&'a A>>,
{
    fn name(&self) -> &str {
        I::NAME
    }

    fn init(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        mut state: ArgminState<T>,
    ) -> Result<(ArgminState<T>, Option<KV>), argmin::core::Error> {
        let mut x = state.take_param().ok_or_else(|| {
            Error::param(
                "param",
                format!("{} needs an initial x (configure `param`)", I::NAME),
            )
        })?;
        let (op, y) = operands(problem)?;
        let params = self.params.as_ref().ok_or_else(|| {
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
                self.driver.prepared = state.get_iter() < state.get_max_iters();
                if self.driver.prepared {
                    self.driver.ended = iteration.prepare(&op);
                }
                let cost = iteration.objective();
                let finished = match self.driver.ended {
                    Some(t) => iteration.finish(&op, y, &mut x, t),
                    None => Ok(()),
                };
                self.driver.iteration = Some(iteration);
                finished.map(|()| cost)
            }
            // Zero measurements or a zero operator: x is a solution and Ax = 0, so the objective
            // is ½‖y‖².
            Ok(ControlFlow::Break(t)) => {
                self.driver.ended = Some(t);
                Ok(0.5 * norm2_sq(y))
            }
            Err(e) => Err(e),
        };
        count_applies(problem, &op);
        Ok((state.param(x).cost(cost?), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        mut state: ArgminState<T>,
    ) -> Result<(ArgminState<T>, Option<KV>), argmin::core::Error> {
        let mut x = state
            .take_param()
            .ok_or_else(|| Error::param("param", "no current x"))?;
        let (op, y) = operands(problem)?;
        let op = Counted::new(op);
        let advanced = self
            .driver
            .advance(&op, y, &mut x, state.get_iter(), state.get_max_iters());
        count_applies(problem, &op);
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

    fn terminate(&mut self, _state: &ArgminState<T>) -> TerminationStatus {
        self.driver.terminate()
    }
}

/// CGLS ([`cgls`](super::cgls)) for argmin.
pub type ArgminCgls<T> = ArgminSolver<T, CglsIteration<T>>;
/// FISTA ([`fista`](super::fista)) for argmin.
pub type ArgminFista<T> = ArgminSolver<T, FistaIteration<T>>;
/// IHT ([`iht`](super::iht)) for argmin.
pub type ArgminIht<T> = ArgminSolver<T, IhtIteration<T>>;
/// CoSaMP ([`cosamp`](super::cosamp)) for argmin.
pub type ArgminCosamp<T> = ArgminSolver<T, CosampIteration<T>>;
