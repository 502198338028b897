//! A data term matched to photon noise: least squares weighted by the light each sample receives.
//!
//! Under photon (shot) noise the variance of sample k follows the light that reaches the
//! detectors at that sample, whatever the codes' signs: `v[k] = α·L[k] + β`, with
//! `L[k] = Σ_{m,n} (x[m,n,:] ⊛ p)[k]` the unmodulated light (the scene's light per depth bin,
//! summed over the pixels, convolved with the pulse) and β the ambient light, the dark counts and
//! any noise that does not follow the light. Least squares weighted by 1/v has `E[v]·E[1/v]` times
//! less variance than the unweighted fit, for columns uncorrelated with v.
//!
//! [`photon_weights`] estimates L from a first estimate and returns the weights w = 1/√v with
//! v = L + the background given (at least 5% of the mean light), unless the first estimate's
//! squared residual does not grow with the light (the slope of its regression on L, by ordinary
//! least squares, is the test; its intercept is not used: where the fit leaves part of the scene
//! unexplained the residual holds more than noise, and the intercept with it). The estimate is
//! then improved on W·A and W·y ([`RowWeighted`](crate::lidar::RowWeighted)).

use crate::error::{Error, Result};
use crate::lidar::LidarOperator;
use crate::operator::{Counted, LinearOperator};
use crate::real::Real;
use crate::solver::Report;

use super::pursuit::explained_tolerance;

/// How the measurement noise is modelled, which sets the data term.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum NoiseModel {
    /// White noise of one variance for every sample (Gaussian noise, ADC quantization):
    /// ordinary least squares.
    #[default]
    Gaussian,
    /// Photon noise: each sample's variance is proportional to the light it receives plus
    /// `background` (the ambient light and dark counts per sample, in the units of the scene's
    /// light: those of `rdlidar simulate --background`). The method runs, its estimate gives each
    /// sample's light, and the estimate is improved on the measurements weighted by the inverse
    /// standard deviations ([`PhotonWeighting`]).
    Photon {
        /// The background per sample, ≥ 0.
        background: f64,
    },
}

impl NoiseModel {
    /// The names of the models on the command line and in Python.
    pub const NAMES: [&'static str; 2] = ["gaussian", "photon"];

    /// The model's name.
    pub fn name(self) -> &'static str {
        match self {
            NoiseModel::Gaussian => Self::NAMES[0],
            NoiseModel::Photon { .. } => Self::NAMES[1],
        }
    }

    /// Checks the background of the photon model.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`background`) unless it is finite and ≥ 0.
    pub fn validate(self) -> Result<()> {
        match self {
            NoiseModel::Photon { background } if !(background.is_finite() && background >= 0.0) => {
                Err(Error::param(
                    "background",
                    format!(
                        "the background must be finite and >= 0, got {}",
                        crate::units::number(background)
                    ),
                ))
            }
            _ => Ok(()),
        }
    }
}

impl std::str::FromStr for NoiseModel {
    type Err = Error;

    /// `gaussian`, or `photon` (no background).
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "gaussian" => Ok(NoiseModel::Gaussian),
            "photon" => Ok(NoiseModel::Photon { background: 0.0 }),
            _ => Err(Error::param(
                "noise",
                format!("unknown noise model {s:?}: expected gaussian or photon"),
            )),
        }
    }
}

/// The light at every sample is at least this fraction of its mean in the weights, so that
/// samples with little light (where the pulse enters and leaves the scene's depths) do not get
/// weights without bound from an estimate of the light that misses a weak return.
const FLOOR_FRACTION: f64 = 0.05;

/// The reweighting runs only when the squared residual grows with the light: the slope of its
/// regression on the light must stand this many standard errors above zero.
const SLOPE_Z: f64 = 3.0;

/// What the photon-noise weighting found.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PhotonWeighting {
    /// The background of the model (as given).
    pub background: f64,
    /// The offset of the weights, v = L + offset: the background, at least 5% of the mean light.
    pub offset: f64,
    /// The variance per unit of light (plus offset) the first estimate's residual shows:
    /// mean r² / mean (L + offset).
    pub scale: f64,
    /// The slope of the regression of the squared residual on the light, over its standard
    /// error: how clearly the residual's variance grows with the light.
    pub slope_z: f64,
    /// The share of the mean variance that comes from the scene's light.
    pub light_share: f64,
    /// `E[v]·E[1/v]` over the samples: how many times less variance the weighted fit has than
    /// the unweighted one, for columns uncorrelated with v (1 when not reweighted).
    pub gain: f64,
    /// Why the estimate was not improved with the weights; `None` when it was.
    pub skipped: Option<&'static str>,
}

impl PhotonWeighting {
    /// One line: the variance model and what was done with it.
    pub fn describe(&self) -> String {
        let head = format!(
            "photon-noise weighting: variance {:.3e}·(light + {:.3e}) ({:.0}% from the scene's \
             light; the squared residual grows with the light by {:.1} standard errors)",
            self.scale,
            self.offset,
            100.0 * self.light_share,
            self.slope_z
        );
        match self.skipped {
            Some(why) => format!("{head}: not reweighted, {why}"),
            None => format!(
                "{head}: reweighted, {:.2} times less variance than unweighted",
                self.gain
            ),
        }
    }

    /// Marks the weights as not used, for `why`.
    pub(super) fn skip(&mut self, why: &'static str) {
        self.skipped = Some(why);
        self.gain = 1.0;
    }
}

