//! The method registry: every reconstruction method with its lidar defaults, and [`run`] of one
//! concrete method on the lidar operator.

use std::str::FromStr;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::lidar::{LidarOperator, NO_RETURN};
use crate::operator::{Counted, PowerIteration};
use crate::real::Real;
use crate::solver::{
    cgls, cosamp, fista, iht, model_based, reflector_amp, tv_depth, CglsParams, Control,
    CosampParams, FistaParams, IhtParams, IterationInfo, Lambda, Observer, ReflectorAmpParams,
    Report, Restart, StepRule, Stopping, TvDepthParams,
};
use crate::space::{self, Space};

use super::names::{by_name, name_of, names, values};
use super::options::{model_params, stopping, ReconstructOptions};
use super::peaks::{backproject, PeakThreshold};
use super::pursuit::{support_pursuit, PURSUIT_ROUNDS};
use super::refit::{refit_support, REFIT_MAX_ITER, REFIT_ROUNDS};

/// λ of [`Method::Fista`] as a fraction of ‖Aᵀy‖∞.
const FISTA_LAMBDA_FRACTION: f64 = 0.05;

/// Default iteration limits.
const CGLS_MAX_ITER: usize = 300;
const FISTA_MAX_ITER: usize = 200;
const GREEDY_MAX_ITER: usize = 100;
/// CGLS iterations of CoSaMP's least squares on the merged support, warm-started from the previous
/// estimate (the trade-off between time and accuracy is measured in docs/solvers.md).
const COSAMP_INNER_ITER: usize = 10;

/// A reconstruction method, named on the command line as [`Method::name`] gives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Method {
    /// The paper's method: plain backprojection Aᵀy normalized by ‖p‖², per-pixel peak,
    /// threshold by [`ReconstructOptions::threshold`] (the paper's rule by default).
    Backprojection,
    /// Backprojection with the zero-mean pulse, normalized by Σ(p − mean p)·p (≈ K_p/4 for a 0/1
    /// pulse) so that peaks estimate amplitudes; per-pixel peak, threshold as
    /// [`Method::Backprojection`].
    BackprojectionDebiased,
    /// Least squares by CGLS (at most 300 iterations or a relative normal-equation residual of
    /// 1e-8), then its returns.
    Cgls,
    /// Nonnegative lasso by FISTA (λ = 0.05·‖Aᵀy‖∞, the step from the Lanczos norm estimate,
    /// function restart, at most 200 iterations), debiased by least squares on its support
    /// ([`ReconstructOptions::debias`]), then its returns.
    Fista,
    /// Iterative hard thresholding (at most 100 iterations) with the sparsity estimated from the
    /// debiased backprojection and the support pursuit, then its returns.
    Iht,
    /// CoSaMP (at most 100 iterations; least squares on the merged support by at most 10
    /// warm-started CGLS iterations on the support operator) with the sparsity estimated as for
    /// [`Method::Iht`], then its returns.
    Cosamp,
    /// Support pursuit: greedy rounds that add each pixel's best voxel where the residual's
    /// correlation stands out of the cross-talk, solve least squares on the support and drop
    /// insignificant amplitudes, until the data are explained or a round gains less than 5%
    /// (at most 100 rounds, a support of at most K/3 voxels). No per-pixel model: pixels may
    /// keep several returns. Exact and cheap wherever the measurements comfortably outnumber the
    /// returns; [`Method::Auto`] runs it first.
    SupportLs,
    /// Message passing with the one-reflector-per-pixel prior alone
    /// ([`ReflectorAmpParams::default`](crate::solver::ReflectorAmpParams)): the most probable
    /// scene, without the least-squares refinement of [`Method::ModelBased`].
    Amp,
    /// Model-based recovery, at most k reflectors per pixel ([`ReconstructOptions::max_returns`],
    /// one by default; otherwise [`ModelBasedParams::default`](crate::solver::ModelBasedParams::default)):
    /// started by message passing, refined by least squares on the support.
    ModelBased,
    /// Total variation on the depth map ([`TvDepthParams::default`]).
    Tv,
    /// For fewer measurements than lit pixels, or heavy noise: [`Method::Tv`] on a grid of 2×2
    /// blocks (each block's pixels share one depth column, so the blocks' codes add up and a
    /// quarter of the unknowns remain), then the surfaces refined on the pixels
    /// ([`refine_surfaces`](crate::solver::refine_surfaces): amplitudes tied along surfaces,
    /// depths moved pixel by pixel). Codes in memory (one ADC or several), the whole scene in one
    /// process.
    CoarseToFine,
    /// Chosen from the regime of the pulse length; see [`reconstruct`](super::reconstruct).
    Auto,
}

