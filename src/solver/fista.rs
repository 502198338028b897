//! FISTA for the lasso, optionally nonnegative, with a step from the norm estimate or
//! backtracking and adaptive restart.

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::linalg::{dist2_sq, norm2};
use crate::operator::{LinearOperator, PowerIteration};
use crate::real::Real;
use crate::space::{self, Space};

use super::iteration::{fit_scratch, solve, Iteration, Iterative, Progress};
use super::{
    check_problem, lipschitz_estimate, validate_power_step, Observer, Report, Stopping, Termination,
};

/// Largest number of backtracking trials in one step before [`fista`] gives up.
const MAX_BACKTRACKS: usize = 1000;

/// The weight λ of the ℓ1 term in [`fista`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lambda {
    /// λ itself (finite, ≥ 0).
    Absolute(f64),
    /// λ = fraction · ‖Aᵀy‖∞ (fraction finite, ≥ 0). ‖Aᵀy‖∞ is the smallest λ for which x = 0
    /// solves the lasso, so fractions in (0, 1) give nonzero solutions. Costs one adjoint
    /// application.
    Fraction(f64),
}

/// How [`fista`] chooses its step 1/L.
#[derive(Debug, Clone, Copy)]
pub enum StepRule {
    /// A fixed L = margin · σ², where σ is the Lanczos estimate of ‖A‖₂ from
    /// [`operator_norm`](crate::operator::operator_norm). The estimate is a lower bound, so a
    /// margin slightly above 1 (1.01 by default) keeps 1/L within the convergent range.
    PowerIteration {
        /// Settings of the norm estimate.
        settings: PowerIteration,
        /// Factor (≥ 1) applied to the estimate of ‖A‖².
        margin: f64,
    },
    /// Backtracking (Beck & Teboulle 2009): L starts at the Rayleigh quotient ‖Ag‖² / ‖g‖² of the
    /// first gradient g (a lower bound of ‖A‖²) and is multiplied by `eta` until the step p from
    /// the point z satisfies ‖A(p − z)‖² ≤ L‖p − z‖², the sufficient-decrease condition of the
    /// quadratic term. L never decreases. Each trial costs one forward application.
    Backtracking {
        /// Growth factor of L (finite, > 1).
        eta: f64,
    },
    /// A given L (finite, > 0): the step is 1/L, as other packages take it (it converges for
    /// L ≥ ‖A‖²).
    Fixed {
        /// The Lipschitz constant of the gradient of ½‖Ax − y‖².
        lipschitz: f64,
    },
}

impl Default for StepRule {
    /// [`StepRule::PowerIteration`] with the default [`PowerIteration`] settings and margin 1.01.
    fn default() -> Self {
        StepRule::PowerIteration {
            settings: PowerIteration::default(),
            margin: 1.01,
        }
    }
}

/// Adaptive restart of the momentum (O'Donoghue & Candès 2015).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Restart {
    /// Plain FISTA: the momentum is never reset.
    Off,
    /// Gradient scheme: reset when ⟨z_k − x_k, x_k − x_{k−1}⟩ > 0, i.e. when the step from the
    /// extrapolated point z_k points against the momentum. Free, but the objective may still
    /// increase occasionally.
    Gradient,
    /// Function scheme: when the accelerated step would increase the objective, the momentum is
    /// reset and the step is replaced by a proximal-gradient step from x_{k−1} (one more forward
    /// and one more adjoint application). With L ≥ ‖A‖² that step cannot increase the objective,
    /// so the objective history is non-increasing.
    #[default]
    Function,
}

/// Parameters of [`fista`].
#[derive(Debug, Clone, Copy)]
pub struct FistaParams {
    /// The weight of the ℓ1 term.
    pub lambda: Lambda,
    /// Constrain x ≥ 0.
    pub nonnegative: bool,
    /// How the step is chosen.
    pub step: StepRule,
    /// Adaptive restart of the momentum.
    pub restart: Restart,
    /// Stopping rules; the residual is ‖Ax − y‖ / ‖y‖ and the objective the lasso objective.
    pub stopping: Stopping,
}

impl Default for FistaParams {
    /// λ = 0.1 · ‖Aᵀy‖∞, no sign constraint, the norm-estimate step with margin 1.01, function
    /// restart; at most 500 iterations, stopping when the relative residual reaches 1e-6 or the
    /// relative change of x falls to 1e-6.
    fn default() -> Self {
        FistaParams {
            lambda: Lambda::Fraction(0.1),
            nonnegative: false,
            step: StepRule::default(),
            restart: Restart::default(),
            stopping: Stopping {
                max_iter: 500,
                rel_change: Some(1e-6),
                ..Stopping::default()
            },
        }
    }
}

