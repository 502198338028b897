//! A detection test at a false-detection rate the user chooses: each return of an estimate is
//! kept only if its least-squares amplitude reaches the bar at which an empty pixel would show a
//! return with probability at most α under white Gaussian noise.
//!
//! Least squares on the estimate's support gives each return an amplitude `b_v` with standard error
//! about σ/(‖A_v‖·√(1 − |S|/K)), σ estimated from the residual over its K − |S| degrees of freedom,
//! K the rows of the operator that are not identically zero (censored samples,
//! [`Acquisition::censor`](crate::acquisition::Acquisition::censor), are not measurements). An
//! empty pixel offers K_s depths, so its best z-score is the largest of K_s (nearly independent)
//! standard normals: the bar Q⁻¹(α/K_s) holds its chance of a false return at α or below
//! (one-sided: reflectivities are ≥ 0). Returns below the bar are dropped and the rest refitted
//! until none drops.
//!
//! The test holds the rate where the residual is noise: with several measurements per return
//! (at 8 per lit pixel, 0–0.58% of the empty pixels at α = 0.01 on random half-lit scenes). Where
//! the fit leaves part of the scene unexplained (a few measurements per lit pixel), false returns
//! absorb it and reach z-scores like the true ones': no bar on amplitudes separates them there,
//! and the rate is not held. Where the support holds more than half as many voxels as there are
//! measurements least squares cannot test it, and nothing is dropped.

use crate::error::{Error, Result};
use crate::lidar::LidarOperator;
use crate::operator::Applies;
use crate::real::Real;
use crate::solver::Report;
use crate::space;

use super::refit::{refit_support, REFIT_MAX_ITER, REFIT_ROUNDS};

/// One forward application, made outside a counter.
const ONE_FORWARD: Applies = Applies {
    forward: 1,
    adjoint: 0,
    support: 0,
};

/// Rounds of testing and refitting at most.
const TEST_ROUNDS: usize = 8;

/// What the false-detection test did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DetectionTest {
    /// α: the chance of a false return in an empty pixel the test allows.
    pub false_rate: f64,
    /// The bar in standard errors, Q⁻¹(α/K_s).
    pub bar: f64,
    /// The residual's standard deviation σ at the last round (0 if the test did not run).
    pub sigma: f64,
    /// Returns before the test.
    pub tested: usize,
    /// Returns the test dropped.
    pub dropped: usize,
    /// Why the test could not run, if it could not.
    pub skipped: Option<&'static str>,
}

impl DetectionTest {
    /// One line: the rate, the bar and what was dropped (or why nothing was tested).
    pub fn describe(&self) -> String {
        let head = format!(
            "false-detection test at α = {} (bar {:.2} standard errors)",
            self.false_rate, self.bar
        );
        match self.skipped {
            Some(why) => format!("{head}: not run, {why}"),
            None => format!(
                "{head}: dropped {} of {} returns (σ = {:.3e})",
                self.dropped, self.tested, self.sigma
            ),
        }
    }
}

/// Checks α: finite, in (0, 1).
///
/// # Errors
/// [`Error::InvalidParameter`] (`false_rate`).
pub fn check_false_rate(alpha: f64) -> Result<()> {
    if alpha.is_finite() && alpha > 0.0 && alpha < 1.0 {
        Ok(())
    } else {
        Err(Error::param(
            "false_rate",
            format!(
                "the false-detection rate must lie strictly between 0 and 1, got {}",
                crate::units::number(alpha)
            ),
        ))
    }
}

