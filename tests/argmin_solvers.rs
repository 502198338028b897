//! FISTA, IHT and CoSaMP driven by argmin's `Executor` against the native solvers (the same
//! iterates, objectives, apply counts and stopping decisions, also across a serialized restart),
//! their typed errors, and the progress-bar observer.

use std::io::IsTerminal;
use std::sync::{Arc, Mutex};

use argmin::core::observers::{Observe, ObserverMode};
use argmin::core::{Executor, Solver, State, TerminationReason, TerminationStatus, KV};
use ndarray::Array2;
use rdlidar::operator::{DenseMatrix, LinearOperator, PowerIteration};
use rdlidar::solver::{
    cosamp, fista, iht, ArgminCosamp, ArgminFista, ArgminIht, ArgminState, Control, CosampParams,
    FistaParams, IhtParams, IhtStep, IterationInfo, Lambda, LinearLeastSquares, ProgressObserver,
    Report, Restart, Stagnation, StepRule, Stopping, Termination,
};
use rdlidar::Error;
use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::common::random_vec;

const M: usize = 30;
const N: usize = 60;

/// A seeded M × N matrix with entries uniform in ±√(3/M) (unit column norms on average) and
/// y = A x♮ + noise for a 3-sparse x♮, so that no solver fits y exactly.
fn problem(seed: u64) -> (DenseMatrix<f64>, Vec<f64>) {
    let scale = (3.0 / M as f64).sqrt();
    let entries: Vec<f64> = random_vec(M * N, seed).iter().map(|v| v * scale).collect();
    let op = DenseMatrix::new(Array2::from_shape_vec((M, N), entries).unwrap()).unwrap();
    let mut truth = vec![0.0; N];
    for (i, v) in [(5, 1.5), (17, -2.0), (42, 1.2)] {
        truth[i] = v;
    }
    let mut y = vec![0.0; M];
    op.apply(&truth, &mut y);
    for (yi, e) in y.iter_mut().zip(random_vec(M, seed + 1)) {
        *yi += 0.01 * e;
    }
    (op, y)
}

/// (x, objective) after each iteration.
type Trajectory = Vec<(Vec<f64>, f64)>;

/// An argmin observer that records the trajectory.
struct Recorder(Arc<Mutex<Trajectory>>);

impl Observe<ArgminState<f64>> for Recorder {
    fn observe_iter(
        &mut self,
        state: &ArgminState<f64>,
        _kv: &KV,
    ) -> Result<(), argmin::core::Error> {
        let x = state.get_param().expect("a current x").clone();
        self.0.lock().unwrap().push((x, state.get_cost()));
        Ok(())
    }
}

/// What an argmin run left behind.
struct ArgminRun<S> {
    solver: S,
    state: ArgminState<f64>,
    forward: u64,
    adjoint: u64,
    trajectory: Trajectory,
}

fn execute<'a, S>(
    solver: S,
    op: &'a DenseMatrix<f64>,
    y: &'a [f64],
    configure: impl FnOnce(ArgminState<f64>) -> ArgminState<f64>,
) -> Result<ArgminRun<S>, argmin::core::Error>
where
    S: Solver<LinearLeastSquares<'a, f64, DenseMatrix<f64>>, ArgminState<f64>> + Clone,
{
    let trajectory = Arc::new(Mutex::new(Vec::new()));
    let problem = LinearLeastSquares { op, y };
    let res = Executor::new(problem, solver)
        .configure(configure)
        .add_observer(Recorder(trajectory.clone()), ObserverMode::Always)
        .run()?;
    let count = |name: &str| res.problem().counts.get(name).copied().unwrap_or(0);
    let (forward, adjoint) = (count("operator_forward"), count("operator_adjoint"));
    let trajectory = std::mem::take(&mut *trajectory.lock().unwrap());
    Ok(ArgminRun {
        solver: res.solver().clone(),
        state: res.state().clone(),
        forward,
        adjoint,
        trajectory,
    })
}

