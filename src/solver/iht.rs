//! Iterative hard thresholding with the normalized step, for sparsity-constrained least squares.

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::linalg::{dist2_sq, dot, norm2};
use crate::operator::{LinearOperator, PowerIteration};
use crate::real::Real;
use crate::space;

use super::iteration::{fit_scratch, refresh_residual, solve, Iteration, Iterative, Progress};
use super::{
    check_problem, check_sparsity, check_tolerance, lipschitz_estimate, support,
    validate_power_step, Observer, Report, Stopping, Termination,
};

/// The constant c of the normalized step's acceptance test (ω = (1 − c)‖Δx‖² / ‖AΔx‖²).
const C: f64 = 0.01;
/// The step shrinks by κ(1 − c) when the test fails; the analysis needs κ > 1/(1 − c).
const KAPPA: f64 = 2.0;
/// Largest number of step reductions in one iteration before [`iht`] gives up.
const MAX_SHRINKS: usize = 200;

/// How [`iht`] chooses its step μ.
#[derive(Debug, Clone, Copy, Default)]
pub enum IhtStep {
    /// The normalized step of Blumensath & Davies (2010): μ = ‖g_Γ‖² / ‖A g_Γ‖², the exact line
    /// search along the gradient g restricted to the current support Γ. When the thresholded
    /// iterate leaves Γ, μ is accepted only if μ ≤ (1 − c)‖x⁺ − x‖² / ‖A(x⁺ − x)‖² (c = 0.01) and
    /// is otherwise divided by κ(1 − c) (κ = 2) until it is. Costs one forward application for the
    /// step and one per reduction.
    #[default]
    Normalized,
    /// A fixed μ = 1/L with L = margin · σ², σ the Lanczos estimate of ‖A‖₂ from
    /// [`operator_norm`](crate::operator::operator_norm) (a lower bound, hence the margin ≥ 1).
    PowerIteration {
        /// Settings of the norm estimate.
        settings: PowerIteration,
        /// Factor (≥ 1) applied to the estimate of ‖A‖².
        margin: f64,
    },
}

/// Parameters of [`iht`].
#[derive(Debug, Clone, Copy)]
pub struct IhtParams {
    /// The number s of nonzeros kept (1 ≤ s ≤ number of unknowns).
    pub sparsity: usize,
    /// How the step is chosen.
    pub step: IhtStep,
    /// The run ends with [`Termination::Converged`] when an iteration leaves the support unchanged
    /// and changes x by at most this, relative: ‖x_k − x_{k−1}‖ ≤ tol · ‖x_k‖ (finite, ≥ 0).
    pub fixed_point_tol: f64,
    /// Stopping rules; the residual is ‖Ax − y‖ / ‖y‖ and the objective ½‖Ax − y‖².
    pub stopping: Stopping,
}

impl IhtParams {
    /// Sparsity `sparsity`, the normalized step, a fixed-point tolerance of 1e-6, and at most 500
    /// iterations, stopping when the relative residual reaches 1e-6.
    pub fn new(sparsity: usize) -> Self {
        IhtParams {
            sparsity,
            step: IhtStep::Normalized,
            fixed_point_tol: 1e-6,
            stopping: Stopping {
                max_iter: 500,
                ..Stopping::default()
            },
        }
    }

    /// Checks every setting that needs no operator (all but the sparsity's upper bound).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the setting.
    pub fn validate(&self) -> Result<()> {
        self.stopping.validate()?;
        check_tolerance("fixed_point_tol", self.fixed_point_tol)?;
        if let IhtStep::PowerIteration { settings, margin } = self.step {
            validate_power_step(&settings, margin)?;
        }
        Ok(())
    }

    /// [`IhtParams::validate`], and the sparsity against the `unknowns` of a problem.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the setting.
    pub fn validate_for(&self, unknowns: usize) -> Result<()> {
        self.validate()?;
        check_sparsity(self.sparsity, unknowns)
    }
}

