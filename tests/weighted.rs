//! The operator with weighted rows (`RowWeighted`): W·A against its definition, its column
//! queries against its applications, the coarse grid built on it, and its refusals.

use std::sync::Arc;

use rdlidar::lidar::{
    Codes, Geometry, LidarOperator, MultiAdcOperator, Pulse, RdOperator, RowWeighted, SeededCodes,
    StreamedOperator,
};
use rdlidar::operator::{dot_test, LinearOperator, VoxelOperator};
use rdlidar::Error;

use crate::blocks::{check_coarse, check_columns, gap};
use crate::reconstruct::problem;

/// Weights between 0.2 and 2.2 that change from row to row, with every seventh row zero (a
/// censored sample).
fn weights(rows: usize) -> Vec<f64> {
    (0..rows)
        .map(|k| {
            if k % 7 == 3 {
                0.0
            } else {
                0.2 + ((k * 37) % 23) as f64 / 11.0
            }
        })
        .collect()
}

/// The operator of `g` with ternary codes (a fifth of them zero).
fn ternary(g: Geometry, kp: usize) -> RdOperator<f64> {
    let pulse = Pulse::<f64>::bernoulli(kp, 4).unwrap().into_inner();
    let codes = Codes::random_ternary(g.pixels(), g.samples(kp), 0.2, 5).unwrap();
    RdOperator::new(g, pulse, Arc::new(codes)).unwrap()
}

/// The operator of `g` with three ADCs.
fn three_adcs(g: Geometry, kp: usize) -> MultiAdcOperator<f64> {
    let p = Pulse::<f64>::bernoulli(kp, 1).unwrap().into_inner();
    let codes = (0..3)
        .map(|s| Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), 20 + s).unwrap()))
        .collect();
    MultiAdcOperator::new(g, &p, codes).unwrap()
}

/// W·A of `op` against diag(w)·A in every direction: dense, sparse, restricted to a support,
/// zero-mean, correlation; the dot test.
fn check_definition(op: &dyn LidarOperator<f64>) {
    let w = weights(op.nrows());
    let wop = RowWeighted::new(op, w.clone()).unwrap();
    assert_eq!(wop.row_weights().map(<[f64]>::len), Some(op.nrows()));
    assert!(dot_test(&wop, 3).unwrap().passed());
    let x: Vec<f64> = (0..op.ncols())
        .map(|i| {
            if i % 9 == 2 {
                1.0 + (i % 5) as f64
            } else {
                0.0
            }
        })
        .collect();
    let (mut y, mut yw, mut ys) = (
        vec![0.0; op.nrows()],
        vec![0.0; op.nrows()],
        vec![0.0; op.nrows()],
    );
    op.apply(&x, &mut y);
    wop.apply(&x, &mut yw);
    wop.apply_sparse(&x, &mut ys);
    let expected: Vec<f64> = y.iter().zip(&w).map(|(a, b)| a * b).collect();
    assert!(gap(&yw, &expected) < 1e-12);
    assert!(gap(&ys, &expected) < 1e-12);
    // Adjoint and correlation: A's of the weighted residual.
    let r: Vec<f64> = (0..op.nrows())
        .map(|k| ((k * 13) % 7) as f64 - 3.0)
        .collect();
    let rw: Vec<f64> = r.iter().zip(&w).map(|(a, b)| a * b).collect();
    let (mut u, mut uw) = (vec![0.0; op.ncols()], vec![0.0; op.ncols()]);
    op.apply_adjoint(&rw, &mut u);
    wop.apply_adjoint(&r, &mut uw);
    assert!(gap(&uw, &u) < 1e-12);
    op.correlate(&rw, &mut u);
    wop.correlate(&r, &mut uw);
    assert!(gap(&uw, &u) < 1e-12);
    // The zero-mean operator.
    let (mut z, mut zw) = (vec![0.0; op.nrows()], vec![0.0; op.nrows()]);
    op.zero_mean_operator().apply(&x, &mut z);
    wop.zero_mean_operator().apply(&x, &mut zw);
    let expected: Vec<f64> = z.iter().zip(&w).map(|(a, b)| a * b).collect();
    assert!(gap(&zw, &expected) < 1e-12);
    // Restricted to a support, in both directions.
    let support: Vec<usize> = (0..op.ncols()).filter(|c| c % 9 == 2).collect();
    let restricted = wop.restrict_columns(support.clone()).unwrap();
    let amps: Vec<f64> = support.iter().map(|&c| x[c]).collect();
    let mut yr = vec![0.0; op.nrows()];
    restricted.apply(&amps, &mut yr);
    assert!(gap(&yr, &yw) < 1e-12);
    let mut ur = vec![0.0; support.len()];
    restricted.apply_adjoint(&r, &mut ur);
    wop.apply_adjoint(&r, &mut uw);
    let picked: Vec<f64> = support.iter().map(|&c| uw[c]).collect();
    assert!(gap(&ur, &picked) < 1e-12);
}

