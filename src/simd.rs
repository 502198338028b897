//! The vector operations of the wide kernels, in two flavours: 512-bit (AVX-512, sixteen `f32`
//! or eight `f64` values a vector) and 256-bit (AVX2, eight or four), so that one generic kernel
//! serves both precisions and both instruction sets. They live beside the scalars they extend:
//! [`Wide`] is a supertrait of [`Real`](crate::Real).

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;
#[cfg(target_arch = "x86_64")]
use std::marker::PhantomData;

/// The vector flavours of a value type (a supertrait of [`Real`](crate::Real), so that generic
/// kernels reach them): [`W512`] and [`W256`].
#[doc(hidden)]
pub trait Wide: Copy + Sized + 'static {
    /// Values per 512-bit vector (and per 64-byte cache line): the layout of the wide tables,
    /// whatever the flavour that reads them.
    const PER: usize;
    /// The 512-bit operations on `Self`.
    #[cfg(target_arch = "x86_64")]
    type W512: Simd<T = Self>;
    /// The 256-bit operations on `Self`.
    #[cfg(target_arch = "x86_64")]
    type W256: Simd<T = Self>;
}

impl Wide for f32 {
    const PER: usize = 16;
    #[cfg(target_arch = "x86_64")]
    type W512 = W512<f32>;
    #[cfg(target_arch = "x86_64")]
    type W256 = W256<f32>;
}

impl Wide for f64 {
    const PER: usize = 8;
    #[cfg(target_arch = "x86_64")]
    type W512 = W512<f64>;
    #[cfg(target_arch = "x86_64")]
    type W256 = W256<f64>;
}

/// The 512-bit flavour (AVX-512F, with BW and VL for the masks).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
#[doc(hidden)]
pub struct W512<T>(PhantomData<T>);

/// The 256-bit flavour (AVX2 and FMA).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
#[doc(hidden)]
pub struct W256<T>(PhantomData<T>);

/// Vector operations on one register of [`PER`](Simd::PER) values of [`T`](Simd::T).
///
/// # Safety
/// Every function needs the flavour's instruction set at run time (`W512`: AVX-512F, BW and VL,
/// which `Isa::Avx512` has; `W256`: AVX2 and FMA, which `Isa::Avx2` and `Isa::Avx512` have),
/// and is inlined into a function compiled with it; the loads read what their documentation says
/// and no more.
#[cfg(target_arch = "x86_64")]
#[doc(hidden)]
pub trait Simd: Copy {
    /// The value type.
    type T: Copy;
    /// Values per vector.
    const PER: usize;
    /// Vector registers of the instruction set (for the kernels' register budgets).
    const REGS: usize;
    /// A vector of [`PER`](Simd::PER) values.
    type V: Copy;
    /// A mask of one flag per lane.
    type M: Copy;

