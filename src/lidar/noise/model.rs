//! A chain of noise stages applied in order: [`NoiseModel`].

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::*;

/// One stage of a [`NoiseModel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NoiseStage {
    /// White Gaussian noise at `snr_db` decibels, relative to the mean power of the noiseless
    /// measurements (the vector given to [`NoiseModel::apply`], before any stage), as in
    /// [`add_gaussian_snr`].
    Gaussian {
        /// Signal-to-noise ratio in dB (finite).
        snr_db: f64,
    },
    /// White Gaussian noise of a given standard deviation, as in [`add_gaussian`].
    GaussianSigma {
        /// Standard deviation (finite, ≥ 0).
        sigma: f64,
    },
    /// Photon (shot) noise, as in [`add_photon_noise`]; needs the unmodulated light
    /// ([`NoiseModel::apply_with_intensity`]).
    Poisson {
        /// Photon count per unit intensity (finite, > 0).
        photons: f64,
        /// Background light per sample in units of intensity (finite, ≥ 0).
        background: f64,
    },
    /// ADC quantization, as in [`quantize`].
    Quantized {
        /// Bit depth, 1..=32.
        bits: u32,
        /// Full scale of the ADC.
        full_scale: FullScale,
    },
}

impl NoiseStage {
    /// Checks the stage's parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the offending parameter.
    pub fn validate(&self) -> Result<()> {
        match *self {
            NoiseStage::Gaussian { snr_db } => check_snr_db(snr_db),
            NoiseStage::GaussianSigma { sigma } => check_sigma(sigma),
            NoiseStage::Poisson {
                photons,
                background,
            } => {
                check_photons(photons)?;
                check_background(background)
            }
            NoiseStage::Quantized { bits, full_scale } => {
                check_bits(bits)?;
                check_full_scale(full_scale)
            }
        }
    }

    /// Checks the stage's parameters for measurements in `T`: those of
    /// [`NoiseStage::validate`], and a fixed full scale whose ADC levels are finite in `T`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the offending parameter (`full_scale` for levels
    /// beyond the range of `T`).
    pub fn validate_in<T: Real>(&self) -> Result<()> {
        self.validate()?;
        match *self {
            NoiseStage::Quantized { bits, full_scale } => check_levels::<T>(bits, full_scale),
            _ => Ok(()),
        }
    }
}

/// What one stage of [`NoiseModel::apply`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StageReport {
    /// A Gaussian stage and the standard deviation it used.
    Gaussian {
        /// Standard deviation of the added noise.
        sigma: f64,
    },
    /// A photon-noise stage.
    Poisson {
        /// Mean photon count per sample, λ averaged over the samples.
        mean_photons: f64,
    },
    /// A quantization stage.
    Quantized(QuantizationReport),
}

/// What [`NoiseModel::apply`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseReport {
    /// Mean power of the noiseless measurements, mean(y²).
    pub signal_power: f64,
    /// Mean power of the total change, mean((y_noisy − y)²).
    pub noise_power: f64,
    /// One entry per stage, in order.
    pub stages: Vec<StageReport>,
}

impl NoiseReport {
    /// The standard deviation of the first Gaussian stage, if there is one.
    pub fn gaussian_sigma(&self) -> Option<f64> {
        self.stages.iter().find_map(|s| match s {
            StageReport::Gaussian { sigma } => Some(*sigma),
            _ => None,
        })
    }

    /// The achieved signal-to-noise ratio 10·log₁₀(signal_power / noise_power) in dB:
    /// +∞ when nothing changed, −∞ for a zero signal with nonzero noise.
    pub fn snr_db(&self) -> f64 {
        if self.noise_power == 0.0 {
            f64::INFINITY
        } else {
            10.0 * (self.signal_power / self.noise_power).log10()
        }
    }

    /// Total number of clipped samples over the quantization stages.
    pub fn clipped(&self) -> usize {
        self.stages
            .iter()
            .map(|s| match s {
                StageReport::Quantized(q) => q.clipped,
                _ => 0,
            })
            .sum()
    }
}

/// A chain of noise stages applied in order (empty: no noise).
///
/// ```
/// use rdlidar::lidar::{FullScale, NoiseModel, NoiseStage};
///
/// # fn main() -> rdlidar::Result<()> {
/// let model = NoiseModel::none()
///     .then(NoiseStage::Gaussian { snr_db: 20.0 })
///     .then(NoiseStage::Quantized { bits: 12, full_scale: FullScale::Auto });
/// let mut y = vec![0.5f64, -1.0, 2.0, 0.25];
/// let report = model.apply(&mut y, 7)?;
/// assert_eq!(report.stages.len(), 2);
/// assert_eq!(report.clipped(), 0);
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NoiseModel {
    /// The stages, applied first to last.
    pub stages: Vec<NoiseStage>,
}

