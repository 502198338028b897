//! Total variation on the depth map: model-based fits alternated with weighted TV denoising of the
//! depths, for piecewise-smooth scenes.

use ndarray::Array2;

use crate::error::{Error, Result};
use crate::real::Real;

use rayon::prelude::*;

use super::amp::{reflector_amp_run, PixelPriors, Posteriors};
use super::model_based::model_based_in;
use super::{tv_denoise, ModelBasedParams, Observer, Report, Termination, TvParams, VoxelOperator};

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
    /// ([`ModelBasedParams::amp`]): each round runs message passing again with every pixel's prior
    /// built from its neighbours' posteriors (default 4; 0 disables it).
    pub neighbour_rounds: usize,
    /// The neighbourhood: pixels within this many rows and columns (default 2, a 5×5 square).
    pub neighbour_radius: usize,
    /// The share of the uniform depth distribution mixed into each neighbourhood depth prior,
    /// so that no depth is excluded (in (0, 1], default 0.1).
    pub neighbour_floor: f64,
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
            neighbour_rounds: 4,
            neighbour_radius: 2,
            neighbour_floor: 0.1,
            tv: TvParams::new(1.0).expect("a valid λ"),
        }
    }
}

/// The neighbourhood prior of every pixel from the posteriors of the others: its probability of a
/// return halfway between the global rate and its neighbours' mean, and its depth distribution
/// the neighbours' depth posteriors summed, spread over ±1 bin (slanted surfaces), normalized
/// and mixed with `floor` of the uniform distribution. The pixel's own posterior is left out.
fn neighbour_priors(
    post: &Posteriors,
    (m, n): (usize, usize),
    ks: usize,
    radius: usize,
    floor: f64,
) -> PixelPriors {
    let global = post.lit.iter().sum::<f64>() / post.lit.len().max(1) as f64;
    let rows: Vec<(Vec<f64>, Vec<f64>)> = (0..m)
        .into_par_iter()
        .map(|i| {
            let mut lit = Vec::with_capacity(n);
            let mut depth = Vec::with_capacity(n * ks);
            let mut h = vec![0.0; ks];
            for j in 0..n {
                h.fill(0.0);
                let (mut sum_lit, mut count) = (0.0, 0usize);
                for a in i.saturating_sub(radius)..(i + radius + 1).min(m) {
                    for b in j.saturating_sub(radius)..(j + radius + 1).min(n) {
                        if (a, b) == (i, j) {
                            continue;
                        }
                        let q = a * n + b;
                        sum_lit += post.lit[q];
                        count += 1;
                        for (d, &w) in post.depth[q * ks..(q + 1) * ks].iter().enumerate() {
                            h[d] += w;
                            if d > 0 {
                                h[d - 1] += w;
                            }
                            if d + 1 < ks {
                                h[d + 1] += w;
                            }
                        }
                    }
                }
                let near = if count > 0 {
                    sum_lit / count as f64
                } else {
                    global
                };
                lit.push((0.5 * global + 0.5 * near).clamp(0.02, 0.98));
                let total: f64 = h.iter().sum();
                depth.extend(h.iter().map(|&v| {
                    let shaped = if total > 0.0 {
                        v / total
                    } else {
                        1.0 / ks as f64
                    };
                    (1.0 - floor) * shaped + floor / ks as f64
                }));
            }
            (lit, depth)
        })
        .collect();
    let mut priors = PixelPriors {
        lit: Vec::with_capacity(m * n),
        depth: Vec::with_capacity(m * n * ks),
    };
    for (lit, depth) in rows {
        priors.lit.extend(lit);
        priors.depth.extend(depth);
    }
    priors
}

/// Adds the counts and histories of `more` to `report`.
fn absorb(report: &mut Report, more: Report) {
    report.iterations += more.iterations;
    report.forward_applies += more.forward_applies;
    report.adjoint_applies += more.adjoint_applies;
    report.residual_history.extend(more.residual_history);
    report.objective_history.extend(more.objective_history);
    report.termination = more.termination;
    report.elapsed += more.elapsed;
}

/// Per pixel of `x` (pixels of `ks` entries): the depth and amplitude of its largest positive
/// entry, if any.
fn peaks<T: Real>(x: &[T], ks: usize) -> Vec<Option<(usize, f64)>> {
    x.chunks(ks)
        .map(|c| {
            c.iter()
                .enumerate()
                .map(|(j, v)| (j, v.as_f64()))
                .filter(|(_, v)| *v > 0.0)
                .max_by(|a, b| a.1.total_cmp(&b.1))
        })
        .collect()
}

