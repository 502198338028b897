//! Weighted total-variation denoising and inpainting of a 2-D map by the primal-dual algorithm of
//! Chambolle and Pock.

mod kernel;

use kernel::{has_avx2, Problem, Sums};
use std::ops::ControlFlow;

use ndarray::{Array2, ArrayView2};

use crate::error::{Error, Result};
use crate::operator::{Gradient2D, LinearOperator};

use super::{solve, Iteration, Iterative, Observer, Progress, Report, Stopping, Termination};

/// Which total variation [`tv_denoise`] penalizes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum TvNorm {
    /// Σ ‖(∇u)ᵢ‖₂, the usual choice: less biased towards the grid axes.
    #[default]
    Isotropic,
    /// Σ ‖(∇u)ᵢ‖₁ = Σ |vertical difference| + |horizontal difference|: favours edges along
    /// the grid axes.
    Anisotropic,
}

/// How [`tv_denoise`] chooses its primal and dual steps τ and σ (always with σ·τ·8 = 0.99).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum TvSteps {
    /// θ = 1 and residual balancing (Goldstein et al. 2013), starting from τ = σ: the product
    /// σ·τ is fixed and their ratio is adapted so that the primal and dual residuals stay
    /// within a factor 1.5 of each other, by factors (1 − α) with α shrinking geometrically
    /// (0.5, then × 0.95 per change), so that the adaptation dies out and the convergence of
    /// Algorithm 1 is kept. The robust default: it works with zero weights, does not depend on
    /// a good initial ratio, and converges fast in practice.
    #[default]
    Adaptive,
    /// When every weight is positive, the data term is γ-strongly convex
    /// (γ = min w / max w) and the steps can follow Algorithm 2 of Chambolle & Pock
    /// (θ = 1/√(1 + 2γτ), τ ← θτ, σ ← σ/θ, starting from τ = 10σ), which guarantees an
    /// O(1/k²) rate. It can beat [`TvSteps::Adaptive`] to moderate accuracy (relative gap
    /// 1e-4) when λ is large and smooths strongly, but its shrinking primal step makes it slow
    /// to high accuracy and when λ is small. With any zero weight the data term is not
    /// strongly convex and this is [`TvSteps::Adaptive`].
    Accelerated,
    /// Algorithm 1 of Chambolle & Pock with θ = 1 and fixed τ = σ.
    Fixed,
}

/// Parameters of [`tv_denoise`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TvParams {
    /// Weight λ ≥ 0 of the total variation (in the units of the weights times those of the
    /// map).
    pub lambda: f64,
    /// Isotropic or anisotropic total variation.
    pub norm: TvNorm,
    /// Step-size rule.
    pub steps: TvSteps,
    /// Stopping rules. The residual is the relative primal-dual gap (P(u) − D(p)) / P(u), an
    /// upper bound on the relative distance of the objective to its minimum, so
    /// `rel_residual` is the gap tolerance; the objective is P(u) and the change is
    /// ‖u_k − u_{k−1}‖ / ‖u_k‖.
    pub stopping: Stopping,
}

impl TvParams {
    /// λ with the defaults: isotropic total variation, [`TvSteps::Adaptive`], at most 1000
    /// iterations, stopping when the relative primal-dual gap reaches 1e-4.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if λ is negative or not finite.
    pub fn new(lambda: f64) -> Result<Self> {
        let params = TvParams {
            lambda,
            norm: TvNorm::default(),
            steps: TvSteps::default(),
            stopping: Stopping {
                max_iter: 1000,
                rel_residual: Some(1e-4),
                ..Stopping::default()
            },
        };
        params.validate()?;
        Ok(params)
    }

    /// Sets the kind of total variation.
    pub fn with_norm(mut self, norm: TvNorm) -> Self {
        self.norm = norm;
        self
    }

    /// Sets the step-size rule.
    pub fn with_steps(mut self, steps: TvSteps) -> Self {
        self.steps = steps;
        self
    }

    /// Sets the stopping rules.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the invalid field.
    pub fn with_stopping(mut self, stopping: Stopping) -> Result<Self> {
        stopping.validate()?;
        self.stopping = stopping;
        Ok(self)
    }

    /// Checks every setting that needs no operator.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the setting.
    pub fn validate(&self) -> Result<()> {
        if !(self.lambda.is_finite() && self.lambda >= 0.0) {
            return Err(Error::param(
                "lambda",
                format!(
                    "must be finite and ≥ 0, got {}",
                    crate::units::number(self.lambda)
                ),
            ));
        }
        self.stopping.validate()
    }
}

