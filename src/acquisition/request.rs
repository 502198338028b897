//! A reconstruction request: what to reconstruct and how, as one value that the command line
//! and the Python package fill, checked once here, and described by one summary both print.

use std::sync::atomic::AtomicBool;

use super::*;
use crate::recon::{check_false_rate, NoiseModel, MAX_RETURNS_ESTIMATE};
use crate::units::number;

/// The scenes a reconstruction holds at once (the estimate, iterates, gradients, the debiased
/// twin's), for the memory it is checked against.
pub const RECONSTRUCT_SCENES: u128 = 10;

/// What to reconstruct and how: the method and its settings, the noise model and the
/// false-detection test, the samples the ADC clipped, and whether unobserved pixels are filled.
///
/// The command line and the Python package fill it from their flags and arguments;
/// [`validate`](Self::validate) holds every rule about the settings (errors name the setting:
/// `max_iter`, `max_returns`, `false_rate`, `background`, `clipped`), [`run`](Self::run) runs
/// it on an acquisition, and [`summary`](Self::summary) describes it, naming each setting in
/// backticks for the front end to put in its own words
/// ([`FrontEnd::words`](crate::settings::FrontEnd::words)).
///
/// ```
/// use rdlidar::acquisition::ReconstructRequest;
/// use rdlidar::recon::Method;
/// use rdlidar::settings::FrontEnd;
///
/// let mut request = ReconstructRequest::new(Method::Auto);
/// request.options.false_rate = Some(0.01);
/// request.validate().unwrap();
/// assert_eq!(
///     FrontEnd::CommandLine.words(&request.summary()),
///     "--solver auto, --false-rate 0.01, --noise gaussian"
/// );
/// request.options.max_iter = Some(0);
/// assert!(request.validate().is_err());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ReconstructRequest {
    /// The reconstruction method.
    pub method: Method,
    /// The settings every method shares.
    pub options: ReconstructOptions,
    /// The samples the ADC clipped, left out of the data term.
    pub clipped: Option<Clipping>,
    /// Fill the depth map's unobserved pixels from their neighbours
    /// ([`DepthMap::fill_unobserved`]).
    pub fill_unobserved: bool,
}

impl ReconstructRequest {
    /// `method` with every other setting at its default.
    pub fn new(method: Method) -> Self {
        ReconstructRequest {
            method,
            options: ReconstructOptions::default(),
            clipped: None,
            fill_unobserved: false,
        }
    }

    /// The noise model `model` with the background `background`, which only the photon model
    /// takes (0 when not given).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming `background` for a background with the Gaussian model
    /// or one that is not finite and ≥ 0.
    pub fn noise_model(model: NoiseModel, background: Option<f64>) -> Result<NoiseModel> {
        let model = match (model, background) {
            (NoiseModel::Photon { .. }, b) => NoiseModel::Photon {
                background: b.unwrap_or(0.0),
            },
            (NoiseModel::Gaussian, Some(_)) => {
                return Err(Error::param(
                    "background",
                    "applies only to the photon noise model (`noise` photon)",
                ))
            }
            (NoiseModel::Gaussian, None) => NoiseModel::Gaussian,
        };
        model.validate()?;
        Ok(model)
    }

    /// Checks every setting: an iteration limit of at least 1, returns per pixel from 1 to
    /// [`MAX_RETURNS_ESTIMATE`], a false-detection rate in (0, 1), a noise model's background
    /// finite and ≥ 0, a clipping level finite and > 0.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the setting.
    pub fn validate(&self) -> Result<()> {
        let o = &self.options;
        if o.max_iter == Some(0) {
            return Err(Error::param("max_iter", "must be at least 1"));
        }
        if let Some(k) = o.max_returns {
            if !(1..=MAX_RETURNS_ESTIMATE).contains(&k) {
                return Err(Error::param(
                    "returns",
                    format!("must be from 1 to {MAX_RETURNS_ESTIMATE}, got {k}"),
                ));
            }
        }
        if let Some(alpha) = o.false_rate {
            check_false_rate(alpha)?;
        }
        o.noise.validate()?;
        if let Some(c) = self.clipped {
            c.checked()?;
        }
        Ok(())
    }