/// Recovers a scene with one reflector per pixel whose depth map is piecewise smooth: the
/// regularization acts on the M×N depth map, not on the voxel cube.
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
/// Steps 2–3 repeat [`rounds`](TvDepthParams::rounds) times; none run when the first fit already
/// explains the data (it stopped on its residual tolerance). Isolated wrong depths, which cross-
/// talk and noise cause and which the per-pixel model cannot tell from true ones, are pulled
/// towards their neighbours' depths, where the data then confirm or move them.
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
    if !(params.lambda.is_finite() && params.lambda >= 0.0) {
        return Err(Error::param(
            "lambda",
            format!("must be finite and ≥ 0, got {}", params.lambda),
        ));
    }
    let tv = TvParams {
        lambda: params.lambda,
        ..params.tv
    };
    if !(params.neighbour_floor > 0.0 && params.neighbour_floor <= 1.0) {
        return Err(Error::param(
            "neighbour_floor",
            format!("must be in (0, 1], got {}", params.neighbour_floor),
        ));
    }
    // The neighbourhood prior: message passing, then again with priors from the neighbours
    // posteriors, until a run explains the data or the rounds are used up.
    let mut start: Option<Report> = None;
    if let Some(amp) = params
        .model
        .amp
        .as_ref()
        .filter(|_| params.neighbour_rounds > 0)
    {
        if x.iter().all(|v| *v == T::zero()) {
            let (mut rep, mut post) = reflector_amp_run(op, y, x, amp, None, None, &mut ())?;
            for _ in 0..params.neighbour_rounds {
                // Done once a run explains the data or settles on a support.
                if matches!(
                    rep.termination,
                    Termination::Residual | Termination::Converged
                ) {
                    break;
                }
                let priors = neighbour_priors(
                    &post,
                    grid,
                    ks,
                    params.neighbour_radius,
                    params.neighbour_floor,
                );
                let (more, p) = reflector_amp_run(op, y, x, amp, None, Some(&priors), &mut ())?;
                absorb(&mut rep, more);
                post = p;
            }
            start = Some(rep);
        }
    }
    let mut report = model_based_in(op, y, x, &params.model, None, observer)?;
    if let Some(mut first) = start {
        absorb(&mut first, report);
        report = first;
    }
    if report.termination == Termination::Residual {
        // The fit explains the data to the solver's tolerance: nothing for TV to correct.
        report.solver = "tv-depth";
        return Ok(report);
    }
    let windowed = ModelBasedParams {
        explore_iterations: 0,
        ..params.model
    };
    for _ in 0..params.rounds {
        let found = peaks(x, ks);
        let amax = found.iter().flatten().map(|p| p.1).fold(0.0, f64::max);
        if amax == 0.0 {
            break;
        }
        let f = Array2::from_shape_fn((m, n), |(i, j)| {
            found[i * n + j].map_or(0.0, |p| p.0 as f64)
        });
        let w = Array2::from_shape_fn((m, n), |(i, j)| {
            found[i * n + j].map_or(0.0, |p| (p.1 / amax).powi(2))
        });
        let mut u = f.clone();
        tv_denoise(f.view(), w.view(), &mut u, &tv, &mut ())?;
        let centre: Vec<usize> = u
            .iter()
            .map(|v| v.round().clamp(0.0, (ks - 1) as f64) as usize)
            .collect();
        let windows: Vec<(usize, usize)> = centre
            .iter()
            .map(|&c| {
                (
                    c.saturating_sub(params.window),
                    (c + params.window).min(ks - 1),
                )
            })
            .collect();
        if params.model.amp.is_some() {
            x.fill(T::zero());
        }
        // Move each reflector to its regularized depth unless its own depth is in the window.
        for (p, found) in found
            .iter()
            .enumerate()
            .filter(|_| params.model.amp.is_none())
        {
            if let Some((d, a)) = *found {
                let (lo, hi) = windows[p];
                if d < lo || d > hi {
                    x[p * ks + d] = T::zero();
                    x[p * ks + centre[p]] = T::of_f64(a);
                }
            }
        }
        let r = model_based_in(op, y, x, &windowed, Some(&windows), observer)?;
        absorb(&mut report, r);
    }
    report.solver = "tv-depth";
    Ok(report)
}
