//! Model-based recovery with at most k reflectors per pixel, one by default (model-based CoSaMP
//! with an adaptive support size).

use std::collections::HashMap;
use std::ops::ControlFlow;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::linalg::dot;
use crate::operator::{check_pixels, VoxelOperator};
use crate::real::Real;
use crate::solver::{
    check_problem, solve, Iteration, Iterative, Observer, Progress, Report, Stopping, Termination,
};
use crate::space::{self, Space};

use super::amp::reflector_amp_constrained;
use super::surface::{on_surface, surface_depths, SurfaceRule};
use super::PixelConstraints;

mod least_squares;
mod params;
use least_squares::fit;
pub(super) use least_squares::residual;
pub use params::ModelBasedParams;

/// 1.4826 · median |u| over the whole of the unknowns: a robust standard deviation of the
/// correlations, dominated by the empty voxels.
fn robust_sigma<T: Real>(space: &dyn Space, u: &[T]) -> f64 {
    let mut a: Vec<f64> = u.iter().map(|v| v.as_f64()).collect();
    space::robust_sigma(space, &mut a, 0.0)
}

/// A warm start whose least squares leaves at most this fraction of ‖y‖ has found the support
/// (one pixel of the 144 lit pixels of a 16×16 scene carries about 8% of ‖y‖, of the 5547 of the
/// 100×100 paper scene 1.3%): the exploration ([`ModelBasedParams::explore_iterations`]), which
/// puts every pixel with a positive correlation in the support, is skipped.
const FOUND: f64 = 1e-3;

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
/// [`Termination::Converged`] when an iteration leaves the support unchanged and its least
/// squares no longer halves the residual (an ill-conditioned support needs more than one refit's
/// inner iterations: those iterations go on, and the correlations confirm the support), with
/// [`Termination::ZeroResidual`] for y = 0, otherwise by the [`Stopping`] rules (residual
/// ‖Ax − y‖ / ‖y‖). A warm start whose least squares (the model's largest entries of `x`,
/// refitted) already meets the residual tolerance ends the run before its first iteration, with
/// [`Termination::Residual`] and no correlation; the final amplitude test still runs. The report
/// counts the restricted applications as support applications.
///
/// # Errors
/// [`Error::InvalidParameter`] for invalid parameters; [`Error::ShapeMismatch`] /
/// [`Error::NonFinite`] for inputs that do not fit the operator or are not finite;
/// [`Error::Breakdown`] if a least-squares step breaks down.
///
/// [`cgls`]: crate::solver::cgls
/// [`LinearOperator::restrict_columns`]: crate::operator::LinearOperator::restrict_columns
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
    model_based_windowed(op, y, x, params, None, None, observer)
}

/// [`model_based`] with each pixel's depth restricted to a window `lo..=hi` of its depths
/// (`windows[p] = (lo, hi)`), as the TV-on-depth solver uses it; with the pixels' `grid`
/// (this part's rows, N) known, the detections follow the surface rule
/// ([`ModelBasedParams::surface_z`]) when the model has one return per pixel.
pub(crate) fn model_based_windowed<T, A, O>(
    op: &A,
    y: &[T],
    x: &mut [T],
    params: &ModelBasedParams,
    windows: Option<&[(usize, usize)]>,
    grid: Option<(usize, usize)>,
    observer: &mut O,
) -> Result<Report>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
    O: Observer<T> + ?Sized,
{
    let surface = grid
        .filter(|_| params.max_returns == 1 && params.surface_neighbours > 0)
        .map(|grid| SurfaceRule {
            grid,
            z: params.surface_z,
            neighbours: params.surface_neighbours,
            join: params.join_neighbours,
            isolated_z: params.isolated_z,
        });
    let setup = ModelBasedSetup {
        params: *params,
        windows,
        surface,
    };
    solve::<T, A, O, ModelBasedIteration<'_, T>>(op, y, x, &setup, observer)
}

