//! Sparse solvers: FISTA against the lasso optimality conditions, IHT and CoSaMP recovering exact
//! supports on Gaussian matrices and on the lidar operator, apply counts, degenerate inputs and
//! typed errors.

use std::sync::Arc;

use ndarray::Array2;
use proptest::prelude::*;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rdlidar::lidar::{random_opaque_scene, Codes, Geometry, Pulse, RdOperator};
use rdlidar::operator::{Counted, DenseMatrix, LinearOperator, PowerIteration, Zero};
use rdlidar::solver::{
    cosamp, fista, iht, CglsParams, Control, CosampParams, FistaParams, IhtParams, IhtStep,
    IterationInfo, Lambda, Report, Restart, StepRule, Stopping, Termination,
};
use rdlidar::{Error, Real};

use crate::common::random_vec;

/// An m × n matrix of i.i.d. N(0, 1/m) entries (columns of unit norm on average).
fn gaussian(m: usize, n: usize, seed: u64) -> Array2<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let scale = 1.0 / (m as f64).sqrt();
    Array2::from_shape_simple_fn((m, n), || {
        let v: f64 = StandardNormal.sample(&mut rng);
        v * scale
    })
}

/// An s-sparse vector of length n: a random support, entries ±(1 + u) with u uniform in [0, 1).
fn sparse_vec(n: usize, s: usize, seed: u64) -> Vec<f64> {
    let keys = random_vec(n, seed);
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| keys[a].total_cmp(&keys[b]));
    let vals = random_vec(s, seed ^ 0x5eed);
    let mut x = vec![0.0; n];
    for (&i, &v) in order[..s].iter().zip(&vals) {
        x[i] = v.signum() * (1.0 + v.abs());
    }
    x
}

fn matvec(a: &Array2<f64>, x: &[f64]) -> Vec<f64> {
    a.rows()
        .into_iter()
        .map(|row| row.iter().zip(x).map(|(u, v)| u * v).sum())
        .collect()
}

fn matvec_t(a: &Array2<f64>, y: &[f64]) -> Vec<f64> {
    a.columns()
        .into_iter()
        .map(|col| col.iter().zip(y).map(|(u, v)| u * v).sum())
        .collect()
}

fn support<T: Real>(x: &[T]) -> Vec<usize> {
    (0..x.len()).filter(|&i| x[i] != T::zero()).collect()
}

fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let n: f64 = b.iter().map(|v| v * v).sum();
    (d / n.max(1e-300)).sqrt()
}

fn to_t<T: Real>(v: &[f64]) -> Vec<T> {
    v.iter().map(|&x| T::of_f64(x)).collect()
}

fn to_f64<T: Real>(v: &[T]) -> Vec<f64> {
    v.iter().map(|x| x.as_f64()).collect()
}

/// The report's counts are those of a counter around the operator.
fn assert_counts<A>(report: &Report, counted: &Counted<A>) {
    assert_eq!(
        report.forward_applies,
        counted.forward_count(),
        "{report:?}"
    );
    assert_eq!(
        report.adjoint_applies,
        counted.adjoint_count(),
        "{report:?}"
    );
    assert_eq!(
        report.support_applies,
        counted.support_count(),
        "{report:?}"
    );
}

// ---------------------------------------------------------------------------------------------
// FISTA

/// Tight stopping: only the relative change of x.
fn tight(max_iter: usize) -> Stopping {
    Stopping {
        max_iter,
        rel_residual: None,
        rel_change: Some(1e-13),
        ..Stopping::default()
    }
}

