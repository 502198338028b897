//! The support-restricted kernels (the sparse forward's entries, the restricted adjoint's signed
//! copies and windowed dot products) in vectors (512-bit on AVX-512, 256-bit on AVX2), and the
//! entry points that choose them or the narrow kernels by instruction set.
//!
//! A code byte's bit becomes a lane mask (AVX-512BW's byte test; on AVX2 the bytes widened to
//! the lanes and shifted so that the bit lands on the sign that the blends read), the mask signs
//! the values (a masked subtraction, or a blend), and the dot products run in four independent
//! accumulators: the narrow kernels' eight-lane sums wait on one addition after another and
//! decode the codes byte by byte. Dot products are summed in blocks of 256 products in `T`, the
//! block sums in `f64`, as the narrow kernels do; within a block the products are fused
//! multiply-adds in four vectors' partial sums (64 for `f32` on AVX-512, 32 on AVX2), so the
//! last bits differ from the narrow kernels'.

#[cfg(target_arch = "x86_64")]
use super::wide::{wide_pair, Simd};
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
    if isa.has_wide() {
        let (m, ternary) = (minus.unwrap_or(plus), minus.is_some());
        // SAFETY: `Isa::Avx512` is chosen only on a CPU with AVX-512F, BW, VL and FMA, and
        // `Isa::Avx2` on one with AVX2 and FMA; every slice holds the window's length (asserted
        // above) and the kernel reads and writes within it.
        unsafe {
            match (isa == Isa::Avx512, ternary) {
                (true, false) => entry_512::<T, false>(amp, bit, plus, m, pw, out),
                (true, true) => entry_512::<T, true>(amp, bit, plus, m, pw, out),
                (false, false) => entry_256::<T, false>(amp, bit, plus, m, pw, out),
                (false, true) => entry_256::<T, true>(amp, bit, plus, m, pw, out),
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

/// [`sparse_entry_isa`] for every entry in turn, all on the window of `out`; with the wide
/// kernels four entries at a time, so that `out` is loaded and stored once for four (the same
/// additions in the same order as one entry at a time).
///
/// # Panics
/// If an entry's slices differ in length from `out`; with the wide kernels also if the entries
/// mix code alphabets (binary and ternary).
pub(crate) fn sparse_entries_isa<T: Real>(isa: Isa, entries: &[Entry<'_, T>], out: &mut [T]) {
    #[cfg(target_arch = "x86_64")]
    if isa.has_wide() {
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
                match (isa == Isa::Avx512, ternary) {
                    (true, false) => entries4_512::<T, false>(quad, out),
                    (true, true) => entries4_512::<T, true>(quad, out),
                    (false, false) => entries4_256::<T, false>(quad, out),
                    (false, true) => entries4_256::<T, true>(quad, out),
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
    if isa.has_wide() {
        let (m, ternary) = (minus.unwrap_or(plus), minus.is_some());
        // SAFETY: as in `sparse_entry_isa`.
        unsafe {
            match (isa == Isa::Avx512, ternary) {
                (true, false) => copy_512::<T, false>(bit, plus, m, y, z),
                (true, true) => copy_512::<T, true>(bit, plus, m, y, z),
                (false, false) => copy_256::<T, false>(bit, plus, m, y, z),
                (false, true) => copy_256::<T, true>(bit, plus, m, y, z),
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
    if isa.has_wide() {
        let (m, ternary) = (minus.unwrap_or(plus), minus.is_some());
        // SAFETY: as in `sparse_entry_isa`.
        *out = unsafe {
            match (isa == Isa::Avx512, ternary) {
                (true, false) => dot_512::<T, true, false>(bit, plus, m, y, p),
                (true, true) => dot_512::<T, true, true>(bit, plus, m, y, p),
                (false, false) => dot_256::<T, true, false>(bit, plus, m, y, p),
                (false, true) => dot_256::<T, true, true>(bit, plus, m, y, p),
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
    if isa.has_wide() {
        // SAFETY: as in `sparse_entry_isa`; no codes are read.
        *out = unsafe {
            if isa == Isa::Avx512 {
                dot_512::<T, false, false>(0, &[], &[], a, b)
            } else {
                dot_256::<T, false, false>(0, &[], &[], a, b)
            }
        };
        return;
    }
    lane_dot_narrow(isa, a, b, out);
}

/// The values at `at` with the codes applied (`CODED`), or as they are.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn coded<S: Simd, const CODED: bool, const TERNARY: bool>(
    bit: u32,
    plus: *const u8,
    minus: *const u8,
    v: S::V,
    at: usize,
) -> S::V {
    if !CODED {
        return v;
    }
    let m = S::m_bit(plus.add(at), bit);
    if TERNARY {
        S::v_ternary(m, S::m_bit(minus.add(at), bit), v)
    } else {
        S::v_sign(m, v)
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

#[cfg(target_arch = "x86_64")]
wide_pair!(dot_512, dot_256, dot_wide<const CODED: bool, const TERNARY: bool>(
    bit: u32, plus: &[u8], minus: &[u8], y: &[T], p: &[T]
) -> f64);

/// Σ s(k)·y[k]·p[k] (`CODED`) or Σ y[k]·p[k].
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn dot_wide<T: Real, S: Simd<T = T>, const CODED: bool, const TERNARY: bool>(
    bit: u32,
    plus: &[u8],
    minus: &[u8],
    y: &[T],
    p: &[T],
) -> f64 {
    let per = S::PER;
    let n = y.len();
    let (yp, pp, cp, cm) = (y.as_ptr(), p.as_ptr(), plus.as_ptr(), minus.as_ptr());
    let mut total = 0.0f64;
    let mut start = 0;
    while start + per <= n {
        let end = (start + BLOCK).min(n);
        let mut acc = [S::v_zero(); 4];
        let mut at = start;
        while at + 4 * per <= end {
            for (a, sum) in acc.iter_mut().enumerate() {
                let k = at + a * per;
                let v = coded::<S, CODED, TERNARY>(bit, cp, cm, S::v_loadu(yp.add(k)), k);
                *sum = S::v_mul_add(v, S::v_loadu(pp.add(k)), *sum);
            }
            at += 4 * per;
        }
        while at + per <= end {
            let v = coded::<S, CODED, TERNARY>(bit, cp, cm, S::v_loadu(yp.add(at)), at);
            acc[0] = S::v_mul_add(v, S::v_loadu(pp.add(at)), acc[0]);
            at += per;
        }
        let sum = S::v_add(S::v_add(acc[0], acc[1]), S::v_add(acc[2], acc[3]));
        total += S::v_lanes8(sum).iter().map(|v| v.as_f64()).sum::<f64>();
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

#[cfg(target_arch = "x86_64")]
wide_pair!(copy_512, copy_256, copy_wide<const TERNARY: bool>(
    bit: u32, plus: &[u8], minus: &[u8], y: &[T], z: &mut [T]
));

/// z[k] = s(k)·y[k].
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn copy_wide<T: Real, S: Simd<T = T>, const TERNARY: bool>(
    bit: u32,
    plus: &[u8],
    minus: &[u8],
    y: &[T],
    z: &mut [T],
) {
    let per = S::PER;
    let n = y.len();
    let (yp, zp, cp, cm) = (y.as_ptr(), z.as_mut_ptr(), plus.as_ptr(), minus.as_ptr());
    let mut at = 0;
    while at + per <= n {
        let v = coded::<S, true, TERNARY>(bit, cp, cm, S::v_loadu(yp.add(at)), at);
        S::v_storeu(zp.add(at), v);
        at += per;
    }
    for k in at..n {
        z[k] = T::of_f64(code_at::<TERNARY>(bit, plus, minus, k)) * y[k];
    }
}

#[cfg(target_arch = "x86_64")]
wide_pair!(entry_512, entry_256, entry_wide<const TERNARY: bool>(
    amp: T, bit: u32, plus: &[u8], minus: &[u8], pw: &[T], out: &mut [T]
));

/// out[k] += amp·s(k)·pw[k].
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn entry_wide<T: Real, S: Simd<T = T>, const TERNARY: bool>(
    amp: T,
    bit: u32,
    plus: &[u8],
    minus: &[u8],
    pw: &[T],
    out: &mut [T],
) {
    let per = S::PER;
    let n = out.len();
    let (pp, op, cp, cm) = (pw.as_ptr(), out.as_mut_ptr(), plus.as_ptr(), minus.as_ptr());
    let a = S::v_splat(amp);
    let mut at = 0;
    while at + per <= n {
        let v = coded::<S, true, TERNARY>(bit, cp, cm, S::v_loadu(pp.add(at)), at);
        S::v_storeu(op.add(at), S::v_mul_add(v, a, S::v_loadu(op.add(at))));
        at += per;
    }
    for k in at..n {
        out[k] = out[k] + amp * pw[k] * T::of_f64(code_at::<TERNARY>(bit, plus, minus, k));
    }
}

#[cfg(target_arch = "x86_64")]
wide_pair!(entries4_512, entries4_256, entries4_wide<const TERNARY: bool>(
    e: &[Entry<'_, T>; 4], out: &mut [T]
));

/// out[k] += Σ over the four entries of amp·s(k)·pw[k], entry by entry.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn entries4_wide<T: Real, S: Simd<T = T>, const TERNARY: bool>(
    e: &[Entry<'_, T>; 4],
    out: &mut [T],
) {
    let per = S::PER;
    let n = out.len();
    let op = out.as_mut_ptr();
    let mut amps = [S::v_zero(); 4];
    let mut negs = [S::v_zero(); 4];
    let mut cm = [e[0].plus.as_ptr(); 4];
    for i in 0..4 {
        amps[i] = S::v_splat(e[i].amp);
        negs[i] = S::v_splat(T::zero() - e[i].amp);
        cm[i] = e[i].minus.unwrap_or(e[i].plus).as_ptr();
    }
    let mut at = 0;
    while at + per <= n {
        let mut o = S::v_loadu(op.add(at));
        for i in 0..4 {
            let p = S::v_loadu(e[i].pw.as_ptr().add(at));
            o = if TERNARY {
                let v = coded::<S, true, TERNARY>(e[i].bit, e[i].plus.as_ptr(), cm[i], p, at);
                S::v_mul_add(v, amps[i], o)
            } else {
                // The code picks +amp or −amp: the same product as the signed pulse value's.
                let m = S::m_bit(e[i].plus.as_ptr().add(at), e[i].bit);
                S::v_mul_add(p, S::v_pick(m, amps[i], negs[i]), o)
            };
        }
        S::v_storeu(op.add(at), o);
        at += per;
    }
    for (k, o) in out.iter_mut().enumerate().skip(at) {
        for ei in e {
            let c = code_at::<TERNARY>(ei.bit, ei.plus, ei.minus.unwrap_or(ei.plus), k);
            *o = *o + ei.amp * ei.pw[k] * T::of_f64(c);
        }
    }
}
