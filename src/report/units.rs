//! Numbers with units for people: SI prefixes, metres, seconds, bytes, frame rates.

/// `v` with an SI prefix and four significant digits: `si(0.0921, "s")` is `"92.1 ms"`.
pub fn si(v: f64, unit: &str) -> String {
    const PREFIXES: [(f64, &str); 11] = [
        (1e18, "E"),
        (1e15, "P"),
        (1e12, "T"),
        (1e9, "G"),
        (1e6, "M"),
        (1e3, "k"),
        (1.0, ""),
        (1e-3, "m"),
        (1e-6, "µ"),
        (1e-9, "n"),
        (1e-12, "p"),
    ];
    if v == 0.0 || !v.is_finite() {
        return format!("{v} {unit}");
    }
    let (scale, prefix) = PREFIXES
        .iter()
        .copied()
        .find(|(s, _)| v.abs() >= *s * (1.0 - 5e-5))
        .unwrap_or((1e-15, "f"));
    let x = v / scale;
    let decimals = if x.abs() >= 99.995 {
        1
    } else if x.abs() >= 9.9995 {
        2
    } else {
        3
    };
    let text = format!("{x:.decimals$}");
    // "6.000" → "6", "2.500" → "2.5": the digits that carry information.
    let text = if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    };
    format!("{text} {prefix}{unit}")
}

/// A length: centimetres between 1 cm and 1 m, SI prefixes otherwise.
pub fn metres(v: f64) -> String {
    if (0.01..1.0).contains(&v) {
        let x = v * 100.0;
        let decimals = if x >= 9.9995 { 2 } else { 3 };
        return format!("{x:.decimals$} cm");
    }
    si(v, "m")
}

/// A duration: SI prefixes below a minute, then minutes, hours and days.
pub fn seconds(v: f64) -> String {
    let (x, unit) = match v {
        v if v < 60.0 => return si(v, "s"),
        v if v < 3600.0 => (v / 60.0, "min"),
        v if v < 172_800.0 => (v / 3600.0, "h"),
        v => (v / 86_400.0, "days"),
    };
    let decimals = if x >= 99.95 {
        0
    } else if x >= 9.995 {
        1
    } else {
        2
    };
    format!("{x:.decimals$} {unit}")
}

pub use crate::units::bytes;

/// A rate of frames per second: four significant digits below 100, whole frames up to 10⁷,
/// scientific notation above.
pub fn frames_per_second(v: f64) -> String {
    if v >= 1e7 {
        return format!("{v:.3e} frames/s");
    }
    if v >= 100.0 || !v.is_finite() || v <= 0.0 {
        return format!("{v:.0} frames/s");
    }
    let decimals = (3 - v.log10().floor() as i32).max(0) as usize;
    let text = format!("{v:.decimals$}");
    let text = if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    };
    format!("{text} frames/s")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn si_prefixes_and_digits() {
        assert_eq!(si(0.029_979_245_8, "m"), "29.98 mm");
        assert_eq!(metres(0.029_979_245_8), "2.998 cm");
        assert_eq!(metres(1.199_169_832), "1.199 m");
        assert_eq!(metres(0.299_792_458), "29.98 cm");
        assert_eq!(seconds(4785.0), "1.33 h");
        assert_eq!(seconds(90.0), "1.50 min");
        assert_eq!(seconds(5e-3), "5 ms");
        assert_eq!(frames_per_second(166_450.28), "166450 frames/s");
        assert_eq!(frames_per_second(39.99), "39.99 frames/s");
        assert_eq!(frames_per_second(1e15), "1.000e15 frames/s");
        assert_eq!(si(6e-6, "s"), "6 µs");
        assert_eq!(si(1.199_169_832, "m"), "1.199 m");
        assert_eq!(si(200e-12, "s"), "200 ps");
        assert_eq!(si(0.0921, "s"), "92.1 ms");
    }
}
