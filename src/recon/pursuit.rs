//! Support pursuit: a greedy solver whose support grows from the data until least squares on it
//! explains the measurements — the cheap first stage of [`Method::Auto`](super::Method::Auto) and
//! a method of its own ([`Method::SupportLs`](super::Method::SupportLs)).

use std::time::Instant;

use crate::error::Result;
use crate::lidar::LidarOperator;
use crate::linalg::{dot, median, robust_sigma};
use crate::real::Real;
use crate::solver::{Report, Termination};

use super::refit::{refit_support, refit_support_to, REFIT_MAX_ITER, REFIT_ROUNDS};

/// Rounds of [`support_pursuit`] at most: a safety net, as every round must lower the residual
/// by [`MIN_PROGRESS`]. Where the returns are many for the measurements (a semi-transparent
/// 32×32×40 scene at 3.9 measurements per return) the support keeps growing for 20–30 rounds
/// before it is exact.
pub(super) const PURSUIT_ROUNDS: usize = 100;

/// The support holds at most this fraction of the number of measurements: beyond it least
/// squares no longer separates true voxels from cross-talk, and a structured model is needed.
pub(super) const PURSUIT_MAX_FRACTION: f64 = 1.0 / 3.0;

/// A candidate joins when its correlation with the residual is at least this many robust
/// standard deviations above the median of all correlations.
const CANDIDATE_Z: f64 = 3.0;

/// A voxel stays when its least-squares amplitude times its column norm is at least this many
/// residual standard deviations.
const AMPLITUDE_Z: f64 = 3.0;

/// CGLS iterations of each round's least squares (warm-started).
const ROUND_LS_ITER: usize = 8;

/// A round whose residual falls below this relative level gets a full refit, which decides
/// whether the data are explained.
const POLISH_BELOW: f64 = 1e-3;

/// A round must lower the residual by at least this fraction, or the pursuit has stalled.
const MIN_PROGRESS: f64 = 0.05;

/// The unexplained returns' cross-talk may hide true returns while there are more than K / this
/// of them (counted in returns of the held voxels' mean energy): then a round adds as many
/// candidates as the support holds even when fewer stand out; otherwise only those that stand
/// out join.
const HIDDEN_RATIO: f64 = 100.0;

/// The relative residual ‖y − Ax‖/‖y‖ at or below which an estimate explains noise-free data:
/// 10⁻⁶, or 30 machine epsilons where that is larger (f32).
pub fn explained_tolerance<T: Real>() -> f64 {
    (30.0 * T::EPS).max(1e-6)
}

/// Why [`support_pursuit`] stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum PursuitEnd {
    /// Least squares on the support explains the data.
    Explained,
    /// The support would exceed [`PURSUIT_MAX_FRACTION`] of the measurements.
    TooLarge,
    /// No correlation of the residual stands out of the cross-talk: nothing left to add.
    NoCandidate,
    /// A round lowered the residual by less than [`MIN_PROGRESS`].
    Stalled,
    /// [`PURSUIT_ROUNDS`] or the iteration limit.
    Rounds,
}

impl PursuitEnd {
    /// One phrase for reports.
    pub(super) fn describe(self) -> &'static str {
        match self {
            PursuitEnd::Explained => "least squares on the support explains the data",
            PursuitEnd::TooLarge => {
                "the support would hold more than a third as many voxels as measurements"
            }
            PursuitEnd::NoCandidate => "no correlation of the residual stands out",
            PursuitEnd::Stalled => "a round lowered the residual by less than 5%",
            PursuitEnd::Rounds => "the round limit was reached",
        }
    }
}

/// What [`support_pursuit`] found.
pub(super) struct Pursuit<T> {
    pub x: Vec<T>,
    pub report: Report,
    pub relative_residual: f64,
    pub end: PursuitEnd,
}

/// ‖y − Ax‖ / ‖y‖ in f64, with the sparse forward when `x` is sparse; counts one application.
pub(super) fn relative_residual<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    x: &[T],
    report: &mut Report,
) -> f64 {
    let ynorm = dot(y, y).sqrt();
    if ynorm == 0.0 {
        return 0.0;
    }
    let mut ax = vec![T::zero(); y.len()];
    let nnz = x.iter().filter(|v| **v != T::zero()).count();
    if 3 * nnz < y.len() {
        op.apply_sparse(x, &mut ax);
        report.support_applies += 1;
    } else {
        op.apply(x, &mut ax);
        report.forward_applies += 1;
    }
    crate::linalg::dist2_sq(y, &ax).sqrt() / ynorm
}

