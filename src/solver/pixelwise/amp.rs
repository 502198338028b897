//! Approximate message passing with the one-reflector-per-pixel prior.
//!
//! The scene prior: a pixel is empty with probability 1 − λ; otherwise it holds one reflector at
//! a depth drawn uniformly from its admissible depths, with an amplitude a ~ N(μ, σ²). AMP turns
//! the coupled problem into one small denoising problem per pixel: after the Onsager-corrected
//! residual z, each pixel sees its correlations g = Aₚᵀz + Gₚx̂ₚ (Gₚ = AₚᵀAₚ, the pixel's own
//! Gram block) as its own reflector observed in Gaussian noise of covariance τ²Gₚ,
//! τ² = ‖z‖²/K. For that model the evidence of depth d is a closed-form Gaussian integral in
//! gᵈ and Gₚ[d, d] alone, so the posterior over "empty or depth d" and the posterior mean are
//! exact and cheap (O(K_s²) per pixel).

use std::ops::ControlFlow;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::linalg::dot;
use crate::operator::{check_pixels, LinearOperator, VoxelOperator};
use crate::real::Real;
use crate::solver::{
    check_problem, solve_with, Iteration, Iterative, Observer, Progress, Report, Stopping,
    Termination,
};
use crate::space::{self, Space};

use super::PixelConstraints;

mod applied;
mod denoise;
use applied::{convert, onsager_residual, Applied};
use denoise::{pixel_posterior, PixelPosterior};

/// Parameters of [`reflector_amp`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReflectorAmpParams {
    /// Prior probability λ that a pixel has a return: the starting value when the prior is
    /// learned (in (0, 1), default 0.5).
    pub lit_probability: f64,
    /// Learns the prior (λ, μ, σ²) from the posteriors after every iteration
    /// (expectation-maximization; default `true`). Otherwise λ stays fixed and μ, σ² keep their
    /// starting values, which come from the measurements' energy.
    pub learn_prior: bool,
    /// Stops when the residual has not improved on its best value for this many iterations, and
    /// returns the best iterate (at least 1, default 5). AMP is not a descent method: on
    /// operators far from its assumptions, or beyond its phase transition, it can drift.
    pub patience: usize,
    /// Stops with [`Termination::Converged`] once the most probable scene's support (which
    /// pixels are lit, at which depth) has stayed the same for this many iterations; `None`
    /// iterates on by the other rules (default `None`; the start of
    /// [`model_based`](super::model_based), which re-fits the amplitudes by least squares, uses 3).
    pub stable_support: Option<usize>,
    /// The estimate keeps a pixel when its posterior probability of a return exceeds this
    /// (in (0, 1), default 0.5).
    pub decision: f64,
    /// Applies the operator in single precision where it has a twin in `f32`
    /// ([`LinearOperator::single`](crate::LinearOperator::single)) and the computation is wider:
    /// the iterates are decided at the noise level τ, far above `f32`'s rounding until the
    /// residual is within about 10⁻⁶ of ‖y‖, and the applications cost about half. The
    /// posteriors, the residual and the state stay in `f64`. Default `false`: the estimate's
    /// amplitudes are the posterior means; the model-based start
    /// ([`ModelBasedParams::amp`](super::ModelBasedParams::amp)), which re-fits them by least
    /// squares in the computation's precision, sets it.
    pub single_precision: bool,
    /// Stopping rules; the residual is ‖y − Ax̂‖ / ‖y‖ for the posterior mean x̂.
    pub stopping: Stopping,
}

impl Default for ReflectorAmpParams {
    fn default() -> Self {
        ReflectorAmpParams {
            lit_probability: 0.5,
            learn_prior: true,
            patience: 5,
            stable_support: None,
            decision: 0.5,
            single_precision: false,
            stopping: Stopping {
                max_iter: 60,
                rel_residual: Some(1e-6),
                ..Stopping::default()
            },
        }
    }
}

impl ReflectorAmpParams {
    /// Checks every setting that needs no operator.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the setting.
    pub fn validate(&self) -> Result<()> {
        self.stopping.validate()?;
        for (name, v) in [
            ("lit_probability", self.lit_probability),
            ("decision", self.decision),
        ] {
            if !(v > 0.0 && v < 1.0) {
                return Err(Error::param(
                    name,
                    format!("must be in (0, 1), got {}", crate::units::number(v)),
                ));
            }
        }
        if self.stable_support == Some(0) {
            return Err(Error::param("stable_support", "must be at least 1"));
        }
        if self.patience == 0 {
            return Err(Error::param("patience", "must be at least 1"));
        }
        Ok(())
    }
}

