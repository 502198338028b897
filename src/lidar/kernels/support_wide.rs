//! The support-restricted kernels (the sparse forward's entries, the restricted adjoint's
//! windowed dot products) in vectors (512-bit on AVX-512, 256-bit on AVX2), and the entry points
//! that choose them or the narrow kernels by instruction set.
//!
//! A code byte's bit becomes a lane mask (AVX-512BW's byte test; on AVX2 the bytes widened to
//! the lanes and shifted so that the bit lands on the sign that the blends read), and the mask
//! signs the values (a masked subtraction, or a blend) or chooses where they are added.
//!
//! Both directions take the voxels of one depth together, since those share the pulse's window:
//! the forward ([`depth_entries_isa`]) sums eight entries' signed amplitudes and adds the sum
//! times the pulse to the measurements once, in place of eight passes that each read the pulse
//! and read and write the measurements; the adjoint ([`depth_dots_isa`], on AVX-512) forms the
//! products of the measurements and the pulse once for eight voxels, widens them to `f64` and
//! adds them where each voxel's code is +1, with their plain sum kept once (Σ s·w = 2·Σ₊ w − Σ w),
//! all in `f64`. The forward's entries left over from its batches go one at a time, and on AVX2
//! the adjoint goes voxel by voxel: a voxel's dot product in four independent accumulators,
//! summed in blocks of 256 products in `T`, the block sums in `f64`, as the narrow kernels do
//! (within a block the products are fused multiply-adds in four vectors' partial sums, so the
//! last bits differ from the narrow kernels').

#[cfg(target_arch = "x86_64")]
use super::wide::{wide_pair, Simd};
use super::{signed_dot_narrow, sparse_entry_narrow, Isa};
use crate::real::Real;
use std::ops::Range;

/// Products summed in `T` before their sum is added in `f64`.
#[cfg(target_arch = "x86_64")]
const BLOCK: usize = 256;

/// Panics unless the code planes cover the `n` values.
fn check_planes(plus: &[u8], minus: Option<&[u8]>, n: usize) {
    assert_eq!(plus.len(), n, "code bytes");
    assert!(minus.is_none_or(|m| m.len() == n), "code planes");
}

