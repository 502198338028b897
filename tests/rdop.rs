//! The fused random-demodulation operator against the one composed from the generic algebra.

use std::sync::Arc;

use proptest::prelude::*;
use rdlidar::lidar::{
    composed_operator, Codes, ForwardPath, Geometry, MultiAdcOperator, Pulse, RdOperator,
};
use rdlidar::operator::{DotTest, LinearOperator};
use rdlidar::Real;

use crate::common::random_vec;

/// Max |a − b| / max |b|.
fn rel<T: Real>(a: &[T], b: &[T]) -> f64 {
    let scale = b
        .iter()
        .fold(0.0f64, |m, v| m.max(v.as_f64().abs()))
        .max(1e-300);
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x.as_f64() - y.as_f64()).abs()))
        / scale
}

#[derive(Debug, Clone, Copy)]
enum SceneKind {
    Dense,
    Sparse,
    Empty,
}

fn scene(kind: SceneKind, len: usize, seed: u64) -> Vec<f64> {
    let v = random_vec(len, seed);
    match kind {
        SceneKind::Dense => v,
        SceneKind::Sparse => v
            .iter()
            .enumerate()
            .map(|(i, &a)| {
                if (i * 7 + seed as usize).is_multiple_of(13) {
                    a
                } else {
                    0.0
                }
            })
            .collect(),
        SceneKind::Empty => vec![0.0; len],
    }
}

fn check<T: Real>(
    g: Geometry,
    kp: usize,
    ternary: bool,
    kind: SceneKind,
    seed: u64,
    tol: f64,
) -> Result<(), TestCaseError> {
    let pulse: Vec<T> = Pulse::<T>::bernoulli(kp, seed).unwrap().into_inner();
    let k = g.samples(kp);
    let codes = if ternary {
        Codes::random_ternary(g.pixels(), k, 0.3, seed ^ 5).unwrap()
    } else {
        Codes::random_binary(g.pixels(), k, seed ^ 5).unwrap()
    };
    let reference = composed_operator(g, &pulse, &codes).unwrap();
    let fused = RdOperator::new(g, pulse.clone(), Arc::new(codes)).unwrap();
    let x: Vec<T> = scene(kind, g.voxels(), seed)
        .into_iter()
        .map(T::of_f64)
        .collect();
    let mut want = vec![T::zero(); k];
    reference.apply(&x, &mut want);
    for path in [ForwardPath::Auto, ForwardPath::Dense, ForwardPath::Sparse] {
        let op = fused
            .with_pulse(pulse.clone())
            .unwrap()
            .with_forward_path(path);
        let mut got = vec![T::zero(); k];
        op.apply(&x, &mut got);
        let e = rel(&got, &want);
        prop_assert!(
            e <= tol,
            "{} {g} K_p {kp} {:?} {:?}: forward differs by {e:e}",
            T::NAME,
            kind,
            path
        );
    }
    let y: Vec<T> = random_vec(k, seed ^ 11)
        .into_iter()
        .map(T::of_f64)
        .collect();
    let mut want_t = vec![T::zero(); g.voxels()];
    reference.apply_adjoint(&y, &mut want_t);
    let mut got_t = vec![T::zero(); g.voxels()];
    fused.apply_adjoint(&y, &mut got_t);
    let e = rel(&got_t, &want_t);
    prop_assert!(
        e <= tol,
        "{} {g} K_p {kp}: adjoint differs by {e:e}",
        T::NAME
    );
    let r = DotTest::new().seed(seed).measure(&fused);
    prop_assert!(r.passed(), "{} dot test gap {:e}", T::NAME, r.gap);
    Ok(())
}

fn geometry() -> impl Strategy<Value = Geometry> {
    (1..=7usize, 1..=9usize, 1..=70usize).prop_map(|(m, n, ks)| Geometry::new(m, n, ks).unwrap())
}

proptest! {
    #![proptest_config(crate::common::config(48))]

    #[test]
    fn fused_matches_composed(
        g in geometry(),
        kp in 1..=120usize,
        ternary in any::<bool>(),
        kind in prop::sample::select(vec![SceneKind::Dense, SceneKind::Sparse, SceneKind::Empty]),
        seed in any::<u64>(),
    ) {
        check::<f64>(g, kp, ternary, kind, seed, 1e-12)?;
        check::<f32>(g, kp, ternary, kind, seed, 1e-5)?;
    }
}

