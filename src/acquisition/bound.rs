//! The Cramér–Rao bound and the noise level of a whole acquisition, tile by tile for a tiled
//! array (each tile its own operator).

use ndarray::{s, Array3};

use super::*;
use crate::lidar::{Response, Returns};
use crate::recon::{depth_bound, joint_bound_fits, joint_depth_bound};

/// The residual's noise level, relative to the measurements' RMS, below which the estimate
/// explains the data to round-off and the noise is taken as zero.
const ROUND_OFF: f64 = 1e-10;

/// A bound computed on one operator for its part of the returns.
type TileBound<'a, T> = dyn Fn(&dyn LidarOperator<T>, &Returns) -> Result<Array3<f64>> + 'a;

impl Acquisition {
    /// The per-return Cramér–Rao bound on the depths of `truth` (R, M, N) under `response` and
    /// white Gaussian noise of standard deviation `sigma` per sample, in bins, every other
    /// pixel known ([`depth_bound`]): NaN where there is no return.
    ///
    /// # Errors
    /// As [`depth_bound`]; [`Error::InvalidParameter`] (`kernel`) for an acquisition whose
    /// pixels are split among processes.
    pub fn depth_bound<T: Real>(
        &self,
        truth: &Returns,
        response: &Response,
        sigma: f64,
    ) -> Result<Array3<f64>> {
        self.tile_by_tile::<T>(truth, &|op, part| depth_bound(op, part, response, sigma))
    }

    /// The per-return Cramér–Rao bound on the depths of `truth` with every return of a tile
    /// (of the whole array where it is not tiled) unknown at once ([`joint_depth_bound`]): what
    /// a method that fits all returns faces. NaN where there is no return.
    ///
    /// # Errors
    /// As [`joint_depth_bound`] for each tile; as [`depth_bound`](Self::depth_bound) for a
    /// split acquisition.
    pub fn joint_depth_bound<T: Real>(
        &self,
        truth: &Returns,
        response: &Response,
        sigma: f64,
    ) -> Result<Array3<f64>> {
        self.tile_by_tile::<T>(truth, &|op, part| {
            joint_depth_bound(op, part, response, sigma)
        })
    }

    /// Whether [`joint_depth_bound`](Self::joint_depth_bound) takes `truth`: every tile's
    /// returns within [`joint_bound_fits`].
    pub fn joint_bound_fits(&self, truth: &Returns) -> bool {
        let (_, m, n) = truth.depth.dim();
        if (m, n) != (self.geometry.m, self.geometry.n) {
            return false;
        }
        let places = self.tile_places();
        let count = |rows: std::ops::Range<usize>, cols: std::ops::Range<usize>| {
            truth
                .depth
                .slice(s![.., rows, cols])
                .iter()
                .filter(|d| !d.is_nan())
                .count()
        };
        if places.is_empty() {
            return joint_bound_fits(self.samples(), count(0..m, 0..n));
        }
        places.iter().all(|place| {
            joint_bound_fits(
                self.samples(),
                count(
                    place.row..place.row + place.geometry.m,
                    place.col..place.col + place.geometry.n,
                ),
            )
        })
    }

    /// `bound` on the whole acquisition or, for a tiled array, on each tile with its part of
    /// `truth`, the results put together.
    fn tile_by_tile<T: Real>(
        &self,
        truth: &Returns,
        bound: &TileBound<'_, T>,
    ) -> Result<Array3<f64>> {
        self.refuse_split()?;
        let places = self.tile_places();
        if places.is_empty() {
            return bound(self.lidar_operator::<T>()?.as_ref(), truth);
        }
        let g = self.geometry;
        if truth.depth.dim().1 != g.m || truth.depth.dim().2 != g.n {
            return Err(Error::shape(
                "returns vs the acquisition's pixels",
                g.m * g.n,
                truth.depth.dim().1 * truth.depth.dim().2,
            ));
        }
        let mut out = Array3::from_elem(truth.depth.dim(), f64::NAN);
        for place in &places {
            let (rows, cols) = (
                place.row..place.row + place.geometry.m,
                place.col..place.col + place.geometry.n,
            );
            let part = Returns::new(
                truth
                    .depth
                    .slice(s![.., rows.clone(), cols.clone()])
                    .to_owned(),
                truth
                    .amplitude
                    .slice(s![.., rows.clone(), cols.clone()])
                    .to_owned(),
            )?;
            let op = self.tile(place)?.lidar_operator::<T>()?;
            let b = bound(op.as_ref(), &part)?;
            out.slice_mut(s![.., rows, cols]).assign(&b);
        }
        Ok(out)
    }

