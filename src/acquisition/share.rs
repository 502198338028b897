//! An acquisition split by pixel rows over the parts of a [`Space`] (the processes of an MPI
//! job): each part holds the codes of its band of rows only, and its operator is its block of
//! the whole one, summed over the parts ([`Part`]).

use std::ops::Range;

use crate::recon::{assemble_tiles, decode_tiles, encode_tile};
use crate::space::{first_failure, my_band, Space};

use super::*;

/// This process's share of an acquisition whose pixel rows are split over the parts of a
/// space: its band of rows of the whole grid.
#[derive(Debug, Clone)]
pub struct Share {
    space: Arc<dyn Space>,
    rows: Range<usize>,
    whole: Geometry,
    /// For a tiled array: the tile size and the tiles dealt to this part (its rows are those
    /// of the tile rows they lie in).
    tiles: Option<(TileSize, Range<usize>)>,
}

impl Share {
    /// The band of `whole`'s pixel rows that this part of `space` holds ([`my_band`]).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`parts`) when there are more parts than pixel rows: every
    /// part refuses, with the same message.
    pub fn of(space: Arc<dyn Space>, whole: Geometry) -> Result<Self> {
        let parts = space.parts();
        if parts > whole.m {
            return Err(Error::param(
                "parts",
                format!(
                    "{parts} processes for the {} pixel rows of {whole}: the pixel rows are \
                     split over the processes, at most one process per row",
                    whole.m
                ),
            ));
        }
        let rows = my_band(&*space, whole.m);
        Ok(Share {
            space,
            rows,
            whole,
            tiles: None,
        })
    }

    /// The tiles of `tile` pixels of `whole` dealt to this part of `space`: an even share of
    /// the tiles in row-major order ([`band`](crate::space::band) of their indices), with the
    /// pixel rows of the tile rows they lie in (tiles solve alone: no communication until their
    /// results are gathered).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`parts`) when there are more parts than tiles.
    pub fn of_tiles(space: Arc<dyn Space>, whole: Geometry, tile: TileSize) -> Result<Self> {
        let places = tile_places(whole, tile)?;
        let parts = space.parts();
        if parts > places.len() {
            return Err(Error::param(
                "parts",
                format!(
                    "{parts} processes for the {} tiles of {tile} of {whole}: the tiles are \
                     dealt to the processes, at most one process per tile",
                    places.len()
                ),
            ));
        }
        let mine = crate::space::band(places.len(), parts, space.part());
        let (first, last) = (places[mine.start], places[mine.end - 1]);
        Ok(Share {
            space,
            rows: first.row..last.row + last.geometry.m,
            whole,
            tiles: Some((tile, mine)),
        })
    }

    /// For a tiled array, the tiles dealt to this part.
    pub fn tiles(&self) -> Option<Range<usize>> {
        self.tiles.as_ref().map(|(_, r)| r.clone())
    }

    /// The index in the whole array of the first tile of this part's rows.
    pub(crate) fn first_tile_of_rows(&self) -> usize {
        match self.tiles {
            Some((t, _)) => self.rows.start / t.m * self.whole.n.div_ceil(t.n),
            None => 0,
        }
    }

    /// The space the parts combine through.
    pub fn space(&self) -> &Arc<dyn Space> {
        &self.space
    }

    /// This part's pixel rows of the whole grid.
    pub fn rows(&self) -> Range<usize> {
        self.rows.clone()
    }

    /// The whole grid.
    pub fn whole(&self) -> Geometry {
        self.whole
    }

    /// This part's grid: its rows, every column.
    pub fn geometry(&self) -> Geometry {
        Geometry {
            m: self.rows.len(),
            ..self.whole
        }
    }

    /// This part's pixels of the whole grid, row-major.
    pub fn pixels(&self) -> Range<usize> {
        self.rows.start * self.whole.n..self.rows.end * self.whole.n
    }

    /// The whole of an array over the pixels (row-major, any number of values per pixel),
    /// gathered in every part from each part's rows of it (`local` here).
    pub fn gather<T: Real>(&self, local: &[T]) -> Vec<T> {
        let wide: Vec<f64> = local.iter().map(|v| v.as_f64()).collect();
        self.space
            .gather(&wide)
            .into_iter()
            .map(T::of_f64)
            .collect()
    }

