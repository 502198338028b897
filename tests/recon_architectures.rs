//! Reconstruction on the paper's architectures: G ADCs through the stacked lidar operator (its
//! lidar capabilities against the sums over its parts, every solver on it), and a tiled array
//! reconstructed tile by tile on the tiles' own grids, stitched in place.

use std::sync::{Arc, Mutex};

use rdlidar::lidar::{
    paper_scene, pixel_groups, random_opaque_scene, tiles, Codes, Geometry, LidarOperator,
    MultiAdcOperator, Pulse, RdOperator, Scene, TileSize,
};
use rdlidar::operator::{dot_test, LinearOperator, VoxelOperator};
use rdlidar::recon::{compare, reconstruct, tile_places, Method, ReconstructOptions, TiledArray};

use crate::common::random_vec;

fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    (num / den.max(1e-300)).sqrt()
}

fn stacked(g: Geometry, kp: usize, sets: u64, seed: u64) -> MultiAdcOperator<f64> {
    let p = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
    let codes = (0..sets)
        .map(|s| Arc::new(Codes::random_binary(g.pixels(), g.samples(kp), seed + 1 + s).unwrap()))
        .collect();
    MultiAdcOperator::new(g, &p, codes).unwrap()
}

#[test]
fn the_stacked_operator_is_the_sum_of_its_parts_in_every_lidar_capability() {
    let g = Geometry::new(5, 3, 7).unwrap();
    let op = stacked(g, 41, 3, 5);
    let k = g.samples(41);
    assert_eq!(
        (op.nrows(), op.ncols(), op.code_sets()),
        (3 * k, g.voxels(), 3)
    );
    assert!(dot_test(&op, 1).unwrap().gap < 1e-12);
    let x = random_vec(g.voxels(), 2);
    let r = random_vec(3 * k, 3);
    let parts = op.parts();
    // Forward: each part's rows; sparse forward: the same.
    let mut y = vec![0.0; 3 * k];
    op.apply(&x, &mut y);
    let mut sparse_x = vec![0.0; g.voxels()];
    for i in [0, 9, 30, 31, 100] {
        sparse_x[i] = x[i];
    }
    let (mut ys, mut yd) = (vec![0.0; 3 * k], vec![0.0; 3 * k]);
    op.apply_sparse(&sparse_x, &mut ys);
    op.apply(&sparse_x, &mut yd);
    assert!(rel_diff(&ys, &yd) < 1e-12);
    // Adjoint, correlation and the zero-mean adjoint: sums over the parts.
    let (mut adj, mut cor, mut zm) = (
        vec![0.0; g.voxels()],
        vec![0.0; g.voxels()],
        vec![0.0; g.voxels()],
    );
    op.apply_adjoint(&r, &mut adj);
    op.correlate(&r, &mut cor);
    op.zero_mean_operator().apply_adjoint(&r, &mut zm);
    let (mut want_adj, mut want_cor) = (vec![0.0; g.voxels()], vec![0.0; g.voxels()]);
    for (i, part) in parts.iter().enumerate() {
        let rows = &r[i * k..(i + 1) * k];
        let mut yi = vec![0.0; k];
        part.apply(&x, &mut yi);
        assert!(rel_diff(&y[i * k..(i + 1) * k], &yi) < 1e-14);
        let mut u = vec![0.0; g.voxels()];
        part.apply_adjoint(rows, &mut u);
        want_adj.iter_mut().zip(&u).for_each(|(a, b)| *a += b);
        part.apply_adjoint_debiased(rows, &mut u);
        want_cor.iter_mut().zip(&u).for_each(|(a, b)| *a += b);
    }
    assert!(rel_diff(&adj, &want_adj) < 1e-12);
    assert!(rel_diff(&cor, &want_cor) < 1e-12);
    assert!(rel_diff(&zm, &want_cor) < 1e-12);
    // Gram blocks and column norms: sums of the parts' (their squares for the norms).
    let gram = op.pixel_gram(4);
    let want: Vec<f64> = (0..gram.len())
        .map(|i| parts.iter().map(|p| p.pixel_gram(4)[i]).sum())
        .collect();
    assert!(rel_diff(&gram, &want) < 1e-14);
    assert!(op.uniform_pixel_gram());
    let cols = [0, 8, 50];
    let norms = op.column_norms(&cols);
    for (n, &c) in norms.iter().zip(&cols) {
        let mut e = vec![0.0; g.voxels()];
        e[c] = 1.0;
        let mut a = vec![0.0; 3 * k];
        op.apply(&e, &mut a);
        let direct = a.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(
            (n - direct).abs() < 1e-10 * direct,
            "column {c}: {n} vs {direct}"
        );
    }
    // Self-correlations: what the correlation of a column's own image gives in its pixel.
    let voxels = [3, 17];
    let own = op.self_correlations(&voxels);
    for (row, &c) in own.chunks(g.ks).zip(&voxels) {
        let mut e = vec![0.0; g.voxels()];
        e[c] = 1.0;
        let mut a = vec![0.0; 3 * k];
        op.apply(&e, &mut a);
        let mut u = vec![0.0; g.voxels()];
        op.correlate(&a, &mut u);
        let p0 = c / g.ks * g.ks;
        assert!(rel_diff(row, &u[p0..p0 + g.ks]) < 1e-10, "voxel {c}");
    }
    // The support operator: the columns of the full operator.
    let support = vec![2, 9, 40];
    let restricted = op.restrict_columns(support.clone()).unwrap();
    let v = [0.5, -1.0, 2.0];
    let mut full_x = vec![0.0; g.voxels()];
    for (&c, &a) in support.iter().zip(&v) {
        full_x[c] = a;
    }
    let (mut y1, mut y2) = (vec![0.0; 3 * k], vec![0.0; 3 * k]);
    restricted.apply(&v, &mut y1);
    op.apply(&full_x, &mut y2);
    assert!(rel_diff(&y1, &y2) < 1e-12);
    assert!(dot_test(restricted.as_ref(), 4).unwrap().gap < 1e-12);
}

