//! The one iteration protocol and its counts: every iterative solver, the pixelwise ones and the
//! support pursuit included, reports what a counter around its operator counts (forward,
//! adjoint and support applications apart), shows every iteration to its observer and can be
//! stopped by it; the counting wrapper has every capability of the operator it wraps.

use std::sync::Arc;

use rdlidar::lidar::{paper_scene, Codes, Geometry, LidarOperator, Pulse, RdOperator};
use rdlidar::operator::{Counted, DenseMatrix, LinearOperator, PixelColumns, VoxelOperator};
use rdlidar::recon::{reconstruct, Method, ReconstructOptions};
use rdlidar::solver::{
    model_based, reflector_amp, tv_depth, Control, IterationInfo, ModelBasedParams,
    ReflectorAmpParams, Report, Termination, TvDepthParams,
};

fn lidar_problem(g: Geometry, kp: usize, seed: u64) -> RdOperator<f64> {
    let pulse = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
    let codes = Codes::random_binary(g.pixels(), g.samples(kp), seed + 1).unwrap();
    RdOperator::new(g, pulse, Arc::new(codes)).unwrap()
}

/// A 16×16×20 paper scene measured at K_p = 600: compressive, so that the solvers iterate.
fn small_problem() -> (Geometry, RdOperator<f64>, Vec<f64>) {
    let g = Geometry::new(16, 16, 20).unwrap();
    let op = lidar_problem(g, 600, 3);
    let truth = paper_scene::<f64>(g).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    (g, op, y)
}

