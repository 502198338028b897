//! Censored samples: an ADC that clips.
//!
//! An ADC saturates at its full scale: a sample whose true value lies beyond it reads as the
//! largest (or smallest) code, and least squares would fit the true scene to a value it does
//! not predict. Such a sample holds only a bound, so the data term leaves it out: the
//! censored acquisition has every code of the pixels that ADC sums set to 0 at the censored
//! samples (a zero row of the operator) and the measurement 0 there, and every solver, fast
//! path and architecture runs on it unchanged. The samples kept determine the scene as long as
//! enough of them are left; on the paper's scene at 32×32×16, 3.3 measurements per lit pixel,
//! with a quarter of the samples clipped, every depth is then exact where fitting the clipped
//! values left 1.7% of the empty pixels with a false return.

use std::fmt;
use std::str::FromStr;

use super::*;

/// Which samples an ADC clipped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Clipping {
    /// Samples with |y| ≥ the level (finite, > 0): the ADC's largest output, its top code (for
    /// a mid-rise ADC of full scale F and step Δ, F − Δ/2: a level of F censors nothing).
    Level(f64),
    /// In each ADC's row, the samples at its largest y and at its smallest (within a few units
    /// of rounding): the top and bottom codes of an ADC that saturated, whether or not its
    /// range is symmetric.
    Top,
}

impl FromStr for Clipping {
    type Err = Error;

    /// `top` or a level (a finite number > 0).
    fn from_str(text: &str) -> Result<Self> {
        if text == "top" {
            return Ok(Clipping::Top);
        }
        match text.parse::<f64>() {
            Ok(level) => Clipping::Level(level).checked(),
            Err(_) => Err(Error::param(
                "clipped",
                format!("expected top or a level (a number > 0), got {text:?}"),
            )),
        }
    }
}

impl fmt::Display for Clipping {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Clipping::Level(level) => write!(f, "|y| ≥ {}", crate::units::number(*level)),
            Clipping::Top => write!(f, "each ADC's top and bottom codes"),
        }
    }
}

impl Clipping {
    /// The clipping, if its level is finite and > 0.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`clipped`) otherwise.
    pub fn checked(self) -> Result<Self> {
        match self {
            Clipping::Level(level) if !(level.is_finite() && level > 0.0) => Err(Error::param(
                "clipped",
                format!(
                    "the clipping level must be finite and > 0, got {}",
                    crate::units::number(level)
                ),
            )),
            c => Ok(c),
        }
    }

    /// Which of one ADC's samples `y` are censored, and the bounds that decided it: samples
    /// ≤ the first or ≥ the second (infinite where a side censors nothing).
    fn mask<T: Real>(self, y: &[T]) -> (Vec<bool>, (f64, f64)) {
        let bounds = match self {
            Clipping::Level(level) => (-level, level),
            Clipping::Top => {
                // Within four units of rounding in `T`: the codes read back from any file.
                let near = 1.0 - 4.0 * T::epsilon().as_f64();
                let (lo, hi) = y.iter().fold((0.0f64, 0.0f64), |(lo, hi), v| {
                    (lo.min(v.as_f64()), hi.max(v.as_f64()))
                });
                // A side that no sample reaches (no light, or one sign only) censors nothing.
                let side = |v: f64| {
                    if v == 0.0 {
                        f64::INFINITY
                    } else {
                        v.abs() * near
                    }
                };
                (-side(lo), side(hi))
            }
        };
        let mask = y
            .iter()
            .map(|v| v.as_f64() <= bounds.0 || v.as_f64() >= bounds.1)
            .collect();
        (mask, bounds)
    }
}

/// The samples of `y` (rows of `samples` values, one per ADC) at their row's largest or
/// smallest value (within four units of rounding), which [`Clipping::Top`] would censor: about
/// two in a row whose ADC did not clip, many where it saturated.
pub fn at_top<T: Real>(y: &[T], samples: usize) -> usize {
    y.chunks(samples.max(1))
        .map(|row| Clipping::Top.mask(row).0.iter().filter(|&&c| c).count())
        .sum()
}

/// What [`Acquisition::censor`] left out.
#[derive(Debug, Clone, PartialEq)]
pub struct Censoring {
    /// Per ADC row: the censored samples' count.
    pub censored: Vec<usize>,
    /// Per ADC row: the bounds (b, t) at and beyond which samples were censored (y ≤ b or
    /// y ≥ t; infinite where a side censored nothing).
    pub levels: Vec<(f64, f64)>,
    /// Samples per row (K).
    pub samples: usize,
}

impl Censoring {
    /// The censored samples of every row.
    pub fn total(&self) -> usize {
        self.censored.iter().sum()
    }

