//! Total variation on the depth map: model-based fits alternated with weighted TV denoising of the
//! depths, for piecewise-smooth scenes.

use ndarray::Array2;

use crate::error::{Error, Result};
use crate::linalg::{column_peaks, PeakRule};
use crate::real::Real;
use crate::space::{self, Space};

use super::amp::reflector_amp_constrained;
use super::model_based::{model_based_windowed, residual};
use super::PixelConstraints;
use crate::operator::{Counted, VoxelOperator};
use crate::solver::{
    residual_norm_sq, tv_denoise, Control, IterationInfo, ModelBasedParams, Observer,
    ReflectorAmpParams, Report, Stopping, Termination, TvParams,
};

mod neighbours;
use neighbours::{changed_fraction, neighbour_priors, Neighbourhood};

/// Parameters of [`tv_depth`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TvDepthParams {
    /// The model-based fits (the first from scratch, the later ones restricted to depth windows).
    pub model: ModelBasedParams,
    /// λ of the weighted TV denoising of the depth map, in depth bins per unit of confidence
    /// weight (the weights are normalized to a maximum of 1; default 0.3).
    pub lambda: f64,
    /// Half-width, in bins, of the window around the regularized depth within which the next
    /// fit may place each pixel's reflector (default 2).
    pub window: usize,
    /// Alternations of TV denoising and windowed fitting (default 2).
    pub rounds: usize,
    /// Rounds of the neighbourhood prior before the first fit, when it starts by message passing
    /// ([`ModelBasedParams::amp`]): each round continues message passing with every pixel's prior
    /// built from its neighbours' posteriors (at most this many, default 32; 0 disables it).
    pub neighbour_rounds: usize,
    /// Message-passing iterations with the global prior before the first round, at most
    /// (default 10; the run stops earlier by the stopping rules of [`ModelBasedParams::amp`]).
    /// The rounds continue from where it stops: it only needs to find the pixels the data
    /// alone decide.
    pub neighbour_start: usize,
    /// Message-passing iterations per round at most (default 2; the rounds run the remaining
    /// stopping rules of [`ModelBasedParams::amp`]). A round only needs to move the posteriors
    /// on: the next round continues from its state under the updated priors.
    pub neighbour_iterations: usize,
    /// When the fit after the continued rounds leaves a relative residual above 10⁻³, the
    /// neighbourhood prior runs again with rounds restarted from scratch, of at most this many
    /// iterations each (after a first run to message passing's own limit), and the fit with the
    /// smaller residual is kept (default 20; 0 skips it). The restart is skipped when the
    /// continued rounds stalled at the noise and their fit leaves at most 0.2 of ‖y‖. Continued
    /// rounds are several times faster on large images, restarted ones reach a lower phase
    /// transition on small ones.
    pub neighbour_restart: usize,
    /// The rounds stop when a round changes the estimate (which pixels have a return, at which
    /// depth) in at most this fraction of the pixels (in [0, 1), default 0.002).
    pub neighbour_change: f64,
    /// The neighbourhood: pixels within this many rows and columns (default 2, a 5×5 square).
    pub neighbour_radius: usize,
    /// The share of the uniform depth distribution mixed into each neighbourhood depth prior,
    /// so that no depth is excluded (in (0, 1], default 0.1).
    pub neighbour_floor: f64,
    /// A neighbour counts as a return for the prior only when its expected amplitude is at least
    /// this fraction of the mean amplitude of the first run (in [0, 1), default 0.25). This keeps
    /// "a return of vanishing amplitude", which the data cannot tell from an empty pixel, from
    /// spreading through the neighbourhoods.
    pub neighbour_gate: f64,
    /// The TV denoising's own stopping rules.
    pub tv: TvParams,
}

impl Default for TvDepthParams {
    fn default() -> Self {
        TvDepthParams {
            model: ModelBasedParams::default(),
            lambda: 0.3,
            window: 2,
            rounds: 2,
            neighbour_rounds: 32,
            neighbour_start: 10,
            neighbour_iterations: 2,
            neighbour_restart: 20,
            neighbour_change: 0.002,
            neighbour_radius: 2,
            neighbour_floor: 0.1,
            neighbour_gate: 0.25,
            tv: TvParams::new(1.0).expect("a valid λ"),
        }
    }
}

