//! The support-restricted kernels (the sparse forward's entries, the restricted adjoint's signed
//! copies and windowed dot products) on AVX-512, and the entry points that choose them or the
//! narrow kernels by instruction set.
//!
//! A code byte's bit becomes a lane mask (AVX-512BW's byte test), the mask signs the values in
//! one masked subtraction, and the dot products run in four independent 512-bit accumulators:
//! the narrow kernels' eight-lane sums wait on one addition after another and decode the codes
//! byte by byte. Dot products are summed in blocks of 256 products in `T`, the block sums in
//! `f64`, as the narrow kernels do; within a block the products are fused multiply-adds in 64
//! partial sums (32 for `f64`), so the last bits differ from the narrow kernels'.

#[cfg(target_arch = "x86_64")]
use super::wide::Wide;
use super::{lane_dot_narrow, signed_copy_narrow, signed_dot_narrow, sparse_entry_narrow, Isa};
use crate::real::Real;

/// Products summed in `T` before their sum is added in `f64`.
#[cfg(target_arch = "x86_64")]
const BLOCK: usize = 256;

/// Panics unless the code planes cover the `n` values.
fn check_planes(plus: &[u8], minus: Option<&[u8]>, n: usize) {
    assert_eq!(plus.len(), n, "code bytes");
    assert!(minus.is_none_or(|m| m.len() == n), "code planes");
}

/// out[k] += a·s(k)·p[k] over the entry's window: one sparse entry of the forward, `out` the
/// measurements on the entry's window.
///
/// # Panics
/// If the entry's slices differ in length from `out`.
pub(crate) fn sparse_entry_isa<T: Real>(isa: Isa, e: &Entry<'_, T>, out: &mut [T]) {
    let Entry {
        amp,
        bit,
        plus,
        minus,
        pw,
    } = *e;
    assert_eq!(pw.len(), out.len(), "pulse window");
    check_planes(plus, minus, out.len());
    #[cfg(target_arch = "x86_64")]
    if isa == Isa::Avx512 {
        // SAFETY: `Isa::Avx512` is chosen only on a CPU with AVX-512F, BW and VL; every slice
        // holds the window's length (asserted above) and the kernel reads and writes within it.
        unsafe {
            match minus {
                None => entry_wide::<T, false>(amp, bit, plus, plus, pw, out),
                Some(m) => entry_wide::<T, true>(amp, bit, plus, m, pw, out),
            }
        }
        return;
    }
    sparse_entry_narrow(isa, amp, bit, plus, minus, pw, out);
}

/// One voxel's term of the sparse forward on a window of samples: its amplitude, its pixel's bit
/// in the code bytes, its group's code planes and the pulse on the window (all of the window's
/// length).
#[derive(Clone, Copy)]
pub(crate) struct Entry<'a, T> {
    pub amp: T,
    pub bit: u32,
    pub plus: &'a [u8],
    pub minus: Option<&'a [u8]>,
    pub pw: &'a [T],
}

