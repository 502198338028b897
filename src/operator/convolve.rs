//! Batched 1-D convolution along the last axis, direct or by FFT.

use std::sync::Arc;

use num_complex::Complex;
use rustfft::{Fft, FftPlanner};

use crate::error::{Error, Result};
use crate::linalg::dot;
use crate::real::Real;

use super::LinearOperator;

/// Which part of the full linear convolution (length `n + L − 1`) is kept.
///
/// The conventions are those of `scipy.signal.convolve`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConvMode {
    /// All `n + L − 1` samples.
    Full,
    /// `n` samples centred on the full result: samples `(L−1)/2 .. (L−1)/2 + n` of it.
    Same,
    /// The `n − L + 1` samples computed without padding (requires `n ≥ L`).
    Valid,
}

/// How the convolution is evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConvMethod {
    /// Pick direct or FFT from an operation-count estimate (the default).
    Auto,
    /// Direct summation: O(n·L) per row.
    Direct,
    /// Zero-padded FFT through `rustfft`: O(F log F) per pair of rows, F ≥ n + L − 1.
    Fft,
}

struct FftPlan<T: Real> {
    len: usize,
    fwd: Arc<dyn Fft<T>>,
    inv: Arc<dyn Fft<T>>,
    /// FFT of the zero-padded kernel, with the 1/F normalization folded in.
    h_hat: Vec<Complex<T>>,
    fft_scratch: usize,
}

impl<T: Real> std::fmt::Debug for FftPlan<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FftPlan").field("len", &self.len).finish()
    }
}

/// Convolution of each of `batch` rows of length `n` (row-major `batch × n` input) with one kernel
/// h of length L: `z[k] = Σⱼ x[j]·h[k − j]`, cropped according to a [`ConvMode`].
///
/// The adjoint is the correlation with h of the zero-embedded output. Sums are accumulated in `f64`
/// on the direct path; the FFT path works in the precision of `T` (its error grows like
/// ε·log F, see the tests).
#[derive(Debug)]
pub struct Convolve1D<T: Real> {
    batch: usize,
    n: usize,
    h: Vec<T>,
    h_rev: Vec<T>,
    mode: ConvMode,
    out_len: usize,
    offset: usize,
    fft: Option<FftPlan<T>>,
}

/// Smallest 2ᵃ3ᵇ5ᶜ ≥ n: sizes rustfft handles with its fastest algorithms.
fn next_fast_len(n: usize) -> usize {
    let mut best = n.max(1).next_power_of_two();
    let mut p5 = 1usize;
    while p5 < best {
        let mut p35 = p5;
        while p35 < best {
            let mut p = p35;
            while p < n {
                p *= 2;
            }
            best = best.min(p);
            p35 *= 3;
        }
        p5 *= 5;
    }
    best
}

