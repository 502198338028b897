//! Measurement noise: additive white Gaussian noise, photon (shot) noise and ADC quantization.
//!
//! Each function acts on a measurement vector `y` (length K) in place. Random draws come from a
//! ChaCha8 generator seeded with the `seed` argument, so a seed always gives the same noise.
//! Parameters and inputs are validated before anything is written: on error, `y` is unchanged.
//! Noise is computed in `f64` and rounded to `T` once per sample; power sums accumulate in `f64`.
//!
//! [`NoiseModel`] chains the stages in a given order behind one entry point,
//! [`NoiseModel::apply`].

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson, StandardNormal};

use crate::error::{Error, Result};
use crate::linalg::norm2_sq;
use crate::real::Real;

use super::scene::Scene;

mod model;

pub use model::{NoiseModel, NoiseReport, NoiseStage, StageReport};

/// Returns [`Error::NonFinite`] naming the first NaN or infinite entry of `v`.
fn check_finite<T: Real>(v: &[T], what: &str) -> Result<()> {
    match v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        Some((k, x)) => Err(Error::NonFinite {
            what: format!("{what}[{k}] = {x}"),
        }),
        None => Ok(()),
    }
}

/// Writes `work` back into `y` if every entry is finite (a value can overflow when rounded to
/// `T`); otherwise leaves `y` unchanged and returns [`Error::NonFinite`].
fn commit<T: Real>(y: &mut [T], work: &[T], what: &str) -> Result<()> {
    check_finite(work, what)?;
    y.copy_from_slice(work);
    Ok(())
}

/// Mean signal power `Σ y² / K`, accumulated in `f64` (0 for an empty vector).
pub fn mean_power<T: Real>(y: &[T]) -> f64 {
    if y.is_empty() {
        0.0
    } else {
        norm2_sq(y) / y.len() as f64
    }
}

fn check_snr_db(snr_db: f64) -> Result<()> {
    if snr_db.is_finite() {
        Ok(())
    } else {
        Err(Error::param(
            "snr_db",
            format!(
                "the SNR must be a finite number of decibels, got {}",
                crate::units::number(snr_db)
            ),
        ))
    }
}

fn check_sigma(sigma: f64) -> Result<()> {
    if sigma.is_finite() && sigma >= 0.0 {
        Ok(())
    } else {
        Err(Error::param(
            "sigma",
            format!(
                "the noise standard deviation must be finite and >= 0, got {}",
                crate::units::number(sigma)
            ),
        ))
    }
}

/// The noise standard deviation that gives `snr_db` for a signal of mean power `power`:
/// σ = √(power / 10^(SNR/10)).
///
/// A zero power gives σ = 0.
///
/// # Errors
/// [`Error::InvalidParameter`] (`snr_db`) for a NaN or infinite SNR, or when the SNR is so low
/// that σ overflows; (`power`) for a negative or non-finite power.
pub fn sigma_for_snr(power: f64, snr_db: f64) -> Result<f64> {
    check_snr_db(snr_db)?;
    if !(power.is_finite() && power >= 0.0) {
        return Err(Error::param(
            "power",
            format!(
                "the signal power must be finite and >= 0, got {}",
                crate::units::number(power)
            ),
        ));
    }
    let sigma = (power / 10f64.powf(snr_db / 10.0)).sqrt();
    if !sigma.is_finite() {
        return Err(Error::param(
            "snr_db",
            format!(
                "an SNR of {} dB gives a non-finite noise level for power {}",
                crate::units::number(snr_db),
                crate::units::number(power)
            ),
        ));
    }
    Ok(sigma)
}

fn gaussian_stage<T: Real>(work: &mut [T], sigma: f64, rng: &mut ChaCha8Rng) {
    for v in work.iter_mut() {
        let z: f64 = StandardNormal.sample(rng);
        *v = T::of_f64(v.as_f64() + sigma * z);
    }
}

