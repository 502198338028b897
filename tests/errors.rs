//! Invalid constructions return typed errors; wrong buffer lengths panic with both lengths named.

use std::panic::{catch_unwind, AssertUnwindSafe};

use ndarray::Array2;
use rdlidar::operator::{
    operator_norm, BlockDiag, BoxedOperator, ConvMethod, ConvMode, Convolve1D, DenseMatrix,
    Diagonal, Gradient2D, HStack, Identity, LinearOperator, NalgebraMatrix, OperatorExt,
    PowerIteration, Restriction, SparseMatrix, VStack, Zero,
};
use rdlidar::Error;

fn shape_err<T>(r: rdlidar::Result<T>, expected: usize, found: usize) {
    match r {
        Err(Error::ShapeMismatch {
            expected: e,
            found: f,
            ..
        }) => assert_eq!((e, f), (expected, found)),
        Err(other) => panic!("expected a shape mismatch, got {other}"),
        Ok(_) => panic!("expected a shape mismatch, got Ok"),
    }
}

fn param_err<T>(r: rdlidar::Result<T>, name: &str) {
    match r {
        Err(Error::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
        Err(other) => panic!("expected an invalid `{name}`, got {other}"),
        Ok(_) => panic!("expected an invalid `{name}`, got Ok"),
    }
}

#[test]
fn mismatched_expressions_are_rejected_when_built() {
    let a = Zero::<f64>::new(3, 4);
    let b = Zero::<f64>::new(5, 2);
    shape_err(a.compose(b), 4, 5);
    shape_err(a.then(b), 2, 3);
    shape_err(a.plus(Zero::<f64>::new(3, 5)), 4, 5);
    shape_err(a.minus(Zero::<f64>::new(2, 4)), 3, 2);
    shape_err(VStack::new(vec![a, b]), 4, 2);
    shape_err(HStack::new(vec![a, b]), 3, 5);
    param_err(VStack::<Zero<f64>>::new(vec![]), "vstack");
    param_err(HStack::<Zero<f64>>::new(vec![]), "hstack");
    param_err(BlockDiag::<Zero<f64>>::new(vec![]), "block_diag");
    param_err(a.scaled(f64::NAN), "alpha");
    param_err(a.scaled(f64::INFINITY), "alpha");
    // The message names the operators.
    let msg = Identity::<f64>::new(3)
        .compose(Identity::<f64>::new(2))
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("Identity(3)") && msg.contains("Identity(2)"),
        "{msg}"
    );
}

#[test]
fn invalid_operator_parameters_are_rejected() {
    assert!(matches!(
        Diagonal::new(vec![1.0, f64::NAN]),
        Err(Error::NonFinite { .. })
    ));
    assert!(matches!(
        Restriction::<f32>::new(3, vec![0, 3]),
        Err(Error::IndexOutOfBounds {
            index: 3,
            len: 3,
            ..
        })
    ));
    param_err(Gradient2D::<f64>::new(0, 4), "grid");
    param_err(Gradient2D::<f64>::new(4, 0), "grid");
    param_err(
        Convolve1D::<f64>::new(0, 4, vec![1.0], ConvMode::Full, ConvMethod::Auto),
        "batch",
    );
    param_err(
        Convolve1D::<f64>::new(1, 0, vec![1.0], ConvMode::Full, ConvMethod::Auto),
        "n",
    );
    param_err(
        Convolve1D::<f64>::new(1, 4, vec![], ConvMode::Full, ConvMethod::Auto),
        "kernel",
    );
    param_err(
        Convolve1D::<f64>::new(1, 2, vec![1.0; 3], ConvMode::Valid, ConvMethod::Fft),
        "mode",
    );
    assert!(matches!(
        Convolve1D::<f32>::new(
            1,
            4,
            vec![1.0, f32::INFINITY],
            ConvMode::Same,
            ConvMethod::Direct
        ),
        Err(Error::NonFinite { .. })
    ));
    let mut bad = Array2::<f64>::zeros((2, 2));
    bad[[1, 0]] = f64::NEG_INFINITY;
    assert!(matches!(
        DenseMatrix::new(bad.clone()),
        Err(Error::NonFinite { .. })
    ));
    assert!(matches!(
        NalgebraMatrix::new(nalgebra::DMatrix::from_element(2, 2, f64::NAN)),
        Err(Error::NonFinite { .. })
    ));
    assert!(matches!(
        SparseMatrix::new(sprs::CsMat::csr_from_dense(bad.view(), 0.0)),
        Err(Error::NonFinite { .. })
    ));
    let id = Identity::<f64>::new(3);
    param_err(
        operator_norm(
            &id,
            &PowerIteration {
                max_iter: 0,
                ..PowerIteration::default()
            },
        ),
        "max_iter",
    );
    param_err(
        operator_norm(
            &id,
            &PowerIteration {
                tol: 0.0,
                ..PowerIteration::default()
            },
        ),
        "tol",
    );
    param_err(
        operator_norm(
            &id,
            &PowerIteration {
                tol: f64::NAN,
                ..PowerIteration::default()
            },
        ),
        "tol",
    );
}

/// Runs `f`, expects a panic, and returns its message.
fn panic_message(f: impl FnOnce()) -> String {
    let prev = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let r = catch_unwind(AssertUnwindSafe(f));
    std::panic::set_hook(prev);
    let e = r.expect_err("expected a panic");
    e.downcast_ref::<String>()
        .cloned()
        .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_default()
}

#[test]
fn wrong_buffer_lengths_panic_naming_both_lengths() {
    let ops: Vec<BoxedOperator<f64>> = vec![
        Zero::<f64>::new(7, 5).boxed(),
        Convolve1D::new(1, 5, vec![1.0; 3], ConvMode::Full, ConvMethod::Fft)
            .unwrap()
            .boxed(),
        Gradient2D::<f64>::new(7, 5)
            .unwrap()
            .compose(Zero::new(35, 5))
            .unwrap()
            .adjoint()
            .adjoint()
            .boxed(),
    ];
    for op in &ops {
        let (m, n) = (op.nrows(), op.ncols());
        let cases: Vec<(String, usize, usize)> = vec![
            (
                panic_message(|| op.apply(&vec![0.0; n + 1], &mut vec![0.0; m])),
                n,
                n + 1,
            ),
            (
                panic_message(|| op.apply(&vec![0.0; n], &mut vec![0.0; m - 1])),
                m,
                m - 1,
            ),
            (
                panic_message(|| op.apply_adjoint(&vec![0.0; m + 2], &mut vec![0.0; n])),
                m,
                m + 2,
            ),
            (
                panic_message(|| op.apply_adjoint(&vec![0.0; m], &mut [])),
                n,
                0,
            ),
        ];
        for (msg, expected, found) in cases {
            assert!(
                msg.contains(&format!("expected length {expected}"))
                    && msg.contains(&format!("found length {found}")),
                "{}: {msg}",
                op.describe()
            );
        }
    }
    let conv = Convolve1D::<f64>::new(1, 5, vec![1.0; 3], ConvMode::Full, ConvMethod::Fft).unwrap();
    let need = conv.scratch_len();
    assert!(need > 0);
    let msg = panic_message(|| {
        conv.apply_with_scratch(&[0.0; 5], &mut [0.0; 7], &mut vec![0.0; need - 1])
    });
    assert!(
        msg.contains(&format!("at least {need}"))
            && msg.contains(&format!("found length {}", need - 1)),
        "{msg}"
    );
}
