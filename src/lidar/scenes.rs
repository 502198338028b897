//! Scene generators: the paper's three-reflector experiment, random opaque and semi-transparent
//! scenes, scenes read from PNG depth maps, and inverse-square attenuation.
//!
//! Every generator returns a [`Scene`] (reflectivity cube `x[m, n, j]`); the random ones draw from a
//! ChaCha8 generator seeded with the given seed, so equal seeds give equal scenes.

use std::ops::RangeInclusive;

use ndarray::{Array2, Array3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Error, Result};
use crate::real::Real;

use super::geometry::Geometry;
use super::scene::{DepthMap, Scene, NO_RETURN};

/// Validates a geometry whose fields may have been set directly, and checks that every depth bin
/// fits the `i32` of a [`DepthMap`].
pub(crate) fn checked(g: Geometry) -> Result<Geometry> {
    let g = Geometry::new(g.m, g.n, g.ks)?;
    if i32::try_from(g.ks).is_err() {
        return Err(Error::param(
            "size",
            format!(
                "{} depth bins exceed the depth-map range ({})",
                g.ks,
                i32::MAX
            ),
        ));
    }
    Ok(g)
}

// Placement of the paper's reflectors, in fractions of the rows (u), columns (v) and depth range.
// A pixel (i, j) belongs to a region when its centre ((i + ½)/M, (j + ½)/N) does.

/// Square: rows [0.15, 0.55), columns [0.10, 0.45), depth 0.3, reflectivity 0.9.
const SQUARE_ROWS: (f64, f64) = (0.15, 0.55);
const SQUARE_COLS: (f64, f64) = (0.10, 0.45);
const SQUARE_DEPTH: f64 = 0.3;
const SQUARE_REFLECTIVITY: f64 = 0.9;

/// Disk: centre (0.35·M, 0.70·N), radius 0.2·min(M, N) pixels, depth 0.6, reflectivity 0.6.
const DISK_CENTRE: (f64, f64) = (0.35, 0.70);
const DISK_RADIUS: f64 = 0.2;
const DISK_DEPTH: f64 = 0.6;
const DISK_REFLECTIVITY: f64 = 0.6;

/// Slanted plane: rows [0.50, 0.85), columns [0.05, 0.95), depth rising linearly with the column
/// from 0.2 to 0.9, reflectivity 0.4.
const PLANE_ROWS: (f64, f64) = (0.50, 0.85);
const PLANE_COLS: (f64, f64) = (0.05, 0.95);
const PLANE_DEPTH: (f64, f64) = (0.2, 0.9);
const PLANE_REFLECTIVITY: f64 = 0.4;

fn within(x: f64, (lo, hi): (f64, f64)) -> bool {
    lo <= x && x < hi
}

/// The three reflectors of [`paper_scene`], each alone on an empty background, in the order
/// square, disk, slanted plane.
///
/// Placement scales with the geometry (fractions of M, N and K_s; a pixel belongs to a reflector
/// when its centre does; a depth fraction f maps to bin `round(f·(K_s − 1))`):
///
/// | reflector     | rows (·M)    | columns (·N) | depth (·(K_s − 1))              | reflectivity |
/// |---------------|--------------|--------------|---------------------------------|--------------|
/// | square        | [0.15, 0.55) | [0.10, 0.45) | 0.3                             | 0.9          |
/// | disk          | centre 0.35, radius 0.2·min(M, N) px | centre 0.70 | 0.6     | 0.6          |
/// | slanted plane | [0.50, 0.85) | [0.05, 0.95) | 0.2 → 0.9, linear in the column | 0.4          |
///
/// The slanted plane overlaps the square (in front of it over the plane's leftmost columns, behind
/// it elsewhere) and the disk (behind it).
///
/// # Errors
/// [`Error::InvalidParameter`] if a dimension of `g` is zero, the voxel count overflows or K_s
/// exceeds `i32::MAX`.
pub fn paper_surfaces<T: Real>(g: Geometry) -> Result<[DepthMap<T>; 3]> {
    let g = checked(g)?;
    let top = (g.ks - 1) as f64;
    Ok(paper_layers(g)?.map(|(depth, reflectivity)| DepthMap {
        depth: depth.mapv(|d| {
            if d.is_nan() {
                NO_RETURN
            } else {
                d.round().clamp(0.0, top) as i32
            }
        }),
        amplitude: depth.mapv(|d| {
            if d.is_nan() {
                T::zero()
            } else {
                T::of_f64(reflectivity)
            }
        }),
    }))
}

