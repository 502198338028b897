//! The streamed operator over seeded codes: every capability equal to the fused operator on the
//! materialized codes (the adjoint bit for bit), whatever the block size, including blocks
//! that do not divide the array and sparse scenes that touch a few blocks; every solver runs on
//! it and auto is exact where the held codes are.

use std::sync::Arc;

use rdlidar::lidar::{
    paper_scene, Geometry, LidarOperator, Pulse, RdOperator, SeededCodes, StreamedOperator,
};
use rdlidar::operator::{dot_test, LinearOperator, VoxelOperator};
use rdlidar::recon::{compare, reconstruct, Method, ReconstructOptions};

use crate::common::random_vec;

fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    (num / den.max(1e-300)).sqrt()
}

/// The streamed operator of code set `set` of seeded codes and the fused operator on the same
/// codes materialized.
fn pair(
    g: Geometry,
    kp: usize,
    seed: u64,
    set: usize,
    block: usize,
) -> (StreamedOperator<f64>, RdOperator<f64>) {
    let p = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
    let codes = SeededCodes::new(seed, set + 1, g.pixels(), g.samples(kp)).unwrap();
    let held = RdOperator::new(g, p.clone(), Arc::new(codes.materialize(set).unwrap())).unwrap();
    let streamed = StreamedOperator::new(g, p, codes, set)
        .unwrap()
        .with_block_pixels(block)
        .unwrap();
    (streamed, held)
}

#[test]
fn the_streamed_operator_equals_the_held_codes_in_every_capability() {
    // 7x5 = 35 pixels in blocks of 16: three blocks, the last of three pixels.
    let g = Geometry::new(7, 5, 9).unwrap();
    for (block, set) in [(16, 0), (3, 1), (1000, 0)] {
        let (op, held) = pair(g, 53, 11, set, block);
        assert_eq!(op.block_pixels(), block.div_ceil(8) * 8);
        assert_eq!((op.nrows(), op.ncols()), (held.nrows(), held.ncols()));
        assert!(dot_test(&op, 3).unwrap().gap < 1e-12, "block {block}");
        let k = op.nrows();
        let x = random_vec(g.voxels(), 4);
        let r = random_vec(k, 5);
        let (mut y, mut want) = (vec![0.0; k], vec![0.0; k]);
        op.apply(&x, &mut y);
        held.apply(&x, &mut want);
        assert!(rel_diff(&y, &want) < 1e-14, "forward, block {block}");
        // A sparse scene in two pixels of different blocks, through both forward paths.
        let mut sparse = vec![0.0; g.voxels()];
        sparse[2] = 1.5;
        sparse[33 * 9 + 4] = -0.5;
        let (mut ys, mut yd) = (vec![0.0; k], vec![0.0; k]);
        op.apply_sparse(&sparse, &mut ys);
        held.apply(&sparse, &mut want);
        op.apply(&sparse, &mut yd);
        assert!(rel_diff(&ys, &want) < 1e-14 && rel_diff(&yd, &want) < 1e-14);
        // The adjoint and the debiased correlation: the same bits.
        let (mut u, mut v) = (vec![0.0; g.voxels()], vec![0.0; g.voxels()]);
        op.apply_adjoint(&r, &mut u);
        held.apply_adjoint(&r, &mut v);
        assert_eq!(u, v, "adjoint, block {block}");
        op.correlate(&r, &mut u);
        held.correlate(&r, &mut v);
        assert_eq!(u, v, "correlation, block {block}");
        op.zero_mean_operator().apply_adjoint(&r, &mut u);
        assert_eq!(u, v);
        // What ±1 codes make the same for every pixel.
        assert!(op.uniform_pixel_gram());
        assert_eq!(op.pixel_gram(30), held.pixel_gram(30));
        let cols = [0, 40, 300];
        assert_eq!(op.column_norms(&cols), held.column_norms(&cols));
        assert_eq!(op.self_correlations(&cols), held.self_correlations(&cols));
        assert_eq!(LidarOperator::observed_pixels(&op), None);
        assert_eq!(op.regime(), held.regime());
    }
}

