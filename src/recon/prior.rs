//! A prior on the depth map inside the continuous fit: under noise, the depths that fit the
//! data best scatter about the surfaces by about their Cramér–Rao bound, pixel by pixel, while
//! real surfaces are nearly planar over a few pixels. The fit then minimizes the squared misfit
//! plus λ·Σ ρ(Δ²d) over the second differences Δ²d of the depth map along its rows and columns
//! (zero on a plane), ρ the Huber function with its corner at the pixels' typical depth bound c
//! (quadratic below, |t| above: an edge between surfaces costs its height once, not its square).
//! Each step is a Gauss–Newton step with the prior's rows stacked under the Jacobian, weighted
//! as iteratively reweighted least squares do.
//!
//! λ is not a setting: it grows over a ladder of multiples of σ²/c (σ the noise the residual
//! shows) for as long as the squared misfit stays within R·σ² of the fit without the prior (R
//! returns): what moving the R depths from the best fit to the truth costs on average, so that
//! the prior never takes the estimate further from the data than the truth lies. Noise-free,
//! σ = 0 and nothing changes.

use crate::error::Result;
use crate::lidar::{LidarOperator, Response};
use crate::linalg::dot;
use crate::operator::{Applies, LinearOperator, SparseMatrix, VStack};
use crate::real::Real;
use crate::solver::cgls;

use super::bound::{pixel_bound, Grams};
use super::subbin::{jacobian, residual, step_of, step_solve, stepped, Ret};

/// The multiples of σ²/c that λ takes in turn, weakest first.
const LADDER: [f64; 6] = [0.125, 0.25, 0.5, 1.0, 2.0, 4.0];

/// Reweighted Gauss–Newton steps per rung of the ladder.
const STEPS_PER_RUNG: usize = 3;

/// Halvings of a step that does not lower the penalized misfit.
const HALVINGS: usize = 4;

/// The second differences of the depth map: triples of returns (before, at, after) in three
/// consecutive pixels of a row or a column, each pixel with one return.
fn triples(found: &[Ret], m: usize, n: usize) -> Vec<[usize; 3]> {
    let mut at: Vec<Option<usize>> = vec![None; m * n];
    let mut several = vec![false; m * n];
    for (i, r) in found.iter().enumerate() {
        several[r.pixel] |= at[r.pixel].is_some();
        at[r.pixel] = Some(i);
    }
    let one = |i: usize, j: usize| (!several[i * n + j]).then_some(at[i * n + j]).flatten();
    let mut out = Vec::new();
    for i in 0..m {
        for j in 0..n {
            let Some(c) = one(i, j) else { continue };
            if j >= 1 && j + 1 < n {
                if let (Some(a), Some(b)) = (one(i, j - 1), one(i, j + 1)) {
                    out.push([a, c, b]);
                }
            }
            if i >= 1 && i + 1 < m {
                if let (Some(a), Some(b)) = (one(i - 1, j), one(i + 1, j)) {
                    out.push([a, c, b]);
                }
            }
        }
    }
    out
}

/// The second difference of a triple.
fn curvature(found: &[Ret], t: &[usize; 3]) -> f64 {
    found[t[0]].d - 2.0 * found[t[1]].d + found[t[2]].d
}

/// Σ ρ(Δ²d): the Huber function at corner `c`.
fn penalty(found: &[Ret], rows: &[[usize; 3]], c: f64) -> f64 {
    rows.iter()
        .map(|t| {
            let v = curvature(found, t).abs();
            if v <= c {
                v * v / (2.0 * c)
            } else {
                v - c / 2.0
            }
        })
        .sum()
}

