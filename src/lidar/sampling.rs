//! Time and depth: the sampling period τ of the ADC and the depth bin τ·c/2 it resolves.

use crate::error::{Error, Result};

/// Speed of light in vacuum, m/s.
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// Length of one depth bin, τ·c/2 metres, for a sampling period of `tau_s` seconds
/// (τ = 200 ps gives 2.998 cm).
///
/// # Errors
/// [`Error::InvalidParameter`] (`tau_s`) unless τ is finite and > 0.
pub fn depth_bin_m(tau_s: f64) -> Result<f64> {
    if tau_s.is_finite() && tau_s > 0.0 {
        Ok(tau_s * SPEED_OF_LIGHT / 2.0)
    } else {
        Err(Error::param(
            "tau_s",
            format!(
                "the sampling period must be finite and > 0 seconds, got {}",
                crate::units::number(tau_s)
            ),
        ))
    }
}

/// The sampling period assumed when none is given: τ = 200 ps (a depth bin of 3 cm).
pub const DEFAULT_TAU_S: f64 = 200e-12;

/// Parses a sampling period with its unit — `"200ps"`, `"0.2 ns"`, `"2e-10s"` — into seconds.
/// Units: `fs`, `ps`, `ns`, `us` or `µs`, `ms`, `s`.
///
/// # Errors
/// [`Error::InvalidParameter`] (`tau`) if the text is not a number followed by one of these
/// units, or if the period is not finite and > 0.
///
/// # Example
/// ```
/// let tau = rdlidar::lidar::parse_tau("200ps")?;
/// assert!((tau - 200e-12).abs() < 1e-24);
/// assert!(rdlidar::lidar::parse_tau("200").is_err()); // a unit is required
/// # Ok::<(), rdlidar::Error>(())
/// ```
pub fn parse_tau(text: &str) -> Result<f64> {
    const UNITS: [(&str, f64); 7] = [
        ("fs", 1e-15),
        ("ps", 1e-12),
        ("ns", 1e-9),
        ("us", 1e-6),
        ("µs", 1e-6),
        ("ms", 1e-3),
        ("s", 1.0),
    ];
    let t = text.trim();
    let bad = || {
        Error::param(
            "tau",
            format!(
                "expected a duration with a unit (fs, ps, ns, us, ms, s), e.g. 200ps, got {text:?}"
            ),
        )
    };
    let (number, scale) = UNITS
        .iter()
        .find_map(|&(u, scale)| t.strip_suffix(u).map(|n| (n, scale)))
        .ok_or_else(bad)?;
    let number = number.trim_end();
    // Reject what `f64::from_str` accepts but a duration is not ("inf", "nan", a bare sign).
    if !number
        .chars()
        .all(|c| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '+' | '-'))
    {
        return Err(bad());
    }
    let v: f64 = number.parse().map_err(|_| bad())?;
    check_tau(v * scale)
}

/// τ itself, finite and > 0.
pub(crate) fn check_tau(tau_s: f64) -> Result<f64> {
    if tau_s.is_finite() && tau_s > 0.0 {
        Ok(tau_s)
    } else {
        Err(Error::param(
            "tau",
            format!("the sampling period must be finite and > 0 seconds, got {tau_s:e} s"),
        ))
    }
}
