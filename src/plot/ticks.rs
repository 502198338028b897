//! Tick values for linear axes (the 1-2-5 rule) and logarithmic axes (decades), and their labels.

use crate::error::{Error, Result};

/// A step of the form {1, 2, 5} × 10^k, the smallest such that `span` is covered by at most
/// `max_intervals` steps. Returns the step as (mantissa, exponent).
fn nice_step(span: f64, max_intervals: usize) -> (i64, i32) {
    let raw = span / max_intervals as f64;
    let mut e = raw.log10().floor() as i32;
    // Guard against rounding of log10 near exact powers of ten.
    if pow10(e) > raw {
        e -= 1;
    }
    if pow10(e + 1) <= raw {
        e += 1;
    }
    for m in [1, 2, 5] {
        if m as f64 * pow10(e) >= raw * (1.0 - 1e-12) {
            return (m, e);
        }
    }
    (1, e + 1)
}

/// 10^e, correctly rounded.
pub(crate) fn pow10(e: i32) -> f64 {
    format!("1e{e}").parse().unwrap_or(f64::NAN)
}

/// `i · m · 10^e`, computed so that decimal steps come out exact where possible.
fn tick_value(i: i64, m: i64, e: i32) -> f64 {
    let n = (i * m) as f64;
    if e >= 0 {
        n * pow10(e)
    } else {
        n / pow10(-e)
    }
}

/// Linear ticks: a step of {1, 2, 5} × 10^k and every multiple of it from the largest one at
/// or below `lo` to the smallest one at or above `hi`, so the ticks cover `[lo, hi]` with at most
/// `max_intervals` (at least 2) steps. A degenerate range (`lo == hi`) is widened by 10 % of the value
/// (by 1 around 0).
///
/// ```
/// let t = rdlidar::plot::linear_ticks(0.13, 0.92, 5).unwrap();
/// assert_eq!(t, vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
/// ```
///
/// # Errors
/// [`Error::NonFinite`] for a NaN or infinite end; [`Error::InvalidParameter`] (`range`) if
/// `lo > hi` or the range is too wide to represent, (`max_intervals`) if it is below 2.
pub fn linear_ticks(lo: f64, hi: f64, max_intervals: usize) -> Result<Vec<f64>> {
    Ok(linear_ticks_with_step(lo, hi, max_intervals)?.0)
}

/// [`linear_ticks`] and the step, as the decimal exponent of its last significant digit.
fn linear_ticks_with_step(lo: f64, hi: f64, max_intervals: usize) -> Result<(Vec<f64>, i32)> {
    if !lo.is_finite() || !hi.is_finite() {
        return Err(Error::NonFinite {
            what: format!("axis range [{lo}, {hi}]"),
        });
    }
    if lo > hi {
        return Err(Error::param("range", format!("[{lo}, {hi}] is reversed")));
    }
    if max_intervals < 2 {
        // A range with a multiple of the step strictly inside needs two intervals, whatever
        // the step.
        return Err(Error::param(
            "max_intervals",
            format!("{max_intervals}: at least two intervals are needed"),
        ));
    }
    let (lo, hi) = if lo == hi {
        let d = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        (lo - d, hi + d)
    } else {
        (lo, hi)
    };
    let span = hi - lo;
    if !span.is_finite() || span < f64::MIN_POSITIVE {
        return Err(Error::param(
            "range",
            format!("[{lo}, {hi}] cannot be divided into ticks"),
        ));
    }
    let (mut m, mut e) = nice_step(span, max_intervals);
    // Once the step is at least the span, two intervals cover the range: a few rounds at most.
    for _ in 0..8 {
        let step = tick_value(1, m, e);
        let first = (lo / step).floor();
        let last = (hi / step).ceil();
        if !(first.abs() < 1e15 && last.abs() < 1e15) {
            return Err(Error::param(
                "range",
                format!("[{lo}, {hi}] is too wide for its step"),
            ));
        }
        let (mut first, mut last) = (first as i64, last as i64);
        // Round-off in the divisions may put an end tick one step too far out or in.
        while tick_value(first + 1, m, e) <= lo {
            first += 1;
        }
        while tick_value(first, m, e) > lo {
            first -= 1;
        }
        while tick_value(last - 1, m, e) >= hi {
            last -= 1;
        }
        while tick_value(last, m, e) < hi {
            last += 1;
        }
        if (last - first) as usize <= max_intervals {
            return Ok(((first..=last).map(|i| tick_value(i, m, e)).collect(), e));
        }
        // The range straddles more steps than allowed: take the next larger step.
        (m, e) = match m {
            1 => (2, e),
            2 => (5, e),
            _ => (1, e + 1),
        };
    }
    Err(Error::param(
        "range",
        format!("[{lo}, {hi}] cannot be divided into ticks"),
    ))
}

