//! The model-based one-reflector-per-pixel solver: exact recovery, the model constraint, the
//! operator hooks it relies on (self-correlations, column norms, restriction), degenerate inputs
//! and typed errors.

use std::sync::Arc;

use ndarray::Array2;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rdlidar::lidar::{paper_scene, random_opaque_scene, Codes, Geometry, Pulse, RdOperator, Scene};
use rdlidar::operator::{DenseMatrix, LinearOperator, PixelColumns, VoxelOperator, Zero};
use rdlidar::recon::compare;
use rdlidar::solver::{model_based, ModelBasedParams, Stopping, Termination};
use rdlidar::Error;

fn lidar_problem(g: Geometry, kp: usize, ternary: bool, seed: u64) -> RdOperator<f64> {
    let pulse = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
    let k = g.samples(kp);
    let codes = if ternary {
        Codes::random_ternary(g.pixels(), k, 0.3, seed + 1).unwrap()
    } else {
        Codes::random_binary(g.pixels(), k, seed + 1).unwrap()
    };
    RdOperator::new(g, pulse, Arc::new(codes)).unwrap()
}

/// At most one nonzero per pixel of `ks` entries.
fn one_per_pixel(x: &[f64], ks: usize) -> bool {
    x.chunks(ks)
        .all(|c| c.iter().filter(|v| **v != 0.0).count() <= 1)
}

#[test]
fn recovers_the_paper_scene_exactly_at_a_comfortable_pulse_length() {
    let g = Geometry::new(24, 24, 32).unwrap();
    let op = lidar_problem(g, 6000, false, 3);
    let truth = paper_scene::<f64>(g).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    let mut x = vec![0.0; g.voxels()];
    let report = model_based(&op, &y, &mut x, &ModelBasedParams::default(), &mut ()).unwrap();
    assert!(one_per_pixel(&x, g.ks));
    let est = Scene::from_vec(g, x).unwrap();
    let m = compare(&truth, &est, 200e-12).unwrap();
    assert_eq!(m.exact, m.lit, "{m} ({report:?})");
    assert_eq!(m.false_detections, 0, "{m}");
    assert!(m.relative_error < 1e-4, "{m}");
    assert!(report.forward_applies > 0 && report.adjoint_applies > 0);
}

#[test]
fn recovers_random_opaque_scenes_and_never_puts_two_depths_in_a_pixel() {
    for seed in 0..3 {
        let g = Geometry::new(12, 12, 16).unwrap();
        let op = lidar_problem(g, 3000, false, 10 + seed);
        let truth = random_opaque_scene::<f64>(g, 0.4, seed).unwrap();
        let mut y = vec![0.0; op.nrows()];
        op.apply(truth.as_slice(), &mut y);
        // A warm start with two depths in every pixel is pruned to the model first.
        let mut x = vec![0.0; g.voxels()];
        for (i, v) in x.iter_mut().enumerate() {
            if i % g.ks < 2 {
                *v = 0.1;
            }
        }
        let mut observed_model = true;
        let mut obs = |info: &rdlidar::solver::IterationInfo<'_, f64>| {
            observed_model &= one_per_pixel(info.x, g.ks);
            rdlidar::solver::Control::Continue
        };
        model_based(&op, &y, &mut x, &ModelBasedParams::default(), &mut obs).unwrap();
        assert!(observed_model, "an iterate held two depths in a pixel");
        assert!(one_per_pixel(&x, g.ks));
        let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
        assert_eq!(m.exact, m.lit, "seed {seed}: {m}");
        assert_eq!(m.false_detections, 0, "seed {seed}: {m}");
    }
}

#[test]
fn works_on_any_operator_through_pixel_columns() {
    // A Gaussian matrix with 30 pixels of 5 columns; 8 pixels hold one positive entry each.
    let (rows, pixels, ks) = (80, 30, 5);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let a = Array2::from_shape_simple_fn((rows, pixels * ks), || {
        let v: f64 = StandardNormal.sample(&mut rng);
        v / (rows as f64).sqrt()
    });
    let mut truth = vec![0.0; pixels * ks];
    for p in (0..pixels).step_by(4) {
        truth[p * ks + (p * 7) % ks] = 1.0 + (p as f64) / 10.0;
    }
    let op = PixelColumns::new(DenseMatrix::new(a).unwrap(), ks).unwrap();
    let mut y = vec![0.0; rows];
    op.apply(&truth, &mut y);
    let mut x = vec![0.0; pixels * ks];
    let report = model_based(&op, &y, &mut x, &ModelBasedParams::default(), &mut ()).unwrap();
    assert!(matches!(
        report.termination,
        Termination::Converged | Termination::Residual
    ));
    for (i, (a, b)) in x.iter().zip(&truth).enumerate() {
        assert!((a - b).abs() < 1e-6, "entry {i}: {a} vs {b}");
    }
}

