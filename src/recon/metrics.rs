//! Reconstruction quality: depth accuracy, detections and the relative error of the cube.
//!
//! A pixel is *lit* when its depth is not [`NO_RETURN`]. For scenes, each pixel's depth is its
//! strongest return ([`Scene::depth_map`]): a zero column is no return, and thresholding of an
//! estimate is left to the solver that produced it. All sums accumulate in `f64`.
//!
//! Fractions whose denominator is zero are given the value that a perfect reconstruction would
//! have, so that every field is a finite number: the exact fraction of a scene with no lit pixel
//! is 1, the other fractions are 0, and the RMSE over no detected pixel is 0 (the count used,
//! [`Metrics::detected`], tells these cases apart).

use ndarray::Array2;

use crate::error::{Error, Result};
use crate::real::Real;

use crate::lidar::{depth_bin_m, DepthMap, Scene, NO_RETURN};

/// How well an estimate matches the truth.
///
/// A pixel is *lit* when its depth is not [`NO_RETURN`]; for scenes, a pixel's depth is its
/// strongest return ([`Scene::depth_map`]), a zero column being no return.
///
/// Fractions whose denominator is zero take the value a perfect reconstruction would have, so that
/// every field is finite: `exact_fraction` is 1 when no pixel is lit, the other fractions are 0,
/// and the RMSE over no detected pixel is 0 ([`Metrics::detected`] tells these cases apart).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Metrics {
    /// Number of pixels, M·N.
    pub pixels: usize,
    /// Pixels lit in the truth.
    pub lit: usize,
    /// Pixels empty in the truth (`pixels − lit`).
    pub empty: usize,
    /// Lit pixels whose estimated depth equals the true depth.
    pub exact: usize,
    /// `exact / lit` (1 when no pixel is lit).
    pub exact_fraction: f64,
    /// Lit pixels whose estimated depth is within one bin of the true depth (the exact ones
    /// included).
    pub within_one: usize,
    /// `within_one / lit` (1 when no pixel is lit).
    pub within_one_fraction: f64,
    /// Lit pixels that are also lit in the estimate: the pixels the RMSE is computed over.
    pub detected: usize,
    /// Root-mean-square depth error over the detected pixels, in bins (0 when none is detected).
    pub depth_rmse_bins: f64,
    /// The same in metres: `depth_rmse_bins · bin_m`.
    pub depth_rmse_m: f64,
    /// Length of one depth bin in metres, τ·c/2.
    pub bin_m: f64,
    /// Missed detections: lit in the truth, no return in the estimate.
    pub missed: usize,
    /// `missed / lit` (0 when no pixel is lit).
    pub missed_fraction: f64,
    /// False detections: no return in the truth, lit in the estimate.
    pub false_detections: usize,
    /// `false_detections / pixels`.
    pub false_fraction_all: f64,
    /// `false_detections / empty` (0 when no pixel is empty).
    pub false_fraction_empty: f64,
    /// ‖X − X̂‖ / ‖X‖ over the whole cubes; ‖X̂‖ when the truth is all zero (so a perfect
    /// estimate always scores 0). From depth maps, the cubes are the single-return scenes they
    /// describe.
    pub relative_error: f64,
    /// Returns (nonzero voxels) of the truth: several per pixel in semi-transparent scenes.
    pub true_returns: usize,
    /// Returns of the estimate at the voxel of a true return.
    pub returns_exact: usize,
    /// True returns with no return of the estimate at their voxel.
    pub returns_missed: usize,
    /// Returns of the estimate at a voxel that is empty in the truth.
    pub returns_false: usize,
    /// ‖x_E − x̂_E‖ / ‖x_E‖ over the returns E found at the exact voxel (0 when there are none):
    /// the amplitude error where the support is right.
    pub amplitude_error: f64,
}

impl Metrics {
    /// Whether the truth or the estimate has a pixel with more than one return.
    pub fn multi_return(&self) -> bool {
        self.true_returns != self.lit
            || self.returns_exact + self.returns_false != self.detected + self.false_detections
    }
}

impl std::fmt::Display for Metrics {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.lit == 0 {
            // No lit pixel: there is no depth to match and no relative error; the error is
            // the estimate's norm.
            return write!(
                f,
                "the true scene has no lit pixel: false {} ({:.2}% of all), ‖X̂‖ = {:.4}",
                self.false_detections,
                100.0 * self.false_fraction_all,
                self.relative_error
            );
        }
        write!(
            f,
            "exact depth {:.1}% ({:.1}% within one bin) of {} lit pixels, depth RMSE {:.3} bins \
             ({:.4} m) over {}, missed {} ({:.1}%), false {} ({:.2}% of all, {:.2}% of empty), \
             relative error {:.4}",
            100.0 * self.exact_fraction,
            100.0 * self.within_one_fraction,
            self.lit,
            self.depth_rmse_bins,
            self.depth_rmse_m,
            self.detected,
            self.missed,
            100.0 * self.missed_fraction,
            self.false_detections,
            100.0 * self.false_fraction_all,
            100.0 * self.false_fraction_empty,
            self.relative_error
        )?;
        if self.multi_return() {
            write!(
                f,
                "; returns: {} of {} at the exact voxel ({:.1}%), {} missed, {} false, \
                 amplitude error {:.4}",
                self.returns_exact,
                self.true_returns,
                100.0 * ratio(self.returns_exact, self.true_returns, 1.0),
                self.returns_missed,
                self.returns_false,
                self.amplitude_error
            )?;
        }
        Ok(())
    }
}