/// Adds white Gaussian noise of standard deviation `sigma` to every sample: `y[k] += σ·z[k]`,
/// `z[k]` i.i.d. N(0, 1), drawn from a ChaCha8 generator seeded with `seed`.
///
/// On error `y` is unchanged.
///
/// # Errors
/// [`Error::InvalidParameter`] (`sigma`) if σ is negative, NaN or infinite;
/// [`Error::NonFinite`] if `y` holds a NaN or infinite value or a noisy value overflows `T`.
pub fn add_gaussian<T: Real>(y: &mut [T], sigma: f64, seed: u64) -> Result<()> {
    check_sigma(sigma)?;
    check_finite(y, "measurements")?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut work = y.to_vec();
    gaussian_stage(&mut work, sigma, &mut rng);
    commit(y, &work, "noisy measurements")
}

/// Adds white Gaussian noise at a signal-to-noise ratio of `snr_db` decibels and returns the
/// standard deviation σ used.
///
/// The SNR is relative to the mean power of the noiseless measurements, i.e. of `y` as given:
/// σ² = mean(y²) / 10^(SNR/10), with the power computed in `f64` ([`mean_power`]). An all-zero
/// (or empty) `y` has zero power and is left unchanged (σ = 0).
/// The noise is drawn as in [`add_gaussian`] with the same seed; on error `y` is unchanged.
///
/// # Errors
/// [`Error::InvalidParameter`] (`snr_db`) if the SNR is NaN or infinite, or so low that σ
/// overflows; [`Error::NonFinite`] if `y` holds a NaN or infinite value or a noisy value
/// overflows `T`.
pub fn add_gaussian_snr<T: Real>(y: &mut [T], snr_db: f64, seed: u64) -> Result<f64> {
    check_snr_db(snr_db)?;
    check_finite(y, "measurements")?;
    let sigma = sigma_for_snr(mean_power(y), snr_db)?;
    add_gaussian(y, sigma, seed)?;
    Ok(sigma)
}

fn check_photons(photons: f64) -> Result<()> {
    if photons.is_finite() && photons > 0.0 {
        Ok(())
    } else {
        Err(Error::param(
            "photons",
            format!(
                "the photon count per unit intensity must be finite and > 0, got {}",
                crate::units::number(photons)
            ),
        ))
    }
}

fn check_background(background: f64) -> Result<()> {
    if background.is_finite() && background >= 0.0 {
        Ok(())
    } else {
        Err(Error::param(
            "background",
            format!(
                "the background level must be finite and >= 0, got {}",
                crate::units::number(background)
            ),
        ))
    }
}

/// Checks everything the Poisson stage needs and returns the largest Poisson mean.
fn check_poisson<T: Real>(
    len: usize,
    intensity: &[T],
    photons: f64,
    background: f64,
) -> Result<f64> {
    check_photons(photons)?;
    check_background(background)?;
    if intensity.len() != len {
        return Err(Error::shape(
            "photon noise: intensity vs measurements",
            len,
            intensity.len(),
        ));
    }
    check_finite(intensity, "intensity")?;
    let mut max_intensity = 0.0f64;
    for (k, &v) in intensity.iter().enumerate() {
        let v = v.as_f64();
        if v < 0.0 {
            return Err(Error::param(
                "intensity",
                format!(
                    "light cannot be negative, got intensity[{k}] = {}",
                    crate::units::number(v)
                ),
            ));
        }
        max_intensity = max_intensity.max(v);
    }
    let max_lambda = photons * (max_intensity + background);
    if !(max_lambda.is_finite() && max_lambda < Poisson::<f64>::MAX_LAMBDA) {
        return Err(Error::param(
            "photons",
            format!(
                "the largest mean photon count {max_lambda:e} exceeds the Poisson sampler's \
                 limit {:e}",
                Poisson::<f64>::MAX_LAMBDA
            ),
        ));
    }
    Ok(max_lambda)
}