    /// All zeros.
    unsafe fn v_zero() -> Self::V;
    /// The [`PER`](Simd::PER) values at `p`, which is aligned to the vector's size.
    unsafe fn v_load(p: *const Self::T) -> Self::V;
    /// The [`PER`](Simd::PER) values at `p` (any alignment).
    unsafe fn v_loadu(p: *const Self::T) -> Self::V;
    /// Stores `v` at `p` (any alignment).
    unsafe fn v_storeu(p: *mut Self::T, v: Self::V);
    /// The first `min(n, PER)` values at `p` (any alignment), zeros after: nothing past them
    /// is read.
    unsafe fn v_load_first(p: *const Self::T, n: usize) -> Self::V;
    /// a + b.
    unsafe fn v_add(a: Self::V, b: Self::V) -> Self::V;
    /// a − b.
    unsafe fn v_sub(a: Self::V, b: Self::V) -> Self::V;
    /// a·b + c.
    unsafe fn v_mul_add(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// Eight lanes whose sum is the sum of the vector's values.
    unsafe fn v_lanes8(v: Self::V) -> [Self::T; 8];
    /// `a` in every lane.
    unsafe fn v_splat(a: Self::T) -> Self::V;
    /// The lanes whose code byte, of the [`PER`](Simd::PER) bytes at `codes`, has bit `bit`
    /// (0 to 7) set.
    unsafe fn m_bit(codes: *const u8, bit: u32) -> Self::M;
    /// `a` in the lanes of `plus`, 0 − a in the others: a binary code applied.
    unsafe fn v_sign(plus: Self::M, a: Self::V) -> Self::V;
    /// `a` in the lanes of `plus` only, 0 − a in those of `minus` only, zero elsewhere: a
    /// ternary code applied.
    unsafe fn v_ternary(plus: Self::M, minus: Self::M, a: Self::V) -> Self::V;
    /// `a` in the lanes of `plus`, `b` in the others.
    unsafe fn v_pick(plus: Self::M, a: Self::V, b: Self::V) -> Self::V;
    /// A vector's values in `f64`, in as many `f64` vectors as they take.
    type D: Copy;
    /// Zeros in `f64`.
    unsafe fn d_zero() -> Self::D;
    /// The values of `v` in `f64` (exact).
    unsafe fn d_widen(v: Self::V) -> Self::D;
    /// a + b lane by lane.
    unsafe fn d_add(a: Self::D, b: Self::D) -> Self::D;
    /// a + b in the lanes of `plus`, `a` in the others.
    unsafe fn d_add_where(plus: Self::M, a: Self::D, b: Self::D) -> Self::D;
    /// The sum of the lanes, in a fixed order.
    unsafe fn d_sum(a: Self::D) -> f64;
    /// The first half of the vector's values at `p` (aligned to half the vector's size), zeros
    /// in the other half: nothing past them is read.
    unsafe fn v_load_half(p: *const Self::T) -> Self::V;
    /// Adds the first half of `v` to the values at `p` (unaligned): nothing past them is read
    /// or written.
    unsafe fn v_add_half(p: *mut Self::T, v: Self::V);
}

/// l₀ + … + l₇ pairwise, in a fixed order.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn sum8(l: [f64; 8]) -> f64 {
    ((l[0] + l[4]) + (l[1] + l[5])) + ((l[2] + l[6]) + (l[3] + l[7]))
}

/// l₀ + … + l₃ pairwise, in a fixed order.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn sum4(l: [f64; 4]) -> f64 {
    (l[0] + l[2]) + (l[1] + l[3])
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

#[cfg(target_arch = "x86_64")]
impl Simd for W512<f32> {
    type T = f32;
    const PER: usize = 16;
    const REGS: usize = 32;
    type V = __m512;
    type M = __mmask16;

    #[inline(always)]
    unsafe fn v_zero() -> __m512 {
        _mm512_setzero_ps()
    }
    #[inline(always)]
    unsafe fn v_load(p: *const f32) -> __m512 {
        _mm512_load_ps(p)
    }
    #[inline(always)]
    unsafe fn v_loadu(p: *const f32) -> __m512 {
        _mm512_loadu_ps(p)
    }
    #[inline(always)]
    unsafe fn v_storeu(p: *mut f32, v: __m512) {
        _mm512_storeu_ps(p, v)
    }
    #[inline(always)]
    unsafe fn v_load_first(p: *const f32, n: usize) -> __m512 {
        _mm512_maskz_loadu_ps(first_lanes(n, 16) as u16, p)
    }
    #[inline(always)]
    unsafe fn v_add(a: __m512, b: __m512) -> __m512 {
        _mm512_add_ps(a, b)
    }
    #[inline(always)]
    unsafe fn v_sub(a: __m512, b: __m512) -> __m512 {
        _mm512_sub_ps(a, b)
    }
    #[inline(always)]
    unsafe fn v_mul_add(a: __m512, b: __m512, c: __m512) -> __m512 {
        _mm512_fmadd_ps(a, b, c)
    }
    #[inline(always)]
    unsafe fn v_lanes8(v: __m512) -> [f32; 8] {
        let high = _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(v)));
        let sum = _mm256_add_ps(_mm512_castps512_ps256(v), high);
        std::mem::transmute::<__m256, [f32; 8]>(sum)
    }
    #[inline(always)]
    unsafe fn v_splat(a: f32) -> __m512 {
        _mm512_set1_ps(a)
    }
    #[inline(always)]
    unsafe fn m_bit(codes: *const u8, bit: u32) -> __mmask16 {
        _mm_test_epi8_mask(_mm_loadu_si128(codes.cast()), _mm_set1_epi8(1 << bit))
    }
    #[inline(always)]
    unsafe fn v_sign(plus: __mmask16, a: __m512) -> __m512 {
        _mm512_mask_sub_ps(a, !plus, _mm512_setzero_ps(), a)
    }
    #[inline(always)]
    unsafe fn v_ternary(plus: __mmask16, minus: __mmask16, a: __m512) -> __m512 {
        let gated = _mm512_maskz_mov_ps(plus, a);
        _mm512_mask_sub_ps(gated, minus, gated, a)
    }
    #[inline(always)]
    unsafe fn v_pick(plus: __mmask16, a: __m512, b: __m512) -> __m512 {
        _mm512_mask_blend_ps(plus, b, a)
    }
    type D = [__m512d; 2];
    #[inline(always)]
    unsafe fn d_zero() -> [__m512d; 2] {
        [_mm512_setzero_pd(); 2]
    }
    #[inline(always)]
    unsafe fn d_widen(v: __m512) -> [__m512d; 2] {
        let high = _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(v)));
        [
            _mm512_cvtps_pd(_mm512_castps512_ps256(v)),
            _mm512_cvtps_pd(high),
        ]
    }
    #[inline(always)]
    unsafe fn d_add(a: [__m512d; 2], b: [__m512d; 2]) -> [__m512d; 2] {
        [_mm512_add_pd(a[0], b[0]), _mm512_add_pd(a[1], b[1])]
    }
    #[inline(always)]
    unsafe fn d_add_where(plus: __mmask16, a: [__m512d; 2], b: [__m512d; 2]) -> [__m512d; 2] {
        let (low, high) = (plus as __mmask8, (plus >> 8) as __mmask8);
        [
            _mm512_mask_add_pd(a[0], low, a[0], b[0]),
            _mm512_mask_add_pd(a[1], high, a[1], b[1]),
        ]
    }
    #[inline(always)]
    unsafe fn d_sum(a: [__m512d; 2]) -> f64 {
        sum8(std::mem::transmute::<__m512d, [f64; 8]>(_mm512_add_pd(
            a[0], a[1],
        )))
    }
    #[inline(always)]
    unsafe fn v_load_half(p: *const f32) -> __m512 {
        _mm512_zextps256_ps512(_mm256_load_ps(p))
    }
    #[inline(always)]
    unsafe fn v_add_half(p: *mut f32, v: __m512) {
        _mm256_storeu_ps(
            p,
            _mm256_add_ps(_mm256_loadu_ps(p), _mm512_castps512_ps256(v)),
        )
    }
}

