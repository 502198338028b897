//! Message passing with the one-reflector prior (`reflector_amp`): exact recovery where the
//! greedy exploration is not enough, the pixel Gram blocks it relies on, noise, degenerate inputs
//! and typed errors.

use std::sync::Arc;

use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rdlidar::lidar::{paper_scene, Codes, Geometry, Pulse, RdOperator, Scene};
use rdlidar::operator::{LinearOperator, PixelColumns, VoxelOperator, Zero};
use rdlidar::recon::compare;
use rdlidar::solver::{
    model_based, reflector_amp, ModelBasedParams, ReflectorAmpParams, Termination,
};
use rdlidar::{Error, Real};

fn lidar_problem<T: Real>(g: Geometry, kp: usize, seed: u64) -> RdOperator<T> {
    let pulse = Pulse::<T>::bernoulli(kp, seed).unwrap().into_inner();
    let codes = Codes::random_binary(g.pixels(), g.samples(kp), seed + 1).unwrap();
    RdOperator::new(g, pulse, Arc::new(codes)).unwrap()
}

fn one_per_pixel<T: Real>(x: &[T], ks: usize) -> bool {
    x.chunks(ks)
        .all(|c| c.iter().filter(|v| **v != T::zero()).count() <= 1)
}

/// 32×32×40 with K_p = 3000: 0.55 lit pixels per 3 measurements, where backprojection finds
/// about a quarter of the depths.
fn hard_problem<T: Real>() -> (Geometry, RdOperator<T>, Scene<T>, Vec<T>) {
    let g = Geometry::new(32, 32, 40).unwrap();
    let op = lidar_problem::<T>(g, 3000, 0);
    let truth = paper_scene::<T>(g).unwrap();
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    (g, op, truth, y)
}

#[test]
fn recovers_the_paper_scene_exactly_in_f64_and_f32() {
    let (g, op, truth, y) = hard_problem::<f64>();
    let mut x = vec![0.0; g.voxels()];
    let report = reflector_amp(&op, &y, &mut x, &ReflectorAmpParams::default(), &mut ()).unwrap();
    assert!(one_per_pixel(&x, g.ks));
    let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
    assert_eq!(m.exact, m.lit, "{m} ({report:?})");
    assert_eq!(m.false_detections, 0, "{m}");
    assert!(m.relative_error < 1e-3, "{m}");
    // One forward and one adjoint application per iteration.
    assert_eq!(report.forward_applies, report.iterations);
    assert_eq!(report.adjoint_applies, report.iterations);
    assert!(report.iterations < 60, "{report:?}");

    let (g, op, truth, y) = hard_problem::<f32>();
    let mut x = vec![0.0f32; g.voxels()];
    reflector_amp(&op, &y, &mut x, &ReflectorAmpParams::default(), &mut ()).unwrap();
    let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
    assert_eq!(m.exact, m.lit, "f32: {m}");
    assert_eq!(m.false_detections, 0, "f32: {m}");
}

#[test]
fn model_based_started_by_amp_is_exact_where_the_exploration_is_not_better() {
    let (g, op, truth, y) = hard_problem::<f64>();
    let run = |amp: Option<ReflectorAmpParams>| {
        let mut x = vec![0.0; g.voxels()];
        let params = ModelBasedParams {
            amp,
            ..ModelBasedParams::default()
        };
        let report = model_based(&op, &y, &mut x, &params, &mut ()).unwrap();
        assert!(one_per_pixel(&x, g.ks));
        (
            compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap(),
            report,
        )
    };
    let (with_amp, report) = run(Some(ReflectorAmpParams::default()));
    assert_eq!(with_amp.exact, with_amp.lit, "{with_amp} ({report:?})");
    assert_eq!(with_amp.false_detections, 0, "{with_amp}");
    assert!(with_amp.relative_error < 1e-6, "{with_amp}");
    let (explored, _) = run(None);
    assert!(explored.exact <= with_amp.exact, "{explored}");
}

