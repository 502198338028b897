//! Backprojection and per-column peak thresholding: the paper's reconstruction.

use crate::error::{Error, Result};
use crate::linalg::{column_peaks, PeakRule};
use crate::operator::LinearOperator;
use crate::real::Real;
use crate::space::{self, Space};

use super::check_measurements;

/// How the per-column peaks are thresholded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Threshold {
    /// Keep every column's peak.
    None,
    /// Keep peaks of at least this value (after normalization).
    Absolute(f64),
    /// Keep peaks of at least this fraction of the largest peak.
    RelativeToMax(f64),
    /// Keep peaks of at least `fraction` times the `quantile` of the per-column peaks: the
    /// largest peak made robust to a few outliers (a strong isolated voxel, a noise spike). With
    /// most columns lit, as in the paper's scenes, the quantile is a typical strong return.
    PeakQuantile {
        /// Which quantile of the per-column peaks, in [0, 1] (0.99: the 99th percentile).
        quantile: f64,
        /// The fraction of it a peak must reach, in [0, 1].
        fraction: f64,
    },
    /// Keep peaks above median + k·σ of all backprojected values, with σ = 1.4826·MAD (a robust
    /// estimate of the cross-talk and noise floor, valid when most voxels are empty).
    Auto {
        /// How many robust standard deviations above the median.
        k: f64,
    },
}

/// Parameters of [`backprojection`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Backprojection {
    /// Length of each column (K_s for a lidar scene): the unknowns are `ncols / column_len`
    /// columns, each with at most one detected peak.
    pub column_len: usize,
    /// The backprojection is divided by this before thresholding (e.g. K_p/4 for a 0/1 pulse with
    /// the zero-mean adjoint, which makes the peak an amplitude estimate).
    pub normalization: f64,
    /// Thresholding rule.
    pub threshold: Threshold,
}

/// What [`backprojection`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct BackprojectionResult<T> {
    /// The estimate: each kept column's peak value at its position, zero elsewhere.
    pub x: Vec<T>,
    /// Per column: the peak's index, or −1 where it was thresholded away.
    pub peaks: Vec<i32>,
    /// The normalized backprojection A*y / normalization.
    pub backprojection: Vec<T>,
    /// The threshold value applied (0 for [`Threshold::None`]).
    pub threshold: f64,
}

/// x̃ = A*y / normalization, then the largest entry of each column, kept if it passes the
/// threshold.
///
/// Pass the operator whose adjoint is the matched filter: for the lidar, the plain operator gives
/// the paper's backprojection, its zero-mean-pulse version the debiased one (docs/math.md §4).
///
/// # Errors
/// [`Error::InvalidParameter`] if `column_len` is zero or does not divide the number of unknowns,
/// if the normalization is not a positive finite number or a threshold parameter is invalid;
/// shape and finiteness errors for `y`.
pub fn backprojection<T: Real, A: LinearOperator<T> + ?Sized>(
    op: &A,
    y: &[T],
    params: &Backprojection,
) -> Result<BackprojectionResult<T>> {
    let n = op.ncols();
    let cl = params.column_len;
    if cl == 0 || n % cl != 0 {
        return Err(Error::param(
            "column_len",
            format!("must be positive and divide the {n} unknowns, got {cl}"),
        ));
    }
    if !(params.normalization.is_finite() && params.normalization > 0.0) {
        return Err(Error::param(
            "normalization",
            format!(
                "must be positive and finite, got {}",
                crate::units::number(params.normalization)
            ),
        ));
    }
    match params.threshold {
        Threshold::Absolute(v) if !v.is_finite() => {
            return Err(Error::param(
                "threshold",
                format!("must be finite, got {}", crate::units::number(v)),
            ))
        }
        Threshold::RelativeToMax(f) if !(0.0..=1.0).contains(&f) => {
            return Err(Error::param(
                "threshold",
                format!(
                    "relative threshold must be in [0, 1], got {}",
                    crate::units::number(f)
                ),
            ))
        }
        Threshold::PeakQuantile { quantile, fraction }
            if !((0.0..=1.0).contains(&quantile) && (0.0..=1.0).contains(&fraction)) =>
        {
            return Err(Error::param(
                "threshold",
                format!(
                    "peak quantile and fraction must be in [0, 1], got {} and {}",
                    crate::units::number(quantile),
                    crate::units::number(fraction)
                ),
            ))
        }
        Threshold::Auto { k } if !(k.is_finite() && k >= 0.0) => {
            return Err(Error::param(
                "threshold",
                format!("k must be finite and ≥ 0, got {}", crate::units::number(k)),
            ))
        }
        _ => {}
    }
    check_measurements("backprojection", op.nrows(), y)?;
    let mut bp = vec![T::zero(); n];
    op.apply_adjoint(y, &mut bp);
    let inv = T::of_f64(1.0 / params.normalization);
    bp.iter_mut().for_each(|v| *v = *v * inv);
    let selection = select_peaks_in(op.space(), &bp, cl, params.threshold);
    Ok(BackprojectionResult {
        x: selection.x,
        peaks: selection.peaks,
        backprojection: bp,
        threshold: selection.threshold,
    })
}

