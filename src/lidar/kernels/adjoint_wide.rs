//! The adjoint's per-pixel sums in vectors: 512-bit on AVX-512, 256-bit on AVX2.
//!
//! The chunk's tables are those of the generic kernel ([`adjoint_tables`]); on AVX-512 their
//! rows are widened to whole vectors (an even number of chunks of eight `f32` values) and start on
//! cache lines (on AVX2 on 32-byte boundaries, all that its vectors need), except `f32` rows on
//! processors that execute 512-bit operations in halves, which the AVX2 kernel reads at the
//! slab's width ([`narrow_f32_rows`]). Each pixel then adds its eight rows (one per octet) in
//! vectors of sixteen `f32` or eight `f64` values (eight or four on AVX2) instead of chunks of
//! eight, in the same order, lane by lane, as the generic kernel: the sums are the same to the
//! last bit, also where the 256-bit kernel reads binary codes' `f32` rows below 128 only and
//! adds row ¬b by a fused multiply-add by −1 ([`symmetric_rows`]). The partial sums hold the
//! slab's bins only, and where the processor has GFNI a group's code bytes of a chunk are
//! transposed in vectors (the same bits as the generic kernel's scalar transposes).

#[cfg(target_arch = "x86_64")]
use super::chunk_bits;
use super::wide::Wide;
#[cfg(target_arch = "x86_64")]
use super::wide::{wide_pair, Simd};
use super::{adjoint_tables, octet_stride, AdjChunk, Isa, Lane, ADJ_OCTETS};
use crate::real::Real;

/// Chunks of eight values per row of the wide adjoint's tables on AVX-512 for a slab of `nch`
/// chunks: whole 512-bit vectors (an even number for `f32`). The widest rows of any instruction
/// set.
pub(crate) fn wide_adjoint_nch<T: Real>(nch: usize) -> usize {
    let per_vector = <T as Wide>::PER / 8;
    nch.div_ceil(per_vector) * per_vector
}

/// Chunks of eight values per row of whole vectors on `isa`: 512-bit vectors on AVX-512
/// ([`wide_adjoint_nch`]); on AVX2 a chunk is a whole 256-bit vector of `f32` and two of `f64`,
/// and generic rows are chunks.
pub(crate) fn vector_row_nch<T: Real>(isa: Isa, nch: usize) -> usize {
    #[cfg(target_arch = "x86_64")]
    if isa == Isa::Avx512 {
        return wide_adjoint_nch::<T>(nch);
    }
    let _ = isa;
    nch
}

/// Chunks of eight values per row of the adjoint's tables on `isa`: whole vectors
/// ([`vector_row_nch`]), but the slab's chunks for `f32` where [`narrow_f32_rows`].
pub(crate) fn adjoint_row_nch<T: Real>(isa: Isa, nch: usize) -> usize {
    if <T as Wide>::PER == 16 && narrow_f32_rows() {
        return nch;
    }
    vector_row_nch::<T>(isa, nch)
}

/// Whether the AVX-512 adjoint reads `f32` rows of the slab's width in 256-bit vectors (the
/// AVX2 kernel) rather than rows widened to whole 512-bit vectors: on AMD's family 19h (Zen 4),
/// which executes a 512-bit operation as two 256-bit halves and loads 64 bytes a cycle as two
/// 256-bit loads, the narrower rows (40 values at 40 bins instead of 48, no load across a cache
/// line) are the faster. Rows of `f64` are whole 512-bit vectors either way. The sums are the
/// same to the last bit on both kernels.
pub(crate) fn narrow_f32_rows() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static NARROW: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *NARROW.get_or_init(|| {
            use std::arch::x86_64::__cpuid;
            let (vendor, signature) = (__cpuid(0), __cpuid(1));
            let amd =
                (vendor.ebx, vendor.edx, vendor.ecx) == (0x6874_7541, 0x6974_6E65, 0x444D_4163);
            let base = (signature.eax >> 8) & 0xF;
            let family = if base == 0xF {
                base + ((signature.eax >> 20) & 0xFF)
            } else {
                base
            };
            amd && family == 0x19
        })
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Whether the wide adjoint's `kernel` reads binary codes' rows below 128 only: the 256-bit
/// kernel in `f32`. A code byte b of 128 or more selects row ¬b instead, added with a fused
/// multiply-add by −1 (row ¬b is −row b exactly, [`adjoint_tables`]; the product by ±1 is exact
/// and the sum rounds once, as an addition does): the same sums from half the table bytes, so
/// that more of the rows a chunk reads stay in L1, and on the multiply-add units. On the Zen 4
/// the `f32` adjoint took 0.91 of its time reading all 256 rows; the other kernels are
/// unmeasured so.
pub(crate) fn symmetric_rows<T: Real>(kernel: Isa) -> bool {
    kernel == Isa::Avx2 && <T as Wide>::PER == 16
}

