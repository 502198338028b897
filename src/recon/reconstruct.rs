//! One entry point for every reconstruction method, with lidar defaults: from measurements to a
//! one-return-per-pixel scene and its depth map.
//!
//! [`reconstruct`] runs a [`Method`] on an [`RdOperator`] and its measurements and returns a
//! [`Reconstruction`]. Generic solvers (CGLS, FISTA, IHT, CoSaMP) estimate the whole voxel cube;
//! their estimate is reduced to at most one return per pixel by the per-pixel peak rule of
//! [`backprojection`] (the largest positive entry of each pixel, kept above a robust threshold).
//! The model-based and TV solvers produce one return per pixel themselves.

use std::str::FromStr;
use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use crate::linalg::norm2;
use crate::operator::{LinearOperator, PowerIteration};
use crate::real::Real;
use crate::solver::{
    backprojection, cgls, cosamp, fista, iht, model_based, reflector_amp, residual_norm_sq,
    select_peaks, tv_depth, Backprojection, CglsParams, CosampParams, FistaParams, IhtParams,
    Lambda, ModelBasedParams, ReflectorAmpParams, Report, Restart, StepRule, Stopping, Termination,
    Threshold, TvDepthParams,
};

use crate::lidar::{DepthMap, Scene, NO_RETURN};
use crate::lidar::{Geometry, RdOperator, Regime};

/// How many robust standard deviations above the median a per-pixel peak must be to count as a
/// return ([`Threshold::Auto`]).
const AUTO_K: f64 = 3.0;

/// Peaks of an iterative estimate below this fraction of the strongest peak are dropped: they are
/// the numerical residue of empty pixels, not returns.
const RELATIVE_FLOOR: f64 = 0.05;

/// λ of [`Method::Fista`] as a fraction of ‖Aᵀy‖∞.
const FISTA_LAMBDA_FRACTION: f64 = 0.05;

/// Default iteration limits.
const CGLS_MAX_ITER: usize = 300;
const FISTA_MAX_ITER: usize = 200;
const GREEDY_MAX_ITER: usize = 100;
/// CGLS iterations of CoSaMP's least squares on the merged support (warm-started from the previous
/// estimate). At the paper size (100×100×40, K_p = 30000), 100 CoSaMP iterations with 10 took about
/// a quarter of the time of 50, for 25.5% instead of 26.5% exact depths; 5 gave 22.9%
/// (docs/solvers.md).
const COSAMP_INNER_ITER: usize = 10;

/// Fraction of the lit pixels of a depth map that must have a lit 4-neighbour within
/// [`SMOOTH_BINS`] of their depth for the map to count as piecewise smooth
/// ([`is_piecewise_smooth`]).
pub const SMOOTH_FRACTION: f64 = 0.6;

/// Depth difference, in bins, up to which two neighbouring returns belong to one surface.
pub const SMOOTH_BINS: i32 = 1;

/// [`Method::Auto`] keeps the TV refinement only if its residual ‖Ax − y‖ is at most this factor
/// times the model-based one (plus 10⁻⁶‖y‖): TV must not buy smoothness with a worse data fit.
pub const TV_RESIDUAL_MARGIN: f64 = 1.05;

