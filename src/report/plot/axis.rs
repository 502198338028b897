//! Axes of charts: the range shown, labelled ticks (powers of ten on logarithmic axes) and
//! their texts, and the linear scale plotters draws them on.

use std::ops::Range;

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::Ranged;

use crate::error::{Error, Result};

/// A linear scale from `lo` to `hi` for plotters, with the values it labels (`bold`) and those
/// that only get a grid line (`light`).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Scale {
    pub lo: f64,
    pub hi: f64,
    pub bold: Vec<f64>,
    pub light: Vec<f64>,
}

impl Ranged for Scale {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        RangedCoordf64::from(self.lo..self.hi).map(value, limit)
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

/// A labelled tick: its value, its place on the drawn scale (the value, or its log10 on a
/// logarithmic axis) and its text.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Tick {
    pub value: f64,
    pub at: f64,
    pub text: String,
}

/// One axis: the range shown, the labelled ticks and the unlabelled grid lines. Logarithmic
/// axes are drawn on the scale of log10 of the values.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Axis {
    pub lo: f64,
    pub hi: f64,
    pub log: bool,
    pub ticks: Vec<Tick>,
    pub minor: Vec<f64>,
}

/// Fraction of the data's span left free at each end of a fitted axis.
const MARGIN: f64 = 0.05;

impl Axis {
    /// Where `v` is on the drawn scale.
    pub fn at(&self, v: f64) -> f64 {
        if self.log {
            v.log10()
        } else {
            v
        }
    }

    /// The ends of the drawn scale.
    pub fn ends(&self) -> (f64, f64) {
        (self.at(self.lo), self.at(self.hi))
    }

    /// The drawn scale, for plotters.
    pub fn scale(&self) -> Scale {
        let (lo, hi) = self.ends();
        Scale {
            lo,
            hi,
            bold: self.ticks.iter().map(|t| t.at).collect(),
            light: self.minor.clone(),
        }
    }