    /// The noise's standard deviation per sample that the residual of the estimate `scene`
    /// shows, ‖y − A x‖/√(measurements − `unknowns`), `unknowns` being the parameters the
    /// estimate fitted (two per return for continuous depths); `None` when the fit leaves no
    /// degree of freedom.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if `y` or `scene` do not fit the acquisition; as
    /// [`depth_bound`](Self::depth_bound) for a split acquisition.
    pub fn residual_sigma<T: Real>(
        &self,
        y: &[T],
        scene: &Scene<T>,
        unknowns: usize,
    ) -> Result<Option<f64>> {
        self.refuse_split()?;
        if y.len() != self.measurements() {
            return Err(Error::shape("meas", self.measurements(), y.len()));
        }
        if scene.geometry() != self.geometry {
            return Err(Error::shape(
                "scene vs the acquisition",
                self.geometry.voxels(),
                scene.data().len(),
            ));
        }
        let mut squares = 0.0;
        let places = self.tile_places();
        let mut add = |op: &dyn LidarOperator<T>, x: &[T], y: &[T]| {
            let mut ax = vec![T::zero(); op.nrows()];
            op.apply(x, &mut ax);
            squares += ax
                .iter()
                .zip(y)
                .map(|(a, b)| (b.as_f64() - a.as_f64()).powi(2))
                .sum::<f64>();
        };
        if places.is_empty() {
            let x = scene.data().as_standard_layout();
            add(
                self.lidar_operator::<T>()?.as_ref(),
                x.as_slice().expect("standard layout"),
                y,
            );
        } else {
            let k = self.samples();
            for place in &places {
                let (rows, cols) = (
                    place.row..place.row + place.geometry.m,
                    place.col..place.col + place.geometry.n,
                );
                let x = scene
                    .data()
                    .slice(s![rows, cols, ..])
                    .as_standard_layout()
                    .to_owned();
                let op = self.tile(place)?.lidar_operator::<T>()?;
                add(
                    op.as_ref(),
                    x.as_slice().expect("standard layout"),
                    &y[place.index * k..(place.index + 1) * k],
                );
            }
        }
        Ok(crate::recon::residual_sigma(
            squares.sqrt(),
            y.len(),
            unknowns,
        ))
    }

    fn refuse_split(&self) -> Result<()> {
        if self.share.is_some() {
            return Err(Error::param(
                "kernel",
                "the bound on continuous depths is computed in one process: run without mpirun",
            ));
        }
        Ok(())
    }
}

/// Continuous depths against the true ones, beside the Cramér–Rao bound: what
/// `reconstruct --truth-range` prints.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RangeComparison {
    /// The errors, and the bound where the true amplitudes were known.
    pub metrics: crate::recon::RangeMetrics,
    /// The noise's standard deviation per sample the bound assumed.
    pub sigma: Option<f64>,
    /// Whether σ was given (`"given"`) or estimated from the estimate's residual
    /// (`"residual"`).
    pub sigma_source: &'static str,
    /// The root-mean-square bound over the same returns with every return of a tile unknown
    /// at once ([`Acquisition::joint_depth_bound`]), where the bound was computed and the
    /// returns are within [`joint_bound_fits`].
    pub joint_bound_bins: Option<f64>,
    /// `rmse_bins / joint_bound_bins` where that bound is positive.
    pub rmse_over_joint_bound: Option<f64>,
}