/// Ticks inside `[lo, hi]` (`lo < hi`, both finite) for an axis of fixed range: the densest
/// {1, 2, 5} × 10^k step giving at most `target + 1` ticks, or a denser one if that would leave
/// fewer than two. Returns the ticks and the decimal exponent of the step's last digit.
pub(crate) fn ticks_within(lo: f64, hi: f64, target: usize) -> (Vec<f64>, i32) {
    let target = target.max(1);
    let (mut m, mut e) = nice_step(hi - lo, 4 * target + 4);
    let mut denser: Option<(Vec<f64>, i32)> = None;
    for _ in 0..16 {
        let step = tick_value(1, m, e);
        let (mut first, mut last) = ((lo / step).ceil() as i64, (hi / step).floor() as i64);
        // Round-off in the divisions may put an end tick one step too far out or in.
        while tick_value(first, m, e) < lo {
            first += 1;
        }
        while tick_value(first - 1, m, e) >= lo {
            first -= 1;
        }
        while tick_value(last, m, e) > hi {
            last -= 1;
        }
        while tick_value(last + 1, m, e) <= hi {
            last += 1;
        }
        let ticks: Vec<f64> = (first..=last).map(|i| tick_value(i, m, e)).collect();
        if ticks.len() <= target + 1 {
            return match denser {
                Some(d) if ticks.len() < 2 => d,
                _ => (ticks, e),
            };
        }
        denser = Some((ticks, e));
        (m, e) = match m {
            1 => (2, e),
            2 => (5, e),
            _ => (1, e + 1),
        };
    }
    denser.unwrap_or((vec![lo, hi], 0))
}

/// Decade ticks for a logarithmic axis: the powers of ten from the largest one at or below `lo`
/// to the smallest one at or above `hi`.
///
/// ```
/// let t = rdlidar::plot::log_ticks(0.03, 250.0).unwrap();
/// assert_eq!(t, vec![0.01, 0.1, 1.0, 10.0, 100.0, 1000.0]);
/// ```
///
/// # Errors
/// [`Error::NonFinite`] for a NaN or infinite end; [`Error::InvalidParameter`] (`range`) if
/// `lo` is not positive, `lo > hi`, or the enclosing decades underflow or overflow `f64`.
pub fn log_ticks(lo: f64, hi: f64) -> Result<Vec<f64>> {
    let (a, b) = decade_span(lo, hi)?;
    Ok((a..=b).map(pow10).collect())
}

/// The exponents of the decades enclosing `[lo, hi]`.
pub(crate) fn decade_span(lo: f64, hi: f64) -> Result<(i32, i32)> {
    if !lo.is_finite() || !hi.is_finite() {
        return Err(Error::NonFinite {
            what: format!("axis range [{lo}, {hi}]"),
        });
    }
    if lo <= 0.0 {
        return Err(Error::param(
            "range",
            format!("a logarithmic axis needs positive values, found {lo}"),
        ));
    }
    if lo > hi {
        return Err(Error::param("range", format!("[{lo}, {hi}] is reversed")));
    }
    let (a, b) = (decade_at_or_below(lo), decade_at_or_above(hi));
    if pow10(a) == 0.0 || pow10(b).is_infinite() {
        return Err(Error::param(
            "range",
            format!("[{lo}, {hi}] reaches beyond the decades a float can hold"),
        ));
    }
    Ok((a, b))
}

