//! The surface rule of the model-based detections: a return that continues a surface of
//! neighbouring returns needs less evidence of its own than an isolated one.
//!
//! A reflector's amplitude test weighs one pixel's data alone. Where the measurements per lit
//! pixel are few or the noise is strong, the standard error of a true return's amplitude is a
//! sizeable fraction of the amplitude, and a bar high enough to keep noise out of the K_s depths of
//! every empty pixel (about 3.7 standard errors) drops a large share of the true returns. Surfaces
//! are what tells them apart: a false detection in an empty region lands at a random one of K_s
//! depths, so it rarely has several neighbours whose returns lie within one bin of it, while a
//! return inside a surface has most of its eight neighbours there. The final test turns the
//! rule round: a return with no neighbour on its surface must stand out far more than the
//! standard errors alone would ask.

use crate::space::{self, Space};

/// The surface rule: on a `(rows, columns)` grid of pixels (this part's rows of an image split by
/// rows), a return passes at `z` standard errors when at least `neighbours` of its pixel's eight
/// neighbours hold a return within one bin of its depth that passes at `z` too; at the final
/// test, a return with no such neighbour needs `isolated_z`. A pixel outside the support joins at
/// `z` robust standard deviations of the correlations, within one bin of the depth where at
/// least `join` of its neighbours hold returns that pass the final test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SurfaceRule {
    pub grid: (usize, usize),
    pub z: f64,
    pub neighbours: usize,
    pub join: usize,
    pub isolated_z: f64,
}

/// This part's depth map of the voxels flagged in `passing` (the first of a pixel's, −1 where
/// there is none) with the rows above and below it fetched from the neighbouring parts: (the
/// map, the row of this part's first row in it, its rows). A collective call when the space is
/// split.
fn depth_rows(
    space: &dyn Space,
    (rows, n): (usize, usize),
    ks: usize,
    voxels: &[usize],
    passing: &[bool],
) -> (Vec<f64>, usize, usize) {
    let mut depth = vec![-1.0; rows * n];
    for (&v, _) in voxels.iter().zip(passing).filter(|(_, p)| **p) {
        if let Some(d) = depth.get_mut(v / ks) {
            if *d < 0.0 {
                *d = (v % ks) as f64;
            }
        }
    }
    let (above, below) = space::neighbour_rows(space, &depth, n, 1);
    let first = above.len() / n.max(1);
    let mut map = above;
    map.extend_from_slice(&depth);
    map.extend_from_slice(&below);
    let all_rows = map.len() / n.max(1);
    (map, first, all_rows)
}

/// The depths of the eight neighbours of pixel (`i`, `j`) of `map` (`all_rows` rows of `n`) that
/// hold a return: the first `count` entries of the array.
fn neighbour_depths(
    map: &[f64],
    (i, j): (usize, usize),
    n: usize,
    all_rows: usize,
) -> ([f64; 8], usize) {
    let (mut out, mut count) = ([0.0; 8], 0);
    for a in i.saturating_sub(1)..(i + 2).min(all_rows) {
        for b in j.saturating_sub(1)..(j + 2).min(n) {
            let e = map[a * n + b];
            if (a, b) != (i, j) && e >= 0.0 {
                out[count] = e;
                count += 1;
            }
        }
    }
    (out, count)
}

/// How many of `depths` (in columns) lie within one bin (`per_bin` columns) of `d`.
fn within_one(depths: &[f64], d: f64, per_bin: usize) -> usize {
    let reach = per_bin as f64;
    depths.iter().filter(|e| (**e - d).abs() <= reach).count()
}

/// For each voxel of `voxels` (at most one per pixel of `ks` voxels), how many of its pixel's
/// eight neighbours hold a voxel flagged in `passing` within one bin of its depth.
/// The rows of the parts above and below are fetched from them (a collective call when the space
/// is split).
pub(crate) fn on_surface(
    space: &dyn Space,
    grid: (usize, usize),
    ks: usize,
    voxels: &[usize],
    passing: &[bool],
    per_bin: usize,
) -> Vec<usize> {
    let n = grid.1;
    let (map, first, all_rows) = depth_rows(space, grid, ks, voxels, passing);
    voxels
        .iter()
        .map(|&v| {
            let p = v / ks;
            let (near, count) = neighbour_depths(&map, (p / n + first, p % n), n, all_rows);
            within_one(&near[..count], (v % ks) as f64, per_bin)
        })
        .collect()
}