impl<T: Real> Convolve1D<T> {
    /// Convolves each of `batch` rows of length `n` with `kernel`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `batch`, `n` or the kernel length is zero, or if
    /// `mode` is [`ConvMode::Valid`] and `n` is shorter than the kernel; [`Error::NonFinite`] if a
    /// kernel value is NaN or infinite.
    pub fn new(
        batch: usize,
        n: usize,
        kernel: Vec<T>,
        mode: ConvMode,
        method: ConvMethod,
    ) -> Result<Self> {
        if batch == 0 {
            return Err(Error::param("batch", "convolution needs at least one row"));
        }
        if n == 0 {
            return Err(Error::param("n", "convolution rows must not be empty"));
        }
        let l = kernel.len();
        if l == 0 {
            return Err(Error::param(
                "kernel",
                "convolution kernel must not be empty",
            ));
        }
        if let Some(i) = kernel.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: format!("convolution kernel entry {i} ({})", kernel[i]),
            });
        }
        let (offset, out_len) = match mode {
            ConvMode::Full => (0, n + l - 1),
            ConvMode::Same => ((l - 1) / 2, n),
            ConvMode::Valid => {
                if n < l {
                    return Err(Error::param(
                        "mode",
                        format!("valid convolution needs rows ({n}) at least as long as the kernel ({l})"),
                    ));
                }
                (l - 1, n - l + 1)
            }
        };
        let full = n + l - 1;
        let fft_len = next_fast_len(full);
        let use_fft = match method {
            ConvMethod::Direct => false,
            ConvMethod::Fft => true,
            ConvMethod::Auto => {
                // Costs per row measured with `cargo bench --bench operators -- convolution` on
                // the reference machine: about 0.4 ns per multiply-add on the direct path, about
                // 0.15 ns per F·log₂F on the FFT path (two rows share a transform).
                let direct = 2.5 * (out_len.min(n) * l) as f64;
                let f = fft_len as f64;
                direct > f * f.log2()
            }
        };
        let fft = use_fft.then(|| {
            let mut planner = FftPlanner::<T>::new();
            let fwd = planner.plan_fft_forward(fft_len);
            let inv = planner.plan_fft_inverse(fft_len);
            let mut h_hat = vec![Complex::new(T::zero(), T::zero()); fft_len];
            for (c, &v) in h_hat.iter_mut().zip(&kernel) {
                c.re = v;
            }
            fwd.process(&mut h_hat);
            let norm = T::of_f64(1.0 / fft_len as f64);
            for c in &mut h_hat {
                *c = *c * norm;
            }
            let fft_scratch = fwd
                .get_inplace_scratch_len()
                .max(inv.get_inplace_scratch_len());
            FftPlan {
                len: fft_len,
                fwd,
                inv,
                h_hat,
                fft_scratch,
            }
        });
        let h_rev = kernel.iter().rev().copied().collect();
        Ok(Convolve1D {
            batch,
            n,
            h: kernel,
            h_rev,
            mode,
            out_len,
            offset,
            fft,
        })
    }

    /// The kernel.
    pub fn kernel(&self) -> &[T] {
        &self.h
    }

    /// The crop mode.
    pub fn mode(&self) -> ConvMode {
        self.mode
    }

    /// Output samples per row.
    pub fn out_len(&self) -> usize {
        self.out_len
    }

    /// The method chosen ([`ConvMethod::Direct`] or [`ConvMethod::Fft`], never `Auto`).
    pub fn method(&self) -> ConvMethod {
        if self.fft.is_some() {
            ConvMethod::Fft
        } else {
            ConvMethod::Direct
        }
    }

    /// y[i] = Σₜ h[t]·x[i + off − t]: with the reversed kernel, a dot product of contiguous slices.
    fn direct_forward_row(&self, x: &[T], y: &mut [T]) {
        let l = self.h.len();
        for (i, yi) in y.iter_mut().enumerate() {
            // Taps t with 0 ≤ i + off − t < n, i.e. t in [lo, hi).
            let k = i + self.offset;
            let lo = (k + 1).saturating_sub(self.n);
            let hi = (k + 1).min(l);
            // Reversed kernel index u = l − 1 − t; x index k − t.
            let hr = &self.h_rev[l - hi..l - lo];
            let xs = &x[k + 1 - hi..k + 1 - lo];
            *yi = T::of_f64(dot(hr, xs));
        }
    }

    /// x[j] = Σᵢ y[i]·h[i + off − j]: a dot product of contiguous slices of y and h.
    fn direct_adjoint_row(&self, y: &[T], x: &mut [T]) {
        let l = self.h.len();
        let m = self.out_len;
        for (j, xj) in x.iter_mut().enumerate() {
            // Outputs i with 0 ≤ i + off − j < l, i.e. i + off in [j, j + l).
            let lo = j.saturating_sub(self.offset);
            let hi = (j + l).saturating_sub(self.offset).min(m);
            *xj = if lo < hi {
                let t0 = lo + self.offset - j;
                T::of_f64(dot(&y[lo..hi], &self.h[t0..t0 + (hi - lo)]))
            } else {
                T::zero()
            };
        }
    }

    /// Runs the FFT path over all rows, two rows per complex transform. `load(r, buf)` writes row
    /// r's input into `buf` (real part for even r, imaginary part for odd r, already zeroed), and
    /// `store(r, buf)` reads row r's result back from the same part.
    fn fft_rows(
        &self,
        plan: &FftPlan<T>,
        conj: bool,
        scratch: &mut [T],
        mut load: impl FnMut(usize, &mut [Complex<T>], bool),
        mut store: impl FnMut(usize, &[Complex<T>], bool),
    ) {
        let (buf, work) = as_complex(scratch).split_at_mut(plan.len);
        let work = &mut work[..plan.fft_scratch];
        let mut r = 0;
        while r < self.batch {
            buf.fill(Complex::new(T::zero(), T::zero()));
            load(r, buf, false);
            let pair = r + 1 < self.batch;
            if pair {
                load(r + 1, buf, true);
            }
            plan.fwd.process_with_scratch(buf, work);
            if conj {
                for (b, h) in buf.iter_mut().zip(&plan.h_hat) {
                    *b = *b * h.conj();
                }
            } else {
                for (b, h) in buf.iter_mut().zip(&plan.h_hat) {
                    *b = *b * *h;
                }
            }
            plan.inv.process_with_scratch(buf, work);
            store(r, buf, false);
            if pair {
                store(r + 1, buf, true);
            }
            r += 2;
        }
    }
}

