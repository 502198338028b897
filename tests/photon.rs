//! The photon-noise data term: least squares weighted by each sample's light.

use rdlidar::lidar::{
    simulate, Geometry, PhotonNoise, Pulse, RdOperator, SceneSpec, SeededCodes, SimulationSpec,
    StreamedOperator,
};
use rdlidar::recon::{compare, reconstruct, Method, Metrics, NoiseModel, ReconstructOptions};
use rdlidar::Error;

/// The paper scene on `g` simulated as `rdlidar simulate --scene paper --pulse-len KP --seed
/// SEED` with `photons` per unit of intensity or Gaussian noise at `snr_db`: its operator,
/// measurements and true scene.
fn simulated(
    g: Geometry,
    kp: usize,
    seed: u64,
    photons: Option<f64>,
    snr_db: Option<f64>,
) -> (RdOperator<f64>, Vec<f64>, rdlidar::lidar::Scene<f64>) {
    simulated_scene(SceneSpec::Paper, g, kp, seed, photons, snr_db)
}

/// [`simulated`] of another scene.
fn simulated_scene(
    scene: SceneSpec,
    g: Geometry,
    kp: usize,
    seed: u64,
    photons: Option<f64>,
    snr_db: Option<f64>,
) -> (RdOperator<f64>, Vec<f64>, rdlidar::lidar::Scene<f64>) {
    let spec = SimulationSpec {
        scene,
        photon_noise: photons.map(|photons| PhotonNoise {
            photons,
            background: 0.0,
        }),
        snr_db,
        ..SimulationSpec::new(g, kp, seed)
    };
    let sim = simulate::<f64>(&spec).unwrap();
    let op = RdOperator::new(g, sim.pulse.into_inner(), sim.code_sets[0].clone()).unwrap();
    (op, sim.meas, sim.scene)
}

fn photon(background: f64) -> ReconstructOptions {
    ReconstructOptions {
        noise: NoiseModel::Photon { background },
        ..ReconstructOptions::default()
    }
}

fn judged(truth: &rdlidar::lidar::Scene<f64>, x: &rdlidar::lidar::Scene<f64>) -> Metrics {
    compare(truth, x, 200e-12).unwrap()
}

