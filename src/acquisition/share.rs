//! An acquisition split by pixel rows over the parts of a [`Space`] (the processes of an MPI
//! job): each part holds the codes of its band of rows only, and its operator is its block of
//! the whole one, summed over the parts ([`Part`]).

use std::ops::Range;

use crate::space::{my_band, Space};

use super::*;

/// This process's share of an acquisition whose pixel rows are split over the parts of a
/// space: its band of rows of the whole grid.
#[derive(Debug, Clone)]
pub struct Share {
    space: Arc<dyn Space>,
    rows: Range<usize>,
    whole: Geometry,
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
        Ok(Share { space, rows, whole })
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
    /// # Errors
    /// [`Share::of`]; [`Error::InvalidParameter`] (`tiles`) for a tiled acquisition (its tiles
    /// are independent problems, reconstructed whole).
    pub fn split_over(&self, space: Arc<dyn Space>) -> Result<Acquisition> {
        if space.parts() == 1 {
            return Ok(self.clone());
        }
        refuse_tiles(self.architecture, "tiles")?;
        let share = Share::of(space, self.geometry)?;
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

/// Refuses to split a tiled acquisition by rows; `flag` names the tile size.
pub(crate) fn refuse_tiles(architecture: Architecture, flag: &str) -> Result<()> {
    match architecture {
        Architecture::Tiles(t) => Err(Error::param(
            "tiles",
            format!(
                "{flag} {t}: the tiles of an array are independent problems, each solved by one \
                 process; the pixel rows of one ADC or of several code sets are split over \
                 processes"
            ),
        )),
        _ => Ok(()),
    }
}
