//! Least squares on the support of an estimate: the debiasing step of the sparse solvers and the
//! refit of [`Method::Auto`](super::Method::Auto)'s support stage.

use crate::error::Result;
use crate::lidar::LidarOperator;
use crate::linalg::norm2_sq;
use crate::operator::{Counted, LinearOperator};
use crate::real::Real;
use crate::solver::{cgls, CglsParams, Report, Stagnation, Stopping};
use crate::space;

/// CGLS iterations of one least-squares refit on a support.
pub(super) const REFIT_MAX_ITER: usize = 50;

/// Rounds of refitting after dropping non-positive amplitudes.
pub(super) const REFIT_ROUNDS: usize = 3;

/// Least squares on the support of `x` (its nonzero voxels), warm-started from its values, in
/// place: the amplitudes that best explain `y` with those voxels alone. Voxels whose amplitude
/// comes out non-positive are dropped (reflectivities are nonnegative) and the rest refitted, up
/// to `rounds` fits in all ([`REFIT_ROUNDS`] for a full refit).
///
/// Returns `None`, leaving `x` unchanged, when the support is empty or holds more than half as
/// many voxels as there are measurements (least squares would then fit noise and cross-talk
/// rather than remove a bias). The report counts its applications as support applies.
///
/// # Errors
/// The least squares' errors ([`crate::Error::Breakdown`]).
pub(super) fn refit_support<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    x: &mut [T],
    max_iter: usize,
    rounds: usize,
) -> Result<Option<Report>> {
    refit_support_to(op, y, x, max_iter, rounds, REFIT_TARGET)
}

/// The normal equations' residual ‖A_Sᵀ(y − A_S·b)‖, relative to its value at the warm start, at
/// which [`refit_support`] stops, unless round-off ends it first ([`ROUND_OFF_WINDOW`]: always
/// in `f32`, often in `f64`).
pub(super) const REFIT_TARGET: f64 = 1e-12;

/// Iterations over which a refit must lower ‖y − A_S·b‖² by more than (ε·‖y‖)², ε the machine
/// epsilon of the precision, to go on: below that the fit's prediction A_S·b moves by less than
/// the rounding of the measurements themselves, and further iterations only stir round-off (in
/// `f32` the normal equations' relative residual levels off near 10⁻⁸ to 10⁻⁶, far above
/// [`REFIT_TARGET`]). CGLS lowers the squared residual by exactly ‖A_S·(b_{k+1} − b_k)‖² in each
/// iteration; a rise can only be round-off and ends the refit too. The rule reads the objective
/// ½‖r‖², the same on every process of a split operator, so every process stops at the same
/// iteration.
pub(super) const ROUND_OFF_WINDOW: usize = 3;

/// [`refit_support`] to the relative residual `target` instead of [`REFIT_TARGET`].
///
/// # Errors
/// As [`refit_support`].
pub(super) fn refit_support_to<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    x: &mut [T],
    max_iter: usize,
    rounds: usize,
    target: f64,
) -> Result<Option<Report>> {
    let space = op.space();
    let mut support: Vec<usize> = (0..x.len()).filter(|&i| x[i] != T::zero()).collect();
    let held = space::count(space, support.len());
    if held == 0 || 2 * held > y.len() {
        return Ok(None);
    }
    let params = CglsParams {
        damp: 0.0,
        stopping: Stopping {
            max_iter,
            rel_residual: Some(target),
            stagnation: Some(Stagnation {
                rel: 0.0,
                window: ROUND_OFF_WINDOW,
                floor: 0.5 * T::EPS * T::EPS * norm2_sq(y),
            }),
            ..Stopping::default()
        },
    };
    // The restrictions' applications count as support applications.
    let counted = Counted::new(op);
    let mut total: Option<Report> = None;
    for _ in 0..rounds.max(1) {
        let restricted = counted.restrict_columns(support.clone())?;
        let mut b: Vec<T> = support.iter().map(|&v| x[v]).collect();
        let rep = cgls(restricted.as_ref(), y, &mut b, &params, &mut ())?;
        match &mut total {
            Some(t) => t.absorb(rep),
            None => total = Some(rep),
        }
        for (&v, &a) in support.iter().zip(&b) {
            x[v] = if a > T::zero() { a } else { T::zero() };
        }
        let before = support.len();
        support.retain(|&v| x[v] > T::zero());
        let [dropped, left] = space::sums(
            space,
            [(before - support.len()) as f64, support.len() as f64],
        );
        if dropped == 0.0 || left == 0.0 {
            break;
        }
    }
    if let Some(t) = &mut total {
        t.set_applies(counted.applies());
    }
    Ok(total)
}