/// Checks the optimality conditions of min ½‖Ax − y‖² + λ‖x‖₁ (or with x ≥ 0) at x, with
/// c = Aᵀ(y − Ax): |c_j| ≤ λ everywhere and c_j = λ·sign(x_j) on the support (nonnegative: c_j ≤ λ
/// everywhere, x ≥ 0 and c_j = λ where x_j > 0), each within tol·λ.
fn check_lasso_kkt(a: &Array2<f64>, y: &[f64], x: &[f64], lambda: f64, nonneg: bool, tol: f64) {
    let ax = matvec(a, x);
    let r: Vec<f64> = y.iter().zip(&ax).map(|(u, v)| u - v).collect();
    let c = matvec_t(a, &r);
    for (j, (&cj, &xj)) in c.iter().zip(x).enumerate() {
        if nonneg {
            assert!(xj >= 0.0, "x[{j}] = {xj}");
            assert!(cj <= lambda * (1.0 + tol), "c[{j}] = {cj} > λ = {lambda}");
        } else {
            assert!(
                cj.abs() <= lambda * (1.0 + tol),
                "|c[{j}]| = {} > λ = {lambda}",
                cj.abs()
            );
        }
        if xj != 0.0 {
            assert!(
                (cj - lambda * xj.signum()).abs() <= tol * lambda,
                "c[{j}] = {cj} but x[{j}] = {xj}, λ = {lambda}"
            );
        }
    }
}

fn non_increasing(history: &[f64]) {
    for (k, w) in history.windows(2).enumerate() {
        assert!(
            w[1] <= w[0] * (1.0 + 1e-12) + 1e-15,
            "objective rose at iteration {}: {} → {}",
            k + 2,
            w[0],
            w[1]
        );
    }
}

proptest! {
    #![proptest_config(crate::common::config(12))]

    #[test]
    fn fista_reaches_the_lasso_optimality_conditions(
        seed in any::<u64>(),
        frac in 0.05f64..0.6,
        nonneg in any::<bool>(),
        backtracking in any::<bool>(),
    ) {
        let (m, n) = (40, 80);
        let a = gaussian(m, n, seed);
        let op = DenseMatrix::new(a.clone()).unwrap();
        let y = matvec(&a, &sparse_vec(n, 6, seed ^ 1))
            .iter()
            .zip(random_vec(m, seed ^ 2))
            .map(|(v, e)| v + 0.05 * e)
            .collect::<Vec<_>>();
        let top = matvec_t(&a, &y).iter().fold(0.0f64, |t, v| t.max(v.abs()));
        let lambda = frac * top;
        let step = if backtracking {
            StepRule::Backtracking { eta: 1.5 }
        } else {
            StepRule::default()
        };
        for restart in [Restart::Function, Restart::Gradient, Restart::Off] {
            let params = FistaParams {
                lambda: if restart == Restart::Gradient {
                    Lambda::Absolute(lambda)
                } else {
                    Lambda::Fraction(frac)
                },
                nonnegative: nonneg,
                step,
                restart,
                stopping: tight(50_000),
            };
            let counted = Counted::new(&op);
            let mut x = vec![0.0; n];
            let report = fista(&counted, &y, &mut x, &params, &mut ()).unwrap();
            prop_assert_eq!(report.termination, Termination::Change, "{:?}: {:?}", restart, report.iterations);
            assert_counts(&report, &counted);
            check_lasso_kkt(&a, &y, &x, lambda, nonneg, 1e-6);
            // The reported objective is the lasso objective at x.
            let ax = matvec(&a, &x);
            let obj = 0.5 * ax.iter().zip(&y).map(|(u, v)| (u - v).powi(2)).sum::<f64>()
                + lambda * x.iter().map(|v| v.abs()).sum::<f64>();
            let last = *report.objective_history.last().unwrap();
            prop_assert!((last - obj).abs() <= 1e-10 * obj, "{last} vs {obj}");
            if restart == Restart::Function {
                non_increasing(&report.objective_history);
            }
        }
    }
}

#[test]
fn fista_restart_speeds_up_convergence_and_warm_starts_finish_at_once() {
    let (m, n) = (40, 80);
    let a = gaussian(m, n, 11);
    let op = DenseMatrix::new(a.clone()).unwrap();
    let y = matvec(&a, &sparse_vec(n, 6, 12));
    let run = |restart, x: &mut [f64]| {
        let params = FistaParams {
            lambda: Lambda::Fraction(0.05),
            restart,
            stopping: tight(50_000),
            ..FistaParams::default()
        };
        fista(&op, &y, x, &params, &mut ()).unwrap()
    };
    let mut x_plain = vec![0.0; n];
    let plain = run(Restart::Off, &mut x_plain);
    let mut x = vec![0.0; n];
    let restarted = run(Restart::Function, &mut x);
    assert!(
        restarted.iterations < plain.iterations,
        "restart {} vs plain {}",
        restarted.iterations,
        plain.iterations
    );
    assert!(rel_err(&x, &x_plain) < 1e-8);
    // From the solution, the first step already changes nothing beyond rounding.
    let again = run(Restart::Function, &mut x);
    assert!(again.iterations <= 3, "{again:?}");
    assert!(rel_err(&x, &x_plain) < 1e-8);
}

