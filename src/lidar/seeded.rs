//! Codes described by a seed: ±1 codes regenerated on demand, pixel by pixel, from a documented
//! stream, so that no code file is needed and any block of pixels (a tile) can be generated
//! alone, in memory proportional to the block.
//!
//! **The stream `chacha8-packbits-v1`** (docs/guide.md gives it with a numpy reader):
//!
//! - the ChaCha stream cipher with 8 rounds (the original layout: 16 words of 32 bits, four
//!   constants "expand 32-byte k", eight key words, a 64-bit block counter in words 12–13
//!   starting at 0, a 64-bit nonce in words 14–15), its keystream taken as bytes in order
//!   (each block's 16 words little-endian);
//! - the key is the seed as 8 little-endian bytes followed by 24 zero bytes;
//! - code set g (0 for one ADC) of an M×N array, pixel p (row-major), has the nonce g·M·N + p;
//! - the pixel's codes are the first ⌈K/8⌉ bytes of its keystream with the pad bits (the low
//!   8⌈K/8⌉ − K bits of the last byte) cleared: exactly the bytes `np.packbits(S > 0, axis=-1)`
//!   writes for its codes S, sample k in bit 7 − k mod 8 of byte ⌊k/8⌋, a set bit for +1.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::error::{Error, Result};

use super::codes::{packed_len, Codes};

/// The name of the stream of [`SeededCodes`], as meta.json gives it.
pub const SEEDED_CODES_GENERATOR: &str = "chacha8-packbits-v1";

/// ±1 codes of `sets` code sets for `pixels` pixels and `len` samples, described by a seed
/// (the stream `chacha8-packbits-v1`, specified in docs/architectures.md: ChaCha8 keyed by the
/// seed, nonce set·pixels + pixel, each pixel's first ⌈len/8⌉ keystream bytes with the pad bits
/// cleared, in the layout of [`Codes::from_packbits`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeededCodes {
    seed: u64,
    sets: usize,
    pixels: usize,
    len: usize,
    /// The first of these pixels in the whole array ([`SeededCodes::band`]); 0 for the whole.
    first: usize,
    /// Pixels per set of the whole array, which number the nonces.
    whole: usize,
}

impl SeededCodes {
    /// The codes of `sets` code sets of `pixels` pixels and `len` samples from `seed`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if a count is zero, or if the nonces sets·pixels do not fit
    /// in 64 bits.
    pub fn new(seed: u64, sets: usize, pixels: usize, len: usize) -> Result<Self> {
        if sets == 0 || pixels == 0 || len == 0 {
            return Err(Error::param(
                "codes",
                format!(
                    "seeded codes need at least one set, pixel and sample, got {sets} × {pixels} \
                     × {len}"
                ),
            ));
        }
        if sets
            .checked_mul(pixels)
            .is_none_or(|n| u64::try_from(n).is_err())
        {
            return Err(Error::param(
                "codes",
                format!("{sets} code sets of {pixels} pixels are too many to number"),
            ));
        }
        Ok(SeededCodes {
            seed,
            sets,
            pixels,
            len,
            first: 0,
            whole: pixels,
        })
    }

    /// The codes of the consecutive pixels `pixels` of these (a band of image rows, row-major),
    /// every set: pixel p of the band is pixel `pixels.start + p` here, with its codes.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an empty range or one beyond these pixels.
    pub fn band(&self, pixels: std::ops::Range<usize>) -> Result<Self> {
        if pixels.is_empty() || pixels.end > self.pixels {
            return Err(Error::param(
                "codes",
                format!(
                    "pixels {}..{} are not a band of the {} pixels of the seeded codes",
                    pixels.start, pixels.end, self.pixels
                ),
            ));
        }
        Ok(SeededCodes {
            pixels: pixels.len(),
            first: self.first + pixels.start,
            ..*self
        })
    }

    /// The first of these pixels in the whole array they are a band of (0 for the whole).
    pub fn first_pixel(&self) -> usize {
        self.first
    }

    /// The seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Number of code sets.
    pub fn sets(&self) -> usize {
        self.sets
    }

    /// Number of pixels of each set (of the band, for a [`SeededCodes::band`]).
    pub fn pixels(&self) -> usize {
        self.pixels
    }

    /// Samples per pixel (K).
    pub fn len(&self) -> usize {
        self.len
    }

    /// Always false: seeded codes have at least one sample.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Writes the packed bytes (`np.packbits` layout, [`packed_len`]`(len)` of them) of pixel
    /// `pixel` of code set `set` into `out`.
    ///
    /// # Panics
    /// If `set` or `pixel` is out of range or `out` does not hold [`packed_len`]`(len)` bytes.
    pub fn pixel_bytes(&self, set: usize, pixel: usize, out: &mut [u8]) {
        assert!(
            set < self.sets && pixel < self.pixels,
            "pixel ({set}, {pixel}) out of range"
        );
        assert_eq!(out.len(), packed_len(self.len), "bytes per pixel");
        let mut key = [0u8; 32];
        key[..8].copy_from_slice(&self.seed.to_le_bytes());
        let mut rng = ChaCha8Rng::from_seed(key);
        rng.set_stream((set * self.whole + self.first + pixel) as u64);
        rng.fill_bytes(out);
        let pad = 8 * out.len() - self.len;
        if let Some(last) = out.last_mut() {
            *last &= 0xffu8 << pad;
        }
    }

    /// The codes of the pixels `pixels` of code set `set`, in that order (a tile's codes),
    /// generated in parallel.
    ///
    /// # Errors
    /// [`Error::IndexOutOfBounds`] for a set or pixel out of range; [`Error::InvalidParameter`]
    /// for an empty selection.
    pub fn select(&self, set: usize, pixels: &[usize]) -> Result<Codes> {
        if set >= self.sets {
            return Err(Error::IndexOutOfBounds {
                context: "code set",
                index: set,
                len: self.sets,
            });
        }
        if let Some(&bad) = pixels.iter().find(|&&p| p >= self.pixels) {
            return Err(Error::IndexOutOfBounds {
                context: "pixel selection",
                index: bad,
                len: self.pixels,
            });
        }
        let nb = packed_len(self.len);
        let mut bytes = vec![0u8; pixels.len() * nb];
        bytes
            .par_chunks_mut(nb)
            .zip(pixels.par_iter())
            .for_each(|(out, &p)| self.pixel_bytes(set, p, out));
        Codes::from_packbits(&bytes, pixels.len(), self.len)
    }

    /// Every pixel's codes of code set `set`.
    ///
    /// # Errors
    /// As [`SeededCodes::select`].
    pub fn materialize(&self, set: usize) -> Result<Codes> {
        let all: Vec<usize> = (0..self.pixels).collect();
        self.select(set, &all)
    }
}