/// The restarted rounds ([`TvDepthParams::neighbour_restart`]) run only when the fit after the
/// continued ones leaves a relative residual above this: below it the support is found, and
/// only the least squares on it may be unfinished (an iteration budget).
const RESTART_BELOW: f64 = 1e-3;

/// A round of the neighbourhood prior improves when the squared residual of its estimate falls
/// at least this fraction below the lowest so far (the first run's included).
const ROUND_GAIN: f64 = 0.01;

/// The rounds stop when this many in a row have not improved ([`ROUND_GAIN`]) with the
/// estimate's relative residual at most [`NOISE_FLOOR`] (a round above it starts the count
/// again); the last round's estimate goes on to the model-based fit. Under noise the pixels at the
/// detection bar keep changing, so the change rule
/// ([`neighbour_change`](TvDepthParams::neighbour_change)) alone would run every round: at 20 dB
/// on the 100×100×40 paper scene at K_p = 10 000 the residual stops falling after about 20 of
/// the 32 rounds and then rises.
const ROUND_PATIENCE: usize = 3;

/// The relative residual at or below which rounds that stop improving are taken to have reached
/// the noise (20 dB leaves about 0.07 on the paper scene): they end ([`ROUND_PATIENCE`]), and
/// when the fit after them leaves at most this much, the rounds are not restarted from scratch
/// (what is left is noise or a few pixels, which the windowed fits correct, and the restarted
/// rounds, several times as many iterations there, find the same fit). Above it, slow rounds
/// go on (noise-free scenes below one measurement per lit pixel gain little per round for
/// several rounds and then more) and stuck fits near the phase transition (0.27–0.94 on
/// 16×16×16 scenes) are restarted.
const NOISE_FLOOR: f64 = 0.2;

/// ‖y − Ax‖² through the operator restricted to the nonzero voxels of `x`: one application on
/// the support.
fn support_residual_sq<T, A>(op: &A, y: &[T], x: &[T]) -> Result<f64>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
{
    let voxels = crate::solver::support(x);
    let b: Vec<T> = voxels.iter().map(|&v| x[v]).collect();
    let r = residual(op, &voxels, y, &b)?;
    Ok(crate::linalg::dot(&r, &r))
}

/// How the rounds of the neighbourhood prior ended.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum RoundsEnd {
    /// A run explained the data, the first run found no amplitude, or a round changed too few
    /// pixels.
    Settled,
    /// The rounds stopped lowering a residual at the noise while pixels still changed
    /// ([`ROUND_PATIENCE`]).
    Stalled,
    /// The round limit.
    Limit,
}

/// How the rounds of the neighbourhood prior run message passing.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Schedule {
    /// A first run of [`neighbour_start`](TvDepthParams::neighbour_start) iterations, then rounds
    /// of [`neighbour_iterations`](TvDepthParams::neighbour_iterations) that continue it.
    Continued,
    /// A first run to message passing's own limit, then rounds restarted from scratch, each of
    /// [`neighbour_restart`](TvDepthParams::neighbour_restart) iterations at most.
    Restarted,
}

