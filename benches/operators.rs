//! Benchmarks of the operator kernels.
//!
//! * `dense_vs_composed`: a matrix-free expression `D_out · C · D_in` (diagonals around a short
//!   `Same` convolution) against its materialized matrix wrapped as a `DenseMatrix`.
//! * `convolution`: `Convolve1D` on 100 rows of length 1000, direct against FFT, forward and
//!   adjoint, in `f32` and `f64`, for several kernel lengths.
//! * `gradient2d`: `Gradient2D<f32>` forward and adjoint on square grids.
//!
//! Every benchmark applies the operator through `apply_with_scratch` with input, output and scratch
//! buffers allocated once outside the timed closure, so the timings contain no allocation. Inputs
//! are drawn from a seeded ChaCha8 generator.
//!
//! Run with `cargo bench --bench operators` (add `-- --quick` for a short run, or a filter such as
//! `-- convolution`).

use std::hint::black_box;
use std::time::Duration;

use criterion::measurement::WallTime;
use criterion::{
    criterion_group, criterion_main, BenchmarkGroup, BenchmarkId, Criterion, SamplingMode,
    Throughput,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rdlidar::operator::{ConvMethod, ConvMode, Convolve1D, DenseMatrix, Diagonal, Gradient2D};
use rdlidar::{LinearOperator, OperatorExt, Real};

/// Samples per benchmark and measurement time: small enough for the whole file to run in a few
/// minutes on two cores.
const SAMPLE_SIZE: usize = 20;
const WARM_UP: Duration = Duration::from_millis(500);
const MEASUREMENT: Duration = Duration::from_secs(2);

/// Which product of the operator is timed.
#[derive(Debug, Clone, Copy)]
enum Direction {
    /// y = A·x.
    Forward,
    /// x = A*·y.
    Adjoint,
}

impl Direction {
    const BOTH: [Direction; 2] = [Direction::Forward, Direction::Adjoint];

    fn name(self) -> &'static str {
        match self {
            Direction::Forward => "forward",
            Direction::Adjoint => "adjoint",
        }
    }
}

/// `len` values uniform in [-1, 1), reproducible from `seed`.
fn random_vec<T: Real>(len: usize, seed: u64) -> Vec<T> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len)
        .map(|_| T::of_f64(rng.random_range(-1.0..1.0)))
        .collect()
}

/// Diagonal entries in [0.5, 1.5), reproducible from `seed`.
fn random_weights<T: Real>(len: usize, seed: u64) -> Vec<T> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len)
        .map(|_| T::of_f64(rng.random_range(0.5..1.5)))
        .collect()
}

fn configure(group: &mut BenchmarkGroup<'_, WallTime>) {
    group
        .sample_size(SAMPLE_SIZE)
        .warm_up_time(WARM_UP)
        .measurement_time(MEASUREMENT);
}

/// Times one product of `op` under `id`. The input, the output and a scratch buffer of
/// `op.scratch_len()` scalars are allocated here, before timing starts.
fn bench_apply<T: Real, A: LinearOperator<T>>(
    group: &mut BenchmarkGroup<'_, WallTime>,
    id: BenchmarkId,
    op: &A,
    dir: Direction,
    seed: u64,
) {
    let (in_len, out_len) = match dir {
        Direction::Forward => (op.ncols(), op.nrows()),
        Direction::Adjoint => (op.nrows(), op.ncols()),
    };
    let input = random_vec::<T>(in_len, seed);
    let mut output = vec![T::zero(); out_len];
    let mut scratch = vec![T::zero(); op.scratch_len()];
    group.bench_function(id, |b| match dir {
        Direction::Forward => b.iter(|| {
            op.apply_with_scratch(black_box(&input), black_box(&mut output), &mut scratch)
        }),
        Direction::Adjoint => b.iter(|| {
            op.apply_adjoint_with_scratch(black_box(&input), black_box(&mut output), &mut scratch)
        }),
    });
}