/// A reconstruction method, named on the command line as [`Method::name`] gives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Method {
    /// The paper's method: plain backprojection Aᵀy normalized by ‖p‖², per-pixel peak, robust
    /// threshold ([`Threshold::Auto`] with k = 3).
    Backprojection,
    /// Backprojection with the zero-mean pulse, normalized by Σ(p − mean p)·p (≈ K_p/4 for a 0/1
    /// pulse) so that peaks estimate amplitudes; per-pixel peak, robust threshold.
    BackprojectionDebiased,
    /// Least squares by CGLS (at most 300 iterations or a relative normal-equation residual of
    /// 1e-8), then per-pixel peaks.
    Cgls,
    /// Nonnegative lasso by FISTA (λ = 0.05·‖Aᵀy‖∞, power-iteration step, function restart, at
    /// most 200 iterations), then per-pixel peaks.
    Fista,
    /// Iterative hard thresholding (at most 100 iterations) with the sparsity estimated from the
    /// debiased backprojection, then per-pixel peaks.
    Iht,
    /// CoSaMP (at most 100 iterations; least squares on the merged support by at most 10
    /// warm-started CGLS iterations on the support operator) with the sparsity estimated from the
    /// debiased backprojection, then per-pixel peaks.
    Cosamp,
    /// Message passing with the one-reflector-per-pixel prior alone
    /// ([`ReflectorAmpParams::default`](crate::solver::ReflectorAmpParams)): the most probable
    /// scene, without the least-squares refinement of [`Method::ModelBased`].
    Amp,
    /// Model-based recovery, at most one reflector per pixel ([`ModelBasedParams::default`]):
    /// started by message passing, refined by least squares on the support.
    ModelBased,
    /// Total variation on the depth map ([`TvDepthParams::default`]).
    Tv,
    /// Chosen from the regime of the pulse length; see [`reconstruct`].
    Auto,
}

impl Method {
    /// Every method, in the order of the command-line help.
    pub const ALL: [Method; 10] = [
        Method::Backprojection,
        Method::BackprojectionDebiased,
        Method::Cgls,
        Method::Fista,
        Method::Iht,
        Method::Cosamp,
        Method::Amp,
        Method::ModelBased,
        Method::Tv,
        Method::Auto,
    ];

    /// The command-line names of [`Method::ALL`].
    pub const NAMES: [&'static str; 10] = [
        "backprojection",
        "backprojection-debiased",
        "cgls",
        "fista",
        "iht",
        "cosamp",
        "amp",
        "model-based",
        "tv",
        "auto",
    ];

    /// The command-line name (`"model-based"`, …).
    pub fn name(self) -> &'static str {
        let i = Method::ALL
            .iter()
            .position(|&m| m == self)
            .expect("ALL lists every method");
        Method::NAMES[i]
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
        Method::NAMES
            .iter()
            .position(|&n| n == s)
            .map(|i| Method::ALL[i])
            .ok_or_else(|| {
                Error::param(
                    "method",
                    format!(
                        "unknown method {s:?}; expected one of {}",
                        Method::NAMES.join(", ")
                    ),
                )
            })
    }
}

/// Settings of [`reconstruct`] shared by every method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReconstructOptions {
    /// Overrides the method's iteration limit (ignored by the backprojections).
    pub max_iter: Option<usize>,
    /// Shows a progress bar on stderr (when it is a terminal) during iterative solves.
    pub progress: bool,
    /// Seed of the randomized parts (the power iteration behind FISTA's step).
    pub seed: u64,
    /// Overrides the number of power iterations that estimate ‖A‖² for [`Method::Fista`]'s step
    /// (by default up to 200, until the estimate changes by less than 10⁻⁶; at 100×100×40 these
    /// cost more than 200 FISTA iterations' worth of applications). Fewer iterations
    /// underestimate ‖A‖² a little (about 2% after 30 iterations at 100×100×40), so the step's
    /// safety margin grows from 1.01 to 1.05 when this is set.
    pub power_iterations: Option<usize>,
}

/// What [`reconstruct`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct Reconstruction<T> {
    /// The estimate, at most one nonzero voxel per pixel.
    pub scene: Scene<T>,
    /// Its depth map ([`Scene::depth_map`]): depth bin and amplitude per pixel, [`NO_RETURN`]
    /// where there is none.
    pub depth: DepthMap<T>,
    /// The method that produced the estimate: the one asked for, or what [`Method::Auto`] chose
    /// ([`Method::Tv`] when it refined a model-based fit).
    pub method_used: Method,
    /// The regime of the pulse length (eq. 8–9).
    pub regime: Regime,
    /// The iterative solver's report (`None` for the backprojections). For [`Method::Auto`]
    /// refined by TV, the model-based and TV reports are summed (iterations, applies, elapsed).
    pub report: Option<Report>,
    /// Wall-clock time of the whole reconstruction, peak extraction included.
    pub elapsed: Duration,
}

