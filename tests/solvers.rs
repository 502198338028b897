//! Solvers: CGLS against dense least squares, backprojection on the lidar operator, the shared
//! interface's behaviour (stopping, observers, reports, typed errors).

use std::sync::Arc;

use ndarray::Array2;
use proptest::prelude::*;
use rdlidar::lidar::{random_opaque_scene, Codes, Geometry, Pulse, RdOperator};
use rdlidar::operator::{DenseMatrix, LinearOperator, Zero};
use rdlidar::solver::{
    backprojection, cgls, Backprojection, CglsParams, Control, IterationInfo, Stopping,
    Termination, Threshold,
};
use rdlidar::{Error, Real};

use crate::common::random_vec;

fn dense(m: usize, n: usize, seed: u64) -> (Array2<f64>, nalgebra::DMatrix<f64>) {
    let v = random_vec(m * n, seed);
    (
        Array2::from_shape_vec((m, n), v.clone()).unwrap(),
        nalgebra::DMatrix::from_row_slice(m, n, &v),
    )
}

/// (AᵀA + λI)⁻¹ Aᵀy by nalgebra's Cholesky (λ = 0: the least-squares solution of a full-rank A).
fn reference(a: &nalgebra::DMatrix<f64>, y: &[f64], lambda: f64) -> Vec<f64> {
    let n = a.ncols();
    let normal = a.transpose() * a + nalgebra::DMatrix::<f64>::identity(n, n) * lambda;
    let rhs = a.transpose() * nalgebra::DVector::from_column_slice(y);
    normal
        .cholesky()
        .expect("positive definite")
        .solve(&rhs)
        .iter()
        .copied()
        .collect()
}

fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let d: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt();
    d / b.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300)
}

fn run_cgls<T: Real>(
    a: &Array2<f64>,
    y: &[f64],
    lambda: f64,
    tol: f64,
) -> (Vec<f64>, rdlidar::solver::Report) {
    let op = DenseMatrix::new(a.mapv(T::of_f64)).unwrap();
    let yt: Vec<T> = y.iter().map(|&v| T::of_f64(v)).collect();
    let mut x = vec![T::zero(); a.ncols()];
    let params = CglsParams {
        damp: lambda,
        stopping: Stopping {
            max_iter: 500,
            rel_residual: Some(tol),
            ..Stopping::default()
        },
    };
    let report = cgls(&op, &yt, &mut x, &params, &mut ()).unwrap();
    (x.iter().map(|v| v.as_f64()).collect(), report)
}

proptest! {
    #![proptest_config(crate::common::config(48))]

    #[test]
    fn cgls_equals_dense_least_squares_and_ridge(n in 1..=20usize, extra in 0..=20usize, seed in any::<u64>(), lambda in 0.01f64..5.0) {
        let m = n + extra + 2;
        let (a, an) = dense(m, n, seed);
        let y = random_vec(m, seed ^ 1);
        for lam in [0.0, lambda] {
            let want = reference(&an, &y, lam);
            let (got, report) = run_cgls::<f64>(&a, &y, lam, 1e-12);
            prop_assert!(rel_err(&got, &want) < 1e-8, "λ = {lam}: error {:e} after {:?}", rel_err(&got, &want), report.termination);
            // One forward and one adjoint per iteration, plus one of each to start.
            prop_assert_eq!(report.forward_applies, report.iterations + 1);
            prop_assert_eq!(report.adjoint_applies, report.iterations + 1);
            // The objective never increases (up to rounding).
            for w in report.objective_history.windows(2) {
                prop_assert!(w[1] <= w[0] * (1.0 + 1e-12) + 1e-15);
            }
            let (got32, _) = run_cgls::<f32>(&a, &y, lam, 1e-6);
            prop_assert!(rel_err(&got32, &want) < 1e-3, "f32 λ = {lam}: error {:e}", rel_err(&got32, &want));
        }
    }
}

#[test]
fn cgls_handles_zero_data_and_zero_operators() {
    let (a, _) = dense(6, 4, 3);
    let op = DenseMatrix::new(a).unwrap();
    let mut x = vec![0.0; 4];
    let r = cgls(&op, &[0.0; 6], &mut x, &CglsParams::default(), &mut ()).unwrap();
    assert_eq!(
        (r.termination, r.iterations),
        (Termination::ZeroResidual, 0)
    );
    assert!(x.iter().all(|v| *v == 0.0));
    let z = Zero::<f64>::new(6, 4);
    let mut x = vec![0.0; 4];
    let r = cgls(
        &z,
        &random_vec(6, 1),
        &mut x,
        &CglsParams::default(),
        &mut (),
    )
    .unwrap();
    assert_eq!(r.termination, Termination::ZeroResidual);
    assert!(x.iter().all(|v| v.is_finite()));
}

