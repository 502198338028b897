//! The system's response: how a reflector at a continuous depth fills its voxel column.
//!
//! A reflector of amplitude a at depth d (in bins, continuous) puts a·g(k − d) into voxel k of
//! its pixel's column, where g is the response of the whole system (pulse chip shape, detector,
//! ADC), with g(0) = 1. The measurement operator stays linear in the voxels: only the scene's
//! voxels change with the response.
//!
//! | response | g(t) | a reflector at d = j + f fills |
//! |---|---|---|
//! | `delta` | 1 at t = 0, else 0 | voxel j, depths on the grid only (the model of the grid methods) |
//! | `triangle` | max(0, 1 − \|t\|) | voxels j and j + 1 with weights 1 − f and f (rectangular chips and an integrating ADC: the ideal system) |
//! | `gaussian:S` | exp(−t²/(2S²)), zero beyond [`GAUSSIAN_REACH`]·S | about 2·6.4·S voxels (a detector's jitter of S bins) |
//! | `measured:O:PATH` | samples of g, O per bin, from an `.npy` file | what a lab measured ([`Measured`]) |

use std::path::Path;
use std::sync::Arc;

use crate::error::{Error, Result};

/// The Gaussian response is zero beyond this many standard deviations, where it falls below
/// 10⁻⁹ (√(2·ln 10⁹) ≈ 6.44), so that a reflector fills a finite stretch of voxels.
pub const GAUSSIAN_REACH: f64 = 6.44;

/// The most samples per bin a measured response may have.
pub const MAX_OVERSAMPLING: usize = 10_000;

/// The most samples a measured response may have.
pub const MAX_MEASURED_SAMPLES: usize = 1 << 20;

/// The response g of the system, g(0) = 1: `delta`, `triangle`, `gaussian:S` or a measured one.
#[derive(Debug, Clone, PartialEq)]
pub enum Response {
    /// Depths on the grid: a reflector fills one voxel.
    Delta,
    /// g(t) = max(0, 1 − |t|): the ideal system of rectangular chips and an integrating ADC.
    Triangle,
    /// g(t) = exp(−t²/(2σ²)), σ in bins, zero beyond [`GAUSSIAN_REACH`]·σ.
    Gaussian {
        /// The standard deviation, in bins (finite, > 0).
        sigma: f64,
    },
    /// A measured response.
    Measured(Arc<Measured>),
}

/// A measured response: samples of g at `oversampling` samples per bin, read from a float64
/// `.npy` vector (any length from 2, nonnegative, finite, not all zero). Its largest sample is
/// t = 0 and is scaled to 1; between samples g is the cubic (Catmull–Rom) interpolation, zero
/// outside the samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    /// The samples, scaled so that the largest is 1.
    samples: Vec<f64>,
    /// Samples per bin.
    oversampling: usize,
    /// The index of the largest sample (t = 0).
    peak: usize,
    /// The file it was read from, as the specification gave it.
    path: String,
}

