//! Inner kernels of the fused operator, compiled for several instruction sets and chosen at run
//! time.
//!
//! The kernels work on a *slab* of `8·NCH` consecutive depth bins (NCH ≤ 8, so at most 64 bins
//! at a time) and on a *block* of 8-pixel groups whose tables (forward) or buckets (adjoint) fit
//! in the L2 cache. Values are held as `[T; 8]` chunks so that the compiler keeps them in vector
//! registers.
//!
//! The adjoint ([`adjoint_slab`]) is bound by the read-modify-write of one random bucket row per
//! group and sample; the rest (the row y[k]·p[k − j], the reduction of the buckets to per-pixel
//! sums every [`FLUSH`] samples) is shared by the groups of a block or done once per window.

use crate::error::{Error, Result};
use crate::real::Real;

/// A chunk of eight lanes.
pub(crate) type Lane<T> = [T; 8];

/// The environment variable that caps the instruction set of the fused operator's kernels:
/// `generic`, `avx2` or `avx512` (or `native`, the default: the best this CPU has). A set the CPU
/// lacks gives the best one below it, so that one machine can measure every path.
pub const ISA_VAR: &str = "RDLIDAR_ISA";

/// Instruction sets the kernels are compiled for, in increasing order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Isa {
    Generic,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Isa {
    /// The best instruction set of this CPU.
    fn best() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vl")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Isa::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Isa::Avx2;
            }
        }
        Isa::Generic
    }

    /// The instruction set the kernels run with: the best of this CPU, capped by
    /// [`ISA_VAR`].
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`RDLIDAR_ISA`) for a value that names no instruction set.
    pub(crate) fn chosen() -> Result<Isa> {
        let best = Isa::best();
        let Some(value) = std::env::var_os(ISA_VAR) else {
            return Ok(best);
        };
        let text = value.to_string_lossy().trim().to_ascii_lowercase();
        let cap = match text.as_str() {
            "" | "native" => return Ok(best),
            "generic" => Isa::Generic,
            #[cfg(target_arch = "x86_64")]
            "avx2" | "avx2+fma" => Isa::Avx2,
            #[cfg(target_arch = "x86_64")]
            "avx512" => Isa::Avx512,
            #[cfg(not(target_arch = "x86_64"))]
            "avx2" | "avx2+fma" | "avx512" => Isa::Generic,
            _ => {
                return Err(Error::param(
                    "RDLIDAR_ISA",
                    format!(
                        "`{}` names no instruction set of the kernels: use generic, avx2, \
                         avx512 or native",
                        value.to_string_lossy().escape_debug()
                    ),
                ))
            }
        };
        Ok(best.min(cap))
    }

    /// The variant of the adjoint's bucket kernel ([`adjoint_slab`]) to run under this set: the
    /// AVX2 one on AVX-512 machines. Its read-modify-write of one random bucket row per group
    /// and sample gains nothing from 512-bit registers: on an AVX-512 Xeon the AVX2 variant
    /// measured 1.15–1.24 times faster (100×100×40, K_p = 10000 and 30000, f32 and f64,
    /// `rdlidar bench`), the forward product unchanged.
    pub(crate) fn for_adjoint(self) -> Isa {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => Isa::Avx2,
            other => other,
        }
    }

    /// [`Isa::chosen`], or the best of this CPU for a value that names none.
    pub(crate) fn detect() -> Isa {
        Isa::chosen().unwrap_or_else(|_| Isa::best())
    }

    pub(crate) fn name(self) -> &'static str {
        match self {
            Isa::Generic => "generic",
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => "avx2+fma",
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => "avx512",
        }
    }
}

#[inline(always)]
fn add8<T: Real>(a: Lane<T>, b: Lane<T>) -> Lane<T> {
    [
        a[0] + b[0],
        a[1] + b[1],
        a[2] + b[2],
        a[3] + b[3],
        a[4] + b[4],
        a[5] + b[5],
        a[6] + b[6],
        a[7] + b[7],
    ]
}

#[inline(always)]
fn sub8<T: Real>(a: Lane<T>, b: Lane<T>) -> Lane<T> {
    [
        a[0] - b[0],
        a[1] - b[1],
        a[2] - b[2],
        a[3] - b[3],
        a[4] - b[4],
        a[5] - b[5],
        a[6] - b[6],
        a[7] - b[7],
    ]
}