impl Method {
    /// Every method with its command-line name, in the order of the command-line help: the
    /// one table of methods.
    const TABLE: [(Method, &'static str); 12] = [
        (Method::Backprojection, "backprojection"),
        (Method::BackprojectionDebiased, "backprojection-debiased"),
        (Method::Cgls, "cgls"),
        (Method::Fista, "fista"),
        (Method::Iht, "iht"),
        (Method::Cosamp, "cosamp"),
        (Method::SupportLs, "support-ls"),
        (Method::Amp, "amp"),
        (Method::ModelBased, "model-based"),
        (Method::Tv, "tv"),
        (Method::CoarseToFine, "coarse-to-fine"),
        (Method::Auto, "auto"),
    ];

    /// Every method, in the order of the command-line help.
    pub const ALL: [Method; 12] = values(&Method::TABLE);

    /// The command-line names of [`Method::ALL`].
    pub const NAMES: [&'static str; 12] = names(&Method::TABLE);

    /// The command-line name (`"model-based"`, …).
    pub fn name(self) -> &'static str {
        name_of(&Method::TABLE, self)
    }
}

/// A method serializes as its name.
impl serde::Serialize for Method {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Method {
    type Err = Error;

    /// Parses a command-line name (exactly as [`Method::name`] writes it).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`method`) listing the valid names.
    fn from_str(s: &str) -> Result<Self> {
        by_name(s, &Method::TABLE, "method", "method")
    }
}

#[cfg(feature = "progress")]
pub(super) fn progress_bar(
    max_iter: usize,
    options: &ReconstructOptions,
) -> crate::solver::ProgressObserver {
    crate::solver::ProgressObserver::new(max_iter).quiet(!options.progress)
}

/// Without the `progress` feature nothing is drawn.
#[cfg(not(feature = "progress"))]
pub(super) fn progress_bar(_max_iter: usize, _options: &ReconstructOptions) -> NoProgress {
    NoProgress
}

/// The observer of a solve when progress bars are not compiled in.
#[cfg(not(feature = "progress"))]
pub(super) struct NoProgress;

#[cfg(not(feature = "progress"))]
impl NoProgress {
    pub(super) fn finish(&self) {}
}

#[cfg(not(feature = "progress"))]
impl<T> crate::solver::Observer<T> for NoProgress {
    fn observe(&mut self, _: &crate::solver::IterationInfo<'_, T>) -> crate::solver::Control {
        crate::solver::Control::Continue
    }
}

/// Two observers in turn: the run stops when either asks to.
struct Tee<'a, T>(&'a mut dyn Observer<T>, &'a mut dyn Observer<T>);

/// Runs `solve` with a progress bar of `max_iter` iterations (when `options` ask for one)
/// seeing every iteration before `observer`, and clears the bar after: the one progress chain
/// of every iterative method.
fn with_progress<T, R>(
    max_iter: usize,
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
    solve: impl FnOnce(&mut dyn Observer<T>) -> R,
) -> R {
    let mut progress = progress_bar(max_iter, options);
    let r = solve(&mut Tee(&mut progress, observer));
    progress.finish();
    r
}

impl<T> Observer<T> for Tee<'_, T> {
    fn observe(&mut self, info: &IterationInfo<'_, T>) -> Control {
        let a = self.0.observe(info);
        let b = self.1.observe(info);
        if a == Control::Stop || b == Control::Stop {
            Control::Stop
        } else {
            Control::Continue
        }
    }
}

/// Runs one concrete method (not [`Method::Auto`]); returns the estimate and the solver's report.
/// The backprojections' estimates have one return per pixel at most; the iterative ones still
/// need [`returns`](super::peaks::returns).
pub(super) fn run<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    method: Method,
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
) -> Result<(Vec<T>, Option<Report>)> {
    let started = Instant::now();
    // Every application of the method counted here, those of its preparation (a sparsity
    // estimate, a pursuit) and of its refits included.
    let counted = Counted::new(op);
    let op: &dyn LidarOperator<T> = &counted;
    let g = op.geometry();
    let n = g.voxels();
    let mut x = vec![T::zero(); n];
    let mut report = match method {
        Method::Backprojection | Method::BackprojectionDebiased => {
            let debiased = method == Method::BackprojectionDebiased;
            let bp = backproject(op, y, debiased, options.threshold)?;
            return Ok((bp.x, None));
        }
        Method::Cgls => {
            let params = CglsParams {
                damp: 0.0,
                stopping: stopping(
                    Stopping {
                        max_iter: CGLS_MAX_ITER,
                        rel_residual: Some(1e-8),
                        ..Stopping::default()
                    },
                    options,
                ),
            };
            with_progress(params.stopping.max_iter, options, observer, |obs| {
                cgls(op, y, &mut x, &params, obs)
            })?
        }
        Method::Fista => {
            let params = fista_params(options);
            let r = with_progress(params.stopping.max_iter, options, observer, |obs| {
                fista(op, y, &mut x, &params, obs)
            })?;
            if options.debias {
                refit_support(op, y, &mut x, REFIT_MAX_ITER, REFIT_ROUNDS)?;
            }
            r
        }
        Method::Iht => {
            let s = estimate_sparsity(op, y)?;
            let d = IhtParams::new(s);
            let params = IhtParams {
                stopping: stopping(
                    Stopping {
                        max_iter: GREEDY_MAX_ITER,
                        ..d.stopping
                    },
                    options,
                ),
                ..d
            };
            with_progress(params.stopping.max_iter, options, observer, |obs| {
                iht(op, y, &mut x, &params, obs)
            })?
        }
        Method::Cosamp => {
            let s = estimate_sparsity(op, y)?;
            let params = cosamp_params(s, options);
            with_progress(params.stopping.max_iter, options, observer, |obs| {
                cosamp(op, y, &mut x, &params, obs)
            })?
        }
        Method::SupportLs => {
            let rounds = options.max_iter.unwrap_or(PURSUIT_ROUNDS);
            let p = support_pursuit(op, y, rounds)?;
            x = p.x;
            p.report
        }
        Method::Amp => {
            let d = ReflectorAmpParams::default();
            let params = ReflectorAmpParams {
                stopping: stopping(d.stopping, options),
                ..d
            };
            with_progress(params.stopping.max_iter, options, observer, |obs| {
                reflector_amp(op, y, &mut x, &params, obs)
            })?
        }
        Method::ModelBased => {
            let mut params = model_params(options);
            params.max_returns = match options.max_returns {
                Some(k) => k,
                None => estimate_returns_in(
                    op.space(),
                    &support_pursuit(op, y, PURSUIT_ROUNDS)?.x,
                    g.ks,
                ),
            };
            with_progress(params.stopping.max_iter, options, observer, |obs| {
                model_based(op, y, &mut x, &params, obs)
            })?
        }
        Method::Tv => {
            let params = TvDepthParams {
                model: model_params(options),
                ..TvDepthParams::default()
            };
            with_progress(params.model.stopping.max_iter, options, observer, |obs| {
                tv_depth(op, (g.m, g.n), y, &mut x, &params, obs)
            })?
        }
        Method::CoarseToFine => {
            let params = model_params(options);
            let (mut report, uncounted) =
                with_progress(params.stopping.max_iter, options, observer, |obs| {
                    super::coarse::coarse_to_fine(op, y, &mut x, options, obs)
                })?;
            report.set_applies(counted.applies() + uncounted);
            report.elapsed = started.elapsed();
            return Ok((x, Some(report)));
        }
        Method::Auto => unreachable!("Auto is resolved before run"),
    };
    report.set_applies(counted.applies());
    report.elapsed = started.elapsed();
    Ok((x, Some(report)))
}

