//! The seam for unknowns split across processes, proved in one process: the unknowns of a lidar
//! problem are split by pixels into R parts, one thread per part; each thread runs a solver on
//! its part through an operator whose space combines the parts (a condition-variable exchange),
//! and the gathered result must be that of the plain run on the whole: the same supports,
//! iterations and endings, and values equal up to round-off.
//!
//! The part operator is a column block of the whole operator: its forward application is the
//! block's partial measurement summed over the parts (a collective), its adjoint and its column
//! queries are local. A split operator must answer the per-pixel column queries
//! ([`VoxelOperator`]) locally, as this one does: the defaults, which apply the whole operator to
//! one column at a time, would make one part's query a collective the others do not join.
//!
//! A part that calls a collective the others do not (a solver deciding on a local value) is
//! caught: the exchange checks that every part calls the same collective on the same length, and
//! gives up with a panic, not a hang, when a part does not come.

use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread;
use std::time::{Duration, Instant};

use rdlidar::error::Result;
use rdlidar::lidar::{paper_scene, Codes, Geometry, Pulse, RdOperator};
use rdlidar::operator::{LinearOperator, VoxelOperator};
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
        })
    }

    fn lock(&self) -> MutexGuard<'_, Exchange> {
        // A part that panicked poisons the lock; the others go on to fail at their next wait.
        self.exchange.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Every part's deposit of one collective, in part order, once all have come.
    fn all(&self, part: usize, kind: &'static str, values: Vec<f64>) -> Arc<Vec<Deposit>> {
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

/// A block of columns of an operator whose outputs are summed over the parts.
struct Summed<'a> {
    block: Box<dyn LinearOperator<f64> + 'a>,
    space: &'a PartSpace,
}

impl LinearOperator<f64> for Summed<'_> {
    fn nrows(&self) -> usize {
        self.block.nrows()
    }
    fn ncols(&self) -> usize {
        self.block.ncols()
    }
    fn forward_kernel(&self, x: &[f64], y: &mut [f64], _: &mut [f64]) {
        self.block.apply(x, y);
        self.space.sum(y);
    }
    fn adjoint_kernel(&self, y: &[f64], x: &mut [f64], _: &mut [f64]) {
        self.block.apply_adjoint(y, x);
    }
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<f64> + '_>> {
        Ok(Box::new(Summed {
            block: self.block.restrict_columns(columns)?,
            space: self.space,
        }))
    }
    fn space(&self) -> &dyn Space {
        self.space
    }
}

/// One part of a lidar operator split by pixels: the columns `first..first + ncols` of `whole`.
struct Part<'a> {
    whole: &'a RdOperator<f64>,
    first: usize,
    summed: Summed<'a>,
}

impl<'a> Part<'a> {
    fn new(
        whole: &'a RdOperator<f64>,
        pixels: std::ops::Range<usize>,
        space: &'a PartSpace,
    ) -> Self {
        let ks = whole.column_len();
        let columns: Vec<usize> = (pixels.start * ks..pixels.end * ks).collect();
        Self {
            whole,
            first: pixels.start * ks,
            summed: Summed {
                block: whole.restrict_columns(columns).unwrap(),
                space,
            },
        }
    }

    fn global(&self, local: &[usize]) -> Vec<usize> {
        local.iter().map(|c| c + self.first).collect()
    }
}

impl LinearOperator<f64> for Part<'_> {
    fn nrows(&self) -> usize {
        self.summed.nrows()
    }
    fn ncols(&self) -> usize {
        self.summed.ncols()
    }
    fn forward_kernel(&self, x: &[f64], y: &mut [f64], s: &mut [f64]) {
        self.summed.forward_kernel(x, y, s)
    }
    fn adjoint_kernel(&self, y: &[f64], x: &mut [f64], s: &mut [f64]) {
        self.summed.adjoint_kernel(y, x, s)
    }
    fn restrict_columns(&self, columns: Vec<usize>) -> Result<Box<dyn LinearOperator<f64> + '_>> {
        self.summed.restrict_columns(columns)
    }
    fn space(&self) -> &dyn Space {
        self.summed.space
    }
}

impl VoxelOperator<f64> for Part<'_> {
    fn column_len(&self) -> usize {
        self.whole.column_len()
    }
    fn correlate(&self, r: &[f64], u: &mut [f64]) {
        let mut all = vec![0.0; self.whole.ncols()];
        self.whole.correlate(r, &mut all);
        u.copy_from_slice(&all[self.first..self.first + u.len()]);
    }
    fn self_correlations(&self, voxels: &[usize]) -> Vec<f64> {
        self.whole.self_correlations(&self.global(voxels))
    }
    fn pixel_gram(&self, pixel: usize) -> Vec<f64> {
        self.whole
            .pixel_gram(pixel + self.first / self.whole.column_len())
    }
    fn uniform_pixel_gram(&self) -> bool {
        self.whole.uniform_pixel_gram()
    }
    fn column_norms(&self, columns: &[usize]) -> Vec<f64> {
        self.whole.column_norms(&self.global(columns))
    }
    fn structured_columns(&self) -> bool {
        true
    }
}

/// A solver run on one operator: the report, or the error's text.
type Run<'o> = dyn Fn(&dyn VoxelOperator<f64>, &[f64], &mut [f64]) -> std::result::Result<Report, String>
    + Sync
    + 'o;

/// The unknowns and the report of a run on the whole.
type Solved = (Vec<f64>, Report);
/// The gathered unknowns and every part's report of a split run.
type SolvedInParts = (Vec<f64>, Vec<Report>);

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
    let pixels = op.ncols() / op.column_len();
    let shared = Shared::new(parts);
    let runs: Vec<(Vec<f64>, Report)> = thread::scope(|s| {
        let handles: Vec<_> = (0..parts)
            .map(|p| {
                let shared = Arc::clone(&shared);
                s.spawn(move || {
                    let space = PartSpace { shared, part: p };
                    let part = Part::new(op, p * pixels / parts..(p + 1) * pixels / parts, &space);
                    let mut x = vec![0.0; part.ncols()];
                    let report = run(&part, y, &mut x).expect("a part's run");
                    (x, report)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
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
    let g = Geometry::new(m, n, ks).unwrap();
    let pulse = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
    let codes = Codes::random_binary(g.pixels(), g.samples(kp), seed + 1).unwrap();
    let op = RdOperator::new(g, pulse, Arc::new(codes)).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
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
        let params = CosampParams {
            stopping: stopping(10),
            ..CosampParams::new(returns())
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