#[test]
fn twenty_db_noise_keeps_almost_every_depth() {
    let (g, op, truth, mut y) = hard_problem::<f64>();
    let power = y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64;
    let sigma = (power / 100.0).sqrt();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    for v in &mut y {
        let e: f64 = StandardNormal.sample(&mut rng);
        *v += sigma * e;
    }
    let mut x = vec![0.0; g.voxels()];
    model_based(&op, &y, &mut x, &ModelBasedParams::default(), &mut ()).unwrap();
    let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
    assert!(m.exact_fraction >= 0.95, "{m}");
    assert!(m.false_fraction_empty <= 0.02, "{m}");
}

#[test]
fn pixel_gram_blocks_are_the_inner_products_of_the_pixel_columns() {
    let g = Geometry::new(3, 2, 6).unwrap();
    let op = lidar_problem::<f64>(g, 40, 3);
    assert!(op.uniform_pixel_gram());
    let column = |c: usize| {
        let mut e = vec![0.0; g.voxels()];
        e[c] = 1.0;
        let mut a = vec![0.0; op.nrows()];
        op.apply(&e, &mut a);
        a
    };
    for pixel in [0, 4] {
        let block = op.pixel_gram(pixel);
        for i in 0..g.ks {
            for j in 0..g.ks {
                let (a, b) = (column(pixel * g.ks + i), column(pixel * g.ks + j));
                let want: f64 = a.iter().zip(&b).map(|(u, v)| u * v).sum();
                assert!(
                    (block[i * g.ks + j] - want).abs() <= 1e-9,
                    "pixel {pixel}, ({i}, {j})"
                );
            }
        }
    }
    // The generic default (through PixelColumns) computes the same block.
    let generic = PixelColumns::new(&op, g.ks).unwrap();
    assert!(!generic.uniform_pixel_gram());
    let (a, b) = (op.pixel_gram(2), generic.pixel_gram(2));
    assert!(a.iter().zip(&b).all(|(u, v)| (u - v).abs() <= 1e-9));

    // Ternary codes: a pixel whose codes are all zero has a zero block, one whose codes are
    // all nonzero the ±1 block.
    let k = g.samples(40);
    let pulse = Pulse::<f64>::bernoulli(40, 3).unwrap().into_inner();
    let mut c = ndarray::Array2::<i8>::zeros((g.pixels(), k));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
    for p in 1..g.pixels() {
        for t in 0..k {
            c[[p, t]] = if rng.random_bool(0.5) { 1 } else { -1 };
        }
    }
    let codes = Codes::from_dense(c.view()).unwrap();
    let ternary = RdOperator::new(g, pulse.clone(), Arc::new(codes)).unwrap();
    assert!(!ternary.uniform_pixel_gram());
    assert!(ternary.pixel_gram(0).iter().all(|v| *v == 0.0));
    let full = RdOperator::new(
        g,
        pulse,
        Arc::new(Codes::random_binary(g.pixels(), k, 1).unwrap()),
    )
    .unwrap();
    let (a, b) = (ternary.pixel_gram(3), full.pixel_gram(3));
    assert!(a.iter().zip(&b).all(|(u, v)| (u - v).abs() <= 1e-12));
}

#[test]
fn degenerate_inputs_give_finite_results() {
    let g = Geometry::new(4, 4, 6).unwrap();
    let op = lidar_problem::<f64>(g, 200, 1);
    let params = ReflectorAmpParams::default();
    let y = vec![0.0; op.nrows()];
    let mut x = vec![1.0; g.voxels()];
    let r = reflector_amp(&op, &y, &mut x, &params, &mut ()).unwrap();
    assert_eq!(r.termination, Termination::ZeroResidual);
    assert!(x.iter().all(|v| *v == 0.0));
    // A zero operator: no pixel is observable, so none is declared lit.
    let zero = PixelColumns::new(Zero::<f64>::new(10, 12), 3).unwrap();
    let mut x = vec![0.0; 12];
    reflector_amp(&zero, &[1.0; 10], &mut x, &params, &mut ()).unwrap();
    assert!(x.iter().all(|v| *v == 0.0));
    // Pure noise: finite, one depth per pixel at most.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let noise: Vec<f64> = (0..op.nrows())
        .map(|_| StandardNormal.sample(&mut rng))
        .collect();
    let mut x = vec![0.0; g.voxels()];
    reflector_amp(&op, &noise, &mut x, &params, &mut ()).unwrap();
    assert!(x.iter().all(|v| v.is_finite()));
    assert!(one_per_pixel(&x, g.ks));
}

