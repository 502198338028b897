//! Simulations with photon noise and an ADC: the noise follows the light that reaches each ADC,
//! the ADC's levels and clipping, and the requests that cannot be simulated.

use ndarray::Array3;
use rdlidar::acquisition::SimulationRequest;
use rdlidar::lidar::{
    simulate, simulate_supplied, AdcQuantization, Architecture, FullScale, Geometry, PhotonNoise,
    Scene, SceneSpec, SimulationSpec, TileSize,
};

/// A scene lit only in its left half: the right tiles of a 2-tile split see no light.
fn half_lit(g: Geometry) -> Scene<f64> {
    let mut x = Array3::<f64>::zeros((g.m, g.n, g.ks));
    for i in 0..g.m {
        for j in 0..g.n / 2 {
            x[[i, j, (i + j) % g.ks]] = 0.5 + 0.05 * (i % 5) as f64;
        }
    }
    Scene::new(x).unwrap()
}

#[test]
fn photon_noise_has_the_variance_of_the_light_each_adc_sees() {
    let g = Geometry::new(8, 8, 6).unwrap();
    let base = SimulationSpec {
        scene: SceneSpec::Supplied,
        architecture: Architecture::Tiles(TileSize { m: 8, n: 4 }),
        ..SimulationSpec::new(g, 3000, 21)
    };
    let clean = simulate_supplied::<f64>(&base, half_lit(g)).unwrap();
    let photons = 40.0;
    let noisy_spec = SimulationSpec {
        photon_noise: Some(PhotonNoise {
            photons,
            background: 0.0,
        }),
        ..base
    };
    let noisy = simulate_supplied::<f64>(&noisy_spec, half_lit(g)).unwrap();
    let k = clean.meas.len() / 2;
    // The lit tile's noise variance is its mean light / photons; the dark tile gets none.
    let pulse_ones: f64 = clean.pulse.as_slice().iter().sum();
    let lit_light: f64 = half_lit(g).as_slice().iter().sum::<f64>() * pulse_ones / k as f64;
    let diff: Vec<f64> = noisy
        .meas
        .iter()
        .zip(&clean.meas)
        .map(|(a, b)| a - b)
        .collect();
    let var = diff[..k].iter().map(|d| d * d).sum::<f64>() / k as f64;
    let expected = lit_light / photons;
    assert!(
        (var / expected - 1.0).abs() < 0.1,
        "variance {var} against {expected}"
    );
    assert!(
        diff[k..].iter().all(|&d| d == 0.0),
        "the dark tile got noise"
    );

    // A background reaches the dark tile too, with variance background / photons.
    let with_background = SimulationSpec {
        photon_noise: Some(PhotonNoise {
            photons,
            background: 8.0,
        }),
        ..base
    };
    let sim = simulate_supplied::<f64>(&with_background, half_lit(g)).unwrap();
    let dark: f64 = sim.meas[k..]
        .iter()
        .zip(&clean.meas[k..])
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        / k as f64;
    assert!(
        (dark / (8.0 / photons) - 1.0).abs() < 0.1,
        "dark-tile variance {dark}"
    );
    let report = sim.noise.as_ref().unwrap();
    assert_eq!(report.stages.len(), 1);
}

#[test]
fn the_adc_quantizes_each_row_to_its_levels_and_counts_what_it_clips() {
    let g = Geometry::new(6, 6, 5).unwrap();
    let base = SimulationSpec {
        architecture: Architecture::MultiAdc(2),
        snr_db: Some(30.0),
        ..SimulationSpec::new(g, 400, 4)
    };
    let noisy = simulate::<f64>(&base).unwrap();
    let bits = 4;
    let full = 0.5 * noisy.meas.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let spec = SimulationSpec {
        quantization: Some(AdcQuantization {
            bits,
            full_scale: FullScale::Fixed(full),
        }),
        ..base
    };
    let sim = simulate::<f64>(&spec).unwrap();
    let step = 2.0 * full / (1u32 << bits) as f64;
    let mut clipped = 0;
    for (&q, &y) in sim.meas.iter().zip(&noisy.meas) {
        // A level −F + (i + ½)Δ, the nearest to y inside [−F, F], the outermost beyond it.
        let index = (q + full) / step - 0.5;
        assert!((index - index.round()).abs() < 1e-9, "{q} is not a level");
        if y.abs() > full {
            clipped += 1;
            assert!((q.abs() - (full - step / 2.0)).abs() < 1e-12 && q * y > 0.0);
        } else {
            assert!((q - y).abs() <= step / 2.0 + 1e-12, "{q} against {y}");
        }
    }
    assert!(clipped > 0);
    assert_eq!(sim.noise.as_ref().unwrap().clipped(), clipped);

    // With the automatic full scale, each ADC's row is quantized to its own largest sample.
    let auto = SimulationSpec {
        quantization: Some(AdcQuantization {
            bits: 3,
            full_scale: FullScale::Auto,
        }),
        ..base
    };
    let sim = simulate::<f64>(&auto).unwrap();
    let k = sim.meas.len() / 2;
    for (row, clean) in sim.meas.chunks(k).zip(noisy.meas.chunks(k)) {
        // Levels ±(2i + 1)·F/8 of this row's own F = max |y|.
        let f = clean.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for &q in row {
            let odd = q / (f / 8.0);
            assert!(
                (odd - odd.round()).abs() < 1e-9 && odd.round().abs() as i64 % 2 == 1,
                "{q} is not a level of full scale {f}"
            );
        }
    }
    let maxima: Vec<f64> = noisy
        .meas
        .chunks(k)
        .map(|c| c.iter().fold(0.0f64, |m, v| m.max(v.abs())))
        .collect();
    assert!(
        maxima[0] != maxima[1],
        "the rows' full scales differ: {maxima:?}"
    );
    assert_eq!(sim.noise.as_ref().unwrap().clipped(), 0);
}

#[test]
fn noise_requests_that_cannot_be_simulated_name_their_setting() {
    let g = Geometry::new(4, 4, 4).unwrap();
    let base = SimulationRequest::new(g, 50, 1);
    for (request, name) in [
        (
            SimulationRequest {
                background: Some(1.0),
                ..base.clone()
            },
            "background",
        ),
        (
            SimulationRequest {
                full_scale: Some(1.0),
                ..base.clone()
            },
            "full_scale",
        ),
        (
            SimulationRequest {
                photons: Some(f64::NAN),
                ..base.clone()
            },
            "photons",
        ),
        (
            SimulationRequest {
                photons: Some(1.0),
                background: Some(-1.0),
                ..base.clone()
            },
            "background",
        ),
        (
            SimulationRequest {
                adc_bits: Some(33),
                ..base.clone()
            },
            "adc_bits",
        ),
        (
            SimulationRequest {
                adc_bits: Some(8),
                full_scale: Some(0.0),
                ..base.clone()
            },
            "full_scale",
        ),
    ] {
        match request.spec() {
            Err(rdlidar::Error::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
            other => panic!("{name}: {other:?}"),
        }
    }
}
