//! [`Method::CoarseToFine`](super::Method::CoarseToFine): TV on the depth map on a grid of 2×2
//! blocks, then the surfaces refined on the pixels.

use crate::error::Result;
use crate::lidar::{BlockOperator, LidarOperator};
use crate::operator::LinearOperator;
use crate::real::Real;
use crate::solver::{refine_surfaces, tv_depth, Observer, RefineParams, Report, TvDepthParams};

use super::method::ReconstructOptions;

/// The block of the coarse grid (rows, columns of pixels).
pub const COARSE_BLOCK: (usize, usize) = (2, 2);

/// Runs the coarse solve and the refinement on `op` into `x`; returns the report of both and the
/// support applications of the coarse grid's own (block-code) kernels, which `op`'s counter
/// does not see.
pub(super) fn coarse_to_fine<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    x: &mut [T],
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
) -> Result<(Report, usize)> {
    let g = op.geometry();
    let blocks = BlockOperator::new(op, COARSE_BLOCK)?;
    let mut coarse = vec![T::zero(); blocks.ncols()];
    let params = TvDepthParams {
        model: super::method::model_params(options),
        ..TvDepthParams::default()
    };
    let mut report = tv_depth(&blocks, blocks.grid(), y, &mut coarse, &params, observer)?;
    let uncounted = report.support_applies;
    blocks.upsample(&coarse, x);
    let refined = refine_surfaces(op, (g.m, g.n), y, x, &RefineParams::default())?;
    report.absorb(refined);
    report.solver = "coarse-to-fine";
    Ok((report, uncounted))
}