/// Greedy support pursuit. Each round correlates the residual with every voxel (one adjoint with
/// the zero-mean pulse, [`VoxelOperator::correlate`]), adds each pixel's best voxel not yet in
/// the support when its correlation stands [`CANDIDATE_Z`] robust standard deviations above the
/// cross-talk, solves least squares on the support (warm-started CGLS on the restricted operator,
/// non-positive amplitudes dropped), and drops voxels whose amplitude is not significant against
/// the residual. No per-pixel constraint: pixels gain several returns over the rounds when the
/// data ask for them.
///
/// It stops when the residual is at most [`explained_tolerance`] of ‖y‖, when no candidate is
/// left, when a round gains less than [`MIN_PROGRESS`], when the support would exceed
/// [`PURSUIT_MAX_FRACTION`] of the measurements, or after `max_rounds`.
pub(super) fn support_pursuit<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    max_rounds: usize,
) -> Result<Pursuit<T>> {
    let start = Instant::now();
    let g = op.geometry();
    let (k, n, ks) = (y.len(), g.voxels(), g.ks);
    let tol = explained_tolerance::<T>();
    let cap = ((PURSUIT_MAX_FRACTION * k as f64) as usize).max(1);
    let mut report = Report {
        solver: "support-ls",
        iterations: 0,
        termination: Termination::MaxIterations,
        residual_history: Vec::new(),
        objective_history: Vec::new(),
        forward_applies: 0,
        adjoint_applies: 0,
        support_applies: 0,
        elapsed: Default::default(),
    };
    let mut x = vec![T::zero(); n];
    let ynorm = dot(y, y).sqrt();
    if ynorm == 0.0 {
        report.termination = Termination::ZeroResidual;
        report.elapsed = start.elapsed();
        return Ok(Pursuit {
            x,
            report,
            relative_residual: 0.0,
            end: PursuitEnd::Explained,
        });
    }
    let mut r = y.to_vec();
    let mut rel = 1.0;
    let mut u = vec![T::zero(); n];
    let mut end = PursuitEnd::Rounds;
    for round in 1..=max_rounds {
        report.iterations = round;
        op.correlate(&r, &mut u);
        report.adjoint_applies += 1;
        let mut all: Vec<f64> = u.iter().map(|v| v.as_f64()).collect();
        let med = median(&mut all);
        let level = med + CANDIDATE_Z * robust_sigma(&mut all, med);
        // Each pixel's best voxel outside the support, when it stands out.
        // Each pixel's best positive voxel outside the support, strongest first.
        let mut candidates: Vec<(usize, f64)> = u
            .chunks(ks)
            .enumerate()
            .filter_map(|(p, col)| {
                col.iter()
                    .enumerate()
                    .filter(|(j, _)| x[p * ks + j] == T::zero())
                    .map(|(j, v)| (p * ks + j, v.as_f64()))
                    .filter(|&(_, v)| v > 0.0)
                    .max_by(|a, b| a.1.total_cmp(&b.1))
            })
            .collect();
        candidates.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        // Those that stand out of the cross-talk join; while the unexplained returns are many
        // and the support already holds more, as many as it holds, so that it can double each
        // round while their cross-talk still hides true returns.
        let standing = candidates.iter().filter(|c| c.1 >= level).count();
        if standing == 0 {
            end = PursuitEnd::NoCandidate;
            break;
        }
        let held = x.iter().filter(|v| **v != T::zero()).count();
        if held >= cap {
            end = PursuitEnd::TooLarge;
            break;
        }
        let joining = if unexplained_returns(op, &x, &r) * HIDDEN_RATIO > k as f64 {
            standing.max(held)
        } else {
            standing
        };
        candidates.truncate(joining.min(cap - held));
        // Start each newcomer at its correlation over its column's squared norm.
        let newcomers: Vec<usize> = candidates.iter().map(|c| c.0).collect();
        let norms = op.column_norms(&newcomers);
        for ((v, c), a) in candidates.iter().zip(&norms) {
            let start = if *a > 0.0 { c / (a * a) } else { 0.0 };
            // The correlation uses the zero-mean pulse, which underestimates; any positive start
            // keeps the voxel in the support for the least squares.
            x[*v] = T::of_f64(start.max(f64::MIN_POSITIVE.sqrt()));
        }
        // A short warm-started least squares; the amplitude test; a full refit only when the
        // support may be final.
        if let Some(rep) = refit_support(op, y, &mut x, ROUND_LS_ITER, 1)? {
            report.absorb_applies(&rep);
        }
        r = residual(op, y, &x, &mut report);
        prune(op, &mut x, &r, ynorm);
        r = residual(op, y, &x, &mut report);
        let mut new_rel = dot(&r, &r).sqrt() / ynorm;
        if new_rel <= POLISH_BELOW || new_rel > (1.0 - MIN_PROGRESS) * rel {
            // The polish: least squares to the explained tolerance, the amplitude test, then
            // least squares on what is left as far as round-off allows. Testing before the
            // last fit spares it the voxels that the test drops.
            if let Some(rep) = refit_support_to(op, y, &mut x, REFIT_MAX_ITER, 1, tol)? {
                report.absorb_applies(&rep);
            }
            r = residual(op, y, &x, &mut report);
            prune(op, &mut x, &r, ynorm);
            if let Some(rep) = refit_support(op, y, &mut x, REFIT_MAX_ITER, REFIT_ROUNDS)? {
                report.absorb_applies(&rep);
            }
            r = residual(op, y, &x, &mut report);
            new_rel = dot(&r, &r).sqrt() / ynorm;
        }
        report.residual_history.push(new_rel);
        report.objective_history.push(0.5 * dot(&r, &r));
        if new_rel <= tol {
            rel = new_rel;
            end = PursuitEnd::Explained;
            report.termination = Termination::Residual;
            break;
        }
        if new_rel > (1.0 - MIN_PROGRESS) * rel {
            rel = new_rel;
            end = PursuitEnd::Stalled;
            report.termination = Termination::Stagnation;
            break;
        }
        rel = new_rel;
    }
    // The last fit may leave round-off amplitudes on voxels the data do not need.
    prune(op, &mut x, &r, ynorm);
    report.elapsed = start.elapsed();
    Ok(Pursuit {
        x,
        report,
        relative_residual: rel,
        end,
    })
}

