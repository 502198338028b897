//! The reconstruction entry point: method names, the automatic choice by regime, exact recovery
//! of small scenes and the one-return-per-pixel output of every method.

use std::sync::Arc;

use ndarray::{array, Array3};
use rdlidar::lidar::{paper_scene, Codes, Geometry, Pulse, RdOperator, Regime, Scene, NO_RETURN};
use rdlidar::recon::{compare, is_piecewise_smooth, reconstruct, Method, ReconstructOptions};
use rdlidar::{Error, LinearOperator, Real};

/// A lidar operator with a Bernoulli pulse from `seed` and binary codes from `seed + 1`.
pub(crate) fn problem<T: Real>(g: Geometry, kp: usize, seed: u64) -> RdOperator<T> {
    let pulse = Pulse::<T>::bernoulli(kp, seed).unwrap().into_inner();
    let codes = Codes::random_binary(g.pixels(), g.samples(kp), seed + 1).unwrap();
    RdOperator::new(g, pulse, Arc::new(codes)).unwrap()
}

/// Noise-free measurements y = A x.
pub(crate) fn measure<T: Real>(op: &RdOperator<T>, x: &Scene<T>) -> Vec<T> {
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(x.as_slice(), &mut y);
    y
}

/// Two isolated returns: no lit pixel has a lit neighbour, so the depth map is not smooth.
fn sparse_scene(g: Geometry) -> Scene<f64> {
    let mut x = Array3::zeros((g.m, g.n, g.ks));
    x[[0, 0, 1]] = 0.8;
    x[[g.m - 1, g.n - 1, g.ks - 2]] = 0.5;
    Scene::new(x).unwrap()
}

#[test]
fn names_round_trip_and_unknown_names_list_the_valid_ones() {
    for m in Method::ALL {
        assert_eq!(m.name().parse::<Method>().unwrap(), m);
        assert_eq!(m.to_string(), m.name());
    }
    assert_eq!("model-based".parse::<Method>().unwrap(), Method::ModelBased);
    let e = "lasso".parse::<Method>().unwrap_err();
    assert!(matches!(e, Error::InvalidParameter { .. }), "{e:?}");
    let text = e.to_string();
    for name in Method::NAMES {
        assert!(text.contains(name), "{text}");
    }
}

#[test]
fn auto_stops_at_the_first_stage_that_explains_the_data_in_every_regime() {
    let g = Geometry::new(3, 3, 4).unwrap();
    let crit = g.critical_pulse_len();
    let truth = sparse_scene(g);
    for (kp, regime) in [
        (4 * crit, Regime::Redundant),
        (2 * crit, Regime::Redundant),
        (crit, Regime::Critical),
    ] {
        let op = problem::<f64>(g, kp, 5);
        let y = measure(&op, &truth);
        let r = reconstruct(&op, &y, Method::Auto, &ReconstructOptions::default()).unwrap();
        assert_eq!(r.regime, regime, "K_p {kp}");
        // The support pursuit explains these few returns: nothing else runs.
        assert_eq!(r.method_used, Method::SupportLs, "K_p {kp}");
        assert_eq!(r.stages.len(), 1, "K_p {kp}: {:?}", r.stages);
        // Every stage before the kept one failed to explain the data; the kept one does.
        let (kept, before) = r.stages.split_last().unwrap();
        assert!(kept.kept && kept.relative_residual <= 1e-6, "{kept}");
        assert_eq!(kept.method, r.method_used);
        assert!(before.iter().all(|s| !s.kept && s.relative_residual > 1e-6));
        let m = compare(&truth, &r.scene, 200e-12).unwrap();
        assert_eq!(m.exact, m.lit, "K_p {kp}: {m}");
        assert!(m.relative_error <= 1e-6, "K_p {kp}: {m}");
    }
}

#[test]
fn model_based_and_auto_recover_a_small_paper_scene_exactly() {
    let g = Geometry::new(8, 8, 8).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    for (kp, method) in [(2000, Method::ModelBased), (300, Method::Auto)] {
        let op = problem::<f64>(g, kp, 11);
        let y = measure(&op, &truth);
        let r = reconstruct(&op, &y, method, &ReconstructOptions::default()).unwrap();
        let m = compare(&truth, &r.scene, 200e-12).unwrap();
        assert_eq!(m.exact, m.lit, "{method} at K_p {kp}: {m}");
        assert_eq!(m.false_detections, 0, "{m}");
        assert!(m.relative_error < 1e-3, "{m}");
        assert_eq!(r.depth, r.scene.depth_map());
    }
}