/// Long pulses cross the adjoint's f64 flush boundary (every 16 384 samples) and many pixels cross
/// the forward's (every 8 blocks of groups): both must still match the reference.
#[test]
fn flush_boundaries_match_the_reference() {
    for (g, kp) in [
        (Geometry::new(2, 3, 8).unwrap(), 40_000),
        (Geometry::new(70, 70, 4).unwrap(), 20),
    ] {
        check::<f64>(g, kp, false, SceneKind::Dense, 3, 1e-12).unwrap();
        check::<f32>(g, kp, false, SceneKind::Dense, 3, 1e-5).unwrap();
        check::<f64>(g, kp, true, SceneKind::Sparse, 4, 1e-12).unwrap();
    }
}

/// At K ≥ 10⁶ the f32 operator agrees with the f64 one to 1e-5 relative (long sums are
/// accumulated in f64).
#[test]
fn f32_agrees_with_f64_at_a_million_samples() {
    let g = Geometry::new(3, 3, 6).unwrap();
    let kp = 1_000_000;
    let codes = Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), 9).unwrap());
    let p64 = Pulse::<f64>::bernoulli(kp, 8).unwrap().into_inner();
    let p32: Vec<f32> = p64.iter().map(|&v| v as f32).collect();
    let a64 = RdOperator::new(g, p64, codes.clone()).unwrap();
    let a32 = RdOperator::new(g, p32, codes).unwrap();
    let x64 = random_vec(g.voxels(), 1);
    let x32: Vec<f32> = x64.iter().map(|&v| v as f32).collect();
    for path in [ForwardPath::Dense, ForwardPath::Sparse] {
        let (a64, a32) = (
            a64.with_pulse(a64.pulse().to_vec())
                .unwrap()
                .with_forward_path(path),
            a32.with_pulse(a32.pulse().to_vec())
                .unwrap()
                .with_forward_path(path),
        );
        let mut y64 = vec![0.0; a64.nrows()];
        let mut y32 = vec![0.0f32; a32.nrows()];
        a64.apply(&x64, &mut y64);
        a32.apply(&x32, &mut y32);
        let y32: Vec<f64> = y32.iter().map(|&v| v as f64).collect();
        let e = rel(&y32, &y64);
        assert!(e <= 1e-5, "{path:?} forward: f32 vs f64 {e:e}");
    }
    // The adjoint sums a million terms per voxel.
    let y64 = random_vec(a64.nrows(), 2);
    let y32: Vec<f32> = y64.iter().map(|&v| v as f32).collect();
    let mut b64 = vec![0.0; g.voxels()];
    let mut b32 = vec![0.0f32; g.voxels()];
    a64.apply_adjoint(&y64, &mut b64);
    a32.apply_adjoint(&y32, &mut b32);
    let b32: Vec<f64> = b32.iter().map(|&v| v as f64).collect();
    let e = rel(&b32, &b64);
    assert!(e <= 1e-5, "adjoint: f32 vs f64 {e:e}");
}