#[test]
fn under_photon_noise_the_weighted_data_term_finds_more_depths() {
    // 32×32×16 at 2.4 measurements per lit pixel, 20 photons per unit of intensity (about
    // 11 dB): the light per sample varies, and least squares weighted by it has about 1.4
    // times less variance. auto's estimate, refined on the weighted data term, finds more
    // depths and fits the amplitudes better.
    let g = Geometry::new(32, 32, 16).unwrap();
    let (mut plain, mut weighted) = (Vec::new(), Vec::new());
    for seed in [41, 42] {
        let (op, y, truth) = simulated(g, 1305, seed, Some(20.0), None);
        let a = reconstruct(&op, &y, Method::Auto, &ReconstructOptions::default()).unwrap();
        let b = reconstruct(&op, &y, Method::Auto, &photon(0.0)).unwrap();
        assert!(a.photon.is_none());
        let p = b.photon.as_ref().unwrap();
        assert_eq!(p.skipped, None, "seed {seed}: {}", p.describe());
        assert!(
            p.gain > 1.2 && p.slope_z >= 3.0,
            "seed {seed}: {}",
            p.describe()
        );
        let (ma, mb) = (judged(&truth, &a.scene), judged(&truth, &b.scene));
        assert!(
            mb.relative_error < ma.relative_error,
            "seed {seed}: weighted {mb}\nunweighted {ma}"
        );
        assert!(
            mb.exact_fraction >= ma.exact_fraction - 0.005,
            "seed {seed}: weighted {mb}\nunweighted {ma}"
        );
        plain.push(ma.exact_fraction);
        weighted.push(mb.exact_fraction);
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(
        mean(&weighted) >= mean(&plain) + 0.01,
        "weighted {weighted:?}, unweighted {plain:?}"
    );
}

#[test]
fn without_photon_noise_the_photon_model_changes_nothing() {
    // Gaussian noise at 20 dB: the residual's variance does not follow the light, so the
    // estimate is the unweighted one. Noise-free: the estimate explains the data.
    let g = Geometry::new(32, 32, 16).unwrap();
    for snr in [Some(20.0), None] {
        let (op, y, _) = simulated(g, 1305, 40, None, snr);
        let a = reconstruct(&op, &y, Method::Auto, &ReconstructOptions::default()).unwrap();
        let b = reconstruct(&op, &y, Method::Auto, &photon(0.5)).unwrap();
        let p = b.photon.as_ref().unwrap();
        assert!(p.skipped.is_some(), "{snr:?}: {}", p.describe());
        assert!(p.describe().contains("not reweighted"), "{}", p.describe());
        assert_eq!(p.gain, 1.0);
        assert_eq!(a.scene, b.scene, "{snr:?}");
    }
}

#[test]
fn a_generic_solver_runs_again_on_the_weighted_data_term() {
    // CGLS keeps no per-pixel model: it runs a second time on the weighted rows, and its
    // report counts both runs.
    let g = Geometry::new(32, 32, 16).unwrap();
    let (op, y, _) = simulated(g, 1305, 41, Some(20.0), None);
    let a = reconstruct(&op, &y, Method::Cgls, &ReconstructOptions::default()).unwrap();
    let b = reconstruct(&op, &y, Method::Cgls, &photon(0.0)).unwrap();
    let p = b.photon.as_ref().unwrap();
    assert_eq!(p.skipped, None, "{}", p.describe());
    let (ra, rb) = (a.report.unwrap(), b.report.unwrap());
    assert!(rb.iterations > ra.iterations, "{rb:?}");
    assert!(rb.forward_applies > ra.forward_applies);
    assert_ne!(a.scene, b.scene);
}

#[test]
fn bad_noise_models_are_refused() {
    let g = Geometry::new(8, 8, 6).unwrap();
    let (op, y, _) = simulated(g, 60, 3, Some(20.0), None);
    for background in [-1.0, f64::NAN, f64::INFINITY] {
        let e = reconstruct(&op, &y, Method::Auto, &photon(background)).unwrap_err();
        assert!(matches!(e, Error::InvalidParameter { .. }), "{e}");
        assert!(e.to_string().contains("background"), "{e}");
    }
    let e = "poisson".parse::<NoiseModel>().unwrap_err();
    assert!(e.to_string().contains("noise"), "{e}");
    assert_eq!(
        "Photon".parse::<NoiseModel>().unwrap(),
        NoiseModel::Photon { background: 0.0 }
    );
    // Streamed codes are not held: the weights' column queries need them.
    let pulse = Pulse::<f64>::bernoulli(60, 3).unwrap().into_inner();
    let seeded = SeededCodes::new(4, 1, g.pixels(), g.samples(60)).unwrap();
    let streamed = StreamedOperator::new(g, pulse, seeded, 0).unwrap();
    let e = reconstruct(&streamed, &y, Method::Auto, &photon(0.0)).unwrap_err();
    assert!(e.to_string().contains("noise"), "{e}");
}

#[test]
fn estimates_the_weighted_pass_does_not_model_are_kept_as_they_are() {
    // A semi-transparent scene (up to three returns per pixel) under photon noise: the
    // model-based solver with three returns leaves pixels with several, which the refinement
    // (one return per pixel) would cut down; the backprojection fits no data term. Both are
    // returned as the unweighted run gives them, and the weighting says why.
    let g = Geometry::new(12, 12, 12).unwrap();
    let (op, y, _) = simulated_scene(SceneSpec::Transparent, g, 2400, 7, Some(200.0), None);
    let several = ReconstructOptions {
        max_returns: Some(3),
        ..ReconstructOptions::default()
    };
    let weighted = ReconstructOptions {
        noise: NoiseModel::Photon { background: 0.0 },
        ..several.clone()
    };
    let a = reconstruct(&op, &y, Method::ModelBased, &several).unwrap();
    let b = reconstruct(&op, &y, Method::ModelBased, &weighted).unwrap();
    let multi = |x: &[f64]| {
        x.chunks(12)
            .filter(|c| c.iter().filter(|v| **v != 0.0).count() > 1)
            .count()
    };
    assert!(multi(a.scene.as_slice()) > 0);
    let p = b.photon.as_ref().unwrap();
    assert!(
        p.skipped.is_some_and(|why| why.contains("several returns")),
        "{}",
        p.describe()
    );
    assert_eq!(a.scene, b.scene);
    assert_eq!(b.method_used, Method::ModelBased);
    let c = reconstruct(&op, &y, Method::BackprojectionDebiased, &photon(0.0)).unwrap();
    let d = reconstruct(
        &op,
        &y,
        Method::BackprojectionDebiased,
        &ReconstructOptions::default(),
    )
    .unwrap();
    if let Some(p) = c.photon.as_ref().filter(|p| p.slope_z >= 3.0) {
        assert!(
            p.skipped.is_some_and(|why| why.contains("backprojections")),
            "{}",
            p.describe()
        );
    }
    assert_eq!(c.scene, d.scene);
}
