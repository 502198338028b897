//! Codes described by a seed: the stream `chacha8-packbits-v1` as docs/guide.md specifies it,
//! checked against an implementation of ChaCha8 written here from the specification, a golden
//! hash that pins it across versions and platforms, and tiles generated alone.

use rdlidar::lidar::{packed_len, Codes, SeededCodes};

/// One ChaCha block with 8 rounds (the original layout: constants, key, 64-bit counter, 64-bit
/// nonce), as 64 bytes.
fn chacha8_block(key: &[u8; 32], counter: u64, nonce: u64) -> [u8; 64] {
    let word = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    let mut s = [0u32; 16];
    s[..4].copy_from_slice(&[0x6170_7865, 0x3320_646e, 0x7962_2d32, 0x6b20_6574]);
    for i in 0..8 {
        s[4 + i] = word(&key[4 * i..]);
    }
    s[12] = counter as u32;
    s[13] = (counter >> 32) as u32;
    s[14] = nonce as u32;
    s[15] = (nonce >> 32) as u32;
    let mut x = s;
    let qr = |x: &mut [u32; 16], a: usize, b: usize, c: usize, d: usize| {
        x[a] = x[a].wrapping_add(x[b]);
        x[d] = (x[d] ^ x[a]).rotate_left(16);
        x[c] = x[c].wrapping_add(x[d]);
        x[b] = (x[b] ^ x[c]).rotate_left(12);
        x[a] = x[a].wrapping_add(x[b]);
        x[d] = (x[d] ^ x[a]).rotate_left(8);
        x[c] = x[c].wrapping_add(x[d]);
        x[b] = (x[b] ^ x[c]).rotate_left(7);
    };
    for _ in 0..4 {
        qr(&mut x, 0, 4, 8, 12);
        qr(&mut x, 1, 5, 9, 13);
        qr(&mut x, 2, 6, 10, 14);
        qr(&mut x, 3, 7, 11, 15);
        qr(&mut x, 0, 5, 10, 15);
        qr(&mut x, 1, 6, 11, 12);
        qr(&mut x, 2, 7, 8, 13);
        qr(&mut x, 3, 4, 9, 14);
    }
    let mut out = [0u8; 64];
    for i in 0..16 {
        out[4 * i..4 * i + 4].copy_from_slice(&x[i].wrapping_add(s[i]).to_le_bytes());
    }
    out
}

/// The bytes of pixel `pixel` of set `set` as the specification gives them.
fn specified(seed: u64, sets_pixels: usize, set: usize, pixel: usize, len: usize) -> Vec<u8> {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    let nonce = (set * sets_pixels + pixel) as u64;
    let nb = len.div_ceil(8);
    let mut out: Vec<u8> = (0..nb.div_ceil(64) as u64)
        .flat_map(|c| chacha8_block(&key, c, nonce))
        .take(nb)
        .collect();
    let pad = 8 * nb - len;
    *out.last_mut().unwrap() &= 0xff << pad;
    out
}

#[test]
fn the_stream_is_chacha8_keyed_by_the_seed_with_one_nonce_per_pixel() {
    for (seed, sets, pixels, len) in [(0u64, 1, 5, 13), (7, 2, 9, 200), (u64::MAX, 3, 4, 1030)] {
        let s = SeededCodes::new(seed, sets, pixels, len).unwrap();
        let mut got = vec![0u8; packed_len(len)];
        for set in 0..sets {
            for p in 0..pixels {
                s.pixel_bytes(set, p, &mut got);
                assert_eq!(
                    got,
                    specified(seed, pixels, set, p, len),
                    "{seed} {set} {p}"
                );
            }
        }
    }
}

/// FNV-1a, 64 bits.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

#[test]
fn the_stream_is_pinned_by_a_golden_hash() {
    // 2 code sets of 37 pixels × 1001 samples from seed 20260101: if this changes, files
    // described by a seed no longer give the codes they were simulated with.
    let s = SeededCodes::new(20_260_101, 2, 37, 1001).unwrap();
    let bytes: Vec<u8> = (0..2)
        .flat_map(|set| s.materialize(set).unwrap().to_packbits().unwrap())
        .collect();
    assert_eq!(bytes.len(), 2 * 37 * 126);
    assert_eq!(fnv1a(&bytes), GOLDEN, "{:#018x}", fnv1a(&bytes));
}

const GOLDEN: u64 = 0xdc5b_533b_e2b3_3545;

#[test]
fn a_tile_is_generated_alone_equal_to_its_pixels_of_the_whole_array() {
    let s = SeededCodes::new(3, 2, 60, 77).unwrap();
    let tile = [7, 8, 9, 19, 20, 21, 31, 32, 33, 59];
    for set in 0..2 {
        let whole = s.materialize(set).unwrap();
        assert_eq!(
            s.select(set, &tile).unwrap(),
            whole.select_pixels(&tile).unwrap()
        );
        // Balanced ±1 codes: about half of the entries are +1.
        let plus = whole.to_dense().iter().filter(|&&v| v == 1).count();
        let n = 60 * 77;
        assert!((plus as f64 - n as f64 / 2.0).abs() < 4.0 * (n as f64 / 4.0).sqrt());
    }
    // The sets differ.
    assert_ne!(s.materialize(0).unwrap(), s.materialize(1).unwrap());
    assert!(s.select(2, &tile).is_err());
    assert!(s.select(0, &[60]).is_err());
    assert!(SeededCodes::new(1, 0, 5, 5).is_err());
    let _: Codes = s.select(1, &[0]).unwrap();
}

#[test]
fn a_band_of_seeded_codes_is_those_pixels_of_the_whole() {
    let whole = SeededCodes::new(17, 2, 40, 37).unwrap();
    let band = whole.band(10..25).unwrap();
    assert_eq!(
        (band.pixels(), band.first_pixel(), band.sets()),
        (15, 10, 2)
    );
    let inner = band.band(5..9).unwrap();
    assert_eq!(inner.first_pixel(), 15);
    for set in 0..2 {
        let all: Vec<usize> = (0..15).collect();
        let rows: Vec<usize> = (10..25).collect();
        assert_eq!(
            band.select(set, &all).unwrap().to_dense(),
            whole.select(set, &rows).unwrap().to_dense()
        );
        assert_eq!(
            inner.materialize(set).unwrap().to_dense(),
            whole.select(set, &[15, 16, 17, 18]).unwrap().to_dense()
        );
    }
    assert!(whole.band(30..41).is_err());
    assert!(whole.band(3..3).is_err());
}
