//! The transmitted pulse p[k], k < K_p.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Error, Result};
use crate::real::Real;

/// A physical pulse: finite, nonnegative (light cannot be negative) and not identically zero.
#[derive(Debug, Clone, PartialEq)]
pub struct Pulse<T> {
    p: Vec<T>,
}

impl<T: Real> Pulse<T> {
    /// Checks `p` against the rules of [`Pulse::new`] without copying it.
    ///
    /// # Errors
    /// As [`Pulse::new`].
    pub fn check(p: &[T]) -> Result<()> {
        if p.is_empty() {
            return Err(Error::param("pulse", "must have at least one sample"));
        }
        if let Some(i) = p.iter().position(|v| !v.is_finite()) {
            return Err(Error::param(
                "pulse",
                format!("sample at index {i} is {}, not a finite value", p[i]),
            ));
        }
        if let Some(i) = p.iter().position(|&v| v < T::zero()) {
            return Err(Error::param(
                "pulse",
                format!(
                    "sample at index {i} is negative ({}): a pulse is light intensity, which \
                     must be ≥ 0",
                    crate::units::number(p[i])
                ),
            ));
        }
        if p.iter().all(|&v| v == T::zero()) {
            return Err(Error::param(
                "pulse",
                format!("is all zero ({} samples): nothing is transmitted", p.len()),
            ));
        }
        Ok(())
    }

    /// Validates and wraps `p`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`pulse`) for an empty or all-zero pulse, or a negative, NaN
    /// or infinite value (naming its index): the one place of the rules about pulses.
    pub fn new(p: Vec<T>) -> Result<Self> {
        Self::check(&p)?;
        Ok(Pulse { p })
    }

    /// An i.i.d. Bernoulli{0, 1} pulse with P(1) = 1/2 from a ChaCha8 stream seeded with `seed`
    /// (one `bool` draw per sample; in the unlikely case of an all-zero draw, the stream continues
    /// until a pulse with a 1 is drawn). The same draws as [`Pulse::bernoulli_duty`] with duty 1/2.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `len` is zero.
    pub fn bernoulli(len: usize, seed: u64) -> Result<Self> {
        Self::bernoulli_duty(len, 0.5, seed)
    }

