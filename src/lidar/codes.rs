//! Per-pixel modulation codes s[p, k], bit-packed.
//!
//! Pixels are taken eight at a time (`group g` holds pixels 8g … 8g+7, in the row-major order of
//! the scene) and, for every sample k, the codes of a group are one byte whose bit i belongs to
//! pixel 8g + i. A ±1 code needs one such bit plane (bit set ⇔ s = +1); a ternary code needs two
//! (s = +1 and s = −1; neither ⇔ s = 0). This is the layout the fused operator's table lookups
//! read directly: 1 bit per ±1 entry (37.5 MB at 100×100 pixels and K = 30 039), never a dense
//! float array.

use ndarray::{Array2, ArrayView2, Axis};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::error::{Error, Result};

/// The values a code takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CodeAlphabet {
    /// s ∈ {−1, +1}: one bit per entry.
    Binary,
    /// s ∈ {−1, 0, +1}: two bits per entry.
    Ternary,
}

impl CodeAlphabet {
    /// "binary" or "ternary".
    pub fn name(&self) -> &'static str {
        match self {
            CodeAlphabet::Binary => "binary",
            CodeAlphabet::Ternary => "ternary",
        }
    }
}

/// The code bytes of a run of consecutive groups in one plane, as [`Codes`] stores them: the
/// run's group g has its byte of sample k at `bytes[g·stride + k]`. The table kernels reach
/// every group's byte of a sample from one pointer and the stride; a slice per group cost them
/// a load of the slice's pointer for every group and sample (the forward ran 8–10% faster
/// without).
#[derive(Debug, Clone, Copy)]
pub(crate) struct GroupBytes<'a> {
    bytes: &'a [u8],
    stride: usize,
}

impl<'a> GroupBytes<'a> {
    /// The groups `groups` of a plane of groups of `stride` bytes each.
    ///
    /// # Panics
    /// If the plane does not hold the groups.
    pub(crate) fn new(plane: &'a [u8], stride: usize, groups: std::ops::Range<usize>) -> Self {
        let bytes = &plane[groups.start * stride..groups.end * stride];
        Self { bytes, stride }
    }

    /// Groups in the run.
    pub(crate) fn groups(&self) -> usize {
        self.bytes.len().checked_div(self.stride).unwrap_or(0)
    }

    /// Bytes per group (samples).
    pub(crate) fn stride(&self) -> usize {
        self.stride
    }

    /// The bytes of the run's group `g`.
    pub(crate) fn group(&self, g: usize) -> &'a [u8] {
        &self.bytes[g * self.stride..(g + 1) * self.stride]
    }

    /// Asks the cache for the bytes `from .. from + 64` of the run's group `g` (when the run has
    /// that group): a hint for a byte that a kernel reads later, without effect on any value.
    #[inline(always)]
    pub(crate) fn prefetch(&self, g: usize, from: usize) {
        #[cfg(target_arch = "x86_64")]
        if g < self.groups() && from < self.stride {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let at = self.bytes[g * self.stride + from..].as_ptr();
            // SAFETY: a prefetch neither reads a value nor faults, whatever the address; the
            // second line's address is formed with `wrapping_add`, without claiming it in bounds.
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>(at.cast());
                _mm_prefetch::<_MM_HINT_T0>(at.wrapping_add(63).cast());
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (g, from);
    }

    /// The first group's first byte: group g's byte of sample k lies `g·stride + k` after it.
    pub(crate) fn as_ptr(&self) -> *const u8 {
        self.bytes.as_ptr()
    }
}

/// Bit-packed codes for `pixels` pixels and `len` samples (K).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Codes {
    pixels: usize,
    len: usize,
    /// Byte `g·len + k`, bit i: s[8g + i, k] = +1.
    plus: Vec<u8>,
    /// Ternary only. Byte `g·len + k`, bit i: s[8g + i, k] = −1.
    minus: Option<Vec<u8>>,
}

/// Bits of the last group that belong to real pixels.
fn tail_mask(pixels: usize) -> u8 {
    match pixels % 8 {
        0 => 0xff,
        r => (1u8 << r) - 1,
    }
}

/// Transposes an 8×8 bit matrix held in a `u64`: the bit of row r, column c (bit 8r + c) moves
/// to bit 8c + r. Three rounds of swaps of ever larger blocks across the diagonal.
fn transpose8(mut x: u64) -> u64 {
    let t = (x ^ (x >> 7)) & 0x00AA_00AA_00AA_00AA;
    x ^= t ^ (t << 7);
    let t = (x ^ (x >> 14)) & 0x0000_CCCC_0000_CCCC;
    x ^= t ^ (t << 14);
    let t = (x ^ (x >> 28)) & 0x0000_0000_F0F0_F0F0;
    x ^= t ^ (t << 28);
    x
}

