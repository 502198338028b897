//! Inner kernels of the fused operator, compiled for several instruction sets and chosen at run
//! time.
//!
//! The kernels work on a *slab* of `8·NCH` consecutive depth bins (NCH ≤ 8, so at most 64 bins
//! at a time). The forward ([`forward_block`]) tabulates the signed subset sums of a block of
//! 8-pixel groups (across the pixels) and adds one row per group and sample; the adjoint
//! ([`adjoint_chunk`]) tabulates the signed subset sums of the rows of a chunk of octets (eight
//! samples each, along the samples) and adds one row per pixel and octet. Both only read their
//! tables, which stay in the L2 cache. Values are held as `[T; 8]` chunks so that the compiler
//! keeps them in vector registers.
//!
//! On AVX-512 the forward uses quad tables that stay in L1 instead ([`quads`]). The adjoint's
//! pixel sums ([`adjoint_wide`]) and the support-restricted kernels ([`support_wide`]) run in
//! 512-bit vectors on AVX-512 and 256-bit ones on AVX2: one generic kernel each, written with the
//! vector operations of [`wide`].

use crate::error::{Error, Result};
use crate::lidar::codes::GroupBytes;
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
                && std::arch::is_x86_feature_detected!("avx512bw")
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

    /// [`Isa::chosen`], or the best of this CPU for a value that names none.
    pub(crate) fn detect() -> Isa {
        Isa::chosen().unwrap_or_else(|_| Isa::best())
    }

    /// Whether the dense forward uses the quad tables ([`quads`]): on AVX-512.
    pub(crate) fn has_quads(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self == Isa::Avx512 {
            return true;
        }
        false
    }

    /// Whether the adjoint ([`adjoint_wide`]) and the support kernels ([`support_wide`]) run in
    /// vectors: 512-bit on AVX-512, 256-bit on AVX2.
    pub(crate) fn has_wide(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self >= Isa::Avx2 {
            return true;
        }
        false
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
    /// The +1 code bytes of the block's groups, at least one per sample of the block.
    pub plus: GroupBytes<'a>,
    /// The −1 code bytes (ternary codes only).
    pub minus: Option<GroupBytes<'a>>,
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
    let (n, stride) = (a.plus.groups(), a.plus.stride());
    // Every row and code byte read below is within bounds: the tables hold 256 rows per group
    // and every group has a code byte per sample of `part`.
    assert!(a.tables.len() >= n * 256 * NCH, "tables");
    assert!(
        stride >= part.len()
            && a.minus
                .is_none_or(|m| m.groups() == n && m.stride() == stride),
        "codes"
    );
    let tables = a.tables.as_ptr();
    for (k, pk) in part.iter_mut().enumerate() {
        // SAFETY: g < n and k < part.len() ≤ stride, so the byte is one of the n groups' bytes,
        // and the row, of the 256 of group g, is within the tables (both asserted above).
        let row = |plane: *const u8, g: usize| unsafe {
            let r = (g * 256 + *plane.add(g * stride + k) as usize) * NCH;
            &*tables.add(r).cast::<[Lane<T>; NCH]>()
        };
        let mut acc = [zero; NCH];
        match a.minus {
            None => {
                for g in 0..n {
                    let row = row(a.plus.as_ptr(), g);
                    for c in 0..NCH {
                        acc[c] = add8(acc[c], row[c]);
                    }
                }
            }
            Some(minus) => {
                for g in 0..n {
                    let (pos, neg) = (row(a.plus.as_ptr(), g), row(minus.as_ptr(), g));
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

/// Everything the adjoint needs for one chunk of octets (eight consecutive samples each) on one
/// depth slab, for the groups of one task.
pub(crate) struct AdjChunk<'a, T> {
    /// The +1 code bytes of the groups, K each.
    pub plus: GroupBytes<'a>,
    /// The −1 code bytes (ternary codes only).
    pub minus: Option<GroupBytes<'a>>,
    /// Measurements.
    pub y: &'a [T],
    /// As in [`FwdBlock`].
    pub prev: &'a [T],
    /// As in [`FwdBlock`].
    pub base0: usize,
    /// The chunk's first octet: the chunk holds samples `8·first_octet` to
    /// `8·(first_octet + ADJ_OCTETS)` (those past K count as zero).
    pub first_octet: usize,
}

/// Transposes an 8×8 bit matrix held as a `u64` (bit i of byte t, i.e. bit 8t + i, goes to bit
/// 8i + t): from one byte per sample with a bit per pixel to one byte per pixel with a bit per
/// sample.
#[inline(always)]
pub(crate) fn transpose8(mut x: u64) -> u64 {
    let t = (x ^ (x >> 7)) & 0x00AA_00AA_00AA_00AA;
    x ^= t ^ (t << 7);
    let t = (x ^ (x >> 14)) & 0x0000_CCCC_0000_CCCC;
    x ^= t ^ (t << 14);
    let t = (x ^ (x >> 28)) & 0x0000_0000_F0F0_F0F0;
    x ^ t ^ (t << 28)
}

/// A group's code bytes for the eight samples of octet `o` (zero past the end), transposed:
/// byte i holds pixel i's codes, bit t for sample 8·o + t.
#[inline(always)]
fn octet_bits(codes: &[u8], o: usize) -> u64 {
    let k = 8 * o;
    let word = match codes.get(k..k + 8) {
        Some(b) => u64::from_le_bytes(b.try_into().expect("8 bytes")),
        None => {
            let mut b = [0u8; 8];
            let rest = &codes[k.min(codes.len())..];
            b[..rest.len()].copy_from_slice(rest);
            u64::from_le_bytes(b)
        }
    };
    transpose8(word)
}

/// Group `g`'s code bits for the chunk's octets, transposed ([`octet_bits`]): the +1 bits into
/// `plus`, and the −1 bits into `minus` for ternary codes. The bytes of group g + 2 are asked
/// for too: consecutive groups' bytes lie K apart, and a group's pixels take longer than the
/// processor looks ahead, so that without the hint each group could wait for its bytes (one
/// build measured twice as slow from it).
#[inline(always)]
fn chunk_bits<T>(
    a: &AdjChunk<'_, T>,
    g: usize,
    plus: &mut [u64; ADJ_OCTETS],
    minus: &mut [u64; ADJ_OCTETS],
) {
    let from = 8 * a.first_octet;
    a.plus.prefetch(g + 2, from);
    if let Some(m) = a.minus {
        m.prefetch(g + 2, from);
    }
    for (oi, b) in plus.iter_mut().enumerate() {
        *b = octet_bits(a.plus.group(g), a.first_octet + oi);
    }
    if let Some(m) = a.minus {
        for (oi, b) in minus.iter_mut().enumerate() {
            *b = octet_bits(m.group(g), a.first_octet + oi);
        }
    }
}

/// Octets per chunk of the adjoint.
pub(crate) const ADJ_OCTETS: usize = 8;

/// Lanes between the tables of successive octets of a chunk: 256 rows and one cache line, so
/// that the same row of successive tables does not fall in the same cache set (a table of
/// 256·NCH lanes is a multiple of 4 KiB).
pub(crate) fn octet_stride<T>(nch: usize) -> usize {
    256 * nch + (64 / std::mem::size_of::<Lane<T>>()).max(1)
}

/// The adjoint of a chunk of octets for a block of groups, added to `out[(g·8 + i)·NCH + c]`
/// (pixel i of group g, chunk c, in `T`; the caller adds these to `f64` sums), from the chunk's
/// tables ([`adjoint_tables`], built once before): each pixel sums one table row per octet, the
/// one its code byte along the samples selects (two for ternary codes: its +1 row minus its −1
/// row). Only reads: the tables are shared by every pixel, and the sum stays in registers.
#[inline(always)]
fn adj_chunk<T: Real, const NCH: usize>(
    a: &AdjChunk<'_, T>,
    tables: &[Lane<T>],
    out: &mut [Lane<T>],
    mut flush: Option<&mut [[f64; 8]]>,
) {
    let zero = [T::zero(); 8];
    let row = |o: usize, b: u64| -> &[Lane<T>; NCH] {
        let r = o * octet_stride::<T>(NCH) + (b & 0xFF) as usize * NCH;
        tables[r..r + NCH].try_into().expect("NCH lanes")
    };
    let (mut bp, mut bm) = ([0u64; ADJ_OCTETS], [0u64; ADJ_OCTETS]);
    for (g, og) in out.chunks_exact_mut(8 * NCH).enumerate() {
        chunk_bits(a, g, &mut bp, &mut bm);
        for (i, oi) in og.chunks_exact_mut(NCH).enumerate() {
            let shift = 8 * i;
            let mut acc = [zero; NCH];
            if a.minus.is_none() {
                for (o, &b) in bp.iter().enumerate() {
                    let r = row(o, b >> shift);
                    for c in 0..NCH {
                        acc[c] = add8(acc[c], r[c]);
                    }
                }
            } else {
                for (o, (&p, &m)) in bp.iter().zip(&bm).enumerate() {
                    let (rp, rm) = (row(o, p >> shift), row(o, m >> shift));
                    for c in 0..NCH {
                        acc[c] = add8(acc[c], sub8(rp[c], rm[c]));
                    }
                }
            }
            for (d, s) in oi.iter_mut().zip(&acc) {
                *d = add8(*d, *s);
            }
        }
        if let Some(f) = flush.as_deref_mut() {
            flush_sums(og, &mut f[g * 8 * NCH..(g + 1) * 8 * NCH]);
        }
    }
}

/// Adds a group's partial sums in `T` to its `f64` sums and clears them: done group by group
/// while they are in the L1 cache, on the chunks that end a run of partial sums.
#[inline(always)]
pub(crate) fn flush_sums<T: Real>(part: &mut [Lane<T>], sums: &mut [[f64; 8]]) {
    for (d, s) in sums.iter_mut().zip(part.iter_mut()) {
        for (dv, sv) in d.iter_mut().zip(s.iter()) {
            *dv += sv.as_f64();
        }
        *s = [T::zero(); 8];
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

/// *out = Σ_k s(k)·y[k]·p[k] for the pixel at bit `bit` of the code bytes (`y`, `p` and the
/// codes aligned on the same window): the restricted adjoint of one voxel in one pass over the
/// codes, the measurements and the pulse. The products are summed in eight lanes of `T` over
/// blocks of 256 and the block sums in `f64`.
#[inline(always)]
fn signed_dot<T: Real>(
    bit: u32,
    plus: &[u8],
    minus: Option<&[u8]>,
    y: &[T],
    p: &[T],
    out: &mut f64,
) {
    let sign = |c: u8, v: T| if (c >> bit) & 1 == 1 { v } else { -v };
    let gate = |c: u8, v: T| if (c >> bit) & 1 == 1 { v } else { T::zero() };
    let mut acc = 0.0f64;
    for (i, (yb, pb)) in y.chunks(256).zip(p.chunks(256)).enumerate() {
        let cb = &plus[256 * i..256 * i + yb.len()];
        let mut lanes = [T::zero(); 8];
        let mut tail = 0.0f64;
        match minus {
            None => {
                let (c8, y8, p8) = (cb.chunks_exact(8), yb.chunks_exact(8), pb.chunks_exact(8));
                for (&c, (&v, &q)) in c8
                    .remainder()
                    .iter()
                    .zip(y8.remainder().iter().zip(p8.remainder()))
                {
                    tail += sign(c, v * q).as_f64();
                }
                for ((c, v), q) in c8.zip(y8).zip(p8) {
                    for l in 0..8 {
                        lanes[l] = lanes[l] + sign(c[l], v[l] * q[l]);
                    }
                }
            }
            Some(minus) => {
                let mb = &minus[256 * i..256 * i + yb.len()];
                let (c8, m8) = (cb.chunks_exact(8), mb.chunks_exact(8));
                let (y8, p8) = (yb.chunks_exact(8), pb.chunks_exact(8));
                for (((&c, &m), &v), &q) in c8
                    .remainder()
                    .iter()
                    .zip(m8.remainder())
                    .zip(y8.remainder())
                    .zip(p8.remainder())
                {
                    tail += (gate(c, v * q) - gate(m, v * q)).as_f64();
                }
                for (((c, m), v), q) in c8.zip(m8).zip(y8).zip(p8) {
                    for l in 0..8 {
                        let w = v[l] * q[l];
                        lanes[l] = lanes[l] + (gate(c[l], w) - gate(m[l], w));
                    }
                }
            }
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
multiversion!(fn adj_chunk_isa<T, const NCH: usize>(a: &AdjChunk<'_, T>, tables: &[Lane<T>], out: &mut [Lane<T>], flush: Option<&mut [[f64; 8]]>) => adj_chunk);
multiversion!(fn sparse_entry_narrow<T>(amp: T, bit: u32, plus: &[u8], minus: Option<&[u8]>, pw: &[T], out: &mut [T]) => sparse_entry);
multiversion!(fn signed_dot_narrow<T>(bit: u32, plus: &[u8], minus: Option<&[u8]>, y: &[T], p: &[T], out: &mut f64) => signed_dot);

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

/// Runs the adjoint's chunk kernel ([`adj_chunk`]) for a slab of `8·nch` bins. With `flush`
/// (one `f64` sum per partial sum of `out`), each group's partial sums are then added to their
/// sums there and cleared ([`flush_sums`]).
pub(crate) fn adjoint_chunk<T: Real>(
    isa: Isa,
    nch: usize,
    a: &AdjChunk<'_, T>,
    tables: &mut [Lane<T>],
    out: &mut [Lane<T>],
    flush: Option<&mut [[f64; 8]]>,
) {
    assert!(flush.as_ref().is_none_or(|f| f.len() == out.len()), "sums");
    adjoint_tables(isa, nch, a, tables, true);
    match nch {
        1 => adj_chunk_isa::<T, 1>(isa, a, tables, out, flush),
        2 => adj_chunk_isa::<T, 2>(isa, a, tables, out, flush),
        3 => adj_chunk_isa::<T, 3>(isa, a, tables, out, flush),
        4 => adj_chunk_isa::<T, 4>(isa, a, tables, out, flush),
        5 => adj_chunk_isa::<T, 5>(isa, a, tables, out, flush),
        6 => adj_chunk_isa::<T, 6>(isa, a, tables, out, flush),
        7 => adj_chunk_isa::<T, 7>(isa, a, tables, out, flush),
        8 => adj_chunk_isa::<T, 8>(isa, a, tables, out, flush),
        _ => unreachable!("slabs have 1 to 8 chunks"),
    }
}

pub(crate) mod adjoint_wide;
mod probe;
pub(crate) mod quads;
pub(crate) mod support_wide;
pub(crate) mod tables;
pub(crate) use tables::adjoint_tables;
#[cfg(test)]
mod tests;
/// The vector flavours of the scalars, from the ground floor.
pub(crate) use crate::simd as wide;

pub(crate) use probe::gather_rows;
pub(crate) use support_wide::{
    depth_dots_isa, depth_entries_isa, depth_schedule, flush_into, Coded,
};