/// Adds centred shot noise; returns the mean photon count per sample.
fn poisson_stage<T: Real>(
    work: &mut [T],
    intensity: &[T],
    photons: f64,
    background: f64,
    rng: &mut ChaCha8Rng,
) -> Result<f64> {
    let mut total = 0.0f64;
    for (v, &light) in work.iter_mut().zip(intensity) {
        let lambda = photons * (light.as_f64() + background);
        total += lambda;
        let count = if lambda > 0.0 {
            let dist = Poisson::new(lambda).map_err(|e| {
                Error::param("photons", format!("Poisson mean {lambda:e} rejected: {e}"))
            })?;
            dist.sample(rng)
        } else {
            0.0
        };
        *v = T::of_f64(v.as_f64() + (count - lambda) / photons);
    }
    Ok(if work.is_empty() {
        0.0
    } else {
        total / work.len() as f64
    })
}

/// Adds photon (shot) noise and returns the mean photon count per sample.
///
/// # Model
/// The pixels' photodiodes count photons before their signals are modulated by the ±1 codes and
/// summed, so the shot noise follows the *unmodulated* light, which the measurement `y` (a signed
/// sum) does not reveal. The caller therefore supplies `intensity[k] ≥ 0`, the total light reaching
/// all pixels during sample k in the units of `y` (for example from [`unmodulated_light`]), and
///
/// ```text
/// λ[k]  = photons · (intensity[k] + background)
/// y[k] += (Poisson(λ[k]) − λ[k]) / photons
/// ```
///
/// `photons` is the photon count per unit intensity and `background` the ambient light plus dark
/// counts summed over the pixels, per sample, in units of intensity. The added noise has zero mean
/// and variance `(intensity[k] + background) / photons`; the signal-to-noise ratio grows with
/// `photons`. Counts are drawn from a ChaCha8 generator seeded with `seed` (the Poisson sampler of
/// `rand_distr`, valid for large means too); on error `y` is unchanged.
///
/// # Limits
/// With ±1 codes each pixel's shot noise enters with sign ±1, so the exact noise is a signed sum
/// of independent centred Poisson variables. One centred Poisson variable with the total mean has
/// the same mean and variance, but not the same higher moments (with random signs the true sum has
/// a skewness near 0, the Poisson variable is skewed when λ is small). The shot noise of a pixel
/// whose code is 0 at sample k does not reach the ADC; this model still counts that pixel's light
/// unless the caller leaves it out of `intensity`.
/// Noise from the electronics after demodulation is not included (use [`add_gaussian`]).
///
/// # Errors
/// [`Error::InvalidParameter`] (`photons`) unless `photons` is finite and > 0, or if a Poisson mean
/// exceeds the sampler's limit (about 1.8·10¹⁹); (`background`) unless it is finite and ≥ 0;
/// (`intensity`) for a negative intensity. [`Error::ShapeMismatch`] if `intensity` and `y` differ
/// in length. [`Error::NonFinite`] for a NaN or infinite value in `y` or `intensity`, or a noisy
/// value that overflows `T`.
pub fn add_photon_noise<T: Real>(
    y: &mut [T],
    intensity: &[T],
    photons: f64,
    background: f64,
    seed: u64,
) -> Result<f64> {
    check_poisson(y.len(), intensity, photons, background)?;
    check_finite(y, "measurements")?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut work = y.to_vec();
    let mean = poisson_stage(&mut work, intensity, photons, background, &mut rng)?;
    commit(y, &work, "noisy measurements")?;
    Ok(mean)
}

/// The unmodulated light of a scene lit by `pulse`: `Σ_{m,n} (x[m,n,:] ⊛ p)[k]` for
/// k < K = K_p + K_s − 1, the measurement the array would give with every code equal to +1.
///
/// It is the intensity the photon-noise model of [`add_photon_noise`] expects. The pixels' columns
/// are summed first and the sum convolved with the pulse, in `f64`.
///
/// # Errors
/// [`Error::InvalidParameter`] (`pulse`) for an empty pulse or a negative pulse value, (`scene`)
/// for a negative reflectivity; [`Error::NonFinite`] for a NaN or infinite value in either.
pub fn unmodulated_light<T: Real>(scene: &Scene<T>, pulse: &[T]) -> Result<Vec<T>> {
    unmodulated_light_of(scene, pulse, None)
}