#[test]
fn every_solver_runs_on_several_adcs_and_auto_is_exact_where_one_adc_is() {
    // 2 ADCs of K_p 300: 614 measurements for 62 returns. The same problem with one ADC of
    // twice the pulse length is exact with auto; so must the stacked one be.
    let g = Geometry::new(12, 10, 8).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    let op = stacked(g, 300, 2, 21);
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    let options = ReconstructOptions::default();
    for method in Method::ALL {
        let r = reconstruct(&op, &y, method, &options).unwrap();
        assert!(r.scene.as_slice().iter().all(|v| v.is_finite()), "{method}");
        let m = compare(&truth, &r.scene, 200e-12).unwrap();
        if matches!(
            method,
            Method::Auto | Method::SupportLs | Method::ModelBased | Method::Tv | Method::Fista
        ) {
            assert!(m.relative_error < 1e-6, "{method}: {m}");
            assert_eq!(m.returns_false, 0, "{method}: {m}");
        }
    }
    // A single ADC with these 307 samples cannot do it: the second ADC's rows matter.
    let one = RdOperator::new(g, op.pulse().to_vec(), op.parts()[0].codes().clone()).unwrap();
    let k = one.nrows();
    let r = reconstruct(&one, &y[..k], Method::SupportLs, &options).unwrap();
    let m = compare(&truth, &r.scene, 200e-12).unwrap();
    assert!(m.relative_error > 1e-3, "one ADC alone: {m}");
}

#[test]
fn the_backprojection_of_g_adcs_is_normalized_by_their_gain() {
    // In the redundant regime the debiased backprojection estimates the amplitudes, with one
    // ADC or several: the normalization must count the code sets.
    let g = Geometry::new(2, 2, 4).unwrap();
    let truth = random_opaque_scene::<f64>(g, 1.0, 3).unwrap();
    let op = stacked(g, 4000, 3, 8);
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    let r = reconstruct(
        &op,
        &y,
        Method::BackprojectionDebiased,
        &ReconstructOptions::default(),
    )
    .unwrap();
    let m = compare(&truth, &r.scene, 200e-12).unwrap();
    assert_eq!(m.returns_exact, m.true_returns, "{m}");
    assert!(m.relative_error < 0.1, "{m}");
}

/// An asymmetric 13×11 array in tiles of 5×4: clipped edge tiles at the bottom and the right.
fn tiled_problem(kp: usize) -> (Geometry, Vec<f64>, Codes, TileSize, Scene<f64>, Vec<f64>) {
    let g = Geometry::new(13, 11, 6).unwrap();
    let truth = random_opaque_scene::<f64>(g, 0.6, 17).unwrap();
    let p = Pulse::<f64>::bernoulli(kp, 5).unwrap().into_inner();
    let codes = Codes::random_binary(g.pixels(), g.samples(kp), 6).unwrap();
    let t = TileSize { m: 5, n: 4 };
    let groups = tiles(g, t.m, t.n).unwrap();
    let op = pixel_groups(g, &p, &codes, &groups).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    (g, p, codes, t, truth, y)
}