/// Panics unless every code covers the `n` values, all in one alphabet; whether it is ternary.
fn check_codes(codes: &[Coded<'_>], n: usize) -> bool {
    let ternary = codes.first().is_some_and(|c| c.minus.is_some());
    for c in codes {
        check_planes(c.plus, c.minus, n);
        assert_eq!(c.minus.is_some(), ternary, "code alphabets");
    }
    ternary
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

/// A piece of the sparse forward's schedule: a range of its order, the entries' depth, and
/// whether the sums kept in `T` go to `f64` before it.
pub(crate) type Piece = (Range<usize>, usize, bool);

/// The sparse forward's schedule, which follows from the entries (pixel, depth, value) alone:
/// their order (by depth, then pixel) and its pieces, ranges of one depth of at most `batch`
/// entries, each with its depth and whether the sums kept in `T` go to `f64` before it (when
/// they would otherwise hold more than `batch` entries).
pub(crate) fn depth_schedule<T>(
    entries: &[(usize, usize, T)],
    batch: usize,
) -> (Vec<usize>, Vec<Piece>) {
    let mut order: Vec<usize> = (0..entries.len()).collect();
    order.sort_unstable_by_key(|&i| (entries[i].1, entries[i].0, i));
    let mut pieces = Vec::new();
    let (mut pending, mut at) = (0, 0);
    for run in order.chunk_by(|&a, &b| entries[a].1 == entries[b].1) {
        for piece in run.chunks(batch) {
            let flush = pending + piece.len() > batch;
            if flush {
                pending = 0;
            }
            pieces.push((at..at + piece.len(), entries[piece[0]].1, flush));
            pending += piece.len();
            at += piece.len();
        }
    }
    (order, pieces)
}

/// acc += buf in `f64`, buf cleared.
pub(crate) fn flush_into<T: Real>(acc: &mut [f64], buf: &mut [T]) {
    for (a, b) in acc.iter_mut().zip(buf.iter_mut()) {
        *a += b.as_f64();
        *b = T::zero();
    }
}

/// A pixel's code on a window of samples: its bit in the code bytes and its group's code planes
/// there.
#[derive(Clone, Copy)]
pub(crate) struct Coded<'a> {
    pub bit: u32,
    pub plus: &'a [u8],
    pub minus: Option<&'a [u8]>,
}

/// out[k] += pw[k]·Σᵢ amps[i]·sᵢ(k): entries of one depth, which share the pulse's window (all
/// slices of the window's length, the codes of one alphabet). With the wide kernels eight (then
/// four) entries at a time: their signed amplitudes are summed first, then multiplied by the
/// pulse and added to `out` once, so that the pulse and `out` are read once for eight entries and
/// each entry costs a code test, a blend and an addition; the entries left over go one at a time.
///
/// # Panics
/// If a slice differs in length from `out`, `amps` and `codes` differ in length, or the codes
/// mix alphabets (binary and ternary).
pub(crate) fn depth_entries_isa<T: Real>(
    isa: Isa,
    amps: &[T],
    codes: &[Coded<'_>],
    pw: &[T],
    out: &mut [T],
) {
    assert_eq!(amps.len(), codes.len(), "amplitudes");
    assert_eq!(pw.len(), out.len(), "pulse window");
    let ternary = check_codes(codes, out.len());
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if isa.has_wide() {
        let wide = isa == Isa::Avx512;
        while amps.len() - done >= 4 {
            let (a, c) = (&amps[done..], &codes[done..]);
            // SAFETY: as in `sparse_entry_isa`, for each entry.
            done += unsafe {
                if a.len() >= 8 {
                    depth_batch::<T, 8>(wide, ternary, a, c, pw, out)
                } else {
                    depth_batch::<T, 4>(wide, ternary, a, c, pw, out)
                }
            };
        }
    }
    for (&amp, c) in amps[done..].iter().zip(&codes[done..]) {
        let e = Entry {
            amp,
            bit: c.bit,
            plus: c.plus,
            minus: c.minus,
            pw,
        };
        sparse_entry_isa(isa, &e, out);
    }
}

/// out[i] = Σₖ sᵢ(k)·y[k]·p[k] for voxels of one depth (their codes on the window of `y` and
/// `p`, all slices of one length, the codes of one alphabet). On AVX-512 eight (binary codes) or
/// four (ternary) voxels at a time: the products y·p are formed once for all of them
/// and summed in `f64`, each voxel adding them where its code is +1 while their plain sum is
/// kept once, so that Σ sᵢ·y·p = 2·Σ_{sᵢ=+1} y·p − Σ y·p (with ternary codes Σ₊ − Σ₋); a voxel's
/// sum does not depend on the voxels that share its batch. Elsewhere one voxel at a time
/// ([`signed_dot_isa`]).
///
/// # Panics
/// If a slice differs in length from `y`, `codes` and `out` differ in length, or the codes mix
/// alphabets.
pub(crate) fn depth_dots_isa<T: Real>(
    isa: Isa,
    codes: &[Coded<'_>],
    y: &[T],
    p: &[T],
    out: &mut [f64],
) {
    assert_eq!(codes.len(), out.len(), "sums");
    assert_eq!(y.len(), p.len(), "pulse window");
    let ternary = check_codes(codes, y.len());
    // On AVX-512 only: AVX2's widening to `f64` and its blends cost more than the voxel at a
    // time does (26.5 against 19.4 ms for the restricted adjoint of `rdlidar bench --pulse-len
    // 30000 --threads 1`, `f32`, on a Zen 4).
    #[cfg(target_arch = "x86_64")]
    if isa == Isa::Avx512 {
        // Eight voxels' sums in `f64` take 16 of the 32 registers (`f32`); with ternary codes,
        // whose sums are two a voxel, four. A last, short batch is filled up with its last
        // voxel, so that every voxel's sum is formed alike whatever voxels share its batch.
        let width = if ternary { 4 } else { 8 };
        for (batch, sums) in codes.chunks(width).zip(out.chunks_mut(width)) {
            let mut full = [batch[batch.len() - 1]; 8];
            full[..batch.len()].copy_from_slice(batch);
            // SAFETY: as in `sparse_entry_isa`, for each voxel.
            let got = unsafe {
                if ternary {
                    let c = (&full[..4]).try_into().expect("4");
                    let four = dots_512::<T, 4, true>(c, y, p);
                    [four[0], four[1], four[2], four[3], 0.0, 0.0, 0.0, 0.0]
                } else {
                    dots_512::<T, 8, false>(&full, y, p)
                }
            };
            sums.copy_from_slice(&got[..sums.len()]);
        }
        return;
    }
    for (c, o) in codes.iter().zip(out.iter_mut()) {
        signed_dot_isa(isa, c.bit, c.plus, c.minus, y, p, o);
    }
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
                (true, false) => dot_512::<T, false>(bit, plus, m, y, p),
                (true, true) => dot_512::<T, true>(bit, plus, m, y, p),
                (false, false) => dot_256::<T, false>(bit, plus, m, y, p),
                (false, true) => dot_256::<T, true>(bit, plus, m, y, p),
            }
        };
        return;
    }
    signed_dot_narrow(isa, bit, plus, minus, y, p, out);
}

