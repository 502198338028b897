//! Checks against LAPACK on problems larger than the nalgebra references handle comfortably
//! (feature `lapack`).

use ndarray::Array2;
use rdlidar::lapack::{lstsq, operator_singular_values};
use rdlidar::linalg::{dot, norm2};
use rdlidar::operator::{
    operator_norm, ConvMethod, ConvMode, Convolve1D, DenseMatrix, Diagonal, LinearOperator,
    OperatorExt, PowerIteration,
};

use crate::common::random_vec;

#[test]
fn operator_norm_matches_lapack_on_a_pulse_convolution() {
    // A 0/1 pulse of length 64 convolved with 8 rows of 40 bins, weighted: 824 × 320.
    let pulse: Vec<f64> = random_vec(64, 2)
        .iter()
        .map(|&v| if v > 0.0 { 1.0 } else { 0.0 })
        .collect();
    let conv = Convolve1D::new(8, 40, pulse, ConvMode::Full, ConvMethod::Fft).unwrap();
    let w = Diagonal::new(random_vec(conv.nrows(), 3)).unwrap();
    let op = w.compose(conv).unwrap();
    let s = operator_singular_values(&op).unwrap();
    let est = operator_norm(
        &op,
        &PowerIteration {
            max_iter: 2000,
            tol: 1e-9,
            seed: 1,
        },
    )
    .unwrap();
    assert!(
        (est.value - s[0]).abs() <= 0.01 * s[0],
        "{} vs {}",
        est.value,
        s[0]
    );
    assert!(s.windows(2).all(|p| p[0] >= p[1]));
}

#[test]
fn lstsq_satisfies_the_normal_equations() {
    let (m, n) = (400, 150);
    let a = Array2::from_shape_vec((m, n), random_vec(m * n, 9)).unwrap();
    let b = random_vec(m, 10);
    let x = lstsq(&a, &b).unwrap();
    let op = DenseMatrix::new(a).unwrap();
    let mut r = vec![0.0; m];
    op.apply(&x, &mut r);
    r.iter_mut().zip(&b).for_each(|(ri, bi)| *ri -= bi);
    let mut g = vec![0.0; n];
    op.apply_adjoint(&r, &mut g);
    // Aᵀ(Ax − b) = 0 up to rounding, relative to ‖Aᵀ‖‖b‖.
    let scale = norm2(&b) * (m as f64).sqrt() * 3.0;
    assert!(norm2(&g) <= 1e-10 * scale, "‖Aᵀr‖ = {}", norm2(&g));
    assert!(dot(&r, &r) <= dot(&b, &b));
}

#[test]
fn lstsq_rejects_bad_input() {
    let a = Array2::<f64>::zeros((3, 2));
    assert!(matches!(
        lstsq(&a, &[1.0, 2.0]),
        Err(rdlidar::Error::ShapeMismatch { .. })
    ));
    assert!(matches!(
        lstsq(&a, &[1.0, f64::NAN, 0.0]),
        Err(rdlidar::Error::NonFinite { .. })
    ));
}
