//! Model-based recovery with at most k reflectors per pixel, one by default (model-based CoSaMP
//! with an adaptive support size).

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::linalg::dot;
use crate::operator::{Counted, LinearOperator};
use crate::real::Real;

use super::amp::{reflector_amp_constrained, ReflectorAmpParams};
use super::PixelConstraints;
use crate::operator::{check_pixels, VoxelOperator};
use crate::solver::{cgls, check_problem, check_tolerance, CglsParams, Monitor, Observer, Report};
use crate::solver::{Stopping, Termination};

/// Parameters of [`model_based`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelBasedParams {
    /// Returns per pixel at most (k, default 1: one reflector per pixel). With k > 1 each
    /// iteration picks a pixel's returns one at a time, each judged on the pixel's correlations
    /// with the ones picked before taken out, and keeps a further return only when it is
    /// significant ([`detection_z`](Self::detection_z), or already held).
    pub max_returns: usize,
    /// Reflectivities are nonnegative: depths are chosen by the largest signed correlation and
    /// pixels whose least-squares amplitude is not positive are dropped (default `true`).
    pub nonnegative: bool,
    /// Exploration: the first iterations put every pixel with a positive best correlation in
    /// the support (within the budget). Least squares then gives each lit pixel at least about
    /// half its amplitude even at a wrong depth (a pixel's columns overlap by half for a 0/1
    /// pulse), so that the amplitude test at the end of the exploration separates lit from empty
    /// pixels even when cross-talk hides the depths (default 3; 0 skips the exploration).
    pub explore_iterations: usize,
    /// After the exploration, a pixel outside the support joins it when its best correlation is
    /// at least this many robust standard deviations (1.4826·MAD) of all correlations: a maximum
    /// over the pixel's depths, hence a high bar (default 4).
    pub detection_z: f64,
    /// A pixel stays in the support when its least-squares amplitude is at least this many
    /// standard errors σ_r/(‖a‖·√(1 − |S|/K)) (σ_r² = ‖r‖²/(K − |S|), ‖a‖ its column's norm, the
    /// square root the variance inflation of least squares on |S| of K measurements, bounded at
    /// √0.05) (default 3).
    pub amplitude_z: f64,
    /// The test of the final support, once, with the same standard errors: a return stays when
    /// its amplitude is at least this many, and the rest is refitted (default 3.7). An empty
    /// pixel offers the best of its K_s depths, so its chance of passing in noise is about
    /// K_s·Q(z): 0.4% for K_s = 40 at z = 3.7.
    pub final_z: f64,
    /// The support holds at most this fraction of the number of measurements, keeping the
    /// least-squares step overdetermined (in (0, 1], default 0.8).
    pub max_support_fraction: f64,
    /// The residual's standard deviation in the amplitude test is taken as at least this
    /// fraction of the measurements' RMS, so that noise-free runs drop the round-off amplitudes
    /// that least squares leaves on empty pixels: it bounds the dynamic range (default 1e-4).
    pub noise_floor: f64,
    /// The least-squares step on the support (CGLS on the restricted operator, warm-started).
    pub inner: CglsParams,
    /// Without a warm start, the first support comes from message passing with the
    /// one-reflector prior ([`reflector_amp`](super::reflector_amp)), and the exploration is
    /// skipped; `None` starts from the exploration instead (default: AMP with its defaults, but
    /// stopping once its support has been stable for 3 iterations).
    pub amp: Option<ReflectorAmpParams>,
    /// Stopping rules; the residual is ‖Ax − y‖ / ‖y‖.
    pub stopping: Stopping,
}

impl Default for ModelBasedParams {
    fn default() -> Self {
        ModelBasedParams {
            max_returns: 1,
            nonnegative: true,
            explore_iterations: 3,
            detection_z: 4.0,
            amplitude_z: 3.0,
            final_z: 3.7,
            noise_floor: 1e-4,
            max_support_fraction: 0.8,
            amp: Some(ReflectorAmpParams {
                stable_support: Some(3),
                ..ReflectorAmpParams::default()
            }),
            inner: CglsParams {
                damp: 0.0,
                stopping: Stopping {
                    max_iter: 10,
                    rel_residual: Some(1e-6),
                    ..Stopping::default()
                },
            },
            stopping: Stopping {
                max_iter: 100,
                rel_residual: Some(1e-6),
                ..Stopping::default()
            },
        }
    }
}