#[test]
fn invalid_parameters_and_shapes_are_typed_errors() {
    let g = Geometry::new(4, 4, 6).unwrap();
    let op = lidar_problem::<f64>(g, 100, 2);
    let y = vec![1.0; op.nrows()];
    let mut x = vec![0.0; g.voxels()];
    let d = ReflectorAmpParams::default();
    for bad in [
        ReflectorAmpParams {
            lit_probability: 0.0,
            ..d
        },
        ReflectorAmpParams {
            lit_probability: f64::NAN,
            ..d
        },
        ReflectorAmpParams { decision: 1.0, ..d },
        ReflectorAmpParams { patience: 0, ..d },
    ] {
        let e = reflector_amp(&op, &y, &mut x, &bad, &mut ()).unwrap_err();
        assert!(matches!(e, Error::InvalidParameter { .. }), "{e}");
        let mb = ModelBasedParams {
            amp: Some(bad),
            ..ModelBasedParams::default()
        };
        let e = model_based(&op, &y, &mut x, &mb, &mut ()).unwrap_err();
        assert!(matches!(e, Error::InvalidParameter { .. }), "{e}");
    }
    let e = reflector_amp(&op, &y[1..], &mut x, &d, &mut ()).unwrap_err();
    assert!(matches!(e, Error::ShapeMismatch { .. }), "{e}");
    let mut nan = y.clone();
    nan[3] = f64::NAN;
    let e = reflector_amp(&op, &nan, &mut x, &d, &mut ()).unwrap_err();
    assert!(matches!(e, Error::NonFinite { .. }), "{e}");
}

/// Message passing with the operator's single-precision twin: on the hard problem in `f64` it
/// recovers the same exact scene in as many iterations, its amplitudes within `f32`'s rounding
/// of the full-precision run's (and not equal to them: the twin ran); in `f32` there is no
/// twin and the run is the same bit for bit.
#[test]
fn single_precision_applications_recover_the_same_scene() {
    let (g, op, truth, y) = hard_problem::<f64>();
    let run = |single_precision: bool| {
        let mut x = vec![0.0; g.voxels()];
        let params = ReflectorAmpParams {
            single_precision,
            ..ReflectorAmpParams::default()
        };
        let report = reflector_amp(&op, &y, &mut x, &params, &mut ()).unwrap();
        (x, report)
    };
    let (full, full_report) = run(false);
    let (low, low_report) = run(true);
    let m = compare(&truth, &Scene::from_vec(g, low.clone()).unwrap(), 200e-12).unwrap();
    assert_eq!((m.exact, m.false_detections), (m.lit, 0), "{m}");
    assert_eq!(low_report.iterations, full_report.iterations);
    assert_eq!(low_report.forward_applies, low_report.iterations);
    let support = |x: &[f64]| x.iter().map(|v| *v != 0.0).collect::<Vec<_>>();
    assert_eq!(support(&low), support(&full));
    let scale = full.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = low
        .iter()
        .zip(&full)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(diff > 0.0 && diff < 1e-4 * scale, "{diff} of {scale}");

    let (g, op, _, y) = hard_problem::<f32>();
    let run = |single_precision: bool| {
        let mut x = vec![0.0f32; g.voxels()];
        let params = ReflectorAmpParams {
            single_precision,
            ..ReflectorAmpParams::default()
        };
        reflector_amp(&op, &y, &mut x, &params, &mut ()).unwrap();
        x
    };
    assert_eq!(run(true), run(false));
}
