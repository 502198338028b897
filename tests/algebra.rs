//! Random operator expressions (sizes 1..=32, nesting depth up to 4) checked against the algebra's
//! promises, in f32 and f64.

use proptest::prelude::*;
use rdlidar::operator::{dot_test, Adjoint, BoxedOperator, DotTest, LinearOperator, OperatorExt};
use rdlidar::Real;

use crate::common::{any_expr, build, random_vec, reference, rel_max_diff, spec, Spec};

fn to_f64(a: ndarray::Array2<impl Real>) -> ndarray::Array2<f64> {
    a.mapv(|v| v.as_f64())
}

fn apply<T: Real>(op: &dyn LinearOperator<T>, x: &[f64]) -> Vec<T> {
    let x: Vec<T> = x.iter().map(|&v| T::of_f64(v)).collect();
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(&x, &mut y);
    y
}

fn apply_adj<T: Real>(op: &dyn LinearOperator<T>, y: &[f64]) -> Vec<T> {
    let y: Vec<T> = y.iter().map(|&v| T::of_f64(v)).collect();
    let mut x = vec![T::zero(); op.ncols()];
    op.apply_adjoint(&y, &mut x);
    x
}

/// Entrywise |a − b| ≤ tol·max(1, ‖b‖∞).
fn close<T: Real>(a: &[T], b: &[T], tol: f64) -> bool {
    let scale = b.iter().fold(1.0f64, |m, v| m.max(v.as_f64().abs()));
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| (x.as_f64() - y.as_f64()).abs() <= tol * scale)
}

fn config() -> ProptestConfig {
    crate::common::config(160)
}

fn dense_matches<T: Real>(s: &Spec, tol: f64) -> Result<(), TestCaseError> {
    let op: BoxedOperator<T> = build(s);
    let got = to_f64(op.to_dense());
    let want = reference(s);
    prop_assert_eq!(got.dim(), want.dim());
    let d = rel_max_diff(&got, &want);
    prop_assert!(
        d <= tol,
        "{}: to_dense differs from the reference by {d:e} ({})",
        T::NAME,
        op.describe()
    );
    Ok(())
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn expressions_pass_the_dot_test(s in any_expr(4), seed in any::<u64>()) {
        let a32: BoxedOperator<f32> = build(&s);
        let r32 = DotTest::new().seed(seed).measure(&a32);
        prop_assert!(r32.passed(), "f32 gap {:e} for {}", r32.gap, a32.describe());
        let a64: BoxedOperator<f64> = build(&s);
        let r64 = DotTest::new().seed(seed).measure(&a64);
        prop_assert!(r64.passed(), "f64 gap {:e} for {}", r64.gap, a64.describe());
    }

    #[test]
    fn to_dense_equals_the_expression_of_dense_parts(s in any_expr(4)) {
        dense_matches::<f64>(&s, 1e-10)?;
        dense_matches::<f32>(&s, 2e-4)?;
    }

    #[test]
    fn double_adjoint_is_the_operator(s in any_expr(3), seed in any::<u64>()) {
        let a: BoxedOperator<f64> = build(&s);
        let x = random_vec(a.ncols(), seed);
        let y = random_vec(a.nrows(), seed ^ 1);
        let aa = Adjoint::new(Adjoint::new(&a));
        // The wrapper of a wrapper calls the very same kernels: results are bitwise equal.
        prop_assert_eq!(apply::<f64>(&aa, &x), apply::<f64>(&a, &x));
        prop_assert_eq!(apply_adj::<f64>(&aa, &y), apply_adj::<f64>(&a, &y));
        // The inherent `Adjoint::adjoint` unwraps instead of wrapping again.
        let back: &BoxedOperator<f64> = (&a).adjoint().adjoint();
        prop_assert!(std::ptr::eq(back, &a));
    }

    #[test]
    fn adjoint_of_a_product_is_the_reversed_product_of_adjoints(
        (sa, sb) in (1..=32usize, 1..=32usize, 1..=32usize)
            .prop_flat_map(|(m, p, n)| (spec(m, p, 2), spec(p, n, 2))),
        seed in any::<u64>(),
    ) {
        let a: BoxedOperator<f64> = build(&sa);
        let b: BoxedOperator<f64> = build(&sb);
        let ab = (&a).compose(&b).unwrap();
        let y = random_vec(ab.nrows(), seed);
        let lhs = apply_adj::<f64>(&ab, &y);
        let aty = apply_adj::<f64>(&a, &y);
        let rhs = apply_adj::<f64>(&b, &aty);
        prop_assert!(close(&lhs, &rhs, 1e-12));
        // The same in f32, against the f64 result.
        let a32: BoxedOperator<f32> = build(&sa);
        let b32: BoxedOperator<f32> = build(&sb);
        let ab32 = (&a32).compose(&b32).unwrap();
        let lhs32: Vec<f64> = apply_adj::<f32>(&ab32, &y).iter().map(|v| v.as_f64()).collect();
        prop_assert!(close(&lhs32, &rhs, 1e-4));
    }

    #[test]
    fn operators_are_linear(s in any_expr(3), seed in any::<u64>(), alpha in -3.0f64..3.0) {
        let a: BoxedOperator<f64> = build(&s);
        let x1 = random_vec(a.ncols(), seed);
        let x2 = random_vec(a.ncols(), seed.wrapping_add(7));
        let comb: Vec<f64> = x1.iter().zip(&x2).map(|(u, v)| alpha * u + v).collect();
        let lhs = apply::<f64>(&a, &comb);
        let (y1, y2) = (apply::<f64>(&a, &x1), apply::<f64>(&a, &x2));
        let rhs: Vec<f64> = y1.iter().zip(&y2).map(|(u, v)| alpha * u + v).collect();
        prop_assert!(close(&lhs, &rhs, 1e-10));
    }

    #[test]
    fn with_scratch_equals_apply_even_with_dirty_scratch(s in any_expr(4), seed in any::<u64>()) {
        let a: BoxedOperator<f64> = build(&s);
        let x = random_vec(a.ncols(), seed);
        let y = random_vec(a.nrows(), seed ^ 3);
        let fresh = apply::<f64>(&a, &x);
        let fresh_adj = apply_adj::<f64>(&a, &y);
        // Scratch (larger than needed) and outputs full of garbage must not leak into results.
        let mut scratch = vec![f64::NAN; a.scratch_len() + 5];
        let mut out = vec![f64::NAN; a.nrows()];
        a.apply_with_scratch(&x, &mut out, &mut scratch);
        prop_assert_eq!(&out, &fresh);
        let mut out_adj = vec![1e300; a.ncols()];
        a.apply_adjoint_with_scratch(&y, &mut out_adj, &mut scratch);
        prop_assert_eq!(&out_adj, &fresh_adj);
    }
}

