//! Neighbour proposals for continuous depths: a fit from a start with a few returns more than a
//! bin off (or missing, or false) cannot move them, for the response's slope does not reach
//! that far, and their misfit spreads over every measurement. Each round proposes, for every
//! pixel beside a lit one, the depths its neighbours suggest (a neighbour's depth, and the
//! plane through two neighbours in a line continued to the pixel, and the pixel's depth in
//! another estimate where one is given: `auto`'s grid methods') and no return; a proposal is
//! taken where it lowers the data misfit by more than the noise could (the pixel's own
//! contribution added back to the residual, its amplitude by least squares, the change judged
//! through the pixel's Gram block), or, for a depth further from its neighbours' prediction
//! than its scatter at the noise level, where a short fit of all the returns lowers it; the
//! proposals are applied together (fewer when together they do not lower the misfit), and the
//! fit runs again.

use rayon::prelude::*;

use crate::error::Result;
use crate::lidar::{LidarOperator, Response};
use crate::linalg::dot;
use crate::operator::Applies;
use crate::real::Real;

use super::subbin::{refine, Ret, GN_STEPS};

/// Gauss–Newton steps of the short fit that judges proposals.
const TRIAL_STEPS: usize = 4;

/// Rounds of proposals at most.
const ROUNDS: usize = 8;

/// Standard deviations of the noise in a proposal's gain it must exceed.
pub(super) const NOISE_MARGIN: f64 = 3.0;

/// How far (in bins) a depth may lie from what its neighbours predict before the prediction is
/// proposed whatever its gain.
const OUTLIER_BINS: f64 = 0.3;

/// One pixel's Gram block, for the misfit of its column.
struct Pixel<'a> {
    gram: &'a [f64],
    ks: usize,
    response: &'a Response,
}

impl Pixel<'_> {
    /// The column of a return (a, d), or zero.
    fn column(&self, ret: Option<(f64, f64)>) -> Vec<f64> {
        let mut col = vec![0.0; self.ks];
        if let Some((a, d)) = ret {
            self.response.add_to(a, d, &mut col);
        }
        col
    }

    /// G·c.
    fn times(&self, c: &[f64]) -> Vec<f64> {
        let ks = self.ks;
        (0..ks)
            .map(|k| dot(&self.gram[k * ks..(k + 1) * ks], c))
            .collect()
    }

    /// The Cramér–Rao bound on the depth of a return (a, d) at noise σ, the other pixels held
    /// (infinite where it cannot be placed).
    fn depth_bound(&self, a: f64, d: f64, sigma: f64) -> f64 {
        super::bound::pixel_bound(self.gram, self.ks, &[(a, d)], self.response, sigma)[0]
    }

    /// The misfit term −⟨g, b⟩²/‖A·g‖² of a return at depth `d` against the pixel's
    /// correlations `b`, and its least-squares amplitude ⟨g, b⟩/‖A·g‖² (none when that would
    /// not be positive).
    fn fit(&self, d: f64, b: &[f64]) -> Option<(f64, f64)> {
        let col = self.column(Some((1.0, d)));
        let (norm, gb) = (dot(&col, &self.times(&col)), dot(&col, b));
        (norm > 0.0 && gb > 0.0).then(|| (-gb * gb / norm, gb / norm))
    }
}