/// FISTA's parameters for reconstruction: λ a fraction of ‖Aᵀy‖∞, nonnegative, the step from
/// a Lanczos norm estimate, function restarts.
fn fista_params(options: &ReconstructOptions) -> FistaParams {
    FistaParams {
        lambda: Lambda::Fraction(FISTA_LAMBDA_FRACTION),
        nonnegative: true,
        step: StepRule::PowerIteration {
            settings: PowerIteration {
                seed: options.seed,
                max_iter: options
                    .power_iterations
                    .unwrap_or(PowerIteration::default().max_iter),
                ..PowerIteration::default()
            },
            margin: if options.power_iterations.is_some() {
                1.05
            } else {
                1.01
            },
        },
        restart: Restart::Function,
        stopping: stopping(
            Stopping {
                max_iter: FISTA_MAX_ITER,
                rel_residual: Some(1e-6),
                rel_change: Some(1e-6),
                ..Stopping::default()
            },
            options,
        ),
    }
}

/// CoSaMP's parameters for reconstruction at sparsity `s`.
fn cosamp_params(s: usize, options: &ReconstructOptions) -> CosampParams {
    let d = CosampParams::new(s);
    CosampParams {
        stopping: stopping(
            Stopping {
                max_iter: GREEDY_MAX_ITER,
                ..d.stopping
            },
            options,
        ),
        inner: CglsParams {
            stopping: Stopping {
                max_iter: COSAMP_INNER_ITER,
                ..d.inner.stopping
            },
            ..d.inner
        },
        ..d
    }
}