proptest! {
    #![proptest_config(crate::common::config(32))]

    /// The support-restricted operator equals A·Rᵀ built with the algebra, in both directions.
    #[test]
    fn support_operator_matches_the_restricted_composition(
        g in geometry(),
        kp in 1..=300usize,
        ternary in any::<bool>(),
        picks in prop::collection::vec(any::<prop::sample::Index>(), 0..=40),
        seed in any::<u64>(),
    ) {
        use rdlidar::lidar::SupportOperator;
        use rdlidar::operator::{OperatorExt, Restriction};
        let pulse = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
        let k = g.samples(kp);
        let codes = if ternary {
            Codes::random_ternary(g.pixels(), k, 0.3, seed ^ 3).unwrap()
        } else {
            Codes::random_binary(g.pixels(), k, seed ^ 3).unwrap()
        };
        let op = RdOperator::new(g, pulse, Arc::new(codes)).unwrap();
        let voxels: Vec<usize> = picks.iter().map(|i| i.index(g.voxels())).collect();
        let sup = SupportOperator::new(&op, voxels.clone()).unwrap();
        let reference = (&op).compose(Restriction::<f64>::new(g.voxels(), voxels.clone()).unwrap().adjoint()).unwrap();
        let a = random_vec(voxels.len(), seed ^ 5);
        let (mut y1, mut y2) = (vec![0.0; k], vec![0.0; k]);
        sup.apply(&a, &mut y1);
        reference.apply(&a, &mut y2);
        prop_assert!(rel(&y1, &y2) <= 1e-12 || y2.iter().all(|v| *v == 0.0));
        let y = random_vec(k, seed ^ 6);
        let (mut x1, mut x2) = (vec![0.0; voxels.len()], vec![0.0; voxels.len()]);
        sup.apply_adjoint(&y, &mut x1);
        reference.apply_adjoint(&y, &mut x2);
        prop_assert!(rel(&x1, &x2) <= 1e-12 || x2.is_empty());
        prop_assert!(DotTest::new().seed(seed).measure(&sup).passed());
        prop_assert!(SupportOperator::new(&op, vec![g.voxels()]).is_err());
    }
}

/// With a pulse longer than the restricted adjoint's spans of samples (2048) and segments of
/// the sparse forward that the windows of some depths miss or cover in part: the support
/// operator equals the composition A·Rᵀ in both directions, in `f64` and `f32`, for pixels with
/// one voxel and with several, both code alphabets.
#[test]
fn support_operator_matches_the_composition_with_a_long_pulse() {
    use rdlidar::lidar::SupportOperator;
    use rdlidar::operator::{OperatorExt, Restriction};
    let g = Geometry::new(3, 5, 24).unwrap();
    let kp = 4700;
    let k = g.samples(kp);
    // Pixel 0: five voxels across the depths; pixel 7: one at the last bin; pixel 14: two; every
    // other pixel of the grid: one at its own depth.
    let mut voxels = vec![0, 3, 11, 12, 23, 7 * 24 + 23, 14 * 24 + 5, 14 * 24 + 6];
    voxels.extend((1..14).filter(|&p| p != 7).map(|p| p * 24 + (p * 5) % 24));
    for ternary in [false, true] {
        let codes = Arc::new(if ternary {
            Codes::random_ternary(g.pixels(), k, 0.3, 41).unwrap()
        } else {
            Codes::random_binary(g.pixels(), k, 41).unwrap()
        });
        let pulse = Pulse::<f64>::bernoulli(kp, 40).unwrap().into_inner();
        let op = RdOperator::new(g, pulse.clone(), codes.clone()).unwrap();
        let sup = SupportOperator::new(&op, voxels.clone()).unwrap();
        // The reference takes the dense forward (tables), not the sparse one the support uses.
        let dense = RdOperator::new(g, pulse.clone(), codes.clone())
            .unwrap()
            .with_forward_path(ForwardPath::Dense);
        let restriction = Restriction::<f64>::new(g.voxels(), voxels.clone()).unwrap();
        let reference = (&dense).compose(restriction.adjoint()).unwrap();
        let a = random_vec(voxels.len(), 42);
        let (mut y1, mut y2) = (vec![0.0; k], vec![0.0; k]);
        sup.apply(&a, &mut y1);
        reference.apply(&a, &mut y2);
        assert!(rel(&y1, &y2) <= 1e-12, "forward, ternary {ternary}");
        let y = random_vec(k, 43);
        let (mut x1, mut x2) = (vec![0.0; voxels.len()], vec![0.0; voxels.len()]);
        sup.apply_adjoint(&y, &mut x1);
        reference.apply_adjoint(&y, &mut x2);
        assert!(rel(&x1, &x2) <= 1e-12, "adjoint, ternary {ternary}");
        let p32: Vec<f32> = pulse.iter().map(|&v| v as f32).collect();
        let op32 = RdOperator::new(g, p32, codes).unwrap();
        let sup32 = SupportOperator::new(&op32, voxels.clone()).unwrap();
        let a32: Vec<f32> = a.iter().map(|&v| v as f32).collect();
        let mut y32 = vec![0.0f32; k];
        sup32.apply(&a32, &mut y32);
        let y32_64: Vec<f64> = y32.iter().map(|&v| f64::from(v)).collect();
        assert!(rel(&y32_64, &y1) <= 1e-5, "f32 forward, ternary {ternary}");
        let yin: Vec<f32> = y.iter().map(|&v| v as f32).collect();
        let mut x32 = vec![0.0f32; voxels.len()];
        sup32.apply_adjoint(&yin, &mut x32);
        let x32_64: Vec<f64> = x32.iter().map(|&v| f64::from(v)).collect();
        assert!(rel(&x32_64, &x1) <= 1e-5, "f32 adjoint, ternary {ternary}");
    }
}