impl FistaParams {
    /// Checks every setting that needs no operator.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the setting.
    pub fn validate(&self) -> Result<()> {
        self.stopping.validate()?;
        let (value, what) = match self.lambda {
            Lambda::Absolute(v) => (v, "λ"),
            Lambda::Fraction(v) => (v, "the fraction of ‖Aᵀy‖∞"),
        };
        if !(value.is_finite() && value >= 0.0) {
            return Err(Error::param(
                "lambda",
                format!(
                    "{what} must be finite and ≥ 0, got {}",
                    crate::units::number(value)
                ),
            ));
        }
        match self.step {
            StepRule::PowerIteration { settings, margin } => validate_power_step(&settings, margin),
            StepRule::Backtracking { eta } if !(eta.is_finite() && eta > 1.0) => Err(Error::param(
                "eta",
                format!(
                    "must be a finite number > 1, got {}",
                    crate::units::number(eta)
                ),
            )),
            StepRule::Backtracking { .. } => Ok(()),
            StepRule::Fixed { lipschitz } if !(lipschitz.is_finite() && lipschitz > 0.0) => {
                Err(Error::param(
                    "lipschitz",
                    format!(
                        "must be a finite number > 0, got {}",
                        crate::units::number(lipschitz)
                    ),
                ))
            }
            StepRule::Fixed { .. } => Ok(()),
        }
    }
}

/// The proximal map of t·|·| (or of t·(·) plus the indicator of [0, ∞) when `nonnegative`).
#[inline]
fn shrink(v: f64, t: f64, nonnegative: bool) -> f64 {
    if nonnegative {
        (v - t).max(0.0)
    } else if v > t {
        v - t
    } else if v < -t {
        v + t
    } else {
        0.0
    }
}

/// out = a + β(a − b), computed in `f64`.
fn extrapolate<T: Real>(out: &mut [T], a: &[T], b: &[T], beta: f64) {
    for ((o, &ai), &bi) in out.iter_mut().zip(a).zip(b) {
        *o = T::of_f64(ai.as_f64() + beta * (ai.as_f64() - bi.as_f64()));
    }
}

/// The lasso's weights and the buffers of its proximal-gradient step.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Lasso<T> {
    lambda: f64,
    nonnegative: bool,
    /// `Some(eta)` for backtracking.
    eta: Option<f64>,
    /// The current Lipschitz estimate (0 until backtracking has set it).
    l: f64,
    #[serde(skip, default = "Vec::new")]
    scratch: Vec<T>,
    /// A z − y.
    res: Vec<T>,
    /// Aᵀ(A z − y).
    grad: Vec<T>,
}

impl<T: Real> Lasso<T> {
    const NAME: &'static str = "fista";

    /// ½‖Ax − y‖² + λ‖x‖₁, from x and Ax, over the unknowns of `space`.
    fn objective(&self, space: &dyn Space, y: &[T], x: &[T], ax: &[T]) -> f64 {
        let fit: f64 = dist2_sq(ax, y);
        let l1: f64 = space::sum(space, x.iter().map(|v| v.as_f64().abs()).sum());
        0.5 * fit + self.lambda * l1
    }

    /// p = prox_{λ/L}(z − Aᵀ(Az − y)/L) and Ap, backtracking on L if configured.
    fn step<A: LinearOperator<T> + ?Sized>(
        &mut self,
        op: &A,
        y: &[T],
        z: &[T],
        az: &[T],
        p: &mut [T],
        ap: &mut [T],
    ) -> Result<()> {
        fit_scratch(&mut self.scratch, op);
        for ((r, &a), &b) in self.res.iter_mut().zip(az).zip(y) {
            *r = a - b;
        }
        op.apply_adjoint_with_scratch(&self.res, &mut self.grad, &mut self.scratch);
        if self.l == 0.0 {
            // First backtracking step: start from the Rayleigh quotient of the gradient.
            let gg = space::norm2(op.space(), &self.grad);
            if gg > 0.0 {
                op.apply_with_scratch(&self.grad, ap, &mut self.scratch);
                let ratio = norm2(ap) / gg;
                self.l = ratio * ratio;
            }
            if !(self.l.is_finite() && self.l > 0.0) {
                self.l = 1.0;
            }
        }
        let mut trials = 0;
        loop {
            let (inv, t) = (1.0 / self.l, self.lambda / self.l);
            for ((pi, &zi), &gi) in p.iter_mut().zip(z).zip(&self.grad) {
                *pi = T::of_f64(shrink(zi.as_f64() - inv * gi.as_f64(), t, self.nonnegative));
            }
            op.apply_with_scratch(p, ap, &mut self.scratch);
            let Some(eta) = self.eta else {
                return Ok(());
            };
            // ‖A(p − z)‖ ≤ √L ‖p − z‖, with a slack for the rounding of Ap and Az.
            let ad = dist2_sq(ap, az).sqrt();
            let d = space::dist2_sq(op.space(), p, z).sqrt();
            let slack = 4.0 * T::EPS * (norm2(ap) + norm2(az));
            if ad <= self.l.sqrt() * d + slack {
                return Ok(());
            }
            self.l *= eta;
            trials += 1;
            if !self.l.is_finite() || trials >= MAX_BACKTRACKS {
                return Err(Error::Breakdown {
                    solver: Self::NAME,
                    reason: format!(
                        "backtracking found no step after {trials} trials (L = {}, eta = {eta})",
                        self.l
                    ),
                });
            }
        }
    }
}