#[test]
fn tile_places_cover_the_array_row_major_with_clipped_edges() {
    let g = Geometry::new(13, 11, 6).unwrap();
    let places = tile_places(g, TileSize { m: 5, n: 4 }).unwrap();
    assert_eq!(places.len(), 9);
    let dims: Vec<(usize, usize, usize, usize)> = places
        .iter()
        .map(|p| (p.row, p.col, p.geometry.m, p.geometry.n))
        .collect();
    assert_eq!(
        dims,
        vec![
            (0, 0, 5, 4),
            (0, 4, 5, 4),
            (0, 8, 5, 3),
            (5, 0, 5, 4),
            (5, 4, 5, 4),
            (5, 8, 5, 3),
            (10, 0, 3, 4),
            (10, 4, 3, 4),
            (10, 8, 3, 3)
        ]
    );
    // The same pixels, in the same order, as the tiles the simulation sums.
    let groups = tiles(g, 5, 4).unwrap();
    for (p, group) in places.iter().zip(&groups) {
        assert_eq!(&p.pixels(g), group, "tile {}", p.index);
    }
}

#[test]
fn a_tiled_array_is_reconstructed_tile_by_tile_and_stitched_in_place() {
    let (g, p, codes, t, truth, y) = tiled_problem(200);
    let tiled = TiledArray::new(g, &p, &codes, t).unwrap();
    let seen = Mutex::new(Vec::new());
    let r = tiled
        .reconstruct(&y, Method::Auto, &ReconstructOptions::default(), &|tile| {
            seen.lock().unwrap().push(tile.place.index)
        })
        .unwrap();
    let mut seen = seen.into_inner().unwrap();
    seen.sort_unstable();
    assert_eq!(seen, (0..9).collect::<Vec<_>>(), "every tile reported once");
    let m = compare(&truth, &r.scene, 200e-12).unwrap();
    assert!(m.relative_error < 1e-6, "{m}");
    assert_eq!(r.depth.depth, truth.depth_map().depth);
    // Each tile's scene is the truth's block at the tile's place, on the tile's own grid.
    for tile in &r.tiles {
        let pl = tile.place;
        let est = tile.reconstruction.scene.data();
        for i in 0..pl.geometry.m {
            for j in 0..pl.geometry.n {
                for d in 0..g.ks {
                    let want = truth.data()[[pl.row + i, pl.col + j, d]];
                    assert!((est[[i, j, d]] - want).abs() < 1e-6, "tile {}", pl.index);
                }
            }
        }
    }
    // TV works on each tile's own 2-D grid.
    let tv = tiled
        .reconstruct(&y, Method::Tv, &ReconstructOptions::default(), &|_| {})
        .unwrap();
    for tile in &tv.tiles {
        assert_eq!(tile.reconstruction.scene.geometry(), tile.place.geometry);
    }
    let mtv = compare(&truth, &tv.scene, 200e-12).unwrap();
    assert_eq!(mtv.returns_exact, mtv.true_returns, "{mtv}");
}

#[test]
fn a_tiled_array_refuses_measurements_and_codes_that_do_not_fit() {
    let (g, p, codes, t, _, y) = tiled_problem(60);
    let tiled = TiledArray::new(g, &p, &codes, t).unwrap();
    let e = tiled
        .reconstruct(
            &y[..y.len() - 1],
            Method::Auto,
            &ReconstructOptions::default(),
            &|_| {},
        )
        .unwrap_err()
        .to_string();
    assert!(e.contains("9 tiles"), "{e}");
    let other = Geometry::new(11, 13, 6).unwrap();
    let e = TiledArray::new(Geometry::new(12, 11, 6).unwrap(), &p, &codes, t)
        .unwrap_err()
        .to_string();
    assert!(e.contains("143") && e.contains("132"), "{e}");
    // Same pixel count, another shape: accepted (the codes are per pixel), and the tiles follow
    // the given grid.
    assert_eq!(
        TiledArray::new(other, &p, &codes, t)
            .unwrap()
            .places()
            .len(),
        12
    );
}