/// The median of `v` (none when empty).
fn median(v: &[f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let h = s.len() / 2;
    Some(if s.len() % 2 == 1 {
        s[h]
    } else {
        0.5 * (s[h - 1] + s[h])
    })
}

/// A proposal: pixel `pixel` gets the return `to` (none for `None`), lowering the squared
/// misfit by about `gain`.
struct Proposal {
    pixel: usize,
    to: Option<(f64, f64)>,
    gain: f64,
    /// Whether the pixel's depth lies further from what its neighbours predict than its scatter
    /// at the noise level: proposed whatever the gain with the other returns held, for the fit
    /// of all may gain.
    outlier: bool,
}

/// Rounds of neighbour proposals on the fitted returns `found` of squared misfit `rr`, each
/// followed by the fit ([`refine`]), for as long as proposals are taken and lower the misfit.
pub(super) fn refine_with_neighbours<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    (mut found, mut rr): (Vec<Ret>, f64),
    response: &Response,
    hints: Option<&[Option<f64>]>,
    applies: &mut Applies,
) -> Result<(Vec<Ret>, f64)> {
    let yy = dot(y, y);
    for _ in 0..ROUNDS {
        if rr <= 1e-28 * yy {
            break;
        }
        let proposals = propose(op, y, &found, response, rr, hints, applies)?;
        if proposals.is_empty() {
            break;
        }
        // The proposals that gain with the other returns held; failing those, the outliers.
        let (clear, outliers): (Vec<Proposal>, Vec<Proposal>) =
            proposals.into_iter().partition(|p| !p.outlier);
        let mut taken = None;
        for mut group in [clear, outliers] {
            // Outliers everywhere: the start is not one a few proposals can mend.
            if group.first().is_some_and(|p| p.outlier) && group.len() * 5 > found.len() {
                continue;
            }
            group.sort_by(|a, b| b.gain.total_cmp(&a.gain));
            taken = take(op, y, &found, &group, rr, response, applies)?;
            if taken.is_some() {
                break;
            }
        }
        let Some((fitted, t)) = taken else { break };
        let gain = rr - t;
        found = fitted;
        rr = t;
        if gain <= 1e-12 * yy {
            break;
        }
    }
    Ok((found, rr))
}

/// The fit after the proposals `group` (sorted best first) if it lowers the misfit `rr`; if
/// not, after the better half, and so on.
fn take<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    found: &[Ret],
    group: &[Proposal],
    rr: f64,
    response: &Response,
    applies: &mut Applies,
) -> Result<Option<(Vec<Ret>, f64)>> {
    let mut count = group.len();
    // All, half, a quarter: beyond that the proposals are not worth their fits.
    let least = group.len().div_ceil(4);
    while count >= least && count > 0 {
        // Judged by a short fit (a few Gauss–Newton steps), then fitted in full.
        let trial = apply(found, &group[..count]);
        let (trial, t) = refine(op, y, trial, response, TRIAL_STEPS, applies)?;
        if t < rr {
            let (fitted, t) = refine(op, y, trial, response, GN_STEPS, applies)?;
            if t < rr {
                return Ok(Some((fitted, t)));
            }
        }
        count /= 2;
    }
    Ok(None)
}

/// `found` with the proposals' pixels given their proposed return.
fn apply(found: &[Ret], proposals: &[Proposal]) -> Vec<Ret> {
    let moved: std::collections::HashMap<usize, Option<(f64, f64)>> =
        proposals.iter().map(|p| (p.pixel, p.to)).collect();
    let mut out: Vec<Ret> = found
        .iter()
        .filter(|r| !moved.contains_key(&r.pixel))
        .copied()
        .collect();
    out.extend(proposals.iter().filter_map(|p| {
        p.to.map(|(a, d)| Ret {
            pixel: p.pixel,
            a,
            d,
        })
    }));
    out.sort_by_key(|r| r.pixel);
    out
}

