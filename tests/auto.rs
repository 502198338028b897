//! `auto` across the regimes and scene kinds, multi-return scenes, FISTA's debiasing and the
//! paper's backprojection threshold.

use ndarray::Array3;
use rdlidar::lidar::{paper_scene, random_opaque_scene, semi_transparent_scene, Geometry, Scene};
use rdlidar::recon::{compare, reconstruct, Method, PeakThreshold, ReconstructOptions};
use rdlidar::solver::{backprojection, Backprojection, Threshold};

use super::reconstruct::{measure, problem};

/// Scenes of several shapes, each with the pulse lengths to try: compressive (at least 5
/// measurements per return), critical, 2× and 4× redundant.
fn cases() -> Vec<(&'static str, Scene<f64>)> {
    vec![
        (
            "paper 8x8x8",
            paper_scene(Geometry::new(8, 8, 8).unwrap()).unwrap(),
        ),
        (
            "random 6x7x6",
            random_opaque_scene(Geometry::new(6, 7, 6).unwrap(), 0.5, 3).unwrap(),
        ),
        (
            "transparent 5x6x10",
            semi_transparent_scene(Geometry::new(5, 6, 10).unwrap(), 1..=3, 4).unwrap(),
        ),
    ]
}

#[test]
fn auto_is_exact_noise_free_in_every_regime_on_scenes_of_several_shapes() {
    for (name, truth) in cases() {
        let g = truth.geometry();
        let crit = g.critical_pulse_len();
        let returns = truth.nnz();
        // The shortest pulse that gives 5 measurements per return, if that is compressive.
        let compressive = (5 * returns).saturating_sub(g.ks - 1);
        let mut lens = vec![crit, 2 * crit, 4 * crit];
        if compressive < crit {
            lens.insert(0, compressive.max(1));
        }
        for kp in lens {
            let op = problem::<f64>(g, kp, 7);
            let y = measure(&op, &truth);
            let r = reconstruct(&op, &y, Method::Auto, &ReconstructOptions::default()).unwrap();
            let m = compare(&truth, &r.scene, 200e-12).unwrap();
            assert!(
                m.relative_error <= 1e-6,
                "{name}, K_p {kp}: {m}; stages {:?}",
                r.stages
            );
            assert_eq!(m.returns_exact, m.true_returns, "{name}, K_p {kp}: {m}");
            assert_eq!(m.returns_false, 0, "{name}, K_p {kp}: {m}");
            let kept = r.stages.last().unwrap();
            assert!(kept.kept && kept.method == r.method_used, "{name}: {kept}");
        }
    }
}

#[test]
fn a_scene_with_one_to_three_returns_per_pixel_is_recovered_at_eight_measurements_per_return() {
    let g = Geometry::new(8, 8, 24).unwrap();
    let truth = semi_transparent_scene::<f64>(g, 1..=3, 11).unwrap();
    let kp = 8 * truth.nnz() - (g.ks - 1);
    assert!(kp < g.critical_pulse_len(), "compressive");
    let op = problem::<f64>(g, kp, 12);
    let y = measure(&op, &truth);
    for method in [Method::Auto, Method::SupportLs, Method::Cosamp, Method::Iht] {
        let r = reconstruct(&op, &y, method, &ReconstructOptions::default()).unwrap();
        let m = compare(&truth, &r.scene, 200e-12).unwrap();
        assert!(m.multi_return(), "{m}");
        assert!(
            m.returns_exact as f64 >= 0.99 * m.true_returns as f64,
            "{method}: {m}"
        );
        assert!(m.to_string().contains("returns:"), "{m}");
        // Several returns stay in a pixel of the output scene; the depth map keeps the
        // strongest.
        let most = r
            .scene
            .as_slice()
            .chunks(g.ks)
            .map(|c| c.iter().filter(|v| **v != 0.0).count())
            .max()
            .unwrap();
        assert!(most >= 2, "{method}: at most {most} return per pixel");
        assert_eq!(r.depth.depth, truth.depth_map().depth, "{method}");
    }
}

