//! Censored samples (an ADC that clips): the censored acquisition is the original one with the
//! censored rows of the operator zeroed, on every architecture; bad requests are refused; and on
//! a clipped paper scene below the critical regime, leaving the clipped samples out recovers
//! what fitting them loses.

use std::sync::Arc;

use rdlidar::acquisition::{observe_nothing, Acquisition, Clipping, CodeStore, Streaming};
use rdlidar::lidar::{
    paper_scene, quantize, Codes, FullScale, Geometry, Pulse, SeededCodes, TileSize,
};
use rdlidar::operator::LinearOperator;
use rdlidar::recon::{compare, Method, Metrics, ReconstructOptions};
use rdlidar::Error;

use crate::common::random_vec;
use crate::split::in_spaces;

/// An acquisition of `g` with a pulse of `kp` samples (seed `seed`), `sets` code sets of
/// `alphabet` codes and tiles of `tiles` pixels.
fn acquisition(
    g: Geometry,
    kp: usize,
    (sets, ternary): (u64, bool),
    tiles: Option<TileSize>,
    seed: u64,
) -> Acquisition {
    let pulse = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
    let k = g.samples(kp);
    let codes = (0..sets)
        .map(|s| {
            let c = if ternary {
                Codes::random_ternary(g.pixels(), k, 0.3, seed + 1 + s)
            } else {
                Codes::random_binary(g.pixels(), k, seed + 1 + s)
            };
            Arc::new(c.unwrap())
        })
        .collect();
    Acquisition::new(g, pulse, CodeStore::Held(codes), tiles, Streaming::Never).unwrap()
}

/// y = A x for the acquisition's operator.
fn apply(acq: &Acquisition, x: &[f64]) -> Vec<f64> {
    let op = acq.operator::<f64>().unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(x, &mut y);
    y
}