#[test]
fn fista_f32_agrees_with_f64() {
    let (m, n) = (40, 80);
    let a = gaussian(m, n, 21);
    let y = matvec(&a, &sparse_vec(n, 5, 22));
    let params = FistaParams {
        lambda: Lambda::Fraction(0.1),
        stopping: Stopping {
            max_iter: 5000,
            rel_change: Some(1e-6),
            ..Stopping::default()
        },
        ..FistaParams::default()
    };
    let mut x64 = vec![0.0; n];
    fista(
        &DenseMatrix::new(a.clone()).unwrap(),
        &y,
        &mut x64,
        &params,
        &mut (),
    )
    .unwrap();
    let mut x32 = vec![0.0f32; n];
    let op32 = DenseMatrix::new(a.mapv(|v| v as f32)).unwrap();
    let r = fista(&op32, &to_t::<f32>(&y), &mut x32, &params, &mut ()).unwrap();
    assert!(x32.iter().all(|v| v.is_finite()));
    assert!(rel_err(&to_f64(&x32), &x64) < 1e-3, "{r:?}");
}

// ---------------------------------------------------------------------------------------------
// IHT and CoSaMP

#[derive(Debug, Clone, Copy)]
enum Greedy {
    Iht,
    Cosamp,
}

fn run_greedy<T: Real, A: LinearOperator<T> + ?Sized>(
    which: Greedy,
    op: &A,
    y: &[T],
    s: usize,
    x: &mut [T],
) -> Report {
    let counted = Counted::new(op);
    let report = match which {
        Greedy::Iht => iht(&counted, y, x, &IhtParams::new(s), &mut ()),
        Greedy::Cosamp => cosamp(&counted, y, x, &CosampParams::new(s), &mut ()),
    }
    .unwrap();
    assert_counts(&report, &counted);
    report
}

fn gaussian_recovery<T: Real>(which: Greedy, seed: u64, tol: f64) {
    let (m, n, s) = (60, 200, 5);
    let a = gaussian(m, n, seed);
    let truth = sparse_vec(n, s, seed ^ 3);
    let y = matvec(&a, &truth);
    let op = DenseMatrix::new(a.mapv(T::of_f64)).unwrap();
    let mut x = vec![T::zero(); n];
    let report = run_greedy(which, &op, &to_t::<T>(&y), s, &mut x);
    assert_eq!(
        support(&x),
        support(&truth),
        "{which:?} {}: {report:?}",
        T::NAME
    );
    let err = rel_err(&to_f64(&x), &truth);
    assert!(
        err < tol,
        "{which:?} {}: error {err:e}, {report:?}",
        T::NAME
    );
    assert!(matches!(
        report.termination,
        Termination::Residual | Termination::Converged
    ));
}

proptest! {
    #![proptest_config(crate::common::config(10))]

    #[test]
    fn iht_and_cosamp_recover_exact_supports_on_gaussian_matrices(seed in any::<u64>()) {
        for which in [Greedy::Iht, Greedy::Cosamp] {
            gaussian_recovery::<f64>(which, seed, 1e-5);
            gaussian_recovery::<f32>(which, seed, 1e-3);
        }
    }
}