/// Views a real scratch buffer as complex numbers (pairs of consecutive reals).
fn as_complex<T: Real>(s: &mut [T]) -> &mut [Complex<T>] {
    // SAFETY: `Complex<T>` is `#[repr(C)]` with two `T` fields, so it has the size of `[T; 2]` and
    // the alignment of `T`; any `T` slice of length 2k is a valid `Complex<T>` slice of length k,
    // and the borrow keeps the original exclusively borrowed for the same lifetime.
    unsafe { std::slice::from_raw_parts_mut(s.as_mut_ptr().cast::<Complex<T>>(), s.len() / 2) }
}

#[inline]
fn put<T: Real>(c: &mut Complex<T>, v: T, imag: bool) {
    if imag {
        c.im = v;
    } else {
        c.re = v;
    }
}

#[inline]
fn get<T: Real>(c: &Complex<T>, imag: bool) -> T {
    if imag {
        c.im
    } else {
        c.re
    }
}

impl<T: Real> LinearOperator<T> for Convolve1D<T> {
    fn nrows(&self) -> usize {
        self.batch * self.out_len
    }
    fn ncols(&self) -> usize {
        self.batch * self.n
    }
    fn scratch_len(&self) -> usize {
        self.fft.as_ref().map_or(0, |p| 2 * (p.len + p.fft_scratch))
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        let (n, m, off) = (self.n, self.out_len, self.offset);
        match &self.fft {
            None => {
                for (xr, yr) in x.chunks_exact(n).zip(y.chunks_exact_mut(m)) {
                    self.direct_forward_row(xr, yr);
                }
            }
            Some(plan) => self.fft_rows(
                plan,
                false,
                scratch,
                |r, buf, im| {
                    for (b, &v) in buf.iter_mut().zip(&x[r * n..(r + 1) * n]) {
                        put(b, v, im);
                    }
                },
                |r, buf, im| {
                    for (o, b) in y[r * m..(r + 1) * m].iter_mut().zip(&buf[off..off + m]) {
                        *o = get(b, im);
                    }
                },
            ),
        }
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        let (n, m, off) = (self.n, self.out_len, self.offset);
        match &self.fft {
            None => {
                for (yr, xr) in y.chunks_exact(m).zip(x.chunks_exact_mut(n)) {
                    self.direct_adjoint_row(yr, xr);
                }
            }
            Some(plan) => self.fft_rows(
                plan,
                true,
                scratch,
                |r, buf, im| {
                    for (b, &v) in buf[off..off + m].iter_mut().zip(&y[r * m..(r + 1) * m]) {
                        put(b, v, im);
                    }
                },
                |r, buf, im| {
                    for (o, b) in x[r * n..(r + 1) * n].iter_mut().zip(&buf[..n]) {
                        *o = get(b, im);
                    }
                },
            ),
        }
    }
    fn describe(&self) -> String {
        format!(
            "Convolve1D({}x{} * {}, {:?}, {:?})",
            self.batch,
            self.n,
            self.h.len(),
            self.mode,
            self.method()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::next_fast_len;

    #[test]
    fn fast_lengths_are_smooth_and_minimal() {
        for n in 1..2000usize {
            let f = next_fast_len(n);
            assert!(f >= n);
            let mut r = f;
            for p in [2, 3, 5] {
                while r.is_multiple_of(p) {
                    r /= p;
                }
            }
            assert_eq!(r, 1, "{f} is not 5-smooth");
            for c in n..f {
                let mut r = c;
                for p in [2, 3, 5] {
                    while r % p == 0 {
                        r /= p;
                    }
                }
                assert_ne!(r, 1, "{c} is a smaller 5-smooth length than {f} for {n}");
            }
        }
    }
}