#[test]
fn a_streamed_support_is_the_held_support_in_any_order_with_repeats() {
    let g = Geometry::new(6, 6, 5).unwrap();
    let (op, held) = pair(g, 40, 3, 0, 8);
    // Voxels out of order, in several blocks, one repeated.
    let support = vec![170, 3, 41, 4, 179, 41, 90];
    let a = op.restrict_columns(support.clone()).unwrap();
    let b = held.restrict_columns(support.clone()).unwrap();
    assert_eq!((a.nrows(), a.ncols()), (b.nrows(), b.ncols()));
    assert!(dot_test(a.as_ref(), 2).unwrap().gap < 1e-12);
    let v = random_vec(support.len(), 6);
    let (mut y1, mut y2) = (vec![0.0; a.nrows()], vec![0.0; a.nrows()]);
    a.apply(&v, &mut y1);
    b.apply(&v, &mut y2);
    assert!(rel_diff(&y1, &y2) < 1e-14);
    let r = random_vec(a.nrows(), 7);
    let (mut u1, mut u2) = (vec![0.0; support.len()], vec![0.0; support.len()]);
    a.apply_adjoint(&r, &mut u1);
    b.apply_adjoint(&r, &mut u2);
    assert!(rel_diff(&u1, &u2) < 1e-14);
    // A restriction of the restriction.
    let c = a.restrict_columns(vec![1, 4]).unwrap();
    let mut y3 = vec![0.0; c.nrows()];
    c.apply(&[1.0, 2.0], &mut y3);
    let mut x = vec![0.0; support.len()];
    x[1] = 1.0;
    x[4] = 2.0;
    a.apply(&x, &mut y1);
    assert!(rel_diff(&y3, &y1) < 1e-14);
    assert!(op.restrict_columns(vec![g.voxels()]).is_err());
}

#[test]
fn every_solver_runs_on_streamed_codes_and_auto_is_exact_where_held_codes_are() {
    // The paper scene at 12x10x8 with K_p 600: compressive, exact with held codes.
    let g = Geometry::new(12, 10, 8).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    let (op, held) = pair(g, 600, 21, 0, 40);
    let mut y = vec![0.0; op.nrows()];
    held.apply(truth.as_slice(), &mut y);
    let options = ReconstructOptions::default();
    for method in Method::ALL {
        if method == Method::CoarseToFine {
            // Its coarse grid sums the codes held in memory: a typed refusal.
            let e = reconstruct(&op, &y, method, &options).unwrap_err();
            assert!(e.to_string().contains("codes in memory"), "{e}");
            continue;
        }
        let r = reconstruct(&op, &y, method, &options).unwrap();
        assert!(r.scene.as_slice().iter().all(|v| v.is_finite()), "{method}");
        if matches!(method, Method::Auto | Method::SupportLs | Method::Tv) {
            let m = compare(&truth, &r.scene, 200e-12).unwrap();
            assert!(m.relative_error < 1e-6, "{method}: {m}");
            assert_eq!(m.returns_false, 0, "{method}: {m}");
            let h = reconstruct(&held, &y, method, &options).unwrap();
            assert_eq!(r.depth.depth, h.depth.depth, "{method}");
        }
    }
}

#[test]
fn streamed_codes_refuse_a_geometry_or_set_they_do_not_have() {
    let g = Geometry::new(4, 4, 6).unwrap();
    let p = vec![1.0f64; 30];
    let k = g.samples(30);
    let codes = SeededCodes::new(1, 2, g.pixels(), k).unwrap();
    assert!(StreamedOperator::new(g, p.clone(), codes, 2).is_err());
    let wrong_len = SeededCodes::new(1, 1, g.pixels(), k + 1).unwrap();
    assert!(StreamedOperator::new(g, p.clone(), wrong_len, 0).is_err());
    let wrong_pixels = SeededCodes::new(1, 1, 15, k).unwrap();
    assert!(StreamedOperator::new(g, p.clone(), wrong_pixels, 0).is_err());
    assert!(StreamedOperator::new(g, vec![f64::NAN; 30], codes, 0).is_err());
    let op = StreamedOperator::new(g, p, codes, 1).unwrap();
    assert!(op.with_block_pixels(0).is_err());
}