#[test]
fn self_correlations_and_column_norms_match_their_definitions() {
    let g = Geometry::new(3, 3, 8).unwrap();
    for ternary in [false, true] {
        let op = lidar_problem(g, 50, ternary, 7);
        let voxels = vec![3, 17, 40, 71];
        let own = op.self_correlations(&voxels);
        let norms = op.column_norms(&voxels);
        for (i, &v) in voxels.iter().enumerate() {
            let mut e = vec![0.0; g.voxels()];
            e[v] = 1.0;
            let mut a = vec![0.0; op.nrows()];
            op.apply(&e, &mut a);
            let norm = a.iter().map(|t| t * t).sum::<f64>().sqrt();
            assert!((norms[i] - norm).abs() <= 1e-12 * norm.max(1.0));
            let mut u = vec![0.0; g.voxels()];
            op.apply_adjoint_debiased(&a, &mut u);
            let p0 = v / g.ks * g.ks;
            for j in 0..g.ks {
                assert!(
                    (u[p0 + j] - own[i * g.ks + j]).abs() <= 1e-10,
                    "ternary {ternary}, voxel {v}, depth {j}"
                );
            }
        }
        // The restriction is the operator on the chosen columns.
        let r = op.restrict_columns(voxels.clone()).unwrap();
        let b = [0.5, -1.0, 2.0, 0.25];
        let mut x = vec![0.0; g.voxels()];
        for (&v, &c) in voxels.iter().zip(&b) {
            x[v] = c;
        }
        let (mut y1, mut y2) = (vec![0.0; op.nrows()], vec![0.0; op.nrows()]);
        r.apply(&b, &mut y1);
        op.apply(&x, &mut y2);
        for (a, c) in y1.iter().zip(&y2) {
            assert!((a - c).abs() <= 1e-12);
        }
    }
}

#[test]
fn degenerate_inputs_give_finite_results() {
    let g = Geometry::new(4, 4, 6).unwrap();
    let op = lidar_problem(g, 200, false, 1);
    let params = ModelBasedParams::default();
    // All-zero measurements (an empty scene): x = 0 at once.
    let y = vec![0.0; op.nrows()];
    let mut x = vec![1.0; g.voxels()];
    let r = model_based(&op, &y, &mut x, &params, &mut ()).unwrap();
    assert_eq!(r.termination, Termination::ZeroResidual);
    assert!(x.iter().all(|v| *v == 0.0));
    // A zero operator with nonzero measurements: nothing can be explained, x stays finite.
    let zero = PixelColumns::new(Zero::<f64>::new(10, 12), 3).unwrap();
    let y = vec![1.0; 10];
    let mut x = vec![0.0; 12];
    let r = model_based(&zero, &y, &mut x, &params, &mut ()).unwrap();
    assert!(x.iter().all(|v| v.is_finite() && *v == 0.0), "{r:?}");
    // Pure noise: the detection and amplitude tests keep the support small.
    let noise: Vec<f64> = rdlidar_noise(op.nrows(), 9);
    let mut x = vec![0.0; g.voxels()];
    model_based(&op, &noise, &mut x, &params, &mut ()).unwrap();
    assert!(x.iter().all(|v| v.is_finite()));
}

fn rdlidar_noise(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| StandardNormal.sample(&mut rng)).collect()
}

