//! Reconstruction metrics on hand-built scenes and depth maps with known answers.

use ndarray::{Array2, Array3};
use rdlidar::lidar::{depth_bin_m, DepthMap, Scene, NO_RETURN, SPEED_OF_LIGHT};
use rdlidar::recon::{compare, compare_depth, relative_error, Metrics};
use rdlidar::Error;

use crate::common::random_vec;

const TAU: f64 = 200e-12;

/// A 4×5 map with 12 lit pixels at depths 0..8 and amplitudes 1..2.
fn truth_map() -> DepthMap<f64> {
    let depth = Array2::from_shape_fn((4, 5), |(i, j)| {
        if j == 0 || j == 2 || (i + j) % 5 == 0 || (j == 3 && i > 0) {
            ((i * 5 + j) % 8) as i32
        } else {
            NO_RETURN
        }
    });
    let amplitude = Array2::from_shape_fn((4, 5), |(i, j)| {
        if depth[[i, j]] == NO_RETURN {
            0.0
        } else {
            1.0 + (i * 5 + j) as f64 / 20.0
        }
    });
    DepthMap { depth, amplitude }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * (1.0 + b.abs())
}

/// Equal metrics, up to rounding in the relative error (summed in a different order).
fn assert_same(a: &Metrics, b: &Metrics) {
    assert!(close(a.relative_error, b.relative_error), "{a:?} vs {b:?}");
    let strip = |m: &Metrics| Metrics {
        relative_error: 0.0,
        ..*m
    };
    assert_eq!(strip(a), strip(b));
}

#[test]
fn perfect_reconstruction_scores_perfectly() {
    let truth = truth_map();
    let scene = truth.to_scene(8).unwrap();
    assert_eq!(truth.lit(), 12);
    for m in [
        compare(&scene, &scene, TAU).unwrap(),
        compare_depth(&truth, &truth, TAU).unwrap(),
    ] {
        assert_eq!(m.pixels, 20);
        assert_eq!((m.lit, m.empty), (12, 8));
        assert_eq!((m.exact, m.detected), (12, 12));
        assert_eq!(m.exact_fraction, 1.0);
        assert_eq!((m.depth_rmse_bins, m.depth_rmse_m), (0.0, 0.0));
        assert_eq!((m.missed, m.false_detections), (0, 0));
        assert_eq!(m.missed_fraction, 0.0);
        assert_eq!((m.false_fraction_all, m.false_fraction_empty), (0.0, 0.0));
        assert_eq!(m.relative_error, 0.0);
    }
}

#[test]
fn one_pixel_two_bins_off() {
    let truth = truth_map();
    let mut est = truth.clone();
    // Pixel (1, 2) sits at depth 7 - move it 2 bins nearer.
    assert_eq!(truth.depth[[1, 2]], 7);
    est.depth[[1, 2]] = 5;
    let m = compare_depth(&truth, &est, TAU).unwrap();
    assert_eq!(
        (m.exact, m.detected, m.missed, m.false_detections),
        (11, 12, 0, 0)
    );
    assert!(close(m.exact_fraction, 11.0 / 12.0));
    // Two bins off is not within one bin either.
    assert_eq!(m.within_one, 11);
    assert!(close(m.within_one_fraction, 11.0 / 12.0));
    // RMSE = √(2² / 12).
    let rmse = (4.0f64 / 12.0).sqrt();
    assert!(close(m.depth_rmse_bins, rmse));
    assert!(close(m.depth_rmse_m, rmse * TAU * SPEED_OF_LIGHT / 2.0));
    // The moved voxel counts twice: ‖X − X̂‖² = 2a² with a the pixel's amplitude.
    let a = truth.amplitude[[1, 2]];
    let norm_sq: f64 = truth.amplitude.iter().map(|v| v * v).sum();
    assert!(close(m.relative_error, (2.0 * a * a / norm_sq).sqrt()));

    // The same through scenes.
    let ms = compare(&truth.to_scene(8).unwrap(), &est.to_scene(8).unwrap(), TAU).unwrap();
    assert_same(&ms, &m);
}