/// μ = ‖g_Γ‖² / ‖A g_Γ‖²; the whole gradient is used when g_Γ or A g_Γ vanishes.
fn normalized_step<T: Real, A: LinearOperator<T> + ?Sized>(
    op: &A,
    g: &[T],
    gamma: &[usize],
    gs: &mut [T],
    ag: &mut [T],
    scratch: &mut [T],
) -> Result<f64> {
    let space = op.space();
    gs.fill(T::zero());
    for &i in gamma {
        gs[i] = g[i];
    }
    let gg = space::norm2_sq(space, gs);
    if gg > 0.0 {
        op.apply_with_scratch(gs, ag, scratch);
        let mu = gg / dot(ag, ag);
        if mu.is_finite() && mu > 0.0 {
            return Ok(mu);
        }
    }
    op.apply_with_scratch(g, ag, scratch);
    let mu = space::norm2_sq(space, g) / dot(ag, ag);
    if mu.is_finite() && mu > 0.0 {
        Ok(mu)
    } else {
        Err(Error::Breakdown {
            solver: "iht",
            reason: format!("step length {mu} along the gradient"),
        })
    }
}

/// The state of [`iht`] between iterations: the forward product and residual of x, its support,
/// the gradient, and the buffers of the step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct IhtIteration<T> {
    sparsity: usize,
    /// μ = 1/L of [`IhtStep::PowerIteration`]; `None` for the normalized step.
    fixed_mu: Option<f64>,
    fixed_point_tol: f64,
    /// ‖y‖.
    ynorm: f64,
    ax: Vec<T>,
    /// y − Ax.
    r: Vec<T>,
    /// Aᵀr, computed by `prepare`.
    g: Vec<T>,
    gs: Vec<T>,
    ag: Vec<T>,
    xn: Vec<T>,
    axn: Vec<T>,
    supp: Vec<usize>,
    #[serde(skip, default = "Vec::new")]
    scratch: Vec<T>,
}

impl<T: Real> Iterative<T> for IhtIteration<T> {
    const NAME: &'static str = "iht";
    type Params = IhtParams;

    fn stopping(params: &IhtParams) -> Stopping {
        params.stopping
    }

    fn check_params(params: &IhtParams) -> Result<()> {
        params.validate()?;
        super::check_nonzero_sparsity(params.sparsity)
    }
}

impl<T: Real, A: LinearOperator<T> + ?Sized> Iteration<T, A> for IhtIteration<T> {
    fn start(
        op: &A,
        y: &[T],
        x: &mut [T],
        params: &IhtParams,
    ) -> Result<ControlFlow<Termination, Self>> {
        let (m, n) = (op.nrows(), op.ncols());
        let space = op.space();
        params.validate_for(space::count(space, n))?;
        check_problem(Self::NAME, space, m, n, y, x)?;
        let s = params.sparsity;
        let ynorm = norm2(y);
        if ynorm == 0.0 {
            x.fill(T::zero());
            return Ok(ControlFlow::Break(Termination::ZeroResidual));
        }
        space::hard_threshold(space, x, s);
        let fixed_mu = match params.step {
            IhtStep::Normalized => None,
            IhtStep::PowerIteration { settings, margin } => {
                let l = lipschitz_estimate(op, &settings, margin)?;
                if l == 0.0 {
                    return Ok(ControlFlow::Break(Termination::Converged));
                }
                Some(1.0 / l)
            }
        };
        let mut scratch = vec![T::zero(); op.scratch_len()];
        let mut ax = vec![T::zero(); m];
        op.apply_with_scratch(x, &mut ax, &mut scratch);
        let r: Vec<T> = y.iter().zip(&ax).map(|(&a, &b)| a - b).collect();
        Ok(ControlFlow::Continue(IhtIteration {
            sparsity: s,
            fixed_mu,
            fixed_point_tol: params.fixed_point_tol,
            ynorm,
            ax,
            r,
            g: vec![T::zero(); n],
            gs: vec![T::zero(); n],
            ag: vec![T::zero(); m],
            xn: vec![T::zero(); n],
            axn: vec![T::zero(); m],
            supp: support(x),
            scratch,
        }))
    }

    /// The gradient g = Aᵀ(y − Ax); x solves the problem when it is exactly zero.
    fn prepare(&mut self, op: &A) -> Option<Termination> {
        fit_scratch(&mut self.scratch, op);
        op.apply_adjoint_with_scratch(&self.r, &mut self.g, &mut self.scratch);
        space::all(op.space(), self.g.iter().all(|&v| v == T::zero()))
            .then_some(Termination::Converged)
    }

