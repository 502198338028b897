//! One entry point for every reconstruction method, with lidar defaults: from measurements to a
//! one-return-per-pixel scene and its depth map.
//!
//! [`reconstruct`] runs a [`Method`] on an [`RdOperator`] and its measurements and returns a
//! [`Reconstruction`]. Generic solvers (CGLS, FISTA, IHT, CoSaMP) estimate the whole voxel cube;
//! their estimate is reduced to at most one return per pixel by the per-pixel peak rule of
//! [`backprojection`] (the largest positive entry of each pixel, kept above a robust threshold).
//! The model-based solver (with its default k = 1) and TV produce one return per pixel
//! themselves.

use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use crate::lidar::{DepthMap, LidarOperator, Regime, Returns, RowWeighted, Scene, NO_RETURN};
use crate::real::Real;
use crate::solver::{refine_surfaces, Observer, RefineParams, Report};

use super::auto::{auto, Stage};
use super::detect::{check_false_rate, false_rate_test, DetectionTest};
use super::method::{run, Method};
use super::options::ReconstructOptions;
use super::peaks::returns;
use super::photon::{photon_weights, NoiseModel, PhotonWeighting};
use super::subbin::{self, AtomStart};

/// Fraction of the lit pixels of a depth map that must have a lit 4-neighbour within
/// [`SMOOTH_BINS`] of their depth for the map to count as piecewise smooth
/// ([`is_piecewise_smooth`]).
pub const SMOOTH_FRACTION: f64 = 0.6;

/// Depth difference, in bins, up to which two neighbouring returns belong to one surface.
pub const SMOOTH_BINS: i32 = 1;

/// What [`reconstruct`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct Reconstruction<T> {
    /// The estimate: every return the method found (one per pixel at most for the backprojections
    /// and the one-reflector solvers; the generic solvers may keep several).
    pub scene: Scene<T>,
    /// Its depth map ([`Scene::depth_map`]): depth bin and amplitude per pixel, [`NO_RETURN`]
    /// where there is none, [`UNOBSERVED`](crate::lidar::UNOBSERVED) for pixels that reach no
    /// ADC (all-zero codes: a coded aperture's blocked pixels).
    pub depth: DepthMap<T>,
    /// The method that produced the estimate: the one asked for, or the stage [`Method::Auto`]
    /// kept.
    pub method_used: Method,
    /// The regime of the pulse length (eq. 8–9).
    pub regime: Regime,
    /// The iterative solver's report (`None` for the backprojections). For [`Method::Auto`],
    /// the reports of every stage it ran are summed (iterations, applies, elapsed).
    pub report: Option<Report>,
    /// What [`Method::Auto`] tried, in order, what it kept and why (empty for other methods).
    pub stages: Vec<Stage>,
    /// Wall-clock time of the whole reconstruction, peak extraction included.
    pub elapsed: Duration,
    /// What the false-detection test did, when [`ReconstructOptions::false_rate`] asked for it
    /// (`None` otherwise, and for the tiles of an array whose tiles were dealt to several
    /// processes: their summaries are not gathered).
    pub detection: Option<DetectionTest>,
    /// What the photon-noise weighting found, when [`ReconstructOptions::noise`] is
    /// [`NoiseModel::Photon`] (`None` otherwise, and for the tiles
    /// of an array whose tiles were dealt to several processes). Boxed: it is rarely there.
    pub photon: Option<Box<PhotonWeighting>>,
    /// Every return's amplitude and continuous depth, under a response other than delta
    /// ([`ReconstructOptions::response`]); `None` on the grid (and for the tiles of an array
    /// whose tiles were dealt to several processes). The scene is then the returns rendered by
    /// the response, and the depth map their nearest bins. Boxed: it is rarely there.
    pub returns: Option<Box<Returns>>,
}

