//! The precision and dot-test groups: the `f32` operator against the `f64` one, and the dot test
//! of both, as the number of samples K grows.

use std::ops::ControlFlow;
use std::sync::Arc;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::lidar::{Codes, Geometry, Pulse, RdOperator, Seeds};
use crate::linalg::{dist2_sq, norm2};
use crate::operator::{DotTest, LinearOperator};
use crate::real::Real;

use super::{
    cast, count_text, f32_exact_gaussian, stress_rng, Check, Group, Sink, StressConfig, StressRow,
};

/// Tolerance of ‖A₃₂x − A₆₄x‖/‖A₆₄x‖ for both forward paths, in units of the `f32` epsilon
/// ε = 2⁻²³ ≈ 1.19e-7. Each sample is a sum over the M·N·K_s voxels (128 here), whatever K: the
/// gap is the rounding of the tables, of the partial sums and of the output (measured 0.6ε to
/// 0.9ε at every K).
pub const FORWARD_TOL_EPS: f64 = 4.0;

/// Tolerance of ‖A₃₂*y − A₆₄*y‖/‖A₆₄*y‖, in units of the `f32` epsilon. Each adjoint entry is a
/// sum over K_p samples; the kernel adds at most 128 table rows (1024 samples) in `f32` before
/// it flushes the sum to `f64`, so the gap does not grow with K (measured 0.7ε to 1.1ε from
/// K = 10⁴ to 10⁷), whereas a plain `f32` sum drifts like ε·√(K/2) (the
/// `naive_f32` value: 3ε to 16ε at K = 10⁴, 140ε to 400ε at 10⁷). The tolerance catches that
/// drift from K = 10⁵ on.
pub const ADJOINT_TOL_EPS: f64 = 8.0;

/// Tolerance of the dot-test gap, in units of the precision's epsilon (ε₃₂ ≈ 1.19e-7,
/// ε₆₄ ≈ 2.22e-16): the adjoint identity must hold to round-off, far tighter than the library's
/// default dot-test tolerance (10⁻⁴ and 10⁻¹⁰), which must hold for every operator.
pub const DOT_TOL_EPS: f64 = 4.0;

/// Runs both groups.
pub(super) fn run(config: &StressConfig, sink: &mut Sink<'_>) -> Result<ControlFlow<()>> {
    let mut dot_rows = Vec::new();
    for &k in &config.samples {
        let rows = at_samples(config, k)?;
        for row in rows {
            if row.group == Group::DotTest {
                dot_rows.push(row);
            } else if sink(row).is_break() {
                return Ok(ControlFlow::Break(()));
            }
        }
    }
    for row in dot_rows {
        if sink(row).is_break() {
            return Ok(ControlFlow::Break(()));
        }
    }
    Ok(ControlFlow::Continue(()))
}

/// ‖a − b‖/‖b‖ in `f64`.
fn relative_gap<A: Real>(a: &[A], b: &[f64]) -> f64 {
    let a: Vec<f64> = a.iter().map(|v| v.as_f64()).collect();
    dist2_sq(&a, b).sqrt() / norm2(b)
}

