//! The 512-bit vector operations of the AVX-512 kernels, for `f32` (sixteen values a vector) and
//! `f64` (eight), so that one generic kernel serves both precisions.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Vector operations on one 512-bit register of `Self` values (the crate's own kernels use them;
/// a supertrait of [`Real`](crate::Real) so that generic kernels reach them).
///
/// # Safety
/// Every function needs AVX-512F at run time, [`m_bit`](Wide::m_bit) also AVX-512BW and VL
/// (`Isa::Avx512` has all three); the loads read what their documentation says and no more.
#[doc(hidden)]
pub trait Wide: Copy {
    /// Values per vector (and per 64-byte cache line).
    const PER: usize;
    /// A vector of [`PER`](Wide::PER) values.
    #[cfg(target_arch = "x86_64")]
    type V: Copy;

    /// All zeros.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_zero() -> Self::V;
    /// The [`PER`](Wide::PER) values at `p`, which is 64-byte aligned.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_load(p: *const Self) -> Self::V;
    /// The [`PER`](Wide::PER) values at `p` (any alignment).
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_loadu(p: *const Self) -> Self::V;
    /// Stores `v` at `p` (any alignment).
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_storeu(p: *mut Self, v: Self::V);
    /// The first `min(n, PER)` values at `p` (any alignment), zeros after: nothing past them
    /// is read.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_load_first(p: *const Self, n: usize) -> Self::V;
    /// a + b.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_add(a: Self::V, b: Self::V) -> Self::V;
    /// a − b.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_sub(a: Self::V, b: Self::V) -> Self::V;
    /// a·b + c.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_mul_add(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// Eight lanes whose sum is the sum of the vector's values.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_lanes8(v: Self::V) -> [Self; 8];
    /// `a` in every lane.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_splat(a: Self) -> Self::V;

    /// A mask of one bit per lane.
    #[cfg(target_arch = "x86_64")]
    type M: Copy;
    /// The lanes whose code byte, of the [`PER`](Wide::PER) bytes at `codes`, has bit `bit`
    /// (0 to 7) set (needs AVX-512BW and VL).
    #[cfg(target_arch = "x86_64")]
    unsafe fn m_bit(codes: *const u8, bit: u32) -> Self::M;
    /// `a` in the lanes of `plus`, −a in the others: a binary code applied.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_sign(plus: Self::M, a: Self::V) -> Self::V;
    /// `a` in the lanes of `plus` only, −a in those of `minus` only, zero elsewhere: a ternary
    /// code applied.
    #[cfg(target_arch = "x86_64")]
    unsafe fn v_ternary(plus: Self::M, minus: Self::M, a: Self::V) -> Self::V;
}

/// The mask of the first `min(n, bits)` lanes.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn first_lanes(n: usize, bits: usize) -> u32 {
    if n >= bits {
        u32::MAX >> (32 - bits)
    } else {
        (1u32 << n) - 1
    }
}

impl Wide for f32 {
    const PER: usize = 16;
    #[cfg(target_arch = "x86_64")]
    type V = __m512;

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_zero() -> __m512 {
        _mm512_setzero_ps()
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_load(p: *const f32) -> __m512 {
        _mm512_load_ps(p)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_loadu(p: *const f32) -> __m512 {
        _mm512_loadu_ps(p)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_storeu(p: *mut f32, v: __m512) {
        _mm512_storeu_ps(p, v)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_load_first(p: *const f32, n: usize) -> __m512 {
        _mm512_maskz_loadu_ps(first_lanes(n, 16) as u16, p)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_add(a: __m512, b: __m512) -> __m512 {
        _mm512_add_ps(a, b)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_sub(a: __m512, b: __m512) -> __m512 {
        _mm512_sub_ps(a, b)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_mul_add(a: __m512, b: __m512, c: __m512) -> __m512 {
        _mm512_fmadd_ps(a, b, c)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_lanes8(v: __m512) -> [f32; 8] {
        let high = _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(v)));
        let sum = _mm256_add_ps(_mm512_castps512_ps256(v), high);
        std::mem::transmute::<std::arch::x86_64::__m256, [f32; 8]>(sum)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_splat(a: f32) -> __m512 {
        _mm512_set1_ps(a)
    }

    #[cfg(target_arch = "x86_64")]
    type M = __mmask16;
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn m_bit(codes: *const u8, bit: u32) -> __mmask16 {
        _mm_test_epi8_mask(_mm_loadu_si128(codes.cast()), _mm_set1_epi8(1 << bit))
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_sign(plus: __mmask16, a: __m512) -> __m512 {
        _mm512_mask_sub_ps(a, !plus, _mm512_setzero_ps(), a)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_ternary(plus: __mmask16, minus: __mmask16, a: __m512) -> __m512 {
        let gated = _mm512_maskz_mov_ps(plus, a);
        _mm512_mask_sub_ps(gated, minus, gated, a)
    }
}

impl Wide for f64 {
    const PER: usize = 8;
    #[cfg(target_arch = "x86_64")]
    type V = __m512d;

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_zero() -> __m512d {
        _mm512_setzero_pd()
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_load(p: *const f64) -> __m512d {
        _mm512_load_pd(p)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_loadu(p: *const f64) -> __m512d {
        _mm512_loadu_pd(p)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_storeu(p: *mut f64, v: __m512d) {
        _mm512_storeu_pd(p, v)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_load_first(p: *const f64, n: usize) -> __m512d {
        _mm512_maskz_loadu_pd(first_lanes(n, 8) as u8, p)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_add(a: __m512d, b: __m512d) -> __m512d {
        _mm512_add_pd(a, b)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_sub(a: __m512d, b: __m512d) -> __m512d {
        _mm512_sub_pd(a, b)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_mul_add(a: __m512d, b: __m512d, c: __m512d) -> __m512d {
        _mm512_fmadd_pd(a, b, c)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_lanes8(v: __m512d) -> [f64; 8] {
        std::mem::transmute::<__m512d, [f64; 8]>(v)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_splat(a: f64) -> __m512d {
        _mm512_set1_pd(a)
    }

    #[cfg(target_arch = "x86_64")]
    type M = __mmask8;
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn m_bit(codes: *const u8, bit: u32) -> __mmask8 {
        _mm_test_epi8_mask(_mm_loadl_epi64(codes.cast()), _mm_set1_epi8(1 << bit)) as __mmask8
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_sign(plus: __mmask8, a: __m512d) -> __m512d {
        _mm512_mask_sub_pd(a, !plus, _mm512_setzero_pd(), a)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn v_ternary(plus: __mmask8, minus: __mmask8, a: __m512d) -> __m512d {
        let gated = _mm512_maskz_mov_pd(plus, a);
        _mm512_mask_sub_pd(gated, minus, gated, a)
    }
}