/// Bytes per pixel of ±1 codes of `len` samples in numpy's `packbits` layout: ⌈len / 8⌉.
pub fn packed_len(len: usize) -> usize {
    len.div_ceil(8)
}

fn check_dims(pixels: usize, len: usize) -> Result<()> {
    if pixels == 0 || len == 0 {
        return Err(Error::param(
            "codes",
            format!("need at least one pixel and one sample, got {pixels} pixels × {len} samples"),
        ));
    }
    Ok(())
}

impl Codes {
    /// Number of 8-pixel groups, ⌈pixels / 8⌉.
    pub fn groups(&self) -> usize {
        self.pixels.div_ceil(8)
    }

    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.pixels
    }

    /// Number of samples K.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Always `false`: codes have at least one sample.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The alphabet.
    pub fn alphabet(&self) -> CodeAlphabet {
        if self.minus.is_some() {
            CodeAlphabet::Ternary
        } else {
            CodeAlphabet::Binary
        }
    }

    /// Bytes held (the codes' memory footprint).
    pub fn memory_bytes(&self) -> usize {
        self.plus.len() + self.minus.as_ref().map_or(0, Vec::len)
    }

    /// The +1 plane: `len` bytes per group, group after group.
    pub fn plus_plane(&self) -> &[u8] {
        &self.plus
    }

    /// The −1 plane of ternary codes.
    pub fn minus_plane(&self) -> Option<&[u8]> {
        self.minus.as_deref()
    }

    /// The +1 bytes and (ternary codes) the −1 bytes of the groups `groups`, as the table
    /// kernels read them.
    ///
    /// # Panics
    /// If `groups` goes past the last group.
    pub(crate) fn group_bytes(
        &self,
        groups: std::ops::Range<usize>,
    ) -> (GroupBytes<'_>, Option<GroupBytes<'_>>) {
        let run = |plane| GroupBytes::new(plane, self.len, groups.clone());
        (run(&self.plus), self.minus.as_deref().map(run))
    }

    /// The +1 bytes of group `g` (one per sample).
    pub fn plus_group(&self, g: usize) -> &[u8] {
        &self.plus[g * self.len..(g + 1) * self.len]
    }

    /// The −1 bytes of group `g` (ternary codes only).
    pub fn minus_group(&self, g: usize) -> Option<&[u8]> {
        self.minus
            .as_ref()
            .map(|m| &m[g * self.len..(g + 1) * self.len])
    }

    /// s[pixel, k].
    ///
    /// # Panics
    /// If `pixel` or `k` is out of range.
    pub fn get(&self, pixel: usize, k: usize) -> i8 {
        assert!(
            pixel < self.pixels && k < self.len,
            "code index ({pixel}, {k}) out of range"
        );
        let at = (pixel / 8) * self.len + k;
        let bit = 1u8 << (pixel % 8);
        if self.plus[at] & bit != 0 {
            1
        } else if self.minus.as_ref().is_some_and(|m| m[at] & bit != 0) {
            -1
        } else if self.minus.is_some() {
            0
        } else {
            -1
        }
    }

    /// I.i.d. equiprobable ±1 codes from a ChaCha8 stream seeded with `seed` (the bytes of the +1
    /// plane are the stream's bytes in order, the unused bits of the last group cleared).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `pixels` or `len` is zero.
    pub fn random_binary(pixels: usize, len: usize, seed: u64) -> Result<Self> {
        check_dims(pixels, len)?;
        let groups = pixels.div_ceil(8);
        let mut plus = vec![0u8; groups * len];
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.fill_bytes(&mut plus);
        let mask = tail_mask(pixels);
        plus[(groups - 1) * len..]
            .iter_mut()
            .for_each(|b| *b &= mask);
        Ok(Codes {
            pixels,
            len,
            plus,
            minus: None,
        })
    }

    /// I.i.d. ternary codes: 0 with probability `zero_prob`, ±1 with probability
    /// (1 − zero_prob)/2 each, from a ChaCha8 stream seeded with `seed` (one `u32` draw per entry,
    /// group by group, sample by sample, pixel by pixel within a group).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `pixels` or `len` is zero or `zero_prob` is not in [0, 1).
    pub fn random_ternary(pixels: usize, len: usize, zero_prob: f64, seed: u64) -> Result<Self> {
        check_dims(pixels, len)?;
        if !(0.0..1.0).contains(&zero_prob) {
            return Err(Error::param(
                "zero_prob",
                format!("must be in [0, 1), got {}", crate::units::number(zero_prob)),
            ));
        }
        let groups = pixels.div_ceil(8);
        let mut plus = vec![0u8; groups * len];
        let mut minus = vec![0u8; groups * len];
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let zero_cut = (zero_prob * 4_294_967_296.0) as u64;
        let half = zero_cut + (4_294_967_296 - zero_cut) / 2;
        for g in 0..groups {
            let width = (pixels - 8 * g).min(8);
            for k in 0..len {
                let (mut p, mut m) = (0u8, 0u8);
                for i in 0..width {
                    let u = rng.next_u32() as u64;
                    if u >= half {
                        p |= 1 << i;
                    } else if u >= zero_cut {
                        m |= 1 << i;
                    }
                }
                plus[g * len + k] = p;
                minus[g * len + k] = m;
            }
        }
        Ok(Codes {
            pixels,
            len,
            plus,
            minus: Some(minus),
        })
    }

    /// Packs a dense `(pixels, len)` array of codes. The alphabet is binary when no entry is 0,
    /// ternary otherwise.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first entry outside {−1, 0, 1}, or for an empty
    /// array.
    pub fn from_dense(s: ArrayView2<'_, i8>) -> Result<Self> {
        /// A group's first entry outside {−1, 0, 1} (pixel, sample, value) and whether it holds
        /// a 0.
        type GroupScan = (Option<(usize, usize, i8)>, bool);
        let (pixels, len) = s.dim();
        check_dims(pixels, len)?;
        let groups = pixels.div_ceil(8);
        let rows = move |g: usize| {
            (8 * g..(8 * g + 8).min(pixels)).map(move |p| (p, s.index_axis_move(Axis(0), p)))
        };
        // Each group of eight rows in parallel: its first entry outside {−1, 0, 1} (the groups
        // in order, so the first of the array is named) and whether it holds a 0.
        let scans: Vec<GroupScan> = (0..groups)
            .into_par_iter()
            .map(|g| {
                let mut zero = false;
                for (p, row) in rows(g) {
                    // The row's range and zeros without a branch per entry (a contiguous row is
                    // scanned in vectors), then the first bad entry only if there is one.
                    let (mut lo, mut hi) = (0i8, 0i8);
                    let mut scan = |v: i8| {
                        (lo, hi) = (lo.min(v), hi.max(v));
                        zero |= v == 0;
                    };
                    match row.as_slice() {
                        Some(values) => values.iter().for_each(|&v| scan(v)),
                        None => row.iter().for_each(|&v| scan(v)),
                    }
                    if lo < -1 || hi > 1 {
                        let (k, &v) = row
                            .iter()
                            .enumerate()
                            .find(|(_, v)| !(-1..=1).contains(*v))
                            .expect("an entry outside {-1, 0, 1}");
                        return (Some((p, k, v)), zero);
                    }
                }
                (None, zero)
            })
            .collect();
        if let Some((p, k, v)) = scans.iter().find_map(|scan| scan.0) {
            return Err(Error::param(
                "codes",
                format!("entry {v} at pixel {p}, sample {k} is not in {{-1, 0, 1}}"),
            ));
        }
        let ternary = scans.iter().any(|scan| scan.1);
        // A group's bytes: bit i of byte k is pixel 8g + i's code at sample k (+1 in `plus`,
        // −1 in `minus`).
        let pack = |g: usize, plus: &mut [u8], mut minus: Option<&mut [u8]>| {
            fn set(dst: &mut [u8], row: &[i8], value: i8, bit: u8) {
                for (d, &v) in dst.iter_mut().zip(row) {
                    *d |= u8::from(v == value) * bit;
                }
            }
            // A contiguous row is packed in vectors; a strided view's row through one copy
            // buffer for the group.
            let mut copy = Vec::new();
            for (p, row) in rows(g) {
                let bit = 1u8 << (p % 8);
                let values = match row.as_slice() {
                    Some(values) => values,
                    None => {
                        copy.clear();
                        copy.extend(row.iter());
                        &copy[..]
                    }
                };
                set(plus, values, 1, bit);
                if let Some(m) = minus.as_deref_mut() {
                    set(m, values, -1, bit);
                }
            }
        };
        let mut plus = vec![0u8; groups * len];
        let mut minus = ternary.then(|| vec![0u8; groups * len]);
        match minus.as_mut() {
            Some(m) => plus
                .par_chunks_mut(len)
                .zip(m.par_chunks_mut(len))
                .enumerate()
                .for_each(|(g, (pg, mg))| pack(g, pg, Some(mg))),
            None => plus
                .par_chunks_mut(len)
                .enumerate()
                .for_each(|(g, pg)| pack(g, pg, None)),
        }
        Ok(Codes {
            pixels,
            len,
            plus,
            minus,
        })
    }

    /// ±1 codes from the bytes `np.packbits(S > 0, axis=-1)` makes of a `(pixels, len)` array S:
    /// [`packed_len`]`(len)` bytes per pixel, pixel after pixel; in each byte the earliest sample
    /// is the most significant bit (numpy's default, big-endian bit order); a set bit is +1, a
    /// clear one −1; the pad bits after the last sample are zero.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if `pixels` or `len` is zero, if `bytes` does not hold
    /// `pixels · ⌈len/8⌉` bytes, or naming the first pixel whose pad bits are not all zero.
    pub fn from_packbits(bytes: &[u8], pixels: usize, len: usize) -> Result<Self> {
        check_dims(pixels, len)?;
        let nb = packed_len(len);
        if Some(bytes.len()) != pixels.checked_mul(nb) {
            return Err(Error::param(
                "codes",
                format!(
                    "packed codes of {pixels} pixels × {len} samples take {pixels} × {nb} bytes, \
                     got {}",
                    bytes.len()
                ),
            ));
        }
        let pad = nb * 8 - len;
        if pad > 0 {
            let mask = (1u8 << pad) - 1;
            if let Some(p) = (0..pixels).find(|p| bytes[p * nb + nb - 1] & mask != 0) {
                return Err(Error::param(
                    "codes",
                    format!(
                        "pixel {p}: the {pad} pad bit(s) after sample {} are not zero \
                         (np.packbits writes zeros there)",
                        len - 1
                    ),
                ));
            }
        }
        let groups = pixels.div_ceil(8);
        let mut plus = vec![0u8; groups * len];
        for (g, dst) in plus.chunks_exact_mut(len).enumerate() {
            let width = (pixels - 8 * g).min(8);
            for j in 0..nb {
                // Row r: the byte of pixel 8g + r, bit c = sample 8j + c.
                let x = (0..width).fold(0u64, |x, r| {
                    x | u64::from(bytes[(8 * g + r) * nb + j].reverse_bits()) << (8 * r)
                });
                // Byte c of the transpose: sample 8j + c, bit r = pixel 8g + r.
                let t = transpose8(x).to_le_bytes();
                let take = (len - 8 * j).min(8);
                dst[8 * j..8 * j + take].copy_from_slice(&t[..take]);
            }
        }
        Ok(Codes {
            pixels,
            len,
            plus,
            minus: None,
        })
    }

    /// The bytes `np.packbits(S > 0, axis=-1)` makes of these codes S as a `(pixels, len)`
    /// array (see [`Codes::from_packbits`]): one bit per entry.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for codes with 0 entries (ternary, or a coded aperture's
    /// masked pixels), which one bit per entry cannot hold.
    pub fn to_packbits(&self) -> Result<Vec<u8>> {
        if self.minus.is_some() {
            return Err(Error::param(
                "codes",
                "packed codes hold ±1 entries only, and these codes have 0 entries \
                 (ternary codes or a coded aperture): write them as int8",
            ));
        }
        let (len, nb) = (self.len, packed_len(self.len));
        let mut out = vec![0u8; self.pixels * nb];
        for (g, src) in self.plus.chunks_exact(len).enumerate() {
            let width = (self.pixels - 8 * g).min(8);
            for j in 0..nb {
                let take = (len - 8 * j).min(8);
                let mut b = [0u8; 8];
                b[..take].copy_from_slice(&src[8 * j..8 * j + take]);
                let t = transpose8(u64::from_le_bytes(b));
                for r in 0..width {
                    out[(8 * g + r) * nb + j] = ((t >> (8 * r)) as u8).reverse_bits();
                }
            }
        }
        Ok(out)
    }

    /// Per pixel, whether any of its codes is nonzero: a pixel whose codes are all zero (blocked
    /// by a coded aperture) reaches no ADC. All true for ±1 codes.
    pub fn observed_pixels(&self) -> Vec<bool> {
        let Some(minus) = &self.minus else {
            return vec![true; self.pixels];
        };
        let mut out = Vec::with_capacity(self.pixels);
        for (plus, minus) in self
            .plus
            .chunks_exact(self.len)
            .zip(minus.chunks_exact(self.len))
        {
            let any = plus.iter().zip(minus).fold(0u8, |acc, (p, m)| acc | p | m);
            let width = (self.pixels - out.len()).min(8);
            out.extend((0..width).map(|r| any & (1 << r) != 0));
        }
        out
    }

    /// These codes with s[p, k] = 0 wherever `zero[row_of(p)][k]` holds: the samples that one
    /// ADC's measurements cannot use (e.g. clipped ones) removed from the pixels that ADC sums.
    /// The result is ternary (±1 codes gain their −1 plane). `row_of(p)` names the mask of
    /// pixel `p` (its ADC: 0 for one ADC, the tile of a tiled array).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`codes`) when a mask does not have `len` samples or
    /// `row_of` names a mask that does not exist.
    pub fn zero_samples(
        &self,
        zero: &[Vec<bool>],
        row_of: &dyn Fn(usize) -> usize,
    ) -> Result<Self> {
        if let Some(bad) = zero.iter().find(|z| z.len() != self.len) {
            return Err(Error::param(
                "codes",
                format!("a mask of {} samples for codes of {}", bad.len(), self.len),
            ));
        }
        let len = self.len;
        let mut plus = self.plus.clone();
        let tail = tail_mask(self.pixels);
        let groups = self.groups();
        let mut minus = match &self.minus {
            Some(m) => m.clone(),
            None => plus
                .chunks_exact(len)
                .enumerate()
                .flat_map(|(g, bytes)| {
                    let valid = if g + 1 == groups { tail } else { 0xff };
                    bytes.iter().map(move |b| !b & valid)
                })
                .collect(),
        };
        for g in 0..groups {
            let width = (self.pixels - 8 * g).min(8);
            let mut rows = [0usize; 8];
            for (i, r) in rows.iter_mut().enumerate().take(width) {
                *r = row_of(8 * g + i);
                if *r >= zero.len() {
                    return Err(Error::param(
                        "codes",
                        format!("pixel {} names mask {r} of {}", 8 * g + i, zero.len()),
                    ));
                }
            }
            let (p, m) = (
                &mut plus[g * len..(g + 1) * len],
                &mut minus[g * len..(g + 1) * len],
            );
            let same = rows[..width].iter().all(|&r| r == rows[0]);
            for k in 0..len {
                let clear = if same {
                    if zero[rows[0]][k] {
                        0xff
                    } else {
                        0
                    }
                } else {
                    (0..width).fold(0u8, |acc, i| acc | (u8::from(zero[rows[i]][k]) << i))
                };
                p[k] &= !clear;
                m[k] &= !clear;
            }
        }
        Ok(Codes {
            pixels: self.pixels,
            len,
            plus,
            minus: Some(minus),
        })
    }

    /// The codes as a dense `(pixels, len)` array (for small problems and file output).
    pub fn to_dense(&self) -> Array2<i8> {
        Array2::from_shape_fn((self.pixels, self.len), |(p, k)| self.get(p, k))
    }

    /// The codes of the pixels `idx` (in that order), e.g. a sub-array or one ADC's group.
    ///
    /// # Errors
    /// [`Error::IndexOutOfBounds`] for a pixel index not below `pixels`, [`Error::InvalidParameter`]
    /// for an empty selection.
    pub fn select_pixels(&self, idx: &[usize]) -> Result<Self> {
        check_dims(idx.len(), self.len)?;
        if let Some(&bad) = idx.iter().find(|&&p| p >= self.pixels) {
            return Err(Error::IndexOutOfBounds {
                context: "pixel selection",
                index: bad,
                len: self.pixels,
            });
        }
        let groups = idx.len().div_ceil(8);
        let len = self.len;
        let mut plus = vec![0u8; groups * len];
        let mut minus = self.minus.as_ref().map(|_| vec![0u8; groups * len]);
        for (q, &p) in idx.iter().enumerate() {
            let (src, sb) = ((p / 8) * len, p % 8);
            let (dst, db) = ((q / 8) * len, q % 8);
            for k in 0..len {
                plus[dst + k] |= ((self.plus[src + k] >> sb) & 1) << db;
            }
            if let (Some(m), Some(sm)) = (minus.as_mut(), self.minus.as_ref()) {
                for k in 0..len {
                    m[dst + k] |= ((sm[src + k] >> sb) & 1) << db;
                }
            }
        }
        Ok(Codes {
            pixels: idx.len(),
            len,
            plus,
            minus,
        })
    }
}