/// A 4×4×8 scene with four lit pixels (one voxel each), the plain random-demodulation operator
/// with a Bernoulli pulse of length K_p and ±1 codes, and the noise-free measurements.
fn lidar_problem<T: Real>(kp: usize, seed: u64) -> (RdOperator<T>, Vec<T>, Vec<f64>) {
    let g = Geometry::new(4, 4, 8).unwrap();
    let scene = random_opaque_scene::<f64>(g, 0.5, seed).unwrap();
    let mut truth = scene.as_slice().to_vec();
    let lit: Vec<usize> = support(&truth);
    assert!(lit.len() >= 4, "seed {seed} lights {} pixels", lit.len());
    for &i in &lit[4..] {
        truth[i] = 0.0;
    }
    let pulse = Pulse::<T>::bernoulli(kp, seed ^ 1).unwrap().into_inner();
    let codes = Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), seed ^ 2).unwrap());
    let op = RdOperator::new(g, pulse, codes).unwrap();
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(&to_t::<T>(&truth), &mut y);
    (op, y, truth)
}

fn lidar_recovery<T: Real>(which: Greedy, seed: u64, tol: f64) {
    let (op, y, truth) = lidar_problem::<T>(200, seed);
    let mut x = vec![T::zero(); op.ncols()];
    let report = run_greedy(which, &op, &y, 4, &mut x);
    assert_eq!(
        support(&x),
        support(&truth),
        "{which:?} {}: {report:?}",
        T::NAME
    );
    let err = rel_err(&to_f64(&x), &truth);
    assert!(
        err < tol,
        "{which:?} {}: error {err:e}, {report:?}",
        T::NAME
    );
}

#[test]
fn iht_and_cosamp_recover_a_lidar_scene() {
    for seed in [7, 8, 9] {
        for which in [Greedy::Iht, Greedy::Cosamp] {
            lidar_recovery::<f64>(which, seed, 1e-5);
            lidar_recovery::<f32>(which, seed, 1e-3);
        }
    }
}

#[test]
fn iht_with_the_fixed_step_recovers_and_counts_the_power_iteration() {
    let (m, n, s) = (100, 200, 5);
    let a = gaussian(m, n, 31);
    let truth = sparse_vec(n, s, 32);
    let y = matvec(&a, &truth);
    let op = DenseMatrix::new(a).unwrap();
    let counted = Counted::new(&op);
    let mut x = vec![0.0; n];
    let params = IhtParams {
        step: IhtStep::PowerIteration {
            settings: PowerIteration::default(),
            margin: 1.01,
        },
        stopping: Stopping {
            max_iter: 5000,
            ..Stopping::default()
        },
        ..IhtParams::new(s)
    };
    let report = iht(&counted, &y, &mut x, &params, &mut ()).unwrap();
    assert_counts(&report, &counted);
    assert_eq!(support(&x), support(&truth), "{report:?}");
    assert!(rel_err(&x, &truth) < 1e-5);
    // One adjoint per iteration plus those of the power iteration, one forward per iteration plus
    // the initial residual and the power iteration's: both exceed the iteration count equally.
    assert!(report.adjoint_applies > report.iterations);
    assert_eq!(report.forward_applies, report.adjoint_applies + 1);
}

#[test]
fn greedy_solvers_accept_warm_starts_and_report_their_work() {
    let (m, n, s) = (60, 200, 5);
    let a = gaussian(m, n, 41);
    let truth = sparse_vec(n, s, 42);
    let y = matvec(&a, &truth);
    let op = DenseMatrix::new(a).unwrap();
    // From the truth: the residual is already zero after one iteration.
    for which in [Greedy::Iht, Greedy::Cosamp] {
        let mut x = truth.clone();
        let report = run_greedy(which, &op, &y, s, &mut x);
        assert_eq!(report.iterations, 1, "{which:?}: {report:?}");
        assert!(rel_err(&x, &truth) < 1e-10);
    }
    // A warm start with too many nonzeros is pruned to s first.
    let mut x: Vec<f64> = truth.iter().map(|v| v + 1e-3).collect();
    let report = run_greedy(Greedy::Cosamp, &op, &y, s, &mut x);
    assert_eq!(support(&x), support(&truth), "{report:?}");
    // IHT with the normalized step: one adjoint per iteration; one forward for the step and at
    // least one for the new iterate per iteration, plus the initial residual.
    let counted = Counted::new(&op);
    let mut x = vec![0.0; n];
    let r = iht(&counted, &y, &mut x, &IhtParams::new(s), &mut ()).unwrap();
    assert_eq!(r.adjoint_applies, r.iterations);
    assert!(r.forward_applies > 2 * r.iterations);
    // CoSaMP: one adjoint per iteration, and the inner CGLS's applications of the operator
    // restricted to the merged support, counted apart as support applications.
    let counted = Counted::new(&op);
    let mut x = vec![0.0; n];
    let r = cosamp(&counted, &y, &mut x, &CosampParams::new(s), &mut ()).unwrap();
    assert_counts(&r, &counted);
    assert_eq!(r.adjoint_applies, r.iterations, "{r:?}");
    assert!(r.support_applies > 2 * r.iterations, "{r:?}");
}

