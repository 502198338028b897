//! Reconstruction of a tiled array (the paper's §3): the M×N array is split into tiles of A×B
//! pixels with one ADC each, so the operator is block-diagonal and every tile is an independent
//! lidar problem on its own 2-D grid. [`TiledArray::reconstruct`] solves the tiles in parallel, each
//! with its true neighbourhood (TV's prior works inside a tile), and stitches the depth maps
//! and scenes.

use std::ops::Range;
use std::time::{Duration, Instant};

use std::sync::atomic::AtomicBool;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::lidar::{
    Cancellable, Codes, DepthMap, Geometry, RdOperator, Regime, Scene, SeededCodes, TileSize,
};
use crate::operator::Applies;
use crate::real::Real;

use super::method::Method;
use super::options::ReconstructOptions;
use super::reconstruct::{reconstruct_observed, Reconstruction};
use crate::solver::{Control, IterationInfo, Report, Termination};

/// Where a tile lies in the array: its first pixel row and column and its own grid (edge tiles
/// are clipped).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TilePlace {
    /// Index of the tile, row-major over the tiles (the row of its measurements).
    pub index: usize,
    /// First pixel row of the tile in the array.
    pub row: usize,
    /// First pixel column of the tile in the array.
    pub col: usize,
    /// The tile's grid: its pixel rows and columns, and K_s.
    pub geometry: Geometry,
}

impl TilePlace {
    /// The array's pixel indices (row-major) of the tile's pixels, in the tile's row-major
    /// order: the order of [`tiles`](crate::lidar::tiles).
    pub fn pixels(&self, array: Geometry) -> Vec<usize> {
        let g = self.geometry;
        (0..g.m)
            .flat_map(|i| (0..g.n).map(move |j| (self.row + i) * array.n + self.col + j))
            .collect()
    }
}

/// The tiles of A×B pixels of an array, row-major, edge tiles clipped.
///
/// # Errors
/// Only the errors of [`Geometry::new`] (none for a valid array).
pub fn tile_places(array: Geometry, tile: TileSize) -> Result<Vec<TilePlace>> {
    let mut out = Vec::new();
    for row in (0..array.m).step_by(tile.m) {
        for col in (0..array.n).step_by(tile.n) {
            let geometry = Geometry::new(
                tile.m.min(array.m - row),
                tile.n.min(array.n - col),
                array.ks,
            )?;
            out.push(TilePlace {
                index: out.len(),
                row,
                col,
                geometry,
            });
        }
    }
    Ok(out)
}

/// One tile's reconstruction.
#[derive(Debug, Clone, PartialEq)]
pub struct TileReconstruction<T> {
    /// Where the tile lies.
    pub place: TilePlace,
    /// The tile's reconstruction on its own grid.
    pub reconstruction: Reconstruction<T>,
}

/// What [`TiledArray::reconstruct`] returns: the stitched estimate and every tile's reconstruction.
#[derive(Debug, Clone, PartialEq)]
pub struct TiledReconstruction<T> {
    /// Every return found, stitched into the M×N×K_s array.
    pub scene: Scene<T>,
    /// Its depth map (each pixel's strongest return).
    pub depth: DepthMap<T>,
    /// The tiles, in row-major order.
    pub tiles: Vec<TileReconstruction<T>>,
    /// Wall-clock time of the whole reconstruction.
    pub elapsed: Duration,
}

impl<T> TiledReconstruction<T> {
    /// How many tiles each method produced (for [`Method::Auto`], the stage it kept), in the
    /// order of [`Method::ALL`].
    pub fn methods_used(&self) -> Vec<(Method, usize)> {
        Method::ALL
            .iter()
            .map(|&m| {
                let n = self
                    .tiles
                    .iter()
                    .filter(|t| t.reconstruction.method_used == m)
                    .count();
                (m, n)
            })
            .filter(|&(_, n)| n > 0)
            .collect()
    }

    /// The regime of a tile's measurements against its unknowns (every tile has K samples;
    /// the largest tile has the most unknowns).
    pub fn regime(&self) -> Regime {
        self.tiles
            .iter()
            .map(|t| t.reconstruction.regime)
            .min_by_key(|r| match r {
                Regime::Compressive => 0,
                Regime::Critical => 1,
                Regime::Redundant => 2,
            })
            .unwrap_or(Regime::Compressive)
    }

    /// The sum over the tiles of the forward, adjoint and support applications.
    pub fn applies(&self) -> Applies {
        self.tiles
            .iter()
            .filter_map(|t| t.reconstruction.report.as_ref())
            .map(Report::applies)
            .sum()
    }
}

