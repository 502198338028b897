//! The paper's architecture variants: dot tests, and agreement with the single-ADC operator whose
//! codes are zero outside the pixels an ADC sees.

use std::sync::Arc;

use ndarray::Array2;
use rdlidar::lidar::{
    coded_aperture, composed_operator, multi_adc, pixel_groups, tiles, Codes, Geometry, Pulse,
    RdOperator,
};
use rdlidar::operator::{dot_test, LinearOperator};

use crate::common::random_vec;

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    let s = b.iter().fold(1e-300f64, |m, v| m.max(v.abs()));
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol * s)
}

/// Codes of the full array with every pixel outside `keep` set to 0 (a ternary code).
fn masked(codes: &Codes, keep: &[usize]) -> Codes {
    let mut d: Array2<i8> = codes.to_dense();
    for p in 0..codes.pixels() {
        if !keep.contains(&p) {
            d.row_mut(p).fill(0);
        }
    }
    Codes::from_dense(d.view()).unwrap()
}

fn setup() -> (Geometry, Vec<f64>, Codes) {
    let g = Geometry::new(4, 5, 6).unwrap();
    let kp = 60;
    let p = Pulse::<f64>::bernoulli(kp, 3).unwrap().into_inner();
    let c = Codes::random_binary(g.pixels(), g.samples(kp), 4).unwrap();
    (g, p, c)
}

#[test]
fn multi_adc_stacks_independent_code_sets() {
    let (g, p, _) = setup();
    let k = g.samples(p.len());
    let sets: Vec<Arc<Codes>> = (0..3)
        .map(|s| Arc::new(Codes::random_binary(g.pixels(), k, 10 + s).unwrap()))
        .collect();
    let a = multi_adc(g, &p, sets.clone()).unwrap();
    assert_eq!((a.nrows(), a.ncols()), (3 * k, g.voxels()));
    assert!(dot_test(&a, 1).unwrap().gap < 1e-12);
    let a32 = multi_adc(
        g,
        &p.iter().map(|&v| v as f32).collect::<Vec<_>>(),
        sets.clone(),
    )
    .unwrap();
    assert!(dot_test(&a32, 1).unwrap().gap < 1e-5);
    let x = random_vec(g.voxels(), 2);
    let mut y = vec![0.0; 3 * k];
    a.apply(&x, &mut y);
    for (s, set) in sets.iter().enumerate() {
        let single = RdOperator::new(g, p.clone(), set.clone()).unwrap();
        let mut ys = vec![0.0; k];
        single.apply(&x, &mut ys);
        assert!(close(&y[s * k..(s + 1) * k], &ys, 1e-12));
    }
}

#[test]
fn coded_aperture_equals_zero_codes_outside_the_aperture() {
    let (g, p, c) = setup();
    let active = vec![0, 3, 7, 8, 19, 12];
    let a = coded_aperture(g, &p, &c, &active).unwrap();
    assert!(dot_test(&a, 5).unwrap().gap < 1e-12);
    let reference = composed_operator(g, &p, &masked(&c, &active)).unwrap();
    let x = random_vec(g.voxels(), 6);
    let (mut y, mut yr) = (vec![0.0; a.nrows()], vec![0.0; a.nrows()]);
    a.apply(&x, &mut y);
    reference.apply(&x, &mut yr);
    assert!(close(&y, &yr, 1e-12));
    let ym = random_vec(a.nrows(), 7);
    let (mut xt, mut xr) = (vec![0.0; g.voxels()], vec![0.0; g.voxels()]);
    a.apply_adjoint(&ym, &mut xt);
    reference.apply_adjoint(&ym, &mut xr);
    assert!(close(&xt, &xr, 1e-12));
}

#[test]
fn pixel_groups_give_one_adc_per_tile() {
    let (g, p, c) = setup();
    let t = tiles(g, 2, 3).unwrap();
    assert_eq!(t.len(), 4);
    let mut all: Vec<usize> = t.concat();
    all.sort_unstable();
    assert_eq!(all, (0..g.pixels()).collect::<Vec<_>>());
    let a = pixel_groups(g, &p, &c, &t).unwrap();
    let k = g.samples(p.len());
    assert_eq!(a.nrows(), t.len() * k);
    assert!(dot_test(&a, 8).unwrap().gap < 1e-12);
    let x = random_vec(g.voxels(), 9);
    let mut y = vec![0.0; a.nrows()];
    a.apply(&x, &mut y);
    for (i, tile) in t.iter().enumerate() {
        let reference = composed_operator(g, &p, &masked(&c, tile)).unwrap();
        let mut yr = vec![0.0; k];
        reference.apply(&x, &mut yr);
        assert!(close(&y[i * k..(i + 1) * k], &yr, 1e-12), "tile {i}");
    }
}

#[test]
fn invalid_variants_are_rejected() {
    let (g, p, c) = setup();
    assert!(multi_adc::<f64>(g, &p, vec![]).is_err());
    assert!(coded_aperture(g, &p, &c, &[]).is_err());
    assert!(matches!(
        coded_aperture(g, &p, &c, &[20]),
        Err(rdlidar::Error::IndexOutOfBounds { index: 20, .. })
    ));
    assert!(pixel_groups(g, &p, &c, &[]).is_err());
    assert!(tiles(g, 0, 2).is_err());
    let wrong = Arc::new(Codes::random_binary(g.pixels(), 7, 1).unwrap());
    assert!(matches!(
        multi_adc(g, &p, vec![wrong]),
        Err(rdlidar::Error::ShapeMismatch { .. })
    ));
}
