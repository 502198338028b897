//! Measurement noise: statistics of the Gaussian and photon noise, the ADC model, reproducibility
//! and parameter validation.

use ndarray::Array3;
use rdlidar::lidar::{
    add_gaussian, add_gaussian_snr, add_photon_noise, mean_power, quantize, sigma_for_snr,
    unmodulated_light, FullScale, Geometry, NoiseModel, NoiseStage, Scene, StageReport,
};
use rdlidar::Error;

use crate::common::random_vec;

fn param_err<T: std::fmt::Debug>(r: rdlidar::Result<T>, name: &str) {
    match r {
        Err(Error::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
        other => panic!("expected an invalid `{name}`, got {other:?}"),
    }
}

fn non_finite<T: std::fmt::Debug>(r: rdlidar::Result<T>) {
    match r {
        Err(Error::NonFinite { .. }) => {}
        other => panic!("expected a non-finite error, got {other:?}"),
    }
}

fn mean_var(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
    (mean, var)
}

#[test]
fn awgn_hits_the_requested_snr() {
    let n = 200_000;
    let clean = random_vec(n, 1);
    for &snr in &[-10.0, 0.0, 10.0, 30.0] {
        let mut y = clean.clone();
        let sigma = add_gaussian_snr(&mut y, snr, 42).unwrap();
        let power = mean_power(&clean);
        assert!((sigma - (power / 10f64.powf(snr / 10.0)).sqrt()).abs() < 1e-12);
        let noise: Vec<f64> = y.iter().zip(&clean).map(|(a, b)| a - b).collect();
        let (mean, var) = mean_var(&noise);
        // The sample variance of n normals has relative standard deviation √(2/n) ≈ 0.3%.
        assert!(
            (var / (sigma * sigma) - 1.0).abs() < 0.02,
            "snr {snr}: {var}"
        );
        assert!(
            mean.abs() < 5.0 * sigma / (n as f64).sqrt(),
            "snr {snr}: mean {mean}"
        );
        let achieved = 10.0 * (power / mean_power(&noise)).log10();
        assert!(
            (achieved - snr).abs() < 0.1,
            "snr {snr}: achieved {achieved}"
        );
    }
}

#[test]
fn awgn_in_f32_hits_the_snr_too() {
    let clean: Vec<f32> = random_vec(100_000, 3).iter().map(|&v| v as f32).collect();
    let mut y = clean.clone();
    add_gaussian_snr(&mut y, 20.0, 5).unwrap();
    let noise: Vec<f32> = y.iter().zip(&clean).map(|(a, b)| a - b).collect();
    let achieved = 10.0 * (mean_power(&clean) / mean_power(&noise)).log10();
    assert!((achieved - 20.0).abs() < 0.1, "achieved {achieved}");
}

#[test]
fn noise_is_reproducible_and_seed_dependent() {
    let clean = random_vec(1000, 2);
    let run = |seed| {
        let mut y = clean.clone();
        add_gaussian(&mut y, 0.1, seed).unwrap();
        y
    };
    assert_eq!(run(7), run(7));
    assert_ne!(run(7), run(8));

    let light: Vec<f64> = clean.iter().map(|v| v.abs() * 50.0).collect();
    let photon = |seed| {
        let mut y = clean.clone();
        add_photon_noise(&mut y, &light, 10.0, 1.0, seed).unwrap();
        y
    };
    assert_eq!(photon(3), photon(3));
    assert_ne!(photon(3), photon(4));
}

#[test]
fn zero_signal_gets_no_snr_noise() {
    let mut y = vec![0.0f64; 10];
    assert_eq!(add_gaussian_snr(&mut y, 10.0, 1).unwrap(), 0.0);
    assert!(y.iter().all(|&v| v == 0.0));
    let mut empty: Vec<f64> = Vec::new();
    assert_eq!(add_gaussian_snr(&mut empty, 10.0, 1).unwrap(), 0.0);
}

#[test]
fn photon_noise_has_zero_mean_and_the_shot_variance() {
    let n = 200_000;
    let photons = 4.0;
    let background = 0.5;
    // Two intensity levels: a small mean (λ = 2), where the sampler's small-λ method is used, and
    // a large one (λ = 4002), with the rejection method.
    for &level in &[0.0, 1000.0] {
        let intensity = vec![level; n];
        let clean = random_vec(n, 11);
        let mut y = clean.clone();
        let mean_photons = add_photon_noise(&mut y, &intensity, photons, background, 9).unwrap();
        assert!((mean_photons - photons * (level + background)).abs() < 1e-9);
        let noise: Vec<f64> = y.iter().zip(&clean).map(|(a, b)| a - b).collect();
        let (mean, var) = mean_var(&noise);
        let expected = (level + background) / photons;
        assert!(
            mean.abs() < 5.0 * (expected / n as f64).sqrt(),
            "level {level}: mean {mean}"
        );
        assert!(
            (var / expected - 1.0).abs() < 0.03,
            "level {level}: variance {var}, expected {expected}"
        );
        // Counts are integers: every noisy value sits on the lattice clean + (c − λ)/photons.
        let lambda = photons * (level + background);
        for (a, b) in y.iter().zip(&clean).take(100) {
            let c = (a - b) * photons + lambda;
            assert!((c - c.round()).abs() < 1e-6 && c.round() >= 0.0);
        }
    }
}

#[test]
fn photon_noise_follows_the_intensity_per_sample() {
    let n = 100_000;
    let intensity: Vec<f64> = (0..n)
        .map(|k| if k % 2 == 0 { 1.0 } else { 100.0 })
        .collect();
    let mut y = vec![0.0f64; n];
    add_photon_noise(&mut y, &intensity, 2.0, 0.0, 1).unwrap();
    let even: Vec<f64> = y.iter().step_by(2).copied().collect();
    let odd: Vec<f64> = y.iter().skip(1).step_by(2).copied().collect();
    let (_, ve) = mean_var(&even);
    let (_, vo) = mean_var(&odd);
    assert!((ve / 0.5 - 1.0).abs() < 0.05, "{ve}");
    assert!((vo / 50.0 - 1.0).abs() < 0.05, "{vo}");

    // No light and no background: no noise.
    let mut y = vec![0.25f64; 4];
    add_photon_noise(&mut y, &[0.0; 4], 1.0, 0.0, 1).unwrap();
    assert_eq!(y, vec![0.25; 4]);
}

#[test]
fn unmodulated_light_is_the_all_plus_measurement() {
    let g = Geometry::new(2, 3, 4).unwrap();
    let x = Array3::from_shape_fn(
        (2, 3, 4),
        |(i, j, d)| if d == (i + j) % 4 { 0.5f64 } else { 0.0 },
    );
    let scene = Scene::new(x.clone()).unwrap();
    let pulse = vec![1.0, 0.0, 1.0, 1.0, 0.0];
    let light = unmodulated_light(&scene, &pulse).unwrap();
    assert_eq!(light.len(), g.samples(pulse.len()));
    for (k, &l) in light.iter().enumerate() {
        let mut expect = 0.0f64;
        for ((_, _, d), &v) in x.indexed_iter() {
            if k >= d && k - d < pulse.len() {
                expect += v * pulse[k - d];
            }
        }
        assert!((l - expect).abs() < 1e-12, "k {k}: {l} vs {expect}");
    }
    assert!(light.iter().all(|&v| v >= 0.0));

    param_err(unmodulated_light(&scene, &[]), "pulse");
    param_err(unmodulated_light(&scene, &[1.0, -1.0]), "pulse");
    non_finite(unmodulated_light(&scene, &[1.0, f64::NAN]));
    let mut neg = x;
    neg[[0, 0, 0]] = -1.0;
    param_err(
        unmodulated_light(&Scene::new(neg).unwrap(), &pulse),
        "scene",
    );
}

#[test]
fn quantization_error_is_at_most_half_a_step_inside_the_range() {
    let clean: Vec<f64> = random_vec(10_000, 4).iter().map(|v| 0.9 * v).collect();
    for bits in [1u32, 2, 5, 8, 16, 32] {
        let mut y = clean.clone();
        let r = quantize(&mut y, bits, FullScale::Fixed(1.0)).unwrap();
        let step = 2.0 / 2f64.powi(bits as i32);
        assert_eq!(r.clipped, 0);
        assert_eq!(r.bits, bits);
        assert!((r.step - step).abs() < 1e-18);
        for (q, v) in y.iter().zip(&clean) {
            assert!(
                (q - v).abs() <= step / 2.0 * (1.0 + 1e-9),
                "bits {bits}: {v} -> {q}"
            );
            // Mid-rise levels: odd multiples of Δ/2.
            let m = (q + 1.0) / step - 0.5;
            assert!((m - m.round()).abs() < 1e-6, "bits {bits}: level {q}");
        }
        let levels: std::collections::BTreeSet<i64> = y
            .iter()
            .map(|q| ((q + 1.0) / step).floor() as i64)
            .collect();
        assert!(levels.len() as f64 <= 2f64.powi(bits as i32));
    }
    // One bit is the sign.
    let mut y = vec![-0.3, 0.0, 0.7];
    quantize(&mut y, 1, FullScale::Fixed(1.0)).unwrap();
    assert_eq!(y, vec![-0.5, 0.5, 0.5]);
}

#[test]
fn quantization_clips_counts_and_clamps() {
    let mut y = vec![-3.0f64, -1.0, -0.2, 0.0, 0.4, 1.0, 1.5, 10.0];
    let r = quantize(&mut y, 3, FullScale::Fixed(1.0)).unwrap();
    // |v| > F for −3, 1.5 and 10; ±1 are on the edge and not clipped.
    assert_eq!(r.clipped, 3);
    assert_eq!(r.step, 0.25);
    assert_eq!(
        y,
        vec![-0.875, -0.875, -0.125, 0.125, 0.375, 0.875, 0.875, 0.875]
    );
}

#[test]
fn quantization_is_monotone() {
    let mut v = random_vec(5000, 6);
    v.iter_mut().for_each(|x| *x *= 1.5);
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    for bits in [1u32, 3, 8] {
        let mut y = v.clone();
        quantize(&mut y, bits, FullScale::Fixed(1.0)).unwrap();
        assert!(y.windows(2).all(|w| w[0] <= w[1]), "bits {bits}");
        let mut y32: Vec<f32> = v.iter().map(|&x| x as f32).collect();
        quantize(&mut y32, bits, FullScale::Fixed(1.0)).unwrap();
        assert!(y32.windows(2).all(|w| w[0] <= w[1]), "bits {bits} f32");
    }
}

#[test]
fn automatic_full_scale_never_clips() {
    let clean: Vec<f64> = random_vec(1000, 8).iter().map(|v| 3.0 * v).collect();
    let fs = clean.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut y = clean.clone();
    let r = quantize(&mut y, 10, FullScale::Auto).unwrap();
    assert_eq!(r.clipped, 0);
    assert_eq!(r.full_scale, fs);
    for (q, v) in y.iter().zip(&clean) {
        assert!((q - v).abs() <= r.step / 2.0 * (1.0 + 1e-9));
    }
    let mut zeros = vec![0.0f32; 5];
    let r = quantize(&mut zeros, 10, FullScale::Auto).unwrap();
    assert_eq!((r.full_scale, r.step, r.clipped), (0.0, 0.0, 0));
    assert!(zeros.iter().all(|&v| v == 0.0));
}

#[test]
fn noise_model_chains_stages_in_order() {
    let clean = random_vec(50_000, 12);
    let light: Vec<f64> = clean.iter().map(|v| 10.0 * v.abs()).collect();

    // A one-stage model equals the stage's own function with the same seed.
    let mut a = clean.clone();
    let report = NoiseModel::none()
        .then(NoiseStage::Gaussian { snr_db: 15.0 })
        .apply(&mut a, 21)
        .unwrap();
    let mut b = clean.clone();
    let sigma = add_gaussian_snr(&mut b, 15.0, 21).unwrap();
    assert_eq!(a, b);
    assert_eq!(report.stages, vec![StageReport::Gaussian { sigma }]);
    assert!((report.snr_db() - 15.0).abs() < 0.2);
    assert_eq!(report.signal_power, mean_power(&clean));

    // Photon noise, electronics noise, then the ADC.
    let model = NoiseModel::new(vec![
        NoiseStage::Poisson {
            photons: 100.0,
            background: 0.1,
        },
        NoiseStage::GaussianSigma { sigma: 0.01 },
        NoiseStage::Quantized {
            bits: 4,
            full_scale: FullScale::Fixed(0.5),
        },
    ]);
    assert!(model.needs_intensity());
    let mut y = clean.clone();
    let report = model.apply_with_intensity(&mut y, Some(&light), 5).unwrap();
    assert_eq!(report.stages.len(), 3);
    assert!(report.clipped() > 0);
    assert!(y.iter().all(|v| v.abs() <= 0.5));
    let mut again = clean.clone();
    model
        .apply_with_intensity(&mut again, Some(&light), 5)
        .unwrap();
    assert_eq!(y, again);
    let noise_power = y
        .iter()
        .zip(&clean)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        / y.len() as f64;
    assert!((report.noise_power - noise_power).abs() < 1e-12);

    // Without intensity the photon stage is refused and y is unchanged.
    let mut y = clean.clone();
    param_err(model.apply(&mut y, 5), "intensity");
    assert_eq!(y, clean);

    // The empty model changes nothing.
    let mut y = clean.clone();
    let r = NoiseModel::default().apply(&mut y, 1).unwrap();
    assert!(NoiseModel::none().is_none());
    assert_eq!(y, clean);
    assert_eq!(r.noise_power, 0.0);
    assert_eq!(r.snr_db(), f64::INFINITY);
}

#[test]
fn invalid_parameters_are_typed_errors() {
    let clean = random_vec(16, 1);
    let mut y = clean.clone();
    for snr in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        param_err(add_gaussian_snr(&mut y, snr, 0), "snr_db");
    }
    param_err(add_gaussian_snr(&mut y, -4000.0, 0), "snr_db");
    for sigma in [-1.0, f64::NAN, f64::INFINITY] {
        param_err(add_gaussian(&mut y, sigma, 0), "sigma");
    }
    param_err(sigma_for_snr(-1.0, 10.0), "power");
    param_err(sigma_for_snr(f64::NAN, 10.0), "power");

    let light = vec![1.0; 16];
    for photons in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        param_err(add_photon_noise(&mut y, &light, photons, 0.0, 0), "photons");
    }
    param_err(add_photon_noise(&mut y, &light, 1e30, 0.0, 0), "photons");
    for background in [-0.1, f64::NAN, f64::INFINITY] {
        param_err(
            add_photon_noise(&mut y, &light, 1.0, background, 0),
            "background",
        );
    }
    let mut neg = light.clone();
    neg[3] = -1.0;
    param_err(add_photon_noise(&mut y, &neg, 1.0, 0.0, 0), "intensity");
    let mut nan = light.clone();
    nan[5] = f64::NAN;
    non_finite(add_photon_noise(&mut y, &nan, 1.0, 0.0, 0));
    match add_photon_noise(&mut y, &light[..10], 1.0, 0.0, 0) {
        Err(Error::ShapeMismatch {
            expected, found, ..
        }) => assert_eq!((expected, found), (16, 10)),
        other => panic!("expected a shape mismatch, got {other:?}"),
    }

    for bits in [0u32, 33, 64] {
        param_err(quantize(&mut y, bits, FullScale::Fixed(1.0)), "bits");
    }
    for fs in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        param_err(quantize(&mut y, 8, FullScale::Fixed(fs)), "full_scale");
    }
    assert_eq!(y, clean, "failed calls leave y unchanged");

    let mut bad = clean.clone();
    bad[2] = f64::INFINITY;
    non_finite(add_gaussian(&mut bad, 0.1, 0));
    non_finite(add_gaussian_snr(&mut bad, 10.0, 0));
    non_finite(quantize(&mut bad, 8, FullScale::Auto));
    non_finite(add_photon_noise(&mut bad, &light, 1.0, 0.0, 0));

    // An f32 result that overflows is reported, and y is kept.
    let mut small = vec![1.0f32; 8];
    non_finite(add_gaussian(&mut small, 1e300, 0));
    assert_eq!(small, vec![1.0f32; 8]);
    // A full scale beyond f32 puts every level beyond it: refused naming the full scale (it
    // was a non-finite value in the measurements), in a model too; fine in f64.
    param_err(
        quantize(&mut small, 8, FullScale::Fixed(1e300)),
        "full_scale",
    );
    let adc = NoiseModel::none().then(NoiseStage::Quantized {
        bits: 8,
        full_scale: FullScale::Fixed(1e300),
    });
    param_err(adc.apply(&mut small, 0), "full_scale");
    assert_eq!(small, vec![1.0f32; 8]);
    let mut wide = vec![1.0f64; 8];
    assert!(quantize(&mut wide, 8, FullScale::Fixed(1e300)).is_ok());

    let model = NoiseModel::none()
        .then(NoiseStage::GaussianSigma { sigma: 0.1 })
        .then(NoiseStage::Quantized {
            bits: 0,
            full_scale: FullScale::Auto,
        });
    param_err(model.validate(), "bits");
    param_err(model.apply(&mut y, 0), "bits");
    param_err(
        NoiseModel::new(vec![NoiseStage::Gaussian { snr_db: f64::NAN }]).apply(&mut y, 0),
        "snr_db",
    );
    param_err(
        NoiseModel::new(vec![NoiseStage::Poisson {
            photons: 1.0,
            background: -1.0,
        }])
        .apply_with_intensity(&mut y, Some(&light), 0),
        "background",
    );
    assert_eq!(y, clean);
}
