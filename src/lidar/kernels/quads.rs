//! The dense forward with tables that stay in the L1 cache (AVX-512).
//!
//! A group's 256-row table (one row per code byte, 40 kB a group at 40 bins in `f32`) keeps a
//! block's tables in the L2 cache, and a row read at random from L2 costs several times one read
//! from L1. Here each group of eight pixels is split into two *quads* of four pixels, each with a
//! 16-row table (the signed subset sums of its four depth columns), and every sample adds two
//! rows per group: the ones the low and the high four bits of its code byte select. That is
//! twice the rows, but a block of several groups' tables (48 kB) stays in L1, the rows start on
//! cache lines (padded to whole 512-bit vectors), and two samples are summed at once from the
//! same code bytes.

use std::ops::Range;

#[cfg(target_arch = "x86_64")]
use super::wide::{by_vectors, wide_pair, Simd};
use super::{Isa, Lane};
use crate::lidar::codes::GroupBytes;
use crate::real::Real;

/// Rows of a quad's table: one per value of four code bits.
pub(crate) const QUAD_ROWS: usize = 16;

/// Cache budget (bytes) for the quad tables of one block of groups: the L1 data cache of recent
/// AVX-512 CPUs (48 kB), whose other traffic (code bytes, the pulse window, the partial sums)
/// streams through it. On such a CPU 48 kB measured 2–4% faster than 32 kB and than 72 kB; on a
/// CPU with 32 kB of L1 (Zen 4), which reads part of the block from L2, 48 kB was still the
/// fastest of 16, 24, 32 and 48 kB.
pub(crate) const QUAD_BLOCK_BYTES: usize = 48 * 1024;

/// 64 bytes aligned to 64: the storage of the quad tables, so that every row starts on a line.
#[derive(Clone, Copy, Default)]
#[repr(C, align(64))]
pub(crate) struct CacheLine([u64; 8]);

/// Values per quad-table row for a slab of `nch` chunks of eight bins: 8·nch rounded up to whole
/// cache lines (sixteen `f32` or eight `f64` values each).
pub(crate) fn quad_row_len<T>(nch: usize) -> usize {
    let per = 64 / std::mem::size_of::<T>();
    (8 * nch).div_ceil(per) * per
}

/// Values the quad forward reads per row of a slab of `nch` chunks holding `width` bins: the
/// whole row, or all but the second half of its last vector when every bin lies before it.
pub(crate) fn quad_row_read<T>(nch: usize, width: usize) -> usize {
    let (rl, half) = (quad_row_len::<T>(nch), per_vector::<T>() / 2);
    if reads_half(width, rl, half) {
        rl - half
    } else {
        rl
    }
}

/// Whether a row of `rl` values holding `width` bins has none in its last `half` values.
fn reads_half(width: usize, rl: usize, half: usize) -> bool {
    width + half <= rl
}

/// Values of `T` per 512-bit vector (and per cache line).
fn per_vector<T>() -> usize {
    64 / std::mem::size_of::<T>()
}

/// Groups whose quad tables of `max_nch` chunks fit in [`QUAD_BLOCK_BYTES`] (1 to 64).
pub(crate) fn quad_groups_per_block<T>(max_nch: usize) -> usize {
    let group = 2 * QUAD_ROWS * quad_row_len::<T>(max_nch) * std::mem::size_of::<T>();
    (QUAD_BLOCK_BYTES / group).clamp(1, 64)
}

/// Cache lines that hold the quad tables of `groups` groups of `max_nch` chunks.
pub(crate) fn quad_lines<T>(groups: usize, max_nch: usize) -> usize {
    groups * 2 * QUAD_ROWS * quad_row_len::<T>(max_nch) * std::mem::size_of::<T>() / 64
}

/// The values of `lines`, as `T`.
pub(crate) fn lines_as_mut<T: Real>(lines: &mut [CacheLine]) -> &mut [T] {
    let len = lines.len() * 64 / std::mem::size_of::<T>();
    // SAFETY: `T` is `f32` or `f64` (`Real` is sealed): plain data for which every bit pattern
    // is a value, whose alignment divides the lines' 64; the slice covers exactly the lines'
    // bytes and borrows them mutably for its lifetime.
    unsafe { std::slice::from_raw_parts_mut(lines.as_mut_ptr().cast::<T>(), len) }
}

