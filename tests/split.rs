//! The seam for unknowns split across processes, proved in one process: the unknowns of a lidar
//! problem are split by image rows into R parts, one thread per part; each thread runs a solver,
//! or a whole reconstruction, on its part through an operator whose space combines the parts (a
//! condition-variable exchange), and the gathered result must be that of the plain run on the
//! whole: the same supports, iterations, endings and stages, and values equal up to round-off.
//! Every solver and every reconstruction method is checked, auto on each of its ways (TV on the
//! depth map, the information criterion in noise, several returns per pixel).
//!
//! Each part is the library's [`Part`]: the lidar operator of its rows alone (their pixels'
//! codes), whose forward application is summed over the parts (a collective) and whose adjoint
//! and column queries are its own, and whose space is the exchange.
//!
//! A part that calls a collective the others do not (a solver deciding on a local value) is
//! caught: the exchange checks that every part calls the same collective on the same length, and
//! fails every part at once, never hangs (a part that never comes fails the others after a
//! timeout).

use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread;
use std::time::{Duration, Instant};

use rdlidar::acquisition::{observe_nothing, Acquisition, CodeStore, Reconstructed, Streaming};
use rdlidar::lidar::{
    paper_scene, semi_transparent_scene, Codes, Geometry, NoiseModel, NoiseStage, Pulse,
    RdOperator, Scene, SeededCodes,
};
use rdlidar::operator::{LinearOperator, Part, VoxelOperator};
use rdlidar::recon::{reconstruct, Method, ReconstructOptions, Reconstruction};
use rdlidar::solver::{
    cgls, cosamp, fista, iht, model_based, reflector_amp, CglsParams, CosampParams, FistaParams,
    IhtParams, Lambda, ModelBasedParams, ReflectorAmpParams, Report, Stopping,
};
use rdlidar::space::{self, Space};

/// How long a part waits for the others at a collective before the test fails.
const PATIENCE: Duration = Duration::from_secs(20);

