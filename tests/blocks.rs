//! The coarse grid (`BlockOperator`) and the refinement along surfaces (`refine_surfaces`).

use std::sync::Arc;

use rdlidar::lidar::{
    paper_scene, BlockOperator, Codes, Geometry, LidarOperator, MultiAdcOperator, Pulse, Scene,
    SeededCodes, StreamedOperator,
};
use rdlidar::operator::{dot_test, LinearOperator, VoxelOperator};
use rdlidar::recon::compare;
use rdlidar::solver::{refine_surfaces, RefineParams};
use rdlidar::Error;

use crate::reconstruct::{measure, problem};

/// ‖a − b‖∞ relative to ‖b‖∞.
pub(crate) fn gap(a: &[f64], b: &[f64]) -> f64 {
    let top = b
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
        / top
}

/// The coarse operator of `op` for `block` against its definition A·U: the dot test, the dense
/// path through A on upsampled scenes, and the restriction to a support (the blocks' summed
/// codes) against the dense path in both directions.
pub(crate) fn check_coarse(op: &dyn LidarOperator<f64>, block: (usize, usize)) {
    let g = op.geometry();
    let b = BlockOperator::new(op, block).unwrap();
    let (gm, gn) = b.grid();
    assert_eq!((gm, gn), (g.m.div_ceil(block.0), g.n.div_ceil(block.1)));
    assert_eq!(b.ncols(), gm * gn * g.ks);
    assert!(dot_test(&b, 11).unwrap().passed(), "{block:?}");
    // A coarse scene, upsampled, through the fine operator.
    let xc: Vec<f64> = (0..b.ncols())
        .map(|i| ((i * 37) % 11) as f64 - 5.0)
        .collect();
    let mut xf = vec![0.0; op.ncols()];
    b.upsample(&xc, &mut xf);
    let (mut y_coarse, mut y_fine) = (vec![0.0; b.nrows()], vec![0.0; b.nrows()]);
    b.apply(&xc, &mut y_coarse);
    op.apply(&xf, &mut y_fine);
    assert!(gap(&y_coarse, &y_fine) < 1e-12, "{block:?}");
    let support: Vec<usize> = (0..b.ncols()).filter(|c| c % 5 == 1).collect();
    let restricted = b.restrict_columns(support.clone()).unwrap();
    let amps: Vec<f64> = (0..support.len()).map(|i| 1.0 + i as f64 * 0.25).collect();
    let mut dense_x = vec![0.0; b.ncols()];
    for (&c, &a) in support.iter().zip(&amps) {
        dense_x[c] = a;
    }
    let (mut ys, mut yd) = (vec![0.0; b.nrows()], vec![0.0; b.nrows()]);
    restricted.apply(&amps, &mut ys);
    b.apply(&dense_x, &mut yd);
    assert!(gap(&ys, &yd) < 1e-12, "{block:?}");
    let mut us = vec![0.0; support.len()];
    let mut ud = vec![0.0; b.ncols()];
    restricted.apply_adjoint(&yd, &mut us);
    b.apply_adjoint(&yd, &mut ud);
    let picked: Vec<f64> = support.iter().map(|&c| ud[c]).collect();
    assert!(gap(&us, &picked) < 1e-12, "{block:?}");
}

#[test]
fn the_coarse_operator_passes_the_dot_test_and_is_the_fine_one_on_upsampled_scenes() {
    // 7×5 pixels: blocks of 2×2 and 3×2 leave smaller blocks at the last row and column.
    let g = Geometry::new(7, 5, 6).unwrap();
    let op = problem::<f64>(g, 37, 3);
    for block in [(1, 1), (2, 2), (3, 2)] {
        check_coarse(&op, block);
        let op32 = problem::<f32>(g, 37, 3);
        let b32 = BlockOperator::new(&op32, block).unwrap();
        assert!(dot_test(&b32, 12).unwrap().passed(), "{block:?} f32");
    }
    // Three ADCs: every code set summed over the blocks, rows stacked ADC by ADC.
    check_coarse(&three_adcs(g), (2, 2));
}

