//! Array geometry and the acquisition regime (the paper's eq. 8–9).

use crate::error::{Error, Result};

/// The scene grid: `m × n` pixels, each with `ks` depth bins.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Geometry {
    /// Pixel rows (M).
    pub m: usize,
    /// Pixel columns (N).
    pub n: usize,
    /// Depth bins per pixel (K_s).
    pub ks: usize,
}

impl Geometry {
    /// A geometry with every dimension at least 1.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if a dimension is zero or the voxel count overflows.
    pub fn new(m: usize, n: usize, ks: usize) -> Result<Self> {
        if m == 0 || n == 0 || ks == 0 {
            return Err(Error::param(
                "size",
                format!("every dimension must be at least 1, got {m}x{n}x{ks}"),
            ));
        }
        m.checked_mul(n)
            .and_then(|p| p.checked_mul(ks))
            .ok_or_else(|| Error::param("size", format!("{m}x{n}x{ks} voxels overflow")))?;
        Ok(Geometry { m, n, ks })
    }

    /// Checks the grid against the bounds of [`crate::limits`]: at most
    /// [`MAX_SIDE`](crate::limits::MAX_SIDE) pixel rows and columns and
    /// [`MAX_DEPTH_BINS`](crate::limits::MAX_DEPTH_BINS) depth bins.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] `size` naming the bound exceeded.
    pub fn check_bounds(&self) -> Result<()> {
        crate::limits::check_grid(self.m, self.n, self.ks)
    }

    /// Parses `"MxNxKS"` (e.g. `"100x100x40"`).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the text when it is not three positive integers
    /// separated by `x`.
    pub fn parse(text: &str) -> Result<Self> {
        let parts: Vec<&str> = text.split(['x', 'X']).collect();
        let bad = || {
            Error::param(
                "size",
                format!("expected MxNxKS with positive integers (e.g. 100x100x40), got {text:?}"),
            )
        };
        if parts.len() != 3 {
            return Err(bad());
        }
        let v: Vec<usize> = parts
            .iter()
            .map(|p| p.trim().parse::<usize>().map_err(|_| bad()))
            .collect::<Result<_>>()?;
        Geometry::new(v[0], v[1], v[2])
    }

    /// Number of pixels, M·N.
    pub fn pixels(&self) -> usize {
        self.m * self.n
    }

    /// Number of unknowns, M·N·K_s.
    pub fn voxels(&self) -> usize {
        self.m * self.n * self.ks
    }

    /// Number of measurements for a pulse of length `kp`: K = K_p + K_s − 1.
    pub fn samples(&self, kp: usize) -> usize {
        kp + self.ks - 1
    }

    /// The pulse length at which measurements and unknowns balance: K = M·N·K_s, i.e.
    /// K_p = (M·N − 1)·K_s + 1 (eq. 9).
    pub fn critical_pulse_len(&self) -> usize {
        (self.pixels() - 1) * self.ks + 1
    }

    /// The regime of a pulse of length `kp` (eq. 8–9): compressive below the critical length,
    /// critical at it, redundant above it.
    pub fn regime(&self, kp: usize) -> Regime {
        let crit = self.critical_pulse_len();
        match kp.cmp(&crit) {
            std::cmp::Ordering::Less => Regime::Compressive,
            std::cmp::Ordering::Equal => Regime::Critical,
            std::cmp::Ordering::Greater => Regime::Redundant,
        }
    }
}

impl std::fmt::Display for Geometry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}x{}", self.m, self.n, self.ks)
    }
}

/// Measurements versus unknowns. Serialized as its lower-case name (`"compressive"`, …).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Regime {
    /// K < M·N·K_s: regularization (sparsity, a scene model, TV) is required.
    Compressive,
    /// K = M·N·K_s: A can be square and full rank.
    Critical,
    /// K > M·N·K_s: A approaches a frame; backprojection approximately inverts.
    Redundant,
}

impl Regime {
    /// The regime of `measurements` against `unknowns`: compressive with fewer measurements,
    /// critical with as many, redundant with more.
    pub fn of(measurements: usize, unknowns: usize) -> Regime {
        match measurements.cmp(&unknowns) {
            std::cmp::Ordering::Less => Regime::Compressive,
            std::cmp::Ordering::Equal => Regime::Critical,
            std::cmp::Ordering::Greater => Regime::Redundant,
        }
    }
}

impl std::fmt::Display for Regime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Regime::Compressive => "compressive",
            Regime::Critical => "critical",
            Regime::Redundant => "redundant",
        })
    }
}
