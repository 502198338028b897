//! The triangle's exact fit: a return between bins j and j + 1 is a pair of voxels whose
//! weights are linear in its amplitude and fraction, so the pairs are fitted by least squares
//! and slide a bin where the residual says the return lies beyond.

use crate::error::Result;
use crate::lidar::LidarOperator;
use crate::linalg::dot;
use crate::operator::Applies;
use crate::real::Real;
use crate::solver::{cgls, CglsParams, Stagnation, Stopping};

use super::subbin::{residual_through, Ret};

/// [`fit_pairs`] ends its rounds once the squared residual is at most this share of ‖y‖² (the
/// data explained to 10⁻⁷): a pair on the wrong side of a bin leaves its return's weight beyond
/// the bin in the residual, so what is left is at most about 10⁻⁷·√(returns) of an amplitude.
const EXPLAINED_TO_ROUNDOFF: f64 = 1e-14;

/// Rounds of [`fit_pairs`] at most.
const PAIR_ROUNDS: usize = 40;

/// The triangle's exact fit: a return at d = j + f is the pair of voxels (j, j + 1) with
/// weights a·(1 − f) and a·f, linear in the pair. Given each return's bin j, least squares on
/// the pairs gives (u, v). A return whose pair leans on a side (v < u: the lower voxel) moves one
/// bin that way when the residual correlates positively with the voxel beyond (j − 1, or
/// j + 2 for the upper side), as it does when the true depth lies across the bin: the least
/// squares then runs again, for as long as the residual falls. Then a = u + v and
/// d = j + v/(u + v) (u, v clamped at zero); a pair whose weights sum to at most zero is no
/// return.
pub(super) fn fit_pairs<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    found: Vec<Ret>,
    ks: usize,
    applies: &mut Applies,
) -> Result<Vec<Ret>> {
    if ks < 3 || found.is_empty() {
        return Ok(found);
    }
    let last = ks - 2;
    let mut bins: Vec<usize> = found
        .iter()
        .map(|r| (r.d.floor().max(0.0) as usize).min(last))
        .collect();
    let pixels: Vec<usize> = found.iter().map(|r| r.pixel).collect();
    let mut w: Vec<T> = found
        .iter()
        .zip(&bins)
        .flat_map(|(r, &j)| {
            let f = (r.d - j as f64).clamp(0.0, 1.0);
            [T::of_f64(r.a * (1.0 - f)), T::of_f64(r.a * f)]
        })
        .collect();
    // The rounds decide the moves on a fit to 1e-6 of the first gradient; the pairs they end on
    // are fitted to 1e-12, or until the misfit stirs only round-off (in `f32` long before).
    let yy = dot(y, y);
    let solve = |tolerance: f64| CglsParams {
        damp: 0.0,
        stopping: Stopping {
            max_iter: 500,
            rel_residual: Some(tolerance),
            stagnation: Some(Stagnation {
                rel: 0.0,
                window: super::refit::ROUND_OFF_WINDOW,
                floor: 0.5 * T::EPS * T::EPS * yy,
            }),
            ..Stopping::default()
        },
    };
    let (params, tight) = (solve(1e-6), solve(1e-12));
    let mut best: Option<(f64, Vec<usize>, Vec<T>)> = None;
    // The share of the largest gain a move needs; raised when a round's moves did not help.
    let mut share = 0.05;
    for _ in 0..PAIR_ROUNDS {
        let a = op.restrict_columns(pair_columns(&pixels, &bins, ks))?;
        let rep = cgls(&a, y, &mut w, &params, &mut ())?;
        applies.support += rep.forward_applies + rep.adjoint_applies + 2;
        let mut r = residual_through(&*a, y, &w);
        let rr = dot(&r, &r);
        if let Some((_, bb, bw)) = best.as_ref().filter(|b| rr >= b.0) {
            // The moves did not help: back to the best pairs, and only the clearest moves.
            share *= 4.0;
            if share > 1.0 {
                break;
            }
            bins = bb.clone();
            w = bw.clone();
            let a = op.restrict_columns(pair_columns(&pixels, &bins, ks))?;
            r = residual_through(&*a, y, &w);
            applies.support += 1;
        } else {
            best = Some((rr, bins.clone(), w.clone()));
        }
        // The data explained to round-off: no move can lower the residual.
        if rr <= EXPLAINED_TO_ROUNDOFF * yy {
            break;
        }
        // The residual's correlation with the voxel beyond each pair, on the side it leans to:
        // the gain c²/‖A·e‖² of adding that voxel.
        let beyond: Vec<Option<usize>> = bins
            .iter()
            .zip(w.chunks(2))
            .map(|(&j, uv)| {
                let (u, v) = (uv[0].as_f64(), uv[1].as_f64());
                if v < u {
                    j.checked_sub(1)
                } else {
                    (j + 2 < ks).then_some(j + 2)
                }
            })
            .collect();
        let probe: Vec<usize> = pixels
            .iter()
            .zip(&beyond)
            .map(|(&p, b)| p * ks + b.unwrap_or(0))
            .collect();
        let norms = op.column_norms(&probe);
        let c = op.restrict_columns(probe)?;
        let mut corr = vec![T::zero(); pixels.len()];
        c.apply_adjoint(&r, &mut corr);
        applies.support += 2;
        let gains: Vec<f64> = corr
            .iter()
            .zip(&norms)
            .zip(&beyond)
            .map(|((c, n), b)| {
                let c = c.as_f64();
                if b.is_some() && c > 0.0 && *n > 0.0 {
                    c * c / (n * n)
                } else {
                    0.0
                }
            })
            .collect();
        let top = gains.iter().copied().fold(0.0, f64::max);
        if top <= 1e-24 * rr.max(f64::MIN_POSITIVE) || top == 0.0 {
            break;
        }
        for (((j, b), g), uv) in bins
            .iter_mut()
            .zip(&beyond)
            .zip(&gains)
            .zip(w.chunks_mut(2))
        {
            let Some(b) = *b else { continue };
            if *g < share * top {
                continue;
            }
            // The pair slides one bin: the leaning voxel keeps its weight on the new pair.
            if b < *j {
                *j -= 1;
                uv[1] = uv[0];
                uv[0] = T::zero();
            } else {
                *j = (*j + 1).min(last);
                uv[0] = uv[1];
                uv[1] = T::zero();
            }
        }
    }
    let (_, bins, mut w) = best.expect("one round ran");
    let a = op.restrict_columns(pair_columns(&pixels, &bins, ks))?;
    let rep = cgls(&a, y, &mut w, &tight, &mut ())?;
    applies.support += rep.forward_applies + rep.adjoint_applies + 1;
    Ok(pixels
        .iter()
        .zip(&bins)
        .zip(w.chunks(2))
        .filter_map(|((&pixel, &j), uv)| {
            let (u, v) = (uv[0].as_f64().max(0.0), uv[1].as_f64().max(0.0));
            let sum = u + v;
            (sum > 0.0).then(|| Ret {
                pixel,
                a: sum,
                d: j as f64 + v / sum,
            })
        })
        .collect())
}

/// The columns of the pairs: voxels j and j + 1 of each pixel, for its bin j.
fn pair_columns(pixels: &[usize], bins: &[usize], ks: usize) -> Vec<usize> {
    pixels
        .iter()
        .zip(bins)
        .flat_map(|(&p, &j)| [p * ks + j, p * ks + j + 1])
        .collect()
}