/// The rows of one K: three precision rows and two dot-test rows.
fn at_samples(config: &StressConfig, k: usize) -> Result<Vec<StressRow>> {
    let g = config.precision_geometry;
    if k < g.ks {
        return Err(Error::param(
            "samples",
            format!("K = {k} is below K_s = {}", g.ks),
        ));
    }
    let kp = k - g.ks + 1;
    let seeds = Seeds::new(config.seed);
    let kt = count_text(k);
    let pulse = Pulse::<f64>::bernoulli(kp, seeds.pulse())?.into_inner();
    let codes = Arc::new(Codes::random_binary(g.pixels(), k, seeds.code_set(0))?);
    let mut rng = stress_rng(config.seed, 1);
    let x = f32_exact_gaussian(g.voxels(), &mut rng);
    let y = f32_exact_gaussian(k, &mut rng);
    // One precision at a time, so that only one operator's work buffers (up to 72 bytes per
    // sample in f64) are held.
    let (out64, t64) = outputs::<f64>(g, &pulse, &codes, &x, &y)?;
    let (out32, t32) = outputs::<f32>(g, &pulse, &codes, &x, &y)?;
    let eps = f32::EPS;
    let mut rows = Vec::new();
    for (i, name) in ["forward (dense)", "forward (sparse)"].iter().enumerate() {
        let gap = relative_gap(&out32[i], &out64[i]);
        rows.push(StressRow::new(
            Group::Precision,
            format!("{name}, K = {kt}"),
            "f32 vs f64",
            vec![("rel_diff", gap)],
            vec![Check::at_most("rel_diff", gap, FORWARD_TOL_EPS * eps)],
            t64[i] + t32[i],
        ));
    }
    let gap = relative_gap(&out32[2], &out64[2]);
    let naive = naive_adjoint_pixel0(&codes, &cast::<f32>(&pulse), &cast::<f32>(&y), g.ks);
    let naive_gap = relative_gap(&naive, &out64[2][..g.ks]);
    rows.push(StressRow::new(
        Group::Precision,
        format!("adjoint, K = {kt}"),
        "f32 vs f64",
        vec![("rel_diff", gap), ("naive_f32", naive_gap)],
        vec![Check::at_most("rel_diff", gap, ADJOINT_TOL_EPS * eps)],
        t64[2] + t32[2],
    ));
    rows.push(dot_row::<f32>(config, k, &pulse, &codes)?);
    rows.push(dot_row::<f64>(config, k, &pulse, &codes)?);
    Ok(rows)
}

/// The dense forward A·x, the sparse forward A·x and the adjoint A*·y of the operator in
/// precision `T`, in `f64`, with the time of each.
fn outputs<T: Real>(
    g: Geometry,
    pulse: &[f64],
    codes: &Arc<Codes>,
    x: &[f64],
    y: &[f64],
) -> Result<([Vec<f64>; 3], [f64; 3])> {
    let op = RdOperator::new(g, cast::<T>(pulse), codes.clone())?;
    let (x, y) = (cast::<T>(x), cast::<T>(y));
    let k = op.nrows();
    let mut times = [0.0; 3];
    let mut timed = |i: usize, f: &dyn Fn(&mut [T]), len: usize| {
        let start = Instant::now();
        let mut out = vec![T::zero(); len];
        f(&mut out);
        times[i] = start.elapsed().as_secs_f64();
        out.iter().map(|v| v.as_f64()).collect::<Vec<f64>>()
    };
    let dense = timed(0, &|out| op.apply_dense(&x, out), k);
    let sparse = timed(1, &|out| op.apply_sparse(&x, out), k);
    let adjoint = timed(2, &|out| op.apply_adjoint(&y, out), g.voxels());
    Ok(([dense, sparse, adjoint], times))
}

/// The dot test of the operator in precision `T`.
fn dot_row<T: Real>(
    config: &StressConfig,
    k: usize,
    pulse: &[f64],
    codes: &Arc<Codes>,
) -> Result<StressRow> {
    let start = Instant::now();
    let g = config.precision_geometry;
    let op = RdOperator::new(g, cast::<T>(pulse), codes.clone())?;
    let report = DotTest::new().seed(config.seed).measure(&op);
    Ok(StressRow::new(
        Group::DotTest,
        format!("K = {}", count_text(k)),
        T::NAME,
        vec![("gap", report.gap)],
        vec![Check::at_most("gap", report.gap, DOT_TOL_EPS * T::EPS)],
        start.elapsed().as_secs_f64(),
    ))
}

/// The adjoint's entries of pixel 0 summed the plain way, sample after sample in `f32`:
/// `x[0, j] = Σ_k s[0, k]·p[k − j]·y[k]`. The reference that shows what `f32` accumulation
/// would cost.
fn naive_adjoint_pixel0(codes: &Codes, pulse: &[f32], y: &[f32], ks: usize) -> Vec<f32> {
    let k = codes.len();
    let signs: Vec<f32> = (0..k).map(|t| f32::from(codes.get(0, t))).collect();
    (0..ks)
        .map(|j| {
            let mut acc = 0.0f32;
            for (t, &p) in pulse.iter().enumerate() {
                let i = t + j;
                if i >= k {
                    break;
                }
                acc += signs[i] * p * y[i];
            }
            acc
        })
        .collect()
}