/// Reconstructs a scene from the measurements `y = A x` of the lidar operator `op`.
///
/// Each [`Method`] runs with lidar defaults (see its documentation). The iterative solvers'
/// estimates are reduced to one return per pixel: each pixel's largest positive entry, kept if it
/// is above median + 3σ of all entries (σ = 1.4826·MAD) and at least 5% of the strongest peak
/// (for the model-based and TV solvers, which already give one return per pixel, this only drops
/// returns too weak to be real).
///
/// **The [`Method::Auto`] rule.** From the regime of K_p ([`Geometry::regime`]):
///
/// * redundant (K > M·N·K_s): [`Method::BackprojectionDebiased`] — the operator is close to a
///   frame and one zero-mean adjoint approximately inverts it;
/// * critical (K = M·N·K_s): [`Method::Cgls`] — A is square and least squares suffices;
/// * compressive: [`Method::ModelBased`]; then, unless its fit already explains the data (its
///   relative residual reached the solver's tolerance, as when it recovers a noise-free scene
///   exactly), [`Method::Tv`] runs from scratch, starting with its neighbourhood prior, which
///   exploits piecewise-smooth depth maps. Its scene is kept if it fits the data about as well
///   ([`TV_RESIDUAL_MARGIN`]); otherwise the model-based scene is returned (and the report, which
///   then still includes the TV run, says `tv-depth` while `method_used` says model-based). On
///   the paper scene at K_p = 10000 the model-based solver finds 6.5% of the depths and TV all.
///   ([`is_piecewise_smooth`] does not gate TV: at short pulses the model-based map is too
///   scattered to pass it although the scene is piecewise smooth.)
///
/// # Errors
/// [`Error::ShapeMismatch`] / [`Error::NonFinite`] if `y` does not fit the operator or is not
/// finite; [`Error::InvalidParameter`] for a zero `max_iter` or an all-zero pulse; the solvers'
/// own errors (e.g. [`Error::Breakdown`]).
pub fn reconstruct<T: Real>(
    op: &RdOperator<T>,
    y: &[T],
    method: Method,
    options: &ReconstructOptions,
) -> Result<Reconstruction<T>> {
    let start = Instant::now();
    if options.max_iter == Some(0) {
        return Err(Error::param("max_iter", "must be at least 1"));
    }
    if options.power_iterations == Some(0) {
        return Err(Error::param("power_iterations", "must be at least 1"));
    }
    if y.len() != op.nrows() {
        return Err(Error::shape(
            "reconstruct: measurements vs operator rows",
            op.nrows(),
            y.len(),
        ));
    }
    let g = op.geometry();
    let regime = g.regime(op.pulse().len());
    let chosen = match method {
        Method::Auto => match regime {
            Regime::Redundant => Method::BackprojectionDebiased,
            Regime::Critical => Method::Cgls,
            Regime::Compressive => Method::ModelBased,
        },
        m => m,
    };
    let (mut x, mut report) = run(op, y, chosen, options)?;
    let mut method_used = chosen;
    if method == Method::Auto && chosen == Method::ModelBased {
        let explained = report
            .as_ref()
            .is_some_and(|r| r.termination == Termination::Residual);
        if !explained {
            let params = TvDepthParams {
                model: model_params(options),
                ..TvDepthParams::default()
            };
            let mut progress = progress_bar(params.model.stopping.max_iter, options);
            // From scratch, so that TV starts with its neighbourhood prior: at short pulses the
            // model-based map is too scattered to be a useful start.
            let mut x_tv = vec![T::zero(); x.len()];
            let tv = tv_depth(op, (g.m, g.n), y, &mut x_tv, &params, &mut progress)?;
            progress.finish();
            let r_mb = residual_norm_sq(op, y, &x).sqrt();
            let r_tv = residual_norm_sq(op, y, &x_tv).sqrt();
            let y_norm = norm2(y);
            if r_tv <= TV_RESIDUAL_MARGIN * r_mb + 1e-6 * y_norm {
                x = x_tv;
                method_used = Method::Tv;
            }
            report = Some(match report {
                Some(mut r) => {
                    r.absorb(tv);
                    r
                }
                None => tv,
            });
        }
    }
    if report.is_some() {
        x = pixel_peaks(&x, g);
    }
    let scene = Scene::from_vec(g, x)?;
    let depth = scene.depth_map();
    Ok(Reconstruction {
        scene,
        depth,
        method_used,
        regime,
        report,
        elapsed: start.elapsed(),
    })
}