/// The neighbourhood prior (from `x` = 0), then the model-based fit from its estimate; the
/// report sums both.
#[allow(clippy::too_many_arguments)]
fn prior_then_fit<T, A, O>(
    op: &A,
    grid: (usize, usize),
    y: &[T],
    x: &mut [T],
    amp: &ReflectorAmpParams,
    params: &TvDepthParams,
    schedule: Schedule,
    observer: &mut O,
) -> Result<(Report, RoundsEnd)>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    let ks = op.column_len();
    let capped = |limit: usize| ReflectorAmpParams {
        stopping: Stopping {
            max_iter: amp.stopping.max_iter.min(limit),
            ..amp.stopping
        },
        ..*amp
    };
    let (first, round) = match schedule {
        Schedule::Continued => (
            capped(params.neighbour_start),
            capped(params.neighbour_iterations),
        ),
        Schedule::Restarted => (*amp, capped(params.neighbour_restart)),
    };
    let (mut rep, mut post, mut state) =
        reflector_amp_constrained(op, y, x, &first, PixelConstraints::default(), &mut ())?;
    let space = op.space();
    let (mean, var) = post.amplitude_moments(space);
    let hood = Neighbourhood {
        radius: params.neighbour_radius,
        floor: params.neighbour_floor,
        reference: (mean, var.max(1e-6 * mean * mean).max(f64::MIN_POSITIVE)),
        gate: params.neighbour_gate,
        per_bin: op.columns_per_bin(),
    };
    let mut last = x.to_vec();
    let y2 = crate::linalg::dot(y, y);
    let mut best = support_residual_sq(op, y, x)?;
    let mut stale = 0;
    let mut end = RoundsEnd::Limit;
    for _ in 0..params.neighbour_rounds {
        // Done once a run explains the data.
        if rep.termination == Termination::Residual || mean <= 0.0 {
            end = RoundsEnd::Settled;
            break;
        }
        let priors = neighbour_priors(space, &post, grid, ks, &hood);
        let resume = (schedule == Schedule::Continued).then_some(&state);
        let (more, p, s) = reflector_amp_constrained(
            op,
            y,
            x,
            &round,
            PixelConstraints {
                windows: None,
                priors: Some(&priors),
                resume,
            },
            &mut (),
        )?;
        rep.absorb(more);
        post = p;
        state = s;
        if changed_fraction(space, x, &last, ks) <= params.neighbour_change {
            end = RoundsEnd::Settled;
            break;
        }
        let low = support_residual_sq(op, y, x)?;
        if low < (1.0 - ROUND_GAIN) * best {
            best = low;
            stale = 0;
        } else if low <= NOISE_FLOOR * NOISE_FLOOR * y2 {
            stale += 1;
        } else {
            stale = 0;
        }
        if stale >= ROUND_PATIENCE {
            end = RoundsEnd::Stalled;
            break;
        }
        last.copy_from_slice(x);
    }
    // Rounds that stalled at the noise leave every return the data decide: exploring from their
    // estimate would only add the empty pixels with a positive correlation (about half of them
    // under noise), which the amplitude tests then drop over a dozen iterations, not all.
    let model = ModelBasedParams {
        explore_iterations: if end == RoundsEnd::Stalled {
            0
        } else {
            params.model.explore_iterations
        },
        ..params.model
    };
    rep.absorb(model_based_windowed(
        op,
        y,
        x,
        &model,
        None,
        Some(grid),
        observer,
    )?);
    Ok((rep, end))
}