#[test]
fn the_model_based_solver_with_k_returns_per_pixel_recovers_a_multi_return_scene() {
    let g = Geometry::new(8, 8, 24).unwrap();
    let truth = semi_transparent_scene::<f64>(g, 1..=3, 11).unwrap();
    let kp = 8 * truth.nnz() - (g.ks - 1);
    let op = problem::<f64>(g, kp, 12);
    let y = measure(&op, &truth);
    let run = |k: Option<usize>| {
        let options = ReconstructOptions {
            max_returns: k,
            ..ReconstructOptions::default()
        };
        let r = reconstruct(&op, &y, Method::ModelBased, &options).unwrap();
        compare(&truth, &r.scene, 200e-12).unwrap()
    };
    for k in [Some(3), Some(4), None] {
        let m = run(k);
        assert!(
            m.returns_exact as f64 >= 0.99 * m.true_returns as f64,
            "k {k:?}: {m}"
        );
    }
    // One return per pixel cannot hold the scene.
    let one = run(Some(1));
    assert!(one.returns_exact <= g.pixels(), "{one}");
    assert!(one.returns_missed > 0, "{one}");
}

#[test]
fn fista_debiased_is_exact_where_its_support_is_right_and_biased_without() {
    let g = Geometry::new(6, 6, 8).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    let op = problem::<f64>(g, 2 * g.critical_pulse_len(), 5);
    let y = measure(&op, &truth);
    let debiased = reconstruct(&op, &y, Method::Fista, &ReconstructOptions::default()).unwrap();
    let m = compare(&truth, &debiased.scene, 200e-12).unwrap();
    assert_eq!(m.exact, m.lit, "{m}");
    assert!(m.relative_error <= 1e-6, "debiased: {m}");
    let lasso = ReconstructOptions {
        debias: false,
        ..ReconstructOptions::default()
    };
    let biased = reconstruct(&op, &y, Method::Fista, &lasso).unwrap();
    let b = compare(&truth, &biased.scene, 200e-12).unwrap();
    assert_eq!(b.exact, b.lit, "{b}");
    assert!(
        b.relative_error > 1e-3,
        "the lasso keeps its shrinkage: {b}"
    );
}

#[test]
fn the_paper_threshold_keeps_most_right_peaks_of_a_paper_like_scene() {
    let g = Geometry::new(24, 24, 16).unwrap();
    let truth = paper_scene::<f32>(g).unwrap();
    let op = problem::<f32>(g, 2000, 21);
    let y = measure(&op, &truth);
    // How many lit pixels the plain backprojection's argmax puts at the true depth.
    let all = backprojection(
        &op,
        &y,
        &Backprojection {
            column_len: g.ks,
            normalization: 1.0,
            threshold: Threshold::None,
        },
    )
    .unwrap();
    let true_depth = truth.depth_map().depth;
    let right = all
        .peaks
        .iter()
        .zip(true_depth.iter())
        .filter(|(p, t)| **t >= 0 && p == t)
        .count();
    let exact = |rule: PeakThreshold| {
        let options = ReconstructOptions {
            threshold: rule,
            ..ReconstructOptions::default()
        };
        let r = reconstruct(&op, &y, Method::Backprojection, &options).unwrap();
        compare(&truth, &r.scene, 200e-12).unwrap()
    };
    let (paper, robust) = (exact(PeakThreshold::Paper), exact(PeakThreshold::Robust));
    assert!(right > paper.lit / 5, "{right} of {}", paper.lit);
    assert!(
        paper.exact as f64 >= 0.75 * right as f64,
        "paper rule: {paper}; argmax right for {right}"
    );
    assert!(paper.exact > robust.exact, "{paper} / {robust}");
    assert!(robust.false_detections <= paper.false_detections);
}