fn ratio(num: usize, den: usize, if_empty: f64) -> f64 {
    if den == 0 {
        if_empty
    } else {
        num as f64 / den as f64
    }
}

fn check_same_dim(context: &str, what: [&str; 3], a: [usize; 3], b: [usize; 3]) -> Result<()> {
    for ((name, x), y) in what.iter().zip(a).zip(b) {
        if x != y {
            return Err(Error::shape(format!("{context}: {name}"), x, y));
        }
    }
    Ok(())
}

/// Depth, detection and count fields from two depth-bin maps of equal shape; the relative error is
/// left at 0.
fn depth_metrics(truth: &Array2<i32>, estimate: &Array2<i32>, tau_s: f64) -> Result<Metrics> {
    let bin_m = depth_bin_m(tau_s)?;
    let pixels = truth.len();
    let (mut lit, mut exact, mut detected, mut missed, mut false_detections) = (0, 0, 0, 0, 0);
    let mut within_one = 0;
    let mut sq = 0.0f64;
    for (&d, &e) in truth.iter().zip(estimate.iter()) {
        match (d != NO_RETURN, e != NO_RETURN) {
            (true, true) => {
                lit += 1;
                detected += 1;
                exact += usize::from(d == e);
                within_one += usize::from(d.abs_diff(e) <= 1);
                let diff = f64::from(d) - f64::from(e);
                sq += diff * diff;
            }
            (true, false) => {
                lit += 1;
                missed += 1;
            }
            (false, true) => false_detections += 1,
            (false, false) => {}
        }
    }
    let empty = pixels - lit;
    let depth_rmse_bins = if detected == 0 {
        0.0
    } else {
        (sq / detected as f64).sqrt()
    };
    Ok(Metrics {
        pixels,
        lit,
        empty,
        exact,
        exact_fraction: ratio(exact, lit, 1.0),
        within_one,
        within_one_fraction: ratio(within_one, lit, 1.0),
        detected,
        depth_rmse_bins,
        depth_rmse_m: depth_rmse_bins * bin_m,
        bin_m,
        missed,
        missed_fraction: ratio(missed, lit, 0.0),
        false_detections,
        false_fraction_all: ratio(false_detections, pixels, 0.0),
        false_fraction_empty: ratio(false_detections, empty, 0.0),
        relative_error: 0.0,
        true_returns: 0,
        returns_exact: 0,
        returns_missed: 0,
        returns_false: 0,
        amplitude_error: 0.0,
    })
}

/// The return counts and the amplitude error from (truth, estimate) value pairs, one per voxel.
fn return_metrics(m: &mut Metrics, pairs: impl Iterator<Item = (f64, f64)>) -> Result<()> {
    let (mut truth_sq, mut diff_sq, mut scale) = (0.0f64, 0.0f64, 0.0f64);
    let mut found: Vec<(f64, f64)> = Vec::new();
    for (x, e) in pairs {
        match (x != 0.0, e != 0.0) {
            (true, true) => {
                m.true_returns += 1;
                m.returns_exact += 1;
                scale = scale.max(x.abs()).max(e.abs());
                found.push((x, e));
            }
            (true, false) => {
                m.true_returns += 1;
                m.returns_missed += 1;
            }
            (false, true) => m.returns_false += 1,
            (false, false) => {}
        }
    }
    if scale > 0.0 {
        for (x, e) in found {
            let (x, e) = (x / scale, e / scale);
            diff_sq += (x - e) * (x - e);
            truth_sq += x * x;
        }
    }
    m.amplitude_error = if truth_sq > 0.0 {
        relative(diff_sq, truth_sq, "the returns found")?
    } else {
        0.0
    };
    Ok(())
}

/// `‖diff‖ / ‖truth‖`, or `‖diff‖` for a zero truth, from squared norms.
fn relative(diff_sq: f64, truth_sq: f64, what: &str) -> Result<f64> {
    let r = if truth_sq > 0.0 {
        (diff_sq / truth_sq).sqrt()
    } else {
        diff_sq.sqrt()
    };
    if r.is_finite() {
        Ok(r)
    } else {
        Err(Error::NonFinite {
            what: format!("relative error of {what}"),
        })
    }
}