/// The pixels' Gram blocks: one shared block or one per pixel (row-major K_s × K_s each).
enum Grams {
    Shared(Vec<f64>),
    PerPixel(Vec<f64>),
}

impl Grams {
    fn of<T: Real, A: VoxelOperator<T> + ?Sized>(op: &A, pixels: usize) -> Self {
        if op.uniform_pixel_gram() {
            Grams::Shared(op.pixel_gram(0))
        } else {
            Grams::PerPixel(
                (0..pixels)
                    .into_par_iter()
                    .flat_map_iter(|p| op.pixel_gram(p))
                    .collect(),
            )
        }
    }

    fn block(&self, pixel: usize, ks: usize) -> &[f64] {
        match self {
            Grams::Shared(g) => g,
            Grams::PerPixel(g) => &g[pixel * ks * ks..(pixel + 1) * ks * ks],
        }
    }
}

/// The prior's parameters.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Prior {
    lit: f64,
    mean: f64,
    var: f64,
}

/// Per-pixel priors that replace the global one: the probability of a return, a depth
/// distribution (K_s weights per pixel, renormalized over the admissible depths) and optionally
/// the amplitude's mean and variance.
#[derive(Debug)]
pub(crate) struct PixelPriors {
    pub(crate) lit: Vec<f64>,
    pub(crate) depth: Vec<f64>,
    pub(crate) amplitude: Option<Vec<(f64, f64)>>,
}

/// What a run leaves besides the estimate: the posterior of its best iterate.
pub(crate) struct Posteriors {
    /// P(return at depth d), K_s per pixel.
    pub(crate) depth: Vec<f64>,
    /// P(return), one per pixel.
    pub(crate) lit: Vec<f64>,
    /// E[a | return] and E[a² | return], one pair per pixel ((0, 0) where P(return) = 0).
    pub(crate) amplitude: Vec<(f64, f64)>,
}

/// Where a run stopped, to resume from: AMP's state is its Onsager-corrected residual, the
/// posterior mean and the learned prior. A run resumed under other pixel priors continues from
/// it instead of from z = y, x̂ = 0, so that it only has to move the posteriors on.
#[derive(Debug, Clone)]
pub(crate) struct AmpState {
    z: Vec<f64>,
    mean: Vec<f64>,
    prior: Prior,
}

impl Posteriors {
    fn zeros(pixels: usize, ks: usize) -> Self {
        Posteriors {
            depth: vec![0.0; pixels * ks],
            lit: vec![0.0; pixels],
            amplitude: vec![(0.0, 0.0); pixels],
        }
    }

    /// The amplitude's mean and variance over the pixels, each weighted by its probability of a
    /// return (the global prior's EM estimate at this posterior).
    pub(crate) fn amplitude_moments(&self, space: &dyn Space) -> (f64, f64) {
        let local = self
            .lit
            .iter()
            .zip(&self.amplitude)
            .fold([0.0, 0.0, 0.0], |s, (l, a)| {
                [s[0] + l, s[1] + l * a.0, s[2] + l * a.1]
            });
        let [w, m1, m2] = space::sums(space, local);
        if w <= 0.0 {
            return (0.0, 0.0);
        }
        let mean = m1 / w;
        (mean, (m2 / w - mean * mean).max(0.0))
    }
}