#[test]
fn the_weighted_operator_is_its_definition_in_every_direction() {
    let g = Geometry::new(5, 6, 7).unwrap();
    check_definition(&problem::<f64>(g, 41, 2));
    check_definition(&ternary(g, 41));
    check_definition(&three_adcs(g, 29));
    // f32 through the dot test.
    let op32 = problem::<f32>(g, 41, 2);
    let w: Vec<f32> = weights(op32.nrows()).iter().map(|&v| v as f32).collect();
    assert!(dot_test(&RowWeighted::new(&op32, w).unwrap(), 4)
        .unwrap()
        .passed());
}

/// The weighted operator's column queries against its applications: each column as a span,
/// its norm, its correlations with its pixel's columns, and (binary codes) its pixel's Gram
/// block.
fn check_weighted_columns(op: &dyn LidarOperator<f64>, exact_gram: bool) {
    let wop = RowWeighted::new(op, weights(op.nrows())).unwrap();
    let ks = wop.column_len();
    let voxels = [0usize, 8, 15, 23, wop.ncols() - 1];
    let norms = wop.column_norms(&voxels);
    let selfc = wop.self_correlations(&voxels);
    assert_eq!(wop.uniform_pixel_gram(), exact_gram);
    for (i, &v) in voxels.iter().enumerate() {
        let mut e = vec![0.0; wop.ncols()];
        e[v] = 1.0;
        let mut a = vec![0.0; wop.nrows()];
        wop.apply(&e, &mut a);
        let (first, values) = wop.column(v);
        let mut spanned = vec![0.0; wop.nrows()];
        spanned[first..first + values.len()].copy_from_slice(&values);
        assert!(gap(&spanned, &a) < 1e-12, "voxel {v}");
        let norm = a.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((norms[i] - norm).abs() <= 1e-12 * norm, "voxel {v}");
        let mut u = vec![0.0; wop.ncols()];
        wop.correlate(&a, &mut u);
        let p0 = v / ks * ks;
        assert!(
            gap(&selfc[i * ks..(i + 1) * ks], &u[p0..p0 + ks]) < 1e-9,
            "voxel {v}"
        );
        if exact_gram {
            let gram = wop.pixel_gram(v / ks);
            for j in 0..ks {
                let mut ej = vec![0.0; wop.ncols()];
                ej[p0 + j] = 1.0;
                let mut aj = vec![0.0; wop.nrows()];
                wop.apply(&ej, &mut aj);
                let g: f64 = a.iter().zip(&aj).map(|(p, q)| p * q).sum();
                let at = (v % ks) * ks + j;
                assert!((gram[at] - g).abs() <= 1e-9 * norm * norm, "voxel {v}, {j}");
            }
        }
    }
}

#[test]
fn the_weighted_operators_column_queries_match_its_applications() {
    let g = Geometry::new(4, 5, 6).unwrap();
    check_weighted_columns(&problem::<f64>(g, 33, 6), true);
    check_weighted_columns(&ternary(g, 33), false);
    check_weighted_columns(&three_adcs(g, 27), true);
}

#[test]
fn the_coarse_grid_of_a_weighted_operator_weights_its_rows_too() {
    let g = Geometry::new(7, 5, 6).unwrap();
    let op = problem::<f64>(g, 37, 3);
    let wop = RowWeighted::new(&op, weights(op.nrows())).unwrap();
    check_coarse(&wop, (2, 2));
    check_columns(&wop, (2, 3));
    let multi = three_adcs(g, 31);
    let wmulti = RowWeighted::new(&multi, weights(multi.nrows())).unwrap();
    check_coarse(&wmulti, (2, 2));
    check_columns(&wmulti, (3, 2));
}

#[test]
fn bad_weights_and_operators_without_codes_in_memory_are_refused() {
    let g = Geometry::new(4, 4, 5).unwrap();
    let op = problem::<f64>(g, 21, 1);
    let k = op.nrows();
    let short = RowWeighted::new(&op, vec![1.0; k - 1]).unwrap_err();
    assert!(matches!(short, Error::ShapeMismatch { .. }), "{short}");
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let mut w = vec![1.0; k];
        w[3] = bad;
        let e = RowWeighted::new(&op, w).unwrap_err();
        assert!(e.to_string().contains("weights"), "{e}");
    }
    let zero = RowWeighted::new(&op, vec![0.0; k]).unwrap_err();
    assert!(zero.to_string().contains("every weight is zero"), "{zero}");
    let once = RowWeighted::new(&op, vec![1.0; k]).unwrap();
    let twice = RowWeighted::new(&once, vec![1.0; k]).unwrap_err();
    assert!(twice.to_string().contains("already weighted"), "{twice}");
    let pulse = Pulse::<f64>::bernoulli(21, 1).unwrap().into_inner();
    let seeded = SeededCodes::new(7, 1, g.pixels(), g.samples(21)).unwrap();
    let streamed = StreamedOperator::new(g, pulse, seeded, 0).unwrap();
    let e = RowWeighted::new(&streamed, vec![1.0; k]).unwrap_err();
    assert!(e.to_string().contains("codes in memory"), "{e}");
}