impl NoiseModel {
    /// The noise-free model.
    pub fn none() -> Self {
        NoiseModel { stages: Vec::new() }
    }

    /// A model from its stages.
    pub fn new(stages: Vec<NoiseStage>) -> Self {
        NoiseModel { stages }
    }

    /// Appends a stage.
    pub fn then(mut self, stage: NoiseStage) -> Self {
        self.stages.push(stage);
        self
    }

    /// `true` when there is no stage.
    pub fn is_none(&self) -> bool {
        self.stages.is_empty()
    }

    /// `true` when a stage needs the unmodulated light (a photon-noise stage).
    pub fn needs_intensity(&self) -> bool {
        self.stages
            .iter()
            .any(|s| matches!(s, NoiseStage::Poisson { .. }))
    }

    /// Checks every stage's parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first offending parameter.
    pub fn validate(&self) -> Result<()> {
        self.stages.iter().try_for_each(NoiseStage::validate)
    }

    /// Applies the stages in order to `y`, which must hold noiseless measurements.
    ///
    /// Same as [`NoiseModel::apply_with_intensity`] without an intensity: a model with a
    /// photon-noise stage is rejected.
    ///
    /// # Errors
    /// As [`NoiseModel::apply_with_intensity`].
    pub fn apply<T: Real>(&self, y: &mut [T], seed: u64) -> Result<NoiseReport> {
        self.apply_with_intensity(y, None, seed)
    }

    /// Applies the stages in order to `y`, which must hold noiseless measurements.
    ///
    /// One ChaCha8 generator seeded with `seed` feeds the stages in turn, so a one-stage model
    /// gives the same result as the stage's own function with the same seed. SNR stages are
    /// relative to the power of `y` as given. `intensity` is the unmodulated light that
    /// photon-noise stages need (see [`add_photon_noise`]); it is ignored by the other stages.
    /// Everything is validated first and `y` is written only on success.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an invalid stage parameter (see
    /// [`NoiseStage::validate_in`]), or (`intensity`) when a photon-noise stage has no
    /// intensity; the errors of the individual stages otherwise.
    pub fn apply_with_intensity<T: Real>(
        &self,
        y: &mut [T],
        intensity: Option<&[T]>,
        seed: u64,
    ) -> Result<NoiseReport> {
        self.stages
            .iter()
            .try_for_each(NoiseStage::validate_in::<T>)?;
        check_finite(y, "measurements")?;
        let signal_power = mean_power(y);
        for stage in &self.stages {
            match *stage {
                NoiseStage::Gaussian { snr_db } => {
                    sigma_for_snr(signal_power, snr_db)?;
                }
                NoiseStage::Poisson {
                    photons,
                    background,
                } => {
                    let light = intensity.ok_or_else(|| {
                        Error::param(
                            "intensity",
                            "a photon-noise stage needs the unmodulated light per sample",
                        )
                    })?;
                    check_poisson(y.len(), light, photons, background)?;
                }
                _ => {}
            }
        }

        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut work = y.to_vec();
        let mut stages = Vec::with_capacity(self.stages.len());
        for stage in &self.stages {
            let report = match *stage {
                NoiseStage::Gaussian { snr_db } => {
                    let sigma = sigma_for_snr(signal_power, snr_db)?;
                    gaussian_stage(&mut work, sigma, &mut rng);
                    StageReport::Gaussian { sigma }
                }
                NoiseStage::GaussianSigma { sigma } => {
                    gaussian_stage(&mut work, sigma, &mut rng);
                    StageReport::Gaussian { sigma }
                }
                NoiseStage::Poisson {
                    photons,
                    background,
                } => {
                    let light = intensity.unwrap_or(&[]);
                    let mean_photons =
                        poisson_stage(&mut work, light, photons, background, &mut rng)?;
                    StageReport::Poisson { mean_photons }
                }
                NoiseStage::Quantized { bits, full_scale } => {
                    check_finite(&work, "measurements before quantization")?;
                    StageReport::Quantized(quantize_stage(&mut work, bits, full_scale))
                }
            };
            stages.push(report);
        }
        check_finite(&work, "noisy measurements")?;
        let noise_power = if y.is_empty() {
            0.0
        } else {
            y.iter()
                .zip(&work)
                .map(|(a, b)| {
                    let d = b.as_f64() - a.as_f64();
                    d * d
                })
                .sum::<f64>()
                / y.len() as f64
        };
        y.copy_from_slice(&work);
        Ok(NoiseReport {
            signal_power,
            noise_power,
            stages,
        })
    }
}
