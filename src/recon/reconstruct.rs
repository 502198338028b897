//! One entry point for every reconstruction method, with lidar defaults: from measurements to a
//! one-return-per-pixel scene and its depth map.
//!
//! [`reconstruct`] runs a [`Method`] on an [`RdOperator`] and its measurements and returns a
//! [`Reconstruction`]. Generic solvers (CGLS, FISTA, IHT, CoSaMP) estimate the whole voxel cube;
//! their estimate is reduced to at most one return per pixel by the per-pixel peak rule of
//! [`backprojection`] (the largest positive entry of each pixel, kept above a robust threshold).
//! The model-based and TV solvers produce one return per pixel themselves.

use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use crate::lidar::{DepthMap, RdOperator, Regime, Scene, NO_RETURN};
use crate::linalg::norm2;
use crate::operator::LinearOperator;
use crate::real::Real;
use crate::solver::{residual_norm_sq, tv_depth, Report, Termination, TvDepthParams};

use super::method::{model_params, progress_bar, run, Method, ReconstructOptions};
use super::peaks::pixel_peaks;

/// Fraction of the lit pixels of a depth map that must have a lit 4-neighbour within
/// [`SMOOTH_BINS`] of their depth for the map to count as piecewise smooth
/// ([`is_piecewise_smooth`]).
pub const SMOOTH_FRACTION: f64 = 0.6;

/// Depth difference, in bins, up to which two neighbouring returns belong to one surface.
pub const SMOOTH_BINS: i32 = 1;

/// [`Method::Auto`] keeps the TV refinement only if its residual ‖Ax − y‖ is at most this factor
/// times the model-based one (plus 10⁻⁶‖y‖): TV must not buy smoothness with a worse data fit.
pub const TV_RESIDUAL_MARGIN: f64 = 1.05;

/// What [`reconstruct`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct Reconstruction<T> {
    /// The estimate, at most one nonzero voxel per pixel.
    pub scene: Scene<T>,
    /// Its depth map ([`Scene::depth_map`]): depth bin and amplitude per pixel, [`NO_RETURN`]
    /// where there is none.
    pub depth: DepthMap<T>,
    /// The method that produced the estimate: the one asked for, or what [`Method::Auto`] chose
    /// ([`Method::Tv`] when it refined a model-based fit).
    pub method_used: Method,
    /// The regime of the pulse length (eq. 8–9).
    pub regime: Regime,
    /// The iterative solver's report (`None` for the backprojections). For [`Method::Auto`]
    /// refined by TV, the model-based and TV reports are summed (iterations, applies, elapsed).
    pub report: Option<Report>,
    /// Wall-clock time of the whole reconstruction, peak extraction included.
    pub elapsed: Duration,
}