/// Tabulates the quads of `groups` for the slab of bins `j0 ..` (`nch` chunks) of the scene `x`
/// (`npix` pixels of `ks` bins) into `tables`: for group g (counted from the block's first),
/// quad h and four code bits b, the row at `((2g + h)·16 + b)·quad_row_len` holds Σ_i ±x[p_i, j]
/// over the quad's pixels p_i = 8g + 4h + i (+ where bit i of b is set, − elsewhere) for binary
/// codes, or the sum over the set bits only for ternary codes (whose −1 rows are looked up
/// separately). Pixels past `npix` count as zero, and so do the bins past the slab's end.
#[allow(clippy::too_many_arguments)]
pub(crate) fn build_quad_tables<T: Real>(
    x: &[T],
    (npix, ks): (usize, usize),
    binary: bool,
    groups: Range<usize>,
    j0: usize,
    nch: usize,
    tables: &mut [T],
) {
    let rl = quad_row_len::<T>(nch);
    let width = (8 * nch).min(ks - j0);
    let two = T::one() + T::one();
    for (gi, g) in groups.enumerate() {
        for h in 0..2 {
            let t = &mut tables[(2 * gi + h) * QUAD_ROWS * rl..][..QUAD_ROWS * rl];
            let column = |i: usize| {
                let p = 8 * g + 4 * h + i;
                (p < npix).then(|| &x[p * ks + j0..p * ks + j0 + width])
            };
            t[..rl].fill(T::zero());
            if binary {
                for c in (0..4).filter_map(column) {
                    for (r, &v) in t[..width].iter_mut().zip(c) {
                        *r = *r - v;
                    }
                }
            }
            for b in 1..QUAD_ROWS {
                let from = b & (b - 1);
                t.copy_within(from * rl..(from + 1) * rl, b * rl);
                if let Some(c) = column(b.trailing_zeros() as usize) {
                    let row = &mut t[b * rl..b * rl + width];
                    for (r, &v) in row.iter_mut().zip(c) {
                        *r = *r + if binary { two * v } else { v };
                    }
                }
            }
        }
    }
}

/// Everything a block of the quad forward needs.
pub(crate) struct QuadBlock<'a, T> {
    /// The block's quad tables ([`build_quad_tables`]), 64-byte aligned.
    pub tables: &'a [T],
    /// Chunks of eight bins of the slab.
    pub nch: usize,
    /// Bins of the slab (at most 8·nch).
    pub width: usize,
    /// The +1 code bytes of the block's groups, at least `part.len()` each.
    pub plus: GroupBytes<'a>,
    /// The −1 code bytes (ternary codes only).
    pub minus: Option<GroupBytes<'a>>,
    /// Reversed, zero-padded pulse, as in [`FwdBlock`](super::FwdBlock).
    pub prev: &'a [T],
    /// See `prev`.
    pub base0: usize,
}

