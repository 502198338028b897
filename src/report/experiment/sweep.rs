//! The sweep of an experiment: one simulated problem per pulse length, seed and noise level,
//! reconstructed by every solver, one [`Row`] per run.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use ndarray::Array2;

use crate::error::Result;
use crate::lidar::{
    depth_bin_m, paper_returns, simulate, simulate_supplied, RdOperator, Response, Returns, Scene,
    SceneSpec, SimulationSpec, DEFAULT_TAU_S,
};
use crate::real::Real;
use crate::recon::{compare, compare_range, reconstruct, Method, ReconstructOptions};

use super::{
    estimated_work, snake_case, Case, Event, ExperimentConfig, ExperimentObserver, Row, Run,
    SceneKind,
};

/// The truth, the operator and the measurements of one [`Case`].
struct Problem<T: Real> {
    truth: Scene<T>,
    /// The true continuous returns of a scene at continuous depths.
    returns: Option<Returns>,
    op: RdOperator<T>,
    y: Vec<T>,
}

/// Simulates `case` through [`simulate`], exactly as `rdlidar simulate` does with the same seed.
fn simulate_case<T: Real>(config: &ExperimentConfig, case: &Case) -> Result<Problem<T>> {
    let spec = SimulationSpec {
        scene: match case.scene {
            SceneKind::Paper | SceneKind::PaperContinuous => SceneSpec::Paper,
            SceneKind::Random => SceneSpec::Random {
                lit_fraction: config.lit_fraction,
            },
            SceneKind::Transparent => SceneSpec::Transparent,
        },
        snr_db: case.snr_db,
        ..SimulationSpec::new(config.size, case.pulse_len, case.seed)
    };
    let (sim, returns) = match case.scene {
        SceneKind::PaperContinuous => {
            let returns = paper_returns(config.size)?;
            let scene = returns.render::<T>(config.size.ks, &Response::Triangle)?;
            let spec = SimulationSpec {
                scene: SceneSpec::Supplied,
                ..spec
            };
            (simulate_supplied::<T>(&spec, scene)?, Some(returns))
        }
        _ => (simulate::<T>(&spec)?, None),
    };
    Ok(Problem {
        op: sim.single_operator()?,
        truth: sim.scene,
        returns,
        y: sim.meas,
    })
}

/// The row of `method` on `case` in `precision` (`f32` or `f64`) before it runs: the problem,
/// the solver and what follows from them (the grid, K, the regime, the iteration budget), no
/// results, and no truth (`lit` and `true_returns` are 0).
pub(super) fn blank_row(
    config: &ExperimentConfig,
    case: &Case,
    method: Method,
    precision: &str,
) -> Row {
    let g = config.size;
    let budget = match method {
        Method::Backprojection | Method::BackprojectionDebiased => None,
        m => config.max_iter.get(m),
    };
    Row {
        scene: case.scene.name().into(),
        size: g.to_string(),
        precision: precision.into(),
        seed: case.seed,
        snr_db: case.snr_db,
        pulse_len: case.pulse_len,
        samples: g.samples(case.pulse_len),
        regime: g.regime(case.pulse_len).to_string(),
        critical_pulse_len: g.critical_pulse_len(),
        solver: method.name().into(),
        method_used: method.name().into(),
        max_iter: budget,
        lit: 0,
        exact: None,
        exact_pct: None,
        false_detections: None,
        missed: None,
        true_returns: 0,
        returns_exact: None,
        returns_false: None,
        depth_rmse_bins: None,
        relative_error: None,
        time_s: 0.0,
        iterations: None,
        termination: None,
        forward_applies: None,
        adjoint_applies: None,
        support_applies: None,
        error: None,
    }
}