#[test]
fn cgls_rejects_invalid_input() {
    let (a, _) = dense(6, 4, 3);
    let op = DenseMatrix::new(a).unwrap();
    let y = random_vec(6, 2);
    let mut x = vec![0.0; 4];
    let bad = |p: CglsParams, y: &[f64], x: &mut [f64]| cgls(&op, y, x, &p, &mut ()).unwrap_err();
    assert!(matches!(
        bad(
            CglsParams {
                damp: -1.0,
                ..CglsParams::default()
            },
            &y,
            &mut x
        ),
        Error::InvalidParameter { name: "damp", .. }
    ));
    assert!(matches!(
        bad(
            CglsParams {
                damp: f64::NAN,
                ..CglsParams::default()
            },
            &y,
            &mut x
        ),
        Error::InvalidParameter { name: "damp", .. }
    ));
    assert!(matches!(
        bad(
            CglsParams {
                stopping: Stopping {
                    max_iter: 0,
                    ..Stopping::default()
                },
                ..CglsParams::default()
            },
            &y,
            &mut x
        ),
        Error::InvalidParameter {
            name: "max_iter",
            ..
        }
    ));
    assert!(matches!(
        bad(CglsParams::default(), &y[..5], &mut x),
        Error::ShapeMismatch { .. }
    ));
    assert!(matches!(
        bad(CglsParams::default(), &y, &mut [0.0; 3]),
        Error::ShapeMismatch { .. }
    ));
    let mut yn = y.clone();
    yn[2] = f64::NAN;
    assert!(matches!(
        bad(CglsParams::default(), &yn, &mut x),
        Error::NonFinite { .. }
    ));
}

#[test]
fn observers_see_every_iteration_and_can_stop() {
    let (a, _) = dense(30, 20, 5);
    let op = DenseMatrix::new(a).unwrap();
    let y = random_vec(30, 6);
    let mut x = vec![0.0; 20];
    let mut seen = Vec::new();
    let mut obs = |info: &IterationInfo<'_, f64>| {
        seen.push((info.iteration, info.residual));
        if info.iteration == 3 {
            Control::Stop
        } else {
            Control::Continue
        }
    };
    let r = cgls(&op, &y, &mut x, &CglsParams::default(), &mut obs).unwrap();
    assert_eq!((r.termination, r.iterations), (Termination::Observer, 3));
    assert_eq!(seen.iter().map(|s| s.0).collect::<Vec<_>>(), vec![1, 2, 3]);
    assert_eq!(
        r.residual_history,
        seen.iter().map(|s| s.1).collect::<Vec<_>>()
    );
    // The iteration limit is a termination reason, not an error.
    let mut x = vec![0.0; 20];
    let r = cgls(
        &op,
        &y,
        &mut x,
        &CglsParams {
            stopping: Stopping::iterations(2),
            ..CglsParams::default()
        },
        &mut (),
    )
    .unwrap();
    assert_eq!(
        (r.termination, r.iterations),
        (Termination::MaxIterations, 2)
    );
}

fn lidar_problem(
    kp: usize,
) -> (
    Geometry,
    RdOperator<f64>,
    Vec<f64>,
    rdlidar::lidar::Scene<f64>,
) {
    let g = Geometry::new(4, 5, 8).unwrap();
    let scene = random_opaque_scene::<f64>(g, 0.6, 7).unwrap();
    let pulse = Pulse::<f64>::bernoulli(kp, 1).unwrap().into_inner();
    let codes = Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), 2).unwrap());
    let op = RdOperator::new(g, pulse, codes).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(scene.as_slice(), &mut y);
    (g, op, y, scene)
}

#[test]
fn debiased_backprojection_recovers_an_opaque_scene_in_the_redundant_regime() {
    let kp = 20_000;
    let (g, op, y, scene) = lidar_problem(kp);
    let params = Backprojection {
        column_len: g.ks,
        normalization: kp as f64 / 4.0,
        threshold: Threshold::Auto { k: 5.0 },
    };
    let r = backprojection(&op.zero_mean(), &y, &params).unwrap();
    let truth = scene.depth_map();
    for (p, &d) in truth.depth.iter().enumerate() {
        assert_eq!(r.peaks[p], d, "pixel {p}");
    }
    // Amplitudes are estimated to within the cross-talk (a few percent at this K_p).
    for (got, want) in r.x.iter().zip(scene.as_slice()) {
        assert!((got - want).abs() < 0.1, "{got} vs {want}");
    }
}

