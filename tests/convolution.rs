//! The convolution's direct and FFT paths against a naive reference, for every mode.

use proptest::prelude::*;
use rdlidar::operator::{ConvMethod, ConvMode, Convolve1D, LinearOperator};
use rdlidar::Real;

use crate::common::{conv_matrix, random_vec};

/// Naive full convolution of one row, then the crop of `mode` (scipy.signal.convolve's conventions).
fn naive(x: &[f64], h: &[f64], mode: ConvMode) -> Vec<f64> {
    let (n, l) = (x.len(), h.len());
    let mut full = vec![0.0; n + l - 1];
    for (j, &xj) in x.iter().enumerate() {
        for (t, &ht) in h.iter().enumerate() {
            full[j + t] += xj * ht;
        }
    }
    match mode {
        ConvMode::Full => full,
        ConvMode::Same => full[(l - 1) / 2..(l - 1) / 2 + n].to_vec(),
        ConvMode::Valid => full[l - 1..n].to_vec(),
    }
}

fn check<T: Real>(
    batch: usize,
    len: usize,
    h: &[f64],
    mode: ConvMode,
    method: ConvMethod,
    seed: u64,
    tol: f64,
) -> Result<(), TestCaseError> {
    let c = Convolve1D::new(
        batch,
        len,
        h.iter().map(|&v| T::of_f64(v)).collect(),
        mode,
        method,
    )
    .unwrap();
    prop_assert_eq!(c.method(), method);
    let x = random_vec(batch * len, seed);
    let xt: Vec<T> = x.iter().map(|&v| T::of_f64(v)).collect();
    let mut y = vec![T::zero(); c.nrows()];
    c.apply(&xt, &mut y);
    let out = c.out_len();
    let scale = h.iter().map(|v| v.abs()).sum::<f64>().max(1e-300);
    for r in 0..batch {
        let want = naive(&x[r * len..(r + 1) * len], h, mode);
        prop_assert_eq!(want.len(), out);
        for (i, w) in want.iter().enumerate() {
            let g = y[r * out + i].as_f64();
            prop_assert!(
                (g - w).abs() <= tol * scale,
                "{} {:?} {:?} row {r} sample {i}: {g} vs {w}",
                T::NAME,
                method,
                mode
            );
        }
    }
    // The adjoint against the transpose of the reference matrix.
    let yr = random_vec(c.nrows(), seed ^ 9);
    let yt: Vec<T> = yr.iter().map(|&v| T::of_f64(v)).collect();
    let mut xa = vec![T::zero(); c.ncols()];
    c.apply_adjoint(&yt, &mut xa);
    let want = conv_matrix(batch, len, h, mode)
        .t()
        .dot(&ndarray::Array1::from(yr));
    for (g, w) in xa.iter().zip(&want) {
        prop_assert!(
            (g.as_f64() - w).abs() <= tol * scale,
            "{} {:?} {:?} adjoint: {g} vs {w}",
            T::NAME,
            method,
            mode
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(crate::common::config(96))]

    #[test]
    fn direct_and_fft_match_the_naive_reference(
        batch in 1..=5usize,
        len in 1..=300usize,
        l in 1..=150usize,
        seed in any::<u64>(),
    ) {
        let h = random_vec(l, seed.wrapping_mul(31));
        for mode in [ConvMode::Full, ConvMode::Same, ConvMode::Valid] {
            if mode == ConvMode::Valid && len < l {
                continue;
            }
            for method in [ConvMethod::Direct, ConvMethod::Fft] {
                check::<f64>(batch, len, &h, mode, method, seed, 1e-12)?;
                check::<f32>(batch, len, &h, mode, method, seed, 1e-5)?;
            }
        }
    }
}

#[test]
fn auto_picks_direct_for_short_kernels_and_fft_for_long_ones() {
    let short =
        Convolve1D::new(4, 10_000, vec![1.0f32; 4], ConvMode::Full, ConvMethod::Auto).unwrap();
    assert_eq!(short.method(), ConvMethod::Direct);
    let long = Convolve1D::new(
        4,
        10_000,
        vec![1.0f32; 2_000],
        ConvMode::Full,
        ConvMethod::Auto,
    )
    .unwrap();
    assert_eq!(long.method(), ConvMethod::Fft);
}

#[test]
fn a_long_pulse_convolution_is_accurate_in_f32_via_fft() {
    // A 0/1 pulse of length 20 000 against 40 depth bins: the lidar's convolution P.
    let pulse: Vec<f64> = random_vec(20_000, 4)
        .iter()
        .map(|&v| if v > 0.0 { 1.0 } else { 0.0 })
        .collect();
    let x = random_vec(40, 8);
    let c = Convolve1D::new(
        1,
        40,
        pulse.iter().map(|&v| v as f32).collect(),
        ConvMode::Full,
        ConvMethod::Fft,
    )
    .unwrap();
    let mut y = vec![0.0f32; c.nrows()];
    c.apply(&x.iter().map(|&v| v as f32).collect::<Vec<_>>(), &mut y);
    let want = naive(&x, &pulse, ConvMode::Full);
    let err = y
        .iter()
        .zip(&want)
        .map(|(g, w)| (*g as f64 - w).abs())
        .fold(0.0, f64::max);
    let peak = want.iter().map(|w| w.abs()).fold(0.0, f64::max);
    assert!(err <= 1e-5 * peak, "max error {err} vs peak {peak}");
}
