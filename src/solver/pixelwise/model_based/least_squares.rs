//! The least squares on a support that every model-based iteration solves, and how long it
//! runs.

use crate::error::{Error, Result};
use crate::operator::{LinearOperator, VoxelOperator};
use crate::real::Real;
use crate::solver::{cgls, CglsParams, Control, IterationInfo, Stopping};
use crate::space;

/// y − A_S b for the restriction `restricted` of the operator to a support.
fn support_residual<T: Real>(restricted: &dyn LinearOperator<T>, y: &[T], b: &[T]) -> Vec<T> {
    let mut r = vec![T::zero(); y.len()];
    if space::count(restricted.space(), b.len()) > 0 {
        restricted.apply(b, &mut r);
    }
    for (ri, &yi) in r.iter_mut().zip(y) {
        *ri = yi - *ri;
    }
    r
}

/// A least squares whose iterations ([`inner`](super::ModelBasedParams::inner)) run out with its
/// residual at most [`NEAR`] of ‖y‖ and its square still falling by at least a factor of 4 over
/// the last [`FAST_WINDOW`] iterations goes on, up to [`FAST_ROUNDS`] times its iterations, until
/// it slows down or reaches a tenth of the run's residual tolerance ([`BEYOND`]). A support that
/// is right converges fast (CGLS on an overdetermined, well-conditioned system): on the
/// noise-free 100×100×40 paper scene at K_p = 10 000 the fit from the neighbourhood prior's
/// estimate falls from 0.04 to 10⁻³ of ‖y‖ in ten iterations, and the correlations of so
/// unfinished a residual make the next iteration offer thousands of spurious pixels, tested and
/// dropped over the iterations after it. Under noise the residual levels off at the noise, and
/// on a wrong support at its misfit, within the first iterations; fits far from the data (a
/// stalled run's wrong support, whose residual may still fall fast for a while) end as before
/// too.
const FAST_FALL: f64 = 0.25;

/// The residual, as a fraction of ‖y‖, at or below which a fast least squares goes on.
const NEAR: f64 = 1e-2;

/// A fast least squares goes on to this fraction of the run's residual tolerance: the scene's
/// error is the residual's times the support's conditioning, and a fit ended just below the
/// tolerance left noise-free scenes off by more than 10⁻⁶ (tests/auto.rs).
const BEYOND: f64 = 0.1;

/// The iterations over which [`FAST_FALL`] is judged.
const FAST_WINDOW: usize = 5;

/// How many times its iterations a fast least squares may run.
const FAST_ROUNDS: usize = 5;

/// Least squares on the support `voxels`, warm-started from `b`, for at least the iterations of
/// `inner` and on while they converge fast ([`FAST_FALL`]) within [`NEAR`] of ‖y‖ = `ynorm` and
/// above [`BEYOND`] times the run's residual `tolerance`; returns the residual y − A_S b.
pub(super) fn fit<T, A>(
    op: &A,
    voxels: &[usize],
    y: &[T],
    b: &mut [T],
    inner: &CglsParams,
    it: usize,
    (ynorm, tolerance): (f64, Option<f64>),
) -> Result<Vec<T>>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
{
    const NAME: &str = "model-based";
    let restricted = op.restrict_columns(voxels.to_vec())?;
    if space::count(op.space(), voxels.len()) > 0 {
        let objective = |rel: f64| 0.5 * (rel * ynorm).powi(2);
        let (near, explained) = (
            objective(NEAR),
            tolerance.map_or(0.0, |t| objective(BEYOND * t)),
        );
        let limit = inner.stopping.max_iter;
        let extended = CglsParams {
            stopping: Stopping {
                max_iter: limit.saturating_mul(FAST_ROUNDS),
                ..inner.stopping
            },
            ..*inner
        };
        let mut objectives: Vec<f64> = Vec::new();
        let mut go_on = |info: &IterationInfo<'_, T>| {
            objectives.push(info.objective);
            let k = objectives.len();
            let fast =
                k > FAST_WINDOW && info.objective <= FAST_FALL * objectives[k - 1 - FAST_WINDOW];
            let going = fast && info.objective <= near && info.objective > explained;
            if k >= limit && !going {
                Control::Stop
            } else {
                Control::Continue
            }
        };
        cgls(&restricted, y, b, &extended, &mut go_on).map_err(|e| match e {
            Error::Breakdown { reason, .. } => Error::Breakdown {
                solver: NAME,
                reason: format!("least squares at iteration {it}: {reason}"),
            },
            other => other,
        })?;
    }
    Ok(support_residual(restricted.as_ref(), y, b))
}

/// y − A_S b.
pub(in crate::solver::pixelwise) fn residual<T, A>(
    op: &A,
    voxels: &[usize],
    y: &[T],
    b: &[T],
) -> Result<Vec<T>>
where
    T: Real,
    A: VoxelOperator<T> + ?Sized,
{
    Ok(support_residual(
        op.restrict_columns(voxels.to_vec())?.as_ref(),
        y,
        b,
    ))
}