/// The values at `at` with the codes applied.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn coded<S: Simd, const TERNARY: bool>(
    bit: u32,
    plus: *const u8,
    minus: *const u8,
    v: S::V,
    at: usize,
) -> S::V {
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
wide_pair!(dot_512, dot_256, dot_wide<const TERNARY: bool>(
    bit: u32, plus: &[u8], minus: &[u8], y: &[T], p: &[T]
) -> f64);

/// Σ s(k)·y[k]·p[k].
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn dot_wide<T: Real, S: Simd<T = T>, const TERNARY: bool>(
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
                let v = coded::<S, TERNARY>(bit, cp, cm, S::v_loadu(yp.add(k)), k);
                *sum = S::v_mul_add(v, S::v_loadu(pp.add(k)), *sum);
            }
            at += 4 * per;
        }
        while at + per <= end {
            let v = coded::<S, TERNARY>(bit, cp, cm, S::v_loadu(yp.add(at)), at);
            acc[0] = S::v_mul_add(v, S::v_loadu(pp.add(at)), acc[0]);
            at += per;
        }
        let sum = S::v_add(S::v_add(acc[0], acc[1]), S::v_add(acc[2], acc[3]));
        total += S::v_lanes8(sum).iter().map(|v| v.as_f64()).sum::<f64>();
        start = at;
    }
    for k in start..n {
        total += code_at::<TERNARY>(bit, plus, minus, k) * (y[k] * p[k]).as_f64();
    }
    total
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
        let v = coded::<S, TERNARY>(bit, cp, cm, S::v_loadu(pp.add(at)), at);
        S::v_storeu(op.add(at), S::v_mul_add(v, a, S::v_loadu(op.add(at))));
        at += per;
    }
    for k in at..n {
        out[k] = out[k] + amp * pw[k] * T::of_f64(code_at::<TERNARY>(bit, plus, minus, k));
    }
}

