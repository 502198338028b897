//! The parameters of model-based recovery and their checks.

use crate::error::{Error, Result};
use crate::solver::{check_tolerance, CglsParams, Stopping};

use super::super::amp::ReflectorAmpParams;

/// Parameters of [`model_based`](crate::solver::model_based).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelBasedParams {
    /// Returns per pixel at most (k, default 1: one reflector per pixel). With k > 1 each
    /// iteration picks a pixel's returns one at a time, each judged on the pixel's correlations
    /// with the ones picked before taken out, and keeps a further return only when it is
    /// significant ([`detection_z`](Self::detection_z), or already held).
    pub max_returns: usize,
    /// Reflectivities are nonnegative: depths are chosen by the largest signed correlation and
    /// pixels whose least-squares amplitude is not positive are dropped (default `true`).
    pub nonnegative: bool,
    /// Exploration: the first iterations put every pixel with a positive best correlation in
    /// the support (within the budget). Least squares then gives each lit pixel at least about
    /// half its amplitude even at a wrong depth (a pixel's columns overlap by half for a 0/1
    /// pulse), so that the amplitude test at the end of the exploration separates lit from empty
    /// pixels even when cross-talk hides the depths (default 3; 0 skips the exploration). A
    /// warm start whose least squares leaves at most 10⁻³ of ‖y‖ has found the support and skips
    /// it.
    pub explore_iterations: usize,
    /// After the exploration, a pixel outside the support joins it when its best correlation is
    /// at least this many robust standard deviations (1.4826·MAD) of all correlations: a maximum
    /// over the pixel's depths, hence a high bar (default 4).
    pub detection_z: f64,
    /// A pixel stays in the support when its least-squares amplitude is at least this many
    /// standard errors σ_r/(‖a‖·√(1 − |S|/K)) (σ_r² = ‖r‖²/(K − |S|), ‖a‖ its column's norm, the
    /// square root the variance inflation of least squares on |S| of K measurements, bounded at
    /// √0.05) (default 3).
    pub amplitude_z: f64,
    /// The test of the final support, once, with the same standard errors: a return stays when
    /// its amplitude is at least this many, and the rest is refitted (default 3.7). An empty
    /// pixel offers the best of its K_s depths, so its chance of passing in noise is about
    /// K_s·Q(z): 0.4% for K_s = 40 at z = 3.7.
    pub final_z: f64,
    /// The surface rule, where the image's grid is known (the TV-on-depth solver, one return per
    /// pixel): a return passes both amplitude tests at this many standard errors when at least
    /// [`surface_neighbours`](Self::surface_neighbours) of its eight neighbours hold a return
    /// within one bin of its depth that passes at this level too (default 2). A false detection
    /// lands at a random one of an empty pixel's K_s depths and rarely has such neighbours; a
    /// return inside a surface has most of its eight.
    pub surface_z: f64,
    /// Neighbours that make a return part of a surface (0 … 8, default 3; 0 disables the rule).
    pub surface_neighbours: usize,
    /// Under the surface rule, a pixel outside the support joins it at a depth within one bin
    /// of the surface its neighbours form, when its correlation there reaches
    /// [`surface_z`](Self::surface_z) robust standard deviations (instead of
    /// [`detection_z`](Self::detection_z) at any depth) and at least this many of its neighbours
    /// hold returns within one bin of that depth that pass the final test (1 … 8, default 4: one
    /// more than an empty pixel along a straight edge of a surface has).
    pub join_neighbours: usize,
    /// Under the surface rule, the final test holds a return none of whose neighbours has a
    /// return within one bin of its depth that passes at [`surface_z`](Self::surface_z) to this
    /// many standard errors (default 7). False detections are isolated, and the standard errors
    /// of least squares on a support chosen from the same data understate how far the best of an
    /// empty pixel's K_s depths stands out when few measurements per lit pixel leave much of the
    /// scene in the residual.
    pub isolated_z: f64,
    /// The support holds at most this fraction of the number of measurements, keeping the
    /// least-squares step overdetermined (in (0, 1], default 0.8).
    pub max_support_fraction: f64,
    /// The residual's standard deviation in the amplitude test is taken as at least this
    /// fraction of the measurements' RMS, so that noise-free runs drop the round-off amplitudes
    /// that least squares leaves on empty pixels: it bounds the dynamic range (default 1e-4).
    pub noise_floor: f64,
    /// The least-squares step on the support (CGLS on the restricted operator, warm-started). A
    /// fit whose iterations run out within 1% of ‖y‖ while its squared residual still falls by a
    /// factor of 4 over five iterations goes on, up to five times as many, until it slows down
    /// or reaches a tenth of [`stopping`](Self::stopping)'s residual tolerance.
    pub inner: CglsParams,
    /// Without a warm start, the first support comes from message passing with the one-reflector
    /// prior ([`reflector_amp`](crate::solver::reflector_amp)), and the exploration is skipped;
    /// `None` starts from the exploration instead (default: AMP with its defaults, but stopping
    /// once its support has been stable for 3 iterations, and applying the operator in single
    /// precision where it can, [`ReflectorAmpParams::single_precision`]: the fit that follows
    /// is in the computation's precision).
    pub amp: Option<ReflectorAmpParams>,
    /// Stopping rules; the residual is ‖Ax − y‖ / ‖y‖.
    pub stopping: Stopping,
}