#[test]
fn one_bin_off_is_within_one_bin_but_not_exact() {
    let truth = truth_map();
    let mut est = truth.clone();
    est.depth[[1, 2]] -= 1;
    let m = compare_depth(&truth, &est, TAU).unwrap();
    assert_eq!((m.exact, m.within_one), (11, 12));
    assert_eq!(m.within_one_fraction, 1.0);
    assert!(m.to_string().contains("(100.0% within one bin)"), "{m}");
    // A missed pixel is not within one bin.
    est.depth[[1, 2]] = NO_RETURN;
    let m = compare_depth(&truth, &est, TAU).unwrap();
    assert_eq!((m.exact, m.within_one, m.missed), (11, 11, 1));
}

#[test]
fn a_missed_pixel_and_a_false_pixel() {
    let truth = truth_map();
    let mut est = truth.clone();
    // Miss (0, 0), invent a return at the empty pixel (0, 1).
    assert_ne!(truth.depth[[0, 0]], NO_RETURN);
    assert_eq!(truth.depth[[0, 1]], NO_RETURN);
    est.depth[[0, 0]] = NO_RETURN;
    est.amplitude[[0, 0]] = 0.0;
    est.depth[[0, 1]] = 3;
    est.amplitude[[0, 1]] = 0.5;
    let m = compare_depth(&truth, &est, TAU).unwrap();
    assert_eq!((m.lit, m.detected, m.exact), (12, 11, 11));
    assert!(close(m.exact_fraction, 11.0 / 12.0));
    assert_eq!(m.depth_rmse_bins, 0.0);
    assert_eq!(m.missed, 1);
    assert!(close(m.missed_fraction, 1.0 / 12.0));
    assert_eq!(m.false_detections, 1);
    assert!(close(m.false_fraction_all, 1.0 / 20.0));
    assert!(close(m.false_fraction_empty, 1.0 / 8.0));
    let a = truth.amplitude[[0, 0]];
    let norm_sq: f64 = truth.amplitude.iter().map(|v| v * v).sum();
    assert!(close(m.relative_error, ((a * a + 0.25) / norm_sq).sqrt()));

    let ms = compare(&truth.to_scene(8).unwrap(), &est.to_scene(8).unwrap(), TAU).unwrap();
    assert_same(&ms, &m);
}

#[test]
fn scene_depths_are_the_strongest_return() {
    // A truth with one voxel; an estimate spread over the column with its peak 2 bins off.
    let mut x = Array3::zeros((1, 2, 6));
    x[[0, 0, 1]] = 2.0;
    let mut xe = Array3::zeros((1, 2, 6));
    xe[[0, 0, 1]] = 0.5;
    xe[[0, 0, 3]] = -1.5;
    xe[[0, 1, 4]] = 1e-3;
    let truth = Scene::new(x).unwrap();
    let est = Scene::new(xe).unwrap();
    let m = compare(&truth, &est, TAU).unwrap();
    assert_eq!((m.lit, m.detected, m.exact), (1, 1, 0));
    assert_eq!(m.depth_rmse_bins, 2.0);
    assert_eq!(m.false_detections, 1);
    assert_eq!(m.false_fraction_empty, 1.0);
    let expect = ((1.5f64 * 1.5 + 1.5 * 1.5 + 1e-6) / 4.0).sqrt();
    assert!(close(m.relative_error, expect));
    assert!(close(relative_error(&truth, &est).unwrap(), expect));
}

#[test]
fn relative_error_matches_its_definition() {
    let g = (3, 4, 5);
    let a = random_vec(60, 1);
    let b = random_vec(60, 2);
    let x = Scene::new(Array3::from_shape_vec(g, a.clone()).unwrap()).unwrap();
    let xe = Scene::new(Array3::from_shape_vec(g, b.clone()).unwrap()).unwrap();
    let num: f64 = a.iter().zip(&b).map(|(u, v)| (u - v) * (u - v)).sum();
    let den: f64 = a.iter().map(|u| u * u).sum();
    assert!(close(relative_error(&x, &xe).unwrap(), (num / den).sqrt()));

    // f32 scenes accumulate in f64 too.
    let x32 = Scene::new(x.data().mapv(|v| v as f32)).unwrap();
    let xe32 = Scene::new(xe.data().mapv(|v| v as f32)).unwrap();
    assert!((relative_error(&x32, &xe32).unwrap() - (num / den).sqrt()).abs() < 1e-6);
}

