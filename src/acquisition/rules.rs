//! The rules about inputs, the same for the command line and Python: pulses, finite values,
//! results that overflow, and counts in messages.

use super::*;

/// The singular or plural of a count: `1 row`, `3 rows`.
pub fn count_of(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

/// Checks a pulse: at most [`limits::MAX_PULSE_LEN`] samples, and the rules of
/// [`Pulse::new`]: at least one sample, finite, ≥ 0, not all zero.
///
/// # Errors
/// [`Error::InvalidParameter`] (`pulse`) naming the first bad sample.
pub fn check_pulse(pulse: &[f64]) -> Result<()> {
    if pulse.is_empty() {
        return Err(Error::param("pulse", "must have at least one sample"));
    }
    if pulse.len() > limits::MAX_PULSE_LEN {
        return Err(Error::param(
            "pulse",
            format!(
                "{} samples, more than the limit of {}",
                pulse.len(),
                limits::MAX_PULSE_LEN
            ),
        ));
    }
    // The rules themselves are the pulse's own.
    Pulse::check(pulse)
}

/// The pulse in `T`, refused if converting it overflows or loses every nonzero sample.
///
/// # Errors
/// [`Error::InvalidParameter`] (`pulse`).
pub fn pulse_in<T: Real>(pulse: &[f64]) -> Result<Vec<T>> {
    let p: Vec<T> = pulse.iter().map(|&v| T::of_f64(v)).collect();
    if let Some(i) = p.iter().position(|v| !v.is_finite()) {
        return Err(Error::param(
            "pulse",
            format!(
                "sample {i} ({:e}) overflows {}: scale the pulse down or compute in f64",
                pulse[i],
                T::NAME
            ),
        ));
    }
    if p.iter().all(|&v| v == T::zero()) {
        return Err(Error::param(
            "pulse",
            format!(
                "every sample underflows {} to zero (the largest is {:e}): scale the pulse up \
                 or compute in f64",
                T::NAME,
                pulse.iter().cloned().fold(0.0, f64::max)
            ),
        ));
    }
    Ok(p)
}

/// Checks that every value of `values` is finite; `what` names them (a flag, a file or an
/// argument).
///
/// # Errors
/// [`Error::InvalidParameter`] naming `what` and the first non-finite entry.
pub fn check_finite<T: Real>(values: &[T], what: &'static str) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(Error::param(
            what,
            format!("entry {i} is {}, not a finite value", values[i]),
        )),
    }
}

/// Checks a result computed from finite inputs (`input` names them): a NaN or an infinite
/// value means that the inputs overflow `T` through the operator.
///
/// # Errors
/// [`Error::InvalidParameter`] naming `input`.
pub fn check_finite_result<T: Real>(values: &[T], what: &str, input: &'static str) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(Error::param(
            input,
            format!(
                "the {what} of these values overflow {} (entry {i} is {}); scale the input \
                 down{}",
                T::NAME,
                values[i],
                if T::NAME == "f32" {
                    " or compute in f64"
                } else {
                    ""
                }
            ),
        )),
    }
}