/// What a model-based run is given: its parameters and the depth windows.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ModelBasedSetup<'w> {
    params: ModelBasedParams,
    windows: Option<&'w [(usize, usize)]>,
    surface: Option<SurfaceRule>,
}

/// The state of model-based recovery between iterations: the support (voxels, amplitudes and
/// their self-correlations) and its residual.
pub(crate) struct ModelBasedIteration<'w, T> {
    params: ModelBasedParams,
    windows: Option<&'w [(usize, usize)]>,
    surface: Option<SurfaceRule>,
    ks: usize,
    ynorm: f64,
    /// The largest support.
    budget: usize,
    /// Iterations of exploration (none after a start from message passing).
    explore_iterations: usize,
    /// The supported voxels, increasing; their amplitudes; and each one's row of
    /// self-correlations (its own reflector's correlations with its pixel's columns).
    voxels: Vec<usize>,
    amp: Vec<T>,
    own: Vec<f64>,
    /// y − Ax.
    r: Vec<T>,
    /// ‖y − Ax‖² at the end of the previous iteration (or of the start).
    rr: f64,
    /// The correlations of the residual.
    u: Vec<T>,
    prev: Vec<T>,
    /// With several returns per pixel, the rows that take a picked return out of its pixel's
    /// correlations, when every pixel has the same ones.
    shared_rows: Option<Vec<f64>>,
    /// Under the surface rule, how often each voxel has left the support (by the amplitude test,
    /// a non-positive amplitude or its pixel's new depth): after [`LEAVES`] times the rule does
    /// not let it join again (only the plain detection test does), so that joining on its lower
    /// bar and leaving cannot cycle.
    dropped: HashMap<usize, usize>,
    /// The last iteration (for messages).
    it: usize,
}

/// How often a voxel may leave the support before the surface rule stops offering it.
const LEAVES: usize = 2;

/// An unchanged support ends the run only once an iteration's least squares no longer lowers
/// the squared residual below this fraction of the previous iteration's (a residual halved).
/// Ill-conditioned supports (every pixel lit at one depth, three measurements per pixel: CGLS
/// gains a factor of about 0.8–0.9 per iteration) need more inner iterations than one refit gives;
/// under noise the residual levels off at the noise within a refit or two and the run ends as
/// before.
const STILL_FALLING: f64 = 0.25;

impl<'w, T: Real> Iterative<T> for ModelBasedIteration<'w, T> {
    const NAME: &'static str = "model-based";
    type Params = ModelBasedSetup<'w>;

    fn stopping(setup: &ModelBasedSetup<'w>) -> Stopping {
        setup.params.stopping
    }

    fn check_params(setup: &ModelBasedSetup<'w>) -> Result<()> {
        setup.params.validate()
    }
}

impl<'w, T: Real> ModelBasedIteration<'w, T> {
    /// A pixel's score: its signed correlation for nonnegative scenes, its magnitude otherwise.
    fn score(&self, v: f64) -> f64 {
        if self.params.nonnegative {
            v
        } else {
            v.abs()
        }
    }

    /// Each voxel's least-squares amplitude in standard errors σ_r/(‖a‖·√(1 − |S|/K)), for the
    /// residual `self.r` of the support `voxels`.
    fn z_scores<A: VoxelOperator<T> + ?Sized>(
        &self,
        op: &A,
        voxels: &[usize],
        amp: &[T],
    ) -> Vec<f64> {
        let m = self.r.len();
        let held = space::count(op.space(), voxels.len());
        let dof = m.saturating_sub(held).max(1);
        let sigma_r = (dot(&self.r, &self.r) / dof as f64)
            .sqrt()
            .max(self.params.noise_floor * self.ynorm / (m as f64).sqrt());
        let inflation = 1.0 / (1.0 - held as f64 / m as f64).max(0.05).sqrt();
        let bar = inflation * sigma_r;
        let norms = op.column_norms(voxels);
        amp.iter()
            .zip(&norms)
            .map(|(a, c)| self.score(a.as_f64()) * c / bar)
            .collect()
    }