#[test]
fn observers_see_every_iteration_of_every_solver() {
    let (m, n, s) = (60, 200, 5);
    let a = gaussian(m, n, 51);
    let y = matvec(&a, &sparse_vec(n, s, 52));
    let op = DenseMatrix::new(a).unwrap();
    for which in 0..3 {
        // CoSaMP solves this problem in two iterations.
        let stop_at = if which == 2 { 2 } else { 4 };
        let mut seen = Vec::new();
        let mut obs = |info: &IterationInfo<'_, f64>| {
            seen.push((info.iteration, info.residual, info.objective));
            if info.iteration == stop_at {
                Control::Stop
            } else {
                Control::Continue
            }
        };
        let mut x = vec![0.0; n];
        let r = match which {
            0 => fista(&op, &y, &mut x, &FistaParams::default(), &mut obs),
            1 => iht(&op, &y, &mut x, &IhtParams::new(s), &mut obs),
            _ => cosamp(&op, &y, &mut x, &CosampParams::new(s), &mut obs),
        }
        .unwrap();
        assert_eq!(
            (r.termination, r.iterations),
            (Termination::Observer, stop_at),
            "{r:?}"
        );
        assert_eq!(
            seen.iter().map(|v| v.0).collect::<Vec<_>>(),
            (1..=stop_at).collect::<Vec<_>>()
        );
        assert_eq!(
            r.residual_history,
            seen.iter().map(|v| v.1).collect::<Vec<_>>()
        );
        assert_eq!(
            r.objective_history,
            seen.iter().map(|v| v.2).collect::<Vec<_>>()
        );
        // The iteration limit is a termination reason.
        let mut x = vec![0.0; n];
        let stop = Stopping::iterations(2);
        let r = match which {
            0 => fista(
                &op,
                &y,
                &mut x,
                &FistaParams {
                    stopping: stop,
                    ..FistaParams::default()
                },
                &mut (),
            ),
            1 => iht(
                &op,
                &y,
                &mut x,
                &IhtParams {
                    stopping: stop,
                    ..IhtParams::new(s)
                },
                &mut (),
            ),
            _ => cosamp(
                &op,
                &y,
                &mut x,
                &CosampParams {
                    stopping: stop,
                    ..CosampParams::new(s)
                },
                &mut (),
            ),
        }
        .unwrap();
        assert_eq!(
            (r.termination, r.iterations),
            (Termination::MaxIterations, 2),
            "{r:?}"
        );
        assert_eq!(r.residual_history.len(), 2);
    }
}

// ---------------------------------------------------------------------------------------------
// Degenerate inputs and errors

/// Runs solver `which` (0 FISTA power step, 1 FISTA backtracking, 2 IHT normalized, 3 IHT fixed
/// step, 4 CoSaMP) with sparsity or λ defaults.
fn run_any<A: LinearOperator<f64> + ?Sized>(
    which: usize,
    op: &A,
    y: &[f64],
    x: &mut [f64],
) -> rdlidar::Result<Report> {
    let s = 3;
    match which {
        0 => fista(op, y, x, &FistaParams::default(), &mut ()),
        1 => fista(
            op,
            y,
            x,
            &FistaParams {
                step: StepRule::Backtracking { eta: 2.0 },
                lambda: Lambda::Absolute(0.1),
                nonnegative: true,
                ..FistaParams::default()
            },
            &mut (),
        ),
        2 => iht(op, y, x, &IhtParams::new(s), &mut ()),
        3 => iht(
            op,
            y,
            x,
            &IhtParams {
                step: IhtStep::PowerIteration {
                    settings: PowerIteration::default(),
                    margin: 1.01,
                },
                ..IhtParams::new(s)
            },
            &mut (),
        ),
        _ => cosamp(op, y, x, &CosampParams::new(s), &mut ()),
    }
}