/// a·b + c, lane by lane.
#[inline(always)]
fn mul_add8<T: Real>(a: Lane<T>, b: Lane<T>, c: Lane<T>) -> Lane<T> {
    [
        a[0] * b[0] + c[0],
        a[1] * b[1] + c[1],
        a[2] * b[2] + c[2],
        a[3] * b[3] + c[3],
        a[4] * b[4] + c[4],
        a[5] * b[5] + c[5],
        a[6] * b[6] + c[6],
        a[7] * b[7] + c[7],
    ]
}

#[inline(always)]
fn scale8<T: Real>(a: T, b: Lane<T>) -> Lane<T> {
    [
        a * b[0],
        a * b[1],
        a * b[2],
        a * b[3],
        a * b[4],
        a * b[5],
        a * b[6],
        a * b[7],
    ]
}

#[inline(always)]
fn lane_at<T: Real>(v: &[T], at: usize) -> Lane<T> {
    v[at..at + 8].try_into().expect("8 lanes")
}

/// Everything a forward block needs.
pub(crate) struct FwdBlock<'a, T> {
    /// `groups × 256 × NCH` lanes: the signed subset sums of each group (binary codes), or the
    /// plain subset sums (ternary codes).
    pub tables: &'a [Lane<T>],
    /// The +1 code bytes of each group of the block, K each.
    pub plus: &'a [&'a [u8]],
    /// The −1 code bytes (ternary codes only).
    pub minus: Option<&'a [&'a [u8]]>,
    /// Reversed, zero-padded pulse: p[k − j] = `prev[base0 − k + (j − j0)]` for the slab's bins.
    pub prev: &'a [T],
    /// See `prev`.
    pub base0: usize,
}

/// part[k] += Σ_c p[k−j]·Σ_g T_g[code_g(k)][j] lane by lane (j = 8c + lane), for every k; the
/// eight lanes of `part[k]` are summed into y[k] by the caller.
#[inline(always)]
fn fwd_block<T: Real, const NCH: usize>(a: &FwdBlock<'_, T>, part: &mut [Lane<T>]) {
    let zero = [T::zero(); 8];
    for (k, pk) in part.iter_mut().enumerate() {
        let mut acc = [zero; NCH];
        match a.minus {
            None => {
                for (g, codes) in a.plus.iter().enumerate() {
                    let r = (g * 256 + codes[k] as usize) * NCH;
                    let row: &[Lane<T>; NCH] = a.tables[r..r + NCH].try_into().expect("NCH lanes");
                    for c in 0..NCH {
                        acc[c] = add8(acc[c], row[c]);
                    }
                }
            }
            Some(minus) => {
                for (g, (cp, cm)) in a.plus.iter().zip(minus).enumerate() {
                    let rp = (g * 256 + cp[k] as usize) * NCH;
                    let rm = (g * 256 + cm[k] as usize) * NCH;
                    let pos: &[Lane<T>; NCH] =
                        a.tables[rp..rp + NCH].try_into().expect("NCH lanes");
                    let neg: &[Lane<T>; NCH] =
                        a.tables[rm..rm + NCH].try_into().expect("NCH lanes");
                    for c in 0..NCH {
                        acc[c] = add8(acc[c], sub8(pos[c], neg[c]));
                    }
                }
            }
        }
        let w0 = a.base0 - k;
        let mut s = *pk;
        for (c, ac) in acc.iter().enumerate() {
            s = mul_add8(*ac, lane_at(a.prev, w0 + 8 * c), s);
        }
        *pk = s;
    }
}

/// One adjoint bucket: a slab's `NCH` lanes, aligned to 32 bytes so that no 256-bit half of a
/// lane straddles two cache lines (the allocator alone guarantees only the element's alignment,
/// and a split access costs about twice as much in this update-bound loop).
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct Row<T, const NCH: usize>([Lane<T>; NCH]);

/// Bytes of one adjoint bucket of `nch` chunks of `T` (see [`adjoint_slab`]).
pub(crate) fn adj_row_bytes<T>(nch: usize) -> usize {
    (8 * nch * std::mem::size_of::<T>()).next_multiple_of(32)
}