/// ‖∇‖² ≤ 8 for forward differences on a grid; the steps keep σ·τ·8 at this.
const STEP_PRODUCT: f64 = 0.99;
/// Initial τ/σ of the accelerated variant.
const ACCEL_RATIO: f64 = 10.0;
/// Residual balancing: first adaptation factor, its decay per change, and the tolerated ratio
/// of the two residuals.
const ADAPT_ALPHA: f64 = 0.5;
const ADAPT_ETA: f64 = 0.95;
const ADAPT_RATIO: f64 = 1.5;

/// Pixels per block of the pointwise passes. Each pass writes its per-pixel terms into small
/// buffers and sums them afterwards, so that the per-pixel loops have no floating-point
/// reduction and vectorize.
const BLOCK: usize = 64;

/// Checks that `b` has the shape `(m, n)` of the data.
fn check_shape(name: &str, b: (usize, usize), m: usize, n: usize) -> Result<()> {
    if b.0 != m {
        return Err(Error::shape(
            format!("tv_denoise: rows of {name} vs f"),
            m,
            b.0,
        ));
    }
    if b.1 != n {
        return Err(Error::shape(
            format!("tv_denoise: columns of {name} vs f"),
            n,
            b.1,
        ));
    }
    Ok(())
}

/// Checks that every entry is finite (and ≥ 0 when `nonnegative`).
fn check_values(name: &str, a: ArrayView2<'_, f64>, nonnegative: bool) -> Result<()> {
    for ((i, j), &v) in a.indexed_iter() {
        if !v.is_finite() {
            return Err(Error::NonFinite {
                what: format!("tv_denoise: {name}[{i}, {j}] = {v}"),
            });
        }
        if nonnegative && v < 0.0 {
            return Err(Error::param(
                "w",
                format!(
                    "weights must be ≥ 0, got w[{i}, {j}] = {}",
                    crate::units::number(v)
                ),
            ));
        }
    }
    Ok(())
}