/// Recovers a scene with at most one reflector per pixel by approximate message passing (AMP)
/// with the one-reflector prior, learned from the data; writes the most probable scene into `x`.
///
/// Each iteration costs one forward and one adjoint application of the full operator:
///
/// 1. the Onsager-corrected residual z = y − Ax̂ + (z/K)·Σ divergences, τ² = ‖z‖²/K;
/// 2. per pixel, the correlations g = Aₚᵀz + Gₚx̂ₚ ([`VoxelOperator::pixel_gram`]) and the exact
///    posterior of "empty, or one reflector at depth d with amplitude a" under the prior
///    (module documentation); x̂ₚ becomes the posterior mean, and the divergence of this
///    denoiser, trace(Cov(xₚ | g)·Gₚ)/τ², feeds the next Onsager term;
/// 3. when [`learn_prior`](ReflectorAmpParams::learn_prior), λ, μ and σ² are re-estimated from
///    the posteriors (expectation-maximization).
///
/// Unlike the greedy solvers, AMP keeps every depth of every pixel in play with a weight, which
/// is what lets it escape the wrong-depth fixed points that cross-talk creates. When the
/// measurements suffice it converges to the exact scene in a few tens of iterations; beyond its
/// phase transition it stalls at a partial estimate (which [`model_based`](super::model_based)
/// then refines).
///
/// The result in `x` is the most probable scene: a pixel holds a return when its posterior
/// probability of one exceeds [`decision`](ReflectorAmpParams::decision), at its most probable
/// depth with the posterior mean amplitude there. The run keeps the iterate with the smallest
/// residual and stops with [`Termination::Stagnation`] after
/// [`patience`](ReflectorAmpParams::patience) iterations without improving it; the report's
/// residuals are those of the posterior means. `x` is not used as a warm start (AMP's state is
/// the residual and the posterior, not an estimate).
///
/// # Errors
/// [`Error::InvalidParameter`] for invalid parameters or a column length that does not divide
/// the columns; [`Error::ShapeMismatch`] / [`Error::NonFinite`] for inputs that do not fit;
/// [`Error::Breakdown`] if the iteration produces non-finite values.
pub fn reflector_amp<T, A, O>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &ReflectorAmpParams,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    reflector_amp_constrained(op, y, x, params, PixelConstraints::default(), observer)
        .map(|(r, ..)| r)
}

/// [`reflector_amp`] under per-pixel constraints (depth windows, priors), resumed from
/// `constraints.resume` when given; also returns the posteriors of the best iterate and the
/// state to resume from (that of the best iterate).
pub(crate) fn reflector_amp_constrained<T, A, O>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &ReflectorAmpParams,
    constraints: PixelConstraints<'_>,
    observer: &mut O,
) -> Result<(Report, Posteriors, AmpState)>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    let setup = AmpSetup {
        params: *params,
        constraints,
    };
    let (report, run) = solve_with::<T, A, O, AmpIteration<'_, T>>(op, y, x, &setup, observer)?;
    Ok(match run {
        Some(run) => {
            let (posteriors, state) = run.outcome();
            (report, posteriors, state)
        }
        // y = 0: the empty scene, nothing learned.
        None => {
            let (pixels, ks) = (op.ncols() / op.column_len(), op.column_len());
            let state = AmpState {
                z: y.iter().map(|v| v.as_f64()).collect(),
                mean: vec![0.0; op.ncols()],
                prior: Prior {
                    lit: params.lit_probability,
                    mean: 0.0,
                    var: 0.0,
                },
            };
            (report, Posteriors::zeros(pixels, ks), state)
        }
    })
}

/// What a message-passing run is given: its parameters and the per-pixel constraints.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AmpSetup<'c> {
    params: ReflectorAmpParams,
    constraints: PixelConstraints<'c>,
}

/// The state of message passing between iterations (the protocol of
/// [`Iteration`](crate::solver::Iteration)).
pub(crate) struct AmpIteration<'c, T> {
    params: ReflectorAmpParams,
    windows: Option<&'c [(usize, usize)]>,
    priors: Option<&'c PixelPriors>,
    ks: usize,
    grams: Grams,
    /// Pixels with an admissible depth.
    seen: usize,
    y64: Vec<f64>,
    yy: f64,
    prior: Prior,
    /// The posterior mean x̂ and the Onsager-corrected residual z.
    mean: Vec<f64>,
    z: Vec<f64>,
    /// τ² = ‖z‖²/K, from `prepare`.
    tau2: f64,
    posteriors: Posteriors,
    /// The iterate with the smallest residual: its scene, posteriors and state.
    best_x: Vec<T>,
    best_res: f64,
    best_post: Posteriors,
    best_state: AmpState,
    since_best: usize,
    /// The previous scene and for how many iterations its support has not changed.
    prev: Vec<T>,
    stable: usize,
    objective: f64,
    /// Whether the run ended on the best iterate (every ending but a zero residual).
    on_best: bool,
    /// The applications' vectors in `T`, and in `f32` for the operator's single-precision twin
    /// (allocated on first use).
    full: Applied<T>,
    low: Applied<f32>,
}

