//! Limits: the documented bounds on every size and count, and the memory a request needs,
//! checked before anything is allocated.
//!
//! | what                                  | bound                      | command-line flag       |
//! |---------------------------------------|----------------------------|-------------------------|
//! | pixel rows M and columns N            | [`MAX_SIDE`] = 4096 each   | `--size`                |
//! | depth bins K_s                        | [`MAX_DEPTH_BINS`] = 65536 | `--size`, `--depth-bins`|
//! | pulse length K_p                      | [`MAX_PULSE_LEN`] = 2³¹    | `--pulse-len(s)`        |
//! | ADCs (code sets, tiles)               | [`MAX_ADCS`] = 4096        | `--adcs`, `--tiles`     |
//! | worker threads                        | [`MAX_THREADS`] = 1024     | `--threads`             |
//! | timed repeats                         | [`MAX_REPEATS`] = 10000    | `bench --repeats`       |
//! | memory of one request                 | what the machine has free  | (the flags above)       |
//!
//! The memory a request needs (scene, codes, measurements, operator and working buffers; the
//! data of a file read) is computed first and compared with [`available_memory`]: the memory
//! the system reports available (`MemAvailable` of `/proc/meminfo`, and the room left under a
//! cgroup v2 memory limit), lowered further by the environment variable `RDLIDAR_MEMORY_LIMIT`
//! when set (see [`parse_bytes`] for its syntax: `4000000000`, `4G`, `4GiB`, `4GB`; a value that
//! is not a byte count is refused, [`memory_limit`]). A request beyond it is an
//! [`Error::TooLarge`] stating the bytes needed, what they are for, and what to change.

use crate::error::{Error, Result};

/// The most pixel rows, and the most pixel columns, of a scene.
pub const MAX_SIDE: usize = 4096;
/// The most depth bins K_s of a scene.
pub const MAX_DEPTH_BINS: usize = 65_536;
/// The longest pulse K_p.
pub const MAX_PULSE_LEN: usize = 1 << 31;
/// The most ADCs of one acquisition (code sets of a multi-ADC array, or tiles).
pub const MAX_ADCS: usize = 4096;
/// The most worker threads.
pub const MAX_THREADS: usize = 1024;
/// The most timed repeats of one measurement.
pub const MAX_REPEATS: usize = 10_000;

/// Checks a scene grid of `m`×`n` pixels and `ks` depth bins against [`MAX_SIDE`] and
/// [`MAX_DEPTH_BINS`] (`Geometry::check_bounds` in `lidar` calls it).
///
/// # Errors
/// [`Error::InvalidParameter`] `size` naming the bound exceeded.
pub fn check_grid(m: usize, n: usize, ks: usize) -> Result<()> {
    if m > MAX_SIDE || n > MAX_SIDE {
        return Err(Error::param(
            "size",
            format!("{m}x{n}x{ks}: at most {MAX_SIDE} pixel rows and {MAX_SIDE} columns"),
        ));
    }
    if ks > MAX_DEPTH_BINS {
        return Err(Error::param(
            "size",
            format!("{m}x{n}x{ks}: at most {MAX_DEPTH_BINS} depth bins"),
        ));
    }
    Ok(())
}

/// Checks a count against its bound: `name` is the setting, `bound` one of this module's
/// constants.
///
/// # Errors
/// [`Error::InvalidParameter`] `name` if `value` is 0 or above `bound`.
pub fn check_count(name: &'static str, value: usize, bound: usize) -> Result<()> {
    if value == 0 {
        return Err(Error::param(name, "must be at least 1, got 0"));
    }
    if value > bound {
        return Err(Error::param(
            name,
            format!("{value} is more than the limit of {bound}"),
        ));
    }
    Ok(())
}

/// The memory a request needs, part by part.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MemoryPlan {
    parts: Vec<(&'static str, u128)>,
}

impl MemoryPlan {
    /// An empty plan.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `count` elements of `size` bytes for `what` (computed without overflow).
    pub fn add(mut self, what: &'static str, count: u128, size: usize) -> Self {
        self.parts.push((what, count.saturating_mul(size as u128)));
        self
    }

    /// The bytes of every part together.
    pub fn total(&self) -> u128 {
        self.parts.iter().fold(0u128, |a, p| a.saturating_add(p.1))
    }