#[cfg(target_arch = "x86_64")]
impl Simd for W512<f64> {
    type T = f64;
    const PER: usize = 8;
    const REGS: usize = 32;
    type V = __m512d;
    type M = __mmask8;

    #[inline(always)]
    unsafe fn v_zero() -> __m512d {
        _mm512_setzero_pd()
    }
    #[inline(always)]
    unsafe fn v_load(p: *const f64) -> __m512d {
        _mm512_load_pd(p)
    }
    #[inline(always)]
    unsafe fn v_loadu(p: *const f64) -> __m512d {
        _mm512_loadu_pd(p)
    }
    #[inline(always)]
    unsafe fn v_storeu(p: *mut f64, v: __m512d) {
        _mm512_storeu_pd(p, v)
    }
    #[inline(always)]
    unsafe fn v_load_first(p: *const f64, n: usize) -> __m512d {
        _mm512_maskz_loadu_pd(first_lanes(n, 8) as u8, p)
    }
    #[inline(always)]
    unsafe fn v_add(a: __m512d, b: __m512d) -> __m512d {
        _mm512_add_pd(a, b)
    }
    #[inline(always)]
    unsafe fn v_sub(a: __m512d, b: __m512d) -> __m512d {
        _mm512_sub_pd(a, b)
    }
    #[inline(always)]
    unsafe fn v_mul_add(a: __m512d, b: __m512d, c: __m512d) -> __m512d {
        _mm512_fmadd_pd(a, b, c)
    }
    #[inline(always)]
    unsafe fn v_lanes8(v: __m512d) -> [f64; 8] {
        std::mem::transmute::<__m512d, [f64; 8]>(v)
    }
    #[inline(always)]
    unsafe fn v_splat(a: f64) -> __m512d {
        _mm512_set1_pd(a)
    }
    #[inline(always)]
    unsafe fn m_bit(codes: *const u8, bit: u32) -> __mmask8 {
        _mm_test_epi8_mask(_mm_loadl_epi64(codes.cast()), _mm_set1_epi8(1 << bit)) as __mmask8
    }
    #[inline(always)]
    unsafe fn v_sign(plus: __mmask8, a: __m512d) -> __m512d {
        _mm512_mask_sub_pd(a, !plus, _mm512_setzero_pd(), a)
    }
    #[inline(always)]
    unsafe fn v_ternary(plus: __mmask8, minus: __mmask8, a: __m512d) -> __m512d {
        let gated = _mm512_maskz_mov_pd(plus, a);
        _mm512_mask_sub_pd(gated, minus, gated, a)
    }
    #[inline(always)]
    unsafe fn v_pick(plus: __mmask8, a: __m512d, b: __m512d) -> __m512d {
        _mm512_mask_blend_pd(plus, b, a)
    }
    type D = __m512d;
    #[inline(always)]
    unsafe fn d_zero() -> __m512d {
        _mm512_setzero_pd()
    }
    #[inline(always)]
    unsafe fn d_widen(v: __m512d) -> __m512d {
        v
    }
    #[inline(always)]
    unsafe fn d_add(a: __m512d, b: __m512d) -> __m512d {
        _mm512_add_pd(a, b)
    }
    #[inline(always)]
    unsafe fn d_add_where(plus: __mmask8, a: __m512d, b: __m512d) -> __m512d {
        _mm512_mask_add_pd(a, plus, a, b)
    }
    #[inline(always)]
    unsafe fn d_sum(a: __m512d) -> f64 {
        sum8(std::mem::transmute::<__m512d, [f64; 8]>(a))
    }
    #[inline(always)]
    unsafe fn v_load_half(p: *const f64) -> __m512d {
        _mm512_zextpd256_pd512(_mm256_load_pd(p))
    }
    #[inline(always)]
    unsafe fn v_add_half(p: *mut f64, v: __m512d) {
        _mm256_storeu_pd(
            p,
            _mm256_add_pd(_mm256_loadu_pd(p), _mm512_castpd512_pd256(v)),
        )
    }
}