/// Recovers a scene with one reflector per pixel whose depth map is piecewise smooth: the
/// regularization acts on the M×N depth map, not on the voxel cube.
///
/// When the fits start by message passing ([`ModelBasedParams::amp`], the default) and `x` is
/// all zero, a *neighbourhood prior* comes first. Message passing runs with the global prior
/// for [`neighbour_start`](TvDepthParams::neighbour_start) iterations; then, for up to
/// [`neighbour_rounds`](TvDepthParams::neighbour_rounds) rounds of
/// [`neighbour_iterations`](TvDepthParams::neighbour_iterations) each, it continues from where it
/// stopped (its residual, posterior means and learned prior) with every pixel's prior built from
/// its neighbours' posteriors at the end of the previous round: the probability of a return, the
/// depth distribution (spread over ±1 bin) and the amplitude's mean and spread. A pixel whose
/// neighbours agree on a surface thus needs the data only to confirm a few depths and an
/// amplitude close to theirs, so confident regions grow round by round from where the data
/// alone decide. The rounds stop when a run explains the data, when a round changes fewer than
/// [`neighbour_change`](TvDepthParams::neighbour_change) of the pixels, or when three rounds in a
/// row do not lower the squared residual by 1% while the residual is at most 0.2 of ‖y‖
/// (noise; the fit from their estimate then skips its exploration,
/// [`ModelBasedParams::explore_iterations`]: it would only add empty pixels). On the 100×100×40
/// paper scene this recovers every depth from K_p = 10000 samples (K ≈ 1.8 times the number of
/// returns), noise-free, where message passing alone finds 19%; short rounds that continue one
/// run (2 iterations each) need a quarter of the iterations that rounds restarted from scratch
/// (20 each) need. Neighbours with an
/// expected amplitude below [`neighbour_gate`](TvDepthParams::neighbour_gate) of the typical
/// one count as empty: otherwise "a return of vanishing amplitude", which the data cannot tell
/// from an empty pixel, spreads through the background.
///
/// Then:
///
/// 1. A [`model_based`](super::model_based) fit gives each pixel a depth and an amplitude.
/// 2. The depth map is denoised by weighted TV ([`tv_denoise`], Chambolle–Pock): each lit pixel
///    weighs by its squared amplitude (normalized to 1), a measure of its confidence; empty
///    pixels weigh 0, so that their depth is inpainted from their neighbours.
/// 3. Every pixel's depth is then restricted to a window of ±[`window`](TvDepthParams::window)
///    bins around the regularized depth and the model-based fit runs again within the windows.
///    When the fits start by message passing ([`ModelBasedParams::amp`], the default), the
///    windowed fit starts afresh: message passing with each pixel's prior confined to its window
///    (a few depths instead of K_s, which is what lets it resolve pulses too short for the
///    unconstrained prior), then the least-squares refinement. Otherwise the reflectors are moved
///    into their windows and the greedy fit continues from them.
///
/// Every model-based fit here knows the grid, so its detections follow the surface rule
/// ([`ModelBasedParams::surface_z`]): a return that continues its neighbours' surface (within one
/// bin of their depths) stays on a lower amplitude bar, a pixel next to such a surface joins it
/// on a lower correlation bar, and an isolated return must stand out far more. At 10 dB SNR and
/// 2.4 measurements per lit pixel this roughly doubles the depths found within one bin with no
/// more false returns than the per-pixel tests leave.
///
/// Steps 2–3 repeat [`rounds`](TvDepthParams::rounds) times; none run when the first fit already
/// explains the data (it stopped on its residual tolerance), and a round whose fit leaves more than
/// twice the squared residual of the one before is undone and ends them (its fit ends as soon as
/// its squared residual is above that bar and rising: it does not come back). Isolated wrong
/// depths, which cross-talk and noise cause and which the per-pixel model cannot tell from true
/// ones, are pulled towards their neighbours' depths, where the data then confirm or move them.
///
/// `grid` is (M, N), with M·N pixels of `op.column_len()` voxels each. The report sums the
/// iterations and the applications of `op` over every fit and ends with the last fit's termination.
///
/// # Errors
/// As [`model_based`](super::model_based) and [`tv_denoise`]; [`Error::ShapeMismatch`] if
/// M·N is not the operator's number of pixels; [`Error::InvalidParameter`] for a negative or
/// non-finite λ.
pub fn tv_depth<T, A, O>(
    op: &A,
    grid: (usize, usize),
    y: &[T],
    x: &mut [T],
    params: &TvDepthParams,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    let ks = op.column_len();
    let (m, n) = grid;
    if ks == 0 || m * n * ks != op.ncols() {
        return Err(Error::shape(
            "tv_depth: grid pixels × column length vs operator columns",
            op.ncols(),
            m * n * ks,
        ));
    }
    params.validate()?;
    // Every application of every part counted once, here.
    let counted = Counted::new(op);
    let mut report = first_fit(&counted, grid, y, x, params, observer)?;
    // When the fit explains the data to the solver's tolerance, there is nothing for TV to
    // correct.
    if report.termination != Termination::Residual {
        tv_rounds(&counted, grid, y, x, params, &mut report, observer)?;
    }
    report.solver = "tv-depth";
    report.set_applies(counted.applies());
    Ok(report)
}

impl TvDepthParams {
    /// Checks every setting that needs no operator, those of the model-based fits and of TV
    /// included.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the setting.
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
        if !(self.neighbour_floor > 0.0 && self.neighbour_floor <= 1.0) {
            return Err(Error::param(
                "neighbour_floor",
                format!(
                    "must be in (0, 1], got {}",
                    crate::units::number(self.neighbour_floor)
                ),
            ));
        }
        if self.neighbour_iterations == 0 || self.neighbour_start == 0 {
            let name = if self.neighbour_start == 0 {
                "neighbour_start"
            } else {
                "neighbour_iterations"
            };
            return Err(Error::param(name, "must be at least 1"));
        }
        for (name, v) in [
            ("neighbour_change", self.neighbour_change),
            ("neighbour_gate", self.neighbour_gate),
        ] {
            if !(0.0..1.0).contains(&v) {
                return Err(Error::param(
                    name,
                    format!("must be in [0, 1), got {}", crate::units::number(v)),
                ));
            }
        }
        self.model.validate()?;
        TvParams {
            lambda: self.lambda,
            ..self.tv
        }
        .validate()
    }
}

