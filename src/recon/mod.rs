//! Lidar reconstruction pipelines over the generic solvers and the lidar operator: the method
//! registry and its defaults, [`reconstruct`] with the `auto` rule, the per-pixel peak rule that
//! reduces a voxel estimate to one return per pixel, and the quality metrics against a truth.

mod auto;
mod method;
mod metrics;
mod peaks;
mod pursuit;
mod reconstruct;
mod refit;

pub use auto::{Stage, TV_RESIDUAL_MARGIN};
pub use method::{Method, PeakThreshold, ReconstructOptions};
pub use metrics::{compare, compare_depth, relative_error, Metrics};
pub use peaks::{PAPER_FRACTION, PAPER_QUANTILE};
pub use pursuit::explained_tolerance;
pub use reconstruct::{
    is_piecewise_smooth, reconstruct, Reconstruction, SMOOTH_BINS, SMOOTH_FRACTION,
};