/// The parameters of one of the three solvers.
#[derive(Debug, Clone, Copy)]
enum Params {
    Fista(FistaParams),
    Iht(IhtParams),
    Cosamp(CosampParams),
}

impl Params {
    fn max_iter(&self) -> usize {
        match self {
            Params::Fista(p) => p.stopping.max_iter,
            Params::Iht(p) => p.stopping.max_iter,
            Params::Cosamp(p) => p.stopping.max_iter,
        }
    }
}

/// The native solver's report, final x and trajectory.
fn native(params: &Params, op: &DenseMatrix<f64>, y: &[f64], x0: &[f64]) -> (Report, Trajectory) {
    let mut x = x0.to_vec();
    let mut trajectory = Vec::new();
    let mut record = |info: &IterationInfo<'_, f64>| {
        trajectory.push((info.x.to_vec(), info.objective));
        Control::Continue
    };
    let report = match params {
        Params::Fista(p) => fista(op, y, &mut x, p, &mut record),
        Params::Iht(p) => iht(op, y, &mut x, p, &mut record),
        Params::Cosamp(p) => cosamp(op, y, &mut x, p, &mut record),
    }
    .unwrap();
    if let Some((last, _)) = trajectory.last() {
        assert_eq!(*last, x);
    }
    (report, trajectory)
}

/// The argmin reason for a native termination.
fn argmin_reason(t: Termination) -> TerminationReason {
    match t {
        Termination::MaxIterations => TerminationReason::MaxItersReached,
        Termination::Residual
        | Termination::Change
        | Termination::Stagnation
        | Termination::Converged
        | Termination::ZeroResidual => TerminationReason::SolverConverged,
        other => panic!("no argmin counterpart for {other:?}"),
    }
}

/// Runs the argmin solver `make()` with the executor's limit at the native `max_iter`, checks
/// that it reproduces the native run exactly, then repeats the run in two parts with the solver
/// passed through JSON in between, and checks the same again.
fn matches_native<S>(what: &str, params: Params, make: impl Fn() -> S, x0: &[f64], seed: u64)
where
    S: for<'a> Solver<LinearLeastSquares<'a, f64, DenseMatrix<f64>>, ArgminState<f64>>
        + Clone
        + Serialize
        + DeserializeOwned,
{
    let (op, y) = problem(seed);
    let (report, want) = native(&params, &op, &y, x0);
    let max_iters = params.max_iter() as u64;
    let check = |run: &ArgminRun<S>, forward: u64, adjoint: u64, trajectory: &Trajectory| {
        assert_eq!(
            run.state.get_iter() as usize,
            report.iterations,
            "{what}: {report:?}"
        );
        assert_eq!(
            run.state.get_termination_status(),
            &TerminationStatus::Terminated(argmin_reason(report.termination)),
            "{what}: {report:?}"
        );
        assert_eq!(forward as usize, report.forward_applies, "{what}: forward");
        assert_eq!(adjoint as usize, report.adjoint_applies, "{what}: adjoint");
        assert_eq!(trajectory.len(), want.len(), "{what}");
        for (k, ((xa, fa), (xn, fn_))) in trajectory.iter().zip(&want).enumerate() {
            assert_eq!(xa, xn, "{what}: x after iteration {}", k + 1);
            assert_eq!(fa, fn_, "{what}: objective after iteration {}", k + 1);
        }
    };

    let whole = execute(make(), &op, &y, |s| {
        s.param(x0.to_vec()).max_iters(max_iters)
    })
    .unwrap();
    check(&whole, whole.forward, whole.adjoint, &whole.trajectory);
    if let Some((x, _)) = want.last() {
        assert_eq!(whole.state.get_param().unwrap(), x, "{what}");
    }

    // Two parts, the solver serialized in between; the second part continues the first.
    let split = report.iterations as u64 / 2;
    if split == 0 {
        return;
    }
    let first = execute(make(), &op, &y, |s| s.param(x0.to_vec()).max_iters(split)).unwrap();
    assert_eq!(first.state.get_iter(), split, "{what}");
    let json = serde_json::to_string(&first.solver).unwrap();
    let solver: S = serde_json::from_str(&json).unwrap();
    assert_eq!(serde_json::to_string(&solver).unwrap(), json, "{what}");
    // As a checkpoint would hold it: before the executor's termination check.
    let mut state = first.state.clone();
    state.termination_status = TerminationStatus::NotTerminated;
    let second = execute(solver, &op, &y, |_| state.max_iters(max_iters)).unwrap();
    let mut trajectory = first.trajectory.clone();
    trajectory.extend(second.trajectory.iter().cloned());
    check(
        &second,
        first.forward + second.forward,
        first.adjoint + second.adjoint,
        &trajectory,
    );
}