/// The first fit: with message passing and `x` = 0, the neighbourhood prior (message passing,
/// then again with priors from the neighbours' posteriors, until a run explains the data or the
/// rounds are used up, continued rounds and if needed restarted ones) and the model-based fit
/// from it; otherwise the model-based fit from `x`.
fn first_fit<T, A, O>(
    op: &A,
    grid: (usize, usize),
    y: &[T],
    x: &mut [T],
    params: &TvDepthParams,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    let amp = params.model.amp.as_ref().filter(|_| {
        params.neighbour_rounds > 0 && space::all(op.space(), x.iter().all(|v| *v == T::zero()))
    });
    let Some(amp) = amp else {
        return model_based_windowed(op, y, x, &params.model, None, Some(grid), observer);
    };
    let (mut report, end) =
        prior_then_fit(op, grid, y, x, amp, params, Schedule::Continued, observer)?;
    let a = residual_norm_sq(op, y, x);
    let y2 = crate::linalg::dot(y, y);
    if a > RESTART_BELOW * RESTART_BELOW * y2
        && params.neighbour_restart > 0
        && !(end == RoundsEnd::Stalled && a <= NOISE_FLOOR * NOISE_FLOOR * y2)
    {
        // Continued rounds can settle where rounds restarted from scratch still find the scene
        // (small images near the phase transition): those run too, and the better fit is kept.
        let mut other = vec![T::zero(); x.len()];
        let (second, _) = prior_then_fit(
            op,
            grid,
            y,
            &mut other,
            amp,
            params,
            Schedule::Restarted,
            observer,
        )?;
        let b = residual_norm_sq(op, y, &other);
        if b < a {
            x.copy_from_slice(&other);
            report.absorb(second);
        } else {
            report.absorb_applies(&second);
        }
    }
    Ok(report)
}

/// The depths of the peaks `found` (the strongest `amax`), denoised by weighted TV on the depth
/// map and rounded to bins, for this part's `grid` = (its rows, N) of an image split by rows.
/// TV couples every pixel with its neighbours: the depth map and the weights (K_s times
/// smaller than the unknowns) are gathered, and every part denoises the whole map.
fn regularized_depths(
    space: &dyn Space,
    found: &[Option<(usize, f64)>],
    amax: f64,
    (m, n): (usize, usize),
    ks: usize,
    tv: &TvParams,
) -> Result<Vec<usize>> {
    let depth: Vec<f64> = found
        .iter()
        .map(|p| p.map_or(0.0, |p| p.0 as f64))
        .collect();
    let weight: Vec<f64> = found
        .iter()
        .map(|p| p.map_or(0.0, |p| (p.1 / amax).powi(2)))
        .collect();
    let first = space.offset(m * n);
    let depth = space::whole_values(space, depth);
    let weight = space::whole_values(space, weight);
    let rows = depth.len() / n.max(1);
    let f = Array2::from_shape_vec((rows, n), depth).expect("whole rows");
    let w = Array2::from_shape_vec((rows, n), weight).expect("whole rows");
    let mut u = f.clone();
    tv_denoise(f.view(), w.view(), &mut u, tv, &mut ())?;
    Ok(u.iter()
        .skip(first)
        .take(m * n)
        .map(|v| v.round().clamp(0.0, (ks - 1) as f64) as usize)
        .collect())
}

/// A windowed fit that leaves more than this many times the squared residual of the fit before
/// it has lost what that one found: its round is undone and the rounds end.
const LOST: f64 = 2.0;