#[test]
fn zero_measurements_and_zero_operators_give_finite_results() {
    let (m, n) = (20, 30);
    let a = gaussian(m, n, 61);
    let op = DenseMatrix::new(a).unwrap();
    let z = Zero::<f64>::new(m, n);
    let y = random_vec(m, 62);
    for which in 0..5 {
        // y = 0: x is the zero solution, nothing is applied.
        let counted = Counted::new(&op);
        let mut x = random_vec(n, 63);
        let r = run_any(which, &counted, &vec![0.0; m], &mut x).unwrap();
        assert_eq!(
            (r.termination, r.iterations),
            (Termination::ZeroResidual, 0)
        );
        assert!(x.iter().all(|&v| v == 0.0), "solver {which}");
        assert_counts(&r, &counted);
        assert_eq!(r.forward_applies + r.adjoint_applies, 0);
        // A zero operator: finite x, finite histories.
        for x0 in [vec![0.0; n], random_vec(n, 64)] {
            let counted = Counted::new(&z);
            let mut x = x0;
            let r = run_any(which, &counted, &y, &mut x)
                .unwrap_or_else(|e| panic!("solver {which}: {e}"));
            assert!(x.iter().all(|v| v.is_finite()), "solver {which}: {x:?}");
            assert!(r.residual_history.iter().all(|v| v.is_finite()));
            assert!(r.objective_history.iter().all(|v| v.is_finite()));
            assert_counts(&r, &counted);
        }
    }
}

