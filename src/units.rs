//! Quantities as text for messages, in one place: bytes with a decimal prefix. A root helper:
//! it imports nothing from the crate.

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
}
