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
//! (bytes, or with a suffix K, M, G, T in powers of 1024) when set. A request beyond it is an
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
    /// [`Error::TooLarge`] if the plan needs more than is available.
    pub fn check(&self, request: &str, change: &str) -> Result<()> {
        let needed = self.total();
        match available_memory() {
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

/// The memory a request may use, in bytes: what the system reports available, under a cgroup
/// memory limit if there is one, and under `RDLIDAR_MEMORY_LIMIT` if set. `None` when nothing
/// is known (then only the documented bounds apply).
pub fn available_memory() -> Option<u64> {
    let system = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| meminfo_available(&t));
    let cgroup = cgroup_room();
    let env = std::env::var("RDLIDAR_MEMORY_LIMIT")
        .ok()
        .and_then(|v| parse_bytes(&v));
    [system, cgroup, env].into_iter().flatten().min()
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

/// Parses `123`, `64K`, `1.5G`, `2T` (powers of 1024).
pub fn parse_bytes(text: &str) -> Option<u64> {
    let t = text.trim();
    let (num, mult) = match t.chars().last()? {
        'k' | 'K' => (&t[..t.len() - 1], 1u64 << 10),
        'm' | 'M' => (&t[..t.len() - 1], 1 << 20),
        'g' | 'G' => (&t[..t.len() - 1], 1 << 30),
        't' | 'T' => (&t[..t.len() - 1], 1 << 40),
        _ => (t, 1),
    };
    let v: f64 = num.trim().parse().ok()?;
    let bytes = v * mult as f64;
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
        assert_eq!(parse_bytes("-1"), None);
        assert_eq!(parse_bytes("lots"), None);
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