/// ‖a − b‖ / ‖b‖, in `f64`.
fn rel_norm(a: &[f32], b: &[f64]) -> f64 {
    let gap: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (f64::from(*x) - y).powi(2))
        .sum();
    let norm: f64 = b.iter().map(|y| y * y).sum();
    (gap / norm).sqrt()
}

/// The support operator in `f32` stays within 1.5·10⁻⁷ (two and a half units of `f32`
/// round-off) of the same operator in `f64`, in both directions, at the paper's size:
/// 100×100×40, K_p 20 000, one voxel in five of every nine pixels with amplitudes in 0.2..1, the
/// adjoint of a residual's size. The solvers' stopping on a relative residual of 10⁻⁶ in `f32`
/// rests on it: a sparse forward of 1.8·10⁻⁷ (eight entries' amplitudes summed from −Σa by
/// masked additions) turned the demo's TV and `auto` from stopping there to running on to their
/// fixed point. Measured: 6.9·10⁻⁸ and 2.5·10⁻⁸ with AVX-512, 6.9·10⁻⁸ and 6.2·10⁻⁸ with AVX2,
/// 1.08·10⁻⁷ and 8.0·10⁻⁸ with the generic kernels.
#[test]
fn support_applications_in_f32_stay_within_round_off_of_f64() {
    use rdlidar::lidar::SupportOperator;
    let g = Geometry::new(100, 100, 40).unwrap();
    let kp = 20_000;
    let k = g.samples(kp);
    let codes = Arc::new(Codes::random_binary(g.pixels(), k, 1).unwrap());
    let p64 = Pulse::<f64>::bernoulli(kp, 0).unwrap().into_inner();
    let p32: Vec<f32> = p64.iter().map(|&v| v as f32).collect();
    let op64 = RdOperator::new(g, p64, codes.clone()).unwrap();
    let op32 = RdOperator::new(g, p32, codes).unwrap();
    let voxels: Vec<usize> = (0..g.pixels())
        .filter(|p| p % 9 < 5)
        .map(|p| p * 40 + (p / 100 * 7 + p % 13) % 40)
        .collect();
    let a32: Vec<f32> = (0..voxels.len())
        .map(|i| 0.2 + 0.8 * ((i * 7919 % 1000) as f32 / 1000.0))
        .collect();
    let a64: Vec<f64> = a32.iter().map(|&v| f64::from(v)).collect();
    let s64 = SupportOperator::new(&op64, voxels.clone()).unwrap();
    let s32 = SupportOperator::new(&op32, voxels.clone()).unwrap();
    let (mut y64, mut y32) = (vec![0.0f64; k], vec![0.0f32; k]);
    s64.apply(&a64, &mut y64);
    s32.apply(&a32, &mut y32);
    let forward = rel_norm(&y32, &y64);
    let r32: Vec<f32> = y64
        .iter()
        .enumerate()
        .map(|(i, v)| (v * 1e-3 * ((i * 31 % 17) as f64 - 8.0)) as f32)
        .collect();
    let r64: Vec<f64> = r32.iter().map(|&v| f64::from(v)).collect();
    let (mut x64, mut x32) = (vec![0.0f64; voxels.len()], vec![0.0f32; voxels.len()]);
    s64.apply_adjoint(&r64, &mut x64);
    s32.apply_adjoint(&r32, &mut x32);
    let adjoint = rel_norm(&x32, &x64);
    assert!(forward <= 1.5e-7, "forward: {forward:e}");
    assert!(adjoint <= 1.5e-7, "adjoint: {adjoint:e}");
}

