//! The false-detection test at a rate the user chooses: its bar, its refusals, that it leaves
//! exact noise-free estimates alone, and that it holds the rate where the residual is noise
//! (Gaussian noise, and the uniform error of a 4-bit ADC).

use rdlidar::lidar::{
    add_gaussian_snr, paper_scene, quantize, random_opaque_scene, FullScale, Geometry, Scene,
};
use rdlidar::recon::{
    check_false_rate, compare, normal_upper_quantile, reconstruct, Method, Metrics,
    ReconstructOptions,
};

use crate::reconstruct::{measure, problem};

#[test]
fn the_bar_is_the_normal_upper_quantile() {
    // Reference values of Φ⁻¹(1 − p).
    for (p, z) in [
        (0.5, 0.0),
        (0.1, 1.2815515655446004),
        (0.025, 1.959963984540054),
        (0.01, 2.3263478740408408),
        (1e-3, 3.090232306167813),
        (1e-6, 4.753424308822899),
        (1e-9, 5.997807015007686),
        (0.975, -1.959963984540054),
    ] {
        let got = normal_upper_quantile(p);
        assert!((got - z).abs() < 1e-9, "p = {p}: {got} against {z}");
    }
    assert_eq!(normal_upper_quantile(0.0), f64::INFINITY);
    assert_eq!(normal_upper_quantile(1.0), f64::NEG_INFINITY);
    assert!(normal_upper_quantile(f64::NAN).is_nan());
    // Far in the tail it stays finite and increasing.
    let (a, b) = (normal_upper_quantile(1e-100), normal_upper_quantile(1e-200));
    assert!(
        a.is_finite() && b.is_finite() && 21.0 < a && a < b,
        "{a} {b}"
    );
}

#[test]
fn a_rate_outside_zero_to_one_is_refused_before_solving() {
    for alpha in [0.0, 1.0, -0.1, 1.5, f64::NAN, f64::INFINITY] {
        let e = check_false_rate(alpha).unwrap_err().to_string();
        assert!(e.contains("false_rate:"), "{alpha}: {e}");
        let g = Geometry::new(4, 4, 4).unwrap();
        let op = problem::<f64>(g, 30, 1);
        let y = vec![1.0; g.samples(30)];
        let options = ReconstructOptions {
            false_rate: Some(alpha),
            ..ReconstructOptions::default()
        };
        let e = reconstruct(&op, &y, Method::Cgls, &options).unwrap_err();
        assert!(e.to_string().contains("false_rate:"), "{alpha}: {e}");
    }
}

#[test]
fn noise_free_exact_estimates_are_left_alone() {
    // The paper scene at 16x16x16 in the compressive regime, where auto is exact.
    let g = Geometry::new(16, 16, 16).unwrap();
    let op = problem::<f64>(g, 1200, 5);
    let truth = paper_scene::<f64>(g).unwrap();
    let y = measure(&op, &truth);
    let options = ReconstructOptions {
        false_rate: Some(0.01),
        ..ReconstructOptions::default()
    };
    let r = reconstruct(&op, &y, Method::Auto, &options).unwrap();
    let test = r.detection.clone().expect("the test ran");
    assert_eq!((test.dropped, test.skipped), (0, None), "{test:?}");
    assert_eq!(
        test.tested,
        truth.as_slice().iter().filter(|v| **v != 0.0).count()
    );
    let m = compare(&truth, &r.scene, 200e-12).unwrap();
    assert!(m.exact_fraction == 1.0 && m.relative_error < 1e-6, "{m:#?}");
    assert!(
        test.describe().contains("dropped 0 of"),
        "{}",
        test.describe()
    );
    // Without the option, no test.
    let plain = reconstruct(&op, &y, Method::Auto, &ReconstructOptions::default()).unwrap();
    assert!(plain.detection.is_none());
}

#[test]
fn a_support_too_large_for_least_squares_is_not_tested() {
    // The backprojection keeps a peak in most pixels: more voxels than K/2.
    let g = Geometry::new(16, 16, 8).unwrap();
    let op = problem::<f64>(g, 60, 7);
    let y = measure(&op, &paper_scene::<f64>(g).unwrap());
    let options = ReconstructOptions {
        false_rate: Some(0.01),
        ..ReconstructOptions::default()
    };
    let r = reconstruct(&op, &y, Method::Backprojection, &options).unwrap();
    let test = r.detection.expect("the test ran");
    assert!(2 * test.tested > y.len(), "{test:?}");
    assert_eq!(test.dropped, 0);
    assert!(test.describe().contains("not run"), "{}", test.describe());
}

/// auto on a random half-lit 32×32×16 scene (seed `seed`) at 8 measurements per lit pixel, the
/// noise added by `noisy`, with and without the test at α = 0.01.
fn half_lit(seed: u64, noisy: &dyn Fn(&mut [f64], u64)) -> (Metrics, Metrics) {
    let g = Geometry::new(32, 32, 16).unwrap();
    let truth: Scene<f64> = random_opaque_scene(g, 0.5, seed).unwrap();
    let op = problem::<f64>(g, 4085, seed);
    let mut y = measure(&op, &truth);
    noisy(&mut y, seed);
    let judge = |false_rate| {
        let options = ReconstructOptions {
            false_rate,
            ..ReconstructOptions::default()
        };
        let r = reconstruct(&op, &y, Method::Auto, &options).unwrap();
        if false_rate.is_some() {
            // The test ran on the estimate (a support small enough for least squares).
            let test = r.detection.as_ref().expect("the test's report");
            assert!(!test.describe().contains("not run"), "{}", test.describe());
        }
        compare(&truth, &r.scene, 200e-12).unwrap()
    };
    (judge(Some(0.01)), judge(None))
}

/// Over seeds 1–3: the test's mean false share is at most α and at most that without it, and
/// it keeps at least 99% of the depths exact.
fn check_rate_held(noisy: &dyn Fn(&mut [f64], u64)) {
    let runs: Vec<(Metrics, Metrics)> = [1, 2, 3].into_iter().map(|s| half_lit(s, noisy)).collect();
    let mean = |f: &dyn Fn(&(Metrics, Metrics)) -> f64| runs.iter().map(f).sum::<f64>() / 3.0;
    let false_with = mean(&|r| r.0.false_fraction_empty);
    let false_without = mean(&|r| r.1.false_fraction_empty);
    let exact_with = mean(&|r| r.0.exact_fraction);
    let show = format!("{runs:#?}");
    assert!(false_with <= 0.01 && false_with <= false_without, "{show}");
    assert!(exact_with >= 0.99, "{show}");
}

#[test]
fn where_the_residual_is_noise_the_rate_is_held() {
    check_rate_held(&|y, seed| {
        add_gaussian_snr(y, 20.0, seed + 2).unwrap();
    });
}

/// A 4-bit ADC with its full scale at the largest sample: an error uniform within a step
/// (about 16 dB here), which least squares on many samples turns into Gaussian amplitude errors.
#[test]
fn under_a_4_bit_adc_the_rate_is_held() {
    check_rate_held(&|y, _| {
        quantize(y, 4, FullScale::Auto).unwrap();
    });
}