impl Measured {
    /// A measured response from its samples, `oversampling` per bin; `path` names it in
    /// messages and in [`Response::spec`].
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`kernel`) for fewer than 2 or more than
    /// [`MAX_MEASURED_SAMPLES`] samples, a negative or non-finite sample, all zeros, or an
    /// oversampling of 0 or above [`MAX_OVERSAMPLING`].
    pub fn new(samples: &[f64], oversampling: usize, path: &str) -> Result<Measured> {
        let bad = |why: String| Error::param("kernel", format!("{path}: {why}"));
        if !(1..=MAX_OVERSAMPLING).contains(&oversampling) {
            return Err(bad(format!(
                "{oversampling} samples per bin: 1 to {MAX_OVERSAMPLING}"
            )));
        }
        if !(2..=MAX_MEASURED_SAMPLES).contains(&samples.len()) {
            return Err(bad(format!(
                "{} samples: a measured response has 2 to {MAX_MEASURED_SAMPLES}",
                samples.len()
            )));
        }
        if let Some(i) = samples.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(bad(format!(
                "sample {i} is {}: samples are finite and nonnegative",
                crate::units::number(samples[i])
            )));
        }
        let (peak, top) = samples
            .iter()
            .copied()
            .enumerate()
            .fold(
                (0, 0.0),
                |(bi, bv), (i, v)| if v > bv { (i, v) } else { (bi, bv) },
            );
        if top <= 0.0 || top < f64::MIN_POSITIVE {
            return Err(bad("every sample is zero".into()));
        }
        Ok(Measured {
            samples: samples.iter().map(|v| v / top).collect(),
            oversampling,
            peak,
            path: path.to_string(),
        })
    }

    /// g(t) and its derivative, by Catmull–Rom interpolation of the samples.
    fn eval(&self, t: f64) -> (f64, f64) {
        let o = self.oversampling as f64;
        let u = self.peak as f64 + t * o;
        let n = self.samples.len();
        if !(u > -1.0 && u < n as f64) {
            return (0.0, 0.0);
        }
        let i = u.floor();
        let s = u - i;
        let i = i as i64;
        let at = |j: i64| {
            usize::try_from(j)
                .ok()
                .and_then(|j| self.samples.get(j))
                .copied()
                .unwrap_or(0.0)
        };
        let (p0, p1, p2, p3) = (at(i - 1), at(i), at(i + 1), at(i + 2));
        let a = -0.5 * p0 + 1.5 * p1 - 1.5 * p2 + 0.5 * p3;
        let b = p0 - 2.5 * p1 + 2.0 * p2 - 0.5 * p3;
        let c = -0.5 * p0 + 0.5 * p2;
        let value = ((a * s + b) * s + c) * s + p1;
        let slope = ((3.0 * a * s + 2.0 * b) * s + c) * o;
        (value, slope)
    }

    /// How far from t = 0 the samples reach, before and after, in bins.
    fn reach(&self) -> (f64, f64) {
        let o = self.oversampling as f64;
        (
            (self.peak as f64 + 1.0) / o,
            (self.samples.len() - self.peak) as f64 / o,
        )
    }
}

impl Response {
    /// The response a specification names: `delta`, `triangle`, `gaussian:S` (S in bins,
    /// finite, > 0) or `measured:O:PATH` (O samples per bin; `PATH` a vector of samples that
    /// `read` reads: [`crate::io::read_response`] reads it from a `.npy` file).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`kernel`) for an unknown name or a bad parameter; `read`'s
    /// errors.
    pub fn parse_with(spec: &str, read: &dyn Fn(&Path) -> Result<Vec<f64>>) -> Result<Response> {
        let spec = spec.trim();
        let (name, rest) = spec.split_once(':').unwrap_or((spec, ""));
        match (name, rest) {
            ("delta", "") => Ok(Response::Delta),
            ("triangle", "") => Ok(Response::Triangle),
            ("gaussian", s) => {
                let sigma: f64 = s.trim().parse().map_err(|_| {
                    Error::param(
                        "kernel",
                        format!("gaussian:S takes the width S in bins, got {s:?}"),
                    )
                })?;
                Response::gaussian(sigma)
            }
            ("measured", rest) => {
                let (o, path) = rest.split_once(':').ok_or_else(|| {
                    Error::param(
                        "kernel",
                        format!("measured:O:PATH takes samples per bin and a file, got {spec:?}"),
                    )
                })?;
                let o = o
                    .trim()
                    .parse::<usize>()
                    .ok()
                    .filter(|o| (1..=MAX_OVERSAMPLING).contains(o))
                    .ok_or_else(|| {
                        Error::param(
                            "kernel",
                            format!(
                                "measured:O:PATH: O is the samples per bin, 1 to \
                                 {MAX_OVERSAMPLING}, got {o:?}"
                            ),
                        )
                    })?;
                let samples = read(Path::new(path))?;
                Ok(Response::Measured(Arc::new(Measured::new(
                    &samples, o, path,
                )?)))
            }
            _ => Err(Error::param(
                "kernel",
                format!(
                    "{spec:?} is not one of \"delta\", \"triangle\", \"gaussian:S\", \
                     \"measured:O:PATH\""
                ),
            )),
        }
    }