/// [`sparse_entry_isa`] for every entry in turn, all on the window of `out`; on AVX-512 four
/// entries at a time, so that `out` is loaded and stored once for four (the same additions in
/// the same order as one entry at a time).
///
/// # Panics
/// If an entry's slices differ in length from `out`; on AVX-512 also if the entries mix code
/// alphabets (binary and ternary).
pub(crate) fn sparse_entries_isa<T: Real>(isa: Isa, entries: &[Entry<'_, T>], out: &mut [T]) {
    #[cfg(target_arch = "x86_64")]
    if isa == Isa::Avx512 {
        let ternary = entries.first().is_some_and(|e| e.minus.is_some());
        for e in entries {
            assert_eq!(e.pw.len(), out.len(), "pulse window");
            check_planes(e.plus, e.minus, out.len());
            assert_eq!(e.minus.is_some(), ternary, "code alphabets");
        }
        let quads = entries.chunks_exact(4);
        let rest = quads.remainder();
        for quad in quads {
            let quad: &[Entry<'_, T>; 4] = quad.try_into().expect("four entries");
            // SAFETY: as in `sparse_entry_isa`, for each of the four entries.
            unsafe {
                if ternary {
                    entries4_wide::<T, true>(quad, out);
                } else {
                    entries4_wide::<T, false>(quad, out);
                }
            }
        }
        for e in rest {
            sparse_entry_isa(isa, e, out);
        }
        return;
    }
    for e in entries {
        sparse_entry_isa(isa, e, out);
    }
}

/// z[k] = s(k)·y[k] for the pixel at bit `bit` of the code bytes.
///
/// # Panics
/// If the slices differ in length.
pub(crate) fn signed_copy_isa<T: Real>(
    isa: Isa,
    bit: u32,
    plus: &[u8],
    minus: Option<&[u8]>,
    y: &[T],
    z: &mut [T],
) {
    assert_eq!(y.len(), z.len(), "measurements");
    check_planes(plus, minus, z.len());
    #[cfg(target_arch = "x86_64")]
    if isa == Isa::Avx512 {
        // SAFETY: as in `sparse_entry_isa`.
        unsafe {
            match minus {
                None => copy_wide::<T, false>(bit, plus, plus, y, z),
                Some(m) => copy_wide::<T, true>(bit, plus, m, y, z),
            }
        }
        return;
    }
    signed_copy_narrow(isa, bit, plus, minus, y, z);
}

/// *out = Σ_k s(k)·y[k]·p[k] for the pixel at bit `bit` of the code bytes: the restricted
/// adjoint of one voxel in one pass.
///
/// # Panics
/// If the slices differ in length.
pub(crate) fn signed_dot_isa<T: Real>(
    isa: Isa,
    bit: u32,
    plus: &[u8],
    minus: Option<&[u8]>,
    y: &[T],
    p: &[T],
    out: &mut f64,
) {
    assert_eq!(y.len(), p.len(), "pulse window");
    check_planes(plus, minus, y.len());
    #[cfg(target_arch = "x86_64")]
    if isa == Isa::Avx512 {
        // SAFETY: as in `sparse_entry_isa`.
        *out = unsafe {
            match minus {
                None => dot_wide::<T, true, false>(bit, plus, plus, y, p),
                Some(m) => dot_wide::<T, true, true>(bit, plus, m, y, p),
            }
        };
        return;
    }
    signed_dot_narrow(isa, bit, plus, minus, y, p, out);
}

/// *out = Σ a[i]·b[i].
///
/// # Panics
/// If the slices differ in length.
pub(crate) fn lane_dot_isa<T: Real>(isa: Isa, a: &[T], b: &[T], out: &mut f64) {
    assert_eq!(a.len(), b.len(), "dot product");
    #[cfg(target_arch = "x86_64")]
    if isa == Isa::Avx512 {
        // SAFETY: as in `sparse_entry_isa`; no codes are read.
        *out = unsafe { dot_wide::<T, false, false>(0, &[], &[], a, b) };
        return;
    }
    lane_dot_narrow(isa, a, b, out);
}

/// The values at `at` with the codes applied (`CODED`), or as they are.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn coded<T: Real, const CODED: bool, const TERNARY: bool>(
    bit: u32,
    plus: *const u8,
    minus: *const u8,
    v: T::V,
    at: usize,
) -> T::V {
    if !CODED {
        return v;
    }
    let m = T::m_bit(plus.add(at), bit);
    if TERNARY {
        T::v_ternary(m, T::m_bit(minus.add(at), bit), v)
    } else {
        T::v_sign(m, v)
    }
}

/// The code of one value (±1, or −1/0/+1 for ternary codes).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn code_at<const TERNARY: bool>(bit: u32, plus: &[u8], minus: &[u8], at: usize) -> f64 {
    let p = f64::from((plus[at] >> bit) & 1);
    if TERNARY {
        p - f64::from((minus[at] >> bit) & 1)
    } else {
        2.0 * p - 1.0
    }
}