impl<'c, T: Real> Iterative<T> for AmpIteration<'c, T> {
    const NAME: &'static str = "reflector-amp";
    type Params = AmpSetup<'c>;

    fn stopping(setup: &AmpSetup<'c>) -> Stopping {
        setup.params.stopping
    }

    fn check_params(setup: &AmpSetup<'c>) -> Result<()> {
        setup.params.validate()
    }
}

impl<'c, T: Real> AmpIteration<'c, T> {
    /// The inputs checked: returns the number of pixels.
    fn check<A: VoxelOperator<T> + ?Sized>(
        op: &A,
        y: &[T],
        x: &[T],
        setup: &AmpSetup<'c>,
    ) -> Result<usize> {
        let name = <Self as Iterative<T>>::NAME;
        setup.params.validate()?;
        let (m, n) = (op.nrows(), op.ncols());
        check_problem(name, op.space(), m, n, y, x)?;
        let PixelConstraints {
            windows,
            priors,
            resume,
        } = setup.constraints;
        let pixels = check_pixels(name, n, op.column_len(), windows)?;
        if let Some(state) = resume {
            if state.z.len() != m || state.mean.len() != n {
                return Err(Error::shape(
                    "reflector-amp: resumed state vs operator columns",
                    n,
                    state.mean.len(),
                ));
            }
        }
        if let Some(pr) = priors {
            if pr.lit.len() != pixels
                || pr.depth.len() != n
                || pr.amplitude.as_ref().is_some_and(|a| a.len() != pixels)
            {
                return Err(Error::shape(
                    "reflector-amp: priors vs pixels",
                    pixels,
                    pr.lit.len(),
                ));
            }
        }
        Ok(pixels)
    }

    /// The starting prior: λ as given, μ and σ² from the measurements' energy (E‖y‖² ≈
    /// Σₚ aₚ²‖a‖², the mean squared amplitude of a lit pixel under λ); and the number of pixels
    /// with an admissible depth (over the whole of the unknowns of `space`).
    fn starting_prior(
        space: &dyn Space,
        grams: &Grams,
        pixels: usize,
        ks: usize,
        yy: f64,
        lit: f64,
    ) -> (Prior, usize) {
        let observable: Vec<bool> = (0..pixels)
            .map(|p| {
                let g = grams.block(p, ks);
                (0..ks).any(|d| g[d * ks + d] > 0.0)
            })
            .collect();
        let seen = observable.iter().filter(|o| **o).count();
        let diag_sum = (0..pixels)
            .filter(|&p| observable[p])
            .map(|p| {
                let g = grams.block(p, ks);
                (0..ks).map(|d| g[d * ks + d]).sum::<f64>() / ks as f64
            })
            .sum::<f64>();
        let [seen, diag_sum] = space::sums(space, [seen as f64, diag_sum]);
        let seen = (seen as usize).max(1);
        let diag_mean = diag_sum / seen as f64;
        let a2 = yy / (lit * seen as f64 * diag_mean);
        let prior = Prior {
            lit,
            mean: 0.8 * a2.sqrt(),
            var: 0.3 * a2,
        };
        (prior, seen)
    }

    /// The posteriors and the state to resume from: those of the best iterate, or of the last
    /// when the run ended on a zero residual.
    fn outcome(self) -> (Posteriors, AmpState) {
        if self.on_best {
            (self.best_post, self.best_state)
        } else {
            let state = AmpState {
                z: self.z,
                mean: self.mean,
                prior: self.prior,
            };
            (self.posteriors, state)
        }
    }