// On AVX2 a lane's flag is the sign bit of its mask lane (what the blends read): the code byte
// widened to the lane and shifted so that the wanted bit lands there.

#[cfg(target_arch = "x86_64")]
impl Simd for W256<f32> {
    type T = f32;
    const PER: usize = 8;
    const REGS: usize = 16;
    type V = __m256;
    type M = __m256;

    #[inline(always)]
    unsafe fn v_zero() -> __m256 {
        _mm256_setzero_ps()
    }
    #[inline(always)]
    unsafe fn v_load(p: *const f32) -> __m256 {
        _mm256_load_ps(p)
    }
    #[inline(always)]
    unsafe fn v_loadu(p: *const f32) -> __m256 {
        _mm256_loadu_ps(p)
    }
    #[inline(always)]
    unsafe fn v_storeu(p: *mut f32, v: __m256) {
        _mm256_storeu_ps(p, v)
    }
    #[inline(always)]
    unsafe fn v_load_first(p: *const f32, n: usize) -> __m256 {
        let lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let mask = _mm256_cmpgt_epi32(_mm256_set1_epi32(n.min(8) as i32), lanes);
        _mm256_maskload_ps(p, mask)
    }
    #[inline(always)]
    unsafe fn v_add(a: __m256, b: __m256) -> __m256 {
        _mm256_add_ps(a, b)
    }
    #[inline(always)]
    unsafe fn v_sub(a: __m256, b: __m256) -> __m256 {
        _mm256_sub_ps(a, b)
    }
    #[inline(always)]
    unsafe fn v_mul_add(a: __m256, b: __m256, c: __m256) -> __m256 {
        _mm256_fmadd_ps(a, b, c)
    }
    #[inline(always)]
    unsafe fn v_lanes8(v: __m256) -> [f32; 8] {
        std::mem::transmute::<__m256, [f32; 8]>(v)
    }
    #[inline(always)]
    unsafe fn v_splat(a: f32) -> __m256 {
        _mm256_set1_ps(a)
    }
    #[inline(always)]
    unsafe fn m_bit(codes: *const u8, bit: u32) -> __m256 {
        let bytes = _mm256_cvtepu8_epi32(_mm_loadl_epi64(codes.cast()));
        let shift = _mm256_set1_epi32(31 - bit as i32);
        _mm256_castsi256_ps(_mm256_sllv_epi32(bytes, shift))
    }
    #[inline(always)]
    unsafe fn v_sign(plus: __m256, a: __m256) -> __m256 {
        _mm256_blendv_ps(_mm256_sub_ps(_mm256_setzero_ps(), a), a, plus)
    }
    #[inline(always)]
    unsafe fn v_ternary(plus: __m256, minus: __m256, a: __m256) -> __m256 {
        let gated = _mm256_blendv_ps(_mm256_setzero_ps(), a, plus);
        _mm256_blendv_ps(gated, _mm256_sub_ps(gated, a), minus)
    }
    #[inline(always)]
    unsafe fn v_pick(plus: __m256, a: __m256, b: __m256) -> __m256 {
        _mm256_blendv_ps(b, a, plus)
    }
    type D = [__m256d; 2];
    #[inline(always)]
    unsafe fn d_zero() -> [__m256d; 2] {
        [_mm256_setzero_pd(); 2]
    }
    #[inline(always)]
    unsafe fn d_widen(v: __m256) -> [__m256d; 2] {
        let high = _mm256_extractf128_ps::<1>(v);
        [
            _mm256_cvtps_pd(_mm256_castps256_ps128(v)),
            _mm256_cvtps_pd(high),
        ]
    }
    #[inline(always)]
    unsafe fn d_add(a: [__m256d; 2], b: [__m256d; 2]) -> [__m256d; 2] {
        [_mm256_add_pd(a[0], b[0]), _mm256_add_pd(a[1], b[1])]
    }
    #[inline(always)]
    unsafe fn d_add_where(plus: __m256, a: [__m256d; 2], b: [__m256d; 2]) -> [__m256d; 2] {
        // The 32-bit lanes' sign bits, sign-extended to the 64-bit lanes that the blends read.
        let m = _mm256_castps_si256(plus);
        let low = _mm256_castsi256_pd(_mm256_cvtepi32_epi64(_mm256_castsi256_si128(m)));
        let high = _mm256_castsi256_pd(_mm256_cvtepi32_epi64(_mm256_extracti128_si256::<1>(m)));
        let zero = _mm256_setzero_pd();
        [
            _mm256_add_pd(a[0], _mm256_blendv_pd(zero, b[0], low)),
            _mm256_add_pd(a[1], _mm256_blendv_pd(zero, b[1], high)),
        ]
    }
    #[inline(always)]
    unsafe fn d_sum(a: [__m256d; 2]) -> f64 {
        sum4(std::mem::transmute::<__m256d, [f64; 4]>(_mm256_add_pd(
            a[0], a[1],
        )))
    }
    #[inline(always)]
    unsafe fn v_load_half(p: *const f32) -> __m256 {
        _mm256_zextps128_ps256(_mm_load_ps(p))
    }
    #[inline(always)]
    unsafe fn v_add_half(p: *mut f32, v: __m256) {
        _mm_storeu_ps(p, _mm_add_ps(_mm_loadu_ps(p), _mm256_castps256_ps128(v)))
    }
}