/// The proposals that lower the misfit `rr` of `found` by more than the noise could.
fn propose<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    found: &[Ret],
    response: &Response,
    rr: f64,
    hints: Option<&[Option<f64>]>,
    applies: &mut Applies,
) -> Result<Vec<Proposal>> {
    let g = op.geometry();
    let (m, n, ks) = (g.m, g.n, g.ks);
    // One return per pixel: pixels with several are left as they are, and suggest nothing.
    let mut state: Vec<Option<(f64, f64)>> = vec![None; m * n];
    let mut several = vec![false; m * n];
    for r in found {
        if state[r.pixel].is_some() {
            several[r.pixel] = true;
        }
        state[r.pixel] = Some((r.a, r.d));
    }
    let mut x = vec![0.0f64; m * n * ks];
    for r in found {
        response.add_to(r.a, r.d, &mut x[r.pixel * ks..(r.pixel + 1) * ks]);
    }
    let x: Vec<T> = x.into_iter().map(T::of_f64).collect();
    let mut ax = vec![T::zero(); y.len()];
    op.apply(&x, &mut ax);
    let r: Vec<T> = y.iter().zip(&ax).map(|(a, b)| *a - *b).collect();
    let mut u = vec![T::zero(); x.len()];
    op.apply_adjoint(&r, &mut u);
    applies.forward += 1;
    applies.adjoint += 1;
    let unknowns = 2 * found.len();
    let sigma = (rr / y.len().saturating_sub(unknowns).max(1) as f64).sqrt();
    let grams = super::bound::Grams::new(op);
    let depth = |i: isize, j: isize| -> Option<f64> {
        if i < 0 || j < 0 || i >= m as isize || j >= n as isize {
            return None;
        }
        let p = i as usize * n + j as usize;
        if several[p] {
            return None;
        }
        state[p].map(|s| s.1)
    };
    let top = (ks - 1) as f64;
    let proposals = (0..m * n)
        .into_par_iter()
        .filter(|&p| !several[p])
        .filter_map(|p| {
            let (i, j) = ((p / n) as isize, (p % n) as isize);
            let mut neighbours = Vec::new();
            let mut lines = Vec::new();
            for (di, dj) in [
                (-1, -1),
                (-1, 0),
                (-1, 1),
                (0, -1),
                (0, 1),
                (1, -1),
                (1, 0),
                (1, 1),
            ] {
                if let Some(d1) = depth(i + di, j + dj) {
                    neighbours.push(d1);
                    if let Some(d2) = depth(i + 2 * di, j + 2 * dj) {
                        lines.push((2.0 * d1 - d2).clamp(0.0, top));
                    }
                }
            }
            // What the neighbours predict: the median of the lines through them (exact on a
            // plane), or of their depths.
            let prediction = median(if lines.len() >= 2 {
                &lines
            } else {
                &neighbours
            });
            let hint = hints.and_then(|h| h[p]);
            if prediction.is_none() && hint.is_none() {
                return None;
            }
            let gram = grams.of(p);
            let pixel = Pixel {
                gram: &gram,
                ks,
                response,
            };
            let old = pixel.column(state[p]);
            let g_old = pixel.times(&old);
            // b: the pixel's correlations with its own contribution added back.
            let b: Vec<f64> = (0..ks).map(|k| u[p * ks + k].as_f64() + g_old[k]).collect();
            let j_old = dot(&old, &g_old) - 2.0 * dot(&old, &b);
            let mut best: (f64, Option<(f64, f64)>) = (0.0, None);
            for &d in neighbours.iter().chain(&lines).chain(&hint) {
                if let Some((j_new, a)) = pixel.fit(d, &b) {
                    if j_new < best.0 {
                        best = (j_new, Some((a, d)));
                    }
                }
            }
            let moves = match (state[p], best.1) {
                (None, None) => false,
                (Some((_, d0)), Some((_, d1))) => (d0 - d1).abs() >= 0.5,
                _ => true,
            };
            let spread = |to: Option<(f64, f64)>| {
                let delta: Vec<f64> = pixel
                    .column(to)
                    .iter()
                    .zip(&old)
                    .map(|(a, b)| a - b)
                    .collect();
                dot(&delta, &pixel.times(&delta)).sqrt()
            };
            let gain = j_old - best.0;
            if moves && gain > 2.0 * NOISE_MARGIN * sigma * spread(best.1) {
                return Some(Proposal {
                    pixel: p,
                    to: best.1,
                    gain,
                    outlier: false,
                });
            }
            // A depth the neighbours do not predict: proposed whatever the gain with the
            // other returns held.
            let (a0, d0) = state[p]?;
            let prediction = prediction?;
            let scatter = NOISE_MARGIN * 5f64.sqrt() * pixel.depth_bound(a0, d0, sigma);
            if (d0 - prediction).abs() <= OUTLIER_BINS.max(scatter) {
                return None;
            }
            let (j_new, a) = pixel.fit(prediction, &b)?;
            Some(Proposal {
                pixel: p,
                to: Some((a, prediction)),
                gain: j_old - j_new,
                outlier: true,
            })
        })
        .collect();
    Ok(proposals)
}
