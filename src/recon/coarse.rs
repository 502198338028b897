//! [`Method::CoarseToFine`](super::Method::CoarseToFine): TV on the depth map on a grid of 2×2
//! blocks, then the surfaces refined on the pixels.

use crate::error::Result;
use crate::lidar::{BlockOperator, Geometry, LidarOperator, MultiAdcOperator, RdOperator};
use crate::operator::{Applies, Counted, LinearOperator};
use crate::real::Real;
use crate::solver::{refine_surfaces, tv_depth, Observer, RefineParams, Report, TvDepthParams};

use super::options::{model_params, ReconstructOptions};

/// The block of the coarse grid (rows, columns of pixels).
pub const COARSE_BLOCK: (usize, usize) = (2, 2);

/// Runs the coarse solve and the refinement on `op` into `x`; returns the report of both and the
/// applications `op`'s counter does not see: the coarse grid's own (block-code) support
/// kernels, and, for an operator whose pixels are split across processes, every application of
/// the whole operator that each process solves on.
///
/// The coarse grid needs the whole scene's codes. Where the pixels are split across processes
/// ([`LidarOperator::gathered_code_sets`]), every process gathers them and runs the same solve
/// on the whole scene, then keeps its own pixels: the result of one process.
pub(super) fn coarse_to_fine<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    x: &mut [T],
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
) -> Result<(Report, Applies)> {
    if op.whole_code_sets().is_none() {
        if let Some(sets) = op.gathered_code_sets() {
            let sets = sets?;
            let band = op.geometry();
            let whole = Geometry::new(sets[0].pixels() / band.n, band.n, band.ks)?;
            let pulse = op.pulse().to_vec();
            let whole: Box<dyn LidarOperator<T>> = match sets.len() {
                1 => Box::new(RdOperator::new(whole, pulse, sets[0].clone())?),
                _ => Box::new(MultiAdcOperator::new(whole, &pulse, sets)?),
            };
            let whole = Counted::new(whole);
            let mut all = vec![T::zero(); whole.ncols()];
            let (report, support) = solve(&whole, y, &mut all, options, observer)?;
            let at = op.space().offset(x.len());
            x.copy_from_slice(&all[at..at + x.len()]);
            let support = Applies {
                support,
                ..Applies::default()
            };
            return Ok((report, whole.applies() + support));
        }
    }
    let (report, support) = solve(op, y, x, options, observer)?;
    let uncounted = Applies {
        support,
        ..Applies::default()
    };
    Ok((report, uncounted))
}

/// [`coarse_to_fine`] on an operator over the whole scene: the report, and the support
/// applications of the coarse grid's own kernels.
fn solve<T: Real>(
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
        model: model_params(options),
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