/// [`adjoint_chunk`](super::adjoint_chunk) in vectors for rows of `nch` chunks (the slab's
/// `slab_nch`, or whole vectors, [`vector_row_nch`]; [`adjoint_row_nch`] chooses), and sums of
/// the slab's `slab_nch` chunks: the chunk's tables into `tables` (64-byte aligned), each
/// pixel's sum added to `out[(g·8 + i)·slab_nch ..]`, and with `flush` each group's partial sums
/// then added to their `f64` sums there and cleared ([`flush_sums`](super::flush_sums)). The
/// sums hold only the slab's bins: where the rows were widened by a chunk (`f32` on AVX-512, an
/// odd `slab_nch`), the last vector's second half is not added, so the partial sums take a sixth
/// less of the cache at 40 bins.
///
/// # Panics
/// If `isa` has no wide kernels ([`Isa::has_wide`]), `nch` is neither width, or the buffers are
/// too short (checked before the unchecked loops).
pub(crate) fn adjoint_chunk_wide<T: Real>(
    isa: Isa,
    nch: usize,
    slab_nch: usize,
    a: &AdjChunk<'_, T>,
    tables: &mut [Lane<T>],
    out: &mut [Lane<T>],
    flush: Option<&mut [[f64; 8]]>,
) {
    assert!(
        (1..=8).contains(&slab_nch)
            && (nch == slab_nch || nch == vector_row_nch::<T>(isa, slab_nch)),
        "row width"
    );
    assert!(
        tables.len() >= ADJ_OCTETS * octet_stride::<T>(nch),
        "tables"
    );
    assert_eq!(tables.as_ptr() as usize % 64, 0, "tables' alignment");
    assert_eq!(out.len(), a.plus.groups() * 8 * slab_nch, "partial sums");
    assert!(flush.as_ref().is_none_or(|f| f.len() == out.len()), "sums");
    assert!(
        a.minus.is_none_or(|m| m.groups() == a.plus.groups()),
        "code planes"
    );
    // The 256-bit kernel reads binary codes' `f32` rows below 128 only ([`symmetric_rows`]).
    let odd_f32 = isa == Isa::Avx512 && <T as Wide>::PER == 16 && nch % 2 == 1;
    let kernel = if odd_f32 { Isa::Avx2 } else { isa };
    let symmetric = a.minus.is_none() && symmetric_rows::<T>(kernel);
    adjoint_tables(isa, nch, a, tables, !symmetric);
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `Isa::Avx512` is chosen only on a CPU with AVX-512F, BW, VL and FMA, and
    // `Isa::Avx2` on one with AVX2 and FMA; the rows read are within the chunk's tables (a code
    // byte selects one of 256 rows of an octet's table) and the sums written are within `out`,
    // as asserted above.
    unsafe {
        // On AVX-512, rows of `f32` that are not whole 512-bit vectors are read by the AVX2
        // kernel ([`narrow_f32_rows`]).
        match (kernel, nch, <T as Wide>::PER) {
            // Rows of `f32` on AVX-512 are whole 512-bit vectors; an odd slab's sums end in half
            // of one.
            (Isa::Avx512, 2, 16) if slab_nch == 1 => {
                adj_512::<T, 2, 1, true>(a, tables, out, flush)
            }
            (Isa::Avx512, 4, 16) if slab_nch == 3 => {
                adj_512::<T, 4, 2, true>(a, tables, out, flush)
            }
            (Isa::Avx512, 6, 16) if slab_nch == 5 => {
                adj_512::<T, 6, 3, true>(a, tables, out, flush)
            }
            (Isa::Avx512, 8, 16) if slab_nch == 7 => {
                adj_512::<T, 8, 4, true>(a, tables, out, flush)
            }
            (Isa::Avx512, 2, 16) => adj_512::<T, 2, 1, false>(a, tables, out, flush),
            (Isa::Avx512, 4, 16) => adj_512::<T, 4, 2, false>(a, tables, out, flush),
            (Isa::Avx512, 6, 16) => adj_512::<T, 6, 3, false>(a, tables, out, flush),
            (Isa::Avx512, 8, 16) => adj_512::<T, 8, 4, false>(a, tables, out, flush),
            (Isa::Avx512, 1, 8) => adj_512::<T, 1, 1, false>(a, tables, out, flush),
            (Isa::Avx512, 2, 8) => adj_512::<T, 2, 2, false>(a, tables, out, flush),
            (Isa::Avx512, 3, 8) => adj_512::<T, 3, 3, false>(a, tables, out, flush),
            (Isa::Avx512, 4, 8) => adj_512::<T, 4, 4, false>(a, tables, out, flush),
            (Isa::Avx512, 5, 8) => adj_512::<T, 5, 5, false>(a, tables, out, flush),
            (Isa::Avx512, 6, 8) => adj_512::<T, 6, 6, false>(a, tables, out, flush),
            (Isa::Avx512, 7, 8) => adj_512::<T, 7, 7, false>(a, tables, out, flush),
            (Isa::Avx512, 8, 8) => adj_512::<T, 8, 8, false>(a, tables, out, flush),
            // On AVX2 a chunk is one vector of `f32`, two of `f64`.
            (Isa::Avx2, 1, 16) => adj_256::<T, 1, 1, false>(a, tables, out, flush),
            (Isa::Avx2, 2, 16) => adj_256::<T, 2, 2, false>(a, tables, out, flush),
            (Isa::Avx2, 3, 16) => adj_256::<T, 3, 3, false>(a, tables, out, flush),
            (Isa::Avx2, 4, 16) => adj_256::<T, 4, 4, false>(a, tables, out, flush),
            (Isa::Avx2, 5, 16) => adj_256::<T, 5, 5, false>(a, tables, out, flush),
            (Isa::Avx2, 6, 16) => adj_256::<T, 6, 6, false>(a, tables, out, flush),
            (Isa::Avx2, 7, 16) => adj_256::<T, 7, 7, false>(a, tables, out, flush),
            (Isa::Avx2, 8, 16) => adj_256::<T, 8, 8, false>(a, tables, out, flush),
            (Isa::Avx2, 1, 8) => adj_256::<T, 1, 2, false>(a, tables, out, flush),
            (Isa::Avx2, 2, 8) => adj_256::<T, 2, 4, false>(a, tables, out, flush),
            (Isa::Avx2, 3, 8) => adj_256::<T, 3, 6, false>(a, tables, out, flush),
            (Isa::Avx2, 4, 8) => adj_256::<T, 4, 8, false>(a, tables, out, flush),
            (Isa::Avx2, 5, 8) => adj_256::<T, 5, 10, false>(a, tables, out, flush),
            (Isa::Avx2, 6, 8) => adj_256::<T, 6, 12, false>(a, tables, out, flush),
            (Isa::Avx2, 7, 8) => adj_256::<T, 7, 14, false>(a, tables, out, flush),
            (Isa::Avx2, 8, 8) => adj_256::<T, 8, 16, false>(a, tables, out, flush),
            _ => panic!("the wide adjoint has no kernel for {}", isa.name()),
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    panic!("the wide adjoint has no kernel for {}", isa.name());
}

#[cfg(target_arch = "x86_64")]
wide_pair!(adj_512, adj_256, adj_wide<const NCH: usize, const Z: usize, const HALF: bool>(
    a: &AdjChunk<'_, T>, tables: &[Lane<T>], out: &mut [Lane<T>],
    flush: Option<&mut [[f64; 8]]>
));

/// Every pixel's rows of the chunk's tables, `Z` vectors a row; with `HALF` the sums hold
/// `NCH − 1` chunks, the first half of the last vector.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
// The accumulators are indexed in step with the vectors' offsets in the rows.
#[allow(clippy::needless_range_loop)]
unsafe fn adj_wide<T: Real, S: Simd<T = T>, const NCH: usize, const Z: usize, const HALF: bool>(
    a: &AdjChunk<'_, T>,
    tables: &[Lane<T>],
    out: &mut [Lane<T>],
    mut flush: Option<&mut [[f64; 8]]>,
) {
    let per = S::PER;
    let stride = octet_stride::<T>(NCH) * 8;
    let base = tables.as_ptr().cast::<T>();
    let row = |o: usize, b: u64| base.add(o * stride + (b & 0xFF) as usize * NCH * 8);
    let sums_nch = if HALF { NCH - 1 } else { NCH };
    let transpose = gfni_transpose(per * std::mem::size_of::<T>());
    // Binary codes' rows read below 128 only where [`symmetric_rows`] says so for this kernel
    // (the caller built the tables by the same decision).
    let kernel = if per * std::mem::size_of::<T>() == 32 {
        Isa::Avx2
    } else {
        Isa::Avx512
    };
    let symmetric = a.minus.is_none() && symmetric_rows::<T>(kernel);
    let (mut bp, mut bm) = ([0u64; ADJ_OCTETS], [0u64; ADJ_OCTETS]);
    for (g, og) in out.chunks_exact_mut(8 * sums_nch).enumerate() {
        wide_chunk_bits(a, g, &mut bp, &mut bm, transpose);
        for (i, oi) in og.chunks_exact_mut(sums_nch).enumerate() {
            let shift = 8 * i;
            let mut acc = [S::v_zero(); Z];
            if a.minus.is_none() {
                if symmetric {
                    let signs = [T::one(), -T::one()];
                    for o in 0..ADJ_OCTETS {
                        let b = (bp[o] >> shift) & 0xFF;
                        let flip = (b >> 7) as usize;
                        let r = row(o, b ^ (0xFF * flip as u64));
                        let sign = S::v_splat(signs[flip]);
                        for z in 0..Z {
                            acc[z] = S::v_mul_add(S::v_load(r.add(z * per)), sign, acc[z]);
                        }
                    }
                } else {
                    for o in 0..ADJ_OCTETS {
                        let r = row(o, bp[o] >> shift);
                        for z in 0..Z {
                            acc[z] = S::v_add(acc[z], S::v_load(r.add(z * per)));
                        }
                    }
                }
            } else {
                for o in 0..ADJ_OCTETS {
                    let (rp, rm) = (row(o, bp[o] >> shift), row(o, bm[o] >> shift));
                    for z in 0..Z {
                        let d = S::v_sub(S::v_load(rp.add(z * per)), S::v_load(rm.add(z * per)));
                        acc[z] = S::v_add(acc[z], d);
                    }
                }
            }
            let dst = oi.as_mut_ptr().cast::<T>();
            for z in 0..Z {
                let d = dst.add(z * per);
                if HALF && z == Z - 1 {
                    S::v_add_half(d, acc[z]);
                } else {
                    S::v_storeu(d, S::v_add(S::v_loadu(d), acc[z]));
                }
            }
        }
        if let Some(f) = flush.as_deref_mut() {
            super::flush_sums(og, &mut f[g * 8 * sums_nch..(g + 1) * 8 * sums_nch]);
        }
    }
}

/// A transpose of a chunk's eight octets of code bytes at once: reads 64 bytes at its first
/// argument, writes what [`transpose8`](super::transpose8) makes of each octet.
#[cfg(target_arch = "x86_64")]
type OctetsTranspose = unsafe fn(*const u8, &mut [u64; ADJ_OCTETS]);

/// The GFNI transpose for a kernel of `vector_bytes`-byte vectors ([`transpose_octets_512`] on
/// AVX-512, [`transpose_octets_256`] on AVX2), where the processor has GFNI beside the kernel's
/// instruction set; `None` elsewhere.
#[cfg(target_arch = "x86_64")]
fn gfni_transpose(vector_bytes: usize) -> Option<OctetsTranspose> {
    use std::arch::is_x86_feature_detected as has;
    if !has!("gfni") {
        return None;
    }
    match vector_bytes {
        64 if has!("avx512f") && has!("avx512bw") => Some(transpose_octets_512),
        32 if has!("avx2") => Some(transpose_octets_256),
        _ => None,
    }
}

/// [`chunk_bits`] for the wide kernels: with a `transpose` ([`gfni_transpose`]) and all the
/// chunk's bytes of the group there (not the last chunk of a K that is not a multiple of 64),
/// the eight octets are transposed at once, the same bits as one octet at a time.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn wide_chunk_bits<T>(
    a: &AdjChunk<'_, T>,
    g: usize,
    plus: &mut [u64; ADJ_OCTETS],
    minus: &mut [u64; ADJ_OCTETS],
    transpose: Option<OctetsTranspose>,
) {
    let from = 8 * a.first_octet;
    let (p, m) = (a.plus.group(g), a.minus.map(|m| m.group(g)));
    let whole = |bytes: &[u8]| from + 8 * ADJ_OCTETS <= bytes.len();
    let Some(transpose) = transpose.filter(|_| whole(p) && m.is_none_or(whole)) else {
        return chunk_bits(a, g, plus, minus);
    };
    a.plus.prefetch(g + 2, from);
    // SAFETY: `gfni_transpose` gives a transpose only where the processor has the features it
    // uses, and the 64 bytes it reads from `from` lie within the group's bytes (both planes'
    // for ternary codes), as checked above.
    unsafe { transpose(p[from..].as_ptr(), plus) };
    if let (Some(m), Some(planes)) = (m, a.minus) {
        planes.prefetch(g + 2, from);
        // SAFETY: as above.
        unsafe { transpose(m[from..].as_ptr(), minus) };
    }
}

/// Each octet's bytes reversed, for `vgf2p8affineqb`'s rows (a 128-bit lane's two words).
#[cfg(target_arch = "x86_64")]
const REVERSE_OCTETS: [i8; 16] = [7, 6, 5, 4, 3, 2, 1, 0, 15, 14, 13, 12, 11, 10, 9, 8];

/// Byte j of each word is 1 << j: the first operand of `vgf2p8affineqb` that transposes.
#[cfg(target_arch = "x86_64")]
const UNIT_BYTES: i64 = 0x8040_2010_0804_0201_u64 as i64;

/// The eight octets of 64 code bytes at `bytes` transposed as [`transpose8`](super::transpose8)
/// does one. `vgf2p8affineqb` multiplies each byte of its first operand by the 8×8 bit matrix
/// of the second operand's word, taking bit i of the product from the word's byte 7 − i: with
/// the unit bytes 1 << j as the first operand and each octet's bytes reversed as the matrix,
/// byte j of the product is bit j of every byte of the octet, the matrix transposed.
///
/// # Safety
/// The processor has AVX-512F, AVX-512BW and GFNI, and 64 bytes are readable at `bytes`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,gfni")]
unsafe fn transpose_octets_512(bytes: *const u8, out: &mut [u64; ADJ_OCTETS]) {
    use std::arch::x86_64::*;
    const _: () = assert!(ADJ_OCTETS == 8, "one 512-bit vector a chunk");
    let lane = _mm_loadu_si128(REVERSE_OCTETS.as_ptr().cast());
    let reverse = _mm512_broadcast_i32x4(lane);
    let rows = _mm512_shuffle_epi8(_mm512_loadu_si512(bytes.cast()), reverse);
    let bits = _mm512_gf2p8affine_epi64_epi8::<0>(_mm512_set1_epi64(UNIT_BYTES), rows);
    _mm512_storeu_si512(out.as_mut_ptr().cast(), bits);
}

/// [`transpose_octets_512`] in two 256-bit halves.
///
/// # Safety
/// The processor has AVX2 and GFNI, and 64 bytes are readable at `bytes`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,gfni")]
unsafe fn transpose_octets_256(bytes: *const u8, out: &mut [u64; ADJ_OCTETS]) {
    use std::arch::x86_64::*;
    let lane = _mm_loadu_si128(REVERSE_OCTETS.as_ptr().cast());
    let reverse = _mm256_broadcastsi128_si256(lane);
    let unit = _mm256_set1_epi64x(UNIT_BYTES);
    for (half, words) in out.chunks_exact_mut(4).enumerate() {
        let rows = _mm256_loadu_si256(bytes.add(32 * half).cast());
        let bits = _mm256_gf2p8affine_epi64_epi8::<0>(unit, _mm256_shuffle_epi8(rows, reverse));
        _mm256_storeu_si256(words.as_mut_ptr().cast(), bits);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lidar::codes::GroupBytes;
    use crate::lidar::kernels::quads::{lines_as_mut, CacheLine};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The wide chunk kernel against the direct sum Σ_k s_i(k)·y[k]·p[k − j] and, to the last
    /// bit, against the generic kernel on rows of the slab's own width, for both alphabets, a
    /// slab of three chunks (rows widened to four for `f32` on AVX-512, the sums not), a K that
    /// is not a multiple of eight and two chunks of octets.
    fn wide_adjoint_matches_the_direct_sum<T: Real>(tol: f64) {
        for isa in crate::lidar::kernels::tests::every_isa() {
            if !isa.has_wide() {
                continue;
            }
            // On AVX-512 both row widths, whichever this processor reads ([`narrow_f32_rows`]).
            let mut widths = vec![SLAB, vector_row_nch::<T>(isa, SLAB)];
            widths.sort_unstable();
            widths.dedup();
            for nch in widths {
                wide_adjoint_on::<T>(isa, nch, tol);
            }
        }
    }

    const SLAB: usize = 3;

    fn wide_adjoint_on<T: Real>(isa: Isa, nch: usize, tol: f64) {
        let mut rng = ChaCha8Rng::seed_from_u64(61);
        let (groups, k) = (3usize, 8 * ADJ_OCTETS + 13);
        let kp = k + 1 - 8 * SLAB;
        let y: Vec<T> = (0..k)
            .map(|_| T::of_f64(rng.random_range(-1.0..1.0)))
            .collect();
        let pulse: Vec<f64> = (0..kp)
            .map(|_| f64::from(rng.random_range(0..2u8)))
            .collect();
        let pad = 8 * SLAB;
        let mut prev = vec![T::zero(); pad + kp + 8 * nch];
        for (t, &v) in pulse.iter().rev().enumerate() {
            prev[pad + t] = T::of_f64(v);
        }
        let (plus, minus) = crate::lidar::kernels::tests::random_planes(&mut rng, groups, k);
        let (plus_plane, minus_plane) = (plus.concat(), minus.concat());
        for ternary in [false, true] {
            let chunk = |o0| AdjChunk {
                plus: GroupBytes::new(&plus_plane, k, 0..groups),
                minus: ternary.then(|| GroupBytes::new(&minus_plane, k, 0..groups)),
                y: &y,
                prev: &prev,
                base0: pad + kp - 1,
                first_octet: o0,
            };
            let bytes = ADJ_OCTETS * octet_stride::<T>(nch) * std::mem::size_of::<Lane<T>>();
            let mut lines = vec![CacheLine::default(); bytes.div_ceil(64)];
            let tables = lines_as_mut::<T>(&mut lines).as_chunks_mut::<8>().0;
            let mut out = vec![[T::zero(); 8]; groups * 8 * SLAB];
            let mut generic_tables = vec![[T::zero(); 8]; ADJ_OCTETS * octet_stride::<T>(SLAB)];
            let mut generic_out = out.clone();
            for o0 in (0..k.div_ceil(8)).step_by(ADJ_OCTETS) {
                let a = chunk(o0);
                adjoint_chunk_wide(isa, nch, SLAB, &a, tables, &mut out, None);
                let generic = &mut generic_tables;
                super::super::adjoint_chunk(
                    Isa::Generic,
                    SLAB,
                    &a,
                    generic,
                    &mut generic_out,
                    None,
                );
            }
            // The same additions in the same order as the generic kernel.
            assert!(
                out == generic_out,
                "{} {} rows of {nch} chunks, ternary {ternary}",
                T::NAME,
                isa.name()
            );
            // Flushed on the last chunk: the same sums in `f64`, the partial sums cleared, on
            // both kernels.
            let chunks: Vec<usize> = (0..k.div_ceil(8)).step_by(ADJ_OCTETS).collect();
            for wide in [true, false] {
                let mut part = vec![[T::zero(); 8]; out.len()];
                let mut sums = vec![[0.0f64; 8]; out.len()];
                for &o0 in &chunks {
                    let a = chunk(o0);
                    let flush = (o0 == *chunks.last().unwrap()).then_some(sums.as_mut_slice());
                    if wide {
                        adjoint_chunk_wide(isa, nch, SLAB, &a, tables, &mut part, flush);
                    } else {
                        let generic = &mut generic_tables;
                        super::super::adjoint_chunk(
                            Isa::Generic,
                            SLAB,
                            &a,
                            generic,
                            &mut part,
                            flush,
                        );
                    }
                }
                assert!(part.iter().flatten().all(|&v| v == T::zero()), "cleared");
                let want: Vec<f64> = out.iter().flatten().map(|v| v.as_f64()).collect();
                assert_eq!(
                    sums.concat(),
                    want,
                    "{} {} wide {wide}",
                    T::NAME,
                    isa.name()
                );
            }
            for (g, (p, m)) in plus.iter().zip(&minus).enumerate() {
                for i in 0..8 {
                    for j in 0..8 * SLAB {
                        let want: f64 = (j..k.min(j + kp))
                            .map(|kk| {
                                let s = f64::from((p[kk] >> i) & 1)
                                    - if ternary {
                                        f64::from((m[kk] >> i) & 1)
                                    } else {
                                        f64::from(!(p[kk] >> i) & 1)
                                    };
                                s * y[kk].as_f64() * pulse[kk - j]
                            })
                            .sum();
                        let got = out[(g * 8 + i) * SLAB + j / 8][j % 8].as_f64();
                        assert!(
                            (got - want).abs() <= tol * (1.0 + want.abs()),
                            "{} {} ternary {ternary}: pixel {g}/{i} bin {j}: {got} vs {want}",
                            T::NAME,
                            isa.name()
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn wide_adjoint_matches_the_direct_sum_f32() {
        wide_adjoint_matches_the_direct_sum::<f32>(1e-4);
    }

    #[test]
    fn wide_adjoint_matches_the_direct_sum_f64() {
        wide_adjoint_matches_the_direct_sum::<f64>(1e-12);
    }

    /// The eight octets transposed at once by GFNI (both vector widths) against one at a time,
    /// on random bytes, where the processor has GFNI.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn octets_transposed_at_once_match_one_at_a_time() {
        let mut rng = ChaCha8Rng::seed_from_u64(67);
        for width in [64, 32] {
            let Some(transpose) = gfni_transpose(width) else {
                continue;
            };
            for _ in 0..64 {
                let bytes: Vec<u8> = (0..64).map(|_| rng.random()).collect();
                let mut at_once = [0u64; ADJ_OCTETS];
                // SAFETY: `gfni_transpose` found the features, and `bytes` has 64 bytes.
                unsafe { transpose(bytes.as_ptr(), &mut at_once) };
                for (o, &got) in at_once.iter().enumerate() {
                    let word = u64::from_le_bytes(bytes[8 * o..8 * o + 8].try_into().unwrap());
                    assert_eq!(
                        got,
                        super::super::transpose8(word),
                        "{width} bytes, octet {o}"
                    );
                }
            }
        }
    }

    #[test]
    fn rows_are_whole_vectors() {
        assert_eq!(wide_adjoint_nch::<f32>(5), 6);
        assert_eq!(wide_adjoint_nch::<f32>(8), 8);
        assert_eq!(wide_adjoint_nch::<f64>(5), 5);
        assert_eq!(adjoint_row_nch::<f32>(Isa::Generic, 5), 5);
        #[cfg(target_arch = "x86_64")]
        {
            assert_eq!(adjoint_row_nch::<f32>(Isa::Avx2, 5), 5);
            let f32_rows = if narrow_f32_rows() { 5 } else { 6 };
            assert_eq!(adjoint_row_nch::<f32>(Isa::Avx512, 5), f32_rows);
            assert_eq!(adjoint_row_nch::<f64>(Isa::Avx512, 5), 5);
        }
    }
}
