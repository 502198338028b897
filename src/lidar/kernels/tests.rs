//! Tests of the kernels against direct sums, on every instruction set this CPU has.

use super::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Random code bytes of `groups` groups over `k` samples: the +1 plane, and a −1 plane that is
/// zero wherever the +1 plane is set (ternary codes).
pub(super) fn random_planes(
    rng: &mut ChaCha8Rng,
    groups: usize,
    k: usize,
) -> (Vec<Vec<u8>>, Vec<Vec<u8>>) {
    let plus: Vec<Vec<u8>> = (0..groups)
        .map(|_| (0..k).map(|_| rng.random()).collect())
        .collect();
    let minus = plus
        .iter()
        .map(|p| p.iter().map(|&b| !b & rng.random::<u8>()).collect())
        .collect();
    (plus, minus)
}

#[test]
fn transpose8_swaps_samples_and_pixels() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    for _ in 0..200 {
        let x: u64 = rng.random();
        let t = transpose8(x);
        for s in 0..8 {
            for p in 0..8 {
                assert_eq!((x >> (8 * s + p)) & 1, (t >> (8 * p + s)) & 1);
            }
        }
        assert_eq!(transpose8(t), x);
    }
}

/// The chunk kernel against the direct sum Σ_k s_i(k)·y[k]·p[k − j] on every instruction
/// set, binary and ternary codes, with a K that is not a multiple of eight (the last octets
/// run past the end) and two chunks.
#[test]
fn adjoint_chunk_matches_the_direct_sum() {
    const NCH: usize = 2;
    let mut rng = ChaCha8Rng::seed_from_u64(27);
    let (groups, k) = (3usize, 8 * ADJ_OCTETS + 13);
    let kp = k + 1 - 8 * NCH;
    let y: Vec<f64> = (0..k).map(|_| rng.random_range(-1.0..1.0)).collect();
    let pulse: Vec<f64> = (0..kp)
        .map(|_| f64::from(rng.random_range(0..2u8)))
        .collect();
    // prev as the operator lays it out: p[k − j] = prev[base0 − k + j], zero outside.
    let pad = 8 * NCH;
    let mut prev = vec![0.0; pad + kp + 8 * NCH];
    for (t, &v) in pulse.iter().rev().enumerate() {
        prev[pad + t] = v;
    }
    let base0 = pad + kp - 1;
    let (plus, minus) = random_planes(&mut rng, groups, k);
    let plus_refs: Vec<&[u8]> = plus.iter().map(|v| v.as_slice()).collect();
    let minus_refs: Vec<&[u8]> = minus.iter().map(|v| v.as_slice()).collect();
    let mut isas = vec![Isa::Generic, Isa::best()];
    isas.dedup();
    for ternary in [false, true] {
        let sign = |g: usize, i: usize, kk: usize| -> f64 {
            let p = f64::from((plus[g][kk] >> i) & 1);
            if ternary {
                p - f64::from((minus[g][kk] >> i) & 1)
            } else {
                2.0 * p - 1.0
            }
        };
        for &isa in &isas {
            let mut tables = vec![[0.0; 8]; ADJ_OCTETS * octet_stride::<f64>(NCH)];
            let mut out = vec![[0.0; 8]; groups * 8 * NCH];
            let octets = k.div_ceil(8);
            for o0 in (0..octets).step_by(ADJ_OCTETS) {
                let a = AdjChunk {
                    plus: &plus_refs,
                    minus: ternary.then_some(minus_refs.as_slice()),
                    y: &y,
                    prev: &prev,
                    base0,
                    first_octet: o0,
                };
                adjoint_chunk(isa, NCH, &a, &mut tables, &mut out);
            }
            for g in 0..groups {
                for i in 0..8 {
                    for j in 0..8 * NCH {
                        let want: f64 = (0..k)
                            .filter(|&kk| kk >= j && kk - j < kp)
                            .map(|kk| sign(g, i, kk) * y[kk] * pulse[kk - j])
                            .sum();
                        let got = out[(g * 8 + i) * NCH + j / 8][j % 8];
                        assert!(
                            (got - want).abs() < 1e-12 * (1.0 + want.abs()),
                            "{isa:?} ternary {ternary}: pixel {g}/{i} bin {j}: {got} vs {want}"
                        );
                    }
                }
            }
        }
    }
}

/// The one-pass restricted adjoint equals the signed copy followed by the windowed dot
/// product, for both alphabets, on every instruction set, with lengths that leave tails.
#[test]
fn signed_dot_equals_the_copy_then_the_dot() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for n in [1usize, 7, 8, 255, 256, 257, 1000] {
        let y: Vec<f32> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let p: Vec<f32> = (0..n)
            .map(|_| f32::from(rng.random_range(0..2u8)))
            .collect();
        let plus: Vec<u8> = (0..n).map(|_| rng.random()).collect();
        let minus: Vec<u8> = plus.iter().map(|&b| !b & rng.random::<u8>()).collect();
        for minus in [None, Some(minus.as_slice())] {
            for isa in [Isa::Generic, Isa::best()] {
                for bit in [0, 3, 7] {
                    let mut z = vec![0.0f32; n];
                    signed_copy_isa(isa, bit, &plus, minus, &y, &mut z);
                    let (mut want, mut got) = (0.0, 0.0);
                    lane_dot_isa(isa, &z, &p, &mut want);
                    signed_dot_isa(isa, bit, &plus, minus, &y, &p, &mut got);
                    let direct: f64 = (0..n)
                        .map(|k| {
                            let s = f64::from((plus[k] >> bit) & 1)
                                - match minus {
                                    None => f64::from(!(plus[k] >> bit) & 1),
                                    Some(m) => f64::from((m[k] >> bit) & 1),
                                };
                            s * f64::from(y[k]) * f64::from(p[k])
                        })
                        .sum();
                    assert!((got - want).abs() <= 1e-5 * (1.0 + want.abs()), "{n} {bit}");
                    assert!(
                        (got - direct).abs() <= 1e-5 * (1.0 + direct.abs()),
                        "{n} {bit}"
                    );
                }
            }
        }
    }
}