    /// An axis over `values` (or exactly `range`), with about `target` labelled ticks.
    pub fn fit(
        values: &[f64],
        range: Option<(f64, f64)>,
        log: bool,
        target: usize,
    ) -> Result<Axis> {
        let fitted = range.is_none();
        let (lo, hi) = range.unwrap_or_else(|| {
            values
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                })
        });
        let too_wide = || {
            Error::param(
                "range",
                format!("the data span [{lo}, {hi}]: too wide for an axis"),
            )
        };
        if !log {
            let (mut lo, mut hi) = (lo, hi);
            if fitted {
                if lo == hi {
                    let d = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
                    (lo, hi) = (lo - d, hi + d);
                }
                let pad = MARGIN * (hi - lo);
                (lo, hi) = (lo - pad, hi + pad);
            }
            if !(lo.is_finite() && hi.is_finite() && (hi - lo).is_finite() && hi > lo) {
                return Err(too_wide());
            }
            let values = RangedCoordf64::from(lo..hi).key_points(target.max(2));
            let step = values
                .windows(2)
                .map(|w| w[1] - w[0])
                .fold(f64::INFINITY, f64::min);
            let ticks = values
                .iter()
                .map(|&v| Tick {
                    value: v,
                    at: v,
                    text: tick_text(v, step),
                })
                .collect();
            return Ok(Axis {
                lo,
                hi,
                log,
                ticks,
                minor: Vec::new(),
            });
        }

        let (mut l0, mut l1) = (lo.log10(), hi.log10());
        if fitted {
            if l0 == l1 {
                (l0, l1) = (l0 - 0.5, l1 + 0.5);
            }
            let pad = MARGIN * (l1 - l0);
            (l0, l1) = (l0 - pad, l1 + pad);
            // Fewer than two powers of ten inside: reach out to the nearer one beyond an end,
            // until two are.
            while l1.floor() - l0.ceil() < 1.0 {
                if l1.ceil() - l1 <= l0 - l0.floor() && l1.ceil() > l1 {
                    l1 = l1.ceil();
                } else if l0.floor() < l0 {
                    l0 = l0.floor();
                } else {
                    l1 = l1.floor() + 1.0;
                }
            }
        }
        let (lo, hi) = (10f64.powf(l0), 10f64.powf(l1));
        if !(lo >= f64::MIN_POSITIVE && hi.is_finite()) {
            return Err(too_wide());
        }
        if l1 <= l0 {
            return Err(Error::param("range", format!("[{lo}, {hi}] is empty")));
        }
        let (k0, k1) = ((l0 - 1e-9).ceil() as i32, (l1 + 1e-9).floor() as i32);
        let mut ticks = Vec::new();
        let mut minor = Vec::new();
        let tick = |value: f64, text: String| Tick {
            value,
            at: value.log10(),
            text,
        };
        if k1 > k0 {
            // Powers of ten, every `stride`-th labelled (the multiples of the stride if two of
            // them are inside, else counting from the first), the others and, over at most six
            // decades, 2..9 times each a grid line.
            let count = (k1 - k0 + 1) as usize;
            let stride = count.div_ceil(target.max(2)).max(1) as i32;
            let multiples = (k0..=k1).filter(|k| k.rem_euclid(stride) == 0).count();
            let origin = if multiples >= 2 { 0 } else { k0 };
            for k in k0..=k1 {
                if (k - origin).rem_euclid(stride) == 0 {
                    ticks.push(tick(10f64.powi(k), format!("10{}", superscript(k))));
                } else {
                    minor.push(k as f64);
                }
            }
            if l1 - l0 <= 6.5 {
                for k in (k0 - 1)..=k1 {
                    for m in 2..=9 {
                        let at = (m as f64 * 10f64.powi(k)).log10();
                        if at > l0 && at < l1 {
                            minor.push(at);
                        }
                    }
                }
            }
        } else {
            // Within about a decade (an explicit range): 1, 2 and 5 times powers of ten, or
            // evenly spaced values if fewer than two of those are inside.
            for k in (k0 - 1)..=k1 {
                for m in [1.0, 2.0, 5.0] {
                    let v = m * 10f64.powi(k);
                    if v >= lo * (1.0 - 1e-12) && v <= hi * (1.0 + 1e-12) {
                        ticks.push(tick(v, tick_text(v, 10f64.powi(k))));
                    }
                }
            }
            if ticks.len() < 2 {
                let values = RangedCoordf64::from(lo..hi).key_points(target.max(2));
                let step = values
                    .windows(2)
                    .map(|w| w[1] - w[0])
                    .fold(f64::INFINITY, f64::min);
                ticks = values
                    .iter()
                    .filter(|&&v| v > 0.0)
                    .map(|&v| tick(v, tick_text(v, step)))
                    .collect();
            }
        }
        Ok(Axis {
            lo,
            hi,
            log,
            ticks,
            minor,
        })
    }
}

/// `k` in superscript digits, e.g. "⁻¹²".
fn superscript(k: i32) -> String {
    const DIGITS: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    k.to_string()
        .chars()
        .map(|c| match c {
            '-' => '⁻',
            d => d.to_digit(10).map_or(d, |d| DIGITS[d as usize]),
        })
        .collect()
}

/// The text of tick value `v` among ticks `step` apart: as many decimals as the step needs, or
/// "m×10ⁿ" for very large or small values; negative values take a minus sign (−).
pub(super) fn tick_text(v: f64, step: f64) -> String {
    let step = if step.is_finite() && step > 0.0 {
        step
    } else {
        v.abs().max(f64::MIN_POSITIVE)
    };
    let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
    let e = if v == 0.0 { step } else { v.abs() }.log10().floor() as i32;
    // Decimals needed to tell ticks `step` apart, on a scale of `scale`.
    let decimals = |scale: f64| -> usize {
        (0..=12)
            .find(|&d| {
                let s = step / scale * 10f64.powi(d);
                (s - s.round()).abs() < 1e-6 * s.max(1.0)
            })
            .unwrap_or(12) as usize
    };
    let text = if (-3..6).contains(&e) {
        format!("{v:.*}", decimals(1.0))
    } else if v == 0.0 {
        "0".into()
    } else {
        let scale = 10f64.powi(e);
        format!("{:.*}×10{}", decimals(scale), v / scale, superscript(e))
    };
    text.replacen('-', "−", 1)
}