#[test]
fn every_method_returns_positive_returns_and_the_one_reflector_methods_one_per_pixel() {
    let g = Geometry::new(6, 6, 8).unwrap();
    let truth = paper_scene::<f32>(g).unwrap();
    let op = problem::<f32>(g, 1200, 2);
    let y = measure(&op, &truth);
    let options = ReconstructOptions {
        max_iter: Some(30),
        ..ReconstructOptions::default()
    };
    for method in Method::ALL {
        let r = reconstruct(&op, &y, method, &options).unwrap();
        assert_eq!(r.scene.geometry(), g);
        let one_reflector = [
            Method::Backprojection,
            Method::BackprojectionDebiased,
            Method::Amp,
            Method::ModelBased,
            Method::Tv,
        ]
        .contains(&method);
        let mut lit = 0;
        for col in r.scene.as_slice().chunks(g.ks) {
            let returns = col.iter().filter(|v| **v != 0.0).count();
            assert!(!one_reflector || returns <= 1, "{method}");
            assert!(col.iter().all(|v| *v >= 0.0), "{method}");
            lit += usize::from(returns > 0);
        }
        // The depth map has a return wherever the scene has one: its strongest.
        assert_eq!(r.depth.lit(), lit, "{method}");
        if method != Method::Auto {
            assert_eq!(r.method_used, method);
        }
        if let Some(rep) = &r.report {
            assert!(rep.iterations <= 30 * 5, "{method}: {}", rep.iterations);
        }
    }
}

#[test]
fn piecewise_smooth_needs_most_lit_pixels_next_to_a_similar_depth() {
    let n = NO_RETURN;
    assert!(is_piecewise_smooth(&array![[3, 3, n], [4, 3, n]]));
    assert!(!is_piecewise_smooth(&array![[3, n, 5], [n, 7, n]]));
    assert!(!is_piecewise_smooth(&array![[3, 6, 1], [8, 4, 9]]));
    assert!(!is_piecewise_smooth(&array![[n, n], [n, n]]));
}

#[test]
fn bad_inputs_are_errors() {
    let g = Geometry::new(2, 2, 3).unwrap();
    let op = problem::<f64>(g, 40, 0);
    let y = vec![0.0; op.nrows()];
    let zero_iter = ReconstructOptions {
        max_iter: Some(0),
        ..ReconstructOptions::default()
    };
    assert!(matches!(
        reconstruct(&op, &y, Method::Cgls, &zero_iter),
        Err(Error::InvalidParameter { .. })
    ));
    assert!(matches!(
        reconstruct(&op, &y[1..], Method::Cgls, &ReconstructOptions::default()),
        Err(Error::ShapeMismatch { .. })
    ));
    // All-zero data: every method returns the empty scene.
    for method in Method::ALL {
        let r = reconstruct(&op, &y, method, &ReconstructOptions::default()).unwrap();
        assert_eq!(r.depth.lit(), 0, "{method}");
    }
}

#[test]
fn auto_turns_to_tv_where_the_model_based_fit_does_not_explain_the_data() {
    // The 32×32×40 paper scene with K = 2.6 times the number of lit pixels: compressive, and
    // short enough that the model-based fit stalls.
    let g = Geometry::new(32, 32, 40).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    let lit = truth.depth_map().lit();
    let kp = (2.6 * lit as f64) as usize - g.ks + 1;
    let op = problem::<f64>(g, kp, 4);
    let y = measure(&op, &truth);
    let options = ReconstructOptions::default();
    let mb = reconstruct(&op, &y, Method::ModelBased, &options).unwrap();
    let auto = reconstruct(&op, &y, Method::Auto, &options).unwrap();
    let plain = compare(&truth, &mb.scene, 200e-12).unwrap();
    let chosen = compare(&truth, &auto.scene, 200e-12).unwrap();
    assert!(plain.exact_fraction < 0.9, "model-based alone: {plain}");
    assert_eq!(auto.method_used, Method::Tv, "{chosen}");
    assert!(chosen.exact_fraction >= 0.99, "{chosen}");
    assert!(chosen.false_detections <= g.pixels() / 200, "{chosen}");
}