/// Whether at least [`SMOOTH_FRACTION`] of the lit pixels of `depth` have a lit 4-neighbour
/// within [`SMOOTH_BINS`] bins of their depth (false for a map with no lit pixel).
pub fn is_piecewise_smooth(depth: &ndarray::Array2<i32>) -> bool {
    let (m, n) = depth.dim();
    let (mut lit, mut smooth) = (0usize, 0usize);
    for ((i, j), &d) in depth.indexed_iter() {
        if d == NO_RETURN {
            continue;
        }
        lit += 1;
        let neighbours = [
            (i.wrapping_sub(1), j),
            (i + 1, j),
            (i, j.wrapping_sub(1)),
            (i, j + 1),
        ];
        if neighbours.iter().any(|&(a, b)| {
            a < m && b < n && {
                let e = depth[[a, b]];
                e != NO_RETURN && (e - d).abs() <= SMOOTH_BINS
            }
        }) {
            smooth += 1;
        }
    }
    lit > 0 && smooth as f64 >= SMOOTH_FRACTION * lit as f64
}

#[cfg(feature = "progress")]
fn progress_bar(max_iter: usize, options: &ReconstructOptions) -> crate::solver::ProgressObserver {
    crate::solver::ProgressObserver::new(max_iter).quiet(!options.progress)
}

/// Without the `progress` feature nothing is drawn.
#[cfg(not(feature = "progress"))]
fn progress_bar(_max_iter: usize, _options: &ReconstructOptions) -> NoProgress {
    NoProgress
}

/// The observer of a solve when progress bars are not compiled in.
#[cfg(not(feature = "progress"))]
struct NoProgress;

#[cfg(not(feature = "progress"))]
impl NoProgress {
    fn finish(&self) {}
}

#[cfg(not(feature = "progress"))]
impl<T> crate::solver::Observer<T> for NoProgress {
    fn observe(&mut self, _: &crate::solver::IterationInfo<'_, T>) -> crate::solver::Control {
        crate::solver::Control::Continue
    }
}

fn stopping(default: Stopping, options: &ReconstructOptions) -> Stopping {
    Stopping {
        max_iter: options.max_iter.unwrap_or(default.max_iter),
        ..default
    }
}

fn model_params(options: &ReconstructOptions) -> ModelBasedParams {
    let d = ModelBasedParams::default();
    ModelBasedParams {
        stopping: stopping(d.stopping, options),
        ..d
    }
}