#[test]
fn invalid_parameters_and_shapes_are_typed_errors() {
    let g = Geometry::new(4, 4, 6).unwrap();
    let op = lidar_problem(g, 100, false, 2);
    let y = vec![1.0; op.nrows()];
    let mut x = vec![0.0; g.voxels()];
    let bad = [
        ModelBasedParams {
            detection_z: -1.0,
            ..ModelBasedParams::default()
        },
        ModelBasedParams {
            amplitude_z: f64::NAN,
            ..ModelBasedParams::default()
        },
        ModelBasedParams {
            max_support_fraction: 0.0,
            ..ModelBasedParams::default()
        },
        ModelBasedParams {
            surface_z: -0.5,
            ..ModelBasedParams::default()
        },
        ModelBasedParams {
            surface_neighbours: 9,
            ..ModelBasedParams::default()
        },
        ModelBasedParams {
            join_neighbours: 0,
            ..ModelBasedParams::default()
        },
        ModelBasedParams {
            isolated_z: f64::INFINITY,
            ..ModelBasedParams::default()
        },
        ModelBasedParams {
            stopping: Stopping {
                max_iter: 0,
                ..Stopping::default()
            },
            ..ModelBasedParams::default()
        },
    ];
    for p in bad {
        assert!(matches!(
            model_based(&op, &y, &mut x, &p, &mut ()),
            Err(Error::InvalidParameter { .. })
        ));
    }
    let p = ModelBasedParams::default();
    assert!(matches!(
        model_based(&op, &y[1..], &mut x, &p, &mut ()),
        Err(Error::ShapeMismatch { .. })
    ));
    let mut short = vec![0.0; 5];
    assert!(matches!(
        model_based(&op, &y, &mut short, &p, &mut ()),
        Err(Error::ShapeMismatch { .. })
    ));
    let mut nan = y.clone();
    nan[3] = f64::NAN;
    assert!(matches!(
        model_based(&op, &nan, &mut x, &p, &mut ()),
        Err(Error::NonFinite { .. })
    ));
    assert!(matches!(
        PixelColumns::new(Zero::<f64>::new(4, 10), 3),
        Err(Error::InvalidParameter { .. })
    ));
}

#[test]
fn tv_on_depth_beats_the_plain_model_at_a_short_pulse_in_noise() {
    use rdlidar::lidar::add_gaussian_snr;
    use rdlidar::solver::{tv_depth, TvDepthParams};
    // The paper scene (a slanted plane, a disk and a square) at 20 dB SNR with a pulse too short
    // for the per-pixel model alone.
    let g = Geometry::new(24, 24, 32).unwrap();
    let op = lidar_problem(g, 1000, false, 0);
    let truth = paper_scene::<f64>(g).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    add_gaussian_snr(&mut y, 20.0, 9).unwrap();
    let mut plain = vec![0.0; g.voxels()];
    model_based(&op, &y, &mut plain, &ModelBasedParams::default(), &mut ()).unwrap();
    let mut tv = vec![0.0; g.voxels()];
    let report = tv_depth(
        &op,
        (g.m, g.n),
        &y,
        &mut tv,
        &TvDepthParams::default(),
        &mut (),
    )
    .unwrap();
    assert_eq!(report.solver, "tv-depth");
    assert!(one_per_pixel(&tv, g.ks));
    let mp = compare(&truth, &Scene::from_vec(g, plain).unwrap(), 200e-12).unwrap();
    let mt = compare(&truth, &Scene::from_vec(g, tv).unwrap(), 200e-12).unwrap();
    assert!(
        mt.depth_rmse_bins < 0.5 * mp.depth_rmse_bins,
        "TV {mt}\nplain {mp}"
    );
    assert!(mt.relative_error < mp.relative_error, "TV {mt}\nplain {mp}");
    assert!(
        mt.false_detections <= mp.false_detections,
        "TV {mt}\nplain {mp}"
    );
}

#[test]
fn tv_on_depth_keeps_an_exact_recovery_exact() {
    use rdlidar::solver::{tv_depth, TvDepthParams};
    let g = Geometry::new(24, 24, 32).unwrap();
    let op = lidar_problem(g, 6000, false, 3);
    let truth = paper_scene::<f64>(g).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    let mut x = vec![0.0; g.voxels()];
    tv_depth(
        &op,
        (g.m, g.n),
        &y,
        &mut x,
        &TvDepthParams::default(),
        &mut (),
    )
    .unwrap();
    let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
    assert_eq!(m.exact, m.lit, "{m}");
    assert_eq!(m.false_detections, 0, "{m}");
    // A grid that does not match the operator is a typed error.
    let mut x = vec![0.0; g.voxels()];
    assert!(matches!(
        tv_depth(
            &op,
            (g.m + 1, g.n),
            &y,
            &mut x,
            &TvDepthParams::default(),
            &mut ()
        ),
        Err(Error::ShapeMismatch { .. })
    ));
}

