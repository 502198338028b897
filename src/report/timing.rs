//! Wall-clock timing of the fused operator: the one timer behind `rdlidar bench` and the
//! calibrated rates of the cost model.

use std::time::Instant;

use serde::Serialize;

use crate::lidar::RdOperator;
use crate::operator::LinearOperator;
use crate::real::Real;

/// Median and minimum wall time of one operation, in seconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Timing {
    /// The median of the timed runs.
    pub median_s: f64,
    /// The fastest timed run.
    pub min_s: f64,
}

/// Wall time of the warm-up before the timed runs, in seconds. A fresh process's first
/// applications can run far slower than its later ones (docs/performance.md: the forward at
/// 100×100×40, K_p 10 000, on two threads, a median of 17–18 ms after one warm-up run against
/// 12.8–13.3 ms after 0.3 s of runs), so the warm-up lasts a given time, not a given count.
pub const WARM_UP_S: f64 = 0.5;

/// Runs `f` as a warm-up, at least once and for at least [`WARM_UP_S`] seconds, then `repeats`
/// (at least 1) timed times.
pub fn time_runs(repeats: usize, mut f: impl FnMut()) -> Timing {
    let warm = Instant::now();
    f();
    while warm.elapsed().as_secs_f64() < WARM_UP_S {
        f();
    }
    let mut t: Vec<f64> = (0..repeats.max(1))
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    Timing {
        median_s: crate::linalg::median_sorted(&t),
        min_s: t[0],
    }
}

/// The timings of the three dense and sparse operations of the fused operator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OperatorTimings {
    /// The dense forward over all voxels ([`RdOperator::apply_dense`]).
    pub forward: Timing,
    /// The adjoint (backprojection).
    pub adjoint: Timing,
    /// The forward over the nonzero voxels only ([`RdOperator::apply_sparse`]).
    pub sparse_forward: Timing,
}

/// Times the dense forward and the sparse forward on the scene `x` and the adjoint on its
/// measurements, each after a warm-up ([`time_runs`]) `repeats` times.
///
/// # Panics
/// If `x` does not have one value per column of `op`.
pub fn time_operator<T: Real>(op: &RdOperator<T>, x: &[T], repeats: usize) -> OperatorTimings {
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(x, &mut y);
    let y_in = y.clone();
    let mut xt = vec![T::zero(); op.ncols()];
    let forward = time_runs(repeats, || {
        op.apply_dense(std::hint::black_box(x), &mut y);
        std::hint::black_box(&y);
    });
    let adjoint = time_runs(repeats, || {
        op.apply_adjoint(std::hint::black_box(&y_in), &mut xt);
        std::hint::black_box(&xt);
    });
    let sparse_forward = time_runs(repeats, || {
        op.apply_sparse(std::hint::black_box(x), &mut y);
        std::hint::black_box(&y);
    });
    OperatorTimings {
        forward,
        adjoint,
        sparse_forward,
    }
}

/// Times the restricted adjoint: the adjoint for the nonzero voxels of the scene `x` only (the
/// operator restricted to its support, [`LinearOperator::restrict_columns`], what the solvers'
/// least squares on a support apply), on the scene's measurements, after a warm-up
/// ([`time_runs`]) `repeats` times.
///
/// # Panics
/// If `x` does not have one value per column of `op`.
pub fn time_restricted_adjoint<T: Real>(op: &RdOperator<T>, x: &[T], repeats: usize) -> Timing {
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(x, &mut y);
    let support = crate::solver::support(x);
    let mut b = vec![T::zero(); support.len()];
    let restricted = op
        .restrict_columns(support)
        .expect("the support's columns are the operator's");
    time_runs(repeats, || {
        restricted.apply_adjoint(std::hint::black_box(&y), &mut b);
        std::hint::black_box(&b);
    })
}