/// The sparse forward and the support operator's adjoint add the same values in the same order
/// whatever the number of threads (their entries and voxels go depth by depth, in batches that
/// follow from the entries alone): 1, 2 and 3 threads give the same bits, in `f32` and `f64`,
/// with many entries of a depth (whole batches) and depths with few.
#[test]
fn support_applications_do_not_depend_on_the_threads() {
    use rdlidar::lidar::SupportOperator;
    fn run<T: Real>(threads: usize) -> (Vec<T>, Vec<T>) {
        let g = Geometry::new(12, 10, 16).unwrap();
        let kp = 3000;
        let k = g.samples(kp);
        let codes = Arc::new(Codes::random_binary(g.pixels(), k, 61).unwrap());
        let pulse = Pulse::<T>::bernoulli(kp, 60).unwrap().into_inner();
        let op = RdOperator::new(g, pulse, codes).unwrap();
        // Depth 3 for most pixels, a few at other depths, two voxels in some pixels.
        let mut voxels: Vec<usize> = (0..g.pixels()).step_by(2).map(|p| p * 16 + 3).collect();
        voxels.extend((1..g.pixels()).step_by(7).map(|p| p * 16 + (p % 16)));
        let x: Vec<T> = (0..voxels.len())
            .map(|i| T::of_f64(((i * 37 % 19) as f64 - 9.0) / 7.0))
            .collect();
        let y: Vec<T> = (0..k)
            .map(|i| T::of_f64(((i * 53 % 23) as f64 - 11.0) / 5.0))
            .collect();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let sup = SupportOperator::new(&op, voxels.clone()).unwrap();
            let (mut fwd, mut adj) = (vec![T::zero(); k], vec![T::zero(); voxels.len()]);
            sup.apply(&x, &mut fwd);
            sup.apply_adjoint(&y, &mut adj);
            (fwd, adj)
        })
    }
    let one = run::<f32>(1);
    assert!(one.0.iter().any(|v| *v != 0.0) && one.1.iter().any(|v| *v != 0.0));
    for threads in [2, 3] {
        assert!(run::<f32>(threads) == one, "f32, {threads} threads");
    }
    let one = run::<f64>(1);
    for threads in [2, 3] {
        assert!(run::<f64>(threads) == one, "f64, {threads} threads");
    }
}

/// The dense forward and adjoint add the same values in the same order whatever the number of
/// threads: 1, 2, 3 and 5 threads give the same bits, in `f32` and `f64`, on an array of many
/// blocks of pixel groups (the forward's blocks go to tasks that follow from the blocks alone),
/// for binary and ternary codes. (Simulations and every reconstruction depend on it.)
#[test]
fn dense_applications_do_not_depend_on_the_threads() {
    fn run<T: Real>(threads: usize, ternary: bool) -> (Vec<T>, Vec<T>) {
        let g = Geometry::new(64, 48, 40).unwrap();
        let kp = 700;
        let k = g.samples(kp);
        let codes = if ternary {
            Codes::random_ternary(g.pixels(), k, 0.3, 71).unwrap()
        } else {
            Codes::random_binary(g.pixels(), k, 71).unwrap()
        };
        let pulse = Pulse::<T>::bernoulli(kp, 70).unwrap().into_inner();
        let op = RdOperator::new(g, pulse, Arc::new(codes)).unwrap();
        let x: Vec<T> = (0..g.voxels())
            .map(|i| T::of_f64(((i * 37 % 19) as f64 - 9.0) / 7.0))
            .collect();
        let y: Vec<T> = (0..k)
            .map(|i| T::of_f64(((i * 53 % 23) as f64 - 11.0) / 5.0))
            .collect();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (mut fwd, mut adj) = (vec![T::zero(); k], vec![T::zero(); g.voxels()]);
            op.apply(&x, &mut fwd);
            op.apply_adjoint(&y, &mut adj);
            (fwd, adj)
        })
    }
    for ternary in [false, true] {
        let one = run::<f32>(1, ternary);
        assert!(one.0.iter().any(|v| *v != 0.0) && one.1.iter().any(|v| *v != 0.0));
        for threads in [2, 3, 5] {
            assert!(
                run::<f32>(threads, ternary) == one,
                "f32, ternary {ternary}, {threads} threads"
            );
        }
        let one = run::<f64>(1, ternary);
        for threads in [2, 3, 5] {
            assert!(
                run::<f64>(threads, ternary) == one,
                "f64, ternary {ternary}, {threads} threads"
            );
        }
    }
}