/// Reconstructs a scene from the measurements `y = A x` of the lidar operator `op`.
///
/// Each [`Method`] runs with lidar defaults (see its documentation). The iterative solvers'
/// estimates are reduced to the returns they found: every positive voxel above median + 3σ of
/// all entries (σ = 1.4826·MAD) and at least 5% of the strongest one. The generic solvers may
/// keep several returns per pixel; the model-based solver (k per pixel, one by default) and TV
/// give one per pixel themselves, and for them this only drops returns too weak to be real. The
/// depth map keeps each pixel's strongest return.
///
/// **The [`Method::Auto`] rule** escalates from the cheapest method and stops at the first whose
/// estimate explains the data (‖y − Ax‖ ≤ [`explained_tolerance`](super::explained_tolerance)
/// · ‖y‖, or the model-based solver's own convergence to its tolerance):
///
/// 1. [`Method::SupportLs`]: greedy support pursuit with least squares on the support; exact and
///    cheap wherever the measurements comfortably outnumber the returns, whatever the regime,
///    and for any number of returns per pixel;
/// 2. if A has full column rank (critical or redundant regime, K ≥ M·N·K_s):
///    [`Method::ModelBased`]; unless it explains the data or agrees with the pursuit's residual
///    within 5%, [`Method::Cgls`] with its returns refitted by least squares on their support.
///    With noise nothing explains the data, and the sparse fit with the lowest information
///    criterion K·ln(‖r‖²/‖y‖²) + |S|·ln K is kept;
/// 3. otherwise (compressive), if at least
///    [`SEVERAL_RETURNS_SHARE`](super::SEVERAL_RETURNS_SHARE) of the pursuit's lit pixels hold
///    several returns, the scene is not one reflector per pixel: straight to step 5. Otherwise
///    [`Method::Tv`], whose first fit is the model-based one; unless it explains the data or
///    its residual is at the noise (few returns' energy, returns standing out of it in no more
///    pixels than noise shows), [`Method::ModelBased`] alone, and TV is kept if it fits about
///    as well as the model-based scene ([`TV_RESIDUAL_MARGIN`](super::TV_RESIDUAL_MARGIN)). If
///    the support pursuit fitted the data more than twice as well as the better one-reflector
///    scene, the scene has more than one return per pixel and the pursuit's estimate is kept;
/// 4. if the one-reflector fit's residual still shows returns at other depths in at least 5% of
///    its lit pixels, step 5 (with the one-reflector fit among the candidates);
/// 5. several returns per pixel: [`Method::ModelBased`] with k returns per pixel (k from the
///    pursuit's estimate, [`estimate_returns`](super::estimate_returns), at least 2); then,
///    only if the residual of the better of it and the pursuit still shows returns in 5% of its
///    lit pixels, [`Method::Fista`] (debiased). The first that explains the data is kept,
///    otherwise the fit with the lowest information criterion.
///
/// [`Reconstruction::stages`] lists what ran, each stage's residual, returns, applications and
/// time, what was kept and why.
///
/// # Errors
/// [`Error::ShapeMismatch`] / [`Error::NonFinite`] if `y` does not fit the operator or is not
/// finite; [`Error::InvalidParameter`] for a zero `max_iter` or an all-zero pulse; the solvers'
/// own errors (e.g. [`Error::Breakdown`]).
pub fn reconstruct<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    method: Method,
    options: &ReconstructOptions,
) -> Result<Reconstruction<T>> {
    reconstruct_observed(op, y, method, options, &mut ())
}

/// [`reconstruct`] with an observer called after every iteration of every iterative solver
/// it runs (for [`Method::Auto`], of each stage in turn; the support pursuit and the
/// backprojections have none): it sees the iteration count, residual and iterate, and returns
/// [`Control::Stop`](crate::solver::Control::Stop) to end that solver's run early.
///
/// # Errors
/// As [`reconstruct`].
pub fn reconstruct_observed<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    method: Method,
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
) -> Result<Reconstruction<T>> {
    let start = Instant::now();
    if options.max_iter == Some(0) {
        return Err(Error::param("max_iter", "must be at least 1"));
    }
    if options.power_iterations == Some(0) {
        return Err(Error::param("power_iterations", "must be at least 1"));
    }
    if let Some(alpha) = options.false_rate {
        check_false_rate(alpha)?;
    }
    if y.len() != op.nrows() {
        return Err(Error::shape(
            "reconstruct: measurements vs operator rows",
            op.nrows(),
            y.len(),
        ));
    }
    let g = op.geometry();
    let regime = op.regime();
    options.noise.validate()?;
    let photon_model = match options.noise {
        NoiseModel::Photon { background } => Some(background),
        NoiseModel::Gaussian => None,
    };
    if photon_model.is_some() && op.whole_code_sets().is_none() {
        return Err(Error::param(
            "noise",
            "the photon-noise model needs the codes in memory and the whole scene in one process",
        ));
    }
    if !options.response.is_delta() {
        return continuous(op, y, method, options, observer, start);
    }
    let (mut x, method_used, mut report, stages) = solve(op, y, method, options, observer)?;
    let mut photon = None;
    let mut weighted = None;
    if let Some(background) = photon_model {
        let pass = PhotonPass {
            background,
            method: method_used,
            options,
        };
        let (found, w) = pass.run(op, y, &mut x, &mut report, observer)?;
        photon = Some(Box::new(found));
        weighted = w;
    }
    // The detection test on the data term the estimate was fitted with.
    let detection = match (options.false_rate, &weighted) {
        (Some(alpha), Some((wop, yw))) => {
            Some(false_rate_test(wop, yw, &mut x, alpha, &mut report)?)
        }
        (Some(alpha), None) => Some(false_rate_test(op, y, &mut x, alpha, &mut report)?),
        (None, _) => None,
    };
    let scene = Scene::from_vec(g, x)?;
    let mut depth = scene.depth_map();
    if let Some(observed) = op.observed_pixels() {
        depth.mark_unobserved(&observed)?;
    }
    Ok(Reconstruction {
        scene,
        depth,
        method_used,
        regime,
        report,
        stages,
        elapsed: start.elapsed(),
        detection,
        photon,
        returns: None,
    })
}

