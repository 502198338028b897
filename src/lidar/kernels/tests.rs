//! Tests of the kernels against direct sums, on every instruction set this CPU has.

use super::support_wide::{signed_dot_isa, sparse_entry_isa, Entry};
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

/// For binary codes a chunk's tables hold row ¬b as row b negated to the bit, on every
/// instruction set (the symmetric reads of the wide adjoint rest on it), and without the upper
/// rows the lower ones are the same; ternary codes' rows are sums over the set bits, row 0 zero.
#[test]
fn binary_adjoint_tables_hold_each_complement_negated() {
    const NCH: usize = 3;
    let mut rng = ChaCha8Rng::seed_from_u64(28);
    let k = 8 * ADJ_OCTETS;
    let y: Vec<f32> = (0..k).map(|_| rng.random_range(-1.0..1.0)).collect();
    // A pulse of alternating ones and zeros, laid out as the operator does (`AdjChunk::prev`).
    let mut prev = vec![0.0f32; 16 * NCH + k];
    for v in prev.iter_mut().skip(8 * NCH).step_by(2) {
        *v = 1.0;
    }
    let (plus, minus) = random_planes(&mut rng, 1, k);
    for isa in every_isa() {
        for ternary in [false, true] {
            let a = AdjChunk {
                plus: GroupBytes::new(&plus[0], k, 0..1),
                minus: ternary.then(|| GroupBytes::new(&minus[0], k, 0..1)),
                y: &y,
                prev: &prev,
                base0: 8 * NCH + k - 1,
                first_octet: 0,
            };
            let stride = octet_stride::<f32>(NCH);
            let mut whole = vec![[f32::NAN; 8]; ADJ_OCTETS * stride];
            let mut lower = whole.clone();
            adjoint_tables(isa, NCH, &a, &mut whole, true);
            adjoint_tables(isa, NCH, &a, &mut lower, false);
            for o in 0..ADJ_OCTETS {
                let row = |t: &[Lane<f32>], b: usize| t[o * stride + b * NCH..][..NCH].to_vec();
                for b in 0..256 {
                    let bits = |r: Vec<Lane<f32>>| r.concat().iter().map(|v| v.to_bits()).collect();
                    let got: Vec<u32> = bits(row(&whole, b));
                    if ternary || b < 128 {
                        assert_eq!(got, bits(row(&lower, b)), "{isa:?} octet {o} row {b}");
                    }
                    if !ternary {
                        let negated = row(&whole, 255 - b).iter().map(|l| l.map(|v| -v)).collect();
                        assert_eq!(got, bits(negated), "{isa:?} octet {o} row {b}");
                    }
                }
                if ternary {
                    assert!(row(&whole, 0).concat().iter().all(|&v| v == 0.0));
                }
            }
        }
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
    let (plus_plane, minus_plane) = (plus.concat(), minus.concat());
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
                    plus: GroupBytes::new(&plus_plane, k, 0..groups),
                    minus: ternary.then(|| GroupBytes::new(&minus_plane, k, 0..groups)),
                    y: &y,
                    prev: &prev,
                    base0,
                    first_octet: o0,
                };
                adjoint_chunk(isa, NCH, &a, &mut tables, &mut out, None);
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

/// Every instruction set this CPU has, and the generic kernels.
pub(crate) fn every_isa() -> Vec<Isa> {
    let mut all = vec![Isa::Generic];
    #[cfg(target_arch = "x86_64")]
    if Isa::best() >= Isa::Avx2 {
        all.push(Isa::Avx2);
    }
    if Isa::best() > *all.last().expect("generic") {
        all.push(Isa::best());
    }
    all
}

/// The code of sample `k` for the pixel at bit `bit`: ±1, or −1/0/+1 with a −1 plane.
fn code_of(plus: &[u8], minus: Option<&[u8]>, bit: u32, k: usize) -> f64 {
    let p = f64::from((plus[k] >> bit) & 1);
    match minus {
        None => 2.0 * p - 1.0,
        Some(m) => p - f64::from((m[k] >> bit) & 1),
    }
}

/// The direct forward at sample `kk`: Σ_p s_p(kk)·Σ_{j ∈ bins} x[p, j]·pulse[kk − j] over the
/// `npix` pixels of `ks` bins of `x`, with the codes of [`random_planes`] (binary, or ternary
/// with `minus`).
pub(crate) fn direct_forward<T: Real>(
    x: &[T],
    (npix, ks): (usize, usize),
    bins: std::ops::Range<usize>,
    pulse: &[f64],
    (plus, minus): (&[Vec<u8>], Option<&[Vec<u8>]>),
    kk: usize,
) -> f64 {
    (0..npix)
        .map(|p| {
            let s = code_of(
                &plus[p / 8],
                minus.map(|m| m[p / 8].as_slice()),
                (p % 8) as u32,
                kk,
            );
            let column: f64 = bins
                .clone()
                .filter(|&j| kk >= j && kk - j < pulse.len())
                .map(|j| x[p * ks + j].as_f64() * pulse[kk - j])
                .sum();
            s * column
        })
        .sum()
}

/// Random values in −1..1 and a random 0/1 pulse, both of length `n`.
fn values_and_pulse<T: Real>(rng: &mut ChaCha8Rng, n: usize) -> (Vec<T>, Vec<T>) {
    let y = (0..n)
        .map(|_| T::of_f64(rng.random_range(-1.0..1.0)))
        .collect();
    let p = (0..n)
        .map(|_| T::of_f64(f64::from(rng.random_range(0..2u8))))
        .collect();
    (y, p)
}

/// The restricted adjoint's sums for voxels of one depth: together ([`depth_dots_isa`]: on
/// AVX-512 eight or four at a time, a last short batch filled up; elsewhere one by one) and one
/// at a time ([`signed_dot_isa`]) equal the direct sum Σ_k s_i(k)·y[k]·p[k], for 1 to 21
/// voxels, both alphabets and precisions, on every instruction set, with lengths around the
/// kernels' blocks; and a voxel's sum together is the same to the bit whatever the voxels
/// that share its batch (those of 21 voxels taken together).
fn depth_dots_match_the_direct_sum<T: Real>(tol: f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for n in [
        1usize, 7, 8, 15, 17, 255, 256, 257, 511, 512, 513, 1000, 2100,
    ] {
        let (y, p) = values_and_pulse::<T>(&mut rng, n);
        let (plus, minus) = random_planes(&mut rng, 21, n);
        for ternary in [false, true] {
            let codes: Vec<Coded<'_>> = (0..21)
                .map(|v| Coded {
                    bit: (v * 3 % 8) as u32,
                    plus: &plus[v],
                    minus: ternary.then_some(minus[v].as_slice()),
                })
                .collect();
            let direct: Vec<f64> = codes
                .iter()
                .map(|c| {
                    (0..n)
                        .map(|k| code_of(c.plus, c.minus, c.bit, k) * (y[k] * p[k]).as_f64())
                        .sum()
                })
                .collect();
            for isa in every_isa() {
                let mut all = vec![f64::NAN; 21];
                depth_dots_isa(isa, &codes, &y, &p, &mut all);
                for count in [1usize, 3, 4, 5, 8, 9, 12, 13, 16, 21] {
                    let ctx = format!("{} {isa:?} n {n} ternary {ternary} voxels {count}", T::NAME);
                    let mut together = vec![f64::NAN; count];
                    depth_dots_isa(isa, &codes[..count], &y, &p, &mut together);
                    assert!(together[..] == all[..count], "{ctx}: batches");
                    for (v, c) in codes[..count].iter().enumerate() {
                        let mut one = f64::NAN;
                        signed_dot_isa(isa, c.bit, c.plus, c.minus, &y, &p, &mut one);
                        let want = direct[v];
                        let close = |got: f64| (got - want).abs() <= tol * (1.0 + want.abs());
                        assert!(close(together[v]), "{ctx}: together, voxel {v}");
                        assert!(close(one), "{ctx}: one at a time, voxel {v}");
                    }
                }
            }
        }
    }
}

#[test]
fn depth_dots_match_the_direct_sum_f32() {
    depth_dots_match_the_direct_sum::<f32>(1e-5);
}

#[test]
fn depth_dots_match_the_direct_sum_f64() {
    depth_dots_match_the_direct_sum::<f64>(1e-12);
}

/// The sparse forward's entries of one depth together ([`depth_entries_isa`]) equal the direct
/// sum Σ_e a_e·s_e(k)·p[k] added to what `out` held, for 1 to 21 entries (eight and four at a
/// time and a rest), amplitudes of both signs, both alphabets and precisions, on every
/// instruction set, with lengths that leave tails; one entry alone adds what
/// [`sparse_entry_isa`] adds, to the bit.
fn depth_entries_match_the_direct_sum<T: Real>(tol: f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(14);
    for n in [3usize, 16, 40, 263] {
        let (start, pulse) = values_and_pulse::<T>(&mut rng, n);
        let (plus, minus) = random_planes(&mut rng, 21, n);
        let amps: Vec<T> = (0..21)
            .map(|_| T::of_f64(rng.random_range(-1.0..1.0)))
            .collect();
        for ternary in [false, true] {
            let codes: Vec<Coded<'_>> = (0..21)
                .map(|e| Coded {
                    bit: (e * 5 % 8) as u32,
                    plus: &plus[e],
                    minus: ternary.then_some(minus[e].as_slice()),
                })
                .collect();
            for isa in every_isa() {
                for count in [1usize, 3, 4, 5, 8, 9, 12, 13, 16, 21] {
                    let ctx = format!(
                        "{} {isa:?} n {n} ternary {ternary} entries {count}",
                        T::NAME
                    );
                    let mut got = start.clone();
                    depth_entries_isa(isa, &amps[..count], &codes[..count], &pulse, &mut got);
                    for k in 0..n {
                        let direct = start[k].as_f64()
                            + (0..count)
                                .map(|e| {
                                    let c = &codes[e];
                                    let s = code_of(c.plus, c.minus, c.bit, k);
                                    amps[e].as_f64() * s * pulse[k].as_f64()
                                })
                                .sum::<f64>();
                        let g = got[k].as_f64();
                        assert!(
                            (g - direct).abs() <= tol * (1.0 + direct.abs()),
                            "{ctx} at {k}"
                        );
                    }
                    if count == 1 {
                        let mut single = start.clone();
                        let c = &codes[0];
                        let (bit, plus, minus) = (c.bit, c.plus, c.minus);
                        let (amp, pw) = (amps[0], pulse.as_slice());
                        let e = Entry {
                            amp,
                            bit,
                            plus,
                            minus,
                            pw,
                        };
                        sparse_entry_isa(isa, &e, &mut single);
                        assert!(single == got, "{ctx}: one entry");
                    }
                }
            }
        }
    }
}

#[test]
fn depth_entries_match_the_direct_sum_f32() {
    depth_entries_match_the_direct_sum::<f32>(1e-5);
}

#[test]
fn depth_entries_match_the_direct_sum_f64() {
    depth_entries_match_the_direct_sum::<f64>(1e-12);
}

/// The 256-row forward block against the direct sum y[k] = Σ_p s_p(k)·Σ_j x[p, j]·p[k − j] on
/// every instruction set, binary and ternary codes, a last group with three pixels missing and
/// a slab wider than the depth bins.
fn forward_block_matches_the_direct_sum<T: Real>(tol: f64) {
    const NCH: usize = 2;
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let (groups, npix, ks, kp) = (3usize, 21usize, 13usize, 25usize);
    let k = kp + ks - 1;
    let x: Vec<T> = (0..npix * ks)
        .map(|_| T::of_f64(rng.random_range(-1.0..1.0)))
        .collect();
    let pulse: Vec<f64> = (0..kp)
        .map(|_| f64::from(rng.random_range(0..2u8)))
        .collect();
    let pad = 8 * NCH;
    let mut prev = vec![T::zero(); pad + kp + 8 * NCH];
    for (t, &v) in pulse.iter().rev().enumerate() {
        prev[pad + t] = T::of_f64(v);
    }
    let (plus, minus) = random_planes(&mut rng, groups, k);
    let (plus_plane, minus_plane) = (plus.concat(), minus.concat());
    for ternary in [false, true] {
        let mut tables = vec![[T::zero(); 8]; groups * 256 * NCH];
        tables::build_group_tables(&x, (npix, ks), !ternary, 0..groups, 0, NCH, &mut tables);
        for isa in every_isa() {
            let blk = FwdBlock {
                tables: &tables,
                plus: GroupBytes::new(&plus_plane, k, 0..groups),
                minus: ternary.then(|| GroupBytes::new(&minus_plane, k, 0..groups)),
                prev: &prev,
                base0: pad + kp - 1,
            };
            let mut part = vec![[T::zero(); 8]; k];
            forward_block(isa, NCH, &blk, &mut part);
            for (kk, lanes) in part.iter().enumerate() {
                let got: f64 = lanes.iter().map(|v| v.as_f64()).sum();
                let codes = (plus.as_slice(), ternary.then_some(minus.as_slice()));
                let want = direct_forward(&x, (npix, ks), 0..ks, &pulse, codes, kk);
                assert!(
                    (got - want).abs() <= tol * (1.0 + want.abs()),
                    "{} {isa:?} ternary {ternary}: sample {kk}: {got} vs {want}",
                    T::NAME
                );
            }
        }
    }
}

#[test]
fn forward_block_matches_the_direct_sum_f32() {
    forward_block_matches_the_direct_sum::<f32>(1e-4);
}

#[test]
fn forward_block_matches_the_direct_sum_f64() {
    forward_block_matches_the_direct_sum::<f64>(1e-12);
}