/// Everything the adjoint needs for one block of groups and one depth slab.
pub(crate) struct AdjSlab<'a, T> {
    /// The code bytes, K per stream: the +1 bytes of each group (binary codes), or the +1 and the
    /// −1 bytes of each group in turn (ternary codes).
    pub streams: &'a [&'a [u8]],
    /// Whether the streams come in (+1, −1) pairs.
    pub ternary: bool,
    /// Measurements.
    pub y: &'a [T],
    /// As in [`FwdBlock`].
    pub prev: &'a [T],
    /// As in [`FwdBlock`].
    pub base0: usize,
}

/// Samples accumulated in the working precision before the buckets are reduced and added to
/// `f64` sums: about 64 additions per bucket.
pub(crate) const FLUSH: usize = 16384;

/// For k in `k0..k1`: bucket[s][code_s(k)] += y[k]·p[k−j] for every stream s.
#[inline(always)]
fn adj_accumulate<T: Real, const NCH: usize>(
    a: &AdjSlab<'_, T>,
    k0: usize,
    k1: usize,
    buckets: &mut [Row<T, NCH>],
) {
    // Fixed-size tables: a code byte indexes them without a bounds check.
    let mut tabs: Vec<(&[u8], &mut [Row<T, NCH>; 256])> = a
        .streams
        .iter()
        .zip(buckets.chunks_exact_mut(256))
        .map(|(s, b)| (&s[k0..k1], b.try_into().expect("256 buckets")))
        .collect();
    for (i, &yk) in a.y[k0..k1].iter().enumerate() {
        if yk == T::zero() {
            continue;
        }
        let w0 = a.base0 - (k0 + i);
        let w: [Lane<T>; NCH] = std::array::from_fn(|c| scale8(yk, lane_at(a.prev, w0 + 8 * c)));
        for (codes, tab) in tabs.iter_mut() {
            let row = &mut tab[codes[i] as usize].0;
            for c in 0..NCH {
                row[c] = add8(row[c], w[c]);
            }
        }
    }
}

/// Per-bit marginals of one stream's 256 buckets U[b]: adds S_i = Σ_{b: bit i set} U[b] to
/// `sums[i]` (i < 8) and Σ_b U[b] to `sums[8]`, in `f64`, then clears the buckets.
///
/// Successive halving: the upper half of the rows (bit 7 set) is summed into S_7 and folded onto
/// the lower half, which leaves the 128 buckets of the remaining seven bits; and so on down to
/// bit 0. That is 2·255 row additions instead of 256·(1 + popcount) for the direct sums, and each
/// result is a sum over a balanced tree of buckets.
#[inline(always)]
fn adj_marginals<T: Real, const NCH: usize>(
    rows: &mut [Row<T, NCH>],
    sums: &mut [[Lane<f64>; NCH]; 9],
) {
    let zero = [T::zero(); 8];
    let mut n = rows.len();
    for bit in (0..8).rev() {
        let half = n / 2;
        let (lo, hi) = rows[..n].split_at_mut(half);
        // Four interleaved partial sums, for instruction-level parallelism and a shorter chain.
        let mut acc = [[zero; NCH]; 4];
        for (lc, hc) in lo.chunks_mut(4).zip(hi.chunks(4)) {
            for ((l, h), a) in lc.iter_mut().zip(hc).zip(acc.iter_mut()) {
                for ((lv, hv), av) in l.0.iter_mut().zip(&h.0).zip(a.iter_mut()) {
                    *av = add8(*av, *hv);
                    *lv = add8(*lv, *hv);
                }
            }
        }
        let s: [Lane<T>; NCH] =
            std::array::from_fn(|c| add8(add8(acc[0][c], acc[1][c]), add8(acc[2][c], acc[3][c])));
        widen_add(&mut sums[bit], &s);
        n = half;
    }
    widen_add(&mut sums[8], &rows[0].0);
    rows.fill(Row([zero; NCH]));
}

/// dst += src, widened to `f64`.
#[inline(always)]
fn widen_add<T: Real, const NCH: usize>(dst: &mut [Lane<f64>; NCH], src: &[Lane<T>; NCH]) {
    for (d, s) in dst.iter_mut().zip(src) {
        for (dv, sv) in d.iter_mut().zip(s) {
            *dv += sv.as_f64();
        }
    }
}