/// [`reconstruct_observed`] under a response other than delta: continuous depths.
fn continuous<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    method: Method,
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
    start: Instant,
) -> Result<Reconstruction<T>> {
    let unsupported = [
        ("false_rate", options.false_rate.is_some()),
        ("noise", options.noise != NoiseModel::Gaussian),
    ];
    if let Some((name, _)) = unsupported.iter().find(|u| u.1) {
        return Err(Error::param(
            name,
            format!(
                "not available yet with `kernel={}`: continuous depths are fitted by least \
                 squares under Gaussian noise",
                options.response
            ),
        ));
    }
    if op.space().parts() > 1 {
        return Err(Error::param(
            "kernel",
            format!(
                "continuous depths (`kernel={}`) are estimated in one process: run without \
                 mpirun, or split the array into tiles",
                options.response
            ),
        ));
    }
    let g = op.geometry();
    let grid = ReconstructOptions {
        response: crate::lidar::Response::Delta,
        ..options.clone()
    };
    let response = &options.response;
    let (estimate, method_used, stages) = match method {
        Method::ModelBased | Method::Tv => {
            let start = if method == Method::Tv {
                AtomStart::Surfaces
            } else {
                AtomStart::Pursuit
            };
            let c = subbin::pursue(op, y, options, start, observer)?;
            (
                subbin::settle(op, y, c, response, None)?,
                method,
                Vec::new(),
            )
        }
        // TV over the response's atoms; where it leaves the data unexplained, the grid methods
        // too, whose returns are proposed where they differ from TV's.
        Method::Auto => {
            let surfaces = subbin::pursue(op, y, options, AtomStart::Surfaces, observer)?;
            if subbin::explains(y, &surfaces) {
                let stages = subbin::atom_stages(y, &surfaces, None, 0);
                (
                    subbin::settle(op, y, surfaces, response, None)?,
                    Method::Tv,
                    stages,
                )
            } else {
                let (x, used, report, grid_stages) = solve(op, y, method, &grid, observer)?;
                let others = subbin::returns_in(&x, response, g.ks);
                let (start, added) = match subbin::filled(op, y, &surfaces, &others, response)? {
                    Some((f, added)) if subbin::fits_better(&f, &surfaces) => (f, added),
                    _ => (surfaces, 0),
                };
                // The grid methods' returns fitted on their own, kept where TV's surfaces
                // stalled so far that even filled they explain less.
                let report = report.unwrap_or_else(|| Report::empty(used.name()));
                let alone = subbin::from_voxels(op, y, &x, response, report)?;
                let from_grid = subbin::fits_better(&alone, &start);
                let stages = subbin::atom_stages(
                    y,
                    &start,
                    Some((grid_stages, used, &alone, from_grid)),
                    added,
                );
                // Each pixel's depth in the start not kept is proposed in its place.
                let (start, other, picked) = if from_grid {
                    (alone, start, used)
                } else {
                    (start, alone, Method::Tv)
                };
                let hints = subbin::depths_by_pixel(&other, g.m * g.n);
                let settled = subbin::settle(op, y, start, response, Some(&hints))?;
                (settled, picked, stages)
            }
        }
        _ => {
            let (x, used, report, stages) = solve(op, y, method, &grid, observer)?;
            let report = report.unwrap_or_else(|| Report::empty(used.name()));
            let c = subbin::from_voxels(op, y, &x, response, report)?;
            (subbin::settle(op, y, c, response, None)?, used, stages)
        }
    };
    let scene = Scene::from_vec(g, estimate.x)?;
    let mut depth = estimate.returns.nearest(g.ks);
    if let Some(observed) = op.observed_pixels() {
        depth.mark_unobserved(&observed)?;
    }
    Ok(Reconstruction {
        scene,
        depth: DepthMap {
            depth: depth.depth,
            amplitude: depth.amplitude.mapv(T::of_f64),
        },
        method_used,
        regime: op.regime(),
        report: Some(estimate.report),
        stages,
        elapsed: start.elapsed(),
        detection: None,
        photon: None,
        returns: Some(Box::new(estimate.returns)),
    })
}