/// The operator of `g` with three ADCs (pulse of 31 samples).
fn three_adcs(g: Geometry) -> MultiAdcOperator<f64> {
    let p = Pulse::<f64>::bernoulli(31, 1).unwrap().into_inner();
    let codes = (0..3)
        .map(|s| Arc::new(Codes::random_binary(g.pixels(), g.samples(31), 10 + s).unwrap()))
        .collect();
    MultiAdcOperator::new(g, &p, codes).unwrap()
}

#[test]
fn the_coarse_operators_column_queries_match_its_applications() {
    let g = Geometry::new(6, 6, 5).unwrap();
    let op = problem::<f64>(g, 29, 8);
    check_columns(&op, (2, 3));
    check_columns(&three_adcs(g), (2, 2));
}

/// The column queries of the coarse operator of `op` (and of `op` itself) against its
/// applications.
pub(crate) fn check_columns(op: &dyn LidarOperator<f64>, block: (usize, usize)) {
    let g = op.geometry();
    let b = BlockOperator::new(op, block).unwrap();
    let ks = g.ks;
    let voxels = [0usize, 7, 13, 24, b.ncols() - 1];
    let norms = b.column_norms(&voxels);
    let selfc = b.self_correlations(&voxels);
    for (i, &v) in voxels.iter().enumerate() {
        let mut e = vec![0.0; b.ncols()];
        e[v] = 1.0;
        let mut a = vec![0.0; b.nrows()];
        b.apply(&e, &mut a);
        // The column as a span of rows.
        let (first, values) = b.column(v);
        let mut spanned = vec![0.0; b.nrows()];
        spanned[first..first + values.len()].copy_from_slice(&values);
        assert!(gap(&spanned, &a) < 1e-12, "voxel {v}");
        let norm = a.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((norms[i] - norm).abs() <= 1e-12 * norm, "voxel {v}");
        // Its correlations with its block's columns.
        let mut u = vec![0.0; b.ncols()];
        b.correlate(&a, &mut u);
        let p0 = v / ks * ks;
        assert!(
            gap(&selfc[i * ks..(i + 1) * ks], &u[p0..p0 + ks]) < 1e-9,
            "voxel {v}"
        );
    }
    // The fine operator's columns too.
    for v in [0usize, 17, op.ncols() - 1] {
        let mut e = vec![0.0; op.ncols()];
        e[v] = 1.0;
        let mut a = vec![0.0; op.nrows()];
        op.apply(&e, &mut a);
        let (first, values) = op.column(v);
        let mut spanned = vec![0.0; op.nrows()];
        spanned[first..first + values.len()].copy_from_slice(&values);
        assert!(gap(&spanned, &a) < 1e-12, "fine voxel {v}");
    }
}

#[test]
fn impossible_blocks_and_streamed_codes_are_refused() {
    let g = Geometry::new(4, 4, 3).unwrap();
    let op = problem::<f64>(g, 20, 1);
    for block in [(0, 2), (2, 0), (12, 11)] {
        let e = BlockOperator::new(&op, block).unwrap_err();
        assert!(matches!(e, Error::InvalidParameter { .. }), "{e}");
        assert!(e.to_string().contains("block"), "{e}");
    }
    // Codes streamed from their seed are not held: nothing to sum.
    let codes = SeededCodes::new(1, 1, g.pixels(), g.samples(20)).unwrap();
    let p = Pulse::<f64>::bernoulli(20, 1).unwrap().into_inner();
    let streamed = StreamedOperator::new(g, p, codes, 0).unwrap();
    let e = BlockOperator::new(&streamed, (2, 2)).unwrap_err();
    assert!(e.to_string().contains("codes in memory"), "{e}");
}