/// part\[k\] += Σ_j p[k − j]·Σ_g (T_g,lo[b & 15] + T_g,hi[b >> 4])[j] lane by lane, b the code byte
/// of group g at sample k (the +1 rows minus the −1 rows for ternary codes): the forward of one
/// block and slab with the quad tables, on AVX-512 (the kernel is generic over the vector
/// flavour, but the bounds asserted here hold for 512-bit vectors only; compiled for AVX2's
/// 256-bit vectors it measured no faster than the 256-row tables, which AVX2 keeps).
///
/// # Panics
/// If `isa` is not AVX-512 ([`Isa::has_quads`]), or on buffers too short for the block (checked
/// once, before the unchecked loops).
pub(crate) fn quad_forward<T: Real>(isa: Isa, a: &QuadBlock<'_, T>, part: &mut [Lane<T>]) {
    let rl = quad_row_len::<T>(a.nch);
    let n = part.len();
    let (groups, stride) = (a.plus.groups(), a.plus.stride());
    assert!(
        stride >= n
            && a.minus
                .is_none_or(|m| m.groups() == groups && m.stride() == stride),
        "code bytes"
    );
    assert!(a.tables.len() >= groups * 2 * QUAD_ROWS * rl, "tables");
    assert_eq!(a.tables.as_ptr() as usize % 64, 0, "tables' alignment");
    // Every vector of a row holds some of the slab's bins (so that no pointer into the pulse
    // window goes past its end).
    assert!(
        (1..=8).contains(&a.nch) && rl - per_vector::<T>() < a.width,
        "slab"
    );
    assert!(a.width <= 8 * a.nch, "slab");
    assert!(
        n == 0 || (a.base0 + 1 >= n && a.base0 + a.width <= a.prev.len()),
        "pulse"
    );
    #[cfg(target_arch = "x86_64")]
    if isa == Isa::Avx512 {
        let z = rl / <T::W512 as Simd>::PER;
        // SAFETY: `Isa::Avx512` is chosen only on a CPU with AVX-512F, BW, VL and FMA; the
        // assertions above bound every unchecked read (code bytes below `part.len()`, table
        // rows within the block's tables, the pulse window within `prev`).
        unsafe {
            by_vectors!(z, quad_kernel_512::<T>(a, part), [1, 2, 3, 4, 5, 6, 7, 8]);
        }
        return;
    }
    panic!("the quad forward runs on AVX-512 only, not {}", isa.name());
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
unsafe fn quad_kernel_512<T: Real, const Z: usize>(a: &QuadBlock<'_, T>, part: &mut [Lane<T>]) {
    quad_kernel::<T, T::W512, Z>(a, part)
}

/// The samples of [`quad_forward`], two at a time while both samples' sums fit in the registers
/// (always with 512-bit vectors; rows of up to six vectors with 256-bit ones).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn quad_kernel<T: Real, S: Simd<T = T>, const Z: usize>(
    a: &QuadBlock<'_, T>,
    part: &mut [Lane<T>],
) {
    // A last vector whose slab bins all lie in its first half is read as that half.
    if reads_half(a.width, Z * S::PER, S::PER / 2) {
        quad_run::<T, S, Z, true>(a, part);
    } else {
        quad_run::<T, S, Z, false>(a, part);
    }
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn quad_run<T: Real, S: Simd<T = T>, const Z: usize, const HALF: bool>(
    a: &QuadBlock<'_, T>,
    part: &mut [Lane<T>],
) {
    let n = part.len();
    let mut k = 0;
    if 2 * Z + 4 <= S::REGS {
        while k + 2 <= n {
            quad_samples::<T, S, Z, 2, HALF>(a, k, part);
            k += 2;
        }
    }
    while k < n {
        quad_samples::<T, S, Z, 1, HALF>(a, k, part);
        k += 1;
    }
}

/// Samples `k .. k + N` of [`quad_forward`]. While rows are short (up to a quarter of the
/// registers for two samples: four 512-bit vectors, two 256-bit ones) each sample sums its low
/// and its high rows in separate registers, so that two chains of additions run side by side;
/// longer rows share one set, to stay within the vector registers.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
// The accumulators are indexed in step with the vectors' offsets in the rows.
#[allow(clippy::needless_range_loop)]
unsafe fn quad_samples<
    T: Real,
    S: Simd<T = T>,
    const Z: usize,
    const N: usize,
    const HALF: bool,
>(
    a: &QuadBlock<'_, T>,
    k: usize,
    part: &mut [Lane<T>],
) {
    let per = S::PER;
    let rl = Z * per;
    let hi_set = usize::from(8 * Z <= S::REGS);
    let tables = a.tables.as_ptr();
    let mut acc = [[[S::v_zero(); Z]; 2]; N];
    let stride = a.plus.stride();
    let rows = |plane: *const u8, g: usize, s: usize| {
        let b = *plane.add(g * stride + k + s) as usize;
        let base = tables.add(g * 2 * QUAD_ROWS * rl);
        (
            base.add((b & 15) * rl),
            base.add((QUAD_ROWS + (b >> 4)) * rl),
        )
    };
    // The row's `z`-th vector, its first half only for the last one of a `HALF` row.
    let load = |row: *const T, z: usize| {
        if HALF && z == Z - 1 {
            S::v_load_half(row.add(z * per))
        } else {
            S::v_load(row.add(z * per))
        }
    };
    for g in 0..a.plus.groups() {
        for (s, acc) in acc.iter_mut().enumerate() {
            let (lo, hi) = rows(a.plus.as_ptr(), g, s);
            for z in 0..Z {
                acc[0][z] = S::v_add(acc[0][z], load(lo, z));
                acc[hi_set][z] = S::v_add(acc[hi_set][z], load(hi, z));
            }
        }
    }
    if let Some(minus) = a.minus {
        for g in 0..minus.groups() {
            for (s, acc) in acc.iter_mut().enumerate() {
                let (lo, hi) = rows(minus.as_ptr(), g, s);
                for z in 0..Z {
                    acc[0][z] = S::v_sub(acc[0][z], load(lo, z));
                    acc[hi_set][z] = S::v_sub(acc[hi_set][z], load(hi, z));
                }
            }
        }
    }
    for (s, acc) in acc.iter().enumerate() {
        let window = a.prev.as_ptr().add(a.base0 - (k + s));
        let mut sum = S::v_zero();
        for z in 0..Z {
            let v = if hi_set == 1 {
                S::v_add(acc[0][z], acc[1][z])
            } else {
                acc[0][z]
            };
            let w = S::v_load_first(window.add(z * per), a.width.saturating_sub(z * per));
            sum = S::v_mul_add(v, w, sum);
        }
        let lanes = S::v_lanes8(sum);
        let out = part.get_unchecked_mut(k + s);
        for (o, l) in out.iter_mut().zip(lanes) {
            *o = *o + l;
        }
    }
}

/// out[..rl] += Σ of the rows of `table` (rows of `rl` values, a power of two of them) that
/// `index` lists, each index taken modulo the rows, in four interleaved sums of vectors: the wide
/// kernels' memory access and additions without their bookkeeping (the probe of
/// [`gather_limit`](crate::lidar::gather_limit) where the wide kernels run: 512-bit vectors on
/// AVX-512, 256-bit ones on AVX2).
///
/// # Panics
/// If `isa` has no wide kernels ([`Isa::has_wide`]), or on a table that is not a power of two of
/// rows of whole vectors (one to sixteen) starting on a cache line, or `out` shorter than a row.
pub(crate) fn gather_rows_wide<T: Real>(
    isa: Isa,
    rl: usize,
    table: &[T],
    index: &[u16],
    out: &mut [T],
) {
    let per = if isa.has_quads() {
        per_vector::<T>()
    } else {
        per_vector::<T>() / 2
    };
    let z = rl / per;
    assert!(
        z * per == rl && (1..=16).contains(&z) && (isa.has_quads() <= (z <= 8)),
        "row length"
    );
    assert!(
        table.len().is_multiple_of(rl) && (table.len() / rl).is_power_of_two(),
        "rows"
    );
    assert_eq!(table.as_ptr() as usize % 64, 0, "table's alignment");
    assert!(out.len() >= rl, "output");
    let mask = table.len() / rl - 1;
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the instruction set is present (`Isa::chosen`); every row read is `index & mask`
    // < the table's rows, and the sums are written within `out`, as asserted above.
    unsafe {
        match isa {
            Isa::Avx512 => {
                by_vectors!(
                    z,
                    gather_512::<T>(table, mask, index, out),
                    [1, 2, 3, 4, 5, 6, 7, 8]
                );
                return;
            }
            Isa::Avx2 => {
                by_vectors!(
                    z,
                    gather_256::<T>(table, mask, index, out),
                    [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16]
                );
                return;
            }
            Isa::Generic => {}
        }
    }
    let _ = (mask, index, z);
    panic!("the wide probe has no kernel for {}", isa.name());
}

#[cfg(target_arch = "x86_64")]
wide_pair!(gather_512, gather_256, gather_wide<const Z: usize>(
    table: &[T], mask: usize, index: &[u16], out: &mut [T]
));

#[cfg(target_arch = "x86_64")]
#[inline(always)]
// The accumulators are indexed in step with the vectors' offsets in the rows.
#[allow(clippy::needless_range_loop)]
unsafe fn gather_wide<T: Real, S: Simd<T = T>, const Z: usize>(
    table: &[T],
    mask: usize,
    index: &[u16],
    out: &mut [T],
) {
    let per = S::PER;
    let base = table.as_ptr();
    // Up to four interleaved sums, as many as the registers hold with two to spare (all four on
    // AVX-512 for rows of up to seven vectors; on AVX2's sixteen registers fewer for longer rows:
    // two for `f32` rows of five vectors, whose three sets with one register to spare were
    // spilled to memory), so that the sums stay in registers.
    let sets = ((S::REGS - 2) / Z).clamp(1, 4);
    let mut acc = [[S::v_zero(); Z]; 4];
    let add_row = |set: &mut [S::V; Z], r: u16| {
        let row = base.add((r as usize & mask) * Z * per);
        for z in 0..Z {
            set[z] = S::v_add(set[z], S::v_load(row.add(z * per)));
        }
    };
    // `sets` is a constant of the instance, so that the loop over the sets unrolls and every
    // sum is indexed by a constant: the sums then stay in registers. (With the sets taken by a
    // loop of run-time length, they were kept in memory, and the probe measured the stores and
    // loads of its own sums instead of the cache.)
    let mut groups = index.chunks_exact(sets);
    for group in &mut groups {
        for s in 0..sets {
            add_row(&mut acc[s], group[s]);
        }
    }
    for &r in groups.remainder() {
        add_row(&mut acc[0], r);
    }
    let dst = out.as_mut_ptr();
    for z in 0..Z {
        let sum = S::v_add(
            S::v_add(acc[0][z], acc[1][z]),
            S::v_add(acc[2][z], acc[3][z]),
        );
        let d = dst.add(z * per);
        S::v_storeu(d, S::v_add(S::v_loadu(d), sum));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The quad forward of one block against the direct sum Σ_p s_p(k)·Σ_j x[p, j]·p[k − j], for
    /// both alphabets, slabs of one to eight chunks (full, partial, and one that starts at bin
    /// 64), a last group with pixels past the grid and an odd K (a last sample alone).
    fn quad_forward_matches_the_direct_sum<T: Real>(tol: f64) {
        for isa in crate::lidar::kernels::tests::every_isa() {
            if isa.has_quads() {
                quad_forward_on::<T>(isa, tol);
            }
        }
    }

    fn quad_forward_on<T: Real>(isa: Isa, tol: f64) {
        let mut rng = ChaCha8Rng::seed_from_u64(44);
        let (groups, npix, kp) = (3usize, 21usize, 37usize);
        for (ks, j0, nch) in [(5, 0, 1), (21, 0, 3), (40, 0, 5), (64, 0, 8), (70, 64, 1)] {
            let k = kp + ks - 1;
            let x: Vec<T> = (0..npix * ks)
                .map(|_| T::of_f64(rng.random_range(-1.0..1.0)))
                .collect();
            let pulse: Vec<f64> = (0..kp)
                .map(|_| f64::from(rng.random_range(0..2u8)))
                .collect();
            let pad = ks;
            let mut prev = vec![T::zero(); pad + kp + j0 + 8 * nch];
            for (t, &v) in pulse.iter().rev().enumerate() {
                prev[pad + t] = T::of_f64(v);
            }
            let (plus, minus) = crate::lidar::kernels::tests::random_planes(&mut rng, groups, k);
            let (plus_plane, minus_plane) = (plus.concat(), minus.concat());
            let width = (8 * nch).min(ks - j0);
            for ternary in [false, true] {
                let mut lines = vec![CacheLine::default(); quad_lines::<T>(groups, nch)];
                let tables = lines_as_mut::<T>(&mut lines);
                build_quad_tables(&x, (npix, ks), !ternary, 0..groups, j0, nch, tables);
                let block = QuadBlock {
                    tables,
                    nch,
                    width,
                    plus: GroupBytes::new(&plus_plane, k, 0..groups),
                    minus: ternary.then(|| GroupBytes::new(&minus_plane, k, 0..groups)),
                    prev: &prev,
                    base0: pad + kp - 1 + j0,
                };
                let mut part = vec![[T::zero(); 8]; k];
                quad_forward(isa, &block, &mut part);
                for (kk, lanes) in part.iter().enumerate() {
                    let got: f64 = lanes.iter().map(|v| v.as_f64()).sum();
                    let codes = (plus.as_slice(), ternary.then_some(minus.as_slice()));
                    let want = crate::lidar::kernels::tests::direct_forward(
                        &x,
                        (npix, ks),
                        j0..j0 + width,
                        &pulse,
                        codes,
                        kk,
                    );
                    assert!(
                        (got - want).abs() <= tol * (1.0 + want.abs()),
                        "{} {} ks {ks} slab {j0}+{nch} ternary {ternary}: sample {kk}: {got} vs {want}",
                        T::NAME,
                        isa.name()
                    );
                }
            }
        }
    }

    #[test]
    fn quad_forward_matches_the_direct_sum_f32() {
        quad_forward_matches_the_direct_sum::<f32>(1e-4);
    }

    #[test]
    fn quad_forward_matches_the_direct_sum_f64() {
        quad_forward_matches_the_direct_sum::<f64>(1e-12);
    }

    /// The probe's sums of random rows against the direct sums, on every wide instruction set,
    /// for rows of one chunk to the widest and an index count that is not a multiple of four.
    fn gather_rows_wide_sums_the_rows<T: Real>(tol: f64) {
        let mut rng = ChaCha8Rng::seed_from_u64(45);
        for isa in crate::lidar::kernels::tests::every_isa() {
            if !isa.has_wide() {
                continue;
            }
            for nch in 1..=8 {
                let rl = if isa.has_quads() {
                    quad_row_len::<T>(nch)
                } else {
                    8 * nch
                };
                let rows = 16;
                let mut lines =
                    vec![CacheLine::default(); rows * rl * std::mem::size_of::<T>() / 64];
                let table = lines_as_mut::<T>(&mut lines);
                for v in table.iter_mut() {
                    *v = T::of_f64(rng.random_range(-1.0..1.0));
                }
                let index: Vec<u16> = (0..23).map(|_| rng.random_range(0..1000)).collect();
                let mut out = vec![T::one(); rl];
                gather_rows_wide(isa, rl, table, &index, &mut out);
                for (j, o) in out.iter().enumerate() {
                    let want: f64 = 1.0
                        + index
                            .iter()
                            .map(|&r| table[(r as usize % rows) * rl + j].as_f64())
                            .sum::<f64>();
                    assert!(
                        (o.as_f64() - want).abs() <= tol,
                        "{} {} nch {nch} value {j}: {} vs {want}",
                        T::NAME,
                        isa.name(),
                        o.as_f64()
                    );
                }
            }
        }
    }

    #[test]
    fn gather_rows_wide_sums_the_rows_f32() {
        gather_rows_wide_sums_the_rows::<f32>(1e-4);
    }

    #[test]
    fn gather_rows_wide_sums_the_rows_f64() {
        gather_rows_wide_sums_the_rows::<f64>(1e-12);
    }

    #[test]
    fn quad_forward_refuses_other_instruction_sets() {
        let mut lines = vec![CacheLine::default(); quad_lines::<f64>(1, 1)];
        let prev = vec![0.0f64; 16];
        let codes = [0u8; 4];
        let block = QuadBlock {
            tables: lines_as_mut::<f64>(&mut lines),
            nch: 1,
            width: 8,
            plus: GroupBytes::new(&codes, 4, 0..1),
            minus: None,
            prev: &prev,
            base0: 7,
        };
        let mut part = vec![[0.0f64; 8]; 4];
        let run = std::panic::catch_unwind(move || quad_forward(Isa::Generic, &block, &mut part));
        assert!(run.is_err());
    }
}
