//! CGLS driven by argmin's `Executor`, so argmin's observers, time limits and checkpointing apply.

use argmin::core::{IterState, Problem, Solver, TerminationReason, TerminationStatus, KV};
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::linalg::{axpy, dot};
use crate::operator::LinearOperator;
use crate::real::Real;

/// The damped linear least-squares problem min ‖Ax − y‖² + λ‖x‖², as an argmin problem.
///
/// With `damp` 0 it is also the problem of [`ArgminFista`](super::ArgminFista),
/// [`ArgminIht`](super::ArgminIht) and [`ArgminCosamp`](super::ArgminCosamp), which add their
/// own ℓ1 term or sparsity constraint.
#[derive(Debug, Clone, Copy)]
pub struct LinearLeastSquares<'a, T, A: ?Sized> {
    /// The operator A.
    pub op: &'a A,
    /// The measurements y.
    pub y: &'a [T],
    /// λ ≥ 0.
    pub damp: f64,
}

/// The argmin state CGLS runs in: the parameter is the iterate x, the cost the objective
/// ½(‖Ax − y‖² + λ‖x‖²).
pub type CglsState<T> = IterState<Vec<T>, (), (), (), (), f64>;

/// CGLS (see [`cgls`](super::cgls)) as an argmin [`Solver`]: one forward and one adjoint
/// application per `next_iter`. It stops with `SolverConverged` when the normal-equation residual
/// relative to its initial value is at most the tolerance; argmin's `max_iters`, observers and
/// checkpoints work as for any argmin solver (the solver's vectors are serializable).
///
/// # Example
/// ```
/// use argmin::core::{Executor, State};
/// use rdlidar::operator::DenseMatrix;
/// use rdlidar::solver::{ArgminCgls, LinearLeastSquares};
///
/// let a = DenseMatrix::new(ndarray::array![[2.0, 0.0], [0.0, 1.0], [1.0, 1.0]]).unwrap();
/// let y = [2.0, 1.0, 2.0];
/// let problem = LinearLeastSquares { op: &a, y: &y, damp: 0.0 };
/// let result = Executor::new(problem, ArgminCgls::new(1e-12).unwrap())
///     .configure(|s| s.param(vec![0.0, 0.0]).max_iters(10))
///     .run()
///     .unwrap();
/// let x: &Vec<f64> = result.state().get_best_param().unwrap();
/// assert!((x[0] - 1.0).abs() < 1e-10 && (x[1] - 1.0).abs() < 1e-10);
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ArgminCgls<T> {
    tol: f64,
    r: Vec<T>,
    s: Vec<T>,
    p: Vec<T>,
    q: Vec<T>,
    gamma: f64,
    gamma0: f64,
}

/// Adds `forward` and `adjoint` applications of the operator to argmin's per-problem counters
/// (`operator_forward`, `operator_adjoint`).
pub(super) fn count_applies<O>(problem: &mut Problem<O>, forward: usize, adjoint: usize) {
    for (name, applies) in [("operator_forward", forward), ("operator_adjoint", adjoint)] {
        *problem.counts.entry(name).or_insert(0) += applies as u64;
    }
}

impl<T: Real> ArgminCgls<T> {
    /// A solver stopping at relative normal-equation residual `tol`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] unless `tol` is finite and ≥ 0.
    pub fn new(tol: f64) -> Result<Self, Error> {
        if !(tol.is_finite() && tol >= 0.0) {
            return Err(Error::param(
                "tol",
                format!("must be finite and ≥ 0, got {tol}"),
            ));
        }
        Ok(ArgminCgls {
            tol,
            r: Vec::new(),
            s: Vec::new(),
            p: Vec::new(),
            q: Vec::new(),
            gamma: 0.0,
            gamma0: 0.0,
        })
    }

    fn objective(&self, x: &[T], damp: f64) -> f64 {
        0.5 * (dot(&self.r, &self.r) + damp * dot(x, x))
    }
}