/// [`unmodulated_light`] of the pixels `pixels` alone (row-major indices m·N + n; `None`: every
/// pixel): the light that reaches an ADC summing those pixels, a tile's or a coded aperture's.
///
/// # Errors
/// As [`unmodulated_light`], and [`Error::InvalidParameter`] (`pixels`) for an index beyond the
/// scene.
pub fn unmodulated_light_of<T: Real>(
    scene: &Scene<T>,
    pulse: &[T],
    pixels: Option<&[usize]>,
) -> Result<Vec<T>> {
    if pulse.is_empty() {
        return Err(Error::param("pulse", "the pulse is empty"));
    }
    check_finite(pulse, "pulse")?;
    if let Some((k, v)) = pulse.iter().enumerate().find(|(_, v)| v.as_f64() < 0.0) {
        return Err(Error::param(
            "pulse",
            format!(
                "light cannot be negative, got pulse[{k}] = {}",
                crate::units::number(*v)
            ),
        ));
    }
    let x = scene.as_slice();
    let ks = scene.geometry().ks;
    let count = x.len() / ks.max(1);
    if let Some(&p) = pixels.and_then(|px| px.iter().find(|&&p| p >= count)) {
        return Err(Error::param(
            "pixels",
            format!("pixel {p} is beyond the scene's {count} pixels"),
        ));
    }
    // Only the pixels that reach the ADC are read (and checked).
    let columns: Box<dyn Iterator<Item = &[T]>> = match pixels {
        None => Box::new(x.chunks_exact(ks)),
        Some(pixels) => Box::new(pixels.iter().map(move |&p| &x[p * ks..(p + 1) * ks])),
    };
    let mut profile = vec![0.0f64; ks];
    for col in columns {
        check_finite(col, "scene")?;
        if let Some(v) = col.iter().find(|v| v.as_f64() < 0.0) {
            return Err(Error::param(
                "scene",
                format!(
                    "reflectivity cannot be negative, got {}",
                    crate::units::number(*v)
                ),
            ));
        }
        for (acc, &v) in profile.iter_mut().zip(col) {
            *acc += v.as_f64();
        }
    }
    let kp = pulse.len();
    let mut out = vec![0.0f64; kp + ks - 1];
    for (j, &a) in profile.iter().enumerate() {
        if a == 0.0 {
            continue;
        }
        for (o, &p) in out[j..j + kp].iter_mut().zip(pulse) {
            *o += a * p.as_f64();
        }
    }
    let out: Vec<T> = out.into_iter().map(T::of_f64).collect();
    check_finite(&out, "unmodulated light")?;
    Ok(out)
}

/// The full scale of an ADC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FullScale {
    /// The ADC maps [−F, F] to its levels; F must be finite and > 0.
    Fixed(f64),
    /// F = max |y| of the vector being quantized: nothing is clipped.
    Auto,
}

/// What [`quantize`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuantizationReport {
    /// Bit depth b.
    pub bits: u32,
    /// Full scale F used (max |y| for [`FullScale::Auto`]).
    pub full_scale: f64,
    /// Quantization step Δ = 2F / 2^b.
    pub step: f64,
    /// Number of samples with |y| > F, set to the outermost level ±(F − Δ/2).
    pub clipped: usize,
}

fn check_bits(bits: u32) -> Result<()> {
    if (1..=32).contains(&bits) {
        Ok(())
    } else {
        Err(Error::param(
            "bits",
            format!("the bit depth must be in 1..=32, got {bits}"),
        ))
    }
}

fn check_full_scale(full_scale: FullScale) -> Result<()> {
    match full_scale {
        FullScale::Fixed(f) if !(f.is_finite() && f > 0.0) => Err(Error::param(
            "full_scale",
            format!(
                "the full scale must be finite and > 0, got {}",
                crate::units::number(f)
            ),
        )),
        _ => Ok(()),
    }
}

