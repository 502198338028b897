//! How well continuous depths match the truth: each true return paired with an estimated one in
//! its pixel, the depth error over the pairs in bins and metres, beside the Cramér–Rao bound.

use ndarray::Array3;

use crate::error::{Error, Result};
use crate::lidar::Returns;

/// Continuous depths against the true ones ([`compare_range`]). Sums in f64; fractions whose
/// denominator is zero are 0, and the RMSE over no pair is 0 (`paired` tells the cases apart).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RangeMetrics {
    /// Pixels, M·N.
    pub pixels: usize,
    /// Pixels with a true return.
    pub lit: usize,
    /// Pixels with none (`pixels − lit`).
    pub empty: usize,
    /// True returns (several per pixel in semi-transparent scenes).
    pub true_returns: usize,
    /// True returns paired with an estimated return of their pixel: the RMSE is over these.
    pub paired: usize,
    /// True returns left without an estimated one.
    pub missed: usize,
    /// Estimated returns left without a true one.
    pub false_returns: usize,
    /// Lit pixels with no estimated return.
    pub missed_pixels: usize,
    /// Empty pixels with an estimated return.
    pub false_pixels: usize,
    /// `false_pixels / empty` (0 when no pixel is empty).
    pub false_fraction_empty: f64,
    /// Root-mean-square depth error over the pairs, in bins.
    pub rmse_bins: f64,
    /// The largest depth error of a pair, in bins.
    pub max_error_bins: f64,
    /// The length of one bin, c·τ/2, in metres.
    pub bin_m: f64,
    /// `rmse_bins · bin_m`.
    pub rmse_m: f64,
    /// The root-mean-square Cramér–Rao bound over the pairs, in bins, when a bound was given
    /// (`None` too when a paired return's bound is infinite).
    pub bound_bins: Option<f64>,
    /// `rmse_bins / bound_bins` where the bound is positive.
    pub rmse_over_bound: Option<f64>,
}

/// Pairs each pixel's true returns (`truth`, (R, M, N)) with its estimated ones (`estimate`,
/// (R′, M, N)), nearest first (the closest remaining true and estimated depths are paired, then
/// the next), and measures the depth errors; `bound` (as `truth`, from
/// [`depth_bound`](super::depth_bound)) adds the bound over the same pairs; `bin_m` is one
/// bin's length in metres.
///
/// # Errors
/// [`Error::ShapeMismatch`] if the pixel grids differ or `bound`'s shape is not `truth`'s;
/// [`Error::InvalidParameter`] (`bin_m`) unless it is finite and > 0.
pub fn compare_range(
    truth: &Returns,
    estimate: &Returns,
    bound: Option<&Array3<f64>>,
    bin_m: f64,
) -> Result<RangeMetrics> {
    let (layers, m, n) = truth.depth.dim();
    let (_, em, en) = estimate.depth.dim();
    if (em, en) != (m, n) {
        return Err(Error::shape(
            "estimated vs true depths: pixels",
            m * n,
            em * en,
        ));
    }
    if let Some(b) = bound {
        if b.dim() != truth.depth.dim() {
            return Err(Error::shape(
                "bound vs true depths",
                truth.depth.len(),
                b.len(),
            ));
        }
    }
    if !(bin_m.is_finite() && bin_m > 0.0) {
        return Err(Error::param(
            "bin_m",
            format!("must be finite and > 0, got {bin_m}"),
        ));
    }
    let mut c = Counts::default();
    for i in 0..m {
        for j in 0..n {
            let t: Vec<(usize, f64)> = (0..layers)
                .map(|r| (r, truth.depth[[r, i, j]]))
                .filter(|(_, d)| !d.is_nan())
                .collect();
            let e: Vec<f64> = estimate
                .depth
                .outer_iter()
                .map(|l| l[[i, j]])
                .filter(|d| !d.is_nan())
                .collect();
            c.pixel(&t, &e, |r| bound.map(|b| b[[r, i, j]]));
        }
    }
    Ok(c.metrics(m * n, bin_m, bound.is_some()))
}

#[derive(Default)]
struct Counts {
    lit: usize,
    true_returns: usize,
    paired: usize,
    missed: usize,
    false_returns: usize,
    missed_pixels: usize,
    false_pixels: usize,
    squares: f64,
    max: f64,
    bound_squares: f64,
}

impl Counts {
    /// One pixel's true returns (layer, depth) and estimated depths.
    fn pixel(&mut self, t: &[(usize, f64)], e: &[f64], bound: impl Fn(usize) -> Option<f64>) {
        self.true_returns += t.len();
        match (t.is_empty(), e.is_empty()) {
            (false, _) => self.lit += 1,
            (true, false) => self.false_pixels += 1,
            (true, true) => {}
        }
        if !t.is_empty() && e.is_empty() {
            self.missed_pixels += 1;
        }
        let (mut t_left, mut e_left) = (vec![true; t.len()], vec![true; e.len()]);
        loop {
            let mut best: Option<(usize, usize, f64)> = None;
            for (a, &(_, td)) in t.iter().enumerate().filter(|(a, _)| t_left[*a]) {
                for (b, &ed) in e.iter().enumerate().filter(|(b, _)| e_left[*b]) {
                    let err = (ed - td).abs();
                    if best.is_none_or(|(_, _, e)| err < e) {
                        best = Some((a, b, err));
                    }
                }
            }
            let Some((a, b, err)) = best else { break };
            t_left[a] = false;
            e_left[b] = false;
            self.paired += 1;
            self.squares += err * err;
            self.max = self.max.max(err);
            if let Some(v) = bound(t[a].0) {
                self.bound_squares += v * v;
            }
        }
        self.missed += t_left.iter().filter(|&&l| l).count();
        self.false_returns += e_left.iter().filter(|&&l| l).count();
    }