#[cfg(target_arch = "x86_64")]
impl Simd for W256<f64> {
    type T = f64;
    const PER: usize = 4;
    const REGS: usize = 16;
    type V = __m256d;
    type M = __m256d;

    #[inline(always)]
    unsafe fn v_zero() -> __m256d {
        _mm256_setzero_pd()
    }
    #[inline(always)]
    unsafe fn v_load(p: *const f64) -> __m256d {
        _mm256_load_pd(p)
    }
    #[inline(always)]
    unsafe fn v_loadu(p: *const f64) -> __m256d {
        _mm256_loadu_pd(p)
    }
    #[inline(always)]
    unsafe fn v_storeu(p: *mut f64, v: __m256d) {
        _mm256_storeu_pd(p, v)
    }
    #[inline(always)]
    unsafe fn v_load_first(p: *const f64, n: usize) -> __m256d {
        let lanes = _mm256_setr_epi64x(0, 1, 2, 3);
        let mask = _mm256_cmpgt_epi64(_mm256_set1_epi64x(n.min(4) as i64), lanes);
        _mm256_maskload_pd(p, mask)
    }
    #[inline(always)]
    unsafe fn v_add(a: __m256d, b: __m256d) -> __m256d {
        _mm256_add_pd(a, b)
    }
    #[inline(always)]
    unsafe fn v_sub(a: __m256d, b: __m256d) -> __m256d {
        _mm256_sub_pd(a, b)
    }
    #[inline(always)]
    unsafe fn v_mul_add(a: __m256d, b: __m256d, c: __m256d) -> __m256d {
        _mm256_fmadd_pd(a, b, c)
    }
    #[inline(always)]
    unsafe fn v_lanes8(v: __m256d) -> [f64; 8] {
        let [a, b, c, d] = std::mem::transmute::<__m256d, [f64; 4]>(v);
        [a, b, c, d, 0.0, 0.0, 0.0, 0.0]
    }
    #[inline(always)]
    unsafe fn v_splat(a: f64) -> __m256d {
        _mm256_set1_pd(a)
    }
    #[inline(always)]
    unsafe fn m_bit(codes: *const u8, bit: u32) -> __m256d {
        let four = codes.cast::<i32>().read_unaligned();
        let bytes = _mm256_cvtepu8_epi64(_mm_cvtsi32_si128(four));
        let shift = _mm256_set1_epi64x(63 - i64::from(bit));
        _mm256_castsi256_pd(_mm256_sllv_epi64(bytes, shift))
    }
    #[inline(always)]
    unsafe fn v_sign(plus: __m256d, a: __m256d) -> __m256d {
        _mm256_blendv_pd(_mm256_sub_pd(_mm256_setzero_pd(), a), a, plus)
    }
    #[inline(always)]
    unsafe fn v_ternary(plus: __m256d, minus: __m256d, a: __m256d) -> __m256d {
        let gated = _mm256_blendv_pd(_mm256_setzero_pd(), a, plus);
        _mm256_blendv_pd(gated, _mm256_sub_pd(gated, a), minus)
    }
    #[inline(always)]
    unsafe fn v_pick(plus: __m256d, a: __m256d, b: __m256d) -> __m256d {
        _mm256_blendv_pd(b, a, plus)
    }
    type D = __m256d;
    #[inline(always)]
    unsafe fn d_zero() -> __m256d {
        _mm256_setzero_pd()
    }
    #[inline(always)]
    unsafe fn d_widen(v: __m256d) -> __m256d {
        v
    }
    #[inline(always)]
    unsafe fn d_add(a: __m256d, b: __m256d) -> __m256d {
        _mm256_add_pd(a, b)
    }
    #[inline(always)]
    unsafe fn d_add_where(plus: __m256d, a: __m256d, b: __m256d) -> __m256d {
        _mm256_add_pd(a, _mm256_blendv_pd(_mm256_setzero_pd(), b, plus))
    }
    #[inline(always)]
    unsafe fn d_sum(a: __m256d) -> f64 {
        sum4(std::mem::transmute::<__m256d, [f64; 4]>(a))
    }
    #[inline(always)]
    unsafe fn v_load_half(p: *const f64) -> __m256d {
        _mm256_zextpd128_pd256(_mm_load_pd(p))
    }
    #[inline(always)]
    unsafe fn v_add_half(p: *mut f64, v: __m256d) {
        _mm_storeu_pd(p, _mm_add_pd(_mm_loadu_pd(p), _mm256_castpd256_pd128(v)))
    }
}