/// Checks that the levels of a fixed full scale are finite in `T`: the outermost, ±(F − Δ/2),
/// overflows `f32` when F is beyond its range.
fn check_levels<T: Real>(bits: u32, full_scale: FullScale) -> Result<()> {
    let FullScale::Fixed(f) = full_scale else {
        return Ok(());
    };
    let inner = f / 2f64.powi(bits as i32);
    let outer = f - inner;
    if T::of_f64(inner) == T::zero() {
        // Every level but the outermost would read as 0: the measurements vanish.
        return Err(Error::param(
            "full_scale",
            format!(
                "the full scale {} puts the ADC's innermost levels (±full scale / 2^{bits}) \
                 below the smallest {} (they would read as 0): raise the full scale{}",
                crate::units::number(f),
                T::NAME,
                if T::NAME == "f32" {
                    " or compute in f64"
                } else {
                    ""
                }
            ),
        ));
    }
    if T::of_f64(outer).is_finite() {
        return Ok(());
    }
    Err(Error::param(
        "full_scale",
        format!(
            "the full scale {} puts the ADC's outermost levels ±{} beyond the range of {} \
             (largest {}): lower the full scale or compute in f64",
            crate::units::number(f),
            crate::units::number(outer),
            T::NAME,
            crate::units::number(<T as num_traits::Float>::max_value())
        ),
    ))
}

fn quantize_stage<T: Real>(work: &mut [T], bits: u32, full_scale: FullScale) -> QuantizationReport {
    let f = match full_scale {
        FullScale::Fixed(f) => f,
        FullScale::Auto => work.iter().fold(0.0f64, |m, v| m.max(v.as_f64().abs())),
    };
    if f == 0.0 {
        // Automatic full scale of an all-zero vector: every level collapses onto 0.
        return QuantizationReport {
            bits,
            full_scale: 0.0,
            step: 0.0,
            clipped: 0,
        };
    }
    let levels = 2f64.powi(bits as i32);
    let step = 2.0 * f / levels;
    let mut clipped = 0;
    for v in work.iter_mut() {
        let x = v.as_f64();
        if x.abs() > f {
            clipped += 1;
        }
        let index = ((x + f) / step).floor().clamp(0.0, levels - 1.0);
        *v = T::of_f64(-f + (index + 0.5) * step);
    }
    QuantizationReport {
        bits,
        full_scale: f,
        step,
        clipped,
    }
}

/// Quantizes `y` as a `bits`-bit ADC with a mid-rise characteristic.
///
/// The range [−F, F] is divided into 2^b cells of width Δ = 2F / 2^b, and each sample is replaced
/// by the centre of its cell: the levels are ±Δ/2, ±3Δ/2, …, ±(F − Δ/2), symmetric about 0, with no
/// level at 0 (a 1-bit ADC returns ±F/2, the sign of the sample). Inside [−F, F] the error is at
/// most Δ/2; samples with |y| > F are clipped to ±(F − Δ/2) and counted. The map is monotone
/// (non-decreasing). The result is rounded to `T`, which for `f32` and large bit depths can exceed
/// Δ/2 by the rounding of `T`.
///
/// With [`FullScale::Auto`], F = max |y|; an all-zero or empty `y` is left unchanged and reported
/// with F = Δ = 0. The map is deterministic; on error `y` is unchanged.
///
/// # Errors
/// [`Error::InvalidParameter`] (`bits`) unless 1 ≤ b ≤ 32, (`full_scale`) for a fixed full scale
/// that is not finite and > 0 or whose levels overflow `T`; [`Error::NonFinite`] for a NaN or
/// infinite value in `y`.
pub fn quantize<T: Real>(
    y: &mut [T],
    bits: u32,
    full_scale: FullScale,
) -> Result<QuantizationReport> {
    check_bits(bits)?;
    check_full_scale(full_scale)?;
    check_levels::<T>(bits, full_scale)?;
    check_finite(y, "measurements")?;
    let mut work = y.to_vec();
    let report = quantize_stage(&mut work, bits, full_scale);
    commit(y, &work, "quantized measurements")?;
    Ok(report)
}