impl ModelBasedParams {
    /// Checks every setting that needs no operator.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the setting.
    pub fn validate(&self) -> Result<()> {
        self.stopping.validate()?;
        self.inner.stopping.validate()?;
        if let Some(a) = &self.amp {
            a.validate()?;
        }
        if self.max_returns == 0 {
            return Err(Error::param("max_returns", "must be at least 1"));
        }
        check_tolerance("detection_z", self.detection_z)?;
        check_tolerance("amplitude_z", self.amplitude_z)?;
        check_tolerance("final_z", self.final_z)?;
        check_tolerance("noise_floor", self.noise_floor)?;
        if !(self.max_support_fraction > 0.0 && self.max_support_fraction <= 1.0) {
            return Err(Error::param(
                "max_support_fraction",
                format!("must be in (0, 1], got {}", self.max_support_fraction),
            ));
        }
        if !(self.inner.damp.is_finite() && self.inner.damp >= 0.0) {
            return Err(Error::param(
                "inner.damp",
                format!("must be finite and ≥ 0, got {}", self.inner.damp),
            ));
        }
        Ok(())
    }
}

/// 1.4826 · median |u|: a robust standard deviation of the correlations, dominated by the empty
/// voxels.
fn robust_sigma<T: Real>(u: &[T]) -> f64 {
    let mut a: Vec<f64> = u.iter().map(|v| v.as_f64()).collect();
    crate::linalg::robust_sigma(&mut a, 0.0)
}

/// Counts applications: of the full operator (message passing, correlations) and of operators
/// restricted to the support (least-squares steps).
#[derive(Default)]
struct Applies {
    forward: usize,
    adjoint: usize,
    support: usize,
}

/// y − A_S b for the restriction `restricted` of the operator to a support.
fn support_residual<T: Real>(restricted: &dyn LinearOperator<T>, y: &[T], b: &[T]) -> Vec<T> {
    let mut r = vec![T::zero(); y.len()];
    if !b.is_empty() {
        restricted.apply(b, &mut r);
    }
    for (ri, &yi) in r.iter_mut().zip(y) {
        *ri = yi - *ri;
    }
    r
}

/// Least squares on the support `voxels`, warm-started from `b`; returns the residual y − A_S b.
fn fit<T, A>(
    op: &A,
    voxels: &[usize],
    y: &[T],
    b: &mut [T],
    inner: &CglsParams,
    applies: &mut Applies,
    it: usize,
) -> Result<Vec<T>>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
{
    const NAME: &str = "model-based";
    let restricted = op.restrict_columns(voxels.to_vec())?;
    if !voxels.is_empty() {
        let rep = cgls(&restricted, y, b, inner, &mut ()).map_err(|e| match e {
            Error::Breakdown { reason, .. } => Error::Breakdown {
                solver: NAME,
                reason: format!("least squares at iteration {it}: {reason}"),
            },
            other => other,
        })?;
        applies.support += rep.forward_applies + 1 + rep.adjoint_applies;
    }
    Ok(support_residual(restricted.as_ref(), y, b))
}

/// y − A_S b.
fn residual<T, A>(
    op: &A,
    voxels: &[usize],
    y: &[T],
    b: &[T],
    applies: &mut Applies,
) -> Result<Vec<T>>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
{
    applies.support += usize::from(!voxels.is_empty());
    Ok(support_residual(
        op.restrict_columns(voxels.to_vec())?.as_ref(),
        y,
        b,
    ))
}

/// Keeps the rows of `v` (rows of `width` entries) whose flag in `keep` is set.
fn retain_rows<U: Copy>(v: &mut Vec<U>, keep: &[bool], width: usize) {
    *v = v
        .chunks(width)
        .zip(keep)
        .filter(|(_, k)| **k)
        .flat_map(|(row, _)| row.iter().copied())
        .collect();
}

/// Keeps the supported voxels marked in `keep`, with their amplitudes and their rows of
/// `ks` self-correlations.
fn retain_support<T: Copy>(
    keep: &[bool],
    voxels: &mut Vec<usize>,
    amp: &mut Vec<T>,
    own: &mut Vec<f64>,
    ks: usize,
) {
    retain_rows(voxels, keep, 1);
    retain_rows(amp, keep, 1);
    retain_rows(own, keep, ks);
}

