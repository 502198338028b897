//! Vector kernels shared by operators and solvers.
//!
//! Every reduction accumulates in `f64`, whatever the element type, with several independent
//! accumulators so that the loop vectorizes.

use crate::real::Real;

/// ⟨a, b⟩ accumulated in `f64`.
///
/// # Panics
/// If the slices have different lengths.
#[inline]
pub fn dot<T: Real>(a: &[T], b: &[T]) -> f64 {
    assert_eq!(
        a.len(),
        b.len(),
        "dot: lengths {} and {} differ",
        a.len(),
        b.len()
    );
    let mut acc = [0.0f64; 4];
    let mut ca = a.chunks_exact(4);
    let mut cb = b.chunks_exact(4);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for l in 0..4 {
            acc[l] += x[l].as_f64() * y[l].as_f64();
        }
    }
    let mut tail = 0.0;
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        tail += x.as_f64() * y.as_f64();
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
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