/// The adjoint of one block of groups on a slab of `8·NCH` bins: `out[(g·8 + i)·NCH + c]` is the
/// backprojection of pixel i of group g on chunk c, in `f64`.
///
/// For every sample, the row w = y[k]·p[k − j] is added to one of 256 buckets per stream,
/// selected by the stream's code byte. Every [`FLUSH`] samples the buckets are reduced to their
/// per-bit marginals S_i and total U in `T` (see [`adj_marginals`]) and these are added up in
/// `f64`. Pixel i of a group then gets 2·S_i − U (binary codes: +1 where its bit is set, −1
/// elsewhere) or S_i⁺ − S_i⁻ (ternary codes).
#[inline(always)]
fn adj_slab<T: Real, const NCH: usize>(a: &AdjSlab<'_, T>, out: &mut [Lane<f64>]) {
    let ns = a.streams.len();
    let mut buckets = vec![Row([[T::zero(); 8]; NCH]); ns * 256];
    let mut sums = vec![[[[0.0f64; 8]; NCH]; 9]; ns];
    let k = a.y.len();
    let mut k0 = 0;
    while k0 < k {
        let k1 = (k0 + FLUSH).min(k);
        adj_accumulate::<T, NCH>(a, k0, k1, &mut buckets);
        for (rows, s) in buckets.chunks_exact_mut(256).zip(sums.iter_mut()) {
            adj_marginals(rows, s);
        }
        k0 = k1;
    }
    let per_group = if a.ternary { 2 } else { 1 };
    for (sg, og) in sums
        .chunks_exact(per_group)
        .zip(out.chunks_exact_mut(8 * NCH))
    {
        for (i, oi) in og.chunks_exact_mut(NCH).enumerate() {
            for (c, o) in oi.iter_mut().enumerate() {
                for l in 0..8 {
                    o[l] = if a.ternary {
                        sg[0][i][c][l] - sg[1][i][c][l]
                    } else {
                        2.0 * sg[0][i][c][l] - sg[0][8][c][l]
                    };
                }
            }
        }
    }
}

/// y[k − k0] += a·p[k − j]·s(k) for k in the entry's range: one sparse entry of the forward.
/// `codes` are the entry's group bytes from `k_lo`, `pw` the pulse from `k_lo − j`.
#[inline(always)]
fn sparse_entry<T: Real>(
    amp: T,
    bit: u32,
    plus: &[u8],
    minus: Option<&[u8]>,
    pw: &[T],
    out: &mut [T],
) {
    match minus {
        None => {
            for ((o, &c), &p) in out.iter_mut().zip(plus).zip(pw) {
                let v = amp * p;
                *o = *o + if (c >> bit) & 1 == 1 { v } else { -v };
            }
        }
        Some(minus) => {
            for (((o, &cp), &cm), &p) in out.iter_mut().zip(plus).zip(minus).zip(pw) {
                let v = amp * p;
                let s = ((cp >> bit) & 1) as i32 - ((cm >> bit) & 1) as i32;
                *o = *o
                    + if s > 0 {
                        v
                    } else if s < 0 {
                        -v
                    } else {
                        T::zero()
                    };
            }
        }
    }
}

/// z[k] = s[k]·y[k] for the pixel at bit `bit` of the code bytes: its codes applied to the
/// measurements, decoded branch-free so that the loop vectorizes.
#[inline(always)]
fn signed_copy<T: Real>(bit: u32, plus: &[u8], minus: Option<&[u8]>, y: &[T], z: &mut [T]) {
    match minus {
        None => {
            for ((o, &c), &v) in z.iter_mut().zip(plus).zip(y) {
                *o = if (c >> bit) & 1 == 1 { v } else { -v };
            }
        }
        Some(minus) => {
            for (((o, &cp), &cm), &v) in z.iter_mut().zip(plus).zip(minus).zip(y) {
                let a = if (cp >> bit) & 1 == 1 { v } else { T::zero() };
                let b = if (cm >> bit) & 1 == 1 { v } else { T::zero() };
                *o = a - b;
            }
        }
    }
}

/// *out = Σ a[i]·b[i]: eight lanes summed in `T` over blocks of 256 products, the block sums
/// added in `f64`.
#[inline(always)]
fn lane_dot<T: Real>(a: &[T], b: &[T], out: &mut f64) {
    let mut acc = 0.0f64;
    for (ab, bb) in a.chunks(256).zip(b.chunks(256)) {
        let mut lanes = [T::zero(); 8];
        let (ac, bc) = (ab.chunks_exact(8), bb.chunks_exact(8));
        let (ar, br) = (ac.remainder(), bc.remainder());
        for (x, y) in ac.zip(bc) {
            for l in 0..8 {
                lanes[l] = lanes[l] + x[l] * y[l];
            }
        }
        let mut tail = 0.0f64;
        for (x, y) in ar.iter().zip(br) {
            tail += x.as_f64() * y.as_f64();
        }
        acc += lanes.iter().map(|v| v.as_f64()).sum::<f64>() + tail;
    }
    *out = acc;
}