/// Runs one method on one problem; a solver's error becomes the row's `error`.
fn run_one<T: Real>(
    config: &ExperimentConfig,
    case: &Case,
    problem: &Problem<T>,
    method: Method,
) -> (Row, Option<Array2<i32>>) {
    let mut row = Row {
        lit: problem.truth.depth_map().lit(),
        true_returns: problem.truth.nnz(),
        ..blank_row(config, case, method, T::NAME)
    };
    let budget = row.max_iter;
    let options = ReconstructOptions {
        max_iter: budget,
        progress: false,
        seed: case.seed,
        power_iterations: config.power_iterations,
        response: match problem.returns {
            Some(_) => Response::Triangle,
            None => Response::Delta,
        },
        ..ReconstructOptions::default()
    };
    let start = Instant::now();
    let result = reconstruct(&problem.op, &problem.y, method, &options).and_then(|r| {
        let m = compare(&problem.truth, &r.scene, DEFAULT_TAU_S)?;
        // At continuous depths, the depth error is the continuous estimate's.
        let range = match (&problem.returns, &r.returns) {
            (Some(truth), Some(estimate)) => {
                Some(compare_range(truth, estimate, None, depth_bin_m(DEFAULT_TAU_S)?)?.rmse_bins)
            }
            _ => None,
        };
        Ok((r, m, range))
    });
    row.time_s = start.elapsed().as_secs_f64();
    match result {
        Ok((r, m, range)) => {
            row.time_s = r.elapsed.as_secs_f64();
            row.method_used = r.method_used.name().into();
            row.exact = Some(m.exact);
            row.exact_pct = Some(100.0 * m.exact_fraction);
            row.false_detections = Some(m.false_detections);
            row.missed = Some(m.missed);
            row.true_returns = m.true_returns;
            row.returns_exact = Some(m.returns_exact);
            row.returns_false = Some(m.returns_false);
            row.depth_rmse_bins = Some(range.unwrap_or(m.depth_rmse_bins));
            row.relative_error = Some(m.relative_error);
            if let Some(rep) = &r.report {
                row.iterations = Some(rep.iterations);
                row.termination = Some(snake_case(&format!("{:?}", rep.termination)));
                row.forward_applies = Some(rep.forward_applies);
                row.adjoint_applies = Some(rep.adjoint_applies);
                row.support_applies = Some(rep.support_applies);
            }
            (row, Some(r.depth.depth))
        }
        Err(e) => {
            row.error = Some(e.to_string());
            (row, None)
        }
    }
}

/// The depth maps of one problem: the truth and each finished solver's estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct CaseDepths {
    /// The problem.
    pub case: Case,
    /// The true depth map (bins, −1 for no return).
    pub truth: Array2<i32>,
    /// Each method's estimate, in the order they ran (failed runs are left out).
    pub estimates: Vec<(Method, Array2<i32>)>,
}

/// What a sweep produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// One row per finished run, in the order they ran.
    pub rows: Vec<Row>,
    /// The depth maps per problem (only when asked for).
    pub depths: Vec<CaseDepths>,
    /// Whether the stop flag ended the sweep early.
    pub interrupted: bool,
    /// Runs planned.
    pub planned: usize,
    /// Wall time of the whole sweep, simulations included.
    pub elapsed: Duration,
}

/// Runs `cases` (the problems of `config`, or this process's share of them) in precision `T`,
/// calling `on_row` with each row as it finishes; stops between runs once `stop` is set.
///
/// # Errors
/// Errors of the simulation and of `on_row`. A solver's own failure is recorded in its row
/// instead.
pub(super) fn sweep<T: Real>(
    config: &ExperimentConfig,
    cases: &[Case],
    run: &Run,
    observer: &mut dyn ExperimentObserver,
    stop: &AtomicBool,
    on_row: &mut dyn FnMut(&Row) -> Result<()>,
) -> Result<Sweep> {
    let start = Instant::now();
    let runs = cases.len() * config.solvers.len();
    let work_of = |m: Method, kp: usize| {
        let budget = config.max_iter.get(m);
        estimated_work(m, budget, kp)
    };
    let work: f64 = cases
        .iter()
        .flat_map(|c| config.solvers.iter().map(move |&m| (m, c.pulse_len)))
        .map(|(m, kp)| work_of(m, kp))
        .sum();
    observer.event(&Event::Planned {
        problems: cases.len(),
        runs,
        work,
        columns: run.columns,
    });
    let mut sweep = Sweep {
        rows: Vec::with_capacity(runs),
        depths: Vec::new(),
        interrupted: false,
        planned: runs,
        elapsed: Duration::ZERO,
    };
    'cases: for case in cases {
        if stop.load(Ordering::SeqCst) {
            sweep.interrupted = true;
            break;
        }
        observer.event(&Event::Simulating {
            case,
            geometry: config.size,
        });
        let problem = simulate_case::<T>(config, case)?;
        let mut depths = CaseDepths {
            case: *case,
            truth: problem.truth.depth_map().depth,
            estimates: Vec::new(),
        };
        for &method in &config.solvers {
            if stop.load(Ordering::SeqCst) {
                sweep.interrupted = true;
                if run.keep_depths {
                    sweep.depths.push(depths);
                }
                break 'cases;
            }
            let index = sweep.rows.len();
            observer.event(&Event::RunStarted {
                index,
                runs,
                method,
                case,
            });
            let (row, depth) = run_one(config, case, &problem, method);
            on_row(&row)?;
            observer.event(&Event::RunFinished {
                index,
                runs,
                row: &row,
                work: work_of(method, case.pulse_len),
            });
            if let (true, Some(d)) = (run.keep_depths, depth) {
                depths.estimates.push((method, d));
            }
            sweep.rows.push(row);
        }
        if run.keep_depths {
            sweep.depths.push(depths);
        }
    }
    if sweep.interrupted {
        observer.event(&Event::Interrupted {
            finished: sweep.rows.len(),
            runs,
        });
    }
    sweep.elapsed = start.elapsed();
    Ok(sweep)
}