    /// The parts, largest first, as `scene 1.2 GB, codes 300 MB`.
    pub fn describe(&self) -> String {
        let mut parts: Vec<_> = self.parts.iter().filter(|p| p.1 > 0).collect();
        parts.sort_by_key(|p| std::cmp::Reverse(p.1));
        parts
            .iter()
            .map(|(what, b)| format!("{what} {}", crate::units::bytes(*b)))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Checks the plan against [`available_memory`]. `request` describes what was asked (e.g.
    /// `"simulate 100000x100000x100, K_p 10"`), `change` what to change (e.g.
    /// `"lower --size or --pulse-len"`).
    ///
    /// # Errors
    /// [`Error::TooLarge`] if the plan needs more than is available; the errors of
    /// [`memory_limit`].
    pub fn check(&self, request: &str, change: &str) -> Result<()> {
        let needed = self.total();
        match available_memory()? {
            Some(available) if needed > available as u128 => Err(Error::TooLarge {
                request: request.to_string(),
                needed,
                parts: self.describe(),
                available: available as u128,
                change: change.to_string(),
            }),
            _ => Ok(()),
        }
    }
}

/// The environment variable that lowers the memory budget of every request.
pub const MEMORY_LIMIT_VAR: &str = "RDLIDAR_MEMORY_LIMIT";

/// The memory a request may use, in bytes: what the system reports available, under a cgroup
/// memory limit if there is one, and under `RDLIDAR_MEMORY_LIMIT` if set. `None` when nothing
/// is known (then only the documented bounds apply).
///
/// # Errors
/// Those of [`memory_limit`].
pub fn available_memory() -> Result<Option<u64>> {
    let env = memory_limit()?;
    let system = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| meminfo_available(&t));
    let cgroup = cgroup_room();
    Ok([system, cgroup, env].into_iter().flatten().min())
}

/// The budget `RDLIDAR_MEMORY_LIMIT` sets, in bytes: `None` when the variable is not set or
/// empty. Its syntax is [`parse_bytes`]'s.
///
/// # Errors
/// [`Error::InvalidParameter`] named `RDLIDAR_MEMORY_LIMIT` for any other value (a negative
/// number, an unknown unit, text that is not a number, bytes that are not Unicode): a budget
/// that was asked for is never ignored.
pub fn memory_limit() -> Result<Option<u64>> {
    let Some(value) = std::env::var_os(MEMORY_LIMIT_VAR) else {
        return Ok(None);
    };
    let text = value.to_string_lossy();
    if text.trim().is_empty() {
        return Ok(None);
    }
    match parse_bytes(&text) {
        Some(bytes) => Ok(Some(bytes)),
        None => {
            let mut shown: String = text.chars().take(40).collect();
            if text.chars().count() > 40 {
                shown.push('…');
            }
            Err(Error::param(
                MEMORY_LIMIT_VAR,
                format!(
                    "expected a number of bytes ≥ 0, with an optional unit: K, M, G, T or KiB, \
                     MiB, GiB, TiB (powers of 1024), kB, MB, GB, TB (powers of 1000), e.g. 4G \
                     or 500MB; got {shown:?}"
                ),
            ))
        }
    }
}

/// `MemAvailable` of a `/proc/meminfo` text, in bytes.
fn meminfo_available(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kb.checked_mul(1024)
}

/// The room left under this process's cgroup v2 memory limit, if it has one.
fn cgroup_room() -> Option<u64> {
    let path = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let rel = path.lines().find_map(|l| l.strip_prefix("0::"))?;
    let dir = std::path::Path::new("/sys/fs/cgroup").join(rel.trim_start_matches('/'));
    let max: u64 = std::fs::read_to_string(dir.join("memory.max"))
        .ok()?
        .trim()
        .parse()
        .ok()?;
    let current: u64 = std::fs::read_to_string(dir.join("memory.current"))
        .ok()
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or(0);
    Some(max.saturating_sub(current))
}

/// Parses a byte count: a number ≥ 0 (`123`, `1.5e9`; a fraction of a byte is dropped),
/// optionally followed by a unit, with or without a space and in either case: `K`, `M`, `G`,
/// `T` and `KiB`, `MiB`, `GiB`, `TiB` in powers of 1024 (`64K`, `1.5G`, `5MiB`); `kB`, `MB`,
/// `GB`, `TB` in powers of 1000, as the messages print sizes (`5MB` is 5 000 000 bytes); `B`
/// for bytes. `None` for anything else: a negative number, an unknown unit, `inf` or `nan`,
/// 2⁶⁴ bytes or more.
pub fn parse_bytes(text: &str) -> Option<u64> {
    const UNITS: [(&str, f64); 13] = [
        ("kib", 1024.0),
        ("mib", 1048576.0),
        ("gib", 1073741824.0),
        ("tib", 1099511627776.0),
        ("kb", 1e3),
        ("mb", 1e6),
        ("gb", 1e9),
        ("tb", 1e12),
        ("k", 1024.0),
        ("m", 1048576.0),
        ("g", 1073741824.0),
        ("t", 1099511627776.0),
        ("b", 1.0),
    ];
    let t = text.trim();
    let lower = t.to_ascii_lowercase();
    let (num, mult) = UNITS
        .iter()
        .find(|(unit, _)| lower.ends_with(unit))
        .map_or((t, 1.0), |&(unit, mult)| (&t[..t.len() - unit.len()], mult));
    let num = num.trim_end();
    // What `f64::from_str` takes but a count is not: a sign, `inf`, `nan`.
    if num.starts_with(['-', '+'])
        || !num
            .chars()
            .all(|c| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '+' | '-'))
    {
        return None;
    }
    let bytes = num.parse::<f64>().ok()? * mult;
    (bytes.is_finite() && bytes >= 0.0 && bytes < u64::MAX as f64).then_some(bytes as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans_add_up_without_overflow_and_describe_their_parts() {
        let p = MemoryPlan::new()
            .add("scene", 1_000_000, 8)
            .add("codes", u128::MAX, 2);
        assert_eq!(p.total(), u128::MAX);
        let small = MemoryPlan::new().add("scene", 1000, 8).add("codes", 3, 1);
        assert_eq!(small.total(), 8003);
        assert_eq!(small.describe(), "scene 8 kB, codes 3 B");
    }

    #[test]
    fn byte_texts_parse() {
        assert_eq!(parse_bytes("1G"), Some(1 << 30));
        assert_eq!(parse_bytes("1.5k"), Some(1536));
        assert_eq!(parse_bytes("42"), Some(42));
        assert_eq!(parse_bytes(" 42 "), Some(42));
        assert_eq!(parse_bytes("1e9"), Some(1_000_000_000));
        assert_eq!(parse_bytes("5MiB"), Some(5 << 20));
        assert_eq!(parse_bytes("5 mib"), Some(5 << 20));
        assert_eq!(parse_bytes("5MB"), Some(5_000_000));
        assert_eq!(parse_bytes("5kB"), Some(5_000));
        assert_eq!(parse_bytes("2 GB"), Some(2_000_000_000));
        assert_eq!(parse_bytes("1TiB"), Some(1 << 40));
        assert_eq!(parse_bytes("100B"), Some(100));
        assert_eq!(parse_bytes("0"), Some(0));
        for bad in [
            "-1", "-1M", "+5", "lots", "", "MB", "5XB", "5 M B", "inf", "nan", "1e30", "5e",
            "0x10", "5PB", "5MB5",
        ] {
            assert_eq!(parse_bytes(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn meminfo_is_read() {
        let t = "MemTotal:  100 kB\nMemAvailable:   2048 kB\n";
        assert_eq!(meminfo_available(t), Some(2048 * 1024));
        assert_eq!(meminfo_available("MemTotal: 1 kB\n"), None);
    }

    #[test]
    fn bounds_are_checked() {
        assert!(check_grid(4096, 4096, 65_536).is_ok());
        assert!(check_grid(4097, 1, 1).is_err());
        assert!(check_grid(1, 1, 65_537).is_err());
        assert!(check_count("threads", 1024, MAX_THREADS).is_ok());
        assert!(check_count("threads", 1025, MAX_THREADS).is_err());
        assert!(check_count("repeats", 0, MAX_REPEATS).is_err());
    }
}