/// Reconstructs a scene from the measurements `y = A x` of the lidar operator `op`.
///
/// Each [`Method`] runs with lidar defaults (see its documentation). The iterative solvers'
/// estimates are reduced to one return per pixel: each pixel's largest positive entry, kept if it
/// is above median + 3σ of all entries (σ = 1.4826·MAD) and at least 5% of the strongest peak
/// (for the model-based and TV solvers, which already give one return per pixel, this only drops
/// returns too weak to be real).
///
/// **The [`Method::Auto`] rule.** From the regime of K_p ([`Geometry::regime`](crate::lidar::Geometry::regime)):
///
/// * redundant (K > M·N·K_s): [`Method::BackprojectionDebiased`] — the operator is close to a
///   frame and one zero-mean adjoint approximately inverts it;
/// * critical (K = M·N·K_s): [`Method::Cgls`] — A is square and least squares suffices;
/// * compressive: [`Method::ModelBased`]; then, unless its fit already explains the data (its
///   relative residual reached the solver's tolerance, as when it recovers a noise-free scene
///   exactly), [`Method::Tv`] runs from scratch, starting with its neighbourhood prior, which
///   exploits piecewise-smooth depth maps. Its scene is kept if it fits the data about as well
///   ([`TV_RESIDUAL_MARGIN`]); otherwise the model-based scene is returned (and the report, which
///   then still includes the TV run, says `tv-depth` while `method_used` says model-based).
///   [`is_piecewise_smooth`] does not gate TV: at short pulses the model-based map can be too
///   scattered to pass it although the scene is piecewise smooth (docs/solvers.md has the
///   measurements).
///
/// # Errors
/// [`Error::ShapeMismatch`] / [`Error::NonFinite`] if `y` does not fit the operator or is not
/// finite; [`Error::InvalidParameter`] for a zero `max_iter` or an all-zero pulse; the solvers'
/// own errors (e.g. [`Error::Breakdown`]).
pub fn reconstruct<T: Real>(
    op: &RdOperator<T>,
    y: &[T],
    method: Method,
    options: &ReconstructOptions,
) -> Result<Reconstruction<T>> {
    let start = Instant::now();
    if options.max_iter == Some(0) {
        return Err(Error::param("max_iter", "must be at least 1"));
    }
    if options.power_iterations == Some(0) {
        return Err(Error::param("power_iterations", "must be at least 1"));
    }
    if y.len() != op.nrows() {
        return Err(Error::shape(
            "reconstruct: measurements vs operator rows",
            op.nrows(),
            y.len(),
        ));
    }
    let g = op.geometry();
    let regime = g.regime(op.pulse().len());
    let chosen = match method {
        Method::Auto => match regime {
            Regime::Redundant => Method::BackprojectionDebiased,
            Regime::Critical => Method::Cgls,
            Regime::Compressive => Method::ModelBased,
        },
        m => m,
    };
    let (mut x, mut report) = run(op, y, chosen, options)?;
    let mut method_used = chosen;
    if method == Method::Auto && chosen == Method::ModelBased {
        let explained = report
            .as_ref()
            .is_some_and(|r| r.termination == Termination::Residual);
        if !explained {
            let params = TvDepthParams {
                model: model_params(options),
                ..TvDepthParams::default()
            };
            let mut progress = progress_bar(params.model.stopping.max_iter, options);
            // From scratch, so that TV starts with its neighbourhood prior: at short pulses the
            // model-based map is too scattered to be a useful start.
            let mut x_tv = vec![T::zero(); x.len()];
            let tv = tv_depth(op, (g.m, g.n), y, &mut x_tv, &params, &mut progress)?;
            progress.finish();
            let r_mb = residual_norm_sq(op, y, &x).sqrt();
            let r_tv = residual_norm_sq(op, y, &x_tv).sqrt();
            let y_norm = norm2(y);
            if r_tv <= TV_RESIDUAL_MARGIN * r_mb + 1e-6 * y_norm {
                x = x_tv;
                method_used = Method::Tv;
            }
            report = Some(match report {
                Some(mut r) => {
                    r.absorb(tv);
                    r
                }
                None => tv,
            });
        }
    }
    if report.is_some() {
        x = pixel_peaks(&x, g);
    }
    let scene = Scene::from_vec(g, x)?;
    let depth = scene.depth_map();
    Ok(Reconstruction {
        scene,
        depth,
        method_used,
        regime,
        report,
        elapsed: start.elapsed(),
    })
}

/// Whether at least [`SMOOTH_FRACTION`] of the lit pixels of `depth` have a lit 4-neighbour
/// within [`SMOOTH_BINS`] bins of their depth (false for a map with no lit pixel).
pub fn is_piecewise_smooth(depth: &ndarray::Array2<i32>) -> bool {
    let (m, n) = depth.dim();
    let (mut lit, mut smooth) = (0usize, 0usize);
    for ((i, j), &d) in depth.indexed_iter() {
        if d == NO_RETURN {
            continue;
        }
        lit += 1;
        let neighbours = [
            (i.wrapping_sub(1), j),
            (i + 1, j),
            (i, j.wrapping_sub(1)),
            (i, j + 1),
        ];
        if neighbours.iter().any(|&(a, b)| {
            a < m && b < n && {
                let e = depth[[a, b]];
                e != NO_RETURN && (e - d).abs() <= SMOOTH_BINS
            }
        }) {
            smooth += 1;
        }
    }
    lit > 0 && smooth as f64 >= SMOOTH_FRACTION * lit as f64
}