#[test]
fn all_zero_truth_uses_the_estimate_norm() {
    let zero = Scene::new(Array3::<f64>::zeros((2, 2, 3))).unwrap();
    let m = compare(&zero, &zero, TAU).unwrap();
    assert_eq!(
        (m.lit, m.empty, m.exact_fraction, m.relative_error),
        (0, 4, 1.0, 0.0)
    );
    assert_eq!(m.missed_fraction, 0.0);

    let mut xe = Array3::zeros((2, 2, 3));
    xe[[1, 1, 2]] = 3.0;
    xe[[0, 1, 0]] = 4.0;
    let m = compare(&zero, &Scene::new(xe).unwrap(), TAU).unwrap();
    assert_eq!(m.relative_error, 5.0);
    assert_eq!((m.false_detections, m.detected), (2, 0));
    assert_eq!(m.false_fraction_all, 0.5);
    assert_eq!(m.depth_rmse_bins, 0.0);
    assert!(m.exact_fraction.is_finite() && m.depth_rmse_m.is_finite());
}

#[test]
fn two_hundred_picoseconds_give_three_centimetres_per_bin() {
    let bin = depth_bin_m(200e-12).unwrap();
    assert!((bin - 0.03).abs() < 1e-4, "{bin}");
    assert!(close(bin, 0.029_979_245_8));
    let truth = truth_map();
    let mut est = truth.clone();
    for d in est.depth.iter_mut().filter(|d| **d != NO_RETURN) {
        *d += 1;
    }
    let m: Metrics = compare_depth(&truth, &est, 200e-12).unwrap();
    assert_eq!(m.depth_rmse_bins, 1.0);
    assert!(close(m.depth_rmse_m, bin));
    assert!(close(m.bin_m, bin));
    assert!(!m.to_string().is_empty());
}

#[test]
fn mismatches_and_bad_parameters_are_typed_errors() {
    let a = Scene::new(Array3::<f64>::zeros((2, 3, 4))).unwrap();
    for (dims, expected, found) in [((2, 3, 5), 4, 5), ((3, 2, 4), 2, 3), ((2, 4, 4), 3, 4)] {
        let b = Scene::new(Array3::<f64>::zeros(dims)).unwrap();
        for r in [
            compare(&a, &b, TAU).map(|_| ()),
            relative_error(&a, &b).map(|_| ()),
        ] {
            match r {
                Err(Error::ShapeMismatch {
                    expected: e,
                    found: f,
                    ..
                }) => assert_eq!((e, f), (expected, found)),
                other => panic!("expected a shape mismatch, got {other:?}"),
            }
        }
    }

    let truth = truth_map();
    let small = DepthMap {
        depth: Array2::from_elem((4, 4), NO_RETURN),
        amplitude: Array2::<f64>::zeros((4, 4)),
    };
    assert!(matches!(
        compare_depth(&truth, &small, TAU),
        Err(Error::ShapeMismatch { .. })
    ));
    let ragged = DepthMap {
        depth: Array2::from_elem((4, 5), NO_RETURN),
        amplitude: Array2::<f64>::zeros((5, 4)),
    };
    assert!(matches!(
        compare_depth(&truth, &ragged, TAU),
        Err(Error::ShapeMismatch { .. })
    ));

    for tau in [0.0, -1e-12, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            compare(&a, &a, tau),
            Err(Error::InvalidParameter { name: "tau_s", .. })
        ));
        assert!(matches!(
            compare_depth(&truth, &truth, tau),
            Err(Error::InvalidParameter { name: "tau_s", .. })
        ));
        assert!(matches!(
            depth_bin_m(tau),
            Err(Error::InvalidParameter { name: "tau_s", .. })
        ));
    }

    let mut below = truth.clone();
    below.depth[[0, 0]] = -2;
    assert!(matches!(
        compare_depth(&truth, &below, TAU),
        Err(Error::InvalidParameter { name: "depth", .. })
    ));
    let mut nan = truth.clone();
    nan.amplitude[[1, 1]] = f64::NAN;
    assert!(matches!(
        compare_depth(&nan, &truth, TAU),
        Err(Error::NonFinite { .. })
    ));
}