#[test]
fn the_neighbourhood_prior_recovers_most_depths_where_the_per_pixel_prior_stalls() {
    use rdlidar::lidar::add_gaussian_snr;
    use rdlidar::solver::{tv_depth, TvDepthParams};
    // 24×24×32 at K_p = 1000 and 20 dB: about 0.3 lit pixels per measurement.
    let g = Geometry::new(24, 24, 32).unwrap();
    let op = lidar_problem(g, 1000, false, 0);
    let truth = paper_scene::<f64>(g).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    add_gaussian_snr(&mut y, 20.0, 9).unwrap();
    let run = |params: &TvDepthParams| {
        let mut x = vec![0.0; g.voxels()];
        tv_depth(&op, (g.m, g.n), &y, &mut x, params, &mut ()).unwrap();
        assert!(one_per_pixel(&x, g.ks));
        compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap()
    };
    let coupled = run(&TvDepthParams::default());
    let uncoupled = run(&TvDepthParams {
        neighbour_rounds: 0,
        ..TvDepthParams::default()
    });
    assert!(coupled.exact_fraction >= 0.8, "{coupled}");
    assert!(
        coupled.exact_fraction > uncoupled.exact_fraction + 0.2,
        "coupled {coupled}\nuncoupled {uncoupled}"
    );
    assert!(coupled.depth_rmse_bins < 2.0, "{coupled}");
    let d = TvDepthParams::default();
    for bad in [
        TvDepthParams {
            neighbour_floor: 0.0,
            ..d
        },
        TvDepthParams {
            neighbour_gate: 1.0,
            ..d
        },
        TvDepthParams {
            neighbour_iterations: 0,
            ..d
        },
        TvDepthParams {
            neighbour_change: f64::NAN,
            ..d
        },
        TvDepthParams {
            neighbour_change: -0.1,
            ..d
        },
    ] {
        let mut x = vec![0.0; g.voxels()];
        assert!(matches!(
            tv_depth(&op, (g.m, g.n), &y, &mut x, &bad, &mut ()),
            Err(Error::InvalidParameter { .. })
        ));
    }
}

#[test]
fn the_neighbourhood_prior_is_exact_with_few_measurements_per_return() {
    use rdlidar::solver::{reflector_amp, tv_depth, ReflectorAmpParams, TvDepthParams};
    // 32×32×40 noise-free with K = 2.6 times the number of lit pixels. (On the 100×100 paper
    // scene 1.8 suffices, K_p = 10000; the threshold rises on smaller images: 1.8–2.2 at 64×64,
    // 2.2–2.6 at 32×32.)
    let g = Geometry::new(32, 32, 40).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    let lit = truth.depth_map().depth.iter().filter(|d| **d >= 0).count();
    let kp = (2.6 * lit as f64) as usize - g.ks + 1;
    for seed in [0, 7] {
        let op = lidar_problem(g, kp, false, seed);
        let mut y = vec![0.0; op.nrows()];
        op.apply(truth.as_slice(), &mut y);
        let mut x = vec![0.0; g.voxels()];
        let report = tv_depth(
            &op,
            (g.m, g.n),
            &y,
            &mut x,
            &TvDepthParams::default(),
            &mut (),
        )
        .unwrap();
        assert!(one_per_pixel(&x, g.ks));
        let coupled = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
        assert!(coupled.exact_fraction >= 0.99, "{coupled} ({report:?})");
        assert!(coupled.false_detections <= g.pixels() / 200, "{coupled}");
        let mut x = vec![0.0; g.voxels()];
        reflector_amp(&op, &y, &mut x, &ReflectorAmpParams::default(), &mut ()).unwrap();
        let alone = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
        assert!(alone.exact_fraction < 0.6, "message passing alone: {alone}");
    }
}

