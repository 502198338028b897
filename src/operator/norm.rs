//! The operator-norm estimate: the Lanczos iteration on AᵀA.

use crate::error::{Error, Result};
use crate::linalg::norm2;
use crate::real::Real;
use crate::space;

use super::testing::{check_rng, gaussian_vector, NORM_STREAM};
use super::LinearOperator;

/// Settings of [`operator_norm`] (the Lanczos iteration on A*A: each step one forward and one
/// adjoint application, as a step of the power iteration it replaced).
#[derive(Debug, Clone, Copy)]
pub struct PowerIteration {
    /// Maximum number of iterations (each one forward and one adjoint application).
    pub max_iter: usize,
    /// Stop when the estimate changes by at most `tol` relative to itself.
    pub tol: f64,
    /// Seed of the random start vector.
    pub seed: u64,
}

impl Default for PowerIteration {
    fn default() -> Self {
        PowerIteration {
            max_iter: 200,
            tol: 1e-6,
            seed: 0,
        }
    }
}

/// Why [`operator_norm`] stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NormStop {
    /// The relative change of the estimate fell below the tolerance, or the Krylov space is
    /// invariant (the estimate is then exact for it).
    Converged,
    /// The iteration limit was reached first.
    MaxIterations,
    /// A·v = 0 for the start vector (or an empty operator): the estimate is 0.
    ZeroOperator,
}

/// The result of [`operator_norm`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormEstimate {
    /// The estimate of ‖A‖₂ (largest singular value), a lower bound up to rounding.
    pub value: f64,
    /// Iterations performed.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: NormStop,
}

/// Estimates ‖A‖₂ by the Lanczos iteration on A*A.
///
/// Each step applies A and A* once, as a step of the power iteration does, and extends the Krylov
/// space span{v, A*A·v, …} of a random unit start vector v; the estimate is σ = √θ, with θ the
/// largest eigenvalue of the tridiagonal matrix the steps build (the largest Rayleigh quotient
/// of A*A over that space). It never exceeds ‖A‖₂ (up to rounding), is at least the power
/// iteration's estimate after as many steps (whose iterate lies in the same space) and converges
/// much faster where the top singular values cluster, as for random codes: at the rate of a
/// Chebyshev polynomial in the gap rather than of its power. The three-term recurrence keeps three
/// vectors of the unknowns' length and no basis: the loss of orthogonality in floating point
/// only repeats eigenvalues that have converged, which leaves the largest one in place.
///
/// It stops when the estimate changes by at most `tol` relative to itself between two steps, or
/// when the Krylov space is invariant (within one step more than the rank of A).
///
/// # Errors
/// [`Error::InvalidParameter`] if `max_iter` is zero or `tol` is not a positive finite number;
/// [`Error::NonFinite`] if the operator produced NaN or infinite values.
pub fn operator_norm<T: Real, A: LinearOperator<T> + ?Sized>(
    op: &A,
    params: &PowerIteration,
) -> Result<NormEstimate> {
    if params.max_iter == 0 {
        return Err(Error::param("max_iter", "must be at least 1"));
    }
    if !(params.tol.is_finite() && params.tol > 0.0) {
        return Err(Error::param(
            "tol",
            format!(
                "must be a positive finite number, got {}",
                crate::units::number(params.tol)
            ),
        ));
    }
    let (m, n) = (op.nrows(), op.ncols());
    // Over unknowns split into parts: the whole vector's count and this part's first index.
    let space = op.space();
    let (total, offset) = (space::count(space, n), space.offset(n));
    let zero = NormEstimate {
        value: 0.0,
        iterations: 0,
        stop: NormStop::ZeroOperator,
    };
    if m == 0 || total == 0 {
        return Ok(zero);
    }
    // The start vector of the whole, so that every split starts from the same one.
    let mut rng = check_rng(params.seed, NORM_STREAM);
    let mut v: Vec<T> = gaussian_vector(total, &mut rng);
    v.drain(..offset);
    v.truncate(n);
    let nv = space::norm2(space, &v);
    v.iter_mut().for_each(|e| *e = T::of_f64(e.as_f64() / nv));
    let mut v_prev = vec![T::zero(); n];
    let mut w = vec![T::zero(); n];
    let mut av = vec![T::zero(); m];
    let mut scratch = vec![T::zero(); op.scratch_len()];
    // The tridiagonal matrix: its diagonal and the off-diagonal built so far.
    let (mut alpha, mut beta) = (Vec::<f64>::new(), Vec::<f64>::new());
    let mut prev = 0.0f64;
    for it in 1..=params.max_iter {
        op.apply_with_scratch(&v, &mut av, &mut scratch);
        let gain = norm2(&av);
        if !gain.is_finite() {
            return Err(Error::NonFinite {
                what: format!("operator output during norm iteration {it}"),
            });
        }
        if it == 1 && gain == 0.0 {
            return Ok(NormEstimate {
                iterations: it,
                ..zero
            });
        }
        op.apply_adjoint_with_scratch(&av, &mut w, &mut scratch);
        // w ← A*A·v − α v − β v_prev, with α = v·A*A·v = ‖A·v‖², the Rayleigh quotient at v
        // (from the measurements, in f64, already summed over any split of the unknowns).
        let a = gain * gain;
        let b_prev = beta.last().copied().unwrap_or(0.0);
        for ((wi, vi), pi) in w.iter_mut().zip(&v).zip(&v_prev) {
            *wi = T::of_f64(wi.as_f64() - a * vi.as_f64() - b_prev * pi.as_f64());
        }
        let b = space::norm2(space, &w);
        if !b.is_finite() {
            return Err(Error::NonFinite {
                what: format!("adjoint output during norm iteration {it}"),
            });
        }
        alpha.push(a);
        let sigma = largest_eigenvalue(&alpha, &beta).max(0.0).sqrt();
        // Rounding leaves b at a few epsilons of θ where the space is invariant.
        let invariant = b <= 16.0 * T::EPS * sigma * sigma;
        if invariant || (it > 1 && (sigma - prev).abs() <= params.tol * sigma) {
            return Ok(NormEstimate {
                value: sigma,
                iterations: it,
                stop: NormStop::Converged,
            });
        }
        beta.push(b);
        std::mem::swap(&mut v_prev, &mut v);
        std::mem::swap(&mut v, &mut w);
        v.iter_mut().for_each(|e| *e = T::of_f64(e.as_f64() / b));
        prev = sigma;
    }
    Ok(NormEstimate {
        value: prev,
        iterations: params.max_iter,
        stop: NormStop::MaxIterations,
    })
}