/// The upper-tail quantile of the standard normal: z with P(Z > z) = p, for p in (0, 1)
/// (+∞ for p ≤ 0, −∞ for p ≥ 1, NaN for NaN). Newton's method on the logarithm of the tail
/// probability from a rational first guess; within 10⁻⁹ of reference values from p = 0.975 to
/// 10⁻⁹ (tested), finite and increasing down to 10⁻³⁰⁰.
pub fn normal_upper_quantile(p: f64) -> f64 {
    if p.is_nan() {
        return f64::NAN;
    }
    if p <= 0.0 {
        return f64::INFINITY;
    }
    if p >= 1.0 {
        return f64::NEG_INFINITY;
    }
    if p > 0.5 {
        return -normal_upper_quantile(1.0 - p);
    }
    if p == 0.5 {
        return 0.0;
    }
    // First guess (a classic rational approximation in t = √(−2 ln p), error below 5·10⁻⁴).
    let t = (-2.0 * p.ln()).sqrt();
    let mut z = t
        - (2.515517 + t * (0.802853 + t * 0.010328))
            / (1.0 + t * (1.432788 + t * (0.189269 + t * 0.001308)));
    // Newton on ln Q(z) = ln p: d/dz ln Q(z) = −φ(z)/Q(z), robust far into the tail.
    for _ in 0..6 {
        let q = normal_tail(z);
        if q <= 0.0 {
            break;
        }
        let phi = (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
        let step = (q.ln() - p.ln()) * q / phi;
        z += step;
        if step.abs() < 1e-14 * z.abs().max(1.0) {
            break;
        }
    }
    z
}

/// Q(z) = P(Z > z) for z ≥ 0: erfc by its continued fraction beyond 2, by the series of erf
/// below.
pub(super) fn normal_tail(z: f64) -> f64 {
    let x = z / std::f64::consts::SQRT_2;
    0.5 * erfc(x)
}

/// The complementary error function for x ≥ 0.
fn erfc(x: f64) -> f64 {
    if x < 2.0 {
        // erf x = 2/√π · Σ (−1)ⁿ x^(2n+1) / (n! (2n+1)).
        let (mut term, mut sum) = (x, x);
        let x2 = x * x;
        for n in 1..200 {
            term *= -x2 / n as f64;
            let add = term / (2 * n + 1) as f64;
            sum += add;
            if add.abs() < 1e-17 * sum.abs() {
                break;
            }
        }
        1.0 - 2.0 / std::f64::consts::PI.sqrt() * sum
    } else {
        // erfc x = e^(−x²)/√π · 1/(x + 1/2/(x + 1/(x + 3/2/(x + …)))), evaluated from the tail.
        let mut f = x;
        for n in (1..120).rev() {
            f = x + (n as f64 / 2.0) / f;
        }
        (-x * x).exp() / std::f64::consts::PI.sqrt() / f
    }
}

/// Runs the test on the estimate `x` of `op` from `y`, in place (see the module's
/// documentation); the refits' applications are added to `report`.
///
/// # Errors
/// [`Error::InvalidParameter`] (`false_rate`) for α outside (0, 1); the refits' errors.
pub(super) fn false_rate_test<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    x: &mut [T],
    alpha: f64,
    report: &mut Option<Report>,
) -> Result<DetectionTest> {
    check_false_rate(alpha)?;
    let space = op.space();
    let ks = op.geometry().ks.max(1);
    let held = |x: &[T]| space::count(space, x.iter().filter(|v| **v != T::zero()).count());
    let mut test = DetectionTest {
        false_rate: alpha,
        bar: normal_upper_quantile(alpha / ks as f64),
        sigma: 0.0,
        tested: held(x),
        dropped: 0,
        skipped: None,
    };
    let k = measured_rows(op);
    if let Some(r) = report.as_mut() {
        r.add_applies(ONE_FORWARD);
    }
    let ynorm = crate::linalg::norm2_sq(y).sqrt();
    // Each round refits the support, then tests it; a round that drops nothing ends the test,
    // and the last round only refits what the one before kept.
    for round in 0..=TEST_ROUNDS {
        let mut fit = x.to_vec();
        let Some(rep) = refit_support(op, y, &mut fit, REFIT_MAX_ITER, REFIT_ROUNDS)? else {
            if round == 0 {
                test.skipped = Some(if test.tested == 0 {
                    "no return to test"
                } else {
                    "the support holds more than half as many voxels as measurements"
                });
            }
            break;
        };
        if let Some(r) = report.as_mut() {
            r.absorb_applies(&rep);
        }
        x.copy_from_slice(&fit);
        if round == TEST_ROUNDS {
            break;
        }
        let support: Vec<usize> = (0..x.len()).filter(|&i| x[i] != T::zero()).collect();
        let n = space::count(space, support.len());
        let mut ax = vec![T::zero(); y.len()];
        op.apply(x, &mut ax);
        if let Some(r) = report.as_mut() {
            r.add_applies(ONE_FORWARD);
        }
        let rr: f64 = y
            .iter()
            .zip(&ax)
            .map(|(a, b)| (a.as_f64() - b.as_f64()).powi(2))
            .sum();
        let dof = k.saturating_sub(n).max(1) as f64;
        let floor = 100.0 * T::epsilon().as_f64() * ynorm / (k.max(1) as f64).sqrt();
        test.sigma = (rr / dof).sqrt().max(floor);
        let inflation = 1.0 / (1.0 - n as f64 / k as f64).max(0.05).sqrt();
        let norms = op.column_norms(&support);
        let mut dropped = 0;
        for (&v, c) in support.iter().zip(&norms) {
            if x[v].as_f64() * c < test.bar * test.sigma * inflation {
                x[v] = T::zero();
                dropped += 1;
            }
        }
        if space::count(space, dropped) == 0 {
            break;
        }
    }
    // Returns the test dropped, and those the refits' amplitudes left at zero or below.
    test.dropped = test.tested - held(x);
    Ok(test)
}

/// The rows of `op` that are not identically zero: a row is zero for every scene if and only
/// if it is zero for a random positive one (almost surely), which one application finds.
/// Censored samples (zero codes for every pixel) and samples no pulse sample reaches are not
/// measurements.
fn measured_rows<T: Real>(op: &dyn LidarOperator<T>) -> usize {
    use rand::{RngExt, SeedableRng};
    // Each process draws its own part of the scene; the application sums them.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5eed ^ op.space().part() as u64);
    let x: Vec<T> = (0..op.ncols())
        .map(|_| T::of_f64(rng.random_range(0.5..1.5)))
        .collect();
    let mut ax = vec![T::zero(); op.nrows()];
    op.apply(&x, &mut ax);
    ax.iter().filter(|v| **v != T::zero()).count()
}