#[test]
fn codes_know_which_pixels_reach_an_adc() {
    let codes = Codes::random_binary(11, 30, 2).unwrap();
    assert_eq!(codes.observed_pixels(), vec![true; 11]);
    let mut dense = codes.to_dense();
    for p in [0, 7, 8, 10] {
        dense.row_mut(p).fill(0);
    }
    dense[[7, 29]] = -1; // one nonzero code is enough to be observed
    let masked = Codes::from_dense(dense.view()).unwrap();
    let want: Vec<bool> = (0..11).map(|p| ![0, 8, 10].contains(&p)).collect();
    assert_eq!(masked.observed_pixels(), want);
}

#[test]
fn blocked_pixels_are_unobserved_and_observed_ones_exact() {
    let g = Geometry::new(9, 8, 6).unwrap();
    let truth = paper_scene::<f64>(g).unwrap();
    let kp = 400;
    let p = Pulse::<f64>::bernoulli(kp, 1).unwrap().into_inner();
    let codes = Codes::random_binary(g.pixels(), g.samples(kp), 2).unwrap();
    let active: Vec<usize> = (0..g.pixels()).filter(|p| p % 3 != 1).collect();
    let mut dense = codes.to_dense();
    for p in (0..g.pixels()).filter(|p| p % 3 == 1) {
        dense.row_mut(p).fill(0);
    }
    let op = RdOperator::new(
        g,
        p.clone(),
        Arc::new(Codes::from_dense(dense.view()).unwrap()),
    )
    .unwrap();
    // The measurements of the coded aperture as the architecture builds it.
    let aperture = rdlidar::lidar::coded_aperture(g, &p, &codes, &active).unwrap();
    let mut y = vec![0.0; aperture.nrows()];
    aperture.apply(truth.as_slice(), &mut y);
    for method in [Method::Auto, Method::Tv, Method::Backprojection] {
        let r = reconstruct(&op, &y, method, &ReconstructOptions::default()).unwrap();
        let td = truth.depth_map().depth;
        for (i, (&d, &t)) in r.depth.depth.iter().zip(&td).enumerate() {
            if i % 3 == 1 {
                assert_eq!(d, rdlidar::lidar::UNOBSERVED, "{method}: pixel {i}");
            } else if method != Method::Backprojection {
                assert_eq!(d, t, "{method}: pixel {i}");
            }
        }
        assert_eq!(r.depth.unobserved(), g.pixels() - active.len());
        assert!(r.depth.lit() + r.depth.unobserved() <= g.pixels());
    }
}

#[test]
fn unobserved_pixels_are_filled_from_their_neighbours() {
    use rdlidar::lidar::{DepthMap, NO_RETURN, UNOBSERVED};
    // A plane at depth 4 on the left, empty on the right; holes inside the plane (a 3x3 block,
    // filled inwards), on the border between the two, and in the empty part.
    let depth = ndarray::Array2::from_shape_fn((7, 8), |(_, j)| if j < 5 { 4 } else { NO_RETURN });
    let amplitude = depth.mapv(|d| if d >= 0 { 0.5f64 } else { 0.0 });
    let mut map = DepthMap { depth, amplitude };
    let truth = map.clone();
    let holes = [
        (1, 1),
        (1, 2),
        (1, 3),
        (2, 1),
        (2, 2),
        (2, 3),
        (3, 1),
        (3, 2),
        (3, 3),
        (5, 7),
    ];
    for &(i, j) in &holes {
        map.depth[[i, j]] = UNOBSERVED;
        map.amplitude[[i, j]] = 0.0;
    }
    assert_eq!(map.unobserved(), holes.len());
    let filled = map.fill_unobserved();
    assert_eq!(filled, 9);
    assert_eq!(map.unobserved(), 0);
    assert_eq!(map.depth, truth.depth);
    assert!(map
        .amplitude
        .iter()
        .zip(&truth.amplitude)
        .all(|(a, b)| (a - b).abs() < 1e-12));
    // Nothing observed: nothing to fill from.
    let mut blind = DepthMap::<f64> {
        depth: ndarray::Array2::from_elem((3, 3), UNOBSERVED),
        amplitude: ndarray::Array2::zeros((3, 3)),
    };
    assert_eq!(blind.fill_unobserved(), 0);
    assert_eq!(blind.unobserved(), 9);
    // The scene of a map with unobserved pixels has nothing there.
    let scene = blind.to_scene(4).unwrap();
    assert_eq!(scene.nnz(), 0);
}