/// Recovers a scene with at most [`max_returns`](ModelBasedParams::max_returns) nonzeros per
/// pixel, one by default (a pixel is `column_len` consecutive unknowns: one reflector per lidar
/// pixel, empty pixels allowed) from y ≈ Ax, starting from `x`.
///
/// Model-based CoSaMP (Baraniuk et al. 2010) with the k-reflectors-per-pixel model and a support
/// size found from the data. Each iteration
///
/// 1. correlates the residual r = y − Ax with every column ([`VoxelOperator::correlate`]: one
///    adjoint application; the lidar operator uses the zero-mean pulse, whose per-pixel Gram
///    block is nearly diagonal);
/// 2. merges the candidates with the current support pixel by pixel: it adds each supported
///    pixel's own reflector back to that pixel's correlations
///    ([`VoxelOperator::self_correlations`]), so that every depth of the pixel, the current one
///    and the new candidates, is judged against the same residual of the *other* pixels;
/// 3. prunes to the model: per pixel the depth with the largest correlation, kept when it is
///    significant (at least [`detection_z`](ModelBasedParams::detection_z) robust standard
///    deviations of all correlations, which measure the cross-talk left and the noise), within a
///    support budget; with k > 1, up to k − 1 further depths, one at a time, each the largest
///    correlation once the returns picked before are taken out of the pixel's correlations
///    (matching pursuit within the pixel), kept when significant or already held;
/// 4. solves least squares on the new support by [`cgls`] on the restricted operator
///    ([`LinearOperator::restrict_columns`]: for the lidar operator O(support × K_p) per application,
///    never the full cube), warm-started, and drops pixels whose amplitude is not positive
///    (nonnegative scenes).
///
/// As the support fills, the residual and with it the cross-talk shrink, so weaker pixels become
/// detectable and wrong depths are corrected: the iteration stops with
/// [`Termination::Converged`] when an iteration leaves the support unchanged, with
/// [`Termination::ZeroResidual`] for y = 0, otherwise by the [`Stopping`] rules (residual
/// ‖Ax − y‖ / ‖y‖). The report counts the restricted applications as support applications.
///
/// # Errors
/// [`Error::InvalidParameter`] for invalid parameters; [`Error::ShapeMismatch`] /
/// [`Error::NonFinite`] for inputs that do not fit the operator or are not finite;
/// [`Error::Breakdown`] if a least-squares step breaks down.
pub fn model_based<T, A, O>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &ModelBasedParams,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    model_based_windowed(op, y, x, params, None, observer)
}