/// The unmodulated light of every row: for each code set, (Σ_pixels max(x, 0)) ⊛ p at its K
/// rows, over the pixels some code reaches.
fn light<T: Real>(op: &dyn LidarOperator<T>, x: &[T]) -> Vec<f64> {
    let ks = op.geometry().ks;
    let observed = op.observed_pixels();
    let mut per_bin = vec![0.0f64; ks];
    for (p, column) in x.chunks(ks).enumerate() {
        if observed.as_ref().is_some_and(|o| !o[p]) {
            continue;
        }
        for (s, v) in per_bin.iter_mut().zip(column) {
            *s += v.as_f64().max(0.0);
        }
    }
    let pulse = op.pulse();
    let sets = op.code_sets().max(1);
    let k = op.nrows() / sets;
    let mut one = vec![0.0f64; k];
    for (d, &s) in per_bin.iter().enumerate() {
        if s == 0.0 {
            continue;
        }
        for (o, p) in one[d..].iter_mut().zip(pulse) {
            *o += s * p.as_f64();
        }
    }
    one.repeat(sets)
}

/// The weights w = 1/√v, v = L + max(background, [`FLOOR_FRACTION`]·mean L), scaled to a mean
/// square of 1 over the rows that are measurements, from the light L of the estimate `x`; or
/// `None` when the residual's variance does not grow with the light (its regression slope
/// below [`SLOPE_Z`] standard errors) or nothing is left unexplained. Adds the residual's
/// application to `report`.
///
/// # Errors
/// [`Error::ShapeMismatch`] if `y` or `x` does not fit the operator.
pub(super) fn photon_weights<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    x: &[T],
    background: f64,
    report: &mut Option<Report>,
) -> Result<(PhotonWeighting, Option<Vec<T>>)> {
    if y.len() != op.nrows() || x.len() != op.ncols() {
        let (what, expected, found) = if y.len() != op.nrows() {
            ("measurements vs operator rows", op.nrows(), y.len())
        } else {
            ("estimate vs operator columns", op.ncols(), x.len())
        };
        return Err(Error::shape(
            format!("photon weights: {what}"),
            expected,
            found,
        ));
    }
    let counted = Counted::new(op);
    let mut ax = vec![T::zero(); y.len()];
    let nnz = x.iter().filter(|v| **v != T::zero()).count();
    if 3 * nnz < y.len() {
        counted.apply_sparse(x, &mut ax);
    } else {
        counted.apply(x, &mut ax);
    }
    if let Some(r) = report.as_mut() {
        r.add_applies(counted.applies());
    }
    let light = light(op, x);
    // The rows that are measurements: a censored row is zero in the operator and the data.
    let measured: Vec<bool> = y
        .iter()
        .zip(&ax)
        .map(|(yk, ak)| *yk != T::zero() || *ak != T::zero())
        .collect();
    let rows: Vec<(f64, f64)> = y
        .iter()
        .zip(&ax)
        .zip(&light)
        .zip(&measured)
        .filter(|(_, m)| **m)
        .map(|(((yk, ak), l), _)| ((yk.as_f64() - ak.as_f64()).powi(2), *l))
        .collect();
    let n = rows.len() as f64;
    let mean_l = rows.iter().map(|r| r.1).sum::<f64>() / n.max(1.0);
    let mean_r = rows.iter().map(|r| r.0).sum::<f64>() / n.max(1.0);
    // Ordinary least squares of r² on L: the slope and its standard error.
    let sxx: f64 = rows.iter().map(|r| (r.1 - mean_l).powi(2)).sum();
    let sxy: f64 = rows.iter().map(|r| (r.1 - mean_l) * (r.0 - mean_r)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let sse: f64 = rows
        .iter()
        .map(|r| (r.0 - mean_r - slope * (r.1 - mean_l)).powi(2))
        .sum();
    let se = (sse / (n - 2.0).max(1.0) / sxx.max(f64::MIN_POSITIVE)).sqrt();
    let slope_z = if se > 0.0 && se.is_finite() && slope.is_finite() {
        slope / se
    } else {
        0.0
    };
    let offset = background.max(FLOOR_FRACTION * mean_l);
    let mut found = PhotonWeighting {
        background,
        offset,
        scale: mean_r / (mean_l + offset).max(f64::MIN_POSITIVE),
        slope_z,
        light_share: mean_l / (mean_l + offset).max(f64::MIN_POSITIVE),
        gain: 1.0,
        skipped: None,
    };
    let ynorm_sq: f64 = y.iter().map(|v| v.as_f64().powi(2)).sum();
    let explained = mean_r * n <= (explained_tolerance::<T>().powi(2) * ynorm_sq);
    found.skipped = if explained || !(mean_r.is_finite() && mean_l > 0.0) {
        Some("the estimate explains the data or has no light")
    } else if slope_z < SLOPE_Z {
        Some("the residual's variance does not grow clearly with the light")
    } else {
        None
    };
    if found.skipped.is_some() {
        return Ok((found, None));
    }
    let v: Vec<f64> = light.iter().map(|l| l + offset).collect();
    let (mut sum_v, mut sum_inv) = (0.0, 0.0);
    for (vk, _) in v.iter().zip(&measured).filter(|(_, m)| **m) {
        sum_v += vk;
        sum_inv += 1.0 / vk;
    }
    found.gain = sum_v * sum_inv / (n * n);
    // Scale: a mean square weight of 1 over the measurements.
    let scale = (n / sum_inv).sqrt();
    let w: Vec<T> = v.iter().map(|vk| T::of_f64(scale / vk.sqrt())).collect();
    Ok((found, Some(w)))
}