#[test]
fn invalid_parameters_and_shapes_are_typed_errors() {
    let (m, n) = (20, 30);
    let op = DenseMatrix::new(gaussian(m, n, 71)).unwrap();
    let y = random_vec(m, 72);
    let x0 = vec![0.0; n];
    let fista_err = |p: FistaParams| fista(&op, &y, &mut x0.clone(), &p, &mut ()).unwrap_err();
    let iht_err = |p: IhtParams| iht(&op, &y, &mut x0.clone(), &p, &mut ()).unwrap_err();
    let cosamp_err = |p: CosampParams| cosamp(&op, &y, &mut x0.clone(), &p, &mut ()).unwrap_err();
    let name = |e: Error| match e {
        Error::InvalidParameter { name, .. } => name,
        other => panic!("expected InvalidParameter, got {other:?}"),
    };
    let base = FistaParams::default();
    for lambda in [
        Lambda::Absolute(-1.0),
        Lambda::Absolute(f64::NAN),
        Lambda::Fraction(-0.1),
        Lambda::Fraction(f64::INFINITY),
    ] {
        assert_eq!(name(fista_err(FistaParams { lambda, ..base })), "lambda");
    }
    for eta in [1.0, 0.5, f64::NAN] {
        let p = FistaParams {
            step: StepRule::Backtracking { eta },
            ..base
        };
        assert_eq!(name(fista_err(p)), "eta");
    }
    for margin in [0.99, f64::INFINITY] {
        let p = FistaParams {
            step: StepRule::PowerIteration {
                settings: PowerIteration::default(),
                margin,
            },
            ..base
        };
        assert_eq!(name(fista_err(p)), "margin");
    }
    let p = FistaParams {
        step: StepRule::PowerIteration {
            settings: PowerIteration {
                max_iter: 0,
                ..PowerIteration::default()
            },
            margin: 1.01,
        },
        ..base
    };
    assert_eq!(name(fista_err(p)), "power_iteration.max_iter");
    let zero_iter = Stopping {
        max_iter: 0,
        ..Stopping::default()
    };
    assert_eq!(
        name(fista_err(FistaParams {
            stopping: zero_iter,
            ..base
        })),
        "max_iter"
    );
    for s in [0, n + 1] {
        assert_eq!(name(iht_err(IhtParams::new(s))), "sparsity");
        assert_eq!(name(cosamp_err(CosampParams::new(s))), "sparsity");
    }
    assert_eq!(
        name(iht_err(IhtParams {
            stopping: zero_iter,
            ..IhtParams::new(3)
        })),
        "max_iter"
    );
    assert_eq!(
        name(iht_err(IhtParams {
            fixed_point_tol: f64::NAN,
            ..IhtParams::new(3)
        })),
        "fixed_point_tol"
    );
    assert_eq!(
        name(iht_err(IhtParams {
            step: IhtStep::PowerIteration {
                settings: PowerIteration {
                    tol: -1.0,
                    ..PowerIteration::default()
                },
                margin: 1.01,
            },
            ..IhtParams::new(3)
        })),
        "power_iteration.tol"
    );
    assert_eq!(
        name(cosamp_err(CosampParams {
            fixed_point_tol: -1.0,
            ..CosampParams::new(3)
        })),
        "fixed_point_tol"
    );
    assert_eq!(
        name(cosamp_err(CosampParams {
            inner: CglsParams {
                damp: -1.0,
                ..CglsParams::default()
            },
            ..CosampParams::new(3)
        })),
        "inner.damp"
    );
    assert_eq!(
        name(cosamp_err(CosampParams {
            stopping: zero_iter,
            ..CosampParams::new(3)
        })),
        "max_iter"
    );

    // Shapes and non-finite data, for every solver.
    let mut y_nan = y.clone();
    y_nan[3] = f64::NAN;
    let mut x_inf = x0.clone();
    x_inf[1] = f64::INFINITY;
    for which in 0..5 {
        let e = run_any(which, &op, &y[1..], &mut x0.clone()).unwrap_err();
        assert!(
            matches!(e, Error::ShapeMismatch { .. }),
            "solver {which}: {e:?}"
        );
        let e = run_any(which, &op, &y, &mut vec![0.0; n + 2]).unwrap_err();
        assert!(
            matches!(e, Error::ShapeMismatch { .. }),
            "solver {which}: {e:?}"
        );
        let e = run_any(which, &op, &y_nan, &mut x0.clone()).unwrap_err();
        assert!(
            matches!(e, Error::NonFinite { .. }),
            "solver {which}: {e:?}"
        );
        let e = run_any(which, &op, &y, &mut x_inf.clone()).unwrap_err();
        assert!(
            matches!(e, Error::NonFinite { .. }),
            "solver {which}: {e:?}"
        );
    }
}

/// An operator that hides `inner`'s own restriction, so that solvers restrict it with the generic
/// A·Rᵀ of the operator algebra.
struct Generic<'a, A>(&'a A);

impl<T: Real, A: LinearOperator<T>> LinearOperator<T> for Generic<'_, A> {
    fn nrows(&self) -> usize {
        self.0.nrows()
    }
    fn ncols(&self) -> usize {
        self.0.ncols()
    }
    fn scratch_len(&self) -> usize {
        self.0.scratch_len()
    }
    fn forward_kernel(&self, x: &[T], y: &mut [T], scratch: &mut [T]) {
        self.0.forward_kernel(x, y, scratch)
    }
    fn adjoint_kernel(&self, y: &[T], x: &mut [T], scratch: &mut [T]) {
        self.0.adjoint_kernel(y, x, scratch)
    }
}

/// CoSaMP's iterates, with its inner least squares cut short so that they depend on every inner
/// step.
fn cosamp_iterates<A: LinearOperator<f64> + ?Sized>(op: &A, y: &[f64], s: usize) -> Vec<Vec<f64>> {
    let mut params = CosampParams::new(s);
    params.inner.stopping.max_iter = 4;
    params.stopping.max_iter = 8;
    let mut xs = Vec::new();
    let mut x = vec![0.0; op.ncols()];
    let counted = Counted::new(op);
    let report = cosamp(&counted, y, &mut x, &params, &mut |info: &IterationInfo<
        '_,
        f64,
    >| {
        xs.push(info.x.to_vec());
        Control::Continue
    })
    .unwrap();
    assert_counts(&report, &counted);
    assert_eq!(xs.len(), report.iterations);
    xs
}