    /// This part's rows of a whole array over the pixels (`per_pixel` values each).
    pub fn rows_of<'a, T>(&self, whole: &'a [T], per_pixel: usize) -> &'a [T] {
        let p = self.pixels();
        &whole[p.start * per_pixel..p.end * per_pixel]
    }

    /// The whole tiled reconstruction from this part's tiles, `local` (on the grid of this
    /// part's rows, as [`TiledArray::only`](crate::recon::TiledArray::only) gives it), in
    /// every part: each part's tiles gathered and stitched. The tiles of other parts carry
    /// their scene, depth map, method and report counts, without histories or auto's stages.
    /// The parts first agree on failure: if any part's `local` is an error, every part returns
    /// one (its own, or the first failing part's).
    ///
    /// # Errors
    /// A part's error; [`Error::InvalidParameter`] (`parts`) for another part's.
    pub fn gather_tiled<T: Real>(
        &self,
        local: Result<TiledReconstruction<T>>,
        samples: usize,
    ) -> Result<TiledReconstruction<T>> {
        let message = local.as_ref().err().map(ToString::to_string);
        match first_failure(&*self.space, message.as_deref()) {
            Some((part, _)) if part == self.space.part() => return local,
            Some((part, m)) => {
                return Err(Error::param("parts", format!("process {part}: {m}")));
            }
            None => {}
        }
        let local = local?;
        let Some((tile, _)) = self.tiles else {
            return Err(Error::param(
                "tiles",
                "the acquisition's tiles are not dealt to parts",
            ));
        };
        let first = self.first_tile_of_rows();
        let mut values = Vec::new();
        for t in &local.tiles {
            let mut t = t.clone();
            t.place.index += first;
            t.place.row += self.rows.start;
            values.extend(encode_tile(&t));
        }
        let all = self.space.gather(&values);
        let places = tile_places(self.whole, tile)?;
        let tiles = decode_tiles(&all, &places, samples)?;
        let seconds = crate::space::max(&*self.space, local.elapsed.as_secs_f64());
        assemble_tiles(
            self.whole,
            tiles,
            std::time::Duration::from_secs_f64(seconds),
        )
    }

    /// The whole reconstruction from this part's: its scene and depth map gathered from every
    /// part's rows (in every part), the rest (method, stages, report, which every part shares)
    /// as they are.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if `r` is not of this part's grid.
    pub fn gather_reconstruction<T: Real>(
        &self,
        r: Reconstruction<T>,
    ) -> Result<Reconstruction<T>> {
        let g = self.geometry();
        if r.scene.geometry() != g {
            return Err(Error::ShapeMismatch {
                context: "a part's reconstruction against its rows".into(),
                expected: g.voxels(),
                found: r.scene.geometry().voxels(),
            });
        }
        let w = self.whole;
        let values: Vec<T> = r.scene.data().iter().copied().collect();
        let scene = Scene::from_vec(w, self.gather(&values))?;
        let depth: Vec<f64> = r.depth.depth.iter().map(|&d| f64::from(d)).collect();
        let depth: Vec<i32> = self
            .space
            .gather(&depth)
            .into_iter()
            .map(|d| d as i32)
            .collect();
        let amplitude: Vec<T> = r.depth.amplitude.iter().copied().collect();
        let amplitude = self.gather(&amplitude);
        let shape = (w.m, w.n);
        let map = |e: ndarray::ShapeError| Error::param("parts", e.to_string());
        let depth = DepthMap {
            depth: ndarray::Array2::from_shape_vec(shape, depth).map_err(map)?,
            amplitude: ndarray::Array2::from_shape_vec(shape, amplitude).map_err(map)?,
        };
        Ok(Reconstruction { scene, depth, ..r })
    }
}