#[test]
fn return_metrics_count_exact_missed_and_false_returns() {
    let g = Geometry::new(1, 2, 4).unwrap();
    let mut t = Array3::<f64>::zeros((1, 2, 4));
    t[[0, 0, 0]] = 1.0;
    t[[0, 0, 2]] = 0.5;
    t[[0, 1, 1]] = 0.8;
    let mut e = Array3::<f64>::zeros((1, 2, 4));
    e[[0, 0, 0]] = 0.9;
    e[[0, 1, 1]] = 0.8;
    e[[0, 1, 3]] = 0.2;
    let (t, e) = (Scene::new(t).unwrap(), Scene::new(e).unwrap());
    assert_eq!(t.geometry(), g);
    let m = compare(&t, &e, 200e-12).unwrap();
    assert_eq!(
        (
            m.true_returns,
            m.returns_exact,
            m.returns_missed,
            m.returns_false
        ),
        (3, 2, 1, 1)
    );
    // Over the two returns found: ‖(1, 0.8) − (0.9, 0.8)‖ / ‖(1, 0.8)‖.
    let expected = 0.1 / (1.0f64 + 0.64).sqrt();
    assert!((m.amplitude_error - expected).abs() < 1e-12, "{m}");
    assert!(m.multi_return());
    assert!(m.to_string().contains("2 of 3 at the exact voxel"), "{m}");
}

#[test]
fn with_noise_at_and_above_the_critical_length_auto_keeps_a_sparse_fit_not_least_squares() {
    use rdlidar::lidar::add_gaussian_snr;
    let g = Geometry::new(8, 8, 8).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    for kp in [g.critical_pulse_len(), 2 * g.critical_pulse_len()] {
        let op = problem::<f64>(g, kp, 31);
        let mut y = measure(&op, &truth);
        add_gaussian_snr(&mut y, 20.0, 32).unwrap();
        let options = ReconstructOptions::default();
        let auto = reconstruct(&op, &y, Method::Auto, &options).unwrap();
        let mb = reconstruct(&op, &y, Method::ModelBased, &options).unwrap();
        let (a, b) = (
            compare(&truth, &auto.scene, 200e-12).unwrap(),
            compare(&truth, &mb.scene, 200e-12).unwrap(),
        );
        assert_eq!(a.exact, a.lit, "K_p {kp}: {a}");
        assert!(
            a.relative_error <= 1.5 * b.relative_error,
            "K_p {kp}: auto {a} / model-based {b}"
        );
        // Nothing explains noisy data: every stage says why it was or was not kept.
        assert!(auto.stages.len() >= 2, "{:?}", auto.stages);
        assert_eq!(auto.stages.iter().filter(|s| s.kept).count(), 1);
        assert!(auto
            .stages
            .iter()
            .all(|s| s.verdict.contains("information criterion")));
    }
}

#[test]
fn auto_turns_to_the_debiased_lasso_when_one_reflector_per_pixel_leaves_returns_unexplained() {
    let g = Geometry::new(8, 8, 16).unwrap();
    let truth = semi_transparent_scene::<f64>(g, 1..=3, 0).unwrap();
    // About 6 measurements per return: too few for the support pursuit.
    let kp = 6 * truth.nnz() - (g.ks - 1);
    let op = problem::<f64>(g, kp, 1);
    let y = measure(&op, &truth);
    let options = ReconstructOptions::default();
    let auto = reconstruct(&op, &y, Method::Auto, &options).unwrap();
    let fista = reconstruct(&op, &y, Method::Fista, &options).unwrap();
    let (a, f) = (
        compare(&truth, &auto.scene, 200e-12).unwrap(),
        compare(&truth, &fista.scene, 200e-12).unwrap(),
    );
    let ran: Vec<Method> = auto.stages.iter().map(|s| s.method).collect();
    assert!(ran.contains(&Method::Fista), "{:?}", auto.stages);
    // Before the lasso, the model-based solver with several returns per pixel was tried.
    assert!(
        auto.stages.iter().any(|s| s.method == Method::ModelBased
            && s.verdict.contains("returns per pixel do not explain")),
        "{:?}",
        auto.stages
    );
    assert!(
        a.relative_error <= f.relative_error.max(1e-9) * 1.01,
        "auto {a} / fista {f}"
    );
    assert!(a.returns_exact as f64 >= 0.9 * a.true_returns as f64, "{a}");
}

