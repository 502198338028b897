//! Vector kernels shared by operators and solvers.
//!
//! Every reduction accumulates in `f64`, whatever the element type, with several independent
//! accumulators so that the loop vectorizes.

use crate::real::Real;

/// Σ f(aᵢ, bᵢ) accumulated in `f64` with four independent accumulators, so that the loop
/// vectorizes.
///
/// # Panics
/// If the slices have different lengths.
#[inline]
fn sum_pairs<T: Real>(what: &str, a: &[T], b: &[T], f: impl Fn(f64, f64) -> f64) -> f64 {
    assert_eq!(
        a.len(),
        b.len(),
        "{what}: lengths {} and {} differ",
        a.len(),
        b.len()
    );
    let mut acc = [0.0f64; 4];
    let mut ca = a.chunks_exact(4);
    let mut cb = b.chunks_exact(4);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for l in 0..4 {
            acc[l] += f(x[l].as_f64(), y[l].as_f64());
        }
    }
    let mut tail = 0.0;
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        tail += f(x.as_f64(), y.as_f64());
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// ⟨a, b⟩ accumulated in `f64`.
///
/// # Panics
/// If the slices have different lengths.
#[inline]
pub fn dot<T: Real>(a: &[T], b: &[T]) -> f64 {
    sum_pairs("dot", a, b, |x, y| x * y)
}

/// ‖a‖² accumulated in `f64`.
#[inline]
pub fn norm2_sq<T: Real>(a: &[T]) -> f64 {
    dot(a, a)
}

/// ‖a‖₂ accumulated in `f64`.
#[inline]
pub fn norm2<T: Real>(a: &[T]) -> f64 {
    norm2_sq(a).sqrt()
}

/// max |aᵢ| (0 for an empty slice); NaN if any entry is NaN.
pub fn norm_inf<T: Real>(a: &[T]) -> f64 {
    let mut m = 0.0f64;
    for &v in a {
        let v = v.as_f64().abs();
        if v.is_nan() {
            return f64::NAN;
        }
        m = m.max(v);
    }
    m
}

/// y ← y + α·x.
///
/// # Panics
/// If the slices have different lengths.
#[inline]
pub fn axpy<T: Real>(alpha: T, x: &[T], y: &mut [T]) {
    assert_eq!(
        x.len(),
        y.len(),
        "axpy: lengths {} and {} differ",
        x.len(),
        y.len()
    );
    for (yi, &xi) in y.iter_mut().zip(x) {
        *yi = *yi + alpha * xi;
    }
}

/// x ← α·x.
#[inline]
pub fn scale<T: Real>(alpha: T, x: &mut [T]) {
    for v in x {
        *v = *v * alpha;
    }
}

/// `true` when every entry is finite.
pub fn all_finite<T: Real>(a: &[T]) -> bool {
    a.iter().all(|v| v.is_finite())
}

/// ‖a − b‖² accumulated in `f64`.
///
/// # Panics
/// If the slices have different lengths.
#[inline]
pub fn dist2_sq<T: Real>(a: &[T], b: &[T]) -> f64 {
    sum_pairs("dist2_sq", a, b, |x, y| (x - y) * (x - y))
}

/// The median of `v` (the mean of the two middle values for an even length; NaN for an empty
/// slice), reordering `v` in linear time. Values compare by [`f64::total_cmp`].
pub fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    let (lower, upper, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    let upper = *upper;
    if n % 2 == 1 {
        upper
    } else {
        // The largest value below the upper middle one is the lower middle one.
        let below = lower.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (below + upper)
    }
}

/// The median of an ascending slice (the mean of the two middle values for an even length;
/// NaN for an empty slice).
pub fn median_sorted(v: &[f64]) -> f64 {
    let n = v.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => v[n / 2],
        _ => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// A robust standard deviation about `center`: 1.4826 · median |vᵢ − center| (the median
/// absolute deviation scaled to σ for Gaussian data; 0 for an empty slice). Overwrites `v` with
/// the absolute deviations.
pub fn robust_sigma(v: &mut [f64], center: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.iter_mut().for_each(|x| *x = (*x - center).abs());
    1.4826 * median(v)
}

/// Which entry of a column [`column_peaks`] takes as its peak.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeakRule {
    /// The largest value, whatever its sign (every column has a peak).
    Largest,
    /// The largest positive value (a column without one has no peak).
    LargestPositive,
    /// The value of largest magnitude (an all-zero column has no peak).
    LargestMagnitude,
}

/// The peak of each column of `x` (consecutive runs of `column_len` values) under `rule`: its
/// index within the column and its value, the first one on ties; `None` where the rule finds
/// none. NaN values are never peaks.
///
/// # Panics
/// If `column_len` is zero or does not divide `x.len()`.
pub fn column_peaks<T: Real>(
    x: &[T],
    column_len: usize,
    rule: PeakRule,
) -> Vec<Option<(usize, f64)>> {
    assert!(
        column_len > 0 && x.len().is_multiple_of(column_len),
        "column_peaks: column length {column_len} does not divide {} values",
        x.len()
    );
    let key = |v: f64| match rule {
        PeakRule::Largest => v,
        PeakRule::LargestPositive => v,
        PeakRule::LargestMagnitude => v.abs(),
    };
    let floor = match rule {
        PeakRule::Largest => f64::NEG_INFINITY,
        PeakRule::LargestPositive | PeakRule::LargestMagnitude => 0.0,
    };
    x.chunks_exact(column_len)
        .map(|col| {
            let mut best: Option<(usize, f64)> = None;
            let mut best_key = floor;
            for (j, v) in col.iter().enumerate() {
                let v = v.as_f64();
                let k = key(v);
                if k > best_key || (best.is_none() && rule == PeakRule::Largest && k == best_key) {
                    best_key = k;
                    best = Some((j, v));
                }
            }
            best
        })
        .collect()
}