/// The first N of `amps` and `codes` by [`depth_wide`] in the instruction set's vectors
/// (512-bit if `wide`) and the codes' alphabet; returns N.
///
/// # Safety
/// As [`depth_512`] and [`depth_256`]: the CPU has the instruction set's features, and the
/// slices hold at least N entries of the window's length.
#[cfg(target_arch = "x86_64")]
unsafe fn depth_batch<T: Real, const N: usize>(
    wide: bool,
    ternary: bool,
    amps: &[T],
    codes: &[Coded<'_>],
    pw: &[T],
    out: &mut [T],
) -> usize {
    let a: &[T; N] = amps[..N].try_into().expect("N amplitudes");
    let c: &[Coded<'_>; N] = codes[..N].try_into().expect("N codes");
    match (wide, ternary) {
        (true, false) => depth_512::<T, N, false>(a, c, pw, out),
        (true, true) => depth_512::<T, N, true>(a, c, pw, out),
        (false, false) => depth_256::<T, N, false>(a, c, pw, out),
        (false, true) => depth_256::<T, N, true>(a, c, pw, out),
    }
    N
}

#[cfg(target_arch = "x86_64")]
wide_pair!(depth_512, depth_256, depth_wide<const N: usize, const TERNARY: bool>(
    amps: &[T; N], codes: &[Coded<'_>; N], pw: &[T], out: &mut [T]
));

/// out[k] += pw[k]·Σᵢ amps[i]·sᵢ(k) over N entries of one depth: the signed amplitudes summed
/// in two chains, then multiplied by the pulse and added to `out` by one fused multiply-add.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn depth_wide<T: Real, S: Simd<T = T>, const N: usize, const TERNARY: bool>(
    amps: &[T; N],
    codes: &[Coded<'_>; N],
    pw: &[T],
    out: &mut [T],
) {
    let per = S::PER;
    let n = out.len();
    let (pp, op) = (pw.as_ptr(), out.as_mut_ptr());
    let amp: [S::V; N] = std::array::from_fn(|i| S::v_splat(amps[i]));
    let neg: [S::V; N] = std::array::from_fn(|i| S::v_splat(T::zero() - amps[i]));
    let plus: [*const u8; N] = std::array::from_fn(|i| codes[i].plus.as_ptr());
    let minus: [*const u8; N] =
        std::array::from_fn(|i| codes[i].minus.unwrap_or(codes[i].plus).as_ptr());
    let zero = S::v_zero();
    let mut at = 0;
    while at + per <= n {
        let mut sums = [zero; 2];
        for i in 0..N {
            let m = S::m_bit(plus[i].add(at), codes[i].bit);
            let term = if TERNARY {
                S::v_ternary(m, S::m_bit(minus[i].add(at), codes[i].bit), amp[i])
            } else {
                S::v_pick(m, amp[i], neg[i])
            };
            sums[i % 2] = S::v_add(sums[i % 2], term);
        }
        let sum = S::v_add(sums[0], sums[1]);
        let o = S::v_mul_add(S::v_loadu(pp.add(at)), sum, S::v_loadu(op.add(at)));
        S::v_storeu(op.add(at), o);
        at += per;
    }
    for k in at..n {
        let mut sums = [T::zero(); 2];
        for i in 0..N {
            let c = &codes[i];
            let code = code_at::<TERNARY>(c.bit, c.plus, c.minus.unwrap_or(c.plus), k);
            sums[i % 2] = sums[i % 2] + T::of_f64(code) * amps[i];
        }
        out[k] = out[k] + pw[k] * (sums[0] + sums[1]);
    }
}

/// [`dots_wide`] in 512-bit vectors.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
unsafe fn dots_512<T: Real, const N: usize, const TERNARY: bool>(
    codes: &[Coded<'_>; N],
    y: &[T],
    p: &[T],
) -> [f64; N] {
    dots_wide::<T, T::W512, N, TERNARY>(codes, y, p)
}

/// Σₖ sᵢ(k)·y[k]·p[k] for N voxels of one depth ([`depth_dots_isa`]): the products y·p in
/// `T`, widened to `f64` once for the N voxels and summed there, where each voxel's code is +1
/// (binary codes, with the plain sum kept once: 2·Σ₊ − Σ), or +1 and −1 (ternary: Σ₊ − Σ₋).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn dots_wide<T: Real, S: Simd<T = T>, const N: usize, const TERNARY: bool>(
    codes: &[Coded<'_>; N],
    y: &[T],
    p: &[T],
) -> [f64; N] {
    let per = S::PER;
    let n = y.len();
    let (yp, pp) = (y.as_ptr(), p.as_ptr());
    let plus: [*const u8; N] = std::array::from_fn(|i| codes[i].plus.as_ptr());
    let minus: [*const u8; N] =
        std::array::from_fn(|i| codes[i].minus.unwrap_or(codes[i].plus).as_ptr());
    let mut pos = [S::d_zero(); N];
    let mut neg = [S::d_zero(); N];
    let mut all = S::d_zero();
    let mut at = 0;
    while at + per <= n {
        let w = S::v_mul_add(S::v_loadu(yp.add(at)), S::v_loadu(pp.add(at)), S::v_zero());
        let w = S::d_widen(w);
        if !TERNARY {
            all = S::d_add(all, w);
        }
        for i in 0..N {
            pos[i] = S::d_add_where(S::m_bit(plus[i].add(at), codes[i].bit), pos[i], w);
            if TERNARY {
                neg[i] = S::d_add_where(S::m_bit(minus[i].add(at), codes[i].bit), neg[i], w);
            }
        }
        at += per;
    }
    let all = S::d_sum(all);
    std::array::from_fn(|i| {
        let c = &codes[i];
        let mut sum = if TERNARY {
            S::d_sum(pos[i]) - S::d_sum(neg[i])
        } else {
            2.0 * S::d_sum(pos[i]) - all
        };
        for k in at..n {
            let code = code_at::<TERNARY>(c.bit, c.plus, c.minus.unwrap_or(c.plus), k);
            sum += code * (y[k] * p[k]).as_f64();
        }
        sum
    })
}