#[test]
fn at_20_db_auto_finds_every_depth_with_at_most_one_percent_of_empty_pixels_lit() {
    use rdlidar::lidar::add_gaussian_snr;
    // A piecewise-smooth scene at 2.9 measurements per lit pixel and one of scattered pixels
    // (fine structure: no smooth depth map to lean on) at 4.7, three noise draws each.
    let g = Geometry::new(24, 24, 16).unwrap();
    let scenes = [
        ("paper", paper_scene::<f64>(g).unwrap(), 900),
        (
            "random",
            random_opaque_scene::<f64>(g, 0.3, 5).unwrap(),
            800,
        ),
    ];
    for (name, truth, kp) in scenes {
        let (mut exact, mut lit, mut false_lit, mut empty) = (0, 0, 0, 0);
        for seed in 0..3 {
            let op = problem::<f64>(g, kp, 40 + seed);
            let mut y = measure(&op, &truth);
            add_gaussian_snr(&mut y, 20.0, 50 + seed).unwrap();
            let r = reconstruct(&op, &y, Method::Auto, &ReconstructOptions::default()).unwrap();
            let m = compare(&truth, &r.scene, 200e-12).unwrap();
            exact += m.exact;
            lit += m.lit;
            false_lit += m.false_detections;
            empty += g.pixels() - m.lit;
        }
        assert!(
            exact as f64 >= 0.99 * lit as f64,
            "{name}: {exact} of {lit} exact"
        );
        assert!(
            false_lit as f64 <= 0.01 * empty as f64,
            "{name}: {false_lit} of {empty} empty pixels lit"
        );
    }
}

#[test]
fn in_the_compressive_regime_auto_skips_the_one_reflector_fits_when_the_pursuit_sees_several_returns(
) {
    use rdlidar::lidar::add_gaussian_snr;
    let g = Geometry::new(16, 16, 24).unwrap();
    let truth = semi_transparent_scene::<f64>(g, 1..=3, 2).unwrap();
    // About 5 measurements per return, 20 dB: nothing explains the data.
    let kp = 5 * truth.nnz() - (g.ks - 1);
    assert!(kp < g.critical_pulse_len(), "compressive");
    let op = problem::<f64>(g, kp, 3);
    let mut y = measure(&op, &truth);
    add_gaussian_snr(&mut y, 20.0, 4).unwrap();
    let options = ReconstructOptions::default();
    let auto = reconstruct(&op, &y, Method::Auto, &options).unwrap();
    let tv = reconstruct(&op, &y, Method::Tv, &options).unwrap();
    let (a, t) = (
        compare(&truth, &auto.scene, 200e-12).unwrap(),
        compare(&truth, &tv.scene, 200e-12).unwrap(),
    );
    assert!(
        auto.stages[0].verdict.contains("hold several returns"),
        "{:?}",
        auto.stages
    );
    assert!(
        auto.stages.iter().all(|s| s.method != Method::Tv),
        "{:?}",
        auto.stages
    );
    // The one-reflector TV scene holds under a quarter of the returns; the kept pursuit 86%.
    assert!(a.returns_exact as f64 >= 0.8 * a.true_returns as f64, "{a}");
    assert!(a.returns_exact > 2 * t.returns_exact, "auto {a} / TV {t}");
}

#[test]
fn at_20_db_auto_skips_the_model_based_fit_where_tvs_residual_is_at_the_noise() {
    // TV cannot explain noisy data, but where its residual holds no return (few returns' energy,
    // and no more lit or empty pixels with a correlation standing out than noise makes) the
    // one-reflector fit cannot do markedly better and is not run. (Where unexplained returns
    // are many, as on a semi-transparent scene, or a few percent of the depths are wrong, as
    // behind a 4-bit ADC, it still runs: tests/split.rs, tests/detection.rs.)
    use rdlidar::lidar::add_gaussian_snr;
    let g = Geometry::new(24, 24, 16).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    let op = problem::<f64>(g, 900, 40);
    let mut y = measure(&op, &truth);
    add_gaussian_snr(&mut y, 20.0, 50).unwrap();
    let r = reconstruct(&op, &y, Method::Auto, &ReconstructOptions::default()).unwrap();
    let ran: Vec<Method> = r.stages.iter().map(|s| s.method).collect();
    assert_eq!(ran, [Method::SupportLs, Method::Tv], "{:?}", r.stages);
    assert_eq!(r.method_used, Method::Tv);
    assert!(
        r.stages[1].verdict.contains("at the noise"),
        "{:?}",
        r.stages
    );
    let m = compare(&truth, &r.scene, 200e-12).unwrap();
    assert!(m.exact as f64 >= 0.99 * m.lit as f64, "{m}");
}
