//! From a voxel estimate to one return per pixel, and the lidar backprojection with its
//! normalization and robust threshold.

use crate::error::{Error, Result};
use crate::lidar::{Geometry, RdOperator};
use crate::real::Real;
use crate::solver::{backprojection, select_peaks, Backprojection, Threshold};

/// How many robust standard deviations above the median a per-pixel peak must be to count as a
/// return ([`Threshold::Auto`]).
const AUTO_K: f64 = 3.0;

/// Peaks of an iterative estimate below this fraction of the strongest peak are dropped: they are
/// the numerical residue of empty pixels, not returns.
const RELATIVE_FLOOR: f64 = 0.05;

/// The (plain or debiased) backprojection with the lidar normalization and the robust threshold.
pub(super) fn backproject<T: Real>(
    op: &RdOperator<T>,
    y: &[T],
    debiased: bool,
) -> Result<crate::solver::BackprojectionResult<T>> {
    let p = op.pulse();
    let (filter, normalization) = if debiased {
        let z = op.zero_mean();
        // Σ (p − mean p)·p: the lag-0 correlation of the matched filter with the pulse.
        let norm: f64 = z
            .pulse()
            .iter()
            .zip(p)
            .map(|(a, b)| a.as_f64() * b.as_f64())
            .sum();
        (Some(z), norm)
    } else {
        (None, p.iter().map(|v| v.as_f64().powi(2)).sum())
    };
    if !(normalization.is_finite() && normalization > 0.0) {
        return Err(Error::param(
            "pulse",
            "backprojection needs a pulse with at least two distinct values (its matched-filter \
             gain is zero)",
        ));
    }
    let params = Backprojection {
        column_len: op.geometry().ks,
        normalization,
        threshold: Threshold::Auto { k: AUTO_K },
    };
    match &filter {
        Some(z) => backprojection(z, y, &params),
        None => backprojection(op, y, &params),
    }
}

/// One return per pixel from a voxel estimate: each pixel's largest positive entry, kept above the
/// robust threshold median + [`AUTO_K`]·σ of all entries ([`select_peaks`]), then peaks below
/// [`RELATIVE_FLOOR`] of the strongest dropped.
pub(super) fn pixel_peaks<T: Real>(x: &[T], g: Geometry) -> Vec<T> {
    let auto = select_peaks(x, g.ks, Threshold::Auto { k: AUTO_K });
    select_peaks(&auto.x, g.ks, Threshold::RelativeToMax(RELATIVE_FLOOR)).x
}