fn fista_cases() -> Vec<(&'static str, FistaParams, Vec<f64>)> {
    vec![
        (
            "fista default",
            FistaParams {
                stopping: Stopping {
                    max_iter: 400,
                    ..FistaParams::default().stopping
                },
                ..FistaParams::default()
            },
            vec![0.0; N],
        ),
        (
            "fista backtracking, gradient restart, nonnegative, stagnation",
            FistaParams {
                lambda: Lambda::Absolute(0.02),
                nonnegative: true,
                step: StepRule::Backtracking { eta: 2.0 },
                restart: Restart::Gradient,
                stopping: Stopping {
                    max_iter: 400,
                    rel_residual: None,
                    rel_change: None,
                    stagnation: Some(Stagnation {
                        rel: 1e-9,
                        window: 5,
                        floor: 0.0,
                    }),
                    time_limit: None,
                },
            },
            random_vec(N, 7),
        ),
        (
            "fista without restart, iteration limit",
            FistaParams {
                restart: Restart::Off,
                stopping: Stopping::iterations(12),
                ..FistaParams::default()
            },
            random_vec(N, 8),
        ),
    ]
}

fn iht_cases() -> Vec<(&'static str, IhtParams, Vec<f64>)> {
    vec![
        ("iht normalized", IhtParams::new(3), vec![0.0; N]),
        (
            "iht fixed step, warm start",
            IhtParams {
                step: IhtStep::PowerIteration {
                    settings: PowerIteration::default(),
                    margin: 1.05,
                },
                stopping: Stopping {
                    max_iter: 300,
                    ..Stopping::default()
                },
                ..IhtParams::new(4)
            },
            random_vec(N, 9),
        ),
        (
            "iht iteration limit",
            IhtParams {
                fixed_point_tol: 0.0,
                stopping: Stopping::iterations(4),
                ..IhtParams::new(6)
            },
            random_vec(N, 10),
        ),
    ]
}

fn cosamp_cases() -> Vec<(&'static str, CosampParams, Vec<f64>)> {
    vec![
        ("cosamp default", CosampParams::new(3), vec![0.0; N]),
        (
            "cosamp iteration limit, warm start",
            CosampParams {
                fixed_point_tol: 0.0,
                stopping: Stopping::iterations(2),
                ..CosampParams::new(5)
            },
            random_vec(N, 11),
        ),
    ]
}

#[test]
fn argmin_fista_reproduces_the_native_iterates() {
    for (what, params, x0) in fista_cases() {
        matches_native(
            what,
            Params::Fista(params),
            || ArgminFista::<f64>::new(params).unwrap(),
            &x0,
            100,
        );
    }
}

#[test]
fn argmin_iht_reproduces_the_native_iterates() {
    for (what, params, x0) in iht_cases() {
        matches_native(
            what,
            Params::Iht(params),
            || ArgminIht::<f64>::new(params).unwrap(),
            &x0,
            200,
        );
    }
}