/// For each pixel of this part's `grid`, the depth of the surface its neighbours' returns (the
/// `voxels` flagged in `passing`) form around it: of the neighbours' depths, the one with the most
/// neighbours' returns within one bin of it (the shallower among equals), when at least `need`
/// are. A collective call when the space is split.
pub(crate) fn surface_depths(
    space: &dyn Space,
    grid: (usize, usize),
    ks: usize,
    voxels: &[usize],
    passing: &[bool],
    need: usize,
    per_bin: usize,
) -> Vec<Option<usize>> {
    let (rows, n) = grid;
    let (map, first, all_rows) = depth_rows(space, grid, ks, voxels, passing);
    (0..rows * n)
        .map(|p| {
            let (near, count) = neighbour_depths(&map, (p / n + first, p % n), n, all_rows);
            let near = &near[..count];
            let mut best: Option<(usize, f64)> = None;
            for &d in near {
                let c = within_one(near, d, per_bin);
                if best.is_none_or(|(bc, bd)| c > bc || c == bc && d < bd) {
                    best = Some((c, d));
                }
            }
            best.filter(|&(c, _)| need > 0 && c >= need)
                .map(|(_, d)| d as usize)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::space::Whole;

    #[test]
    fn the_surface_depth_is_where_most_neighbours_agree() {
        // A 3×3 grid of 8 depths: the top row at 5, 5, 6, the left at 2, the right at 6.
        let ks = 8;
        let at = |i: usize, j: usize, d: usize| (i * 3 + j) * ks + d;
        let voxels = vec![
            at(0, 0, 5),
            at(0, 1, 5),
            at(0, 2, 6),
            at(1, 0, 2),
            at(1, 2, 6),
        ];
        let all = vec![true; voxels.len()];
        let got = surface_depths(&Whole, (3, 3), ks, &voxels, &all, 3, 1);
        // The centre: 5, 5, 6, 6 lie within one bin of 5 (and of 6); the shallower wins.
        assert_eq!(got[4], Some(5));
        assert_eq!(
            surface_depths(&Whole, (3, 3), ks, &voxels, &all, 5, 1)[4],
            None
        );
        // (2, 1) sees (1, 0) at 2 and (1, 2) at 6 only: one each.
        assert_eq!(got[7], None);
        assert_eq!(
            surface_depths(&Whole, (3, 3), ks, &voxels, &all, 1, 1)[7],
            Some(2)
        );
        // Need 0 means no rule.
        assert!(surface_depths(&Whole, (3, 3), ks, &voxels, &all, 0, 1)
            .iter()
            .all(Option::is_none));
    }

    #[test]
    fn counts_neighbours_within_one_bin_that_pass() {
        // A 3×3 grid of 4 depths; the centre at depth 2.
        let ks = 4;
        let at = |i: usize, j: usize, d: usize| (i * 3 + j) * ks + d;
        let centre = at(1, 1, 2);
        let voxels = vec![at(0, 0, 1), at(0, 1, 3), at(0, 2, 0), at(1, 0, 2), centre];
        let all = vec![true; voxels.len()];
        let got = on_surface(&Whole, (3, 3), ks, &voxels, &all, 1);
        // The centre's neighbours within one bin: depths 1, 3 and 2 (not 0).
        assert_eq!(got[4], 3);
        // The corner (0, 0) at depth 1 sees (0, 1) at 3 (no), (1, 0) at 2 and the centre at 2;
        // (0, 2) at depth 0 sees (0, 1) at 3 (no) and the centre at 2 (no).
        assert_eq!(got[0], 2);
        assert_eq!(got[2], 0);
        // A neighbour that does not pass does not count, wherever it is.
        let mut some = all.clone();
        some[1] = false;
        assert_eq!(on_surface(&Whole, (3, 3), ks, &voxels, &some, 1)[4], 2);
        some[4] = false;
        assert_eq!(on_surface(&Whole, (3, 3), ks, &voxels, &some, 1)[0], 1);
    }

    /// With 4 columns per bin (a dictionary of responses shifted by a quarter bin), one bin is
    /// 4 columns: the same scene with every depth times 4 counts the same neighbours, and its
    /// surface depths are the same depths times 4.
    #[test]
    fn one_bin_is_columns_per_bin_columns() {
        let ks = 4;
        let at = |i: usize, j: usize, d: usize, ks: usize| (i * 3 + j) * ks + d;
        let scene = [(0, 0, 1), (0, 1, 3), (0, 2, 0), (1, 0, 2), (1, 1, 2)];
        let voxels: Vec<usize> = scene.iter().map(|&(i, j, d)| at(i, j, d, ks)).collect();
        let fine: Vec<usize> = scene
            .iter()
            .map(|&(i, j, d)| at(i, j, 4 * d, 4 * ks))
            .collect();
        let all = vec![true; voxels.len()];
        assert_eq!(
            on_surface(&Whole, (3, 3), ks, &voxels, &all, 1),
            on_surface(&Whole, (3, 3), 4 * ks, &fine, &all, 4)
        );
        // Counted in columns, only the centre's neighbour at its own depth is within one.
        assert_eq!(on_surface(&Whole, (3, 3), 4 * ks, &fine, &all, 1)[4], 1);
        let coarse = surface_depths(&Whole, (3, 3), ks, &voxels, &all, 2, 1);
        let scaled: Vec<Option<usize>> = coarse.iter().map(|d| d.map(|d| 4 * d)).collect();
        assert!(coarse.iter().any(Option::is_some));
        assert_eq!(
            surface_depths(&Whole, (3, 3), 4 * ks, &fine, &all, 2, 4),
            scaled
        );
    }
}