impl Default for ModelBasedParams {
    fn default() -> Self {
        ModelBasedParams {
            max_returns: 1,
            nonnegative: true,
            explore_iterations: 3,
            detection_z: 4.0,
            amplitude_z: 3.0,
            final_z: 3.7,
            surface_z: 2.0,
            surface_neighbours: 3,
            join_neighbours: 4,
            isolated_z: 7.0,
            noise_floor: 1e-4,
            max_support_fraction: 0.8,
            amp: Some(ReflectorAmpParams {
                stable_support: Some(3),
                single_precision: true,
                ..ReflectorAmpParams::default()
            }),
            inner: CglsParams {
                damp: 0.0,
                stopping: Stopping {
                    max_iter: 10,
                    rel_residual: Some(1e-6),
                    ..Stopping::default()
                },
            },
            stopping: Stopping {
                max_iter: 100,
                rel_residual: Some(1e-6),
                ..Stopping::default()
            },
        }
    }
}

impl ModelBasedParams {
    /// Checks every setting that needs no operator.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`](crate::Error::InvalidParameter) naming the setting.
    pub fn validate(&self) -> Result<()> {
        self.stopping.validate()?;
        self.inner.stopping.validate()?;
        if let Some(a) = &self.amp {
            a.validate()?;
        }
        if self.max_returns == 0 {
            return Err(Error::param("max_returns", "must be at least 1"));
        }
        check_tolerance("detection_z", self.detection_z)?;
        check_tolerance("amplitude_z", self.amplitude_z)?;
        check_tolerance("final_z", self.final_z)?;
        check_tolerance("surface_z", self.surface_z)?;
        check_tolerance("isolated_z", self.isolated_z)?;
        if self.surface_neighbours > 8 {
            return Err(Error::param(
                "surface_neighbours",
                format!("must be at most 8, got {}", self.surface_neighbours),
            ));
        }
        if !(1..=8).contains(&self.join_neighbours) {
            return Err(Error::param(
                "join_neighbours",
                format!("must be in 1 … 8, got {}", self.join_neighbours),
            ));
        }
        check_tolerance("noise_floor", self.noise_floor)?;
        if !(self.max_support_fraction > 0.0 && self.max_support_fraction <= 1.0) {
            return Err(Error::param(
                "max_support_fraction",
                format!(
                    "must be in (0, 1], got {}",
                    crate::units::number(self.max_support_fraction)
                ),
            ));
        }
        if !(self.inner.damp.is_finite() && self.inner.damp >= 0.0) {
            return Err(Error::param(
                "inner.damp",
                format!(
                    "must be finite and ≥ 0, got {}",
                    crate::units::number(self.inner.damp)
                ),
            ));
        }
        Ok(())
    }
}