    fn metrics(&self, pixels: usize, bin_m: f64, bounded: bool) -> RangeMetrics {
        let empty = pixels - self.lit;
        let rmse = if self.paired > 0 {
            (self.squares / self.paired as f64).sqrt()
        } else {
            0.0
        };
        let bound = (bounded && self.paired > 0 && self.bound_squares.is_finite())
            .then(|| (self.bound_squares / self.paired as f64).sqrt());
        RangeMetrics {
            pixels,
            lit: self.lit,
            empty,
            true_returns: self.true_returns,
            paired: self.paired,
            missed: self.missed,
            false_returns: self.false_returns,
            missed_pixels: self.missed_pixels,
            false_pixels: self.false_pixels,
            false_fraction_empty: if empty > 0 {
                self.false_pixels as f64 / empty as f64
            } else {
                0.0
            },
            rmse_bins: rmse,
            max_error_bins: self.max,
            bin_m,
            rmse_m: rmse * bin_m,
            bound_bins: bound,
            rmse_over_bound: bound.filter(|b| *b > 0.0).map(|b| rmse / b),
        }
    }
}

impl std::fmt::Display for RangeMetrics {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "depth RMSE {:.4} bins ({}) over {} of {} true returns, largest error {:.4} bins",
            self.rmse_bins,
            millimetres(self.rmse_m),
            self.paired,
            self.true_returns,
            self.max_error_bins
        )?;
        match (self.bound_bins, self.rmse_over_bound) {
            (Some(b), Some(ratio)) => write!(
                f,
                ", Cramér–Rao bound {b:.4} bins ({}): RMSE/bound {ratio:.2}",
                millimetres(b * self.bin_m)
            )?,
            (Some(_), None) => write!(f, ", Cramér–Rao bound 0 (no noise)")?,
            _ => {}
        }
        write!(
            f,
            "; missed {} returns ({} lit pixels), false {} returns ({} of {} empty pixels, {:.2}%)",
            self.missed,
            self.missed_pixels,
            self.false_returns,
            self.false_pixels,
            self.empty,
            100.0 * self.false_fraction_empty
        )
    }
}

/// A length in metres written in millimetres, three significant digits below 1 mm.
pub(crate) fn millimetres(m: f64) -> String {
    let mm = m * 1e3;
    if mm != 0.0 && mm.abs() < 1.0 {
        format!("{mm:.3} mm")
    } else {
        format!("{mm:.1} mm")
    }
}

#[cfg(test)]
mod tests {
    use ndarray::{arr3, Array3};

    use super::*;

    fn returns(depth: Array3<f64>) -> Returns {
        let amplitude = depth.mapv(|d| if d.is_nan() { 0.0 } else { 1.0 });
        Returns::new(depth, amplitude).unwrap()
    }

    #[test]
    fn returns_pair_nearest_first_and_the_rest_are_missed_or_false() {
        let nan = f64::NAN;
        // Pixel (0,0): two true returns, one estimate near the second; (0,1): one true, two
        // estimates; (1,0): empty with an estimate; (1,1): lit, none estimated.
        let truth = returns(arr3(&[[[2.0, 5.0], [nan, 3.0]], [[8.0, nan], [nan, nan]]]));
        let estimate = returns(arr3(&[[[7.9, 5.5], [1.0, nan]], [[nan, 4.5], [nan, nan]]]));
        let bound = arr3(&[[[0.1, 0.2], [nan, 0.3]], [[0.4, nan], [nan, nan]]]);
        let m = compare_range(&truth, &estimate, Some(&bound), 0.03).unwrap();
        assert_eq!((m.lit, m.empty, m.true_returns), (3, 1, 4));
        assert_eq!((m.paired, m.missed, m.false_returns), (2, 2, 2));
        assert_eq!((m.missed_pixels, m.false_pixels), (1, 1));
        // Pairs: 8.0 with 7.9 (not 2.0 with 7.9), 5.0 with 5.5 (not 4.5).
        let rmse = ((0.01f64 + 0.25) / 2.0).sqrt();
        assert!((m.rmse_bins - rmse).abs() < 1e-12);
        assert!((m.max_error_bins - 0.5).abs() < 1e-12);
        assert!((m.rmse_m - 0.03 * rmse).abs() < 1e-12);
        let b = ((0.16f64 + 0.04) / 2.0).sqrt();
        assert!((m.bound_bins.unwrap() - b).abs() < 1e-12);
        assert!((m.rmse_over_bound.unwrap() - rmse / b).abs() < 1e-12);
        assert!((m.false_fraction_empty - 1.0).abs() < 1e-12);
        assert!(m.to_string().contains("RMSE/bound"), "{m}");
    }

    #[test]
    fn shapes_and_bin_lengths_are_checked() {
        let a = returns(Array3::from_elem((1, 2, 2), 1.0));
        let b = returns(Array3::from_elem((1, 2, 3), 1.0));
        assert!(matches!(
            compare_range(&a, &b, None, 0.03),
            Err(Error::ShapeMismatch { .. })
        ));
        let bad = Array3::zeros((2, 2, 2));
        assert!(matches!(
            compare_range(&a, &a, Some(&bad), 0.03),
            Err(Error::ShapeMismatch { .. })
        ));
        assert!(matches!(
            compare_range(&a, &a, None, 0.0),
            Err(Error::InvalidParameter { name: "bin_m", .. })
        ));
        let m = compare_range(&a, &a, None, 0.03).unwrap();
        assert_eq!((m.rmse_bins, m.bound_bins, m.paired), (0.0, None, 4));
    }
}
