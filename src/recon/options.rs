//! The settings of a reconstruction that every method shares, and the solver parameters they
//! set.

use crate::lidar::Response;
use crate::solver::{ModelBasedParams, Stopping};

use super::peaks::PeakThreshold;
use super::photon::NoiseModel;

/// Settings of [`reconstruct`](super::reconstruct) shared by every method.
#[derive(Debug, Clone, PartialEq)]
pub struct ReconstructOptions {
    /// Overrides the method's iteration limit (ignored by the backprojections).
    pub max_iter: Option<usize>,
    /// Shows a progress bar on stderr (when it is a terminal) during iterative solves.
    pub progress: bool,
    /// Seed of the randomized parts (the norm estimate behind FISTA's step).
    pub seed: u64,
    /// Overrides the number of Lanczos iterations that estimate ‖A‖² for [`Method::Fista`](super::Method::Fista)'s step
    /// (by default up to 200, until the estimate changes by less than 10⁻⁶: about 43 at
    /// 100×100×40, K_p = 10 000). Fewer iterations underestimate ‖A‖² a little (0.5–1% after 15
    /// at 100×100×40), so the step's safety margin grows from 1.01 to 1.05 when this is set.
    pub power_iterations: Option<usize>,
    /// The threshold rule of [`Method::Backprojection`](super::Method::Backprojection) and [`Method::BackprojectionDebiased`](super::Method::BackprojectionDebiased)
    /// (default [`PeakThreshold::Paper`]).
    pub threshold: PeakThreshold,
    /// Debias [`Method::Fista`](super::Method::Fista): least squares on the support of the lasso solution removes the
    /// shrinkage of the amplitudes (default `true`; skipped when the support has more than half
    /// as many voxels as there are measurements).
    pub debias: bool,
    /// Returns per pixel at most for [`Method::ModelBased`](super::Method::ModelBased): `Some(k)` (default `Some(1)`, the
    /// one-reflector model), or `None` to estimate k from the data (from a support pursuit,
    /// [`estimate_returns`](super::estimate_returns)).
    pub max_returns: Option<usize>,
    /// A false-detection rate α in (0, 1): after the method, each return is kept only if its
    /// least-squares amplitude passes the test at which an empty pixel shows a false return
    /// with probability at most α under white Gaussian noise, and the returns kept are
    /// refitted by least squares ([`DetectionTest`](super::DetectionTest); it holds the rate
    /// where the residual is noise, not with a few measurements per lit pixel). `None`
    /// (default): no test.
    pub false_rate: Option<f64>,
    /// The noise model that sets the data term (default [`NoiseModel::Gaussian`], ordinary
    /// least squares). With [`NoiseModel::Photon`] the method's estimate is then refined (the
    /// per-pixel solvers) or solved again (the generic ones) on the rows weighted by the inverse
    /// standard deviations that its light gives ([`PhotonWeighting`](super::PhotonWeighting)).
    pub noise: NoiseModel,
    /// The system's response (default [`Response::Delta`]: depths on the grid, today's model).
    /// With another response every method estimates each return's amplitude and continuous
    /// depth under it ([`Reconstruction::returns`](super::Reconstruction::returns)).
    pub response: Response,
}

impl Default for ReconstructOptions {
    fn default() -> Self {
        ReconstructOptions {
            max_iter: None,
            progress: false,
            seed: 0,
            power_iterations: None,
            threshold: PeakThreshold::Paper,
            debias: true,
            max_returns: Some(1),
            false_rate: None,
            noise: NoiseModel::Gaussian,
            response: Response::Delta,
        }
    }
}

/// `default` with the iteration limit that `options` override.
pub(super) fn stopping(default: Stopping, options: &ReconstructOptions) -> Stopping {
    Stopping {
        max_iter: options.max_iter.unwrap_or(default.max_iter),
        ..default
    }
}

/// The model-based solver's parameters under `options`.
pub(super) fn model_params(options: &ReconstructOptions) -> ModelBasedParams {
    let d = ModelBasedParams::default();
    ModelBasedParams {
        stopping: stopping(d.stopping, options),
        ..d
    }
}