    /// Every pixel's posterior given the correlations `u` = Aᵀz, x̂ updated to the posterior
    /// mean.
    fn pixel_posteriors<U: Real>(&mut self, u: &[U]) -> Vec<PixelPosterior> {
        let (ks, tau2, prior) = (self.ks, self.tau2, self.prior);
        let (grams, windows, priors) = (&self.grams, self.windows, self.priors);
        self.mean
            .par_chunks_mut(ks)
            .zip(u.par_chunks(ks))
            .zip(self.posteriors.depth.par_chunks_mut(ks))
            .enumerate()
            .map(|(p, ((mp, up), wp))| {
                let gram = grams.block(p, ks);
                let window = windows.map_or((0, ks - 1), |w| w[p]);
                let pixel_prior = priors.map(|pr| {
                    (
                        pr.lit[p],
                        &pr.depth[p * ks..(p + 1) * ks],
                        pr.amplitude.as_ref().map(|a| a[p]),
                    )
                });
                pixel_posterior(up, gram, window, tau2, prior, pixel_prior, mp, wp)
            })
            .collect()
    }

    /// The most probable scene into `x`, the posteriors' summaries, and the prior learned from
    /// them; returns the Onsager sum of the divergences.
    fn decide(&mut self, space: &dyn Space, posts: &[PixelPosterior], x: &mut [T]) -> f64 {
        let ks = self.ks;
        x.fill(T::zero());
        let (mut lit, mut amp1, mut amp2, mut div) = (0.0, 0.0, 0.0, 0.0);
        for (p, post) in posts.iter().enumerate() {
            self.posteriors.lit[p] = post.lit;
            self.posteriors.amplitude[p] = if post.lit > 0.0 {
                (post.amp1 / post.lit, post.amp2 / post.lit)
            } else {
                (0.0, 0.0)
            };
            lit += post.lit;
            amp1 += post.amp1;
            amp2 += post.amp2;
            div += post.divergence;
            if let Some((d, a)) = post.best {
                if post.lit > self.params.decision {
                    x[p * ks + d] = T::of_f64(a);
                }
            }
        }
        let [lit, amp1, amp2, div] = space::sums(space, [lit, amp1, amp2, div]);
        if self.params.learn_prior && lit > 0.0 {
            let prior = &mut self.prior;
            prior.lit = (lit / self.seen as f64).clamp(1e-4, 1.0 - 1e-4);
            prior.mean = amp1 / lit;
            prior.var = (amp2 / lit - prior.mean * prior.mean)
                .max(1e-6 * prior.mean * prior.mean)
                .max(f64::MIN_POSITIVE);
        }
        div
    }

    /// One iteration's applications of `op` in its precision `U`: u = Aᵀz, the posteriors and
    /// the most probable scene into `x` (the sums over the unknowns through `space`), then Ax̂
    /// and the Onsager-corrected residual; returns ‖y − Ax̂‖².
    fn apply_on<U: Real, B: LinearOperator<U> + ?Sized>(
        &mut self,
        op: &B,
        space: &dyn Space,
        v: &mut Applied<U>,
        x: &mut [T],
    ) -> f64 {
        convert(&self.z, &mut v.z);
        op.apply_adjoint(&v.z, &mut v.u);
        let posts = self.pixel_posteriors(&v.u);
        let div = self.decide(space, &posts, x);
        convert(&self.mean, &mut v.x);
        op.apply(&v.x, &mut v.ax);
        onsager_residual(&mut self.z, &self.y64, &v.ax, div)
    }

    /// Keeps the current iterate when its residual `res` is the best so far.
    fn keep_if_best(&mut self, res: f64, x: &[T]) {
        if res < self.best_res {
            self.best_res = res;
            self.best_x.copy_from_slice(x);
            self.best_post.depth.copy_from_slice(&self.posteriors.depth);
            self.best_post.lit.copy_from_slice(&self.posteriors.lit);
            self.best_post
                .amplitude
                .copy_from_slice(&self.posteriors.amplitude);
            self.best_state.z.copy_from_slice(&self.z);
            self.best_state.mean.copy_from_slice(&self.mean);
            self.best_state.prior = self.prior;
            self.since_best = 0;
        } else {
            self.since_best += 1;
        }
    }
}