/// Runs one concrete method (not [`Method::Auto`]); returns the estimate and the solver's report.
/// The backprojections' estimates have one return per pixel at most; the iterative ones still
/// need [`pixel_peaks`].
fn run<T: Real>(
    op: &RdOperator<T>,
    y: &[T],
    method: Method,
    options: &ReconstructOptions,
) -> Result<(Vec<T>, Option<Report>)> {
    let g = op.geometry();
    let n = g.voxels();
    let mut x = vec![T::zero(); n];
    let report = match method {
        Method::Backprojection | Method::BackprojectionDebiased => {
            let bp = backproject(op, y, method == Method::BackprojectionDebiased)?;
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
            let mut progress = progress_bar(params.stopping.max_iter, options);
            let r = cgls(op, y, &mut x, &params, &mut progress)?;
            progress.finish();
            r
        }
        Method::Fista => {
            let params = FistaParams {
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
            };
            let mut progress = progress_bar(params.stopping.max_iter, options);
            let r = fista(op, y, &mut x, &params, &mut progress)?;
            progress.finish();
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
            let mut progress = progress_bar(params.stopping.max_iter, options);
            let r = iht(op, y, &mut x, &params, &mut progress)?;
            progress.finish();
            r
        }
        Method::Cosamp => {
            let s = estimate_sparsity(op, y)?;
            let d = CosampParams::new(s);
            let params = CosampParams {
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
            };
            let mut progress = progress_bar(params.stopping.max_iter, options);
            let r = cosamp(op, y, &mut x, &params, &mut progress)?;
            progress.finish();
            r
        }
        Method::Amp => {
            let d = ReflectorAmpParams::default();
            let params = ReflectorAmpParams {
                stopping: stopping(d.stopping, options),
                ..d
            };
            let mut progress = progress_bar(params.stopping.max_iter, options);
            let r = reflector_amp(op, y, &mut x, &params, &mut progress)?;
            progress.finish();
            r
        }
        Method::ModelBased => {
            let params = model_params(options);
            let mut progress = progress_bar(params.stopping.max_iter, options);
            let r = model_based(op, y, &mut x, &params, &mut progress)?;
            progress.finish();
            r
        }
        Method::Tv => {
            let params = TvDepthParams {
                model: model_params(options),
                ..TvDepthParams::default()
            };
            let mut progress = progress_bar(params.model.stopping.max_iter, options);
            let r = tv_depth(op, (g.m, g.n), y, &mut x, &params, &mut progress)?;
            progress.finish();
            r
        }
        Method::Auto => unreachable!("Auto is resolved before run"),
    };
    Ok((x, Some(report)))
}

/// The (plain or debiased) backprojection with the lidar normalization and the robust threshold.
fn backproject<T: Real>(
    op: &RdOperator<T>,
    y: &[T],
    debiased: bool,
) -> Result<crate::solver::BackprojectionResult<T>> {
    let p = op.pulse();
    let (filter, normalization) = if debiased {
        let z = op.zero_mean();
        // Σ (p − mean p)·p: the lag-0 correlation of the matched filter with the pulse.
        let norm: f64 = z
            .pulse()
            .iter()
            .zip(p)
            .map(|(a, b)| a.as_f64() * b.as_f64())
            .sum();
        (Some(z), norm)
    } else {
        (None, p.iter().map(|v| v.as_f64().powi(2)).sum())
    };
    if !(normalization.is_finite() && normalization > 0.0) {
        return Err(Error::param(
            "pulse",
            "backprojection needs a pulse with at least two distinct values (its matched-filter \
             gain is zero)",
        ));
    }
    let params = Backprojection {
        column_len: op.geometry().ks,
        normalization,
        threshold: Threshold::Auto { k: AUTO_K },
    };
    match &filter {
        Some(z) => backprojection(z, y, &params),
        None => backprojection(op, y, &params),
    }
}

/// The sparsity for IHT and CoSaMP: twice the number of pixels the debiased backprojection
/// detects (cross-talk hides weak returns from it, and too small a sparsity cannot be recovered
/// from, whereas a larger one only costs some accuracy), clamped to [1, min(M·N, K/3)]: one
/// return per pixel at most, and K/3 keeps CoSaMP's least squares on up to 3s columns
/// overdetermined.
fn estimate_sparsity<T: Real>(op: &RdOperator<T>, y: &[T]) -> Result<usize> {
    let bp = backproject(op, y, true)?;
    let found = bp.peaks.iter().filter(|&&p| p != NO_RETURN).count();
    let cap = (op.nrows() / 3).min(op.geometry().pixels()).max(1);
    Ok((2 * found).clamp(1, cap))
}

/// One return per pixel from a voxel estimate: each pixel's largest positive entry, kept above the
/// robust threshold median + [`AUTO_K`]·σ of all entries ([`select_peaks`]), then peaks below
/// [`RELATIVE_FLOOR`] of the strongest dropped.
fn pixel_peaks<T: Real>(x: &[T], g: Geometry) -> Vec<T> {
    let auto = select_peaks(x, g.ks, Threshold::Auto { k: AUTO_K });
    select_peaks(&auto.x, g.ks, Threshold::RelativeToMax(RELATIVE_FLOOR)).x
}
