//! Lidar reconstruction pipelines over the generic solvers and the lidar operator: the method
//! registry and its defaults, [`reconstruct`] with the `auto` rule, the per-pixel peak rule that
//! reduces a voxel estimate to one return per pixel, and the quality metrics against a truth.

mod method;
mod metrics;
mod peaks;
mod reconstruct;

pub use method::{Method, ReconstructOptions};
pub use metrics::{compare, compare_depth, relative_error, Metrics};
pub use reconstruct::{
    is_piecewise_smooth, reconstruct, Reconstruction, SMOOTH_BINS, SMOOTH_FRACTION,
    TV_RESIDUAL_MARGIN,
};