macro_rules! multiversion {
    ($vis:vis fn $name:ident < $t:ident $(, const $c:ident : usize)? > ( $($arg:ident : $ty:ty),* ) => $inner:ident) => {
        $vis fn $name<$t: Real $(, const $c: usize)?>(isa: Isa, $($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2,fma")]
                fn avx2<$t: Real $(, const $c: usize)?>($($arg: $ty),*) {
                    $inner::<$t $(, $c)?>($($arg),*)
                }
                #[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
                fn avx512<$t: Real $(, const $c: usize)?>($($arg: $ty),*) {
                    $inner::<$t $(, $c)?>($($arg),*)
                }
                match isa {
                    // SAFETY: `Isa::chosen` returns these variants only after checking that the
                    // CPU supports every feature the function is compiled with.
                    Isa::Avx512 => return unsafe { avx512::<$t $(, $c)?>($($arg),*) },
                    Isa::Avx2 => return unsafe { avx2::<$t $(, $c)?>($($arg),*) },
                    Isa::Generic => {}
                }
            }
            let _ = isa;
            $inner::<$t $(, $c)?>($($arg),*)
        }
    };
}

multiversion!(fn fwd_block_isa<T, const NCH: usize>(a: &FwdBlock<'_, T>, part: &mut [Lane<T>]) => fwd_block);
multiversion!(fn adj_slab_isa<T, const NCH: usize>(a: &AdjSlab<'_, T>, out: &mut [Lane<f64>]) => adj_slab);
multiversion!(pub(crate) fn sparse_entry_isa<T>(amp: T, bit: u32, plus: &[u8], minus: Option<&[u8]>, pw: &[T], out: &mut [T]) => sparse_entry);
multiversion!(pub(crate) fn signed_copy_isa<T>(bit: u32, plus: &[u8], minus: Option<&[u8]>, y: &[T], z: &mut [T]) => signed_copy);
multiversion!(pub(crate) fn lane_dot_isa<T>(a: &[T], b: &[T], out: &mut f64) => lane_dot);

/// Runs the forward block kernel for a slab of `8·nch` bins.
pub(crate) fn forward_block<T: Real>(
    isa: Isa,
    nch: usize,
    a: &FwdBlock<'_, T>,
    part: &mut [Lane<T>],
) {
    match nch {
        1 => fwd_block_isa::<T, 1>(isa, a, part),
        2 => fwd_block_isa::<T, 2>(isa, a, part),
        3 => fwd_block_isa::<T, 3>(isa, a, part),
        4 => fwd_block_isa::<T, 4>(isa, a, part),
        5 => fwd_block_isa::<T, 5>(isa, a, part),
        6 => fwd_block_isa::<T, 6>(isa, a, part),
        7 => fwd_block_isa::<T, 7>(isa, a, part),
        8 => fwd_block_isa::<T, 8>(isa, a, part),
        _ => unreachable!("slabs have 1 to 8 chunks"),
    }
}

/// Runs the adjoint kernel ([`adj_slab`]) for a block of groups and a slab of `8·nch` bins:
/// `out` receives `8·nch` lanes per group.
pub(crate) fn adjoint_slab<T: Real>(
    isa: Isa,
    nch: usize,
    a: &AdjSlab<'_, T>,
    out: &mut [Lane<f64>],
) {
    match nch {
        1 => adj_slab_isa::<T, 1>(isa, a, out),
        2 => adj_slab_isa::<T, 2>(isa, a, out),
        3 => adj_slab_isa::<T, 3>(isa, a, out),
        4 => adj_slab_isa::<T, 4>(isa, a, out),
        5 => adj_slab_isa::<T, 5>(isa, a, out),
        6 => adj_slab_isa::<T, 6>(isa, a, out),
        7 => adj_slab_isa::<T, 7>(isa, a, out),
        8 => adj_slab_isa::<T, 8>(isa, a, out),
        _ => unreachable!("slabs have 1 to 8 chunks"),
    }
}