proptest! {
    #![proptest_config(crate::common::config(32))]

    /// The operator's own restriction (the support operator) equals the generic A·Rᵀ, passes the
    /// dot test, and restricting it again gives the support operator of the composed voxels.
    #[test]
    fn restrict_columns_gives_the_support_operator(
        g in geometry(),
        kp in 1..=300usize,
        ternary in any::<bool>(),
        picks in prop::collection::vec(any::<prop::sample::Index>(), 1..=40),
        again in prop::collection::vec(any::<prop::sample::Index>(), 1..=20),
        seed in any::<u64>(),
    ) {
        use rdlidar::operator::{OperatorExt, Restriction};
        let pulse = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
        let k = g.samples(kp);
        let codes = if ternary {
            Codes::random_ternary(g.pixels(), k, 0.3, seed ^ 3).unwrap()
        } else {
            Codes::random_binary(g.pixels(), k, seed ^ 3).unwrap()
        };
        let op = RdOperator::new(g, pulse, Arc::new(codes)).unwrap();
        let voxels: Vec<usize> = picks.iter().map(|i| i.index(g.voxels())).collect();
        let r = op.restrict_columns(voxels.clone()).unwrap();
        prop_assert!(r.describe().starts_with("SupportOperator"));
        let generic = |cols: Vec<usize>| {
            (&op).compose(Restriction::<f64>::new(g.voxels(), cols).unwrap().adjoint()).unwrap()
        };
        let reference = generic(voxels.clone());
        let a = random_vec(voxels.len(), seed ^ 5);
        let (mut y1, mut y2) = (vec![0.0; k], vec![0.0; k]);
        r.apply(&a, &mut y1);
        reference.apply(&a, &mut y2);
        prop_assert!(rel(&y1, &y2) <= 1e-12 || y2.iter().all(|v| *v == 0.0));
        let y = random_vec(k, seed ^ 6);
        let (mut x1, mut x2) = (vec![0.0; voxels.len()], vec![0.0; voxels.len()]);
        r.apply_adjoint(&y, &mut x1);
        reference.apply_adjoint(&y, &mut x2);
        prop_assert!(rel(&x1, &x2) <= 1e-12);
        prop_assert!(DotTest::new().seed(seed).measure(&r).passed());
        let sub: Vec<usize> = again.iter().map(|i| i.index(voxels.len())).collect();
        let composed: Vec<usize> = sub.iter().map(|&c| voxels[c]).collect();
        let rr = r.restrict_columns(sub.clone()).unwrap();
        prop_assert!(rr.describe().starts_with("SupportOperator"));
        let mut x3 = vec![0.0; sub.len()];
        let mut x4 = vec![0.0; sub.len()];
        rr.apply_adjoint(&y, &mut x3);
        generic(composed).apply_adjoint(&y, &mut x4);
        prop_assert!(rel(&x3, &x4) <= 1e-12);
        prop_assert!(r.restrict_columns(vec![voxels.len()]).is_err());
        prop_assert!(op.restrict_columns(vec![g.voxels()]).is_err());
    }
}