/// What the parts of one collective deposit: the collective's kind, and the part's values.
type Deposit = (&'static str, Vec<f64>);

#[derive(Debug, Default)]
struct Exchange {
    /// Completed collectives.
    round: u64,
    /// Deposits of the collective under way, by part.
    slots: Vec<Option<Deposit>>,
    /// The deposits of the last completed collective, in part order.
    done: Arc<Vec<Deposit>>,
    /// Why the parts went out of step, once they have.
    broken: Option<String>,
}

/// The communicator shared by the parts' threads.
#[derive(Debug)]
struct Shared {
    parts: usize,
    exchange: Mutex<Exchange>,
    arrived: Condvar,
    /// The values each part has sent, over every collective.
    sent: Vec<AtomicUsize>,
}

impl Shared {
    fn new(parts: usize) -> Arc<Self> {
        Arc::new(Self {
            parts,
            exchange: Mutex::new(Exchange {
                slots: vec![None; parts],
                ..Exchange::default()
            }),
            arrived: Condvar::new(),
            sent: (0..parts).map(|_| AtomicUsize::new(0)).collect(),
        })
    }

    fn lock(&self) -> MutexGuard<'_, Exchange> {
        // A part that panicked poisons the lock; the others go on to fail at their next wait.
        self.exchange.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Every part's deposit of one collective, in part order, once all have come.
    fn all(&self, part: usize, kind: &'static str, values: Vec<f64>) -> Arc<Vec<Deposit>> {
        self.sent[part].fetch_add(values.len(), Ordering::Relaxed);
        let mut ex = self.lock();
        let round = ex.round;
        assert!(ex.slots[part].is_none(), "part {part} deposited twice");
        ex.slots[part] = Some((kind, values));
        if ex.slots.iter().all(Option::is_some) {
            let done: Vec<Deposit> = ex.slots.iter_mut().map(|s| s.take().unwrap()).collect();
            let first = (done[0].0, done[0].1.len());
            let odd = done
                .iter()
                .position(|d| d.0 != first.0 || d.0 != "gather" && d.1.len() != first.1);
            if let Some(p) = odd {
                let why = format!(
                    "collective {round}: part {p} called {} on {} values, part 0 {} on {}",
                    done[p].0,
                    done[p].1.len(),
                    first.0,
                    first.1
                );
                ex.broken = Some(why.clone());
                self.arrived.notify_all();
                drop(ex);
                panic!("{why}");
            }
            ex.done = Arc::new(done);
            ex.round += 1;
            self.arrived.notify_all();
            return Arc::clone(&ex.done);
        }
        let start = Instant::now();
        while ex.round == round {
            if let Some(why) = &ex.broken {
                let why = why.clone();
                drop(ex);
                panic!("{why}");
            }
            let left = PATIENCE.saturating_sub(start.elapsed());
            assert!(
                !left.is_zero(),
                "collective {round}: part {part} called {kind} and the others did not come"
            );
            ex = self
                .arrived
                .wait_timeout(ex, left)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        Arc::clone(&ex.done)
    }
}

/// One part's view of the split unknowns.
#[derive(Debug)]
struct PartSpace {
    shared: Arc<Shared>,
    part: usize,
}

impl Space for PartSpace {
    fn parts(&self) -> usize {
        self.shared.parts
    }
    fn part(&self) -> usize {
        self.part
    }
    fn sum(&self, values: &mut [f64]) {
        let all = self.shared.all(self.part, "sum", values.to_vec());
        for (i, v) in values.iter_mut().enumerate() {
            *v = all.iter().map(|d| d.1[i]).sum();
        }
    }
    fn max(&self, values: &mut [f64]) {
        let all = self.shared.all(self.part, "max", values.to_vec());
        for (i, v) in values.iter_mut().enumerate() {
            *v = all.iter().map(|d| d.1[i]).fold(f64::NEG_INFINITY, f64::max);
        }
    }
    fn gather(&self, local: &[f64]) -> Vec<f64> {
        let all = self.shared.all(self.part, "gather", local.to_vec());
        all.iter().flat_map(|d| d.1.iter().copied()).collect()
    }
    fn offset(&self, local_len: usize) -> usize {
        let all = self.shared.all(self.part, "offset", vec![local_len as f64]);
        all[..self.part].iter().map(|d| d.1[0] as usize).sum()
    }
}

/// The lidar operator of the rows `rows` of `op`'s scene alone (their pixels' codes), as the
/// part of the whole that combines with the others through `space`.
fn part_of(
    op: &RdOperator<f64>,
    rows: Range<usize>,
    space: Arc<dyn Space>,
) -> Part<RdOperator<f64>> {
    Part::new(op.row_band(rows).unwrap(), space)
}

/// A solver run on one operator: the report, or the error's text.
type Run<'o> = dyn Fn(&dyn VoxelOperator<f64>, &[f64], &mut [f64]) -> std::result::Result<Report, String>
    + Sync
    + 'o;

/// The unknowns and the report of a run on the whole.
type Solved = (Vec<f64>, Report);
/// The gathered unknowns and every part's report of a split run.
type SolvedInParts = (Vec<f64>, Vec<Report>);

/// `run` on each of `parts` parts of `op` (split by image rows), each in its own thread, in
/// part order.
fn in_parts<R: Send>(
    op: &RdOperator<f64>,
    parts: usize,
    run: &(dyn Fn(&Part<RdOperator<f64>>) -> R + Sync),
) -> Vec<R> {
    in_parts_of(&Shared::new(parts), op, run)
}

/// [`in_parts`] through the exchange `shared` (of as many parts as it has).
fn in_parts_of<R: Send>(
    shared: &Arc<Shared>,
    op: &RdOperator<f64>,
    run: &(dyn Fn(&Part<RdOperator<f64>>) -> R + Sync),
) -> Vec<R> {
    let (m, parts) = (op.geometry().m, shared.parts);
    thread::scope(|s| {
        let handles: Vec<_> = (0..parts)
            .map(|p| {
                let shared = Arc::clone(shared);
                s.spawn(move || {
                    let space: Arc<dyn Space> = Arc::new(PartSpace { shared, part: p });
                    run(&part_of(op, p * m / parts..(p + 1) * m / parts, space))
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    })
}

/// The plain run on the whole operator, and the run split into `parts` parts (the gathered
/// unknowns and every part's report).
fn whole_and_split(
    op: &RdOperator<f64>,
    y: &[f64],
    parts: usize,
    run: &Run<'_>,
) -> (Solved, SolvedInParts) {
    let mut x = vec![0.0; op.ncols()];
    let report = run(op, y, &mut x).expect("the whole run");
    let runs = in_parts(op, parts, &|part| {
        let mut x = vec![0.0; part.ncols()];
        let report = run(part, y, &mut x).expect("a part's run");
        (x, report)
    });
    let (xs, reports): (Vec<Vec<f64>>, Vec<Report>) = runs.into_iter().unzip();
    ((x, report), (xs.concat(), reports))
}

fn last(history: &[f64]) -> f64 {
    history.last().copied().unwrap_or(0.0)
}

fn support(x: &[f64]) -> Vec<usize> {
    (0..x.len()).filter(|&i| x[i] != 0.0).collect()
}

/// The split run's result is the whole run's: supports, iterations and endings identical, values
/// within `tol` of the largest.
fn assert_same(name: &str, parts: usize, whole: &Solved, split: &SolvedInParts, tol: f64) {
    let (x, report) = whole;
    let (xs, reports) = split;
    assert!(
        !support(x).is_empty(),
        "{name}: the whole run found nothing"
    );
    assert_eq!(
        support(x),
        support(xs),
        "{name} in {parts} parts: supports differ"
    );
    let scale = space::norm_inf(&space::WHOLE, x);
    let worst = x
        .iter()
        .zip(xs)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        worst <= tol * scale,
        "{name} in {parts} parts: values differ by {worst:e} (largest {scale:e})"
    );
    for (p, r) in reports.iter().enumerate() {
        assert_eq!(
            r.iterations, report.iterations,
            "{name}: part {p}'s iterations"
        );
        assert_eq!(
            r.termination, report.termination,
            "{name}: part {p}'s ending"
        );
        // Relative residuals: round-off is absolute where the fit is exact.
        let (a, b) = (last(&r.residual_history), last(&report.residual_history));
        assert!(
            (a - b).abs() <= 1e-10 + 1e-8 * b,
            "{name}: part {p}'s last residual {a:e} against {b:e}"
        );
    }
}

const GEOMETRY: (usize, usize, usize) = (12, 12, 16);

/// The number of returns of the paper scene of [`GEOMETRY`]: the sparsity given to the greedy
/// solvers (with more, the surplus entries they keep are round-off, anywhere).
fn returns() -> usize {
    let (m, n, ks) = GEOMETRY;
    let truth = paper_scene::<f64>(Geometry::new(m, n, ks).unwrap()).unwrap();
    support(truth.as_slice()).len()
}

/// The paper scene of [`GEOMETRY`] measured at K_p = `kp`.
fn problem(kp: usize, seed: u64) -> (RdOperator<f64>, Vec<f64>) {
    let (m, n, ks) = GEOMETRY;
    let truth = paper_scene::<f64>(Geometry::new(m, n, ks).unwrap()).unwrap();
    measured(&truth, kp, seed, None)
}

/// `truth` measured at K_p = `kp`, with Gaussian noise at `snr_db` if given.
fn measured(
    truth: &Scene<f64>,
    kp: usize,
    seed: u64,
    snr_db: Option<f64>,
) -> (RdOperator<f64>, Vec<f64>) {
    let g = truth.geometry();
    let pulse = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
    let codes = Codes::random_binary(g.pixels(), g.samples(kp), seed + 1).unwrap();
    let op = RdOperator::new(g, pulse, Arc::new(codes)).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    if let Some(snr_db) = snr_db {
        NoiseModel::none()
            .then(NoiseStage::Gaussian { snr_db })
            .apply(&mut y, seed + 2)
            .unwrap();
    }
    (op, y)
}

fn check_solver(name: &str, kp: usize, tol: f64, run: &Run<'_>) {
    let (op, y) = problem(kp, 11);
    for parts in [2, 3] {
        let (whole, split) = whole_and_split(&op, &y, parts, run);
        assert_same(name, parts, &whole, &split, tol);
    }
}

fn stopping(max_iter: usize) -> Stopping {
    Stopping {
        max_iter,
        ..Stopping::default()
    }
}

#[test]
fn cgls_on_split_unknowns_is_cgls_on_the_whole() {
    check_solver("CGLS", 3000, 1e-8, &|op, y, x| {
        let params = CglsParams {
            stopping: stopping(30),
            ..CglsParams::default()
        };
        cgls(op, y, x, &params, &mut ()).map_err(|e| e.to_string())
    });
}

#[test]
fn fista_on_split_unknowns_is_fista_on_the_whole() {
    check_solver("FISTA", 600, 1e-8, &|op, y, x| {
        let params = FistaParams {
            lambda: Lambda::Fraction(0.05),
            nonnegative: true,
            stopping: stopping(60),
            ..FistaParams::default()
        };
        fista(op, y, x, &params, &mut ()).map_err(|e| e.to_string())
    });
}

#[test]
fn iht_and_cosamp_on_split_unknowns_are_themselves_on_the_whole() {
    check_solver("IHT", 1000, 1e-8, &|op, y, x| {
        let params = IhtParams {
            stopping: stopping(40),
            ..IhtParams::new(returns())
        };
        iht(op, y, x, &params, &mut ()).map_err(|e| e.to_string())
    });
    check_solver("CoSaMP", 1500, 1e-8, &|op, y, x| {
        // The inner least squares by a count of iterations: stopped by a tolerance, a split
        // run's inner solve can end one iteration apart from the whole's where round-off puts
        // the residual at the threshold, which compares two different fits.
        let d = CosampParams::new(returns());
        let params = CosampParams {
            stopping: stopping(10),
            inner: CglsParams {
                stopping: Stopping::iterations(20),
                ..d.inner
            },
            ..d
        };
        cosamp(op, y, x, &params, &mut ()).map_err(|e| e.to_string())
    });
}

#[test]
fn the_pixelwise_solvers_on_split_unknowns_are_themselves_on_the_whole() {
    check_solver("message passing", 400, 1e-8, &|op, y, x| {
        reflector_amp(op, y, x, &ReflectorAmpParams::default(), &mut ()).map_err(|e| e.to_string())
    });
    check_solver("model-based", 400, 1e-8, &|op, y, x| {
        model_based(op, y, x, &ModelBasedParams::default(), &mut ()).map_err(|e| e.to_string())
    });
}

#[test]
fn a_part_that_skips_a_collective_fails_instead_of_hanging() {
    let shared = Shared::new(2);
    let result = thread::scope(|s| {
        let start = Instant::now();
        let summing = {
            let shared = Arc::clone(&shared);
            s.spawn(move || {
                let space = PartSpace { shared, part: 0 };
                space::sum(&space, 1.0)
            })
        };
        let other = {
            let shared = Arc::clone(&shared);
            s.spawn(move || {
                let space = PartSpace { shared, part: 1 };
                space::max(&space, 1.0)
            })
        };
        let r = (summing.join(), other.join());
        assert!(
            start.elapsed() < PATIENCE,
            "the parts waited out their patience"
        );
        r
    });
    // The two calls meet, the mismatch is seen, and both parts fail at once.
    assert!(result.0.is_err() && result.1.is_err());
}

/// The split reconstruction's is the whole one's: the same scene up to round-off (the same
/// returns), the same method kept, the same stages.
fn assert_same_reconstruction(
    what: &str,
    whole: &Reconstruction<f64>,
    parts: &[Reconstruction<f64>],
) {
    let x = whole.scene.as_slice();
    let xs: Vec<f64> = parts
        .iter()
        .flat_map(|r| r.scene.as_slice().iter().copied())
        .collect();
    assert_eq!(support(x), support(&xs), "{what}: the returns differ");
    let scale = space::norm_inf(&space::WHOLE, x).max(f64::MIN_POSITIVE);
    let worst = x
        .iter()
        .zip(&xs)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst <= 1e-8 * scale, "{what}: values differ by {worst:e}");
    for (p, r) in parts.iter().enumerate() {
        assert_eq!(
            r.method_used, whole.method_used,
            "{what}: part {p}'s method"
        );
        assert_eq!(r.regime, whole.regime, "{what}: part {p}'s regime");
        let stages = |r: &Reconstruction<f64>| -> Vec<_> {
            r.stages
                .iter()
                .map(|s| {
                    (
                        s.method,
                        s.returns,
                        s.kept,
                        s.report.as_ref().map(|r| r.iterations),
                    )
                })
                .collect()
        };
        assert_eq!(stages(r), stages(whole), "{what}: part {p}'s stages");
        let iterations = |r: &Reconstruction<f64>| r.report.as_ref().map(|r| r.iterations);
        assert_eq!(
            iterations(r),
            iterations(whole),
            "{what}: part {p}'s iterations"
        );
    }
}

/// Every method, on the whole operator and split into 2 and 3 parts by image rows; returns the
/// whole's reconstructions.
fn check_methods(
    what: &str,
    op: &RdOperator<f64>,
    y: &[f64],
    methods: &[Method],
) -> Vec<Reconstruction<f64>> {
    let options = ReconstructOptions::default();
    let mut out = Vec::new();
    for &method in methods {
        let whole = reconstruct(op, y, method, &options).unwrap();
        // Coarse-to-fine (alone or as auto's stage) needs the whole scene's codes: the parts
        // gather them and solve the same coarse problem, then keep their own pixels. Where it
        // runs, the split runs are compared stage by stage with one part holding every row (on
        // one multi-return scene, auto's TV stage, not kept, stops at other iterations on the
        // whole operator than on one part), and the kept scene with the whole's too.
        let coarse = whole
            .stages
            .iter()
            .any(|s| s.method == Method::CoarseToFine);
        let reference = if coarse {
            let one = in_parts(op, 1, &|part| {
                reconstruct(part, y, method, &options).expect("one part's reconstruction")
            })
            .remove(0);
            let (a, b) = (whole.scene.as_slice(), one.scene.as_slice());
            assert!(
                support(a) == support(b),
                "{what}, {method}: one part's returns"
            );
            let worst = a
                .iter()
                .zip(b)
                .map(|(u, v)| (u - v).abs())
                .fold(0.0, f64::max);
            let scale = space::norm_inf(&space::WHOLE, a).max(f64::MIN_POSITIVE);
            assert!(worst <= 1e-8 * scale, "{what}, {method}: one part's scene");
            assert_eq!(one.method_used, whole.method_used, "{what}, {method}");
            one
        } else {
            whole.clone()
        };
        for parts in [2, 3] {
            let split = in_parts(op, parts, &|part| {
                reconstruct(part, y, method, &options).expect("a part's reconstruction")
            });
            let what = format!("{what}, {method} in {parts} parts");
            assert_same_reconstruction(&what, &reference, &split);
        }
        out.push(whole);
    }
    out
}

/// The methods of auto's stages, in order.
fn stages(r: &Reconstruction<f64>) -> Vec<Method> {
    r.stages.iter().map(|s| s.method).collect()
}

#[test]
fn every_method_on_split_unknowns_reconstructs_the_compressive_scene_as_on_the_whole() {
    // 73 returns from 215 measurements: the support pursuit does not explain the data, TV on
    // the depth map (the neighbourhood prior first) does.
    let (op, y) = problem(200, 5);
    let all = check_methods("compressive", &op, &y, &Method::ALL);
    let auto = all.last().unwrap();
    assert_eq!(stages(auto), [Method::SupportLs, Method::Tv]);
    assert_eq!(auto.method_used, Method::Tv);
}

#[test]
fn auto_on_split_unknowns_is_auto_on_the_whole_in_noise_and_with_several_returns() {
    let (m, n, ks) = GEOMETRY;
    let g = Geometry::new(m, n, ks).unwrap();
    // Redundant and noisy: the two cheap fits agree, the information criterion picks one.
    let truth = paper_scene::<f64>(g).unwrap();
    let (op, y) = measured(&truth, 2400, 7, Some(20.0));
    let r = check_methods("redundant at 20 dB", &op, &y, &[Method::Auto]);
    assert_eq!(stages(&r[0]), [Method::SupportLs, Method::ModelBased]);
    // Two or three returns per pixel, compressive: TV and the model-based fit, whose residual
    // is searched for hidden returns; the fit leaves more than a quarter of the data
    // unexplained, so coarse-to-fine is tried (the parts too, on the codes they gather), and
    // not kept.
    let truth = semi_transparent_scene::<f64>(g, 2..=3, 9).unwrap();
    let (op, y) = measured(&truth, 1200, 9, None);
    let r = check_methods("semi-transparent", &op, &y, &[Method::Auto]);
    assert_eq!(
        stages(&r[0]),
        [
            Method::SupportLs,
            Method::Tv,
            Method::ModelBased,
            Method::CoarseToFine
        ]
    );
    assert_eq!(r[0].method_used, Method::ModelBased);
    // The same with more measurements at 30 dB: the pursuit finds several returns per pixel,
    // and the model-based fit with as many returns follows.
    let (op, y) = measured(&truth, 2000, 9, Some(30.0));
    let r = check_methods("semi-transparent at 30 dB", &op, &y, &[Method::Auto]);
    assert_eq!(stages(&r[0]), [Method::SupportLs, Method::ModelBased]);
    assert!(r[0].stages[0].verdict.contains("several returns"));
}

#[test]
fn each_part_sees_the_rows_within_the_radius_even_across_thin_parts() {
    // 7 rows of 3 values, split 1 + 2 + 1 + 3; row r holds r·10 + column.
    let image: Vec<f64> = (0..7)
        .flat_map(|r| (0..3).map(move |c| (r * 10 + c) as f64))
        .collect();
    let bounds = [0, 1, 3, 4, 7];
    let shared = Shared::new(4);
    for radius in [1, 2, 3] {
        let seen: Vec<(Vec<f64>, Vec<f64>)> = thread::scope(|s| {
            let handles: Vec<_> = (0..4)
                .map(|p| {
                    let shared = Arc::clone(&shared);
                    let rows = &image[bounds[p] * 3..bounds[p + 1] * 3];
                    s.spawn(move || {
                        let space = PartSpace { shared, part: p };
                        space::neighbour_rows(&space, rows, 3, radius)
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        for (p, (above, below)) in seen.iter().enumerate() {
            let (lo, hi) = (bounds[p], bounds[p + 1]);
            let above_rows = lo.saturating_sub(radius)..lo;
            let below_rows = hi..(hi + radius).min(7);
            assert_eq!(
                above,
                &image[above_rows.start * 3..above_rows.end * 3],
                "part {p}"
            );
            assert_eq!(
                below,
                &image[below_rows.start * 3..below_rows.end * 3],
                "part {p}"
            );
        }
    }
}

#[test]
fn the_parts_adjoints_are_the_adjoint_of_their_summed_forward() {
    // ⟨A x, y⟩ = Σ_r ⟨x_r, A_rᵀ y⟩, with A x = Σ_r A_r x_r computed by the parts together.
    let (op, _) = problem(300, 21);
    let n = op.ncols();
    let x: Vec<f64> = (0..n)
        .map(|i| ((i * 7919) % 101) as f64 / 50.0 - 1.0)
        .collect();
    let y: Vec<f64> = (0..op.nrows())
        .map(|k| ((k * 104_729) % 97) as f64 / 48.0 - 1.0)
        .collect();
    for parts in [2, 3] {
        let sides = in_parts(&op, parts, &|part| {
            let first = part.space().offset(part.ncols());
            let xr = &x[first..first + part.ncols()];
            let mut ax = vec![0.0; part.nrows()];
            part.apply(xr, &mut ax);
            let mut aty = vec![0.0; part.ncols()];
            part.apply_adjoint(&y, &mut aty);
            let lhs: f64 = ax.iter().zip(&y).map(|(a, b)| a * b).sum();
            let rhs = space::dot(part.space(), xr, &aty);
            (lhs, rhs)
        });
        let mut whole = vec![0.0; op.nrows()];
        op.apply(&x, &mut whole);
        let direct: f64 = whole.iter().zip(&y).map(|(a, b)| a * b).sum();
        for (p, (lhs, rhs)) in sides.into_iter().enumerate() {
            assert!(
                (lhs - rhs).abs() <= 1e-12 * lhs.abs(),
                "part {p}: {lhs} against {rhs}"
            );
            assert!(
                (lhs - direct).abs() <= 1e-12 * direct.abs(),
                "part {p}: {lhs} against the whole's {direct}"
            );
        }
    }
}

#[test]
fn order_statistics_over_split_values_are_those_of_the_whole() {
    // Ties, signed zeros, negatives, an even and an odd count, parts of unequal (and no) length.
    let mut values: Vec<f64> = (0..41)
        .map(|i| (((i * 37) % 23) as f64 - 11.0) * 0.25)
        .collect();
    values.extend([0.0, -0.0, 1e300, -1e-300, 2.5, 2.5]);
    for len in [values.len(), values.len() - 1] {
        let whole = &values[..len];
        let bounds = [0, 5, 5, 30, len];
        let shared = Shared::new(4);
        let seen: Vec<(f64, f64, Vec<f64>)> = thread::scope(|s| {
            let handles: Vec<_> = (0..4)
                .map(|p| {
                    let shared = Arc::clone(&shared);
                    let mine = whole[bounds[p]..bounds[p + 1]].to_vec();
                    s.spawn(move || {
                        let space = PartSpace { shared, part: p };
                        let mut v = mine.clone();
                        let med = space::median(&space, &mut v);
                        let mut v = mine.clone();
                        let sigma = space::robust_sigma(&space, &mut v, med);
                        let ks: Vec<f64> = [0, 7, len / 2, len - 1]
                            .iter()
                            .map(|&k| space::kth_smallest(&space, &mut mine.clone(), k))
                            .collect();
                        (med, sigma, ks)
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        let mut sorted = whole.to_vec();
        sorted.sort_by(f64::total_cmp);
        let med = rdlidar::linalg::median(&mut whole.to_vec());
        let sigma = rdlidar::linalg::robust_sigma(&mut whole.to_vec(), med);
        for (p, (m, s, ks)) in seen.iter().enumerate() {
            assert_eq!(m.to_bits(), med.to_bits(), "part {p}, {len} values: median");
            assert_eq!(
                s.to_bits(),
                sigma.to_bits(),
                "part {p}, {len} values: spread"
            );
            let expected: Vec<f64> = [0, 7, len / 2, len - 1]
                .iter()
                .map(|&k| sorted[k])
                .collect();
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(ks),
                bits(&expected),
                "part {p}, {len} values: order statistics"
            );
        }
    }
}

#[test]
fn the_solvers_send_the_measurements_and_a_few_scalars_per_iteration() {
    // What a part sends, in values: K per forward application (the sum of the measurements),
    // and per iteration scalars (inner products, norms, counts, order statistics) and candidate
    // lists (top-k) far below its unknowns: a solver that gathered the unknowns each iteration
    // would send at least half as many again (n/2 per part here, the bound n/4).
    let (op, y) = problem(600, 13);
    let (k, n) = (op.nrows(), op.ncols());
    let s = returns();
    type Solve = fn(&dyn VoxelOperator<f64>, &[f64], &mut [f64], usize) -> rdlidar::Result<Report>;
    let solvers: [(&str, Solve); 6] = [
        ("cgls", |op, y, x, _| {
            cgls(
                op,
                y,
                x,
                &CglsParams {
                    stopping: stopping(20),
                    ..CglsParams::default()
                },
                &mut (),
            )
        }),
        ("fista", |op, y, x, _| {
            fista(
                op,
                y,
                x,
                &FistaParams {
                    stopping: stopping(20),
                    ..FistaParams::default()
                },
                &mut (),
            )
        }),
        ("iht", |op, y, x, s| {
            iht(
                op,
                y,
                x,
                &IhtParams {
                    stopping: stopping(20),
                    ..IhtParams::new(s)
                },
                &mut (),
            )
        }),
        ("cosamp", |op, y, x, s| {
            cosamp(
                op,
                y,
                x,
                &CosampParams {
                    stopping: stopping(5),
                    ..CosampParams::new(s)
                },
                &mut (),
            )
        }),
        ("amp", |op, y, x, _| {
            reflector_amp(op, y, x, &ReflectorAmpParams::default(), &mut ())
        }),
        ("model-based", |op, y, x, _| {
            model_based(op, y, x, &ModelBasedParams::default(), &mut ())
        }),
    ];
    for (name, solve) in solvers {
        let shared = Shared::new(2);
        let reports = in_parts_of(&shared, &op, &|part| {
            let mut x = vec![0.0; part.ncols()];
            solve(part, &y, &mut x, s).unwrap()
        });
        for (p, r) in reports.iter().enumerate() {
            let sent = shared.sent[p].load(Ordering::Relaxed);
            // Every forward application, of the whole or of a support, sums K values.
            let sums = k * (r.forward_applies + r.support_applies);
            let beyond = sent.saturating_sub(sums);
            assert!(
                beyond <= n / 4 * (r.iterations + 1),
                "{name}: part {p} sent {beyond} values beyond the measurements' sums in {} \
                 iterations, of {} unknowns per part",
                r.iterations,
                n / 2
            );
            assert!(
                sent >= k * r.forward_applies,
                "{name}: part {p} sent too little"
            );
        }
    }
}

#[test]
fn one_parts_observer_ends_every_parts_run_at_the_same_iteration() {
    let (op, y) = problem(3000, 11);
    let params = CglsParams {
        stopping: stopping(30),
        ..CglsParams::default()
    };
    let reports = in_parts(&op, 3, &|part| {
        let first = part.space().offset(part.ncols());
        let mut x = vec![0.0; part.ncols()];
        // Only the part holding the first unknowns stops, after its third iteration.
        let mut observer = |info: &rdlidar::solver::IterationInfo<'_, f64>| {
            if first == 0 && info.iteration == 3 {
                rdlidar::solver::Control::Stop
            } else {
                rdlidar::solver::Control::Continue
            }
        };
        cgls(part, &y, &mut x, &params, &mut observer).unwrap()
    });
    for (p, r) in reports.iter().enumerate() {
        assert_eq!(r.iterations, 3, "part {p}");
        assert_eq!(
            r.termination,
            rdlidar::solver::Termination::Observer,
            "part {p}"
        );
    }
}

/// `run` in each of `parts` parts, each in its own thread with its space, in part order.
pub(crate) fn in_spaces<R: Send>(
    parts: usize,
    run: &(dyn Fn(Arc<dyn Space>) -> R + Sync),
) -> Vec<R> {
    let shared = Shared::new(parts);
    thread::scope(|s| {
        let handles: Vec<_> = (0..parts)
            .map(|p| {
                let shared = Arc::clone(&shared);
                s.spawn(move || run(Arc::new(PartSpace { shared, part: p })))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    })
}

#[test]
fn the_parts_agree_on_the_first_failure() {
    let failing = |fails: &'static [usize]| {
        in_spaces(3, &move |space| {
            let mine = fails
                .contains(&space.part())
                .then(|| format!("part {} failed", space.part()));
            space::first_failure(&*space, mine.as_deref())
        })
    };
    assert_eq!(failing(&[]), vec![None, None, None]);
    let second = Some((1, "part 1 failed".to_string()));
    assert_eq!(
        failing(&[2, 1]),
        vec![second.clone(), second.clone(), second]
    );
    let first = Some((0, "part 0 failed".to_string()));
    assert_eq!(failing(&[0, 2]), vec![first.clone(), first.clone(), first]);
}

/// The acquisitions of a 13×10×16 paper scene: one ADC of int8 codes, two ADCs, and seeded
/// codes streamed block by block, with their measurements.
fn acquisitions() -> Vec<(&'static str, Acquisition, Vec<f64>, Scene<f64>)> {
    let g = Geometry::new(13, 10, 16).unwrap();
    let truth = paper_scene(g).unwrap();
    let kp = 300;
    let pulse = Pulse::<f64>::bernoulli(kp, 3).unwrap().into_inner();
    let k = g.samples(kp);
    let held = |seeds: &[u64]| {
        CodeStore::Held(
            seeds
                .iter()
                .map(|&s| Arc::new(Codes::random_binary(g.pixels(), k, s).unwrap()))
                .collect(),
        )
    };
    let seeded = CodeStore::Seeded(SeededCodes::new(8, 1, g.pixels(), k).unwrap());
    [
        ("one ADC", held(&[4]), Streaming::Never),
        ("two ADCs", held(&[5, 6]), Streaming::Never),
        ("seeded, streamed", seeded, Streaming::Always),
    ]
    .into_iter()
    .map(|(name, codes, streaming)| {
        let acq = Acquisition::new(g, pulse.clone(), codes, None, streaming).unwrap();
        let op = acq.operator::<f64>().unwrap();
        let mut y = vec![0.0; op.nrows()];
        op.apply(truth.as_slice(), &mut y);
        (name, acq, y, truth.clone())
    })
    .collect()
}

#[test]
fn an_acquisition_split_over_parts_measures_and_reconstructs_as_the_whole() {
    let options = ReconstructOptions::default();
    for (name, acq, y, truth) in acquisitions() {
        for method in [Method::Auto, Method::Cgls] {
            let whole = match acq
                .reconstruct(&y, method, &options, &observe_nothing, &|_| {})
                .unwrap()
            {
                Reconstructed::Single(r) => r,
                Reconstructed::Tiled(_) => unreachable!("not tiled"),
            };
            let parts = in_spaces(3, &|space| {
                let part = acq.split_over(space).unwrap();
                let share = part.share().expect("split").clone();
                // Its forward application of its rows of the scene sums to the whole's.
                let op = part.operator::<f64>().unwrap();
                let mut y_part = vec![0.0; op.nrows()];
                op.apply(share.rows_of(truth.as_slice(), 16), &mut y_part);
                let r = match part
                    .reconstruct(&y, method, &options, &observe_nothing, &|_| {})
                    .unwrap()
                {
                    Reconstructed::Single(r) => r,
                    Reconstructed::Tiled(_) => unreachable!("not tiled"),
                };
                (
                    y_part,
                    share.rows(),
                    share.gather_reconstruction(r).unwrap(),
                )
            });
            let mut rows = Vec::new();
            for (y_part, band, r) in parts {
                let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let worst = y
                    .iter()
                    .zip(&y_part)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                assert!(
                    worst <= 1e-13 * scale,
                    "{name}: forward differs by {worst:e}"
                );
                assert_eq!(r.method_used, whole.method_used, "{name} {method}");
                assert_eq!(
                    r.depth.depth, whole.depth.depth,
                    "{name} {method}: depth maps"
                );
                let (a, b) = (whole.scene.as_slice(), r.scene.as_slice());
                let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let worst = a
                    .iter()
                    .zip(b)
                    .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
                assert!(
                    worst <= 1e-8 * scale,
                    "{name} {method}: scenes differ by {worst:e}"
                );
                rows.push(band);
            }
            // Bands of 5, 4 and 4 rows, in order.
            assert_eq!(rows, vec![0..5, 5..9, 9..13], "{name}");
        }
    }
}

#[test]
fn codes_files_split_over_parts_give_each_part_its_rows_only() {
    use rdlidar::acquisition::{AcquisitionFiles, InputNames};
    use rdlidar::io::{write_codes, write_packed_code_sets};
    let dir = std::env::temp_dir().join(format!("rdlidar-split-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let g = Geometry::new(13, 10, 16).unwrap();
    for (name, acq, _, _) in acquisitions().into_iter().take(2) {
        let CodeStore::Held(sets) = acq.codes() else {
            unreachable!("held codes")
        };
        let path = dir.join("codes.npy");
        if sets.len() == 1 {
            write_codes(&path, (g.m, g.n), &sets[0]).unwrap();
        } else {
            write_packed_code_sets(&path, (g.m, g.n), sets).unwrap();
        }
        let pulse = acq.pulse().to_vec();
        let dense = |a: &Acquisition| match a.codes() {
            CodeStore::Held(sets) => sets.iter().map(|c| c.to_dense()).collect::<Vec<_>>(),
            CodeStore::Seeded(_) => unreachable!("held codes"),
        };
        let loaded = in_spaces(3, &|space| {
            let files = AcquisitionFiles::describe(
                &path,
                pulse.len(),
                g.ks,
                None,
                None,
                Streaming::Auto,
                InputNames::COMMAND_LINE,
            )
            .unwrap()
            .split_over(Arc::clone(&space))
            .unwrap();
            let from_file = files.load(pulse.clone()).unwrap();
            let in_memory = acq.split_over(space).unwrap();
            (dense(&from_file), dense(&in_memory), from_file.geometry())
        });
        for (p, (file, memory, geometry)) in loaded.into_iter().enumerate() {
            assert_eq!(file, memory, "{name}, part {p}");
            assert_eq!(geometry.m, [5, 4, 4][p], "{name}, part {p}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    // More parts than pixel rows, and a tiled acquisition, are refused by every part alike.
    let (_, acq, _, _) = acquisitions().remove(0);
    for r in in_spaces(14, &|space| acq.split_over(space).map(|_| ())) {
        let e = r.unwrap_err().to_string();
        assert!(e.contains("14 processes for the 13 pixel rows"), "{e}");
    }
    let tiled = Acquisition::new(
        g,
        acq.pulse().to_vec(),
        acq.codes().clone(),
        Some(rdlidar::lidar::TileSize { m: 7, n: 10 }),
        Streaming::Never,
    )
    .unwrap();
    for r in in_spaces(3, &|space| tiled.split_over(space).map(|_| ())) {
        let e = r.unwrap_err().to_string();
        assert!(e.contains("3 processes for the 2 tiles"), "{e}");
    }
}

#[test]
fn the_tiles_of_an_acquisition_dealt_to_parts_are_reconstructed_as_on_one() {
    let g = Geometry::new(23, 17, 16).unwrap();
    let truth = paper_scene(g).unwrap();
    let kp = 400;
    let pulse = Pulse::<f64>::bernoulli(kp, 3).unwrap().into_inner();
    let k = g.samples(kp);
    let tile = rdlidar::lidar::TileSize { m: 5, n: 6 };
    let options = ReconstructOptions::default();
    for codes in [
        CodeStore::Held(vec![Arc::new(
            Codes::random_binary(g.pixels(), k, 4).unwrap(),
        )]),
        CodeStore::Seeded(SeededCodes::new(8, 1, g.pixels(), k).unwrap()),
    ] {
        let acq = Acquisition::new(g, pulse.clone(), codes, Some(tile), Streaming::Never).unwrap();
        let op = acq.operator::<f64>().unwrap();
        let mut y = vec![0.0; op.nrows()];
        op.apply(truth.as_slice(), &mut y);
        let tiled = |r: Reconstructed<f64>| match r {
            Reconstructed::Tiled(r) => r,
            Reconstructed::Single(_) => unreachable!("tiled"),
        };
        for method in [Method::Auto, Method::Cgls] {
            let whole = tiled(
                acq.reconstruct(&y, method, &options, &observe_nothing, &|_| {})
                    .unwrap(),
            );
            // 15 tiles over 2 and 4 parts: bands of tile rows that share a tile row.
            for parts in [2, 4] {
                let seen = AtomicUsize::new(0);
                let split = in_spaces(parts, &|space| {
                    let part = acq.split_over(space).unwrap();
                    let on_tile = |t: &rdlidar::recon::TileReconstruction<f64>| {
                        // Whole places: the tile's rows and index in the whole array.
                        assert_eq!(t.place, whole.tiles[t.place.index].place);
                        seen.fetch_add(1, Ordering::Relaxed);
                    };
                    tiled(
                        part.reconstruct(&y, method, &options, &observe_nothing, &on_tile)
                            .unwrap(),
                    )
                });
                assert_eq!(seen.load(Ordering::Relaxed), 15, "every tile once");
                for r in split {
                    assert_eq!(r.depth.depth, whole.depth.depth, "{method} in {parts}");
                    assert_eq!(
                        r.methods_used(),
                        whole.methods_used(),
                        "{method} in {parts}"
                    );
                    assert_eq!(r.applies(), whole.applies(), "{method} in {parts}");
                    assert_eq!(r.regime(), whole.regime());
                    let places: Vec<_> = r.tiles.iter().map(|t| t.place).collect();
                    let want: Vec<_> = whole.tiles.iter().map(|t| t.place).collect();
                    assert_eq!(places, want);
                    let (a, b) = (whole.scene.as_slice(), r.scene.as_slice());
                    let worst = a
                        .iter()
                        .zip(b)
                        .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
                    assert!(
                        worst <= 1e-12,
                        "{method} in {parts}: scenes differ by {worst:e}"
                    );
                }
            }
        }
    }
}

#[test]
fn a_simulation_split_over_parts_measures_what_one_process_measures() {
    use rdlidar::lidar::{simulate, simulate_split, Architecture, SceneSpec, SimulationSpec};
    let g = Geometry::new(13, 10, 16).unwrap();
    for architecture in [Architecture::Single, Architecture::MultiAdc(2)] {
        let spec = SimulationSpec {
            scene: SceneSpec::Transparent,
            architecture,
            snr_db: Some(20.0),
            seeded_codes: true,
            ..SimulationSpec::new(g, 300, 7)
        };
        let whole = simulate::<f64>(&spec).unwrap();
        for parts in [2, 3] {
            for sim in in_spaces(parts, &|space| {
                simulate_split::<f64>(&spec, &space).unwrap()
            }) {
                assert_eq!(sim.scene, whole.scene);
                assert_eq!(sim.pulse.as_slice(), whole.pulse.as_slice());
                let scale = whole.meas.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let worst = whole
                    .meas
                    .iter()
                    .zip(&sim.meas)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                assert!(worst <= 1e-13 * scale, "{parts} parts: {worst:e}");
                // Each part holds its own rows' codes only.
                assert!(sim.code_sets[0].pixels() <= g.pixels().div_ceil(parts) + g.n);
            }
        }
    }
    let not_seeded = SimulationSpec::new(g, 300, 7);
    for r in in_spaces(2, &|space| {
        simulate_split::<f64>(&not_seeded, &space).map(|_| ())
    }) {
        assert!(r.unwrap_err().to_string().contains("seeded"));
    }
}

#[test]
fn a_supplied_scene_is_simulated_as_a_generated_one_whole_and_split() {
    use rdlidar::lidar::{
        simulate, simulate_split_supplied, simulate_supplied, SceneSpec, SimulationSpec,
    };
    let g = Geometry::new(9, 6, 12).unwrap();
    let generated = SimulationSpec {
        scene: SceneSpec::Random { lit_fraction: 0.6 },
        snr_db: Some(25.0),
        seeded_codes: true,
        ..SimulationSpec::new(g, 200, 3)
    };
    let reference = simulate::<f64>(&generated).unwrap();
    // The same scene supplied: the same pulse, codes, noise and measurements.
    let spec = SimulationSpec {
        scene: SceneSpec::Supplied,
        ..generated
    };
    let whole = simulate_supplied::<f64>(&spec, reference.scene.clone()).unwrap();
    assert_eq!(whole.meas, reference.meas);
    for sim in in_spaces(2, &|space| {
        simulate_split_supplied::<f64>(&spec, &space, reference.scene.clone()).unwrap()
    }) {
        let worst = sim
            .meas
            .iter()
            .zip(&whole.meas)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(worst <= 1e-12, "{worst:e}");
    }
    // A supplied scene needs the supplied kind and the spec's grid; the kind needs a scene.
    let err = simulate_supplied::<f64>(&generated, reference.scene.clone()).unwrap_err();
    assert!(err.to_string().contains("scene"), "{err}");
    let other = rdlidar::lidar::Scene::<f64>::zeros(Geometry::new(9, 7, 12).unwrap());
    let err = simulate_supplied::<f64>(&spec, other).unwrap_err();
    assert!(err.to_string().contains("9x7x12"), "{err}");
    let err = simulate::<f64>(&spec).unwrap_err();
    assert!(err.to_string().contains("supplied"), "{err}");
}