    /// The amplitude test: which voxels of a support have a least-squares amplitude of at least
    /// `z` standard errors, inflated for least squares on |S| of K measurements (or, under the
    /// surface rule, at least its lower bar with enough neighbours that pass it too).
    fn significant<A: VoxelOperator<T> + ?Sized>(
        &self,
        op: &A,
        voxels: &[usize],
        amp: &[T],
        (z, last): (f64, bool),
    ) -> Vec<bool> {
        let stat = self.z_scores(op, voxels, amp);
        let mut keep: Vec<bool> = stat.iter().map(|s| *s >= z).collect();
        if let Some(rule) = self.surface {
            let lenient: Vec<bool> = stat.iter().map(|s| *s >= rule.z).collect();
            let near = on_surface(
                op.space(),
                rule.grid,
                self.ks,
                voxels,
                &lenient,
                op.columns_per_bin(),
            );
            for (((k, l), &count), s) in keep.iter_mut().zip(&lenient).zip(&near).zip(&stat) {
                *k |= *l && count >= rule.neighbours;
                if last && count == 0 && *s < rule.isolated_z {
                    *k = false;
                }
            }
        }
        keep
    }

    /// The warm start `x` pruned to the model: per pixel its largest entries.
    fn pruned(&self, x: &[T]) -> Vec<usize> {
        let (ks, max_returns) = (self.ks, self.params.max_returns);
        x.par_chunks(ks)
            .enumerate()
            .flat_map_iter(|(p, col)| {
                let mut held: Vec<(usize, f64)> = col
                    .iter()
                    .enumerate()
                    .map(|(j, v)| (j, self.score(v.as_f64())))
                    .filter(|c| c.1 > 0.0)
                    .collect();
                held.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
                held.truncate(max_returns);
                let mut kept: Vec<usize> = held.iter().map(|h| p * ks + h.0).collect();
                kept.sort_unstable();
                kept
            })
            .collect()
    }