/// The largest eigenvalue of the symmetric tridiagonal matrix with diagonal `alpha` and
/// off-diagonal `beta` (one shorter), by bisection on Sturm counts between the largest diagonal
/// entry and the Gershgorin bound: to the last bits, in O(len) per halving. The entries are
/// scaled to at most 1 first, so that the squares of the pivots neither overflow nor underflow.
fn largest_eigenvalue(alpha: &[f64], beta: &[f64]) -> f64 {
    let scale = alpha.iter().chain(beta).fold(0.0f64, |m, v| m.max(v.abs()));
    if !(scale > 0.0 && scale.is_finite()) {
        return alpha.iter().copied().fold(0.0, f64::max);
    }
    let alpha: Vec<f64> = alpha.iter().map(|a| a / scale).collect();
    let beta: Vec<f64> = beta.iter().map(|b| b / scale).collect();
    scale * largest_scaled(&alpha, &beta)
}

/// [`largest_eigenvalue`] of entries at most 1 in magnitude.
fn largest_scaled(alpha: &[f64], beta: &[f64]) -> f64 {
    let off = |i: usize| beta.get(i).map_or(0.0, |b| b.abs());
    let mut lo = alpha.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut hi = (0..alpha.len())
        .map(|i| alpha[i] + off(i) + if i > 0 { off(i - 1) } else { 0.0 })
        .fold(f64::NEG_INFINITY, f64::max);
    // The eigenvalues below x: the negative pivots of the LDLᵀ factorization of T − x·I.
    let below = |x: f64| {
        let (mut count, mut d) = (0, 1.0f64);
        for (i, &a) in alpha.iter().enumerate() {
            let coupling = if i > 0 {
                beta[i - 1] * beta[i - 1] / d
            } else {
                0.0
            };
            d = a - x - coupling;
            if d == 0.0 {
                d = -f64::MIN_POSITIVE;
            }
            if d < 0.0 {
                count += 1;
            }
        }
        count
    };
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if below(mid) == alpha.len() {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    lo
}

#[cfg(test)]
mod tests {
    use super::largest_eigenvalue;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn largest_eigenvalue_of_tridiagonals_matches_the_dense_eigensolver() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for len in 1..=40 {
            let alpha: Vec<f64> = (0..len).map(|_| rng.random_range(-2.0..5.0)).collect();
            // Some couplings zero: the matrix splits into blocks.
            let beta: Vec<f64> = (1..len)
                .map(|i| {
                    if i % 7 == 0 {
                        0.0
                    } else {
                        rng.random_range(-3.0..3.0)
                    }
                })
                .collect();
            let t = nalgebra::DMatrix::from_fn(len, len, |i, j| match i.abs_diff(j) {
                0 => alpha[i],
                1 => beta[i.min(j)],
                _ => 0.0,
            });
            let want = t.symmetric_eigenvalues().max();
            let got = largest_eigenvalue(&alpha, &beta);
            assert!(
                (got - want).abs() <= 1e-12 * want.abs().max(1.0),
                "length {len}: {got} vs {want}"
            );
            // Far from 1 in either direction, where the squared couplings would overflow or
            // underflow unscaled.
            for scale in [1e-200, 1e200] {
                let a: Vec<f64> = alpha.iter().map(|v| v * scale).collect();
                let b: Vec<f64> = beta.iter().map(|v| v * scale).collect();
                let got = largest_eigenvalue(&a, &b) / scale;
                assert!(
                    (got - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "length {len}, scale {scale:e}: {got} vs {want}"
                );
            }
        }
    }
}