/// Σ s(k)·y[k]·p[k] (`CODED`) or Σ y[k]·p[k].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
unsafe fn dot_wide<T: Real, const CODED: bool, const TERNARY: bool>(
    bit: u32,
    plus: &[u8],
    minus: &[u8],
    y: &[T],
    p: &[T],
) -> f64 {
    let per = <T as Wide>::PER;
    let n = y.len();
    let (yp, pp, cp, cm) = (y.as_ptr(), p.as_ptr(), plus.as_ptr(), minus.as_ptr());
    let mut total = 0.0f64;
    let mut start = 0;
    while start + per <= n {
        let end = (start + BLOCK).min(n);
        let mut acc = [T::v_zero(); 4];
        let mut at = start;
        while at + 4 * per <= end {
            for (a, sum) in acc.iter_mut().enumerate() {
                let k = at + a * per;
                let v = coded::<T, CODED, TERNARY>(bit, cp, cm, T::v_loadu(yp.add(k)), k);
                *sum = T::v_mul_add(v, T::v_loadu(pp.add(k)), *sum);
            }
            at += 4 * per;
        }
        while at + per <= end {
            let v = coded::<T, CODED, TERNARY>(bit, cp, cm, T::v_loadu(yp.add(at)), at);
            acc[0] = T::v_mul_add(v, T::v_loadu(pp.add(at)), acc[0]);
            at += per;
        }
        let sum = T::v_add(T::v_add(acc[0], acc[1]), T::v_add(acc[2], acc[3]));
        total += T::v_lanes8(sum).iter().map(|v| v.as_f64()).sum::<f64>();
        start = at;
    }
    for k in start..n {
        let c = if CODED {
            code_at::<TERNARY>(bit, plus, minus, k)
        } else {
            1.0
        };
        total += c * (y[k] * p[k]).as_f64();
    }
    total
}

/// z[k] = s(k)·y[k].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
unsafe fn copy_wide<T: Real, const TERNARY: bool>(
    bit: u32,
    plus: &[u8],
    minus: &[u8],
    y: &[T],
    z: &mut [T],
) {
    let per = <T as Wide>::PER;
    let n = y.len();
    let (yp, zp, cp, cm) = (y.as_ptr(), z.as_mut_ptr(), plus.as_ptr(), minus.as_ptr());
    let mut at = 0;
    while at + per <= n {
        let v = coded::<T, true, TERNARY>(bit, cp, cm, T::v_loadu(yp.add(at)), at);
        T::v_storeu(zp.add(at), v);
        at += per;
    }
    for k in at..n {
        z[k] = T::of_f64(code_at::<TERNARY>(bit, plus, minus, k)) * y[k];
    }
}

/// out[k] += amp·s(k)·pw[k].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
unsafe fn entry_wide<T: Real, const TERNARY: bool>(
    amp: T,
    bit: u32,
    plus: &[u8],
    minus: &[u8],
    pw: &[T],
    out: &mut [T],
) {
    let per = <T as Wide>::PER;
    let n = out.len();
    let (pp, op, cp, cm) = (pw.as_ptr(), out.as_mut_ptr(), plus.as_ptr(), minus.as_ptr());
    let a = T::v_splat(amp);
    let mut at = 0;
    while at + per <= n {
        let v = coded::<T, true, TERNARY>(bit, cp, cm, T::v_loadu(pp.add(at)), at);
        T::v_storeu(op.add(at), T::v_mul_add(v, a, T::v_loadu(op.add(at))));
        at += per;
    }
    for k in at..n {
        out[k] = out[k] + amp * pw[k] * T::of_f64(code_at::<TERNARY>(bit, plus, minus, k));
    }
}

/// out[k] += Σ over the four entries of amp·s(k)·pw[k], entry by entry.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
unsafe fn entries4_wide<T: Real, const TERNARY: bool>(e: &[Entry<'_, T>; 4], out: &mut [T]) {
    let per = <T as Wide>::PER;
    let n = out.len();
    let op = out.as_mut_ptr();
    let mut amps = [T::v_zero(); 4];
    let mut cm = [e[0].plus.as_ptr(); 4];
    for i in 0..4 {
        amps[i] = T::v_splat(e[i].amp);
        cm[i] = e[i].minus.unwrap_or(e[i].plus).as_ptr();
    }
    let mut at = 0;
    while at + per <= n {
        let mut o = T::v_loadu(op.add(at));
        for i in 0..4 {
            let p = T::v_loadu(e[i].pw.as_ptr().add(at));
            let v = coded::<T, true, TERNARY>(e[i].bit, e[i].plus.as_ptr(), cm[i], p, at);
            o = T::v_mul_add(v, amps[i], o);
        }
        T::v_storeu(op.add(at), o);
        at += per;
    }
    for (k, o) in out.iter_mut().enumerate().skip(at) {
        for ei in e {
            let c = code_at::<TERNARY>(ei.bit, ei.plus, ei.minus.unwrap_or(ei.plus), k);
            *o = *o + ei.amp * ei.pw[k] * T::of_f64(c);
        }
    }
}