    /// One line: how many samples were censored, and where.
    pub fn describe(&self) -> String {
        let all = self.censored.len() * self.samples;
        if self.total() == 0 {
            return format!(
                "censored none of {all} samples: no sample reaches the level (give the ADC's \
                 top code, or top)"
            );
        }
        // The rows that censored something, as one bound per side or a range per ADC.
        let used: Vec<(f64, f64)> = self
            .levels
            .iter()
            .zip(&self.censored)
            .filter(|(_, &n)| n > 0)
            .map(|(&l, _)| l)
            .collect();
        let side = |pick: &dyn Fn(&(f64, f64)) -> f64| {
            let v: Vec<f64> = used.iter().map(pick).filter(|v| v.is_finite()).collect();
            let (lo, hi) = v
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            match v.len() {
                0 => None,
                _ if lo == hi => Some(format!("{lo:.6e}")),
                _ => Some(format!("{lo:.6e} … {hi:.6e}")),
            }
        };
        let bounds = match (side(&|l| l.0), side(&|l| l.1)) {
            (Some(b), Some(t)) => format!("y ≤ {b} or y ≥ {t}"),
            (Some(b), None) => format!("y ≤ {b}"),
            (None, Some(t)) => format!("y ≥ {t}"),
            (None, None) => "nothing".to_string(),
        };
        format!(
            "censored {} of {all} samples ({:.1}%) at {bounds}: the solvers fit the others",
            self.total(),
            100.0 * self.total() as f64 / all.max(1) as f64
        )
    }
}

impl Acquisition {
    /// This acquisition and its measurements `y` with the samples `clipping` names censored:
    /// the codes of the pixels each ADC sums are 0 at its censored samples and the
    /// measurements 0 there (see the module's documentation), with what was censored.
    /// Nothing censored leaves both as they were (the codes are shared, not copied).
    ///
    /// # Errors
    /// [`Acquisition::check_measurements`]; [`Error::InvalidParameter`] (`clipped`) for a level
    /// that is not finite and > 0, for an ADC whose every nonzero sample would be censored,
    /// and for codes regenerated from their seed on every application (streamed, or tiled
    /// seeded codes): censoring needs them held. An ADC that saw no light (every sample 0)
    /// has nothing censored.
    pub fn censor<T: Real>(
        &self,
        y: &[T],
        clipping: Clipping,
    ) -> Result<(Self, Vec<T>, Censoring)> {
        let clipping = clipping.checked()?;
        self.check_measurements(y, "meas")?;
        let k = self.samples();
        let rows = self.rows().unwrap_or(1);
        let mut masks = Vec::with_capacity(rows);
        let mut censoring = Censoring {
            censored: Vec::with_capacity(rows),
            levels: Vec::with_capacity(rows),
            samples: k,
        };
        for (r, row) in y.chunks_exact(k).enumerate() {
            let (mask, bounds) = clipping.mask(row);
            let count = mask.iter().filter(|&&c| c).count();
            let signal_left = row.iter().zip(&mask).any(|(v, &c)| !c && *v != T::zero());
            if count > 0 && !signal_left {
                return Err(Error::param(
                    "clipped",
                    format!(
                        "every nonzero sample of ADC row {r} is at or beyond its level \
                         ({clipping}): nothing would be left to fit"
                    ),
                ));
            }
            censoring.censored.push(count);
            censoring.levels.push(bounds);
            masks.push(mask);
        }
        if censoring.total() == 0 {
            return Ok((self.clone(), y.to_vec(), censoring));
        }
        let CodeStore::Held(sets) = &self.codes else {
            return Err(Error::param(
                "clipped",
                "censoring clipped samples needs the codes held in memory; these are \
                 regenerated from their seed on every application (streamed, or the seeded \
                 codes of a tiled array)",
            ));
        };
        let sets = match self.architecture {
            Architecture::Tiles(t) => {
                let row_of = self.tile_of_pixels(t)?;
                vec![Arc::new(sets[0].zero_samples(&masks, &|p| row_of[p])?)]
            }
            // A code set whose ADC censored nothing keeps its codes (binary stays binary).
            _ => sets
                .iter()
                .zip(&masks)
                .zip(&censoring.censored)
                .map(|((codes, mask), &n)| match n {
                    0 => Ok(Arc::clone(codes)),
                    _ => codes
                        .zero_samples(std::slice::from_ref(mask), &|_| 0)
                        .map(Arc::new),
                })
                .collect::<Result<Vec<_>>>()?,
        };
        let mut y = y.to_vec();
        for (row, mask) in y.chunks_exact_mut(k).zip(&masks) {
            for (v, &c) in row.iter_mut().zip(mask) {
                if c {
                    *v = T::zero();
                }
            }
        }
        let acq = Acquisition {
            codes: CodeStore::Held(sets),
            ..self.clone()
        };
        Ok((acq, y, censoring))
    }

    /// For each pixel held here (this process's band of rows, or all), the index of the tile
    /// of `tile` pixels it lies in (its ADC's row of the measurements).
    fn tile_of_pixels(&self, tile: TileSize) -> Result<Vec<usize>> {
        let whole = self.whole_geometry();
        let here = self.share.as_ref().map_or(0..whole.pixels(), Share::pixels);
        let mut row_of = vec![usize::MAX; here.len()];
        for place in tile_places(whole, tile)? {
            for p in place.pixels(whole) {
                if here.contains(&p) {
                    row_of[p - here.start] = place.index;
                }
            }
        }
        Ok(row_of)
    }
}
