//! Lidar reconstruction pipelines over the generic solvers and the lidar operator: the method
//! registry and its defaults, [`reconstruct`] and the stages of `auto`, the support pursuit, the
//! least-squares refit on a support, the rule that extracts the returns of a voxel estimate, the
//! backprojection thresholds, and the quality metrics against a truth.

mod atoms;
mod auto;
mod bound;
mod coarse;
mod detect;
mod method;
mod metrics;
mod names;
mod options;
mod pairs;
mod peaks;
mod photon;
mod prior;
mod pursuit;
mod range_metrics;
mod reconstruct;
mod refit;
mod reseat;
mod subbin;
mod tiled;

pub use auto::{Stage, COARSE_RESIDUAL, SEVERAL_RETURNS_SHARE, TV_RESIDUAL_MARGIN};
pub use bound::{
    depth_bound, joint_bound_fits, joint_depth_bound, residual_sigma, JOINT_BOUND_MAX_WORK,
};
pub use coarse::COARSE_BLOCK;
pub use detect::{check_false_rate, normal_upper_quantile, DetectionTest};
pub use method::{estimate_returns, Method, MAX_RETURNS_ESTIMATE};
pub use metrics::{
    compare, compare_depth, compare_observed, relative_error, Metrics, ObservedComparison,
};
pub use options::ReconstructOptions;
pub use peaks::{PeakThreshold, PAPER_FRACTION, PAPER_QUANTILE};
pub use photon::{NoiseModel, PhotonWeighting};
pub use pursuit::explained_tolerance;
pub(crate) use range_metrics::millimetres;
pub use range_metrics::{compare_range, RangeMetrics};
pub use reconstruct::{
    is_piecewise_smooth, reconstruct, reconstruct_observed, Reconstruction, SMOOTH_BINS,
    SMOOTH_FRACTION,
};
pub(crate) use tiled::{assemble_tiles, decode_tiles, encode_tile};
pub use tiled::{
    tile_places, ArrayCodes, TilePlace, TileReconstruction, TiledArray, TiledReconstruction,
};