/// Bound on the decade exponents considered (`f64` spans about 10^−324 to 10^308).
const DECADE_LIMIT: i32 = 400;

/// The largest `k` with 10^k ≤ v, for positive finite `v` (clamped to ±400 otherwise).
pub(crate) fn decade_at_or_below(v: f64) -> i32 {
    let guess = v.log10().floor();
    let mut k = if guess.is_nan() {
        -DECADE_LIMIT
    } else {
        guess.clamp(-DECADE_LIMIT as f64, DECADE_LIMIT as f64) as i32
    };
    while k > -DECADE_LIMIT && pow10(k) > v {
        k -= 1;
    }
    while k < DECADE_LIMIT && pow10(k + 1) <= v {
        k += 1;
    }
    k
}

/// The smallest `k` with 10^k ≥ v (v > 0).
pub(crate) fn decade_at_or_above(v: f64) -> i32 {
    let k = decade_at_or_below(v);
    if pow10(k) < v {
        k + 1
    } else {
        k
    }
}

/// The label of a linear tick whose step's last significant digit is at 10^`e`: fixed-point
/// with just enough decimals, or `m.mmme±x` notation for very large or small magnitudes.
pub(crate) fn format_tick(v: f64, e: i32, largest: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if largest >= 1e6 || e < -4 {
        // Scientific with the exponent of the largest tick, keeping the digits down to the step's.
        let exp = decade_at_or_below(largest.abs());
        let digits = (exp - e).max(0) as usize;
        let mant = v / pow10(exp);
        return format!("{mant:.digits$}e{exp}");
    }
    let decimals = (-e).max(0) as usize;
    let s = format!("{v:.decimals$}");
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        "0".into()
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_have_just_enough_decimals() {
        assert_eq!(format_tick(0.30000000000000004, -1, 1.0), "0.3");
        assert_eq!(format_tick(2500.0, 2, 3000.0), "2500");
        assert_eq!(format_tick(-0.0, 0, 1.0), "0");
        assert_eq!(format_tick(0.25, -2, 1.0), "0.25");
        assert_eq!(format_tick(2e6, 6, 4e6), "2e6");
        assert_eq!(format_tick(2.5e-6, -7, 4e-6), "2.5e-6");
    }

    #[test]
    fn ticks_within_a_range_are_dense_enough() {
        assert_eq!(ticks_within(-0.1, 2.1, 2), (vec![0.0, 1.0, 2.0], 0));
        assert_eq!(
            ticks_within(-0.05, 1.05, 5).0,
            vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]
        );
        assert_eq!(ticks_within(0.1, 1.3, 1).0, vec![0.5, 1.0]);
        let (t, e) = ticks_within(-1600.0, 33600.0, 7);
        assert_eq!((t.len(), e), (7, 3));
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..5000 {
            let scale = pow10(rng.random_range(-6..7));
            let lo = (rng.random::<f64>() - 0.5) * 10.0 * scale;
            let hi = lo + (rng.random::<f64>() + 1e-3) * 5.0 * scale;
            let target = rng.random_range(1..12);
            let (t, _) = ticks_within(lo, hi, target);
            assert!(t.len() >= 2, "[{lo}, {hi}] / {target}: {t:?}");
            assert!(t.iter().all(|&v| v >= lo && v <= hi), "[{lo}, {hi}]: {t:?}");
            // At most one step denser than `target` allows, when that would leave one tick.
            assert!(
                t.len() <= (5 * (target + 1)).div_ceil(2) + 1,
                "[{lo}, {hi}] / {target}: {t:?}"
            );
        }
    }

    #[test]
    fn decades_are_exact() {
        assert_eq!(decade_at_or_below(1000.0), 3);
        assert_eq!(decade_at_or_below(999.999), 2);
        assert_eq!(decade_at_or_above(1e-3), -3);
        assert_eq!(decade_at_or_above(1.0001e-3), -2);
    }
}