#[test]
fn backprojection_thresholds_and_rejects_invalid_parameters() {
    let kp = 2_000;
    let (g, op, y, _) = lidar_problem(kp);
    let base = Backprojection {
        column_len: g.ks,
        normalization: kp as f64 / 4.0,
        threshold: Threshold::None,
    };
    let all = backprojection(&op, &y, &base).unwrap();
    assert!(all.peaks.iter().all(|&p| p >= 0));
    let none = backprojection(
        &op,
        &y,
        &Backprojection {
            threshold: Threshold::Absolute(1e9),
            ..base
        },
    )
    .unwrap();
    assert!(none.peaks.iter().all(|&p| p == -1) && none.x.iter().all(|&v| v == 0.0));
    let rel = backprojection(
        &op,
        &y,
        &Backprojection {
            threshold: Threshold::RelativeToMax(1.0),
            ..base
        },
    )
    .unwrap();
    assert_eq!(rel.peaks.iter().filter(|&&p| p >= 0).count(), 1);
    for bad in [
        Backprojection {
            column_len: 0,
            ..base
        },
        Backprojection {
            column_len: 7,
            ..base
        },
        Backprojection {
            normalization: 0.0,
            ..base
        },
        Backprojection {
            threshold: Threshold::RelativeToMax(1.5),
            ..base
        },
        Backprojection {
            threshold: Threshold::Auto { k: f64::NAN },
            ..base
        },
    ] {
        assert!(
            matches!(
                backprojection(&op, &y, &bad),
                Err(Error::InvalidParameter { .. })
            ),
            "{bad:?}"
        );
    }
    assert!(matches!(
        backprojection(&op, &y[1..], &base),
        Err(Error::ShapeMismatch { .. })
    ));
    // All-zero measurements: finite output, nothing detected above a positive threshold.
    let zero = backprojection(
        &op,
        &vec![0.0; y.len()],
        &Backprojection {
            threshold: Threshold::Auto { k: 3.0 },
            ..base
        },
    )
    .unwrap();
    assert!(zero.x.iter().all(|v| *v == 0.0));
}

#[test]
fn argmin_executor_drives_cgls_to_the_same_solution() {
    use argmin::core::{Executor, State, TerminationReason, TerminationStatus};
    use rdlidar::solver::{ArgminCgls, LinearLeastSquares};
    let (a, an) = dense(40, 15, 21);
    let y = random_vec(40, 22);
    let op = DenseMatrix::new(a).unwrap();
    for lambda in [0.0, 0.7] {
        let want = reference(&an, &y, lambda);
        let problem = LinearLeastSquares { op: &op, y: &y };
        let argmin_params = CglsParams {
            damp: lambda,
            stopping: Stopping {
                rel_residual: Some(1e-12),
                ..Stopping::default()
            },
        };
        let res = Executor::new(problem, ArgminCgls::new(argmin_params).unwrap())
            .configure(|s| s.param(vec![0.0; 15]).max_iters(200))
            .run()
            .unwrap();
        let x = res.state().get_best_param().unwrap();
        assert!(
            rel_err(x, &want) < 1e-8,
            "λ = {lambda}: {:e}",
            rel_err(x, &want)
        );
        assert_eq!(
            res.state().get_termination_status(),
            &TerminationStatus::Terminated(TerminationReason::SolverConverged)
        );
        // The same iterations as the native solver.
        let mut xn = vec![0.0; 15];
        let params = CglsParams {
            damp: lambda,
            stopping: Stopping {
                max_iter: 200,
                rel_residual: Some(1e-12),
                ..Stopping::default()
            },
        };
        let report = cgls(&op, &y, &mut xn, &params, &mut ()).unwrap();
        assert_eq!(res.state().get_iter() as usize, report.iterations);
    }
    // Argmin's iteration limit applies.
    let problem = LinearLeastSquares { op: &op, y: &y };
    let res = Executor::new(problem, ArgminCgls::new(CglsParams::default()).unwrap())
        .configure(|s| s.param(vec![0.0; 15]).max_iters(3))
        .run()
        .unwrap();
    assert_eq!(res.state().get_iter(), 3);
    // Errors are reported, not panics.
    let problem = LinearLeastSquares {
        op: &op,
        y: &y[..39],
    };
    assert!(
        Executor::new(problem, ArgminCgls::new(CglsParams::default()).unwrap())
            .configure(|s| s.param(vec![0.0; 15]))
            .run()
            .is_err()
    );
    let nan_damp = CglsParams {
        damp: f64::NAN,
        ..CglsParams::default()
    };
    assert!(ArgminCgls::<f64>::new(nan_damp).is_err());
}

/// A badly scaled problem in `f32`: a 1×1 operator of 10⁻¹⁸ or 10⁻²⁰, whose solution 10¹⁸ or
/// 10²⁰ fits in `f32` although the step α = ‖Aᵀr‖²/‖Ap‖² that reaches it (10³⁶, 10⁴⁰) may not,
/// and whose curvature ‖Ap‖² underflows to zero once the residual is at round-off.
#[test]
fn cgls_solves_badly_scaled_problems_to_round_off_instead_of_breaking_down() {
    for a in [1e-18f32, 3e-19, 1e-20] {
        let op = DenseMatrix::new(Array2::from_elem((1, 1), a)).unwrap();
        let mut x = vec![0.0f32];
        let params = CglsParams {
            damp: 0.0,
            stopping: Stopping {
                max_iter: 10,
                rel_residual: Some(1e-30),
                ..Stopping::default()
            },
        };
        let r = cgls(&op, &[1.0f32], &mut x, &params, &mut ()).unwrap();
        let want = 1.0 / f64::from(a);
        assert!(
            // Within the precision of the subnormal products A·p (10⁻⁴⁰ at a = 10⁻²⁰).
            (f64::from(x[0]) - want).abs() <= 1e-4 * want,
            "a {a:e}: x {} ({:?})",
            x[0],
            r.termination
        );
        assert!(r.iterations <= 10, "a {a:e}: {}", r.iterations);
    }
}