#[test]
fn argmin_cosamp_reproduces_the_native_iterates() {
    for (what, params, x0) in cosamp_cases() {
        matches_native(
            what,
            Params::Cosamp(params),
            || ArgminCosamp::<f64>::new(params).unwrap(),
            &x0,
            300,
        );
    }
}

/// The cases above end in every way they should: by convergence and by the iteration limit.
#[test]
fn the_cases_cover_convergence_and_the_iteration_limit() {
    let mut reasons = Vec::new();
    let all = fista_cases()
        .into_iter()
        .map(|(w, p, x)| (w, Params::Fista(p), x, 100))
        .chain(
            iht_cases()
                .into_iter()
                .map(|(w, p, x)| (w, Params::Iht(p), x, 200)),
        )
        .chain(
            cosamp_cases()
                .into_iter()
                .map(|(w, p, x)| (w, Params::Cosamp(p), x, 300)),
        );
    for (what, params, x0, seed) in all {
        let (op, y) = problem(seed);
        let (report, _) = native(&params, &op, &y, &x0);
        assert!(report.iterations >= 2, "{what}: {report:?}");
        reasons.push((what, report.termination));
    }
    for (what, t) in &reasons {
        if what.contains("limit") {
            assert_eq!(*t, Termination::MaxIterations, "{what}");
        } else {
            assert_ne!(*t, Termination::MaxIterations, "{what}");
        }
    }
    assert!(reasons.iter().any(|(_, t)| *t == Termination::Stagnation));
}

#[test]
fn argmin_max_iters_stops_every_solver() {
    let (op, y) = problem(400);
    let x0 = vec![0.0; N];
    let configure = |s: ArgminState<f64>| s.param(vec![0.0; N]).max_iters(3);
    let tol_free = Stopping {
        rel_residual: None,
        ..Stopping::iterations(1000)
    };
    let fista_run = execute(
        ArgminFista::new(FistaParams {
            stopping: tol_free,
            ..FistaParams::default()
        })
        .unwrap(),
        &op,
        &y,
        configure,
    )
    .unwrap();
    let iht_run = execute(
        ArgminIht::new(IhtParams {
            fixed_point_tol: 0.0,
            stopping: tol_free,
            ..IhtParams::new(3)
        })
        .unwrap(),
        &op,
        &y,
        configure,
    )
    .unwrap();
    let cosamp_run = execute(
        ArgminCosamp::new(CosampParams {
            fixed_point_tol: 0.0,
            stopping: tol_free,
            ..CosampParams::new(3)
        })
        .unwrap(),
        &op,
        &y,
        configure,
    )
    .unwrap();
    for (what, state, forward, adjoint, steps) in [
        (
            "fista",
            &fista_run.state,
            fista_run.forward,
            fista_run.adjoint,
            fista_run.trajectory.len(),
        ),
        (
            "iht",
            &iht_run.state,
            iht_run.forward,
            iht_run.adjoint,
            iht_run.trajectory.len(),
        ),
        (
            "cosamp",
            &cosamp_run.state,
            cosamp_run.forward,
            cosamp_run.adjoint,
            cosamp_run.trajectory.len(),
        ),
    ] {
        assert_eq!(state.get_iter(), 3, "{what}");
        assert_eq!(steps, 3, "{what}");
        assert_eq!(
            state.get_termination_reason(),
            Some(&TerminationReason::MaxItersReached),
            "{what}"
        );
        assert!(forward >= 3 && adjoint >= 3, "{what}: {forward} {adjoint}");
        assert_ne!(state.get_param().unwrap(), &x0, "{what}");
        // The cost is the objective of the current x.
        let x = state.get_param().unwrap();
        let mut ax = vec![0.0; M];
        op.apply(x, &mut ax);
        let fit = 0.5 * ax.iter().zip(&y).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        if what == "fista" {
            assert!(state.get_cost() > fit, "{what}: the ℓ1 term is missing");
        } else {
            assert!(
                (state.get_cost() - fit).abs() <= 1e-12 * fit,
                "{what}: {} vs {fit}",
                state.get_cost()
            );
        }
    }
    // IHT without a fixed step: one adjoint (gradient) and two forwards (step, update) per
    // iteration while the support is kept, plus the initial forward.
    assert_eq!(iht_run.adjoint, 3);
    assert!(iht_run.forward >= 7, "{}", iht_run.forward);
}