/// Weighted total-variation denoising and inpainting of an `m × n` map:
///
/// min_u P(u) = ½ Σᵢ wᵢ (uᵢ − fᵢ)² + λ · TV(u),
///
/// with TV(u) = Σᵢ ‖(∇u)ᵢ‖₂ ([`TvNorm::Isotropic`]) or Σᵢ ‖(∇u)ᵢ‖₁ ([`TvNorm::Anisotropic`]),
/// ∇ the forward differences with Neumann boundary of [`Gradient2D`]. Pixels with wᵢ = 0 carry
/// no data and are filled in by the total variation (inpainting). `u` is the warm start and
/// receives the result; the observer sees the current map flattened in row-major order.
///
/// # Algorithm
/// The primal-dual algorithm of Chambolle & Pock on the saddle-point problem
/// min_u max_p ⟨∇u, p⟩ + G(u) − F*(p), where F* is the indicator of ‖pᵢ‖₂ ≤ λ (of
/// ‖pᵢ‖∞ ≤ λ for the anisotropic TV) and G the data term. Every minimizer lies in the box
/// [a, b]ⁿ spanned by the data (a = min fᵢ, b = max fᵢ over wᵢ > 0), because clipping a map to
/// it raises neither term; G includes the indicator of that box, which keeps the iterates
/// bounded and the dual objective finite where wᵢ = 0. Starting from p = 0, iteration k computes
///
/// * u⁺ = clip((u + τ div p + τ wᵢ fᵢ) / (1 + τ wᵢ), a, b), the proximal map of τG,
/// * p ← Π_λ(p + σ∇(u⁺ + θ(u⁺ − u))), Π_λ the pointwise projection onto the dual ball,
/// * u ← u⁺,
///
/// with σ τ ‖∇‖² ≤ 0.99 (‖∇‖² ≤ 8) and θ and the steps set by [`TvSteps`]: by default θ = 1
/// (Algorithm 1 of the paper) with the ratio τ/σ adapted by residual balancing; Algorithm 2
/// (accelerated, for positive weights) and fixed steps are options. The problem is solved in normalized form, with the weights divided by
/// their maximum and the values mapped from [a, b] onto [−1, 1] (λ scaled to match), which
/// leaves the minimizers unchanged and makes the iterations independent of the units. ∇ of the
/// extrapolated point is formed from the stored ∇u⁺ and ∇u, so an iteration costs one
/// gradient and one divergence (the report counts them as forward and adjoint applications of
/// [`Gradient2D`], plus the gradient of the warm start) and a few pointwise passes, which run
/// with AVX2 where the CPU has it.
///
/// # Stopping
/// After each iteration the primal objective P(u) and the dual objective
/// D(p) = −Σᵢ G*ᵢ((div p)ᵢ) are evaluated, G*ᵢ the convex conjugate of the box-constrained data
/// term of pixel i (finite also where wᵢ = 0). Since D(p) ≤ min P ≤ P(u), the report's residual
/// (P(u) − D(p)) / P(u) bounds the relative suboptimality of u: `stopping.rel_residual` is a
/// certified tolerance on the objective. It is 0 when the gap is 0 and +∞ when P(u) = 0 < gap.
/// The objective history holds P(u) in the units of the input.
///
/// # Special cases
/// Each ends with [`Termination::Converged`] after 0 iterations.
/// * λ = 0: uᵢ = fᵢ wherever wᵢ > 0 and the warm start is kept where wᵢ = 0 (every such u is
///   a minimizer).
/// * All weights zero (λ > 0): the minimizers are the constant maps; u is set to the mean of
///   the warm start, the minimizer nearest to it.
/// * The same value of f at every pixel with wᵢ > 0: u is that constant (P(u) = 0).
/// * λ ≥ Σᵢ wᵢ|fᵢ − c|, c = Σᵢ wᵢfᵢ / Σᵢ wᵢ the weighted mean: u is the constant map c, which
///   is then a minimizer (a dual certificate exists along a spanning tree of the grid).
///
/// # Example
/// ```
/// use ndarray::Array2;
/// use rdlidar::solver::{tv_denoise, TvParams};
///
/// # fn main() -> rdlidar::Result<()> {
/// // A noisy constant map with a hole (weight 0) in the middle.
/// let f = Array2::from_shape_fn((20, 30), |(i, j)| {
///     5.0 + 0.1 * (((i * 7 + j * 3) % 5) as f64 - 2.0)
/// });
/// let mut w = Array2::ones((20, 30));
/// w[[10, 15]] = 0.0;
/// let mut u = f.clone();
/// let report = tv_denoise(f.view(), w.view(), &mut u, &TvParams::new(0.5)?, &mut ())?;
/// assert!(report.residual_history.last().unwrap() <= &1e-4);
/// assert!((u[[10, 15]] - 5.0).abs() < 0.05);
/// # Ok(())
/// # }
/// ```
///
/// # References
/// * A. Chambolle, T. Pock, *A first-order primal-dual algorithm for convex problems with
///   applications to imaging*, J. Math. Imaging and Vision 40, 2011.
/// * T. Goldstein, M. Li, X. Yuan, E. Esser, R. Baraniuk, *Adaptive primal-dual hybrid
///   gradient methods for saddle-point problems*, arXiv:1305.0546, 2013.
/// * L. Rudin, S. Osher, E. Fatemi, *Nonlinear total variation based noise removal
///   algorithms*, Physica D 60, 1992.
///
/// # Errors
/// [`Error::InvalidParameter`] for a negative or non-finite λ, invalid stopping rules, a
/// negative weight or an empty map; [`Error::ShapeMismatch`] if `w` or `u` differs in shape
/// from `f`; [`Error::NonFinite`] for a non-finite entry of `f`, `w` or the warm start;
/// [`Error::Breakdown`] if the iteration produces a non-finite objective.
pub fn tv_denoise<O: Observer<f64> + ?Sized>(
    f: ArrayView2<'_, f64>,
    w: ArrayView2<'_, f64>,
    u: &mut Array2<f64>,
    params: &TvParams,
    observer: &mut O,
) -> Result<Report> {
    params.validate()?;
    let (m, n) = f.dim();
    if m == 0 || n == 0 {
        return Err(Error::param(
            "f",
            format!("the map must be non-empty, got {m}x{n}"),
        ));
    }
    check_shape("w", w.dim(), m, n)?;
    check_shape("u", u.dim(), m, n)?;
    check_values("f", f, false)?;
    check_values("w", w, true)?;
    check_values("u (warm start)", u.view(), false)?;

    let grad = Gradient2D::<f64>::new(m, n)?;
    let fv: Vec<f64> = f.iter().copied().collect();
    let wv: Vec<f64> = w.iter().copied().collect();
    let mut x: Vec<f64> = u.iter().copied().collect();
    let setup = TvSetup {
        params: *params,
        w: &wv,
    };
    let report = solve::<f64, _, O, TvIteration<'_>>(&grad, &fv, &mut x, &setup, observer)?;
    u.iter_mut().zip(&x).for_each(|(ui, &v)| *ui = v);
    Ok(report)
}