#[test]
fn dot_test_catches_a_wrong_adjoint() {
    struct Broken;
    impl LinearOperator<f64> for Broken {
        fn nrows(&self) -> usize {
            3
        }
        fn ncols(&self) -> usize {
            2
        }
        fn forward_kernel(&self, x: &[f64], y: &mut [f64], _: &mut [f64]) {
            y[0] = x[0];
            y[1] = x[1];
            y[2] = x[0] + x[1];
        }
        fn adjoint_kernel(&self, y: &[f64], x: &mut [f64], _: &mut [f64]) {
            // Wrong: the (2, 1) entry is dropped.
            x[0] = y[0] + y[2];
            x[1] = y[1];
        }
    }
    let err = dot_test(&Broken, 3).unwrap_err();
    match err {
        rdlidar::Error::DotTestFailed { gap, tolerance } => {
            assert!(gap > 1e-3 && tolerance == f64::DOT_TEST_TOL, "gap {gap}");
        }
        other => panic!("unexpected error {other}"),
    }
}

#[test]
fn counted_counts_applications_through_an_expression() {
    let d = rdlidar::operator::Diagonal::new(vec![1.0f64, 2.0, 3.0])
        .unwrap()
        .counted();
    let expr = (&d).compose(&d).unwrap().normal();
    let mut y = vec![0.0; 3];
    expr.apply(&[1.0, 1.0, 1.0], &mut y);
    assert_eq!(y, vec![1.0, 16.0, 81.0]);
    // (D·D)*(D·D) applies D twice forward (inner product) and twice adjoint.
    assert_eq!((d.forward_count(), d.adjoint_count()), (2, 2));
    d.reset();
    assert_eq!((d.forward_count(), d.adjoint_count()), (0, 0));
}