/// The `q`-quantile of the values `v` of every part (nearest rank, `q` in [0, 1]); −∞ when there
/// are none. Reorders `v`.
fn quantile_of(space: &dyn Space, v: &mut [f64], q: f64) -> f64 {
    let n = space::count(space, v.len());
    if n == 0 {
        return f64::NEG_INFINITY;
    }
    let rank = ((q * (n - 1) as f64).round() as usize).min(n - 1);
    space::kth_smallest(space, v, rank)
}

/// What [`select_peaks`] keeps.
#[derive(Debug, Clone, PartialEq)]
pub struct PeakSelection<T> {
    /// Each kept column's peak value at its position, zero elsewhere.
    pub x: Vec<T>,
    /// Per column: the peak's index, or −1 where there is none or it was thresholded away.
    pub peaks: Vec<i32>,
    /// The threshold value applied (0 for [`Threshold::None`]).
    pub threshold: f64,
}

/// One return per column: each column's largest value ([`PeakRule::Largest`]), kept when it is
/// positive and at least the threshold. The threshold's parameters are not checked here (see
/// [`backprojection`]).
///
/// # Panics
/// If `column_len` is zero or does not divide `values.len()`.
pub fn select_peaks<T: Real>(
    values: &[T],
    column_len: usize,
    threshold: Threshold,
) -> PeakSelection<T> {
    select_peaks_in(&space::WHOLE, values, column_len, threshold)
}

/// [`select_peaks`] on `values` that are one part of a vector split into parts of whole columns:
/// the threshold is that of the whole vector.
pub(crate) fn select_peaks_in<T: Real>(
    space: &dyn Space,
    values: &[T],
    column_len: usize,
    threshold: Threshold,
) -> PeakSelection<T> {
    let found = column_peaks(values, column_len, PeakRule::Largest);
    let threshold = match threshold {
        Threshold::None => f64::NEG_INFINITY,
        Threshold::Absolute(v) => v,
        Threshold::RelativeToMax(f) => {
            let local = found
                .iter()
                .flatten()
                .map(|p| p.1)
                .fold(f64::NEG_INFINITY, f64::max);
            f * space::max(space, local)
        }
        Threshold::PeakQuantile { quantile, fraction } => {
            let mut peaks: Vec<f64> = found.iter().flatten().map(|p| p.1).collect();
            fraction * quantile_of(space, &mut peaks, quantile)
        }
        Threshold::Auto { k } => {
            let mut all: Vec<f64> = values.iter().map(|v| v.as_f64()).collect();
            let med = space::median(space, &mut all);
            med + k * space::robust_sigma(space, &mut all, med)
        }
    };
    let mut x = vec![T::zero(); values.len()];
    let peaks = found
        .iter()
        .enumerate()
        .map(|(c, p)| match *p {
            Some((j, v)) if v >= threshold && v > 0.0 => {
                x[c * column_len + j] = T::of_f64(v);
                j as i32
            }
            _ => -1,
        })
        .collect();
    PeakSelection {
        x,
        peaks,
        threshold: if threshold.is_finite() {
            threshold
        } else {
            0.0
        },
    }
}
