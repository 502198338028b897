//! The frame behaviour of docs/math.md §4: as K_p grows, AᵀA/(K_p/4) tends to
//! blockdiag(I + 11ᵀ) for a 0/1 pulse, Ãᵀ A/(K_p/4) to I with the zero-mean pulse Ã, and AᵀA/K_p
//! to I for a ±1 pulse — with a deviation shrinking like 1/√K_p.

use std::sync::Arc;

use ndarray::Array2;
use rdlidar::lidar::{Codes, Geometry, Pulse, RdOperator};
use rdlidar::operator::LinearOperator;

const PULSES: [usize; 4] = [100, 1_000, 10_000, 100_000];
const SEEDS: [u64; 3] = [1, 2, 3];

fn spectral_norm(a: &Array2<f64>) -> f64 {
    let m = nalgebra::DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[[i, j]]);
    m.singular_values().iter().fold(0.0f64, |s, &v| s.max(v))
}

#[derive(Clone, Copy, Debug)]
enum Limit {
    /// 0/1 pulse, plain adjoint: blockdiag(I + 11ᵀ), scale K_p/4.
    PlainBernoulli,
    /// 0/1 pulse, zero-mean adjoint: I, scale K_p/4.
    DebiasedBernoulli,
    /// ±1 pulse: I, scale K_p.
    Signed,
}

/// ‖Bᵀ A / scale − G∞‖₂ for one pulse length and seed.
fn deviation(g: Geometry, kp: usize, seed: u64, limit: Limit) -> f64 {
    let p01 = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
    let pulse: Vec<f64> = match limit {
        Limit::Signed => p01.iter().map(|&v| 2.0 * v - 1.0).collect(),
        _ => p01,
    };
    let codes = Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), seed + 100).unwrap());
    let a_op = RdOperator::new(g, pulse, codes).unwrap();
    let a = a_op.to_dense();
    let b = match limit {
        Limit::DebiasedBernoulli => a_op.zero_mean().to_dense(),
        _ => a.clone(),
    };
    let scale = match limit {
        Limit::Signed => kp as f64,
        _ => kp as f64 / 4.0,
    };
    let gram = b.t().dot(&a) / scale;
    let n = g.voxels();
    let ks = g.ks;
    let limit_matrix = Array2::from_shape_fn((n, n), |(i, j)| {
        let same_pixel = i / ks == j / ks;
        let diag = if i == j { 1.0 } else { 0.0 };
        match limit {
            Limit::PlainBernoulli if same_pixel => diag + 1.0,
            _ => diag,
        }
    });
    spectral_norm(&(gram - limit_matrix))
}

fn check_trend(limit: Limit) {
    let g = Geometry::new(3, 3, 8).unwrap();
    let means: Vec<f64> = PULSES
        .iter()
        .map(|&kp| {
            SEEDS
                .iter()
                .map(|&s| deviation(g, kp, s, limit))
                .sum::<f64>()
                / SEEDS.len() as f64
        })
        .collect();
    // Decreasing at every step...
    for w in means.windows(2) {
        assert!(
            w[1] < w[0],
            "{limit:?}: deviation does not decrease: {means:?}"
        );
    }
    // ...roughly like 1/√K_p: a least-squares slope of log(deviation) against log(K_p) near −1/2.
    let xs: Vec<f64> = PULSES.iter().map(|&k| (k as f64).ln()).collect();
    let ys: Vec<f64> = means.iter().map(|d| d.ln()).collect();
    let (mx, my) = (xs.iter().sum::<f64>() / 4.0, ys.iter().sum::<f64>() / 4.0);
    let slope = xs
        .iter()
        .zip(&ys)
        .map(|(x, y)| (x - mx) * (y - my))
        .sum::<f64>()
        / xs.iter().map(|x| (x - mx).powi(2)).sum::<f64>();
    assert!(
        (-0.65..=-0.35).contains(&slope),
        "{limit:?}: slope {slope} for deviations {means:?}"
    );
    // And small at the longest pulse, relative to ‖G∞‖₂ (1 + K_s for blockdiag(I + 11ᵀ), else 1):
    // a 72 × 72 deviation with entries of size ~1.4/√K_p has a norm near 24/√K_p ≈ 0.08 here.
    let limit_norm = match limit {
        Limit::PlainBernoulli => 1.0 + g.ks as f64,
        _ => 1.0,
    };
    assert!(
        means[3] < 0.15 * limit_norm,
        "{limit:?}: deviation {} at K_p = 10⁵",
        means[3]
    );
}

#[test]
fn bernoulli_pulse_tends_to_identity_plus_ones_per_pixel() {
    check_trend(Limit::PlainBernoulli);
}

#[test]
fn zero_mean_adjoint_tends_to_identity() {
    check_trend(Limit::DebiasedBernoulli);
}

#[test]
fn signed_pulse_tends_to_identity() {
    check_trend(Limit::Signed);
}

/// Against the wrong limit (I for the plain 0/1 pulse) the deviation does not vanish: the limit
/// matters, and the test above could fail.
#[test]
fn plain_bernoulli_does_not_tend_to_identity() {
    let g = Geometry::new(3, 3, 8).unwrap();
    let kp = 100_000;
    let p = Pulse::<f64>::bernoulli(kp, 1).unwrap().into_inner();
    let codes = Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), 101).unwrap());
    let a = RdOperator::new(g, p, codes).unwrap().to_dense();
    let gram = a.t().dot(&a) / (kp as f64 / 4.0);
    let dev = spectral_norm(&(gram - Array2::<f64>::eye(g.voxels())));
    // blockdiag(11ᵀ) has norm K_s = 8.
    assert!((dev - 8.0).abs() < 0.5, "deviation from I: {dev}");
}