/// The median over the returns of the depth's Cramér–Rao bound at noise `sigma`, each pixel's
/// other returns and every other pixel held (none when no return has a finite bound).
fn typical_bound<T: Real>(
    op: &dyn LidarOperator<T>,
    found: &[Ret],
    response: &Response,
    sigma: f64,
) -> Option<f64> {
    let ks = op.geometry().ks;
    let grams = Grams::new(op);
    let mut bounds: Vec<f64> = found
        .iter()
        .map(|r| pixel_bound(&grams.of(r.pixel), ks, &[(r.a, r.d)], response, sigma)[0])
        .filter(|b| b.is_finite() && *b > 0.0)
        .collect();
    if bounds.is_empty() {
        return None;
    }
    let mid = bounds.len() / 2;
    Some(*bounds.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// The fitted returns `found` (squared misfit `rr`) refitted with the prior on the depth map,
/// with their squared misfit; unchanged where the residual shows no noise, no pixel has two
/// neighbours in a line, or the weakest prior already moves the fit further than the noise
/// allows.
pub(super) fn with_prior<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    (found, rr): (Vec<Ret>, f64),
    response: &Response,
    applies: &mut Applies,
) -> Result<(Vec<Ret>, f64)> {
    let g = op.geometry();
    let yy = dot(y, y);
    let dof = y.len().saturating_sub(2 * found.len());
    if found.is_empty() || dof == 0 || rr <= 1e-20 * yy {
        return Ok((found, rr));
    }
    let sigma2 = rr / dof as f64;
    let rows = triples(&found, g.m, g.n);
    let Some(c) = typical_bound(op, &found, response, sigma2.sqrt()) else {
        return Ok((found, rr));
    };
    if rows.is_empty() {
        return Ok((found, rr));
    }
    let budget = rr + found.len() as f64 * sigma2;
    let top = (g.ks - 1) as f64;
    let mut best = (found.clone(), rr);
    let (mut cur, mut cur_rr) = (found, rr);
    for s in LADDER {
        let lambda = s * sigma2 / c;
        for _ in 0..STEPS_PER_RUNG {
            let objective = cur_rr + lambda * penalty(&cur, &rows, c);
            let step = penalized_step(op, y, &cur, &rows, (lambda, c), response, applies)?;
            let mut scale = 1.0;
            let mut accepted = None;
            for _ in 0..=HALVINGS {
                let trial = stepped(&cur, &step, scale, top);
                let t = residual(op, y, &trial, response, g.ks, applies)?;
                if t + lambda * penalty(&trial, &rows, c) < objective {
                    accepted = Some((trial, t));
                    break;
                }
                scale *= 0.5;
            }
            let Some((trial, t)) = accepted else { break };
            cur = trial;
            cur_rr = t;
        }
        if cur_rr > budget {
            break;
        }
        best = (cur.clone(), cur_rr);
    }
    Ok(best)
}

/// One Gauss–Newton step of the squared misfit plus λ·Σ ρ(Δ²d), ρ majorized at the current
/// depths by w·t²/2 with w = 1/max(|Δ²d|, c): the least squares of the Jacobian stacked over
/// the prior's rows √(λw/2)·Δ²(d + Δd) (the depth's step variable is a·Δd, so the rows weigh it
/// by 1/a).
fn penalized_step<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    found: &[Ret],
    rows: &[[usize; 3]],
    (lambda, c): (f64, f64),
    response: &Response,
    applies: &mut Applies,
) -> Result<Vec<(f64, f64)>> {
    let (j, r) = jacobian(op, y, found, response, op.geometry().ks)?;
    let mut tri = sprs::TriMat::new((rows.len(), 2 * found.len()));
    let mut rhs = r;
    for (row, t) in rows.iter().enumerate() {
        let v = curvature(found, t);
        let w = (lambda / (2.0 * v.abs().max(c))).sqrt();
        for (&i, coef) in t.iter().zip([1.0, -2.0, 1.0]) {
            let a = found[i].a;
            if a > 0.0 {
                tri.add_triplet(row, 2 * i + 1, T::of_f64(w * coef / a));
            }
        }
        rhs.push(T::of_f64(-w * v));
    }
    let prior: Box<dyn LinearOperator<T> + '_> = Box::new(SparseMatrix::new(tri.to_csr())?);
    let stacked = VStack::new(vec![j, prior])?;
    let mut delta = vec![T::zero(); 2 * found.len()];
    let rep = cgls(&stacked, &rhs, &mut delta, &step_solve(), &mut ())?;
    applies.support += 1 + rep.forward_applies + rep.adjoint_applies;
    Ok(step_of(found, &delta))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ret(pixel: usize, d: f64) -> Ret {
        Ret { pixel, a: 1.0, d }
    }

    #[test]
    fn second_differences_run_along_rows_and_columns_of_pixels_with_one_return() {
        // A 3×3 grid, every pixel lit, the centre with two returns.
        let mut found: Vec<Ret> = (0..9).map(|p| ret(p, p as f64)).collect();
        found.push(ret(4, 7.5));
        let rows = triples(&found, 3, 3);
        // Through the centre every line is left out; the edges' middles have none of their own
        // in the direction along the border only.
        let mut got: Vec<[usize; 3]> = rows.clone();
        got.sort();
        assert_eq!(got, vec![[0, 1, 2], [0, 3, 6], [2, 5, 8], [6, 7, 8]]);
        // Without the second return the centre's two lines join.
        found.pop();
        assert_eq!(triples(&found, 3, 3).len(), 6);
    }

    #[test]
    fn the_huber_penalty_is_quadratic_below_its_corner_and_linear_above() {
        let rows = [[0, 1, 2]];
        let c = 0.2;
        let flat = [ret(0, 1.0), ret(1, 1.0), ret(2, 1.0)];
        assert_eq!(penalty(&flat, &rows, c), 0.0);
        // A plane costs nothing either.
        let plane = [ret(0, 1.0), ret(1, 1.5), ret(2, 2.0)];
        assert!(penalty(&plane, &rows, c).abs() < 1e-15);
        let small = [ret(0, 1.0), ret(1, 0.95), ret(2, 1.0)];
        assert!((penalty(&small, &rows, c) - 0.01 / 0.4).abs() < 1e-12);
        let edge = [ret(0, 1.0), ret(1, 1.0), ret(2, 5.0)];
        assert!((penalty(&edge, &rows, c) - (4.0 - 0.1)).abs() < 1e-12);
        // Continuous at the corner.
        let at = [ret(0, 1.0), ret(1, 0.9), ret(2, 1.0)];
        assert!((penalty(&at, &rows, c) - 0.1).abs() < 1e-12);
    }
}