/// [`model_based`] with each pixel's depth restricted to a window `lo..=hi` of its depths
/// (`windows[p] = (lo, hi)`), as the TV-on-depth solver uses it.
pub(crate) fn model_based_windowed<T, A, O>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &ModelBasedParams,
    windows: Option<&[(usize, usize)]>,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    const NAME: &str = "model-based";
    params.validate()?;
    let (m, n) = (op.nrows(), op.ncols());
    check_problem(NAME, m, n, y, x)?;
    let ks = op.column_len();
    check_pixels(NAME, n, ks, windows)?;
    let counted = Counted::new(op);
    let mut applies = Applies::default();
    let mut monitor = Monitor::new(NAME, params.stopping, observer);
    let ynorm = dot(y, y).sqrt();
    if ynorm == 0.0 {
        x.fill(T::zero());
        return Ok(monitor.finish(0, Termination::ZeroResidual, &counted));
    }
    let budget = ((params.max_support_fraction * m as f64) as usize).max(1);
    let score = |v: f64| if params.nonnegative { v } else { v.abs() };
    // The amplitude test: which voxels of a support have a least-squares amplitude of at least
    // `z` standard errors, inflated for least squares on |S| of K measurements.
    let significant = |voxels: &[usize], amp: &[T], r: &[T], z: f64| {
        let dof = m.saturating_sub(voxels.len()).max(1);
        let sigma_r = (dot(r, r) / dof as f64)
            .sqrt()
            .max(params.noise_floor * ynorm / (m as f64).sqrt());
        let inflation = 1.0 / (1.0 - voxels.len() as f64 / m as f64).max(0.05).sqrt();
        let norms = op.column_norms(voxels);
        amp.iter()
            .zip(&norms)
            .map(|(a, c)| score(a.as_f64()) * c >= z * inflation * sigma_r)
            .collect::<Vec<bool>>()
    };

    // Without a warm start, message passing proposes the first support.
    let mut explore_iterations = params.explore_iterations;
    if let Some(amp_params) = &params.amp {
        if x.iter().all(|v| *v == T::zero()) {
            let constraints = PixelConstraints {
                windows,
                ..PixelConstraints::default()
            };
            let (rep, ..) = reflector_amp_constrained(op, y, x, amp_params, constraints, &mut ())?;
            applies.forward += rep.forward_applies;
            applies.adjoint += rep.adjoint_applies;
            explore_iterations = 0;
        }
    }

    // The warm start, pruned to the model (per pixel its largest entries) and re-fitted.
    let mut voxels: Vec<usize> = x
        .par_chunks(ks)
        .enumerate()
        .flat_map_iter(|(p, col)| {
            let mut held: Vec<(usize, f64)> = col
                .iter()
                .enumerate()
                .map(|(j, v)| (j, score(v.as_f64())))
                .filter(|c| c.1 > 0.0)
                .collect();
            held.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            held.truncate(params.max_returns);
            let mut kept: Vec<usize> = held.iter().map(|h| p * ks + h.0).collect();
            kept.sort_unstable();
            kept
        })
        .collect();
    let mut amp: Vec<T> = voxels.iter().map(|&v| x[v]).collect();
    // Each supported pixel's Gram row (its own reflector's correlations), kept with the support.
    let mut own = op.self_correlations(&voxels);
    let mut r = fit(op, &voxels, y, &mut amp, &params.inner, &mut applies, 0)?;
    let mut u = vec![T::zero(); n];
    let mut prev = x.to_vec();
    // With several returns per pixel, the Gram rows that take a picked return out of its pixel's
    // correlations: computed once when every pixel has the same ones.
    let shared_rows = (params.max_returns > 1 && op.uniform_pixel_gram())
        .then(|| op.self_correlations(&(0..ks).collect::<Vec<_>>()));
    let mut it = 0;
    loop {
        it += 1;
        op.correlate(&r, &mut u);
        applies.adjoint += 1;
        let sigma = robust_sigma(&u);
        let explore = it <= explore_iterations;
        // Each supported pixel's own reflectors are added back to its correlations.
        let mut first = vec![usize::MAX; n / ks];
        for (i, &v) in voxels.iter().enumerate().rev() {
            first[v / ks] = i;
        }
        let own_of = |i: usize| &own[i * ks..(i + 1) * ks];
        let mut picks: Vec<(usize, f64, f64)> = u
            .par_chunks(ks)
            .enumerate()
            .flat_map_iter(|(p, col)| {
                let (lo, hi) = windows.map_or((0, ks - 1), |w| w[p]);
                let mut v: Vec<f64> = col.iter().map(|c| c.as_f64()).collect();
                let supported = (first[p]..voxels.len())
                    .take_while(|&i| first[p] != usize::MAX && voxels[i] / ks == p);
                for i in supported.clone() {
                    for (vj, o) in v.iter_mut().zip(own_of(i)) {
                        *vj += amp[i].as_f64() * o;
                    }
                }
                let mut found = Vec::new();
                for rank in 0..params.max_returns {
                    let best = (lo..=hi)
                        .map(|j| (j, score(v[j]), v[j]))
                        .filter(|b| {
                            !found
                                .iter()
                                .any(|f: &(usize, f64, f64)| f.0 == p * ks + b.0)
                        })
                        .fold(
                            (0, f64::NEG_INFINITY, 0.0),
                            |b, c| if c.1 > b.1 { c } else { b },
                        );
                    let held = supported.clone().any(|i| voxels[i] == p * ks + best.0);
                    let lenient =
                        explore || sigma == 0.0 || held || rank == 0 && first[p] != usize::MAX;
                    let join = if lenient {
                        best.1 > 0.0
                    } else {
                        best.1 >= params.detection_z * sigma
                    };
                    if !join {
                        break;
                    }
                    found.push((p * ks + best.0, best.1, best.2));
                    if rank + 1 < params.max_returns {
                        // The next return is judged with this one's contribution taken out.
                        let row: std::borrow::Cow<'_, [f64]> = match &shared_rows {
                            Some(rows) => rows[best.0 * ks..(best.0 + 1) * ks].into(),
                            None => op.self_correlations(&[p * ks + best.0]).into(),
                        };
                        let d = row[best.0];
                        if d > 0.0 {
                            for (vj, o) in v.iter_mut().zip(row.iter()) {
                                *vj -= best.2 / d * o;
                            }
                        }
                    }
                }
                found.sort_by_key(|f| f.0);
                found
            })
            .collect();
        if picks.len() > budget {
            picks.sort_by(|a, b| b.1.total_cmp(&a.1));
            picks.truncate(budget);
            picks.sort_by_key(|p| p.0);
        }
        // Amplitudes to start the least squares from: kept where the depth is unchanged, the
        // correlation over the pixel's own diagonal Gram entry elsewhere.
        let mut new_voxels: Vec<usize> = picks.iter().map(|p| p.0).collect();
        let mut new_own = op.self_correlations(&new_voxels);
        let mut new_amp: Vec<T> = picks
            .iter()
            .enumerate()
            .map(|(i, &(v, _, c))| match voxels.binary_search(&v) {
                Ok(k) => amp[k],
                Err(_) => {
                    let d = new_own[i * ks + v % ks];
                    T::of_f64(if d > 0.0 { c / d } else { 0.0 })
                }
            })
            .collect();
        // Least squares on the support, warm-started from `amp`, giving the residual.
        let refit = |voxels: &[usize], amp: &mut [T], applies: &mut Applies| {
            fit(op, voxels, y, amp, &params.inner, applies, it)
        };
        r = refit(&new_voxels, &mut new_amp, &mut applies)?;
        if params.nonnegative && new_amp.iter().any(|a| *a <= T::zero()) {
            // Drop the pixels whose amplitude came out non-positive; their depth is re-judged
            // at the next iteration against the residual without them.
            let keep: Vec<bool> = new_amp.iter().map(|a| *a > T::zero()).collect();
            retain_support(&keep, &mut new_voxels, &mut new_amp, &mut new_own, ks);
            r = residual(op, &new_voxels, y, &new_amp, &mut applies)?;
        }
        let rel = (dot(&r, &r)).sqrt() / ynorm;
        if it >= explore_iterations || params.stopping.rel_residual.is_some_and(|t| rel <= t) {
            // The amplitude test, then least squares on what remains.
            let keep = significant(&new_voxels, &new_amp, &r, params.amplitude_z);
            if keep.iter().any(|k| !k) {
                retain_support(&keep, &mut new_voxels, &mut new_amp, &mut new_own, ks);
                r = refit(&new_voxels, &mut new_amp, &mut applies)?;
            }
        }

        let same = new_voxels == voxels;
        voxels = new_voxels;
        amp = new_amp;
        own = new_own;
        x.fill(T::zero());
        for (&v, &a) in voxels.iter().zip(&amp) {
            x[v] = a;
        }
        let rr = dot(&r, &r);
        if !rr.is_finite() || amp.iter().any(|v| !v.is_finite()) {
            return Err(Error::Breakdown {
                solver: NAME,
                reason: format!("non-finite values at iteration {it}"),
            });
        }
        let change = crate::solver::relative_change(x, &prev);
        prev.copy_from_slice(x);
        let stop = monitor.step(it, rr.sqrt() / ynorm, 0.5 * rr, change, x);
        let term = match stop {
            Some(Termination::MaxIterations) | None if same && !explore => {
                Some(Termination::Converged)
            }
            other => other,
        };
        if let Some(t) = term {
            // The final test, stricter and with the variance inflation; applied once, as a
            // support refitted after it could not be re-tested without drifting (each pass
            // raising σ_r and dropping more).
            let keep = significant(&voxels, &amp, &r, params.final_z);
            if keep.iter().any(|k| !k) {
                retain_support(&keep, &mut voxels, &mut amp, &mut own, ks);
                fit(op, &voxels, y, &mut amp, &params.inner, &mut applies, it)?;
                x.fill(T::zero());
                for (&v, &a) in voxels.iter().zip(&amp) {
                    x[v] = a;
                }
            }
            let mut report = monitor.finish(it, t, &counted);
            report.forward_applies += applies.forward;
            report.adjoint_applies += applies.adjoint;
            report.support_applies += applies.support;
            return Ok(report);
        }
    }
}