/// The photon-noise pass after the method's estimate (`method` the method that made it).
struct PhotonPass<'o> {
    background: f64,
    method: Method,
    options: &'o ReconstructOptions,
}

/// The weighted operator and measurements of a photon-noise pass that ran.
type Weighted<'a, T> = (RowWeighted<'a, T>, Vec<T>);

impl PhotonPass<'_> {
    /// Weights the rows by the light of the estimate `x` ([`photon_weights`]) and, unless the
    /// residual does not call for it, replaces `x` by an estimate on the weighted data term:
    /// the per-pixel solvers' one-return estimates are refined there ([`refine_surfaces`]: their
    /// own statistics assume rows of one variance, and message passing on the weighted rows
    /// fails), the generic solvers run again. The backprojections and estimates with several
    /// returns in a pixel from the per-pixel solvers are left as they are, and so is `x` when
    /// the weighted pass fails (other than by cancellation).
    fn run<'a, T: Real>(
        &self,
        op: &'a dyn LidarOperator<T>,
        y: &[T],
        x: &mut Vec<T>,
        report: &mut Option<Report>,
        observer: &mut dyn Observer<T>,
    ) -> Result<(PhotonWeighting, Option<Weighted<'a, T>>)> {
        let (mut found, weights) = photon_weights(op, y, x, self.background, report)?;
        let Some(w) = weights else {
            return Ok((found, None));
        };
        let g = op.geometry();
        let several = |x: &[T]| {
            x.chunks(g.ks.max(1))
                .any(|c| c.iter().filter(|v| **v != T::zero()).count() > 1)
        };
        let refine = match self.method {
            Method::Backprojection | Method::BackprojectionDebiased => {
                found.skip("the backprojections fit no data term");
                return Ok((found, None));
            }
            Method::Tv | Method::CoarseToFine | Method::Amp | Method::ModelBased if several(x) => {
                found.skip("the estimate has several returns in a pixel: not refined");
                return Ok((found, None));
            }
            Method::Tv | Method::CoarseToFine | Method::Amp | Method::ModelBased => true,
            _ => false,
        };
        let wop = RowWeighted::new(op, w)?;
        let yw = wop.weigh(y);
        let attempt = if refine {
            let mut refined = x.clone();
            let params = RefineParams::default();
            refine_surfaces(&wop, (g.m, g.n), &yw, &mut refined, &params)
                .map(|r| (refined, Some(r)))
        } else {
            solve(&wop, &yw, self.method, self.options, observer).map(|s| (s.0, s.2))
        };
        match attempt {
            Ok((estimate, later)) => {
                *x = estimate;
                *report = match (report.take(), later) {
                    (Some(mut first), Some(later)) => {
                        first.absorb(later);
                        Some(first)
                    }
                    (first, later) => later.or(first),
                };
                Ok((found, Some((wop, yw))))
            }
            Err(e @ Error::Cancelled { .. }) => Err(e),
            Err(_) => {
                found.skip("the weighted pass failed, the first estimate is kept");
                Ok((found, None))
            }
        }
    }
}

/// The method's estimate reduced to its returns, the method used, its report and (for
/// [`Method::Auto`]) its stages.
type Solved<T> = (Vec<T>, Method, Option<Report>, Vec<Stage>);

/// Runs `method` (auto's escalation, or one method with its returns extracted).
fn solve<T: Real>(
    op: &dyn LidarOperator<T>,
    y: &[T],
    method: Method,
    options: &ReconstructOptions,
    observer: &mut dyn Observer<T>,
) -> Result<Solved<T>> {
    if method == Method::Auto {
        let a = auto(op, y, options, observer)?;
        return Ok((a.x, a.method_used, a.report, a.stages));
    }
    let (x, report) = run(op, y, method, options, observer)?;
    // The backprojections already keep one thresholded peak per pixel.
    let x = if report.is_some() {
        returns(op.space(), &x, op.geometry())
    } else {
        x
    };
    Ok((x, method, report, Vec::new()))
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