/// Adds seeded uniform noise of `level` times the RMS of `y`.
pub(crate) fn add_noise(y: &mut [f64], level: f64, seed: u64) {
    let rms = (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt();
    let noise = crate::common::random_vec(y.len(), seed);
    for (v, e) in y.iter_mut().zip(noise) {
        *v += level * rms * e;
    }
}

fn counts<A>(c: &Counted<A>) -> (usize, usize, usize) {
    (c.forward_count(), c.adjoint_count(), c.support_count())
}

fn report_counts(r: &Report) -> (usize, usize, usize) {
    (r.forward_applies, r.adjoint_applies, r.support_applies)
}

#[test]
fn the_counter_of_a_structured_operator_counts_each_query_once_and_answers_as_it() {
    let (g, op, y) = small_problem();
    let counted = Counted::new(&op);
    let ks = g.ks;
    // The correlation is an adjoint application, with the operator's own matched filter.
    let (mut u, mut v) = (vec![0.0; op.ncols()], vec![0.0; op.ncols()]);
    counted.correlate(&y, &mut u);
    op.correlate(&y, &mut v);
    assert_eq!(u, v);
    assert_eq!(counts(&counted), (0, 1, 0));
    // Column queries from the pulse and the codes: one support application per call.
    let voxels = [3, ks + 7, 5 * ks];
    assert_eq!(
        counted.self_correlations(&voxels),
        op.self_correlations(&voxels)
    );
    assert_eq!(counted.column_norms(&voxels), op.column_norms(&voxels));
    assert_eq!(counted.pixel_gram(2), op.pixel_gram(2));
    assert!(counted.structured_columns() && counted.uniform_pixel_gram());
    assert_eq!(counts(&counted), (0, 1, 3));
    // The sparse forward is a support application, the zero-mean operator's applications full.
    let mut x = vec![0.0; op.ncols()];
    x[ks + 7] = 1.0;
    let (mut a, mut b) = (vec![0.0; op.nrows()], vec![0.0; op.nrows()]);
    counted.apply_sparse(&x, &mut a);
    op.apply_sparse(&x, &mut b);
    assert_eq!(a, b);
    let zero_mean = counted.zero_mean_operator();
    zero_mean.apply(&x, &mut a);
    zero_mean.apply_adjoint(&y, &mut u);
    assert_eq!(counts(&counted), (1, 2, 4));
    // A restriction of the zero-mean operator is a support operator again.
    zero_mean
        .restrict_columns(vec![ks + 7])
        .unwrap()
        .apply(&[1.0], &mut a);
    assert_eq!(counts(&counted), (1, 2, 5));
    assert_eq!(LidarOperator::geometry(&counted), g);
}

#[test]
fn the_counter_of_a_plain_operator_counts_the_applications_its_queries_make() {
    let a = ndarray::Array2::from_shape_fn((7, 12), |(i, j)| ((3 * i + 5 * j) % 11) as f64 - 4.0);
    let plain = PixelColumns::new(DenseMatrix::new(a).unwrap(), 4).unwrap();
    let counted = Counted::new(&plain);
    assert!(!counted.structured_columns());
    // One forward and one correlation (an adjoint) per voxel.
    assert_eq!(
        counted.self_correlations(&[1, 6]),
        plain.self_correlations(&[1, 6])
    );
    assert_eq!(counts(&counted), (2, 2, 0));
    // One forward per column; one per column of the pixel.
    assert_eq!(
        counted.column_norms(&[0, 5, 11]),
        plain.column_norms(&[0, 5, 11])
    );
    assert_eq!(counted.pixel_gram(1), plain.pixel_gram(1));
    assert_eq!(counts(&counted), (2 + 3 + 4, 2, 0));
}

#[test]
fn pixelwise_solvers_report_what_a_counter_around_the_operator_counts() {
    let (g, op, y) = small_problem();
    let n = op.ncols();
    let amp_params = ReflectorAmpParams::default();
    let counted = Counted::new(&op);
    let r = reflector_amp(&counted, &y, &mut vec![0.0; n], &amp_params, &mut ()).unwrap();
    assert_eq!(report_counts(&r), counts(&counted), "{r:?}");
    // One adjoint and one forward per iteration; the shared Gram block once.
    assert_eq!(report_counts(&r), (r.iterations, r.iterations, 1), "{r:?}");

    let counted = Counted::new(&op);
    let params = ModelBasedParams::default();
    let r = model_based(&counted, &y, &mut vec![0.0; n], &params, &mut ()).unwrap();
    assert_eq!(report_counts(&r), counts(&counted), "{r:?}");
    assert!(r.support_applies > r.iterations, "{r:?}");

    let counted = Counted::new(&op);
    let grid = (g.m, g.n);
    let params = TvDepthParams::default();
    let r = tv_depth(&counted, grid, &y, &mut vec![0.0; n], &params, &mut ()).unwrap();
    assert_eq!(report_counts(&r), counts(&counted), "{r:?}");
    assert_eq!(r.solver, "tv-depth");
}

#[test]
fn reconstruction_reports_count_every_application_of_the_method() {
    let (_, op, y) = small_problem();
    let options = ReconstructOptions::default();
    for method in [
        Method::SupportLs,
        Method::ModelBased,
        Method::Iht,
        Method::Fista,
    ] {
        let counted = Counted::new(&op);
        let rec = reconstruct(&counted, &y, method, &options).unwrap();
        let r = rec.report.unwrap();
        // Every application the method made, its preparation and refits included; the
        // reconstruction measures nothing more through the operator.
        assert_eq!(report_counts(&r), counts(&counted), "{method}: {r:?}");
        assert_eq!(r.residual_history.len(), r.iterations, "{method}: {r:?}");
    }
}

#[test]
fn observers_see_and_stop_the_pixelwise_solvers() {
    let (_, op, mut y) = small_problem();
    // Noise, so that no fit explains the data before its first iteration (a warm start that
    // does ends the model-based run there).
    add_noise(&mut y, 0.01, 5);
    let n = op.ncols();
    for solver in ["reflector-amp", "model-based"] {
        let mut seen = Vec::new();
        let mut observer = |info: &IterationInfo<'_, f64>| {
            assert!(info.x.iter().all(|v| v.is_finite()));
            seen.push((info.iteration, info.residual));
            Control::Continue
        };
        let mut x = vec![0.0; n];
        let r = match solver {
            "reflector-amp" => {
                reflector_amp(&op, &y, &mut x, &Default::default(), &mut observer).unwrap()
            }
            _ => model_based(&op, &y, &mut x, &Default::default(), &mut observer).unwrap(),
        };
        assert_eq!(r.solver, solver);
        assert!(r.iterations >= 1, "{r:?}");
        let iterations: Vec<usize> = seen.iter().map(|s| s.0).collect();
        assert_eq!(iterations, (1..=r.iterations).collect::<Vec<_>>());
        let residuals: Vec<f64> = seen.iter().map(|s| s.1).collect();
        assert_eq!(residuals, r.residual_history);

        // Stopped after its first iteration, it still finishes: a finite scene, one return per
        // pixel at most.
        let mut stop = |_: &IterationInfo<'_, f64>| Control::Stop;
        let mut x = vec![0.0; n];
        let r = match solver {
            "reflector-amp" => {
                reflector_amp(&op, &y, &mut x, &Default::default(), &mut stop).unwrap()
            }
            _ => model_based(&op, &y, &mut x, &Default::default(), &mut stop).unwrap(),
        };
        assert_eq!((r.iterations, r.termination), (1, Termination::Observer));
        assert!(x.iter().all(|v| v.is_finite()));
        assert!(x
            .chunks(20)
            .all(|c| c.iter().filter(|v| **v != 0.0).count() <= 1));
    }
}