    /// The response a specification names, as [`parse_with`](Self::parse_with), except that a
    /// measured response (which needs its file read) is refused.
    ///
    /// # Errors
    /// As [`parse_with`](Self::parse_with).
    pub fn parse(spec: &str) -> Result<Response> {
        Response::parse_with(spec, &|path| {
            Err(Error::param(
                "kernel",
                format!(
                    "{}: a measured response is read by rdlidar::io::read_response",
                    path.display()
                ),
            ))
        })
    }

    /// The Gaussian response of width `sigma` bins.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`kernel`) unless `sigma` is finite and in (0, 10⁶].
    pub fn gaussian(sigma: f64) -> Result<Response> {
        if !(sigma.is_finite() && sigma > 0.0 && sigma <= 1e6) {
            return Err(Error::param(
                "kernel",
                format!(
                    "gaussian:S needs a width S in (0, 1e6] bins, got {}",
                    crate::units::number(sigma)
                ),
            ));
        }
        Ok(Response::Gaussian { sigma })
    }

    /// The specification that [`parse`](Self::parse) reads back.
    pub fn spec(&self) -> String {
        match self {
            Response::Delta => "delta".into(),
            Response::Triangle => "triangle".into(),
            Response::Gaussian { sigma } => format!("gaussian:{sigma}"),
            Response::Measured(m) => format!("measured:{}:{}", m.oversampling, m.path),
        }
    }

    /// Whether depths lie on the grid (the delta response).
    pub fn is_delta(&self) -> bool {
        matches!(self, Response::Delta)
    }

    /// g(t).
    pub fn value(&self, t: f64) -> f64 {
        self.eval(t).0
    }

    /// g(t) and its derivative g′(t). The triangle's derivative is taken from the right in the
    /// depth (g′ = 1 on (−1, 0], −1 on (0, 1]), so that ∂/∂d of g(k − d) = −g′(k − d) is the
    /// right derivative at every depth, grid depths included.
    pub fn eval(&self, t: f64) -> (f64, f64) {
        match self {
            Response::Delta => (if t == 0.0 { 1.0 } else { 0.0 }, 0.0),
            Response::Triangle => {
                if t > -1.0 && t <= 0.0 {
                    (1.0 + t, 1.0)
                } else if t > 0.0 && t <= 1.0 {
                    (1.0 - t, -1.0)
                } else {
                    (0.0, 0.0)
                }
            }
            Response::Gaussian { sigma } => {
                let u = t / sigma;
                if u.abs() > GAUSSIAN_REACH {
                    (0.0, 0.0)
                } else {
                    let v = (-0.5 * u * u).exp();
                    (v, -u / sigma * v)
                }
            }
            Response::Measured(m) => m.eval(t),
        }
    }

    /// How far g reaches before and after t = 0, in bins: g(t) = 0 for t ≤ −before and
    /// t ≥ after.
    pub fn reach(&self) -> (f64, f64) {
        match self {
            Response::Delta => (0.5, 0.5),
            Response::Triangle => (1.0, 1.0),
            Response::Gaussian { sigma } => (GAUSSIAN_REACH * sigma, GAUSSIAN_REACH * sigma),
            Response::Measured(m) => m.reach(),
        }
    }