    /// Pixel `p`'s picks (voxel, score, correlation) from its correlations `col` with its own
    /// reflectors added back: up to `max_returns`, each judged with the ones before taken out;
    /// under the surface rule, a pixel whose best depth falls short joins within one bin of the
    /// `surface` its neighbours form when its correlation there reaches the rule's bar.
    fn pixel_picks<A: VoxelOperator<T> + ?Sized>(
        &self,
        op: &A,
        p: usize,
        col: &[T],
        first: usize,
        (sigma, explore): (f64, bool),
        surface: Option<usize>,
    ) -> Vec<(usize, f64, f64)> {
        let ks = self.ks;
        let (lo, hi) = self.windows.map_or((0, ks - 1), |w| w[p]);
        let mut v: Vec<f64> = col.iter().map(|c| c.as_f64()).collect();
        let supported = (first..self.voxels.len())
            .take_while(|&i| first != usize::MAX && self.voxels[i] / ks == p);
        for i in supported.clone() {
            for (vj, o) in v.iter_mut().zip(&self.own[i * ks..(i + 1) * ks]) {
                *vj += self.amp[i].as_f64() * o;
            }
        }
        let mut found: Vec<(usize, f64, f64)> = Vec::new();
        for rank in 0..self.params.max_returns {
            let mut best = (lo..=hi)
                .map(|j| (j, self.score(v[j]), v[j]))
                .filter(|b| !found.iter().any(|f| f.0 == p * ks + b.0))
                .fold(
                    (0, f64::NEG_INFINITY, 0.0),
                    |b, c| if c.1 > b.1 { c } else { b },
                );
            let held = supported.clone().any(|i| self.voxels[i] == p * ks + best.0);
            let lenient = explore || sigma == 0.0 || held || rank == 0 && first != usize::MAX;
            let mut join = if lenient {
                best.1 > 0.0
            } else {
                best.1 >= self.params.detection_z * sigma
            };
            // The surface rule: a pixel that continues its neighbours' surface joins at a
            // depth within one bin of it on a lower bar.
            if let (false, 0, Some(c), Some(rule)) = (join, rank, surface, self.surface) {
                let (a, b) = (c.saturating_sub(1).max(lo), (c + 1).min(hi));
                let on = (a..=b).map(|j| (j, self.score(v[j]), v[j])).fold(
                    (0, f64::NEG_INFINITY, 0.0),
                    |b, c| if c.1 > b.1 { c } else { b },
                );
                if a <= b
                    && on.1 >= rule.z * sigma
                    && self
                        .dropped
                        .get(&(p * ks + on.0))
                        .is_none_or(|&n| n < LEAVES)
                {
                    (best, join) = (on, true);
                }
            }
            if !join {
                break;
            }
            found.push((p * ks + best.0, best.1, best.2));
            if rank + 1 < self.params.max_returns {
                // The next return is judged with this one's contribution taken out.
                let row: std::borrow::Cow<'_, [f64]> = match &self.shared_rows {
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
    }

    /// Every pixel's picks from the correlations `self.u`, within the support budget.
    fn picks<A: VoxelOperator<T> + ?Sized>(
        &self,
        op: &A,
        sigma: f64,
        explore: bool,
    ) -> Vec<(usize, f64, f64)> {
        let ks = self.ks;
        let mut first = vec![usize::MAX; self.u.len() / ks];
        for (i, &v) in self.voxels.iter().enumerate().rev() {
            first[v / ks] = i;
        }
        // Surfaces grow from the returns that pass the final test.
        let surface = match self.surface {
            Some(rule) if !explore => {
                let strong: Vec<bool> = self
                    .z_scores(op, &self.voxels, &self.amp)
                    .iter()
                    .map(|z| *z >= self.params.final_z)
                    .collect();
                surface_depths(
                    op.space(),
                    rule.grid,
                    ks,
                    &self.voxels,
                    &strong,
                    rule.join,
                    op.columns_per_bin(),
                )
            }
            _ => vec![None; first.len()],
        };
        let mut picks: Vec<(usize, f64, f64)> = self
            .u
            .par_chunks(ks)
            .enumerate()
            .flat_map_iter(|(p, col)| {
                self.pixel_picks(op, p, col, first[p], (sigma, explore), surface[p])
            })
            .collect();
        let space = op.space();
        if space::count(space, picks.len()) > self.budget {
            // The strongest within the budget, the lower voxel first among equals.
            let scores: Vec<f64> = picks.iter().map(|p| p.1).collect();
            let keep = space::largest_by(space, &scores, self.budget);
            picks = keep.into_iter().map(|i| picks[i]).collect();
        }
        picks
    }

    /// Least squares on `voxels`, warm-started from `amp`; the residual becomes its residual.
    fn refit<A: VoxelOperator<T> + ?Sized>(
        &mut self,
        op: &A,
        y: &[T],
        voxels: &[usize],
        amp: &mut [T],
    ) -> Result<()> {
        let goal = (self.ynorm, self.params.stopping.rel_residual);
        self.r = fit(op, voxels, y, amp, &self.params.inner, self.it, goal)?;
        Ok(())
    }

    /// x from the support.
    fn write_scene(&self, x: &mut [T]) {
        x.fill(T::zero());
        for (&v, &a) in self.voxels.iter().zip(&self.amp) {
            x[v] = a;
        }
    }
}

impl<'w, T: Real, A: VoxelOperator<T> + ?Sized> Iteration<T, A> for ModelBasedIteration<'w, T> {
    fn start(
        op: &A,
        y: &[T],
        x: &mut [T],
        setup: &ModelBasedSetup<'w>,
    ) -> Result<ControlFlow<Termination, Self>> {
        let name = <Self as Iterative<T>>::NAME;
        let params = setup.params;
        params.validate()?;
        let (m, n) = (op.nrows(), op.ncols());
        let space = op.space();
        check_problem(name, space, m, n, y, x)?;
        let ks = op.column_len();
        check_pixels(name, n, ks, setup.windows)?;
        let ynorm = dot(y, y).sqrt();
        if ynorm == 0.0 {
            x.fill(T::zero());
            return Ok(ControlFlow::Break(Termination::ZeroResidual));
        }
        // Without a warm start, message passing proposes the first support.
        let mut explore_iterations = params.explore_iterations;
        if let Some(amp_params) = &params.amp {
            if space::all(space, x.iter().all(|v| *v == T::zero())) {
                let constraints = PixelConstraints {
                    windows: setup.windows,
                    ..PixelConstraints::default()
                };
                reflector_amp_constrained(op, y, x, amp_params, constraints, &mut ())?;
                explore_iterations = 0;
            }
        }
        let mut run = ModelBasedIteration {
            params,
            windows: setup.windows,
            surface: setup.surface,
            ks,
            ynorm,
            budget: ((params.max_support_fraction * m as f64) as usize).max(1),
            explore_iterations,
            voxels: Vec::new(),
            amp: Vec::new(),
            own: Vec::new(),
            r: Vec::new(),
            rr: f64::INFINITY,
            u: vec![T::zero(); n],
            prev: x.to_vec(),
            shared_rows: (params.max_returns > 1 && op.uniform_pixel_gram())
                .then(|| op.self_correlations(&(0..ks).collect::<Vec<_>>())),
            dropped: HashMap::new(),
            it: 0,
        };
        // The warm start, pruned to the model and re-fitted.
        let voxels = run.pruned(x);
        let mut amp: Vec<T> = voxels.iter().map(|&v| x[v]).collect();
        run.own = op.self_correlations(&voxels);
        run.refit(op, y, &voxels, &mut amp)?;
        run.voxels = voxels;
        run.amp = amp;
        run.rr = dot(&run.r, &run.r);
        run.write_scene(x);
        if run.rr <= (FOUND * ynorm).powi(2) {
            run.explore_iterations = 0;
        }
        Ok(ControlFlow::Continue(run))
    }

    /// A warm start whose least squares explains the data to the tolerance ends the run before
    /// any correlation (the final test still runs).
    fn prepare(&mut self, _op: &A) -> Option<Termination> {
        let explained = self
            .params
            .stopping
            .rel_residual
            .is_some_and(|t| self.rr <= (t * self.ynorm).powi(2));
        (self.it == 0 && explained).then_some(Termination::Residual)
    }

    fn step(&mut self, op: &A, y: &[T], x: &mut [T], it: usize) -> Result<Progress> {
        let ks = self.ks;
        self.it = it;
        op.correlate(&self.r, &mut self.u);
        let space = op.space();
        let sigma = robust_sigma(space, &self.u);
        let explore = it <= self.explore_iterations;
        let picks = self.picks(op, sigma, explore);
        // Amplitudes to start the least squares from: kept where the depth is unchanged, the
        // correlation over the pixel's own diagonal Gram entry elsewhere.
        let mut new_voxels: Vec<usize> = picks.iter().map(|p| p.0).collect();
        let mut new_own = op.self_correlations(&new_voxels);
        let mut new_amp: Vec<T> = picks
            .iter()
            .enumerate()
            .map(|(i, &(v, _, c))| match self.voxels.binary_search(&v) {
                Ok(k) => self.amp[k],
                Err(_) => {
                    let d = new_own[i * ks + v % ks];
                    T::of_f64(if d > 0.0 { c / d } else { 0.0 })
                }
            })
            .collect();
        // Least squares on the support, warm-started from `amp`, giving the residual.
        self.refit(op, y, &new_voxels, &mut new_amp)?;
        let positive = space::all(space, new_amp.iter().all(|a| *a > T::zero()));
        if self.params.nonnegative && !positive {
            // Drop the pixels whose amplitude came out non-positive; their depth is re-judged
            // at the next iteration against the residual without them.
            let keep: Vec<bool> = new_amp.iter().map(|a| *a > T::zero()).collect();
            retain_support(&keep, &mut new_voxels, &mut new_amp, &mut new_own, ks);
            self.r = residual(op, &new_voxels, y, &new_amp)?;
        }
        let rel = dot(&self.r, &self.r).sqrt() / self.ynorm;
        let explained = self.params.stopping.rel_residual.is_some_and(|t| rel <= t);
        if it >= self.explore_iterations || explained {
            // The amplitude test, then least squares on what remains.
            let keep =
                self.significant(op, &new_voxels, &new_amp, (self.params.amplitude_z, false));
            if !space::all(space, keep.iter().all(|k| *k)) {
                if self.surface.is_some() {
                    // New picks that fail at once (a held voxel's departure is counted below).
                    let gone = new_voxels
                        .iter()
                        .zip(&keep)
                        .filter(|(v, k)| !**k && self.voxels.binary_search(v).is_err());
                    for (&v, _) in gone {
                        *self.dropped.entry(v).or_insert(0) += 1;
                    }
                }
                retain_support(&keep, &mut new_voxels, &mut new_amp, &mut new_own, ks);
                self.refit(op, y, &new_voxels, &mut new_amp)?;
            }
        }

        let same = space::all(space, new_voxels == self.voxels);
        if self.surface.is_some() {
            for &v in self
                .voxels
                .iter()
                .filter(|v| new_voxels.binary_search(v).is_err())
            {
                *self.dropped.entry(v).or_insert(0) += 1;
            }
        }
        self.voxels = new_voxels;
        self.amp = new_amp;
        self.own = new_own;
        self.write_scene(x);
        let rr = dot(&self.r, &self.r);
        if !rr.is_finite() || !space::all(space, self.amp.iter().all(|v| v.is_finite())) {
            return Err(Error::Breakdown {
                solver: <Self as Iterative<T>>::NAME,
                reason: format!("non-finite values at iteration {it}"),
            });
        }
        let change = space::relative_change(space, x, &self.prev);
        self.prev.copy_from_slice(x);
        // An unchanged support whose least squares still lowers the residual fast (its inner
        // iterations ran out before the amplitudes converged) goes on: the next iterations
        // finish the fit, as the correlations confirm the support.
        let settling = rr < STILL_FALLING * self.rr;
        self.rr = rr;
        Ok(Progress {
            ending: (same && !explore && !settling).then_some(Termination::Converged),
            ..Progress::least_squares(rr, self.ynorm, change, false)
        })
    }

    fn objective(&self) -> f64 {
        0.5 * dot(&self.r, &self.r)
    }

    /// The final test, stricter and with the variance inflation; applied once, as a support
    /// refitted after it could not be re-tested without drifting (each pass raising σ_r and
    /// dropping more).
    fn finish(&mut self, op: &A, y: &[T], x: &mut [T], _termination: Termination) -> Result<()> {
        let keep = self.significant(op, &self.voxels, &self.amp, (self.params.final_z, true));
        if !space::all(op.space(), keep.iter().all(|k| *k)) {
            let (mut voxels, mut amp, mut own) = (
                std::mem::take(&mut self.voxels),
                std::mem::take(&mut self.amp),
                std::mem::take(&mut self.own),
            );
            retain_support(&keep, &mut voxels, &mut amp, &mut own, self.ks);
            self.refit(op, y, &voxels, &mut amp)?;
            (self.voxels, self.amp, self.own) = (voxels, amp, own);
            self.write_scene(x);
        }
        Ok(())
    }
}