#[test]
fn zero_measurements_end_in_init_like_the_native_solvers() {
    let (op, _) = problem(500);
    let y = vec![0.0; M];
    let x0 = random_vec(N, 501);
    let configure = |s: ArgminState<f64>| s.param(x0.clone()).max_iters(50);
    let runs = [
        execute(
            ArgminFista::new(FistaParams::default()).unwrap(),
            &op,
            &y,
            configure,
        )
        .map(|r| (r.state, r.forward + r.adjoint)),
        execute(
            ArgminIht::new(IhtParams::new(3)).unwrap(),
            &op,
            &y,
            configure,
        )
        .map(|r| (r.state, r.forward + r.adjoint)),
        execute(
            ArgminCosamp::new(CosampParams::new(3)).unwrap(),
            &op,
            &y,
            configure,
        )
        .map(|r| (r.state, r.forward + r.adjoint)),
    ];
    for run in runs {
        let (state, applies) = run.unwrap();
        assert_eq!(state.get_iter(), 0);
        assert_eq!(
            state.get_termination_reason(),
            Some(&TerminationReason::SolverConverged)
        );
        assert!(state.get_param().unwrap().iter().all(|&v| v == 0.0));
        assert_eq!(state.get_cost(), 0.0);
        assert_eq!(applies, 0);
    }
    let mut x = x0.clone();
    let report = iht(&op, &y, &mut x, &IhtParams::new(3), &mut ()).unwrap();
    assert_eq!(report.termination, Termination::ZeroResidual);
}

/// The crate's error inside argmin's.
fn typed(e: argmin::core::Error) -> Error {
    e.downcast_ref::<Error>()
        .unwrap_or_else(|| panic!("not a crate error: {e}"))
        .clone()
}

#[test]
fn invalid_problems_and_parameters_are_typed_errors() {
    let (op, y) = problem(600);
    let param = |name: &'static str| move |e: Error| matches!(e, Error::InvalidParameter { name: n, .. } if n == name);

    // Constructors validate what they can.
    let bad_fista = FistaParams {
        lambda: Lambda::Absolute(-1.0),
        ..FistaParams::default()
    };
    assert!(ArgminFista::<f64>::new(bad_fista).is_err_and(param("lambda")));
    assert!(ArgminIht::<f64>::new(IhtParams::new(0)).is_err_and(param("sparsity")));
    assert!(ArgminCosamp::<f64>::new(CosampParams {
        fixed_point_tol: f64::NAN,
        ..CosampParams::new(2)
    })
    .is_err_and(param("fixed_point_tol")));
    assert!(ArgminIht::<f64>::new(IhtParams {
        stopping: Stopping {
            max_iter: 0,
            ..Stopping::default()
        },
        ..IhtParams::new(2)
    })
    .is_err_and(param("max_iter")));

    // init reports what needs the problem.
    let run = |solver: ArgminIht<f64>, y: &[f64], x0: Option<Vec<f64>>| {
        let problem = LinearLeastSquares { op: &op, y };
        Executor::new(problem, solver)
            .configure(|s| match x0 {
                Some(x) => s.param(x).max_iters(5),
                None => s.max_iters(5),
            })
            .run()
            .map(|_| ())
            .map_err(typed)
    };
    let ok = ArgminIht::new(IhtParams::new(3)).unwrap();
    assert!(run(ok.clone(), &y, Some(vec![0.0; N])).is_ok());
    assert!(run(ok.clone(), &y, None).is_err_and(param("param")));
    assert!(matches!(
        run(ok.clone(), &y[1..], Some(vec![0.0; N])),
        Err(Error::ShapeMismatch { .. })
    ));
    assert!(matches!(
        run(ok.clone(), &y, Some(vec![f64::NAN; N])),
        Err(Error::NonFinite { .. })
    ));
    let too_sparse = ArgminIht::new(IhtParams::new(N + 1)).unwrap();
    assert!(run(too_sparse, &y, Some(vec![0.0; N])).is_err_and(param("sparsity")));
    // The parameters are not serialized: a deserialized solver that never ran cannot start.
    let json = serde_json::to_string(&ok).unwrap();
    let restored: ArgminIht<f64> = serde_json::from_str(&json).unwrap();
    assert!(run(restored, &y, Some(vec![0.0; N])).is_err_and(param("params")));

    // FISTA and CoSaMP go through the same checks.
    let problem = LinearLeastSquares {
        op: &op,
        y: &y[..M - 1],
    };
    let e = Executor::new(problem, ArgminCosamp::new(CosampParams::new(2)).unwrap())
        .configure(|s| s.param(vec![0.0; N]))
        .run()
        .map_err(typed);
    assert!(matches!(e, Err(Error::ShapeMismatch { .. })));
}

