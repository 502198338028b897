//! Quantities as text for messages, in one place: bytes with a decimal prefix, and numbers
//! however large or small in a few characters. A root helper: it imports nothing from the crate.

use std::fmt::{Display, LowerExp};

use num_traits::Float;

/// A number as messages echo it: as Rust writes it (`0.25`, `-3`, `1500`) for magnitudes from
/// 10⁻⁴ up to 10¹⁰, in scientific notation beyond (`1e-300`, `-1e308`, `5e-324`), so that a
/// value of any size stays a short part of a one-line message. The digits are the shortest that
/// read back as the same value; NaN and the infinities are `NaN`, `inf` and `-inf`.
pub fn number<X: Float + Display + LowerExp>(x: X) -> String {
    let magnitude = x.abs().to_f64().unwrap_or(f64::NAN);
    if magnitude == 0.0 || !magnitude.is_finite() || (1e-4..1e10).contains(&magnitude) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// Bytes with a decimal prefix and three significant digits (`"37.5 MB"`, `"1.2 GB"`).
pub fn bytes(b: impl Into<u128>) -> String {
    let b: u128 = b.into();
    if b < 1000 {
        return format!("{b} B");
    }
    let x = b as f64;
    let (scale, prefix) = [
        (1e18, "E"),
        (1e15, "P"),
        (1e12, "T"),
        (1e9, "G"),
        (1e6, "M"),
    ]
    .into_iter()
    .find(|(s, _)| x >= *s * 0.9995)
    .unwrap_or((1e3, "k"));
    let y = x / scale;
    let decimals = if y >= 99.95 {
        0
    } else if y >= 9.995 {
        1
    } else {
        2
    };
    let text = format!("{y:.decimals$}");
    let text = if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    };
    format!("{text} {prefix}B")
}

/// Serializes a duration as seconds (a float), as reports give times.
///
/// # Errors
/// The serializer's.
pub fn serialize_seconds<S: serde::Serializer>(
    d: &std::time::Duration,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_f64(d.as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_have_three_significant_digits() {
        assert_eq!(bytes(37_548_750u64), "37.5 MB");
        assert_eq!(bytes(1_201_560_000u64), "1.2 GB");
        assert_eq!(bytes(120_000u64), "120 kB");
        assert_eq!(bytes(999u64), "999 B");
        assert_eq!(bytes(8_000_000_000_000u64), "8 TB");
        assert!(bytes(u128::MAX).ends_with(" EB"));
    }

    #[test]
    fn numbers_of_any_size_are_short() {
        assert_eq!(number(0.25), "0.25");
        assert_eq!(number(-3.0), "-3");
        assert_eq!(number(1500.0), "1500");
        assert_eq!(number(0.0), "0");
        assert_eq!(number(1e-300), "1e-300");
        assert_eq!(number(-1e308), "-1e308");
        assert_eq!(number(1e-320), "1e-320");
        assert_eq!(number(1.5e10), "1.5e10");
        assert_eq!(number(1e300f64 as f32), "inf");
        assert_eq!(number(f64::NAN), "NaN");
        assert_eq!(number(-f64::INFINITY), "-inf");
        assert_eq!(number(1e-30f32), "1e-30");
        for x in [
            1e-300,
            -1e308,
            f64::MIN_POSITIVE,
            5e-324,
            1.0 / 3.0,
            123456.789,
        ] {
            assert_eq!(number(x).parse::<f64>().unwrap(), x);
            assert!(number(x).len() <= 24, "{}", number(x));
        }
    }
}