#[test]
fn cosamp_through_the_lidar_restriction_repeats_the_generic_iterates() {
    let g = Geometry::new(6, 6, 12).unwrap();
    let scene = random_opaque_scene::<f64>(g, 0.6, 41).unwrap();
    let truth = scene.as_slice().to_vec();
    let s = support(&truth).len();
    for ternary in [false, true] {
        let kp = 120;
        let pulse = Pulse::<f64>::bernoulli(kp, 42).unwrap().into_inner();
        let codes = if ternary {
            Codes::random_ternary(g.pixels(), g.samples(kp), 0.3, 43).unwrap()
        } else {
            Codes::random_binary(g.pixels(), g.samples(kp), 43).unwrap()
        };
        let op = RdOperator::new(g, pulse, Arc::new(codes)).unwrap();
        let mut y = vec![0.0; op.nrows()];
        op.apply(&truth, &mut y);
        let fast = cosamp_iterates(&op, &y, s);
        let generic = cosamp_iterates(&Generic(&op), &y, s);
        assert_eq!(fast.len(), generic.len());
        assert!(fast.len() > 1, "{} iterations", fast.len());
        for (k, (a, b)) in fast.iter().zip(&generic).enumerate() {
            assert_eq!(
                support(a),
                support(b),
                "ternary {ternary}, iteration {}",
                k + 1
            );
            let e = rel_err(a, b);
            assert!(e < 1e-9, "ternary {ternary}, iteration {}: {e:e}", k + 1);
        }
    }
}

#[test]
fn fista_with_a_fixed_step_is_the_textbook_iteration() {
    // Plain FISTA (no restart) with step 1/L: the iterates of the textbook recursion, written
    // here with dense products.
    let (m, n) = (30, 60);
    let a = gaussian(m, n, 17);
    let op = DenseMatrix::new(a.clone()).unwrap();
    let y = matvec(&a, &sparse_vec(n, 5, 18));
    let (lambda, l) = (0.05, 8.0);
    for iterations in [1, 2, 30] {
        let params = FistaParams {
            lambda: Lambda::Absolute(lambda),
            nonnegative: false,
            step: StepRule::Fixed { lipschitz: l },
            restart: Restart::Off,
            stopping: Stopping {
                max_iter: iterations,
                rel_residual: None,
                rel_change: None,
                ..Stopping::default()
            },
        };
        let mut x = vec![0.0; n];
        let report = fista(&op, &y, &mut x, &params, &mut ()).unwrap();
        assert_eq!(report.iterations, iterations);
        let (mut xr, mut z, mut t) = (vec![0.0; n], vec![0.0; n], 1.0f64);
        for _ in 0..iterations {
            let az = matvec(&a, &z);
            let r: Vec<f64> = az.iter().zip(&y).map(|(u, v)| u - v).collect();
            let g = matvec_t(&a, &r);
            let p: Vec<f64> = z
                .iter()
                .zip(&g)
                .map(|(zi, gi)| {
                    let v = zi - gi / l;
                    v.signum() * (v.abs() - lambda / l).max(0.0)
                })
                .collect();
            let t_next = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
            z = p
                .iter()
                .zip(&xr)
                .map(|(pi, xi)| pi + (t - 1.0) / t_next * (pi - xi))
                .collect();
            xr = p;
            t = t_next;
        }
        let diff: f64 = x.iter().zip(&xr).map(|(u, v)| (u - v).powi(2)).sum();
        let size: f64 = xr.iter().map(|v| v * v).sum();
        assert!(
            diff.sqrt() <= 1e-12 * size.sqrt(),
            "{iterations} iterations"
        );
    }
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let params = FistaParams {
            step: StepRule::Fixed { lipschitz: bad },
            ..FistaParams::default()
        };
        let mut x = vec![0.0; n];
        assert!(fista(&op, &y, &mut x, &params, &mut ()).is_err(), "{bad}");
    }
}