impl<'a, T, A> Solver<LinearLeastSquares<'a, T, A>, CglsState<T>> for ArgminCgls<T>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
{
    fn name(&self) -> &str {
        "CGLS"
    }

    fn init(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        mut state: CglsState<T>,
    ) -> Result<(CglsState<T>, Option<KV>), argmin::core::Error> {
        let x = state
            .take_param()
            .ok_or_else(|| Error::param("param", "CGLS needs an initial x (configure `param`)"))?;
        let lls = problem
            .problem
            .as_ref()
            .ok_or_else(|| Error::param("problem", "missing"))?;
        let (m, n) = (lls.op.nrows(), lls.op.ncols());
        super::check_problem("cgls", m, n, lls.y, &x)?;
        if !(lls.damp.is_finite() && lls.damp >= 0.0) {
            return Err(Error::param(
                "damp",
                format!("λ must be finite and ≥ 0, got {}", lls.damp),
            )
            .into());
        }
        self.r = vec![T::zero(); m];
        lls.op.apply(&x, &mut self.r);
        self.r
            .iter_mut()
            .zip(lls.y)
            .for_each(|(ri, &yi)| *ri = yi - *ri);
        self.s = vec![T::zero(); n];
        lls.op.apply_adjoint(&self.r, &mut self.s);
        axpy(T::of_f64(-lls.damp), &x, &mut self.s);
        self.p = self.s.clone();
        self.q = vec![T::zero(); m];
        self.gamma = dot(&self.s, &self.s);
        self.gamma0 = self.gamma;
        let cost = self.objective(&x, lls.damp);
        count_applies(problem, 1, 1);
        Ok((state.param(x).cost(cost), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<LinearLeastSquares<'a, T, A>>,
        mut state: CglsState<T>,
    ) -> Result<(CglsState<T>, Option<KV>), argmin::core::Error> {
        let mut x = state
            .take_param()
            .ok_or_else(|| Error::param("param", "no current x"))?;
        if self.gamma == 0.0 {
            return Ok((state.param(x), None));
        }
        let lls = problem
            .problem
            .as_ref()
            .ok_or_else(|| Error::param("problem", "missing"))?;
        lls.op.apply(&self.p, &mut self.q);
        let pp = dot(&self.p, &self.p);
        let delta = dot(&self.q, &self.q) + lls.damp * pp;
        if !(delta.is_finite() && delta > 0.0) {
            return Err(Error::Breakdown {
                solver: "cgls",
                reason: format!("search direction with curvature {delta}"),
            }
            .into());
        }
        let alpha = self.gamma / delta;
        axpy(T::of_f64(alpha), &self.p, &mut x);
        axpy(T::of_f64(-alpha), &self.q, &mut self.r);
        lls.op.apply_adjoint(&self.r, &mut self.s);
        axpy(T::of_f64(-lls.damp), &x, &mut self.s);
        let gamma_new = dot(&self.s, &self.s);
        let beta = T::of_f64(if self.gamma > 0.0 {
            gamma_new / self.gamma
        } else {
            0.0
        });
        self.p
            .iter_mut()
            .zip(&self.s)
            .for_each(|(pi, &si)| *pi = si + beta * *pi);
        self.gamma = gamma_new;
        let cost = self.objective(&x, lls.damp);
        count_applies(problem, 1, 1);
        let residual = if self.gamma0 > 0.0 {
            (gamma_new / self.gamma0).sqrt()
        } else {
            0.0
        };
        let kv = argmin::kv!("residual" => residual;);
        Ok((state.param(x).cost(cost), Some(kv)))
    }

    fn terminate(&mut self, _state: &CglsState<T>) -> TerminationStatus {
        if self.gamma0 == 0.0 || self.gamma <= self.tol * self.tol * self.gamma0 {
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
        } else {
            TerminationStatus::NotTerminated
        }
    }
}