/// Aᵀ y for the acquisition's operator.
fn adjoint(acq: &Acquisition, y: &[f64]) -> Vec<f64> {
    let op = acq.operator::<f64>().unwrap();
    let mut x = vec![0.0; op.ncols()];
    op.apply_adjoint(y, &mut x);
    x
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn zeroing_samples_clears_exactly_the_codes_of_the_pixels_each_mask_belongs_to() {
    for ternary in [false, true] {
        // 21 pixels: three groups, the last one partial.
        let (pixels, len) = (21, 37);
        let codes = if ternary {
            Codes::random_ternary(pixels, len, 0.25, 3)
        } else {
            Codes::random_binary(pixels, len, 3)
        }
        .unwrap();
        let masks: Vec<Vec<bool>> = (0..3)
            .map(|m| (0..len).map(|k| (k * 7 + m * 5) % 4 == 0).collect())
            .collect();
        // Groups whose pixels share a mask and groups that mix them.
        let row_of = |p: usize| if p < 8 { 1 } else { p % 3 };
        let zeroed = codes.zero_samples(&masks, &row_of).unwrap();
        assert_eq!(zeroed.alphabet().name(), "ternary");
        for p in 0..pixels {
            for (k, &censored) in masks[row_of(p)].iter().enumerate() {
                let want = if censored { 0 } else { codes.get(p, k) };
                assert_eq!(zeroed.get(p, k), want, "pixel {p}, sample {k}, {ternary}");
            }
        }
        // Bits beyond the last pixel stay clear in both planes.
        let tail = zeroed
            .plus_group(2)
            .iter()
            .chain(zeroed.minus_group(2).unwrap());
        assert!(tail.into_iter().all(|b| b & !0x1f == 0));
        assert!(codes.zero_samples(&[vec![false; len - 1]], &|_| 0).is_err());
        assert!(codes.zero_samples(&masks, &|_| 3).is_err());
    }
}

#[test]
fn a_censored_acquisition_is_the_original_with_the_censored_rows_zeroed() {
    let g = Geometry::new(6, 5, 4).unwrap();
    let kp = 60;
    let cases = [
        ("one ADC", (1, false), None),
        ("one ADC, ternary codes", (1, true), None),
        ("three ADCs", (3, false), None),
        ("tiles of 4x2", (1, false), Some(TileSize { m: 4, n: 2 })),
    ];
    for (name, sets, tiles) in cases {
        let acq = acquisition(g, kp, sets, tiles, 7);
        let k = acq.samples();
        let x = random_vec(g.voxels(), 8);
        let y = apply(&acq, &x);
        let top = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for clipping in [Clipping::Level(0.6 * top), Clipping::Top] {
            let (censored, yc, report) = acq.censor(&y, clipping).unwrap();
            let mask: Vec<bool> = match clipping {
                Clipping::Level(l) => y.iter().map(|v| v.abs() >= l).collect(),
                // Each row's largest and smallest values: its top and bottom codes.
                Clipping::Top => y
                    .chunks_exact(k)
                    .flat_map(|row| {
                        let t = row.iter().fold(0.0f64, |m, &v| m.max(v));
                        let b = row.iter().fold(0.0f64, |m, &v| m.min(v));
                        row.iter().map(move |&v| v == t || v == b)
                    })
                    .collect(),
            };
            let count = mask.iter().filter(|&&c| c).count();
            assert!(count > 0, "{name}: {clipping}");
            assert_eq!(report.total(), count, "{name}: {clipping}");
            assert_eq!(report.levels.len(), y.len() / k, "{name}");
            let masked = |v: &[f64]| -> Vec<f64> {
                v.iter()
                    .zip(&mask)
                    .map(|(&v, &c)| if c { 0.0 } else { v })
                    .collect()
            };
            assert_eq!(yc, masked(&y), "{name}: {clipping}");
            // Forward: the censored rows are zero, the others unchanged.
            let z = random_vec(g.voxels(), 9);
            let got = apply(&censored, &z);
            assert!(max_diff(&got, &masked(&apply(&acq, &z))) < 1e-12, "{name}");
            // Adjoint: the censored samples contribute nothing.
            let w = random_vec(y.len(), 10);
            let got = adjoint(&censored, &w);
            assert!(
                max_diff(&got, &adjoint(&acq, &masked(&w))) < 1e-12,
                "{name}"
            );
        }
        // Nothing at or beyond the level: the acquisition and measurements as they were.
        let (same, ys, report) = acq.censor(&y, Clipping::Level(2.0 * top)).unwrap();
        assert_eq!((report.total(), ys), (0, y.clone()));
        assert_eq!(apply(&same, &x), y);
    }
}

#[test]
fn each_process_censors_its_band_of_a_tiled_array_as_the_whole_does() {
    let g = Geometry::new(9, 7, 3).unwrap();
    let tile = TileSize { m: 4, n: 3 };
    let acq = acquisition(g, 40, (1, false), Some(tile), 11);
    let y = apply(&acq, &random_vec(g.voxels(), 12));
    let clipping = Clipping::Level(0.5 * y.iter().fold(0.0f64, |m, v| m.max(v.abs())));
    let (whole, _, report) = acq.censor(&y, clipping).unwrap();
    assert!(report.total() > 0);
    let dense = |a: &Acquisition| match a.codes() {
        CodeStore::Held(sets) => sets[0].to_dense(),
        CodeStore::Seeded(_) => unreachable!("held codes"),
    };
    let whole = dense(&whole);
    let bands = in_spaces(2, &|space| {
        let part = acq.split_over(space).unwrap();
        let rows = part.share().unwrap().pixels();
        let (censored, _, r) = part.censor(&y, clipping).unwrap();
        (rows, dense(&censored), r.total())
    });
    for (rows, band, total) in bands {
        assert_eq!(total, report.total());
        assert_eq!(band, whole.slice(ndarray::s![rows, ..]));
    }
}

#[test]
fn top_censors_both_codes_of_an_asymmetric_adc() {
    // A two's-complement ADC saturates at −8 and +7 codes of its step: both sides clipped.
    let g = Geometry::new(4, 4, 3).unwrap();
    let acq = acquisition(g, 30, (1, false), None, 2);
    let mut y = apply(&acq, &random_vec(g.voxels(), 3));
    let top = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let step = top / 6.0;
    for v in &mut y {
        *v = (*v / step).round().clamp(-3.0, 2.0) * step;
    }
    let (_, yc, report) = acq.censor(&y, Clipping::Top).unwrap();
    let at = |code: f64| y.iter().filter(|&&v| v == code * step).count();
    let (low, high) = (at(-3.0), at(2.0));
    assert!(low > 1 && high > 1, "{low} {high}");
    assert_eq!(report.total(), low + high);
    assert!(yc.iter().all(|&v| v > -3.0 * step && v < 2.0 * step));
    assert_eq!(report.levels.len(), 1);
    let (b, t) = report.levels[0];
    assert!(b > -3.0 * step && b < -2.9 * step && t > 1.9 * step && t < 2.0 * step);
    let line = report.describe();
    assert!(line.contains("y ≤ ") && line.contains(" or y ≥ "), "{line}");
    // A level censors |y| at or beyond it on both sides alike: here the bottom code only.
    let (_, _, level) = acq.censor(&y, Clipping::Level(2.5 * step)).unwrap();
    assert_eq!(level.total(), low);
}

#[test]
fn bad_censoring_requests_are_refused_naming_clipped() {
    let g = Geometry::new(4, 4, 3).unwrap();
    let acq = acquisition(g, 30, (1, false), None, 2);
    let y = apply(&acq, &random_vec(g.voxels(), 3));
    let refused = |r: Result<(Acquisition, Vec<f64>, _), Error>, what: &str| {
        let e = r.expect_err(what).to_string();
        assert!(e.contains("clipped:"), "{what}: {e}");
        e
    };
    for level in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        refused(acq.censor(&y, Clipping::Level(level)), "a bad level");
    }
    let flat = vec![-1.5; y.len()];
    for clipping in [Clipping::Level(1.0), Clipping::Top] {
        let e = refused(acq.censor(&flat, clipping), "everything censored");
        assert!(e.contains("nothing would be left"), "{e}");
    }
    // An ADC that saw no light has nothing clipped; a level no sample reaches says so.
    let (_, _, none) = acq.censor(&vec![0.0; y.len()], Clipping::Top).unwrap();
    assert_eq!(none.total(), 0);
    let (_, _, none) = acq.censor(&y, Clipping::Level(1e300)).unwrap();
    assert!(
        none.describe().contains("no sample reaches the level"),
        "{}",
        none.describe()
    );
    for text in ["", "abc", "0", "-2", "nan", "inf", "Top"] {
        assert!(text.parse::<Clipping>().is_err(), "{text:?}");
    }
    assert_eq!("top".parse::<Clipping>().unwrap(), Clipping::Top);
    assert_eq!("2.5".parse::<Clipping>().unwrap(), Clipping::Level(2.5));
    // Wrong measurements are refused as any reconstruction refuses them.
    let e = acq
        .censor(&y[1..], Clipping::Top)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("meas"), "{e}");
    // Codes regenerated on every application cannot be censored.
    let pulse = acq.pulse().to_vec();
    let seeded = SeededCodes::new(5, 1, g.pixels(), acq.samples()).unwrap();
    let streamed =
        Acquisition::new(g, pulse, CodeStore::Seeded(seeded), None, Streaming::Always).unwrap();
    let e = refused(streamed.censor(&y, Clipping::Top), "streamed codes");
    assert!(e.contains("held in memory"), "{e}");
}