/// ‖X − X̂‖ / ‖X‖ over the whole cubes, accumulated in `f64`; ‖X̂‖ when the truth is all zero.
///
/// # Errors
/// [`Error::ShapeMismatch`] if the geometries differ (the first differing dimension is named);
/// [`Error::NonFinite`] if a value or the result is NaN or infinite.
pub fn relative_error<T: Real>(truth: &Scene<T>, estimate: &Scene<T>) -> Result<f64> {
    check_scenes(truth, estimate)?;
    // Sums of squares of values scaled by the largest magnitude, so that scenes near the ends
    // of the floating-point range neither overflow nor underflow.
    let pairs = || truth.as_slice().iter().zip(estimate.as_slice());
    let scale = pairs().fold(0.0f64, |m, (&x, &e)| {
        m.max(x.as_f64().abs()).max(e.as_f64().abs())
    });
    if !scale.is_finite() {
        return Err(Error::NonFinite {
            what: "scenes compared".to_string(),
        });
    }
    if scale == 0.0 {
        return Ok(0.0);
    }
    let (mut diff_sq, mut truth_sq) = (0.0f64, 0.0f64);
    for (&x, &e) in pairs() {
        let (x, e) = (x.as_f64() / scale, e.as_f64() / scale);
        diff_sq += (x - e) * (x - e);
        truth_sq += x * x;
    }
    if truth_sq == 0.0 {
        // The truth is all zero: the error is ‖X̂‖ itself.
        let norm = diff_sq.sqrt() * scale;
        return if norm.is_finite() {
            Ok(norm)
        } else {
            Err(Error::NonFinite {
                what: "the norm of the estimate".to_string(),
            })
        };
    }
    relative(diff_sq, truth_sq, "scenes")
}

fn check_scenes<T: Real>(truth: &Scene<T>, estimate: &Scene<T>) -> Result<()> {
    let (a, b) = (truth.geometry(), estimate.geometry());
    check_same_dim(
        "compare scenes: estimate vs truth",
        ["rows (M)", "columns (N)", "depth bins (K_s)"],
        [a.m, a.n, a.ks],
        [b.m, b.n, b.ks],
    )
}

/// Compares an estimated scene with the true one.
///
/// Depths are the strongest return of each pixel of either scene ([`Scene::depth_map`]; for a
/// truth with several returns per pixel, the strongest one); the relative error is over the full
/// cubes. `tau_s` is the sampling period in seconds, for the metre figures.
///
/// # Errors
/// [`Error::ShapeMismatch`] if the geometries differ (the first differing dimension is named);
/// [`Error::InvalidParameter`] (`tau_s`) unless τ is finite and > 0; [`Error::NonFinite`] for a NaN
/// or infinite value.
pub fn compare<T: Real>(truth: &Scene<T>, estimate: &Scene<T>, tau_s: f64) -> Result<Metrics> {
    check_scenes(truth, estimate)?;
    depth_bin_m(tau_s)?;
    let relative_error = relative_error(truth, estimate)?;
    let mut m = depth_metrics(&truth.depth_map().depth, &estimate.depth_map().depth, tau_s)?;
    m.relative_error = relative_error;
    return_metrics(
        &mut m,
        truth
            .as_slice()
            .iter()
            .zip(estimate.as_slice())
            .map(|(x, e)| (x.as_f64(), e.as_f64())),
    )?;
    Ok(m)
}

fn check_depth_map<T: Real>(d: &DepthMap<T>, which: &str) -> Result<()> {
    let (a, b) = (d.depth.dim(), d.amplitude.dim());
    check_same_dim(
        &format!("{which} depth map: amplitude vs depth"),
        ["rows", "columns", "maps"],
        [a.0, a.1, 1],
        [b.0, b.1, 1],
    )?;
    if let Some(((i, j), v)) = d.depth.indexed_iter().find(|(_, &v)| v < NO_RETURN) {
        return Err(Error::param(
            "depth",
            format!("{which} depth bin {v} at pixel ({i}, {j}) is below {NO_RETURN}"),
        ));
    }
    if let Some(((i, j), v)) = d.amplitude.indexed_iter().find(|(_, v)| !v.is_finite()) {
        return Err(Error::NonFinite {
            what: format!("{which} amplitude {v} at pixel ({i}, {j})"),
        });
    }
    Ok(())
}