/// The codes of a tiled array: held in memory for the whole array, or described by a seed and
/// generated tile by tile (memory proportional to the tiles being solved).
#[derive(Debug, Clone, Copy)]
pub enum ArrayCodes<'a> {
    /// Packed codes of every pixel.
    Packed(&'a Codes),
    /// Codes regenerated from their seed (one code set) for each tile's pixels.
    Seeded(SeededCodes),
}

impl<'a> From<&'a Codes> for ArrayCodes<'a> {
    fn from(c: &'a Codes) -> Self {
        ArrayCodes::Packed(c)
    }
}

impl From<SeededCodes> for ArrayCodes<'_> {
    fn from(c: SeededCodes) -> Self {
        ArrayCodes::Seeded(c)
    }
}

impl ArrayCodes<'_> {
    fn pixels(&self) -> usize {
        match self {
            ArrayCodes::Packed(c) => c.pixels(),
            ArrayCodes::Seeded(c) => c.pixels(),
        }
    }

    fn len(&self) -> usize {
        match self {
            ArrayCodes::Packed(c) => c.len(),
            ArrayCodes::Seeded(c) => c.len(),
        }
    }

    fn select(&self, pixels: &[usize]) -> Result<Codes> {
        match self {
            ArrayCodes::Packed(c) => c.select_pixels(pixels),
            ArrayCodes::Seeded(c) => c.select(0, pixels),
        }
    }

    fn observed_pixels(&self) -> Vec<bool> {
        match self {
            ArrayCodes::Packed(c) => c.observed_pixels(),
            ArrayCodes::Seeded(c) => vec![true; c.pixels()],
        }
    }
}

/// A tiled array (the paper's §3): one code set for the M×N array, one ADC per tile of A×B
/// pixels (row-major tiles, edge tiles clipped), as `simulate --tiles` writes it.
#[derive(Debug, Clone, Copy)]
pub struct TiledArray<'a, T> {
    array: Geometry,
    pulse: &'a [T],
    codes: ArrayCodes<'a>,
    tile: TileSize,
    cancel: Option<&'a AtomicBool>,
    /// The tiles to solve, from the first to before the second (all when None).
    only: Option<(usize, usize)>,
}

impl<'a, T: Real> TiledArray<'a, T> {
    /// The array `array` with the pulse `pulse`, the codes `codes` of all its pixels (packed,
    /// or described by a seed) and tiles of `tile` pixels.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if `codes` do not have the array's pixels.
    pub fn new(
        array: Geometry,
        pulse: &'a [T],
        codes: impl Into<ArrayCodes<'a>>,
        tile: TileSize,
    ) -> Result<Self> {
        let codes = codes.into();
        if codes.pixels() != array.pixels() {
            return Err(Error::shape(
                "tiled array: code pixels vs M·N",
                array.pixels(),
                codes.pixels(),
            ));
        }
        Ok(TiledArray {
            array,
            pulse,
            codes,
            tile,
            cancel: None,
            only: None,
        })
    }

    /// The same array of which [`TiledArray::reconstruct`] solves only the tiles numbered
    /// `tiles` (this process's share of a split over processes): the others are left empty in
    /// the stitched result and missing from its tiles.
    pub fn only(self, tiles: Range<usize>) -> Self {
        TiledArray {
            only: Some((tiles.start, tiles.end)),
            ..self
        }
    }

    /// The same array whose reconstructions stop within one application once `flag` is
    /// raised (see [`Cancellable`]).
    pub fn cancelled_by(self, flag: &'a AtomicBool) -> Self {
        TiledArray {
            cancel: Some(flag),
            ..self
        }
    }

    /// The tiles, row-major.
    pub fn places(&self) -> Vec<TilePlace> {
        tile_places(self.array, self.tile).expect("tiles of a valid array are valid")
    }

    /// Samples per tile (one ADC each): K = K_p + K_s − 1.
    pub fn samples(&self) -> usize {
        self.codes.len()
    }

    /// The one-ADC operator of a tile on the tile's own grid, with its pixels' codes.
    ///
    /// # Errors
    /// The errors of [`RdOperator::new`].
    pub fn tile_operator(&self, place: &TilePlace) -> Result<RdOperator<T>> {
        let codes = self.codes.select(&place.pixels(self.array))?;
        RdOperator::new(place.geometry, self.pulse.to_vec(), codes.into())
    }

    /// Reconstructs every tile from `y`, the T rows of K measurements (row-major tile order),
    /// and stitches them. Each tile is an independent problem with its own 2-D grid: the tiles
    /// run in parallel, each by [`reconstruct`](super::reconstruct()) with `method` and `options` (no progress bar
    /// inside a tile), and `on_tile` is called as each finishes (from its worker thread). Only
    /// the tiles being solved hold their own codes (beside the array's, unless those are seeded).
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if `y` does not hold one row of K samples per tile; the errors
    /// of [`RdOperator::new`] and [`reconstruct`](super::reconstruct()), naming the first tile
    /// that failed.
    pub fn reconstruct(
        &self,
        y: &[T],
        method: Method,
        options: &ReconstructOptions,
        on_tile: &(dyn Fn(&TileReconstruction<T>) + Sync),
    ) -> Result<TiledReconstruction<T>> {
        self.reconstruct_observed(y, method, options, &|_, _| Control::Continue, on_tile)
    }