/// The three reflectors of [`paper_surfaces`] at their continuous depths, in bins (a depth
/// fraction f is depth f·(K_s − 1), NaN where the reflector is absent), each with its
/// reflectivity.
pub(crate) fn paper_layers(g: Geometry) -> Result<[(Array2<f64>, f64); 3]> {
    let g = checked(g)?;
    let top = (g.ks - 1) as f64;
    let empty = || Array2::from_elem((g.m, g.n), f64::NAN);
    let (mut square, mut disk, mut plane) = (empty(), empty(), empty());
    let (mf, nf) = (g.m as f64, g.n as f64);
    let radius = DISK_RADIUS * mf.min(nf);
    let (cu, cv) = (DISK_CENTRE.0 * mf, DISK_CENTRE.1 * nf);
    for i in 0..g.m {
        let u = (i as f64 + 0.5) / mf;
        for j in 0..g.n {
            let v = (j as f64 + 0.5) / nf;
            if within(u, SQUARE_ROWS) && within(v, SQUARE_COLS) {
                square[[i, j]] = SQUARE_DEPTH * top;
            }
            let (du, dv) = (i as f64 + 0.5 - cu, j as f64 + 0.5 - cv);
            if du * du + dv * dv <= radius * radius {
                disk[[i, j]] = DISK_DEPTH * top;
            }
            if within(u, PLANE_ROWS) && within(v, PLANE_COLS) {
                let t = (v - PLANE_COLS.0) / (PLANE_COLS.1 - PLANE_COLS.0);
                let f = PLANE_DEPTH.0 + t * (PLANE_DEPTH.1 - PLANE_DEPTH.0);
                plane[[i, j]] = f * top;
            }
        }
    }
    Ok([
        (square, SQUARE_REFLECTIVITY),
        (disk, DISK_REFLECTIVITY),
        (plane, PLANE_REFLECTIVITY),
    ])
}

/// Composites opaque layers: each pixel takes the return of the nearest layer that has one
/// (smallest depth bin; the earlier layer on equal depths), or none if no layer has one.
///
/// A pixel counts as lit in a layer by its depth (not [`NO_RETURN`]), whatever its amplitude.
///
/// # Errors
/// [`Error::InvalidParameter`] if `layers` is empty or a depth is negative other than
/// [`NO_RETURN`]; [`Error::ShapeMismatch`] if the layers (or a layer's depth and amplitude maps)
/// differ in shape.
pub fn composite_nearest<T: Real>(layers: &[DepthMap<T>]) -> Result<DepthMap<T>> {
    let first = layers
        .first()
        .ok_or_else(|| Error::param("layers", "at least one layer is required"))?;
    let (m, n) = first.depth.dim();
    for (k, layer) in layers.iter().enumerate() {
        let (lm, ln) = layer.depth.dim();
        if lm != m {
            return Err(Error::shape(
                format!("composite: rows of layer {k} vs layer 0"),
                m,
                lm,
            ));
        }
        if ln != n {
            return Err(Error::shape(
                format!("composite: columns of layer {k} vs layer 0"),
                n,
                ln,
            ));
        }
        if layer.amplitude.dim() != (m, n) {
            return Err(Error::shape(
                format!("composite: amplitude pixels of layer {k} vs its depth map"),
                m * n,
                layer.amplitude.len(),
            ));
        }
    }
    let mut out = DepthMap {
        depth: Array2::from_elem((m, n), NO_RETURN),
        amplitude: Array2::zeros((m, n)),
    };
    for (k, layer) in layers.iter().enumerate() {
        for ((i, j), &d) in layer.depth.indexed_iter() {
            if d == NO_RETURN {
                continue;
            }
            if d < 0 {
                return Err(Error::param(
                    "depth",
                    format!("layer {k}: depth bin {d} at pixel ({i}, {j}) is negative"),
                ));
            }
            let current = out.depth[[i, j]];
            if current == NO_RETURN || d < current {
                out.depth[[i, j]] = d;
                out.amplitude[[i, j]] = layer.amplitude[[i, j]];
            }
        }
    }
    Ok(out)
}

/// The paper's experiment at any size: a fronto-parallel square, a disk and a slanted plane on an
/// empty background (see [`paper_surfaces`] for their placement), the nearest surface winning where
/// they overlap, so each pixel has at most one return.
///
/// At 100×100×40 it lights 5 547 of the 10 000 pixels. Deterministic.
///
/// # Errors
/// [`Error::InvalidParameter`] if a dimension of `g` is zero, the voxel count overflows or K_s
/// exceeds `i32::MAX`.
pub fn paper_scene<T: Real>(g: Geometry) -> Result<Scene<T>> {
    let g = checked(g)?;
    composite_nearest(&paper_surfaces::<T>(g)?)?.to_scene(g.ks)
}