#[test]
fn the_refinement_keeps_an_exact_scene_and_repairs_a_damaged_one() {
    // 16×16×16 with K_p 1500: 1515 measurements for 141 lit pixels, noise-free.
    let g = Geometry::new(16, 16, 16).unwrap();
    let op = problem::<f64>(g, 1500, 5);
    let truth = paper_scene::<f64>(g).unwrap();
    let y = measure(&op, &truth);
    let params = RefineParams::default();
    let mut x = truth.as_slice().to_vec();
    let report = refine_surfaces(&op, (g.m, g.n), &y, &mut x, &params).unwrap();
    let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
    assert!(m.relative_error < 1e-6, "{m}");
    assert_eq!(report.iterations, 1, "{report:?}");
    // Every lit pixel one bin off, and a few returns dropped: the sweeps put them back.
    let mut damaged = vec![0.0; g.voxels()];
    let mut lit = 0;
    for (p, col) in truth.as_slice().chunks(g.ks).enumerate() {
        if let Some(d) = col.iter().position(|&v| v != 0.0) {
            lit += 1;
            if lit % 7 != 0 {
                damaged[p * g.ks + (d + 1).min(g.ks - 1)] = col[d];
            }
        }
    }
    let report = refine_surfaces(&op, (g.m, g.n), &y, &mut damaged, &params).unwrap();
    let m = compare(&truth, &Scene::from_vec(g, damaged).unwrap(), 200e-12).unwrap();
    assert_eq!(m.exact, m.lit, "{m}\n{report:?}");
    assert!(m.relative_error < 1e-6, "{m}");
}

#[test]
fn the_refinement_at_20_db_removes_a_false_patch_and_keeps_every_depth() {
    // The scene of the test above at 20 dB, started from the truth plus a false 3×3 patch where
    // it is empty: the fits, the sweeps and the last test of what each patch explains remove
    // the patch and keep every true return (hard_scenes.rs guards a patch only that test
    // removes).
    let g = Geometry::new(16, 16, 16).unwrap();
    let op = problem::<f64>(g, 1500, 5);
    let truth = paper_scene::<f64>(g).unwrap();
    let mut y = measure(&op, &truth);
    rdlidar::lidar::add_gaussian_snr(&mut y, 20.0, 9).unwrap();
    let lit = |p: usize| {
        truth.as_slice()[p * g.ks..(p + 1) * g.ks]
            .iter()
            .any(|&v| v != 0.0)
    };
    let window = |(a, b): (usize, usize)| -> Vec<usize> {
        (a..a + 3)
            .flat_map(|i| (b..b + 3).map(move |j| i * g.n + j))
            .collect()
    };
    let corner = (0..g.m - 2)
        .flat_map(|a| (0..g.n - 2).map(move |b| (a, b)))
        .map(window)
        .find(|w| w.iter().all(|&p| !lit(p)))
        .expect("an empty 3×3 window");
    let start = |x: &mut Vec<f64>| {
        for &p in &corner {
            x[p * g.ks + 5] = 0.3;
        }
    };
    let kept_in_corner = |x: &[f64]| {
        corner
            .iter()
            .filter(|&&p| x[p * g.ks..(p + 1) * g.ks].iter().any(|&v| v != 0.0))
            .count()
    };
    let mut x = truth.as_slice().to_vec();
    start(&mut x);
    refine_surfaces(&op, (g.m, g.n), &y, &mut x, &RefineParams::default()).unwrap();
    assert_eq!(kept_in_corner(&x), 0);
    let m = compare(&truth, &Scene::from_vec(g, x).unwrap(), 200e-12).unwrap();
    assert_eq!(m.exact, m.lit, "{m}");
    assert_eq!(m.false_detections, 0, "{m}");
}

#[test]
fn the_refinement_refuses_bad_parameters_and_shapes() {
    let g = Geometry::new(4, 4, 3).unwrap();
    let op = problem::<f64>(g, 20, 1);
    let y = vec![0.0; op.nrows()];
    let mut x = vec![0.0; op.ncols()];
    let bad = [
        RefineParams {
            tie: -1.0,
            ..RefineParams::default()
        },
        RefineParams {
            disagreement: f64::NAN,
            ..RefineParams::default()
        },
        RefineParams {
            iterations: 0,
            ..RefineParams::default()
        },
        RefineParams {
            patch_gain: Some(-1.0),
            ..RefineParams::default()
        },
    ];
    for params in bad {
        let e = refine_surfaces(&op, (g.m, g.n), &y, &mut x, &params).unwrap_err();
        assert!(matches!(e, Error::InvalidParameter { .. }), "{e}");
    }
    let params = RefineParams::default();
    assert!(refine_surfaces(&op, (3, 4), &y, &mut x, &params).is_err());
    assert!(refine_surfaces(&op, (g.m, g.n), &y[1..], &mut x, &params).is_err());
    let mut nan = y.clone();
    nan[0] = f64::NAN;
    assert!(refine_surfaces(&op, (g.m, g.n), &nan, &mut x, &params).is_err());
}
