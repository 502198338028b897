//! From a voxel estimate to the returns it reports, and the lidar backprojection with its
//! normalization and threshold rules.

use crate::error::{Error, Result};
use crate::lidar::{Geometry, LidarOperator};
use crate::real::Real;
use crate::solver::{backprojection, Backprojection, Threshold};
use crate::space::{self, Space};

use std::str::FromStr;

use super::names::{by_name, name_of, names, values};

/// How the backprojections decide which per-pixel peaks are returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum PeakThreshold {
    /// The paper's rule (default): a pixel's peak counts when it reaches 0.4 times the 99th
    /// percentile of all per-pixel peaks ([`PAPER_FRACTION`] of the
    /// [`PAPER_QUANTILE`]): a level relative to the strong returns, which
    /// reproduces the quality of the paper's Fig. 2 on scenes with many lit pixels. It assumes
    /// the scene has returns: on an empty scene it keeps the strongest cross-talk.
    #[default]
    Paper,
    /// Median + 3σ of all backprojected values (σ = 1.4826·MAD): a level relative to the
    /// cross-talk and noise floor. It keeps fewer false returns on noisy or sparsely lit scenes
    /// and misses more weak ones.
    Robust,
}

impl PeakThreshold {
    /// Every rule with its command-line name: the one table of rules.
    const TABLE: [(PeakThreshold, &'static str); 2] = [
        (PeakThreshold::Paper, "paper"),
        (PeakThreshold::Robust, "robust"),
    ];
    /// The command-line names, in the order of [`PeakThreshold::ALL`].
    pub const NAMES: [&'static str; 2] = names(&PeakThreshold::TABLE);
    /// Every rule.
    pub const ALL: [PeakThreshold; 2] = values(&PeakThreshold::TABLE);

    /// The command-line name.
    pub fn name(self) -> &'static str {
        name_of(&PeakThreshold::TABLE, self)
    }
}

impl FromStr for PeakThreshold {
    type Err = Error;

    /// Parses `paper` or `robust`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`threshold`) listing the valid names.
    fn from_str(s: &str) -> Result<Self> {
        by_name(s, &PeakThreshold::TABLE, "threshold", "threshold rule")
    }
}

/// How many robust standard deviations above the median a value must be to count as a return
/// ([`Threshold::Auto`]).
const AUTO_K: f64 = 3.0;

/// Returns of an iterative estimate below this fraction of the strongest one are dropped: they are
/// the numerical residue of empty voxels, not returns.
const RELATIVE_FLOOR: f64 = 0.05;

/// The paper's rule ([`PeakThreshold::Paper`]): a pixel's peak counts when it reaches
/// [`PAPER_FRACTION`] of the [`PAPER_QUANTILE`] of all per-pixel peaks.
pub const PAPER_QUANTILE: f64 = 0.99;

/// See [`PAPER_QUANTILE`].
pub const PAPER_FRACTION: f64 = 0.4;

impl PeakThreshold {
    /// The rule as a [`Threshold`] of the backprojection.
    pub fn rule(self) -> Threshold {
        match self {
            PeakThreshold::Paper => Threshold::PeakQuantile {
                quantile: PAPER_QUANTILE,
                fraction: PAPER_FRACTION,
            },
            PeakThreshold::Robust => Threshold::Auto { k: AUTO_K },
        }
    }
}

/// The (plain or debiased) backprojection with the lidar normalization and the given threshold
/// rule.
pub(super) fn backproject<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    debiased: bool,
    threshold: PeakThreshold,
) -> Result<crate::solver::BackprojectionResult<T>> {
    let p = op.pulse();
    // Every column is the pulse modulated by `code_sets` code sets of ±1 (or 0) entries.
    let sets = op.code_sets() as f64;
    let (filter, normalization) = if debiased {
        let z = crate::lidar::zero_mean(p);
        // Σ (p − mean p)·p: the lag-0 correlation of the matched filter with the pulse.
        let norm: f64 = z.iter().zip(p).map(|(a, b)| a.as_f64() * b.as_f64()).sum();
        (Some(op.zero_mean_operator()), sets * norm)
    } else {
        (
            None,
            sets * p.iter().map(|v| v.as_f64().powi(2)).sum::<f64>(),
        )
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
        threshold: threshold.rule(),
    };
    match &filter {
        Some(z) => backprojection(z.as_ref(), y, &params),
        None => backprojection(op, y, &params),
    }
}

/// The returns an iterative estimate reports: every positive voxel above the robust threshold
/// median + [`AUTO_K`]·σ of all entries and at least [`RELATIVE_FLOOR`] of the strongest one;
/// the others are zeroed. A pixel may keep several returns (semi-transparent scenes); an estimate
/// with one nonzero per pixel keeps at most one.
///
/// `x` is the operator's part of the unknowns (`space`): the threshold is that of the whole.
pub(super) fn returns<T: Real>(space: &dyn Space, x: &[T], g: Geometry) -> Vec<T> {
    debug_assert_eq!(x.len(), g.voxels());
    let mut all: Vec<f64> = x.iter().map(|v| v.as_f64()).collect();
    let med = space::median(space, &mut all);
    let robust = med + AUTO_K * space::robust_sigma(space, &mut all, med);
    let strongest = space::max(space, x.iter().map(|v| v.as_f64()).fold(0.0, f64::max));
    let floor = robust.max(RELATIVE_FLOOR * strongest);
    x.iter()
        .map(|&v| {
            let f = v.as_f64();
            if f > 0.0 && f >= floor {
                v
            } else {
                T::zero()
            }
        })
        .collect()
}