/// auto on the paper scene at 32×32×16 measured with a pulse of `kp` samples (seed 40, codes
/// 41) through an 8-bit ADC whose full scale is 29% of the largest sample, with and without
/// censoring the clipped samples.
fn clipped_paper_scene(kp: usize) -> (Metrics, Metrics, usize) {
    let g = Geometry::new(32, 32, 16).unwrap();
    let acq = acquisition(g, kp, (1, false), None, 40);
    let truth = paper_scene::<f64>(g).unwrap();
    let mut y = apply(&acq, truth.as_slice());
    let top = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let adc = quantize(&mut y, 8, FullScale::Fixed(0.29 * top)).unwrap();
    let options = ReconstructOptions::default();
    let judge = |acq: &Acquisition, y: &[f64]| {
        let r = acq
            .reconstruct(y, Method::Auto, &options, &observe_nothing, &|_| {})
            .unwrap();
        compare(&truth, r.scene(), 200e-12).unwrap()
    };
    let fitted = judge(&acq, &y);
    let (censored, yc, report) = acq.censor(&y, Clipping::Top).unwrap();
    assert!(report.total() >= adc.clipped, "{report:?} {adc:?}");
    (judge(&censored, &yc), fitted, report.total())
}

#[test]
fn censoring_the_samples_a_clipping_adc_saturated_recovers_the_scene() {
    // K = 1815 for 550 lit pixels (3.3 per lit pixel), a quarter of the samples clipped:
    // fitting their values leaves false returns and amplitudes far off; leaving them out,
    // every depth is exact.
    let (censored, fitted, count) = clipped_paper_scene(1800);
    let show = format!("censored ({count}) {censored:#?}\nfitted {fitted:#?}");
    assert!((300..=600).contains(&count), "{show}");
    assert!(censored.exact_fraction >= 0.99, "{show}");
    assert!(censored.false_fraction_empty <= 0.005, "{show}");
    assert!(
        censored.false_fraction_empty < fitted.false_fraction_empty,
        "{show}"
    );
    assert!(
        censored.relative_error < 0.6 * fitted.relative_error,
        "{show}"
    );
}
