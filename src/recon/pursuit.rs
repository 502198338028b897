//! Support pursuit: a greedy solver whose support grows from the data until least squares on it
//! explains the measurements — the cheap first stage of [`Method::Auto`](super::Method::Auto) and
//! a method of its own ([`Method::SupportLs`](super::Method::SupportLs)).

use std::ops::ControlFlow;

use crate::error::Result;
use crate::lidar::LidarOperator;
use crate::linalg::dot;
use crate::operator::{Counted, LinearOperator};
use crate::real::Real;
use crate::solver::{solve_with, Iteration, Iterative, Progress, Report, Stopping, Termination};
use crate::space;

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
/// out join. [`Method::Auto`](super::Method::Auto) takes a residual for noise only when it holds
/// at most K / this returns' energy.
pub(super) const HIDDEN_RATIO: f64 = 100.0;

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

/// ‖y − Ax‖ / ‖y‖ in f64, with the sparse forward when `x` is sparse; adds the application to
/// `report`.
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
    let op = Counted::new(op);
    let mut ax = vec![T::zero(); y.len()];
    let nnz = space::count(op.space(), x.iter().filter(|v| **v != T::zero()).count());
    if 3 * nnz < y.len() {
        op.apply_sparse(x, &mut ax);
    } else {
        op.apply(x, &mut ax);
    }
    report.add_applies(op.applies());
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
    let mut x = vec![T::zero(); op.ncols()];
    let (report, run) = solve_with::<T, _, (), PursuitIteration<T>>(
        &op,
        y,
        &mut x,
        &Stopping::iterations(max_rounds.max(1)),
        &mut (),
    )?;
    let (relative_residual, end) = match run {
        Some(run) => (run.rel, run.end),
        None => (0.0, PursuitEnd::Explained),
    };
    Ok(Pursuit {
        x,
        report,
        relative_residual,
        end,
    })
}

/// The state of [`support_pursuit`] between rounds (the protocol of
/// [`Iteration`](crate::solver::Iteration)).
pub(super) struct PursuitIteration<T> {
    ynorm: f64,
    /// The relative residual at which the data are explained.
    tol: f64,
    /// The largest support.
    cap: usize,
    /// y − Ax, its relative norm, and the correlations of the residual.
    r: Vec<T>,
    rel: f64,
    u: Vec<T>,
    /// The voxels that join in the next round, strongest first.
    candidates: Vec<(usize, f64)>,
    prev: Vec<T>,
    end: PursuitEnd,
}

impl<T: Real> Iterative<T> for PursuitIteration<T> {
    const NAME: &'static str = "support-ls";
    /// The round limit (and a time limit, if any).
    type Params = Stopping;

    fn stopping(stopping: &Stopping) -> Stopping {
        *stopping
    }

    fn check_params(stopping: &Stopping) -> Result<()> {
        stopping.validate()
    }
}

impl<T: Real, A: LidarOperator<T>> Iteration<T, A> for PursuitIteration<T> {
    fn start(
        op: &A,
        y: &[T],
        x: &mut [T],
        _stopping: &Stopping,
    ) -> Result<ControlFlow<Termination, Self>> {
        let ynorm = dot(y, y).sqrt();
        x.fill(T::zero());
        if ynorm == 0.0 {
            return Ok(ControlFlow::Break(Termination::ZeroResidual));
        }
        let cap = ((PURSUIT_MAX_FRACTION * y.len() as f64) as usize).max(1);
        Ok(ControlFlow::Continue(PursuitIteration {
            ynorm,
            tol: explained_tolerance::<T>(),
            cap,
            r: y.to_vec(),
            rel: 1.0,
            u: vec![T::zero(); op.ncols()],
            candidates: Vec::new(),
            prev: x.to_vec(),
            end: PursuitEnd::Rounds,
        }))
    }

    /// Correlates the residual with every voxel (one adjoint with the zero-mean pulse) and
    /// keeps each pixel's best voxel outside the support that stands out of the cross-talk;
    /// ends the run when none does ([`Termination::Converged`]) or the support is full
    /// ([`Termination::Stagnation`]).
    fn prepare(&mut self, op: &A) -> Option<Termination> {
        let ks = op.geometry().ks;
        let space = op.space();
        op.correlate(&self.r, &mut self.u);
        let mut all: Vec<f64> = self.u.iter().map(|v| v.as_f64()).collect();
        let med = space::median(space, &mut all);
        let level = med + CANDIDATE_Z * space::robust_sigma(space, &mut all, med);
        // Each pixel's best positive voxel outside the support.
        let x = &self.prev;
        let candidates: Vec<(usize, f64)> = self
            .u
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
        // Those that stand out of the cross-talk join; while the unexplained returns are many
        // and the support already holds more, as many as it holds, so that it can double each
        // round while their cross-talk still hides true returns.
        let standing = space::count(space, candidates.iter().filter(|c| c.1 >= level).count());
        if standing == 0 {
            self.end = PursuitEnd::NoCandidate;
            return Some(Termination::Converged);
        }
        let held = space::count(space, x.iter().filter(|v| **v != T::zero()).count());
        if held >= self.cap {
            self.end = PursuitEnd::TooLarge;
            return Some(Termination::Stagnation);
        }
        let k = self.r.len();
        let joining = if unexplained_returns(op, x, &self.r) * HIDDEN_RATIO > k as f64 {
            standing.max(held)
        } else {
            standing
        };
        // The strongest, the lower voxel first among equals.
        let scores: Vec<f64> = candidates.iter().map(|c| c.1).collect();
        let joining = space::largest_by(space, &scores, joining.min(self.cap - held));
        self.candidates = joining.into_iter().map(|i| candidates[i]).collect();
        None
    }