    /// An i.i.d. Bernoulli{0, 1} pulse whose samples are 1 with probability `duty` (the duty
    /// cycle: the expected fraction of the K_p samples during which light is sent), from a
    /// ChaCha8 stream seeded with `seed`. One `bool` draw per sample; an all-zero draw is
    /// discarded and the stream continues until a pulse with a 1 is drawn (for a tiny `duty`
    /// and a short pulse this can take many draws).
    ///
    /// A low duty cycle (e.g. 0.05) is a harder acquisition than the default 1/2: each voxel's
    /// column has about `duty`·K_p nonzero samples, so the measurements carry less energy.
    ///
    /// ```
    /// use rdlidar::lidar::Pulse;
    /// let p = Pulse::<f64>::bernoulli_duty(10_000, 0.05, 1).unwrap();
    /// let ones = p.as_slice().iter().filter(|&&v| v == 1.0).count();
    /// assert!((400..600).contains(&ones));
    /// ```
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `len` is zero (`pulse_len`) or `duty` is not in (0, 1]
    /// (`duty`).
    pub fn bernoulli_duty(len: usize, duty: f64, seed: u64) -> Result<Self> {
        if len == 0 {
            return Err(Error::param("pulse_len", "must be at least 1"));
        }
        if !(duty > 0.0 && duty <= 1.0) {
            return Err(Error::param(
                "duty",
                format!(
                    "the probability of a 1 must be in (0, 1], got {}",
                    crate::units::number(duty)
                ),
            ));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        loop {
            let p: Vec<T> = (0..len)
                .map(|_| {
                    if rng.random_bool(duty) {
                        T::one()
                    } else {
                        T::zero()
                    }
                })
                .collect();
            if p.iter().any(|&v| v != T::zero()) {
                return Ok(Pulse { p });
            }
        }
    }

    /// The samples.
    pub fn as_slice(&self) -> &[T] {
        &self.p
    }

    /// K_p.
    pub fn len(&self) -> usize {
        self.p.len()
    }

    /// Always `false`: a pulse has at least one sample.
    pub fn is_empty(&self) -> bool {
        self.p.is_empty()
    }

    /// The mean value over the pulse's K_p samples.
    pub fn mean(&self) -> f64 {
        mean(&self.p)
    }

    /// p − mean(p) on the pulse's support: the zero-mean pulse of the debiased matched filter
    /// (docs/math.md §4). Not a physical pulse, so returned as a plain vector.
    pub fn zero_mean(&self) -> Vec<T> {
        zero_mean(&self.p)
    }

    /// Unwraps the samples.
    pub fn into_inner(self) -> Vec<T> {
        self.p
    }
}

/// The mean of `p` in `f64`, as Σ pₖ/K_p so that it cannot overflow for finite samples.
fn mean<T: Real>(p: &[T]) -> f64 {
    let n = p.len().max(1) as f64;
    p.iter().map(|v| v.as_f64() / n).sum()
}

/// p − mean(p): the zero-mean pulse of the debiased matched filter (docs/math.md §4), for any
/// pulse samples (an empty slice gives an empty vector). Finite for finite samples of one sign.
pub fn zero_mean<T: Real>(p: &[T]) -> Vec<T> {
    let m = mean(p);
    p.iter().map(|v| T::of_f64(v.as_f64() - m)).collect()
}

/// The pulse of a single-precision twin: `p` rounded to `f32`, or `None` when `T` is no wider
/// than `f32` (nothing to gain). A value that overflows `f32` becomes infinite, which the
/// twin's constructor refuses.
pub(super) fn single_pulse<T: Real>(p: &[T]) -> Option<Vec<f32>> {
    (std::mem::size_of::<T>() > std::mem::size_of::<f32>())
        .then(|| p.iter().map(|v| f32::of_f64(v.as_f64())).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bernoulli_duty_draws_zeros_and_ones_at_the_asked_rate() {
        let p = Pulse::<f64>::bernoulli_duty(40_000, 0.05, 11).unwrap();
        assert!(p.as_slice().iter().all(|&v| v == 0.0 || v == 1.0));
        // 2000 ones expected, standard deviation about 44.
        let ones = p.as_slice().iter().filter(|&&v| v == 1.0).count();
        assert!((1800..2200).contains(&ones), "{ones} ones");
        // Reproducible, and the same draws in both precisions.
        let again = Pulse::<f32>::bernoulli_duty(40_000, 0.05, 11).unwrap();
        assert!(again
            .as_slice()
            .iter()
            .zip(p.as_slice())
            .all(|(&a, &b)| a as f64 == b));
        // Duty 1 is a constant pulse; duty 1/2 is `bernoulli`.
        let on = Pulse::<f32>::bernoulli_duty(50, 1.0, 3).unwrap();
        assert!(on.as_slice().iter().all(|&v| v == 1.0));
        assert_eq!(
            Pulse::<f32>::bernoulli_duty(300, 0.5, 3).unwrap(),
            Pulse::<f32>::bernoulli(300, 3).unwrap()
        );
        // A one-sample pulse at a low duty is redrawn until it is not all zero.
        assert_eq!(
            Pulse::<f64>::bernoulli_duty(1, 0.05, 5).unwrap().as_slice(),
            &[1.0]
        );
    }

    #[test]
    fn bernoulli_duty_refuses_impossible_settings() {
        for duty in [0.0, -0.1, 1.5, f64::NAN, f64::INFINITY] {
            let e = Pulse::<f64>::bernoulli_duty(10, duty, 0).unwrap_err();
            assert!(e.to_string().contains("duty"), "{e}");
        }
        let e = Pulse::<f64>::bernoulli_duty(0, 0.5, 0).unwrap_err();
        assert!(e.to_string().contains("pulse_len"), "{e}");
    }
}