impl<'c, T: Real, A: VoxelOperator<T> + ?Sized> Iteration<T, A> for AmpIteration<'c, T> {
    fn start(
        op: &A,
        y: &[T],
        x: &mut [T],
        setup: &AmpSetup<'c>,
    ) -> Result<ControlFlow<Termination, Self>> {
        let pixels = Self::check(op, y, x, setup)?;
        let (m, n, ks) = (op.nrows(), op.ncols(), op.column_len());
        let params = setup.params;
        x.fill(T::zero());
        let yy = dot(y, y);
        if yy == 0.0 {
            return Ok(ControlFlow::Break(Termination::ZeroResidual));
        }
        let grams = Grams::of(op, pixels);
        let (mut prior, seen) =
            Self::starting_prior(op.space(), &grams, pixels, ks, yy, params.lit_probability);
        let y64: Vec<f64> = y.iter().map(|v| v.as_f64()).collect();
        let mut mean = vec![0.0f64; n];
        let mut z = y64.clone();
        if let Some(state) = setup.constraints.resume {
            mean.copy_from_slice(&state.mean);
            z.copy_from_slice(&state.z);
            prior = state.prior;
        }
        let best_state = AmpState {
            z: z.clone(),
            mean: mean.clone(),
            prior,
        };
        Ok(ControlFlow::Continue(AmpIteration {
            params,
            windows: setup.constraints.windows,
            priors: setup.constraints.priors,
            ks,
            grams,
            seen,
            y64,
            yy,
            prior,
            mean,
            z,
            tau2: 0.0,
            posteriors: Posteriors::zeros(pixels, ks),
            best_x: vec![T::zero(); n],
            best_res: f64::INFINITY,
            best_post: Posteriors::zeros(pixels, ks),
            best_state,
            since_best: 0,
            prev: vec![T::zero(); n],
            stable: 0,
            objective: 0.5 * yy,
            on_best: false,
            full: Applied::zeros(m, n),
            low: Applied::zeros(0, 0),
        }))
    }

    /// τ² = ‖z‖²/K; z = 0 exactly ends the run: the last posterior mean explains y, and x
    /// holds its scene.
    fn prepare(&mut self, _op: &A) -> Option<Termination> {
        self.tau2 = self.z.iter().map(|v| v * v).sum::<f64>() / self.z.len() as f64;
        (!(self.tau2 > 0.0 && self.tau2.is_finite())).then_some(Termination::ZeroResidual)
    }

    fn step(&mut self, op: &A, _y: &[T], x: &mut [T], it: usize) -> Result<Progress> {
        let single = if self.params.single_precision {
            op.single()
        } else {
            None
        };
        let space = op.space();
        let rr = match &single {
            Some(low) => {
                let (m, n) = (self.z.len(), self.mean.len());
                if self.low.z.len() != m {
                    self.low = Applied::zeros(m, n);
                }
                let mut v = std::mem::replace(&mut self.low, Applied::zeros(0, 0));
                let rr = self.apply_on(&**low, space, &mut v, x);
                self.low = v;
                rr
            }
            None => {
                let mut v = std::mem::replace(&mut self.full, Applied::zeros(0, 0));
                let rr = self.apply_on(op, space, &mut v, x);
                self.full = v;
                rr
            }
        };
        let res = (rr / self.yy).sqrt();
        if !res.is_finite() || !space::all(space, x.iter().all(|v| v.is_finite())) {
            return Err(Error::Breakdown {
                solver: <Self as Iterative<T>>::NAME,
                reason: format!("non-finite values at iteration {it}"),
            });
        }
        self.keep_if_best(res, x);
        let same_support = it > 1
            && space::all(
                space,
                x.iter()
                    .zip(&self.prev)
                    .all(|(a, b)| (*a == T::zero()) == (*b == T::zero())),
            );
        self.stable = if same_support { self.stable + 1 } else { 0 };
        let change = space::relative_change(space, x, &self.prev);
        self.prev.copy_from_slice(x);
        self.objective = 0.5 * rr;
        let stable = self.params.stable_support.is_some_and(|s| self.stable >= s);
        let ending = if stable && self.since_best == 0 {
            Some(Termination::Converged)
        } else if self.since_best >= self.params.patience {
            Some(Termination::Stagnation)
        } else {
            None
        };
        Ok(Progress {
            residual: res,
            objective: self.objective,
            change,
            ending,
        })
    }

    fn objective(&self) -> f64 {
        self.objective
    }

    /// The best iterate's scene into `x`, unless the run ended on a zero residual.
    fn finish(&mut self, _op: &A, _y: &[T], x: &mut [T], termination: Termination) -> Result<()> {
        self.on_best = termination != Termination::ZeroResidual;
        if self.on_best {
            x.copy_from_slice(&self.best_x);
        }
        Ok(())
    }
}