    /// [`TiledArray::reconstruct`] with `observe` called after every iteration of every
    /// tile's solvers, with the tile's index, from the tile's worker thread: [`Control::Stop`]
    /// ends that solver (to stop every tile, keep returning it).
    ///
    /// # Errors
    /// As [`TiledArray::reconstruct`].
    pub fn reconstruct_observed(
        &self,
        y: &[T],
        method: Method,
        options: &ReconstructOptions,
        observe: &(dyn Fn(usize, &IterationInfo<'_, T>) -> Control + Sync),
        on_tile: &(dyn Fn(&TileReconstruction<T>) + Sync),
    ) -> Result<TiledReconstruction<T>> {
        let start = Instant::now();
        let places = self.places();
        let k = self.samples();
        let solved: Vec<TilePlace> = places
            .iter()
            .filter(|p| self.only.is_none_or(|(a, b)| (a..b).contains(&p.index)))
            .copied()
            .collect();
        if Some(y.len()) != places.len().checked_mul(k) {
            return Err(Error::shape(
                format!(
                    "tiled reconstruction: measurements vs {} tiles of {} × K = {k}",
                    places.len(),
                    self.tile
                ),
                places.len() * k,
                y.len(),
            ));
        }
        let inner = ReconstructOptions {
            progress: false,
            ..options.clone()
        };
        let tiles = solved
            .par_iter()
            .map(|place| {
                let name = |e: Error| {
                    let g = place.geometry;
                    Error::param(
                        "tile",
                        format!(
                            "tile {} (rows {}..{}, columns {}..{}): {e}",
                            place.index,
                            place.row,
                            place.row + g.m,
                            place.col,
                            place.col + g.n
                        ),
                    )
                };
                // A cancelled reconstruction does not even build the tiles still to come.
                if self
                    .cancel
                    .is_some_and(|f| f.load(std::sync::atomic::Ordering::Relaxed))
                {
                    return Err(Error::Cancelled {
                        what: format!("tile {}", place.index),
                    });
                }
                let op = self.tile_operator(place).map_err(name)?;
                let rows = &y[place.index * k..(place.index + 1) * k];
                let mut observer = |info: &IterationInfo<'_, T>| observe(place.index, info);
                let reconstruction = match self.cancel {
                    Some(flag) => reconstruct_observed(
                        &Cancellable::new(&op, flag),
                        rows,
                        method,
                        &inner,
                        &mut observer,
                    ),
                    None => reconstruct_observed(&op, rows, method, &inner, &mut observer),
                }
                .map_err(name)?;
                let done = TileReconstruction {
                    place: *place,
                    reconstruction,
                };
                on_tile(&done);
                Ok(done)
            })
            .collect::<Result<Vec<_>>>()?;
        let scene = stitch(self.array, &tiles)?;
        let mut depth = scene.depth_map();
        let observed = self.codes.observed_pixels();
        if observed.iter().any(|&o| !o) {
            depth.mark_unobserved(&observed)?;
        }
        Ok(TiledReconstruction {
            scene,
            depth,
            tiles,
            elapsed: start.elapsed(),
        })
    }
}

/// The tiles' scenes put in their places of the array.
fn stitch<T: Real>(array: Geometry, tiles: &[TileReconstruction<T>]) -> Result<Scene<T>> {
    let ks = array.ks;
    let mut x = vec![T::zero(); array.voxels()];
    for t in tiles {
        let src = t.reconstruction.scene.data();
        let src = src
            .as_slice()
            .ok_or_else(|| Error::param("tile", "a tile's scene is not contiguous"))?;
        for (i, p) in t.place.pixels(array).into_iter().enumerate() {
            x[p * ks..(p + 1) * ks].copy_from_slice(&src[i * ks..(i + 1) * ks]);
        }
    }
    Scene::from_vec(array, x)
}

/// Values per tile before its arrays in [`encode_tile`].
const TILE_HEADER: usize = 9;

/// One tile's reconstruction as values: its index, method, report (iterations, termination,
/// applications, time) and elapsed time, then its scene, depth bins and amplitudes (to gather the
/// tiles solved by several processes). The auto stages and the histories are not sent.
pub(crate) fn encode_tile<T: Real>(t: &TileReconstruction<T>) -> Vec<f64> {
    let r = &t.reconstruction;
    let method = Method::ALL.iter().position(|&m| m == r.method_used);
    let report = r.report.as_ref();
    let termination =
        report.and_then(|rep| Termination::ALL.iter().position(|&x| x == rep.termination));
    let mut v = vec![
        t.place.index as f64,
        method.map_or(-1.0, |m| m as f64),
        report.map_or(-1.0, |rep| rep.iterations as f64),
        termination.map_or(-1.0, |x| x as f64),
        report.map_or(0.0, |rep| rep.forward_applies as f64),
        report.map_or(0.0, |rep| rep.adjoint_applies as f64),
        report.map_or(0.0, |rep| rep.support_applies as f64),
        report.map_or(0.0, |rep| rep.elapsed.as_secs_f64()),
        r.elapsed.as_secs_f64(),
    ];
    v.extend(r.scene.data().iter().map(|x| x.as_f64()));
    v.extend(r.depth.depth.iter().map(|&d| f64::from(d)));
    v.extend(r.depth.amplitude.iter().map(|a| a.as_f64()));
    v
}

/// The tiles of `values`, one [`encode_tile`] after another, each of its place in `places` (by
/// index); a tile's report holds its counts and time, without histories.
pub(crate) fn decode_tiles<T: Real>(
    values: &[f64],
    places: &[TilePlace],
    k: usize,
) -> Result<Vec<TileReconstruction<T>>> {
    let bad = || {
        Error::param(
            "tiles",
            "the tiles gathered from the processes are malformed",
        )
    };
    let mut out = Vec::new();
    let mut at = 0;
    while at < values.len() {
        let head = values.get(at..at + TILE_HEADER).ok_or_else(bad)?;
        let place = *places.get(head[0] as usize).ok_or_else(bad)?;
        let g = place.geometry;
        let body = values
            .get(at + TILE_HEADER..at + TILE_HEADER + g.voxels() + 2 * g.pixels())
            .ok_or_else(bad)?;
        let (scene, rest) = body.split_at(g.voxels());
        let (depth, amplitude) = rest.split_at(g.pixels());
        let method = *Method::ALL.get(head[1] as usize).ok_or_else(bad)?;
        let seconds = |s: f64| Duration::from_secs_f64(s.max(0.0));
        let report = match Termination::ALL.get(head[3] as usize) {
            Some(&termination) if head[2] >= 0.0 => Some(Report {
                solver: method.name(),
                iterations: head[2] as usize,
                termination,
                residual_history: Vec::new(),
                objective_history: Vec::new(),
                forward_applies: head[4] as usize,
                adjoint_applies: head[5] as usize,
                support_applies: head[6] as usize,
                elapsed: seconds(head[7]),
            }),
            _ => None,
        };
        let shape = (g.m, g.n);
        let map = |_| bad();
        let reconstruction = Reconstruction {
            scene: Scene::from_vec(g, scene.iter().map(|&x| T::of_f64(x)).collect())?,
            depth: DepthMap {
                depth: ndarray::Array2::from_shape_vec(
                    shape,
                    depth.iter().map(|&d| d as i32).collect(),
                )
                .map_err(map)?,
                amplitude: ndarray::Array2::from_shape_vec(
                    shape,
                    amplitude.iter().map(|&a| T::of_f64(a)).collect(),
                )
                .map_err(map)?,
            },
            method_used: method,
            regime: Regime::of(k, g.voxels()),
            report,
            stages: Vec::new(),
            elapsed: seconds(head[8]),
            photon: None,
            detection: None,
            returns: None,
        };
        out.push(TileReconstruction {
            place,
            reconstruction,
        });
        at += TILE_HEADER + g.voxels() + 2 * g.pixels();
    }
    Ok(out)
}

/// The whole array's reconstruction from all its tiles' (in any order): stitched, with the
/// depth map of every tile as its reconstruction gave it.
pub(crate) fn assemble_tiles<T: Real>(
    array: Geometry,
    mut tiles: Vec<TileReconstruction<T>>,
    elapsed: Duration,
) -> Result<TiledReconstruction<T>> {
    tiles.sort_by_key(|t| t.place.index);
    let scene = stitch(array, &tiles)?;
    let mut depth = DepthMap {
        depth: ndarray::Array2::from_elem((array.m, array.n), crate::lidar::NO_RETURN),
        amplitude: ndarray::Array2::zeros((array.m, array.n)),
    };
    for t in &tiles {
        let (p, d) = (t.place, &t.reconstruction.depth);
        for i in 0..p.geometry.m {
            for j in 0..p.geometry.n {
                depth.depth[[p.row + i, p.col + j]] = d.depth[[i, j]];
                depth.amplitude[[p.row + i, p.col + j]] = d.amplitude[[i, j]];
            }
        }
    }
    Ok(TiledReconstruction {
        scene,
        depth,
        tiles,
        elapsed,
    })
}