    fn step(&mut self, op: &A, y: &[T], x: &mut [T], it: usize) -> Result<Progress> {
        fit_scratch(&mut self.scratch, op);
        let space = op.space();
        let s = self.sparsity;
        // Γ: the current support, or the s largest gradient entries when x = 0.
        let (mut mu, gamma) = match self.fixed_mu {
            Some(mu) => (mu, None),
            None => {
                let gamma = if space::count(space, self.supp.len()) == 0 {
                    space::largest_indices(space, &self.g, s)
                } else {
                    self.supp.clone()
                };
                let mu = normalized_step(
                    op,
                    &self.g,
                    &gamma,
                    &mut self.gs,
                    &mut self.ag,
                    &mut self.scratch,
                )?;
                (mu, Some(gamma))
            }
        };
        let mut shrinks = 0;
        let new_supp = loop {
            for ((v, &xi), &gi) in self.xn.iter_mut().zip(x.iter()).zip(&self.g) {
                *v = T::of_f64(xi.as_f64() + mu * gi.as_f64());
            }
            space::hard_threshold(space, &mut self.xn, s);
            op.apply_with_scratch(&self.xn, &mut self.axn, &mut self.scratch);
            let new_supp = support(&self.xn);
            let Some(gamma) = &gamma else {
                break new_supp;
            };
            if space::all(space, new_supp == *gamma) {
                break new_supp;
            }
            let dx: f64 = space::dist2_sq(space, &self.xn, x);
            let adx: f64 = dist2_sq(&self.axn, &self.ax);
            let omega = if adx > 0.0 {
                (1.0 - C) * dx / adx
            } else {
                f64::INFINITY
            };
            if mu <= omega {
                break new_supp;
            }
            mu /= KAPPA * (1.0 - C);
            shrinks += 1;
            if shrinks >= MAX_SHRINKS || mu == 0.0 {
                return Err(Error::Breakdown {
                    solver: Self::NAME,
                    reason: format!("no admissible step after {shrinks} reductions (μ = {mu})"),
                });
            }
        };
        let change = space::relative_change(space, &self.xn, x);
        let same_support = space::all(space, new_supp == self.supp);
        x.copy_from_slice(&self.xn);
        std::mem::swap(&mut self.ax, &mut self.axn);
        self.supp = new_supp;
        let rr = refresh_residual(Self::NAME, it, y, &self.ax, &mut self.r)?;
        let converged = same_support && change <= self.fixed_point_tol;
        Ok(Progress::least_squares(rr, self.ynorm, change, converged))
    }

    fn objective(&self) -> f64 {
        0.5 * dot(&self.r, &self.r)
    }
}

/// Finds an s-sparse x approximately minimizing ½‖Ax − y‖² by iterative hard thresholding,
/// starting from `x`:
///
/// x_{k+1} = H_s(x_k + μ_k Aᵀ(y − A x_k)),
///
/// where H_s keeps the s entries of largest magnitude (ties to the lower index) and μ_k is the
/// normalized step of Blumensath & Davies (2010) or a fixed 1/L ([`IhtStep`]). An iteration costs
/// one adjoint and one forward application, plus one forward for the normalized step (and one per
/// step reduction); the residual y − Ax is recomputed from a fresh forward product every time.
///
/// The run ends with [`Termination::Converged`] when an iteration keeps the support and changes x
/// by at most [`fixed_point_tol`](IhtParams::fixed_point_tol), or when the gradient Aᵀ(y − Ax) is
/// exactly zero; the other reasons come from the [`Stopping`] rules, whose residual is
/// ‖Ax − y‖ / ‖y‖. Apply counts include the norm estimate of [`IhtStep::PowerIteration`].
///
/// The warm start is first pruned to its s largest entries. If y = 0, x is set to 0 (the
/// solution) and the run ends with [`Termination::ZeroResidual`] without applying the operator;
/// if the norm estimate finds ‖A‖ = 0 (a zero operator), the run ends with
/// [`Termination::Converged`] after 0 iterations.
///
/// # References
/// * T. Blumensath, M. E. Davies, *Normalized iterative hard thresholding: guaranteed stability
///   and performance*, IEEE J. Selected Topics in Signal Processing, 2010.
///
/// # Errors
/// [`Error::InvalidParameter`] if the sparsity is 0 or above the number of unknowns, for an
/// invalid tolerance, step rule or stopping rules; [`Error::ShapeMismatch`] /
/// [`Error::NonFinite`] for inputs that do not fit the operator or are not finite;
/// [`Error::Breakdown`] if no admissible step is found or the iteration produces non-finite
/// values.
pub fn iht<T, A, O>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &IhtParams,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    solve::<T, A, O, IhtIteration<T>>(op, y, x, params, observer)
}