    /// The voxels k of a column of `ks` that a reflector at depth `d` may fill or, moving, start
    /// to fill: those with −before ≤ k − d ≤ after, clipped to the column (empty when none).
    pub fn voxels(&self, d: f64, ks: usize) -> std::ops::Range<usize> {
        if self.is_delta() {
            let k = d.round();
            return if d == k && k >= 0.0 && k < ks as f64 {
                k as usize..k as usize + 1
            } else {
                0..0
            };
        }
        let (before, after) = self.reach();
        let lo = (d - before).ceil();
        let hi = (d + after).floor() + 1.0;
        let clip = |v: f64| v.clamp(0.0, ks as f64) as usize;
        let (lo, hi) = (clip(lo), clip(hi));
        lo..hi.max(lo)
    }

    /// Adds a·g(k − d) to the column `col`, for every k where it may be nonzero.
    pub fn add_to(&self, a: f64, d: f64, col: &mut [f64]) {
        for k in self.voxels(d, col.len()) {
            col[k] += a * self.value(k as f64 - d);
        }
    }
}

impl std::fmt::Display for Response {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.spec())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_response_peaks_at_one_and_its_slope_is_the_difference_quotient() {
        let measured: Vec<f64> = (0..41)
            .map(|i| (-((i as f64 - 17.0) / 6.0).powi(2)).exp() * 3.0)
            .collect();
        let responses = [
            Response::Triangle,
            Response::gaussian(0.8).unwrap(),
            Response::Measured(Arc::new(Measured::new(&measured, 8, "m.npy").unwrap())),
        ];
        for r in &responses {
            assert!((r.value(0.0) - 1.0).abs() < 1e-12, "{r}");
            for t in [-1.7, -0.6, -0.3, 0.2, 0.45, 0.8, 1.3] {
                let h = 1e-6;
                let numeric = (r.value(t + h) - r.value(t - h)) / (2.0 * h);
                let (_, slope) = r.eval(t);
                assert!(
                    (numeric - slope).abs() < 1e-4,
                    "{r} at {t}: {numeric} vs {slope}"
                );
            }
            let (before, after) = r.reach();
            assert_eq!(r.value(-before - 1e-9), 0.0, "{r}");
            assert_eq!(r.value(after + 1e-9), 0.0, "{r}");
        }
    }

    #[test]
    fn a_reflector_between_bins_fills_its_neighbours_by_the_response() {
        let mut col = vec![0.0; 8];
        Response::Triangle.add_to(2.0, 3.25, &mut col);
        assert_eq!(col, [0.0, 0.0, 0.0, 1.5, 0.5, 0.0, 0.0, 0.0]);
        let mut col = vec![0.0; 8];
        Response::Delta.add_to(2.0, 5.0, &mut col);
        assert_eq!(col[5], 2.0);
        assert_eq!(Response::Delta.voxels(5.5, 8), 0..0);
        let g = Response::gaussian(0.8).unwrap();
        assert_eq!(g.voxels(3.5, 8), 0..8);
        assert_eq!(Response::Triangle.voxels(3.0, 8), 2..5);
        assert_eq!(Response::Triangle.voxels(3.25, 8), 3..5);
        let mut col = vec![0.0; 8];
        g.add_to(1.0, 3.5, &mut col);
        assert!(
            (col[3] - col[4]).abs() < 1e-15 && (col[3] - (-0.5f64 * 0.390625).exp()).abs() < 1e-12
        );
    }

    #[test]
    fn specifications_round_trip_and_bad_ones_name_the_kernel() {
        for spec in ["delta", "triangle", "gaussian:0.8"] {
            assert_eq!(Response::parse(spec).unwrap().spec(), spec);
        }
        for bad in [
            "gauss",
            "gaussian",
            "gaussian:-1",
            "gaussian:nan",
            "triangle:2",
            "measured:8",
        ] {
            let e = Response::parse(bad).unwrap_err().to_string();
            assert!(e.contains("kernel"), "{bad}: {e}");
        }
        assert!(Measured::new(&[0.0, 0.0], 4, "z").is_err());
        assert!(Measured::new(&[1.0, -0.1], 4, "z").is_err());
        assert!(Measured::new(&[1.0, 0.5], 0, "z").is_err());
    }
}