impl std::fmt::Display for RangeComparison {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.metrics)?;
        if let (Some(_), Some(sigma)) = (self.metrics.bound_bins, self.sigma) {
            write!(
                f,
                " (bound at σ = {} per sample, {})",
                if sigma >= 1e-3 {
                    format!("{sigma:.4}")
                } else {
                    format!("{sigma:.3e}")
                },
                if self.sigma_source == "given" {
                    "given"
                } else {
                    "estimated from the residual"
                }
            )?;
        }
        if let (Some(b), Some(ratio)) = (self.joint_bound_bins, self.rmse_over_joint_bound) {
            write!(
                f,
                "; with every return unknown at once the bound is {b:.4} bins ({}): RMSE/bound {ratio:.2}",
                crate::recon::millimetres(b * self.metrics.bin_m)
            )?;
        }
        Ok(())
    }
}

impl Acquisition {
    /// Compares the continuous estimate `estimate` (the returns of an [`Outcome`], whose scene
    /// is `scene`) with the true depths `truth_range` ((M, N) or (R, M, N) in bins, NaN where
    /// there is none, as `range.npy` holds them). With the true scene `truth_scene` the true
    /// amplitudes are known ([`Returns::fit_to_scene`]) and the Cramér–Rao bound is computed
    /// under `response` at the noise level `sigma` or, without it, the level the residual of
    /// `scene` shows on `y` (two unknowns per estimated return). `bin_m` is one bin's length.
    ///
    /// # Errors
    /// As [`Returns::fit_to_scene`], [`depth_bound`](Self::depth_bound),
    /// [`residual_sigma`](Self::residual_sigma) and [`compare_range`](crate::recon::compare_range).
    #[allow(clippy::too_many_arguments)]
    pub fn compare_range<T: Real>(
        &self,
        y: &[T],
        estimate: (&Returns, &Scene<T>),
        truth_range: ndarray::ArrayD<f64>,
        truth_scene: Option<&Scene<T>>,
        response: &Response,
        sigma: Option<f64>,
        bin_m: f64,
    ) -> Result<RangeComparison> {
        let (returns, scene) = estimate;
        let truth = match truth_scene {
            Some(t) => Returns::fit_to_scene(truth_range, t, response)?,
            None => {
                let depth = match truth_range.ndim() {
                    2 => truth_range.insert_axis(ndarray::Axis(0)),
                    _ => truth_range,
                }
                .into_dimensionality::<ndarray::Ix3>()
                .map_err(|_| Error::shape("range: (M, N) or (R, M, N)", 3, 0))?;
                let amplitude = depth.mapv(|d| if d.is_nan() { 0.0 } else { 1.0 });
                Returns::new(depth, amplitude)?
            }
        };
        let (sigma, sigma_source) = match sigma {
            Some(s) => (Some(s), "given"),
            None if truth_scene.is_some() => {
                let unknowns = 2 * returns.depth.iter().filter(|d| !d.is_nan()).count();
                // A residual at round-off is no noise: the bound is 0, not a ratio of
                // round-off errors.
                let rms = (y.iter().map(|v| v.as_f64().powi(2)).sum::<f64>()
                    / y.len().max(1) as f64)
                    .sqrt();
                let sigma = self.residual_sigma(y, scene, unknowns)?.map(|s| {
                    if s <= ROUND_OFF * rms {
                        0.0
                    } else {
                        s
                    }
                });
                (sigma, "residual")
            }
            None => (None, "residual"),
        };
        let bound = match (truth_scene, sigma) {
            (Some(_), Some(s)) => Some(self.depth_bound::<T>(&truth, response, s)?),
            _ => None,
        };
        let metrics = crate::recon::compare_range(&truth, returns, bound.as_ref(), bin_m)?;
        let joint = match (&bound, sigma) {
            (Some(_), Some(s)) if self.joint_bound_fits(&truth) => {
                let b = self.joint_depth_bound::<T>(&truth, response, s)?;
                Some(crate::recon::compare_range(
                    &truth,
                    returns,
                    Some(&b),
                    bin_m,
                )?)
            }
            _ => None,
        };
        Ok(RangeComparison {
            metrics,
            sigma,
            sigma_source,
            joint_bound_bins: joint.and_then(|j| j.bound_bins),
            rmse_over_joint_bound: joint.and_then(|j| j.rmse_over_bound),
        })
    }
}