/// The work model counts one table row per group and sample (forward; two rows of the quads'
/// tables on AVX-512) and per pixel and octet (adjoint), twice that for ternary codes, plus the
/// tables built; rows are padded to whole chunks of eight values (whole cache lines for quads).
#[test]
fn work_counts_the_table_rows_of_each_kernel() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| {
        // 20 pixels: 3 groups; K_s = 6 bins in one chunk of 8; K = 50 + 5 = 55: 7 octets.
        let g = Geometry::new(4, 5, 6).unwrap();
        let pulse = Pulse::<f32>::bernoulli(50, 0).unwrap().into_inner();
        for (codes, planes) in [
            (Codes::random_binary(20, 55, 1).unwrap(), 1.0),
            (Codes::random_ternary(20, 55, 0.3, 1).unwrap(), 2.0),
        ] {
            let op = RdOperator::new(g, pulse.clone(), Arc::new(codes)).unwrap();
            let w = op.work();
            let (groups, k, octets, ks) = (3.0, 55.0, 7.0, 6.0);
            if op.isa() == "avx512" {
                // Two quads of 16 rows per group, rows padded to a cache line (16 values), of
                // which the kernel reads the first half: the 6 bins all lie there.
                assert_eq!(
                    w.forward.additions,
                    planes * 2.0 * groups * k * ks + groups * 32.0 * ks
                );
                assert_eq!(w.forward.table_bytes, planes * 2.0 * groups * k * 8.0 * 4.0);
            } else {
                assert_eq!(
                    w.forward.additions,
                    planes * groups * k * ks + groups * 256.0 * ks
                );
                assert_eq!(w.forward.table_bytes, planes * groups * k * 8.0 * 4.0);
            }
            // One block of pixels with one thread: the octets' tables are built once.
            assert_eq!(
                w.adjoint.additions,
                planes * 8.0 * groups * octets * ks + octets * 256.0 * ks
            );
            // On AVX-512 the adjoint's rows are whole 512-bit vectors (16 values), but where
            // the processor reads `f32` rows at the slab's width in 256-bit vectors.
            let row = (op.adjoint_row_bytes(1) / 4) as f64;
            let widened = op.isa() == "avx512" && row == 16.0;
            assert!(widened || row == 8.0, "{} rows of {row} values", op.isa());
            assert_eq!(
                w.adjoint.table_bytes,
                planes * 8.0 * groups * octets * row * 4.0
            );
            assert_eq!(w.forward.additions_per_s(0.5), 2.0 * w.forward.additions);
        }
        // K_s = 12 reaches into the second half of the row's vector: the whole row is read.
        let g = Geometry::new(4, 5, 12).unwrap();
        let pulse = Pulse::<f32>::bernoulli(44, 0).unwrap().into_inner();
        let codes = Codes::random_binary(20, 55, 1).unwrap();
        let op = RdOperator::new(g, pulse, Arc::new(codes)).unwrap();
        if op.isa() == "avx512" {
            assert_eq!(op.work().forward.table_bytes, 2.0 * 3.0 * 55.0 * 16.0 * 4.0);
        }
    });
}

#[test]
fn the_gather_limit_is_measured_and_refuses_impossible_rows() {
    let l = rdlidar::lidar::gather_limit::<f64>(5, 32 * 1024, 2).unwrap();
    assert_eq!(l.row_bytes, 5 * 8 * 8);
    assert!(l.table_bytes <= 32 * 1024 && l.table_bytes > 16 * 1024);
    assert!(l.rows_per_s.is_finite() && l.rows_per_s > 0.0);
    assert!((l.bytes_per_s - l.rows_per_s * 320.0).abs() <= 1e-9 * l.bytes_per_s);
    assert!((l.additions_per_s - l.rows_per_s * 40.0).abs() <= 1e-9 * l.additions_per_s);
    for (nch, repeats, name) in [(0, 1, "nch"), (9, 1, "nch"), (2, 0, "repeats")] {
        let e = rdlidar::lidar::gather_limit::<f32>(nch, 4096, repeats).unwrap_err();
        assert!(e.to_string().contains(name), "{e}");
    }
}