/// [`Restart`] for serde.
#[derive(Serialize, Deserialize)]
#[serde(remote = "Restart")]
enum RestartDef {
    Off,
    Gradient,
    Function,
}

/// The state of [`fista`] between iterations: the lasso, the previous iterate, the extrapolated
/// point z, the forward products of all three, and the momentum.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FistaIteration<T> {
    lasso: Lasso<T>,
    #[serde(with = "RestartDef")]
    restart: Restart,
    /// ‖y‖.
    ynorm: f64,
    /// The objective at x.
    f_x: f64,
    ax: Vec<T>,
    x_prev: Vec<T>,
    ax_prev: Vec<T>,
    z: Vec<T>,
    az: Vec<T>,
    p: Vec<T>,
    ap: Vec<T>,
    t: f64,
    momentum: bool,
}

impl<T: Real> Iterative<T> for FistaIteration<T> {
    const NAME: &'static str = "fista";
    type Params = FistaParams;

    fn stopping(params: &FistaParams) -> Stopping {
        params.stopping
    }

    fn check_params(params: &FistaParams) -> Result<()> {
        params.validate()
    }
}

impl<T: Real, A: LinearOperator<T> + ?Sized> Iteration<T, A> for FistaIteration<T> {
    fn start(
        op: &A,
        y: &[T],
        x: &mut [T],
        params: &FistaParams,
    ) -> Result<ControlFlow<Termination, Self>> {
        params.validate()?;
        let (m, n) = (op.nrows(), op.ncols());
        let space = op.space();
        check_problem(Self::NAME, space, m, n, y, x)?;
        let ynorm = norm2(y);
        if ynorm == 0.0 {
            x.fill(T::zero());
            return Ok(ControlFlow::Break(Termination::ZeroResidual));
        }
        if params.nonnegative {
            x.iter_mut()
                .for_each(|v| *v = if *v > T::zero() { *v } else { T::zero() });
        }
        let mut scratch = vec![T::zero(); op.scratch_len()];
        let lambda = match params.lambda {
            Lambda::Absolute(v) => v,
            Lambda::Fraction(f) => {
                let mut aty = vec![T::zero(); n];
                op.apply_adjoint_with_scratch(y, &mut aty, &mut scratch);
                let top = space::norm_inf(space, &aty);
                if !top.is_finite() {
                    return Err(Error::NonFinite {
                        what: format!("{}: ‖Aᵀy‖∞ = {top}", Self::NAME),
                    });
                }
                f * top
            }
        };
        let (l, eta) = match params.step {
            StepRule::PowerIteration { settings, margin } => {
                let l = lipschitz_estimate(op, &settings, margin)?;
                if l == 0.0 {
                    if lambda > 0.0 {
                        x.fill(T::zero());
                    }
                    return Ok(ControlFlow::Break(Termination::Converged));
                }
                (l, None)
            }
            StepRule::Backtracking { eta } => (0.0, Some(eta)),
            StepRule::Fixed { lipschitz } => (lipschitz, None),
        };
        let mut lasso = Lasso {
            lambda,
            nonnegative: params.nonnegative,
            eta,
            l,
            scratch,
            res: vec![T::zero(); m],
            grad: vec![T::zero(); n],
        };
        let mut ax = vec![T::zero(); m];
        op.apply_with_scratch(x, &mut ax, &mut lasso.scratch);
        let f_x = lasso.objective(space, y, x, &ax);
        Ok(ControlFlow::Continue(FistaIteration {
            lasso,
            restart: params.restart,
            ynorm,
            f_x,
            x_prev: x.to_vec(),
            ax_prev: ax.clone(),
            z: x.to_vec(),
            az: ax.clone(),
            ax,
            p: vec![T::zero(); n],
            ap: vec![T::zero(); m],
            t: 1.0,
            momentum: false,
        }))
    }