/// The most returns per pixel [`estimate_returns`] proposes.
pub const MAX_RETURNS_ESTIMATE: usize = 8;

/// The returns per pixel a scene estimate `x` (K_s voxels per pixel) suggests: the smallest k
/// such that at least 99% of its lit pixels hold at most k returns, within
/// [1, [`MAX_RETURNS_ESTIMATE`]]. From the support pursuit's estimate, which has no per-pixel
/// model, it gives [`Method::ModelBased`] its k when none is given.
pub fn estimate_returns<T: Real>(x: &[T], ks: usize) -> usize {
    estimate_returns_in(&space::WHOLE, x, ks)
}

/// [`estimate_returns`] of the whole scene, of which `x` is the operator's part (`space`).
pub(super) fn estimate_returns_in<T: Real>(space: &dyn Space, x: &[T], ks: usize) -> usize {
    let counts: Vec<f64> = x
        .chunks(ks.max(1))
        .map(|c| c.iter().filter(|v| **v != T::zero()).count())
        .filter(|&c| c > 0)
        .map(|c| c as f64)
        .collect();
    let mut counts = counts;
    let n = space::count(space, counts.len());
    if n == 0 {
        return 1;
    }
    let at = ((0.99 * n as f64).ceil() as usize).clamp(1, n);
    (space::kth_smallest(space, &mut counts, at - 1) as usize).clamp(1, MAX_RETURNS_ESTIMATE)
}

/// The sparsity for IHT and CoSaMP: the larger of twice the number of pixels the debiased
/// backprojection detects (cross-talk hides weak returns from it, and too small a sparsity
/// cannot be recovered from, whereas a larger one only costs some accuracy) and 1.25 times the
/// support the support pursuit ([`Method::SupportLs`]) settles on, which counts every return of
/// a pixel with several; clamped to [1, K/3], which keeps CoSaMP's least squares on up to 3s
/// columns overdetermined.
fn estimate_sparsity<T: Real>(op: &dyn LidarOperator<T>, y: &[T]) -> Result<usize> {
    let bp = backproject(op, y, true, PeakThreshold::Robust)?;
    let space = op.space();
    let found = space::count(space, bp.peaks.iter().filter(|&&p| p != NO_RETURN).count());
    let pursuit = support_pursuit(op, y, PURSUIT_ROUNDS)?;
    let settled = space::count(space, pursuit.x.iter().filter(|v| **v != T::zero()).count());
    let cap = (op.nrows() / 3)
        .min(space::count(space, op.geometry().voxels()))
        .max(1);
    Ok((2 * found).max(settled + settled.div_ceil(4)).clamp(1, cap))
}