/// Compares an estimated depth map with the true one.
///
/// A pixel is lit when its depth is not [`NO_RETURN`]. The relative error is that of the
/// single-return scenes the maps describe (one voxel of value `amplitude` at the pixel's depth,
/// none at [`NO_RETURN`]): per pixel, (a − â)² at equal depths, a² + â² otherwise. `tau_s` is the
/// sampling period in seconds, for the metre figures.
///
/// # Errors
/// [`Error::ShapeMismatch`] if the maps differ in shape, or a map's amplitude differs from its
/// depth; [`Error::InvalidParameter`] (`depth`) for a depth below −1, (`tau_s`) unless τ is finite
/// and > 0; [`Error::NonFinite`] for a NaN or infinite amplitude.
pub fn compare_depth<T: Real>(
    truth: &DepthMap<T>,
    estimate: &DepthMap<T>,
    tau_s: f64,
) -> Result<Metrics> {
    check_depth_map(truth, "true")?;
    check_depth_map(estimate, "estimated")?;
    let (a, b) = (truth.depth.dim(), estimate.depth.dim());
    check_same_dim(
        "compare depth maps: estimate vs truth",
        ["rows (M)", "columns (N)", "maps"],
        [a.0, a.1, 1],
        [b.0, b.1, 1],
    )?;
    let mut m = depth_metrics(&truth.depth, &estimate.depth, tau_s)?;
    let (mut diff_sq, mut truth_sq) = (0.0f64, 0.0f64);
    // Each lit pixel is one return, at its depth: (truth, estimate) per voxel that either has.
    let mut pairs = Vec::new();
    for (((&d, &e), &x), &xe) in truth
        .depth
        .iter()
        .zip(estimate.depth.iter())
        .zip(truth.amplitude.iter())
        .zip(estimate.amplitude.iter())
    {
        let x = if d == NO_RETURN { 0.0 } else { x.as_f64() };
        let xe = if e == NO_RETURN { 0.0 } else { xe.as_f64() };
        truth_sq += x * x;
        if d == e {
            diff_sq += (x - xe) * (x - xe);
            pairs.push((x, xe));
        } else {
            diff_sq += x * x + xe * xe;
            pairs.push((x, 0.0));
            pairs.push((0.0, xe));
        }
    }
    m.relative_error = relative(diff_sq, truth_sq, "depth maps")?;
    return_metrics(&mut m, pairs.into_iter())?;
    Ok(m)
}
/// How an estimate compares with the truth when some pixels reach no ADC (a coded aperture's
/// blocked pixels, −2 in the depth map): the metrics on the observed pixels, and what became
/// of the unobserved ones.
#[derive(Debug, Clone, PartialEq)]
pub struct ObservedComparison {
    /// [`compare`] on the observed pixels (the others emptied in both scenes).
    pub observed: Metrics,
    /// Pixels that reach an ADC.
    pub observed_pixels: usize,
    /// Pixels that reach none.
    pub unobserved: usize,
    /// Unobserved pixels with a return in the truth.
    pub unobserved_lit: usize,
    /// Unobserved pixels lit in the truth whose filled depth is the true one.
    pub filled_exact: usize,
    /// Unobserved pixels lit in the truth whose filled depth is within one bin.
    pub filled_near: usize,
    /// Unobserved pixels empty in the truth that were filled with a return.
    pub filled_false: usize,
}

/// Compares `estimate` with `truth` on the pixels `observed` says reach an ADC, and the depth
/// map `depth` (after any filling of the unobserved pixels from their neighbours) with the true
/// depths on the others.
///
/// # Errors
/// The errors of [`compare`]; [`Error::ShapeMismatch`] if `observed` or `depth` do not have
/// the truth's pixels.
pub fn compare_observed<T: Real>(
    truth: &Scene<T>,
    estimate: &Scene<T>,
    depth: &ndarray::Array2<i32>,
    observed: &[bool],
    tau_s: f64,
) -> Result<ObservedComparison> {
    let g = truth.geometry();
    if depth.len() != g.pixels() {
        return Err(Error::shape(
            "compare_observed: depth map pixels vs M·N",
            g.pixels(),
            depth.len(),
        ));
    }
    let seen = truth.masked_pixels(observed)?;
    let metrics = compare(&seen, estimate, tau_s)?;
    let true_depth = truth.depth_map().depth;
    let hidden: Vec<(i32, i32)> = true_depth
        .iter()
        .zip(depth.iter())
        .zip(observed)
        .filter(|(_, &o)| !o)
        .map(|((&d, &e), _)| (d, e))
        .collect();
    let lit = |d: i32| d >= 0;
    Ok(ObservedComparison {
        observed: metrics,
        observed_pixels: observed.iter().filter(|&&o| o).count(),
        unobserved: hidden.len(),
        unobserved_lit: hidden.iter().filter(|(d, _)| lit(*d)).count(),
        filled_exact: hidden.iter().filter(|(d, e)| lit(*d) && d == e).count(),
        filled_near: hidden
            .iter()
            .filter(|(d, e)| lit(*d) && lit(*e) && (d - e).abs() <= 1)
            .count(),
        filled_false: hidden.iter().filter(|(d, e)| !lit(*d) && lit(*e)).count(),
    })
}
