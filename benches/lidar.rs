//! The random-demodulation operator at the paper's size (100×100×40) and at a small size:
//! forward (dense tables), debiased adjoint and sparse forward on the paper scene, f32 and f64.
//!
//! `cargo bench --bench lidar`; `RDLIDAR_BENCH_PULSES=30000 cargo bench --bench lidar` restricts
//! the pulse lengths.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use rdlidar::lidar::{paper_scene, Codes, ForwardPath, Geometry, Pulse, RdOperator};
use rdlidar::operator::LinearOperator;
use rdlidar::Real;

fn pulses() -> Vec<usize> {
    std::env::var("RDLIDAR_BENCH_PULSES")
        .ok()
        .map(|s| s.split(',').filter_map(|t| t.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![10_000, 20_000, 30_000])
}

fn setup<T: Real>(g: Geometry, kp: usize) -> (RdOperator<T>, Vec<T>, Vec<T>, Vec<T>) {
    let pulse = Pulse::<T>::bernoulli(kp, 1).unwrap().into_inner();
    let codes = Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), 2).unwrap());
    let op = RdOperator::new(g, pulse, codes).unwrap();
    let scene = paper_scene::<T>(g).unwrap();
    let x_sparse = scene.as_slice().to_vec();
    // A dense scene: every voxel nonzero.
    let x_dense: Vec<T> = (0..g.voxels())
        .map(|i| T::of_f64(((i * 7919) % 1000) as f64 / 1000.0))
        .collect();
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(&x_sparse, &mut y);
    (op, x_sparse, x_dense, y)
}

fn bench_precision<T: Real>(c: &mut Criterion, g: Geometry, kps: &[usize]) {
    let mut group = c.benchmark_group(format!("rdop_{g}_{}", T::NAME));
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));
    for &kp in kps {
        let (op, x_sparse, x_dense, y) = setup::<T>(g, kp);
        let dense = op
            .with_pulse(op.pulse().to_vec())
            .unwrap()
            .with_forward_path(ForwardPath::Dense);
        let debiased = op.zero_mean();
        let mut out_y = vec![T::zero(); op.nrows()];
        let mut out_x = vec![T::zero(); op.ncols()];
        group.bench_function(BenchmarkId::new("forward_dense", kp), |b| {
            b.iter(|| dense.apply(black_box(&x_dense), &mut out_y))
        });
        group.bench_function(BenchmarkId::new("adjoint_debiased", kp), |b| {
            b.iter(|| debiased.apply_adjoint(black_box(&y), &mut out_x))
        });
        group.bench_function(BenchmarkId::new("forward_sparse_paper_scene", kp), |b| {
            b.iter(|| op.apply_sparse(black_box(&x_sparse), &mut out_y))
        });
    }
    group.finish();
}

fn paper_size(c: &mut Criterion) {
    let g = Geometry::new(100, 100, 40).unwrap();
    bench_precision::<f32>(c, g, &pulses());
    bench_precision::<f64>(c, g, &pulses());
}

fn small_size(c: &mut Criterion) {
    let g = Geometry::new(16, 16, 16).unwrap();
    bench_precision::<f32>(c, g, &[1_000, 4_081]);
    bench_precision::<f64>(c, g, &[1_000, 4_081]);
}

criterion_group!(benches, paper_size, small_size);
criterion_main!(benches);