/// Checks a random scene's fraction of lit pixels: in [0, 1] (NaN refused).
pub(crate) fn check_lit_fraction(lit_fraction: f64) -> Result<()> {
    if !(0.0..=1.0).contains(&lit_fraction) {
        return Err(Error::param(
            "lit_fraction",
            format!(
                "must be in [0, 1], got {}",
                crate::units::number(lit_fraction)
            ),
        ));
    }
    Ok(())
}

/// A random opaque scene: each pixel is lit independently with probability `lit_fraction`, at a
/// uniformly random depth bin in `[0, K_s)` with an amplitude uniform in `[0.2, 1.0]`.
///
/// # Errors
/// [`Error::InvalidParameter`] if `lit_fraction` is not in `[0, 1]` (NaN included), a dimension of
/// `g` is zero, the voxel count overflows or K_s exceeds `i32::MAX`.
pub fn random_opaque_scene<T: Real>(g: Geometry, lit_fraction: f64, seed: u64) -> Result<Scene<T>> {
    let g = checked(g)?;
    check_lit_fraction(lit_fraction)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut map = DepthMap {
        depth: Array2::from_elem((g.m, g.n), NO_RETURN),
        amplitude: Array2::<T>::zeros((g.m, g.n)),
    };
    for (d, a) in map.depth.iter_mut().zip(map.amplitude.iter_mut()) {
        if rng.random_bool(lit_fraction) {
            *d = rng.random_range(0..g.ks) as i32;
            *a = T::of_f64(rng.random_range(0.2..=1.0));
        }
    }
    map.to_scene(g.ks)
}

/// A random semi-transparent scene: every pixel has a number of returns drawn uniformly from
/// `returns` (`min..=max`), at distinct depth bins chosen uniformly in `[0, K_s)`, with amplitudes
/// drawn uniformly in `[0.1, 1.0]` and sorted so that they do not increase with depth (the first
/// surface is the strongest; equal amplitudes need two draws that round to the same value of `T`).
///
/// # Errors
/// [`Error::InvalidParameter`] unless `1 ≤ min ≤ max ≤ K_s`, or if a dimension of `g` is zero or the
/// voxel count overflows.
pub fn semi_transparent_scene<T: Real>(
    g: Geometry,
    returns: RangeInclusive<usize>,
    seed: u64,
) -> Result<Scene<T>> {
    let g = Geometry::new(g.m, g.n, g.ks)?;
    let (lo, hi) = (*returns.start(), *returns.end());
    if lo < 1 || lo > hi || hi > g.ks {
        return Err(Error::param(
            "returns",
            format!("need 1 <= min <= max <= K_s = {}, got {lo}..={hi}", g.ks),
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut x = Array3::<T>::zeros((g.m, g.n, g.ks));
    let mut amps: Vec<f64> = Vec::with_capacity(hi);
    for mut col in x.lanes_mut(ndarray::Axis(2)) {
        let count = rng.random_range(lo..=hi);
        let mut bins = rand::seq::index::sample(&mut rng, g.ks, count).into_vec();
        bins.sort_unstable();
        amps.clear();
        amps.extend((0..count).map(|_| rng.random_range(0.1..=1.0)));
        amps.sort_unstable_by(|a, b| b.total_cmp(a));
        for (&j, &a) in bins.iter().zip(&amps) {
            col[j] = T::of_f64(a);
        }
    }
    Scene::new(x)
}

/// Inverse-square range attenuation: the voxel at depth bin j is scaled by `(near / d_j)²` with
/// `d_j = near + j`, distances measured in bin widths and `near > 0` the distance of bin 0 from the
/// sensor. Bin 0 is unchanged and deeper bins are attenuated (factor in `(0, 1]`), so values stay
/// finite; `near = 1` gives the factor `1/(j + 1)²`.
///
/// The support (the set of nonzero voxels) is preserved.
///
/// # Errors
/// [`Error::InvalidParameter`] with name `"near"` unless `near` is finite and positive, and with
/// name `"scene"` if a nonzero value would underflow to zero in `T`.
pub fn attenuate<T: Real>(scene: &Scene<T>, near: f64) -> Result<Scene<T>> {
    if !(near.is_finite() && near > 0.0) {
        return Err(Error::param(
            "near",
            format!(
                "must be finite and positive, got {}",
                crate::units::number(near)
            ),
        ));
    }
    let mut x = scene.data().clone();
    for ((i, j, k), v) in x.indexed_iter_mut() {
        if *v == T::zero() {
            continue;
        }
        let f = near / (near + k as f64);
        let out = T::of_f64(v.as_f64() * f * f);
        if out == T::zero() {
            return Err(Error::param(
                "scene",
                format!("value {v} at voxel ({i}, {j}, {k}) underflows to zero when attenuated"),
            ));
        }
        *v = out;
    }
    Scene::new(x)
}