    fn step(&mut self, op: &A, y: &[T], x: &mut [T], it: usize) -> Result<Progress> {
        let space = op.space();
        let lasso = &mut self.lasso;
        lasso.step(op, y, &self.z, &self.az, &mut self.p, &mut self.ap)?;
        let mut f_p = lasso.objective(space, y, &self.p, &self.ap);
        let mut restarted = false;
        match self.restart {
            Restart::Function if self.momentum && f_p > self.f_x => {
                lasso.step(op, y, x, &self.ax, &mut self.p, &mut self.ap)?;
                f_p = lasso.objective(space, y, &self.p, &self.ap);
                restarted = true;
            }
            Restart::Gradient => {
                let along: f64 = self
                    .z
                    .iter()
                    .zip(self.p.iter())
                    .zip(x.iter())
                    .map(|((&zi, &pi), &xi)| {
                        (zi.as_f64() - pi.as_f64()) * (pi.as_f64() - xi.as_f64())
                    })
                    .sum();
                restarted = space::sum(space, along) > 0.0;
            }
            _ => {}
        }
        if !f_p.is_finite() {
            return Err(Error::Breakdown {
                solver: Self::NAME,
                reason: format!("non-finite objective at iteration {it}"),
            });
        }
        let change = space::relative_change(space, &self.p, x);
        self.x_prev.copy_from_slice(x);
        x.copy_from_slice(&self.p);
        std::mem::swap(&mut self.ax_prev, &mut self.ax);
        std::mem::swap(&mut self.ax, &mut self.ap);
        self.f_x = f_p;
        if restarted {
            self.t = 1.0;
        }
        let t_next = 0.5 * (1.0 + (1.0 + 4.0 * self.t * self.t).sqrt());
        let beta = (self.t - 1.0) / t_next;
        self.t = t_next;
        self.momentum = beta > 0.0;
        extrapolate(&mut self.z, x, &self.x_prev, beta);
        extrapolate(&mut self.az, &self.ax, &self.ax_prev, beta);
        let residual = dist2_sq(&self.ax, y).sqrt() / self.ynorm;
        Ok(Progress {
            residual,
            objective: self.f_x,
            change,
            ending: None,
        })
    }

    fn objective(&self) -> f64 {
        self.f_x
    }
}

/// Solves the lasso
///
/// min_x ½‖Ax − y‖² + λ‖x‖₁  (subject to x ≥ 0 when `nonnegative`)
///
/// by FISTA (Beck & Teboulle 2009) with adaptive restart (O'Donoghue & Candès 2015), starting
/// from `x`.
///
/// With t₁ = 1 and z₁ = x₀, iteration k computes
///
/// * x_k = prox_{λ/L}(z_k − Aᵀ(Az_k − y)/L), where prox is soft thresholding at λ/L (followed by
///   clipping at 0 when `nonnegative`),
/// * t_{k+1} = (1 + √(1 + 4t_k²)) / 2,
/// * z_{k+1} = x_k + ((t_k − 1)/t_{k+1}) (x_k − x_{k−1}),
///
/// and a restart sets t_k = 1, so that z_{k+1} = x_k. L is a fixed estimate of ‖A‖² or found by
/// backtracking ([`StepRule`]). A·z is formed from the stored A·x_k and A·x_{k−1}, so an
/// iteration costs one adjoint and one forward application (plus one forward per backtracking
/// trial, and one of each for a function restart).
///
/// The report's residual is ‖Ax − y‖ / ‖y‖, its objective the lasso objective above; apply counts
/// include the norm estimate and the adjoint that computes ‖Aᵀy‖∞ for [`Lambda::Fraction`].
/// With `nonnegative` the warm start is first projected onto x ≥ 0.
///
/// Special cases: if y = 0, x is set to 0 (the solution) and the run ends with
/// [`Termination::ZeroResidual`] without applying the operator; if the norm estimate finds
/// ‖A‖ = 0 (a zero operator), x is set to 0 when λ > 0 (left as it is when λ = 0, where every
/// x solves the problem) and the run ends with [`Termination::Converged`] after 0 iterations.
///
/// # References
/// * A. Beck, M. Teboulle, *A fast iterative shrinkage-thresholding algorithm for linear inverse
///   problems*, SIAM J. Imaging Sciences, 2009.
/// * B. O'Donoghue, E. Candès, *Adaptive restart for accelerated gradient schemes*, Foundations
///   of Computational Mathematics, 2015.
///
/// # Errors
/// [`Error::InvalidParameter`] for a negative or non-finite λ or fraction, an invalid step rule
/// (margin < 1, eta ≤ 1, invalid norm-estimate settings) or invalid stopping rules;
/// [`Error::ShapeMismatch`] / [`Error::NonFinite`] for inputs that do not fit the operator or are
/// not finite; [`Error::NonFinite`] if ‖Aᵀy‖∞ or the operator-norm estimate is not finite;
/// [`Error::Breakdown`] if backtracking finds no step or the iteration produces non-finite values.
pub fn fista<T, A, O>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &FistaParams,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: LinearOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    solve::<T, A, O, FistaIteration<T>>(op, y, x, params, observer)
}