    fn step(&mut self, op: &A, y: &[T], x: &mut [T], _it: usize) -> Result<Progress> {
        let (ynorm, tol) = (self.ynorm, self.tol);
        // Start each newcomer at its correlation over its column's squared norm.
        let newcomers: Vec<usize> = self.candidates.iter().map(|c| c.0).collect();
        let norms = op.column_norms(&newcomers);
        for ((v, c), a) in self.candidates.iter().zip(&norms) {
            let start = if *a > 0.0 { c / (a * a) } else { 0.0 };
            // The correlation uses the zero-mean pulse, which underestimates; any positive
            // start keeps the voxel in the support for the least squares.
            x[*v] = T::of_f64(start.max(f64::MIN_POSITIVE.sqrt()));
        }
        // A short warm-started least squares; the amplitude test; a full refit only when the
        // support may be final.
        refit_support(op, y, x, ROUND_LS_ITER, 1)?;
        let mut r = residual(op, y, x);
        prune(op, x, &r, ynorm);
        r = residual(op, y, x);
        let mut new_rel = dot(&r, &r).sqrt() / ynorm;
        if new_rel <= POLISH_BELOW || new_rel > (1.0 - MIN_PROGRESS) * self.rel {
            // The polish: least squares to the explained tolerance, the amplitude test, then
            // least squares on what is left as far as round-off allows. Testing before the
            // last fit spares it the voxels that the test drops.
            refit_support_to(op, y, x, REFIT_MAX_ITER, 1, tol)?;
            r = residual(op, y, x);
            prune(op, x, &r, ynorm);
            refit_support(op, y, x, REFIT_MAX_ITER, REFIT_ROUNDS)?;
            r = residual(op, y, x);
            new_rel = dot(&r, &r).sqrt() / ynorm;
        }
        let ending = if new_rel <= tol {
            self.end = PursuitEnd::Explained;
            Some(Termination::Residual)
        } else if new_rel > (1.0 - MIN_PROGRESS) * self.rel {
            self.end = PursuitEnd::Stalled;
            Some(Termination::Stagnation)
        } else {
            None
        };
        self.rel = new_rel;
        let rr = dot(&r, &r);
        self.r = r;
        let change = space::relative_change(op.space(), x, &self.prev);
        self.prev.copy_from_slice(x);
        Ok(Progress {
            ending,
            ..Progress::least_squares(rr, ynorm, change, false)
        })
    }

    fn objective(&self) -> f64 {
        0.5 * dot(&self.r, &self.r)
    }

    /// The last fit may leave round-off amplitudes on voxels the data do not need.
    fn finish(&mut self, op: &A, _y: &[T], x: &mut [T], _termination: Termination) -> Result<()> {
        prune(op, x, &self.r, self.ynorm);
        Ok(())
    }
}

/// The residual's energy in returns of the held voxels' mean energy (amplitude² times column
/// norm²): about how many returns are still unexplained. Infinite when nothing is held.
pub(super) fn unexplained_returns<T: Real>(op: &dyn LidarOperator<T>, x: &[T], r: &[T]) -> f64 {
    let support: Vec<usize> = (0..x.len()).filter(|&i| x[i] != T::zero()).collect();
    let norms = op.column_norms(&support);
    let held: f64 = support
        .iter()
        .zip(&norms)
        .map(|(&v, a)| (x[v].as_f64() * a).powi(2))
        .sum();
    let [held, count] = space::sums(op.space(), [held, support.len() as f64]);
    if held <= 0.0 {
        return f64::INFINITY;
    }
    dot(r, r) * count / held
}

/// The amplitude test: zeroes the voxels whose amplitude times column norm is below
/// [`AMPLITUDE_Z`] standard deviations of the residual `r` (at least 100 machine epsilons of the
/// measurements' RMS, which bounds the dynamic range of noise-free fits).
fn prune<T: Real>(op: &dyn LidarOperator<T>, x: &mut [T], r: &[T], ynorm: f64) {
    let k = r.len();
    let support: Vec<usize> = (0..x.len()).filter(|&i| x[i] != T::zero()).collect();
    let dof = k
        .saturating_sub(space::count(op.space(), support.len()))
        .max(1);
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

/// y − Ax with the sparse forward.
fn residual<T: Real>(op: &dyn LidarOperator<T>, y: &[T], x: &[T]) -> Vec<T> {
    let mut ax = vec![T::zero(); y.len()];
    op.apply_sparse(x, &mut ax);
    ax.iter().zip(y).map(|(&a, &b)| b - a).collect()
}