/// Largest absolute difference between the forward products of two operators on one input.
fn max_forward_gap<T: Real>(a: &dyn LinearOperator<T>, b: &dyn LinearOperator<T>) -> f64 {
    let x = random_vec::<T>(a.ncols(), 99);
    let mut ya = vec![T::zero(); a.nrows()];
    let mut yb = vec![T::zero(); b.nrows()];
    a.apply(&x, &mut ya);
    b.apply(&x, &mut yb);
    ya.iter()
        .zip(&yb)
        .map(|(&p, &q)| (p.as_f64() - q.as_f64()).abs())
        .fold(0.0, f64::max)
}

/// `D_out · C · D_in` with C a length-8 `Same` convolution of one row of length `n`, applied
/// matrix-free and as its `n × n` dense matrix.
fn dense_vs_composed(c: &mut Criterion) {
    let mut group = c.benchmark_group("dense_vs_composed");
    configure(&mut group);
    for n in [64usize, 256, 1024] {
        let kernel = random_vec::<f64>(8, 1);
        let conv = Convolve1D::new(1, n, kernel, ConvMode::Same, ConvMethod::Direct)
            .expect("valid convolution");
        let d_in = Diagonal::new(random_weights::<f64>(n, 2)).expect("finite weights");
        let d_out = Diagonal::new(random_weights::<f64>(n, 3)).expect("finite weights");
        let composed = conv
            .compose(d_in)
            .and_then(|op| op.then(d_out))
            .expect("shapes fit");
        let dense = DenseMatrix::new(composed.to_dense()).expect("finite matrix");
        let gap = max_forward_gap(&composed, &dense);
        assert!(
            gap < 1e-10,
            "dense and composed forms differ by {gap:e} at n = {n}"
        );

        group.throughput(Throughput::Elements(n as u64));
        bench_apply(
            &mut group,
            BenchmarkId::new("composed", n),
            &composed,
            Direction::Forward,
            4,
        );
        bench_apply(
            &mut group,
            BenchmarkId::new("dense", n),
            &dense,
            Direction::Forward,
            4,
        );
    }
    group.finish();
}

const CONV_BATCH: usize = 100;
const CONV_ROW: usize = 1000;
const CONV_KERNELS: [usize; 3] = [8, 64, 512];

fn bench_convolution_type<T: Real>(group: &mut BenchmarkGroup<'_, WallTime>) {
    for kernel_len in CONV_KERNELS {
        let kernel = random_vec::<T>(kernel_len, 10 + kernel_len as u64);
        for (method, method_name) in [(ConvMethod::Direct, "direct"), (ConvMethod::Fft, "fft")] {
            let op = Convolve1D::new(CONV_BATCH, CONV_ROW, kernel.clone(), ConvMode::Same, method)
                .expect("valid convolution");
            for dir in Direction::BOTH {
                let id = BenchmarkId::new(
                    format!("{}_{method_name}_{}", T::NAME, dir.name()),
                    kernel_len,
                );
                bench_apply(group, id, &op, dir, 20);
            }
        }
    }
}

/// `Convolve1D` on `CONV_BATCH` rows of `CONV_ROW` samples (`Same` mode), direct vs FFT.
fn convolution(c: &mut Criterion) {
    let mut group = c.benchmark_group("convolution");
    configure(&mut group);
    // The direct path with long kernels takes tens of milliseconds per call; flat sampling keeps
    // the number of iterations per benchmark small.
    group.sampling_mode(SamplingMode::Flat);
    group.throughput(Throughput::Elements((CONV_BATCH * CONV_ROW) as u64));
    bench_convolution_type::<f32>(&mut group);
    bench_convolution_type::<f64>(&mut group);
    group.finish();
}

/// `Gradient2D<f32>` on square grids.
fn gradient2d(c: &mut Criterion) {
    let mut group = c.benchmark_group("gradient2d");
    configure(&mut group);
    for side in [100usize, 500] {
        let op = Gradient2D::<f32>::new(side, side).expect("non-empty grid");
        group.throughput(Throughput::Elements((side * side) as u64));
        for dir in Direction::BOTH {
            let id = BenchmarkId::new(dir.name(), format!("{side}x{side}"));
            bench_apply(&mut group, id, &op, dir, 30);
        }
    }
    group.finish();
}

criterion_group!(benches, dense_vs_composed, convolution, gradient2d);
criterion_main!(benches);