/// The residual's energy in returns of the held voxels' mean energy (amplitude² times column
/// norm²): about how many returns are still unexplained. Infinite when nothing is held.
fn unexplained_returns<T: Real>(op: &dyn LidarOperator<T>, x: &[T], r: &[T]) -> f64 {
    let support: Vec<usize> = (0..x.len()).filter(|&i| x[i] != T::zero()).collect();
    let norms = op.column_norms(&support);
    let held: f64 = support
        .iter()
        .zip(&norms)
        .map(|(&v, a)| (x[v].as_f64() * a).powi(2))
        .sum();
    if held <= 0.0 {
        return f64::INFINITY;
    }
    dot(r, r) * support.len() as f64 / held
}

/// The amplitude test: zeroes the voxels whose amplitude times column norm is below
/// [`AMPLITUDE_Z`] standard deviations of the residual `r` (at least 100 machine epsilons of the
/// measurements' RMS, which bounds the dynamic range of noise-free fits).
fn prune<T: Real>(op: &dyn LidarOperator<T>, x: &mut [T], r: &[T], ynorm: f64) {
    let k = r.len();
    let support: Vec<usize> = (0..x.len()).filter(|&i| x[i] != T::zero()).collect();
    let dof = k.saturating_sub(support.len()).max(1);
    let sigma_r = (dot(r, r) / dof as f64)
        .sqrt()
        .max(100.0 * T::EPS * ynorm / (k as f64).sqrt());
    let norms = op.column_norms(&support);
    for (&v, &a) in support.iter().zip(&norms) {
        if x[v].as_f64() * a < AMPLITUDE_Z * sigma_r {
            x[v] = T::zero();
        }
    }
}

/// y − Ax with the sparse forward, counted as a support apply.
fn residual<T: Real>(op: &dyn LidarOperator<T>, y: &[T], x: &[T], report: &mut Report) -> Vec<T> {
    let mut ax = vec![T::zero(); y.len()];
    op.apply_sparse(x, &mut ax);
    report.support_applies += 1;
    ax.iter().zip(y).map(|(&a, &b)| b - a).collect()
}
