//! Codes in numpy's `packbits` layout: agreement with a direct bit-by-bit packing, round trips,
//! and refusals.

use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rdlidar::lidar::{packed_len, Codes};

/// `np.packbits(S > 0, axis=-1)` of a (pixels, len) ±1 array, bit by bit.
fn packbits(s: &Array2<i8>) -> Vec<u8> {
    let (pixels, len) = s.dim();
    let nb = len.div_ceil(8);
    let mut out = vec![0u8; pixels * nb];
    for p in 0..pixels {
        for k in 0..len {
            if s[[p, k]] > 0 {
                out[p * nb + k / 8] |= 0x80 >> (k % 8);
            }
        }
    }
    out
}

fn random_signs(pixels: usize, len: usize, seed: u64) -> Array2<i8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    Array2::from_shape_fn((pixels, len), |_| if rng.random_bool(0.5) { 1 } else { -1 })
}

#[test]
fn packbits_bytes_give_the_codes_of_the_dense_array_at_odd_sizes() {
    let mut seed = 0;
    for pixels in [1, 3, 7, 8, 9, 15, 16, 17, 29] {
        for len in [1, 2, 7, 8, 9, 13, 16, 23, 64, 65] {
            seed += 1;
            let s = random_signs(pixels, len, seed);
            let bytes = packbits(&s);
            assert_eq!(bytes.len(), pixels * packed_len(len));
            let from_bits = Codes::from_packbits(&bytes, pixels, len).unwrap();
            let from_dense = Codes::from_dense(s.view()).unwrap();
            assert_eq!(from_bits, from_dense, "{pixels} pixels × {len} samples");
            assert_eq!(from_bits.to_dense(), s, "{pixels} × {len}");
            assert_eq!(from_dense.to_packbits().unwrap(), bytes, "{pixels} × {len}");
        }
    }
}

#[test]
fn random_codes_survive_a_packbits_round_trip() {
    let codes = Codes::random_binary(37, 101, 5).unwrap();
    let bytes = codes.to_packbits().unwrap();
    assert_eq!(bytes, packbits(&codes.to_dense()));
    assert_eq!(Codes::from_packbits(&bytes, 37, 101).unwrap(), codes);
}

#[test]
fn packbits_with_nonzero_pad_bits_or_the_wrong_length_are_refused() {
    let s = random_signs(5, 11, 9);
    let mut bytes = packbits(&s);
    // 11 samples: 2 bytes per pixel, the last 5 bits of each second byte are padding.
    bytes[3 * 2 + 1] |= 0x01;
    let e = Codes::from_packbits(&bytes, 5, 11).unwrap_err().to_string();
    assert!(e.contains("pixel 3") && e.contains("pad bit"), "{e}");
    let e = Codes::from_packbits(&bytes[..9], 5, 11)
        .unwrap_err()
        .to_string();
    assert!(e.contains("5 × 2 bytes, got 9"), "{e}");
    assert!(Codes::from_packbits(&[], 0, 11).is_err());
    // A whole number of bytes per pixel has no padding to check.
    let full = packbits(&random_signs(3, 16, 10));
    assert!(Codes::from_packbits(&full, 3, 16).is_ok());
}

#[test]
fn codes_with_zero_entries_cannot_be_packed_one_bit_per_entry() {
    let ternary = Codes::random_ternary(9, 20, 0.3, 1).unwrap();
    let e = ternary.to_packbits().unwrap_err().to_string();
    assert!(e.contains("±1 entries only") && e.contains("int8"), "{e}");
}

#[test]
fn dense_codes_are_packed_entry_for_entry_and_the_first_bad_entry_is_named() {
    // 21 pixels (three groups, the last partial); zeros only in the last group's pixels make
    // the whole set ternary.
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let mut s = Array2::from_shape_fn((21, 37), |_| if rng.random_bool(0.5) { 1i8 } else { -1 });
    s[[20, 5]] = 0;
    s[[17, 36]] = 0;
    let codes = Codes::from_dense(s.view()).unwrap();
    assert_eq!(codes.alphabet(), rdlidar::lidar::CodeAlphabet::Ternary);
    assert_eq!(codes.to_dense(), s);
    // A view that is not in row-major order (the transpose of a (len, pixels) array) packs the
    // same.
    let t = s.t().to_owned();
    assert_eq!(Codes::from_dense(t.t()).unwrap(), codes);
    // Bad entries in the third group and the first: the first in row-major order is named.
    s[[18, 2]] = 7;
    s[[3, 30]] = -128;
    s[[3, 31]] = 2;
    let e = Codes::from_dense(s.view()).unwrap_err().to_string();
    assert!(e.contains("entry -128 at pixel 3, sample 30"), "{e}");
    // The same from a view that is not in row-major order.
    let t = s.t().to_owned();
    let e = Codes::from_dense(t.t()).unwrap_err().to_string();
    assert!(e.contains("entry -128 at pixel 3, sample 30"), "{e}");
}