impl Acquisition {
    /// This process's share of the acquisition when its pixel rows are split over the parts of
    /// `space`: the codes of its band of rows only (seeded codes stay a seed), and an operator
    /// that is its block of the whole one ([`Part`]: forward summed over the parts, adjoint
    /// local). The reconstructions then run on every part at once and give each its rows of the
    /// whole one's result. With one part, the acquisition itself.
    ///
    /// A tiled acquisition's tiles are dealt to the parts instead ([`Share::of_tiles`]): each
    /// holds the codes of the tile rows its tiles lie in and solves its tiles alone.
    ///
    /// # Errors
    /// [`Share::of`] or [`Share::of_tiles`]: more parts than pixel rows, or than tiles.
    pub fn split_over(&self, space: Arc<dyn Space>) -> Result<Acquisition> {
        if space.parts() == 1 {
            return Ok(self.clone());
        }
        let share = match self.architecture {
            Architecture::Tiles(t) => Share::of_tiles(space, self.geometry, t)?,
            _ => Share::of(space, self.geometry)?,
        };
        let pixels: Vec<usize> = share.pixels().collect();
        let codes = match &self.codes {
            CodeStore::Held(sets) => CodeStore::Held(
                sets.iter()
                    .map(|c| c.select_pixels(&pixels).map(Arc::new))
                    .collect::<Result<Vec<_>>>()?,
            ),
            CodeStore::Seeded(s) => CodeStore::Seeded(s.band(share.pixels())?),
        };
        // Seeded codes of the band are streamed if the whole's are, or if the band's are large.
        let streaming = if self.streamed {
            Streaming::Always
        } else {
            Streaming::Auto
        };
        Acquisition::new(share.geometry(), self.pulse.clone(), codes, None, streaming)?
            .band_of(share, self.architecture)
    }

    /// This acquisition, of a band's grid and codes, as `share` of a whole of `architecture`.
    pub(crate) fn band_of(self, share: Share, architecture: Architecture) -> Result<Acquisition> {
        if share.geometry() != self.geometry {
            return Err(Error::param(
                "codes",
                format!(
                    "the band of rows {}..{} is {}, the codes are {}",
                    share.rows.start,
                    share.rows.end,
                    share.geometry(),
                    self.geometry
                ),
            ));
        }
        Ok(Acquisition {
            architecture,
            share: Some(share),
            ..self
        })
    }

    /// A tiled acquisition's share: solves the tiles `mine` (whole indices) of `tiled` (the
    /// array of this part's rows) from the whole measurements, then gathers every part's tiles
    /// ([`Share::gather_tiled`]). `observe` and `on_tile` see the whole array's tile indices and
    /// places.
    pub(crate) fn reconstruct_dealt<T: Real>(
        &self,
        tiled: &TiledArray<'_, T>,
        share: &Share,
        mine: Range<usize>,
        (y, method, options): (&[T], Method, &ReconstructOptions),
        observe: &(dyn Fn(usize, &IterationInfo<'_, T>) -> Control + Sync),
        on_tile: &(dyn Fn(&TileReconstruction<T>) + Sync),
    ) -> Result<Reconstructed<T>> {
        let (k, first) = (self.samples(), share.first_tile_of_rows());
        let here = self.tile_places().len();
        let rows = share.rows.start;
        let observe = |i: usize, info: &IterationInfo<'_, T>| observe(i + first, info);
        let on_tile = |t: &TileReconstruction<T>| {
            let mut t = t.clone();
            t.place.index += first;
            t.place.row += rows;
            on_tile(&t);
        };
        let local = match y.get(first * k..(first + here) * k) {
            Some(y) => (*tiled)
                .only(mine.start - first..mine.end - first)
                .reconstruct_observed(y, method, options, &observe, &on_tile),
            None => Err(Error::shape(
                "a part's tiles' measurements",
                (first + here) * k,
                y.len(),
            )),
        };
        share.gather_tiled(local, k).map(Reconstructed::Tiled)
    }

    /// How the pixel rows are split over processes, when they are.
    pub fn share(&self) -> Option<&Share> {
        self.share.as_ref()
    }

    /// The whole grid: [`Acquisition::geometry`], or the grid the shares of a split
    /// acquisition make together.
    pub fn whole_geometry(&self) -> Geometry {
        self.share.as_ref().map_or(self.geometry, Share::whole)
    }
}