/// What a TV run is given besides the map: its parameters and the weights.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TvSetup<'w> {
    params: TvParams,
    /// The weights, in the map's order.
    w: &'w [f64],
}

/// The state of [`tv_denoise`] between iterations (the protocol of
/// [`Iteration`](super::Iteration) on the gradient operator, with y the data map and x the
/// map in its own units): the normalized problem, the primal and dual iterates and the steps.
pub(crate) struct TvIteration<'w> {
    problem: Problem,
    /// The objective's factor back to the map's units.
    unit: f64,
    /// The acceleration's strong convexity (0: none) and the adaptive steps' α (0: fixed).
    gamma: f64,
    alpha: f64,
    tau: f64,
    sigma: f64,
    /// The normalized primal iterate, its gradient and the previous one, the dual iterate, its
    /// divergence (the adjoint), and the pointwise residual.
    x: Vec<f64>,
    g: Vec<f64>,
    g_prev: Vec<f64>,
    p: Vec<f64>,
    adj: Vec<f64>,
    r: Vec<f64>,
    sums: Sums,
    objective: f64,
    _setup: std::marker::PhantomData<TvSetup<'w>>,
}

impl<'w> Iterative<f64> for TvIteration<'w> {
    const NAME: &'static str = "tv_denoise";
    type Params = TvSetup<'w>;

    fn stopping(setup: &TvSetup<'w>) -> Stopping {
        setup.params.stopping
    }

    fn check_params(setup: &TvSetup<'w>) -> Result<()> {
        setup.params.validate()
    }
}

impl TvIteration<'_> {
    /// The solution when it is known without iterating (λ = 0, no weight, constant data, or a
    /// λ beyond which the weighted mean is the minimizer), written into `u`; otherwise the
    /// normalized problem: weights divided by their maximum, values mapped affinely from
    /// [lo, hi] (their range where w > 0) onto [−1, 1], λ scaled accordingly. Its minimizers are
    /// those of the original problem mapped the same way.
    fn normalized(f: &[f64], w: &[f64], u: &mut [f64], params: &TvParams) -> Option<Problem> {
        let wmax = w.iter().fold(0.0f64, |a, &b| a.max(b));
        if params.lambda == 0.0 {
            for ((ui, &fi), &wi) in u.iter_mut().zip(f).zip(w) {
                if wi > 0.0 {
                    *ui = fi;
                }
            }
            return None;
        }
        if wmax == 0.0 {
            // Summing vᵢ/len keeps the partial sums within about the range of the values;
            // clamping to that range (where the mean lies) absorbs the rounding, including an
            // overflow of the last steps at the extremes.
            let len = u.len() as f64;
            let (lo, hi) = u
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                });
            let mean = u.iter().map(|&v| v / len).sum::<f64>();
            u.fill(mean.clamp(lo, hi));
            return None;
        }
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (&fi, &wi) in f.iter().zip(w) {
            if wi > 0.0 {
                lo = lo.min(fi);
                hi = hi.max(fi);
            }
        }
        if lo == hi {
            // Constant data: u = that constant has no cost at all.
            u.fill(lo);
            return None;
        }
        let (shift, scale) = (0.5 * lo + 0.5 * hi, 0.5 * hi - 0.5 * lo);
        let fv: Vec<f64> = f.iter().map(|&v| (v - shift) / scale).collect();
        let wv: Vec<f64> = w.iter().map(|&v| v / wmax).collect();
        let lambda = params.lambda / (wmax * scale);
        // With c the weighted mean, the constant map c is a minimizer as soon as
        // λ ≥ Σ wᵢ|fᵢ − c|: along a spanning tree of the grid, a flow p with div p = w(c − f)
        // (which sums to zero) carries at most ½ Σ wᵢ|fᵢ − c| on any edge, so ‖pᵢ‖₂ ≤ λ and
        // (u = c, p) satisfies the optimality conditions for either TV. This also covers a λ
        // too large to represent once normalized.
        let (sw, swf) = wv
            .iter()
            .zip(&fv)
            .fold((0.0, 0.0), |(a, b), (&wi, &fi)| (a + wi, b + wi * fi));
        let mean = swf / sw;
        let spread: f64 = wv
            .iter()
            .zip(&fv)
            .map(|(&wi, &fi)| wi * (fi - mean).abs())
            .sum();
        if lambda >= spread {
            u.fill(shift + scale * mean);
            return None;
        }
        // The warm start, within the data's range (which holds every minimizer).
        for v in u.iter_mut() {
            *v = v.clamp(lo, hi);
        }
        Some(Problem {
            avx2: has_avx2(),
            f: fv,
            w: wv,
            lambda,
            shift,
            scale,
            norm: params.norm,
        })
    }
}