#[test]
fn progress_observer_follows_a_run_to_the_end() {
    let (op, y) = problem(700);
    let params = IhtParams::new(3);
    let mut x = vec![0.0; N];
    let mut progress = ProgressObserver::new(params.stopping.max_iter);
    if !std::io::stderr().is_terminal() {
        assert!(progress.is_hidden());
    }
    let report = iht(&op, &y, &mut x, &params, &mut progress).unwrap();
    assert!(report.iterations >= 1);
    assert_ne!(report.termination, Termination::Observer);
    assert_eq!(progress.iteration(), report.iterations);
    progress.finish();
    // Finished, the bar still counts (and a second finish or the drop are harmless).
    let mut x = vec![0.0; N];
    let again = iht(&op, &y, &mut x, &params, &mut progress).unwrap();
    assert_eq!(progress.iteration(), again.iterations);
    progress.finish();
    drop(progress);

    // Quiet: hidden whatever stderr is.
    let quiet = ProgressObserver::new(10).quiet(true);
    assert!(quiet.is_hidden());
    let loud = ProgressObserver::new(10).quiet(false);
    assert_eq!(loud.is_hidden(), !std::io::stderr().is_terminal());
}

#[test]
fn progress_observer_forwards_every_iteration_and_the_stop_of_a_chained_observer() {
    let (op, y) = problem(800);
    let params = FistaParams {
        stopping: Stopping::iterations(200),
        ..FistaParams::default()
    };
    let mut seen = Vec::new();
    let early_stop = |info: &IterationInfo<'_, f64>| {
        seen.push(info.iteration);
        if info.iteration == 7 {
            Control::Stop
        } else {
            Control::Continue
        }
    };
    let mut progress = ProgressObserver::new(params.stopping.max_iter)
        .quiet(true)
        .chain(early_stop);
    let mut x = vec![0.0; N];
    let report = fista(&op, &y, &mut x, &params, &mut progress).unwrap();
    assert_eq!(report.termination, Termination::Observer);
    assert_eq!(report.iterations, 7);
    assert_eq!(progress.iteration(), 7);
    drop(progress);
    assert_eq!(seen, (1..=7).collect::<Vec<_>>());

    // Without a stop request the chained observer sees the whole run.
    let mut count = 0;
    let mut progress =
        ProgressObserver::new(params.stopping.max_iter).chain(|_: &IterationInfo<'_, f64>| {
            count += 1;
            Control::Continue
        });
    let mut x = vec![0.0; N];
    let report = cosamp(&op, &y, &mut x, &CosampParams::new(3), &mut progress).unwrap();
    drop(progress);
    assert_eq!(count, report.iterations);
    assert_ne!(report.termination, Termination::Observer);
}