/// The single-precision twin of an `f64` operator (one ADC or several) is the operator built in
/// `f32` from the same pulse and codes (bit for bit, on both forward paths), within `f32`'s
/// rounding of the `f64` products; an `f32` operator and a pulse beyond `f32`'s range have
/// none; counting and cancellation reach the twin.
#[test]
fn the_single_precision_twin_is_the_f32_operator() {
    use rdlidar::lidar::Cancellable;
    use rdlidar::operator::Counted;
    use std::sync::atomic::AtomicBool;

    let g = Geometry::new(5, 3, 12).unwrap();
    let kp = 70;
    let pulse = Pulse::<f64>::bernoulli(kp, 3).unwrap().into_inner();
    let codes = Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), 4).unwrap());
    let pulse32: Vec<f32> = pulse.iter().map(|&v| v as f32).collect();
    let x = scene(SceneKind::Sparse, g.voxels(), 5);
    let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
    let y = random_vec(g.samples(kp), 6);
    let y32: Vec<f32> = y.iter().map(|&v| v as f32).collect();
    for path in [ForwardPath::Dense, ForwardPath::Sparse] {
        let op = RdOperator::new(g, pulse.clone(), codes.clone())
            .unwrap()
            .with_forward_path(path);
        let want = RdOperator::new(g, pulse32.clone(), codes.clone())
            .unwrap()
            .with_forward_path(path);
        let twin = op.single().expect("an f64 operator has a twin");
        assert_eq!((twin.nrows(), twin.ncols()), (op.nrows(), op.ncols()));
        let (mut a, mut b) = (vec![0f32; op.nrows()], vec![0f32; op.nrows()]);
        twin.apply(&x32, &mut a);
        want.apply(&x32, &mut b);
        assert_eq!(a, b, "{path:?} forward");
        let mut full = vec![0f64; op.nrows()];
        op.apply(&x, &mut full);
        assert!(rel(&a, &full.iter().map(|&v| v as f32).collect::<Vec<_>>()) < 1e-5);
        let (mut u, mut v) = (vec![0f32; op.ncols()], vec![0f32; op.ncols()]);
        twin.apply_adjoint(&y32, &mut u);
        want.apply_adjoint(&y32, &mut v);
        assert_eq!(u, v, "{path:?} adjoint");
    }
    // G ADCs: the twin is the f32 operator of the same code sets.
    let sets: Vec<_> = (0..3u64)
        .map(|s| Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), 20 + s).unwrap()))
        .collect();
    let multi = MultiAdcOperator::new(g, &pulse, sets.clone()).unwrap();
    let want = MultiAdcOperator::new(g, &pulse32, sets.clone()).unwrap();
    let twin = multi
        .single()
        .expect("an f64 multi-ADC operator has a twin");
    let (mut a, mut b) = (vec![0f32; multi.nrows()], vec![0f32; multi.nrows()]);
    twin.apply(&x32, &mut a);
    want.apply(&x32, &mut b);
    assert_eq!(a, b, "multi-ADC forward");
    let y3: Vec<f32> = random_vec(multi.nrows(), 7)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let (mut u, mut v) = (vec![0f32; g.voxels()], vec![0f32; g.voxels()]);
    twin.apply_adjoint(&y3, &mut u);
    want.apply_adjoint(&y3, &mut v);
    assert_eq!(u, v, "multi-ADC adjoint");
    assert!(want.single().is_none());

    let op32 = RdOperator::new(g, pulse32, codes.clone()).unwrap();
    assert!(op32.single().is_none(), "nothing to gain in f32");
    let mut wide = pulse.clone();
    wide[0] = 1e300;
    let beyond = RdOperator::new(g, wide, codes.clone()).unwrap();
    assert!(beyond.single().is_none(), "a pulse beyond f32's range");

    let op = RdOperator::new(g, pulse, codes).unwrap();
    let counted = Counted::new(&op);
    let twin = counted.single().unwrap();
    let mut a = vec![0f32; op.nrows()];
    twin.apply(&x32, &mut a);
    twin.apply(&x32, &mut a);
    let mut u = vec![0f32; op.ncols()];
    twin.apply_adjoint(&y32, &mut u);
    assert_eq!((counted.forward_count(), counted.adjoint_count()), (2, 1));
    let flag = AtomicBool::new(false);
    let cancellable = Cancellable::new(&op, &flag);
    cancellable.single().unwrap().apply(&x32, &mut a);
    assert!(a.iter().any(|v| *v != 0.0));
    flag.store(true, std::sync::atomic::Ordering::Relaxed);
    cancellable.single().unwrap().apply(&x32, &mut a);
    assert!(
        a.iter().all(|v| *v == 0.0),
        "a raised flag reaches the twin"
    );
}
