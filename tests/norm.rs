//! `operator_norm` against the largest singular value from nalgebra's SVD.

use proptest::prelude::*;
use rdlidar::operator::{operator_norm, BoxedOperator, NormStop, PowerIteration, Zero};

use crate::common::{any_expr, build, random_vec, reference};

fn sigma_max(a: &ndarray::Array2<f64>) -> f64 {
    let m = nalgebra::DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[[i, j]]);
    m.singular_values().iter().fold(0.0f64, |s, &v| s.max(v))
}

proptest! {
    #![proptest_config(crate::common::config(64))]

    #[test]
    fn agrees_with_the_svd_on_dense_matrices(m in 1..=32usize, n in 1..=32usize, seed in any::<u64>()) {
        let a = ndarray::Array2::from_shape_vec((m, n), random_vec(m * n, seed)).unwrap();
        let op = rdlidar::operator::DenseMatrix::new(a.clone()).unwrap();
        let est = operator_norm(&op, &PowerIteration { max_iter: 1000, seed, ..PowerIteration::default() }).unwrap();
        let s = sigma_max(&a);
        prop_assert!((est.value - s).abs() <= 0.01 * s, "estimate {} vs σ_max {s} ({:?})", est.value, est.stop);
        prop_assert!(est.value <= s * (1.0 + 1e-12));
    }

    #[test]
    fn agrees_with_the_svd_on_expressions(s in any_expr(2), seed in any::<u64>()) {
        let op: BoxedOperator<f64> = build(&s);
        let est = operator_norm(&op, &PowerIteration { max_iter: 1000, seed, ..PowerIteration::default() }).unwrap();
        let want = sigma_max(&reference(&s));
        prop_assert!((est.value - want).abs() <= 0.01 * want + 1e-12, "estimate {} vs σ_max {want}", est.value);
    }
}

#[test]
fn reports_how_it_stopped() {
    let z = Zero::<f64>::new(3, 4);
    let est = operator_norm(&z, &PowerIteration::default()).unwrap();
    assert_eq!((est.value, est.stop), (0.0, NormStop::ZeroOperator));

    let a = ndarray::Array2::from_shape_vec((6, 6), random_vec(36, 3)).unwrap();
    let op = rdlidar::operator::DenseMatrix::new(a).unwrap();
    let one = operator_norm(
        &op,
        &PowerIteration {
            max_iter: 1,
            ..PowerIteration::default()
        },
    )
    .unwrap();
    assert_eq!((one.iterations, one.stop), (1, NormStop::MaxIterations));
    let full = operator_norm(&op, &PowerIteration::default()).unwrap();
    assert_eq!(full.stop, NormStop::Converged);
    assert!(full.iterations > 1 && full.value >= one.value);
}

/// A start vector drawn from the matrix's own random stream converged to σ₂ here; the power
/// iteration now draws from a stream of its own.
#[test]
fn start_vector_is_independent_of_a_matrix_drawn_from_the_same_seed() {
    let (m, n, seed) = (11, 25, 3_394_372_794_526_115_410);
    let a = ndarray::Array2::from_shape_vec((m, n), random_vec(m * n, seed)).unwrap();
    let op = rdlidar::operator::DenseMatrix::new(a.clone()).unwrap();
    let est = operator_norm(
        &op,
        &PowerIteration {
            max_iter: 1000,
            seed,
            ..PowerIteration::default()
        },
    )
    .unwrap();
    let s = sigma_max(&a);
    assert!(
        (est.value - s).abs() <= 0.01 * s,
        "estimate {} vs σ_max {s}",
        est.value
    );
}

/// A Gaussian matrix's top singular values crowd at the edge of its spectrum, which slows the
/// power iteration: after as many steps, the Lanczos estimate must be far closer.
#[test]
fn converges_where_the_top_singular_values_cluster() {
    let (m, n, steps) = (120, 240, 25);
    let a = ndarray::Array2::from_shape_vec((m, n), random_vec(m * n, 11)).unwrap();
    let s = sigma_max(&a);
    let op = rdlidar::operator::DenseMatrix::new(a.clone()).unwrap();
    let est = operator_norm(
        &op,
        &PowerIteration {
            max_iter: steps,
            tol: 1e-15,
            seed: 5,
        },
    )
    .unwrap();
    // The power iteration from a start vector of its own, as many steps.
    let mut v = ndarray::Array1::from(random_vec(n, 6));
    let mut power = 0.0;
    for _ in 0..steps {
        v /= v.dot(&v).sqrt();
        let av = a.dot(&v);
        power = av.dot(&av).sqrt();
        v = a.t().dot(&av);
    }
    let (lanczos_err, power_err) = (1.0 - est.value / s, 1.0 - power / s);
    assert!(
        est.value <= s * (1.0 + 1e-12),
        "{} above σ_max {s}",
        est.value
    );
    assert!(
        lanczos_err <= 1e-4 && lanczos_err <= power_err / 100.0,
        "after {steps} steps: Lanczos {lanczos_err:e}, power iteration {power_err:e} below σ_max"
    );
}

/// Where the Krylov space is invariant the estimate is exact and the iteration stops at once:
/// the identity after one step, a rank-one matrix within two.
#[test]
fn an_invariant_krylov_space_stops_the_iteration_exactly() {
    let id = rdlidar::operator::Identity::<f64>::new(7);
    let est = operator_norm(&id, &PowerIteration::default()).unwrap();
    assert_eq!((est.iterations, est.stop), (1, NormStop::Converged));
    assert!((est.value - 1.0).abs() <= 1e-15, "{}", est.value);

    let (u, w) = (random_vec(9, 21), random_vec(13, 22));
    let a = ndarray::Array2::from_shape_fn((9, 13), |(i, j)| u[i] * w[j]);
    let want = sigma_max(&a);
    let op = rdlidar::operator::DenseMatrix::new(a).unwrap();
    let est = operator_norm(&op, &PowerIteration::default()).unwrap();
    assert!(
        est.iterations <= 2 && est.stop == NormStop::Converged,
        "{est:?}"
    );
    assert!(
        (est.value - want).abs() <= 1e-12 * want,
        "{} vs {want}",
        est.value
    );
}
