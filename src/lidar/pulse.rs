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
    /// Validates and wraps `p`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an empty or all-zero pulse or a negative value (naming its
    /// index), [`Error::NonFinite`] for NaN or infinite values.
    pub fn new(p: Vec<T>) -> Result<Self> {
        if p.is_empty() {
            return Err(Error::param("pulse", "must have at least one sample"));
        }
        if let Some(i) = p.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: format!("pulse sample {i} ({})", p[i]),
            });
        }
        if let Some(i) = p.iter().position(|&v| v < T::zero()) {
            return Err(Error::param(
                "pulse",
                format!(
                    "sample {i} is negative ({}); light intensity must be ≥ 0",
                    p[i]
                ),
            ));
        }
        if p.iter().all(|&v| v == T::zero()) {
            return Err(Error::param("pulse", "is all zero: nothing is transmitted"));
        }
        Ok(Pulse { p })
    }

    /// An i.i.d. Bernoulli{0, 1} pulse with P(1) = 1/2 from a ChaCha8 stream seeded with `seed`
    /// (one `bool` draw per sample; in the unlikely case of an all-zero draw, the stream continues
    /// until a pulse with a 1 is drawn).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `len` is zero.
    pub fn bernoulli(len: usize, seed: u64) -> Result<Self> {
        if len == 0 {
            return Err(Error::param("pulse_len", "must be at least 1"));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        loop {
            let p: Vec<T> = (0..len)
                .map(|_| {
                    if rng.random_bool(0.5) {
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
    /// (DESIGN.md §4). Not a physical pulse, so returned as a plain vector.
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

/// p − mean(p): the zero-mean pulse of the debiased matched filter (DESIGN.md §4), for any
/// pulse samples (an empty slice gives an empty vector). Finite for finite samples of one sign.
pub fn zero_mean<T: Real>(p: &[T]) -> Vec<T> {
    let m = mean(p);
    p.iter().map(|v| T::of_f64(v.as_f64() - m)).collect()
}