impl<'w, A: LinearOperator<f64> + ?Sized> Iteration<f64, A> for TvIteration<'w> {
    fn start(
        op: &A,
        f: &[f64],
        u: &mut [f64],
        setup: &TvSetup<'w>,
    ) -> Result<ControlFlow<Termination, Self>> {
        let params = &setup.params;
        let Some(problem) = Self::normalized(f, setup.w, u, params) else {
            return Ok(ControlFlow::Break(Termination::Converged));
        };
        let wmax = setup.w.iter().fold(0.0f64, |a, &b| a.max(b));
        let wmin = problem.w.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        let gamma = match params.steps {
            TvSteps::Accelerated if wmin > 0.0 => wmin,
            _ => 0.0,
        };
        let alpha = match params.steps {
            TvSteps::Fixed => 0.0,
            _ if gamma > 0.0 => 0.0,
            _ => ADAPT_ALPHA,
        };
        let x: Vec<f64> = u
            .iter()
            .map(|&v| (v - problem.shift) / problem.scale)
            .collect();
        let mut g = vec![0.0; op.nrows()];
        op.apply(&x, &mut g);
        // τ/σ: 1 for the plain variants (the adaptive one finds its own ratio); a longer first
        // primal step for the accelerated one, whose τ only shrinks.
        let ratio = if gamma > 0.0 { ACCEL_RATIO } else { 1.0 };
        let tau = (ratio * STEP_PRODUCT / 8.0).sqrt();
        let unit = wmax * problem.scale * problem.scale;
        Ok(ControlFlow::Continue(TvIteration {
            unit,
            gamma,
            alpha,
            tau,
            sigma: STEP_PRODUCT / (8.0 * tau),
            g_prev: vec![0.0; g.len()],
            p: vec![0.0; g.len()],
            g,
            adj: vec![0.0; x.len()],
            r: vec![0.0; x.len()],
            x,
            sums: Sums::default(),
            objective: f64::NAN,
            problem,
            _setup: std::marker::PhantomData,
        }))
    }

    /// One primal-dual step; `u` becomes the primal iterate in the map's units.
    fn step(&mut self, op: &A, _f: &[f64], u: &mut [f64], it: usize) -> Result<Progress> {
        let problem = &self.problem;
        let sums = &mut self.sums;
        problem.primal_step(&mut self.x, u, &self.adj, &mut self.r, self.tau, sums);
        std::mem::swap(&mut self.g, &mut self.g_prev);
        op.apply(&self.x, &mut self.g);
        let theta = if self.gamma > 0.0 {
            let theta = 1.0 / (1.0 + 2.0 * self.gamma * self.tau).sqrt();
            self.tau *= theta;
            self.sigma /= theta;
            theta
        } else {
            1.0
        };
        problem.dual_step(&mut self.p, &self.g, &self.g_prev, self.sigma, theta, sums);
        op.apply_adjoint(&self.p, &mut self.adj);
        problem.conjugate(&self.adj, &self.r, sums);

        let primal = sums.data + problem.lambda * sums.tv;
        if !(primal.is_finite() && sums.conj.is_finite()) {
            return Err(Error::Breakdown {
                solver: <Self as Iterative<f64>>::NAME,
                reason: format!("non-finite objective at iteration {it}"),
            });
        }
        let gap = (primal + sums.conj).max(0.0);
        let residual = if gap == 0.0 {
            0.0
        } else if primal > 0.0 {
            gap / primal
        } else {
            f64::INFINITY
        };
        let change = if sums.change == 0.0 {
            0.0
        } else if sums.norm == 0.0 {
            f64::INFINITY
        } else {
            (sums.change / sums.norm).sqrt()
        };
        if self.alpha > 0.0 {
            // Residual balancing: a larger primal residual asks for a longer primal step.
            let (rp, rd) = (sums.primal_res.sqrt(), sums.dual_res.sqrt());
            if rp > ADAPT_RATIO * rd {
                self.tau /= 1.0 - self.alpha;
                self.sigma *= 1.0 - self.alpha;
                self.alpha *= ADAPT_ETA;
            } else if rd > ADAPT_RATIO * rp {
                self.tau *= 1.0 - self.alpha;
                self.sigma /= 1.0 - self.alpha;
                self.alpha *= ADAPT_ETA;
            }
        }
        self.objective = self.unit * primal;
        Ok(Progress {
            residual,
            objective: self.objective,
            change,
            ending: None,
        })
    }

    fn objective(&self) -> f64 {
        self.objective
    }
}