#[test]
fn an_observer_sees_every_iteration_and_can_stop_the_solver() {
    use rdlidar::recon::reconstruct_observed;
    use rdlidar::solver::{Control, IterationInfo, Termination};
    let g = Geometry::new(6, 5, 8).unwrap();
    let op = problem::<f64>(g, 120, 4);
    let mut y = measure(&op, &paper_scene(g).unwrap());
    // Noise, so that TV's model-based fit does not explain the data before its first iteration.
    crate::iteration::add_noise(&mut y, 0.01, 6);
    let options = ReconstructOptions::default();
    // Every iteration, in order, with the iterate of the scene's size.
    for method in [Method::Fista, Method::Cgls, Method::Tv] {
        let mut seen = Vec::new();
        let mut watch = |info: &IterationInfo<'_, f64>| {
            assert_eq!(info.x.len(), g.voxels());
            seen.push(info.iteration);
            Control::Continue
        };
        let r = reconstruct_observed(&op, &y, method, &options, &mut watch).unwrap();
        let report = r.report.unwrap();
        assert!(!seen.is_empty(), "{method}");
        // TV's report also counts the iterations of its inner one-reflector fits, each of which
        // the observer sees from its first iteration on.
        if method == Method::Tv {
            assert_eq!(seen[0], 1, "{seen:?}");
            assert!(
                seen.windows(2).all(|w| w[1] == w[0] + 1 || w[1] == 1),
                "{seen:?}"
            );
            assert!(seen.len() <= report.iterations, "{method}");
        } else {
            assert_eq!(seen, (1..=seen.len()).collect::<Vec<_>>(), "{method}");
            assert_eq!(seen.len(), report.iterations, "{method}");
        }
    }
    // Stopping after three iterations ends FISTA there.
    let mut stop = |info: &IterationInfo<'_, f64>| {
        if info.iteration >= 3 {
            Control::Stop
        } else {
            Control::Continue
        }
    };
    let options = ReconstructOptions {
        debias: false,
        ..ReconstructOptions::default()
    };
    let r = reconstruct_observed(&op, &y, Method::Fista, &options, &mut stop).unwrap();
    let report = r.report.unwrap();
    assert_eq!(
        (report.iterations, report.termination),
        (3, Termination::Observer)
    );
    // auto's stages are observed through the same observer: never more calls than the
    // iterations it reports (its support pursuit's rounds are counted but not observed).
    let mut calls = 0;
    let mut count = |_: &IterationInfo<'_, f64>| {
        calls += 1;
        Control::Continue
    };
    let r = reconstruct_observed(&op, &y, Method::Auto, &options, &mut count).unwrap();
    let iterations = r.report.map_or(0, |r| r.iterations);
    assert!(
        calls <= iterations,
        "{calls} calls, {iterations} iterations"
    );
}

/// The support pursuit's estimate of the 8×8×8 paper scene in `T` at K_p `kp` (noise-free), as
/// `f64`, and its support applications.
fn support_pursuit_in<T: Real>(g: Geometry, kp: usize) -> (Vec<f64>, usize) {
    let op = problem::<T>(g, kp, 13);
    let y = measure(&op, &paper_scene::<T>(g).unwrap());
    let r = reconstruct(&op, &y, Method::SupportLs, &ReconstructOptions::default()).unwrap();
    let x = r.scene.as_slice().iter().map(|v| v.as_f64()).collect();
    (x, r.report.unwrap().support_applies)
}

#[test]
fn f32_support_pursuit_stops_its_refits_at_round_off_with_the_f64_result() {
    // In f32 the normal equations' relative residual levels off far above the refits' target
    // (10⁻¹²): the refits must end where the fit stops moving by more than the measurements'
    // rounding, not at their iteration limit (50 CGLS iterations, 100 support applications for
    // the last refit alone), and find what f64 finds.
    let g = Geometry::new(8, 8, 8).unwrap();
    let ((x64, n64), (x32, n32)) = (
        support_pursuit_in::<f64>(g, 600),
        support_pursuit_in::<f32>(g, 600),
    );
    let truth = paper_scene::<f64>(g).unwrap();
    let lit = truth.as_slice().iter().filter(|v| **v != 0.0).count();
    assert_eq!(x64.iter().filter(|v| **v != 0.0).count(), lit);
    for ((a, b), t) in x64.iter().zip(&x32).zip(truth.as_slice()) {
        assert_eq!((*a != 0.0, *b != 0.0), (*t != 0.0, *t != 0.0));
        assert!(
            (a - b).abs() <= 1e-5 * t,
            "{a} in f64, {b} in f32, truth {t}"
        );
    }
    assert!(
        n32 <= n64 + 20,
        "f32 {n32} against f64 {n64} support applications"
    );
}