    /// What the request asks for, in one line, each setting named in backticks (`` `method` ``
    /// auto, …); the settings at their defaults are left out but the method and the noise model.
    pub fn summary(&self) -> String {
        let o = &self.options;
        let defaults = ReconstructOptions::default();
        let mut parts = vec![format!("`method` {}", self.method)];
        if let Some(n) = o.max_iter {
            parts.push(format!("`max_iter` {n}"));
        }
        if o.max_returns != defaults.max_returns {
            parts.push(match o.max_returns {
                Some(k) => format!("`returns` {k}"),
                None => "`returns` auto".to_string(),
            });
        }
        if o.threshold != defaults.threshold {
            parts.push(format!("`threshold` {}", o.threshold.name()));
        }
        if !o.debias {
            parts.push("no debiasing".to_string());
        }
        if let Some(alpha) = o.false_rate {
            parts.push(format!("`false_rate` {}", number(alpha)));
        }
        parts.push(match o.noise {
            NoiseModel::Gaussian => "`noise` gaussian".to_string(),
            NoiseModel::Photon { background } => {
                format!("`noise` photon, `background` {}", number(background))
            }
        });
        if !o.response.is_delta() {
            parts.push(format!("`kernel` {}", o.response));
        }
        if let Some(c) = self.clipped {
            parts.push(match c {
                Clipping::Top => "`clipped` top".to_string(),
                Clipping::Level(level) => format!("`clipped` {}", number(level)),
            });
        }
        if self.fill_unobserved {
            parts.push("`fill_unobserved`".to_string());
        }
        if o.seed != defaults.seed {
            parts.push(format!("`seed` {}", o.seed));
        }
        parts.join(", ")
    }

    /// Checks that a reconstruction of `acq` in `T` fits in memory ([`RECONSTRUCT_SCENES`]
    /// scenes and the operator), before anything is allocated.
    ///
    /// # Errors
    /// [`Error::TooLarge`].
    pub fn check_memory<T: Real>(&self, acq: &Acquisition) -> Result<()> {
        acq.solver_memory_plan::<T>(RECONSTRUCT_SCENES)
            .check("reconstruct", "use a smaller acquisition or free memory")
    }

    /// The acquisition and measurements with the samples [`clipped`](Self::clipped) names
    /// censored ([`Acquisition::censor`]), and what was censored; as they are without it.
    ///
    /// # Errors
    /// [`Acquisition::censor`]'s.
    pub fn censor<T: Real>(
        &self,
        acq: Acquisition,
        y: Vec<T>,
    ) -> Result<(Acquisition, Vec<T>, Option<Censoring>)> {
        match self.clipped {
            None => Ok((acq, y, None)),
            Some(clipping) => {
                let (acq, y, c) = acq.censor(&y, clipping)?;
                Ok((acq, y, Some(c)))
            }
        }
    }

    /// Runs the method on `acq` and its measurements `y` (censored already, see
    /// [`censor`](Self::censor)), observed by `observe` and `on_tile`, cancelled by `cancel`
    /// ([`Acquisition::reconstruct_cancellable`]). Under a split of the rows, each process
    /// gets its own rows' result; [`finish`](Self::finish) completes the whole one.
    ///
    /// # Errors
    /// [`validate`](Self::validate)'s, and those of
    /// [`Acquisition::reconstruct_cancellable`].
    pub fn run<T: Real>(
        &self,
        acq: &Acquisition,
        y: &[T],
        observe: &(dyn Fn(usize, &IterationInfo<'_, T>) -> Control + Sync),
        on_tile: &(dyn Fn(&TileReconstruction<T>) + Sync),
        cancel: &AtomicBool,
    ) -> Result<Reconstructed<T>> {
        self.validate()?;
        acq.reconstruct_cancellable(y, self.method, &self.options, observe, on_tile, cancel)
    }
}