/// The observer of a round's windowed fit: every iteration goes on to the caller's observer, and
/// the fit ends as soon as it is on its way to being undone, its squared residual above
/// [`LOST`] times that of the fit before and rising. Without exploration the windowed fit finds
/// few new returns, and no fit measured that dropped returns faster than it found them came back:
/// at 20 dB on the 100×100×40 paper scene at K_p = 10 000 the windowed fit started from message
/// passing within the windows at 15 times the squared residual and rose for 31 iterations, a
/// third of the solver's time, to be undone. Fits that are kept may start as high (up to 8
/// times on the 16×16×16 scenes of the hard comparisons) but fall from their first iteration.
struct Losing<'o, O: ?Sized> {
    observer: &'o mut O,
    /// √([`LOST`] · the fit before) / ‖y‖: the bar on the relative residual.
    bar: f64,
    /// The previous iteration's relative residual.
    last: f64,
    lost: bool,
}

impl<T, O: Observer<T> + ?Sized> Observer<T> for Losing<'_, O> {
    fn observe(&mut self, info: &IterationInfo<'_, T>) -> Control {
        let control = self.observer.observe(info);
        let rising = info.residual > self.last;
        self.last = info.residual;
        if control == Control::Continue && rising && info.residual > self.bar {
            self.lost = true;
            return Control::Stop;
        }
        control
    }
}

/// The rounds of TV on the depth map of `x`, each followed by the model-based fit within the
/// windows around the regularized depths; a round whose fit more than doubles the squared
/// residual is undone and ends them. Adds each fit to `report`.
fn tv_rounds<T, A, O>(
    op: &A,
    (m, n): (usize, usize),
    y: &[T],
    x: &mut [T],
    params: &TvDepthParams,
    report: &mut Report,
    observer: &mut O,
) -> Result<()>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    let ks = op.column_len();
    // λ and the windows in bins, the depths in columns.
    let per_bin = op.columns_per_bin();
    let tv = TvParams {
        lambda: params.lambda * per_bin as f64,
        ..params.tv
    };
    let windowed = ModelBasedParams {
        explore_iterations: 0,
        ..params.model
    };
    let mut before = x.to_vec();
    let mut fit_before = residual_norm_sq(op, y, x);
    let y2 = crate::linalg::dot(y, y);
    let space = op.space();
    for _ in 0..params.rounds {
        let found = column_peaks(x, ks, PeakRule::LargestPositive);
        let amax = space::max(
            space,
            found.iter().flatten().map(|p| p.1).fold(0.0, f64::max),
        );
        if amax == 0.0 {
            break;
        }
        let centre = regularized_depths(space, &found, amax, (m, n), ks, &tv)?;
        let windows: Vec<(usize, usize)> = centre
            .iter()
            .map(|&c| {
                (
                    c.saturating_sub(params.window * per_bin),
                    (c + params.window * per_bin).min(ks - 1),
                )
            })
            .collect();
        if params.model.amp.is_some() {
            x.fill(T::zero());
        } else {
            // Move each reflector to its regularized depth unless its own depth is in the
            // window.
            for (p, found) in found.iter().enumerate() {
                if let Some((d, a)) = *found {
                    let (lo, hi) = windows[p];
                    if d < lo || d > hi {
                        x[p * ks + d] = T::zero();
                        x[p * ks + centre[p]] = T::of_f64(a);
                    }
                }
            }
        }
        // The windows are a heuristic: a windowed fit that lost what the previous one had found
        // (more than doubling the squared residual) is undone. Smaller increases are expected
        // in noise, where dropping false detections leaves more of the noise unexplained.
        let mut watch = Losing {
            observer: &mut *observer,
            bar: (LOST * fit_before / y2).sqrt(),
            last: f64::INFINITY,
            lost: false,
        };
        let r = model_based_windowed(
            op,
            y,
            x,
            &windowed,
            Some(&windows),
            Some((m, n)),
            &mut watch,
        )?;
        let termination = report.termination;
        report.absorb(r);
        let fit = if watch.lost {
            // Ended by the watch: the iterations and applications count, the ending is the
            // previous fit's.
            report.termination = termination;
            f64::INFINITY
        } else {
            residual_norm_sq(op, y, x)
        };
        if fit > LOST * fit_before {
            x.copy_from_slice(&before);
            break;
        }
        before.copy_from_slice(x);
        fit_before = fit;
    }
    Ok(())
}