#[test]
fn an_ill_conditioned_support_is_fitted_to_the_end() {
    // Every pixel lit at one depth, three measurements per pixel: least squares on that support
    // gains a factor of about 0.8–0.9 per CGLS iteration, so one refit (10 iterations) leaves the
    // residual far above the tolerance when the support is already right. The fit must go on
    // until the data are explained (it stopped on the unchanged support, and TV's rounds and
    // `auto`'s model-based stage then ran for nothing: a 100×100 tile took 60 s instead of 9).
    use rdlidar::solver::{tv_depth, TvDepthParams};
    let g = Geometry::new(32, 32, 16).unwrap();
    let op = lidar_problem(g, 3057, false, 1);
    let mut plane = ndarray::Array3::zeros((g.m, g.n, g.ks));
    plane.slice_mut(ndarray::s![.., .., 5]).fill(0.9);
    let truth = Scene::new(plane).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    let mut x = vec![0.0; g.voxels()];
    let params = TvDepthParams::default();
    let report = tv_depth(&op, (g.m, g.n), &y, &mut x, &params, &mut ()).unwrap();
    let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
    assert_eq!(m.exact, m.lit, "{m}");
    assert_eq!(m.false_detections, 0, "{m}");
    assert_eq!(
        report.termination,
        Termination::Residual,
        "{} iterations, residual {:?}",
        report.iterations,
        report.residual_history.last()
    );
}

/// The paper scene's amplitudes each scaled by a factor in [1 − spread, 1 + spread]: a warm
/// start on the true support.
fn perturbed(truth: &Scene<f64>, spread: f64, seed: u64) -> Vec<f64> {
    use rand::RngExt;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    truth
        .as_slice()
        .iter()
        .map(|&v| v * (1.0 + rng.random_range(-spread..=spread)))
        .collect()
}

#[test]
fn a_warm_start_on_the_right_support_is_fitted_to_the_tolerance_without_a_correlation() {
    // Least squares on the true support converges fast; at 2.3 measurements per lit pixel ten
    // CGLS iterations from amplitudes half wrong leave far more than the tolerance, and the fit
    // goes on while it falls fast, so that the run ends before its first iteration: no
    // correlation (an adjoint application of the whole operator) is needed.
    let g = Geometry::new(24, 24, 32).unwrap();
    let op = lidar_problem(g, 700, false, 3);
    let truth = paper_scene::<f64>(g).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    let mut x = perturbed(&truth, 0.5, 7);
    let report = model_based(&op, &y, &mut x, &ModelBasedParams::default(), &mut ()).unwrap();
    assert_eq!(report.termination, Termination::Residual, "{report:?}");
    assert_eq!(report.iterations, 0, "{report:?}");
    assert_eq!(report.adjoint_applies, 0, "{report:?}");
    let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
    assert_eq!(m.exact, m.lit, "{m}");
    assert_eq!(m.false_detections, 0, "{m}");
    assert!(m.relative_error < 1e-5, "{m}");
}

#[test]
fn a_warm_start_that_nearly_explains_the_data_is_not_explored() {
    // Three CGLS iterations from amplitudes 5% off leave the residual between the tolerance
    // and 10⁻³ of ‖y‖: the support is found, and the first iteration must not put every pixel
    // with a positive correlation in it (the exploration); with a tolerance far below the
    // residual the run goes on, and no pixel joins.
    let g = Geometry::new(24, 24, 32).unwrap();
    let op = lidar_problem(g, 6000, false, 3);
    let truth = paper_scene::<f64>(g).unwrap();
    let lit = truth
        .as_slice()
        .chunks(g.ks)
        .filter(|c| c.iter().any(|v| *v != 0.0))
        .count();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    for tolerance in [1e-6, 1e-12] {
        let mut x = perturbed(&truth, 0.05, 8);
        let mut params = ModelBasedParams::default();
        params.inner.stopping.max_iter = 3;
        params.stopping.rel_residual = Some(tolerance);
        let mut widest = 0;
        let mut watch = |info: &rdlidar::solver::IterationInfo<'_, f64>| {
            let held = info
                .x
                .chunks(g.ks)
                .filter(|c| c.iter().any(|v| *v != 0.0))
                .count();
            widest = widest.max(held);
            rdlidar::solver::Control::Continue
        };
        let report = model_based(&op, &y, &mut x, &params, &mut watch).unwrap();
        assert!(report.iterations >= 1, "{report:?}");
        assert!(
            widest <= lit,
            "tolerance {tolerance}: {widest} pixels held for {lit} lit ({report:?})"
        );
        let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
        assert_eq!(m.exact, m.lit, "{m}");
        assert_eq!(m.false_detections, 0, "{m}");
    }
}