/// Calls the kernel `$f::<…, Z>` for the number of vectors `$z`, one of the listed ones.
#[cfg(target_arch = "x86_64")]
macro_rules! by_vectors {
    ($z:expr, $f:ident::<$t:ty> $args:tt, [$($n:literal),*]) => {
        match $z {
            $($n => $f::<$t, $n> $args,)*
            _ => unreachable!("rows of whole vectors"),
        }
    };
}
#[cfg(target_arch = "x86_64")]
pub(crate) use by_vectors;

/// Defines `$name`, the kernel `$body::<T, S, …>` compiled for AVX-512 (`S` the 512-bit
/// flavour), and `$name256`, compiled for AVX2 (the 256-bit flavour), both generic over `T` and
/// the listed constants.
#[cfg(target_arch = "x86_64")]
macro_rules! wide_pair {
    (
        $name:ident, $name256:ident, $body:ident <$(const $c:ident: $ct:ty),*>
        ($($arg:ident: $ty:ty),*) $(-> $ret:ty)?
    ) => {
        #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
        unsafe fn $name<T: Real, $(const $c: $ct),*>($($arg: $ty),*) $(-> $ret)? {
            $body::<T, T::W512, $($c),*>($($arg),*)
        }
        #[target_feature(enable = "avx2,fma")]
        unsafe fn $name256<T: Real, $(const $c: $ct),*>($($arg: $ty),*) $(-> $ret)? {
            $body::<T, T::W256, $($c),*>($($arg),*)
        }
    };
}
#[cfg(target_arch = "x86_64")]
pub(crate) use wide_pair;
