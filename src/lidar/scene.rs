//! Scenes: reflectivity cubes (M, N, K_s) and their depth-map form.

use ndarray::{Array2, Array3};

use crate::error::{Error, Result};
use crate::linalg::{column_peaks, PeakRule};
use crate::real::Real;

use super::geometry::Geometry;

/// Depth bin marking a pixel with no return.
pub const NO_RETURN: i32 = -1;

/// The depth of a pixel that was not observed: a pixel whose codes are all zero (blocked by a
/// coded aperture) reaches no ADC, so nothing can be said of it. Distinct from [`NO_RETURN`],
/// which is an observed pixel with nothing in it.
pub const UNOBSERVED: i32 = -2;

/// A reflectivity cube `x[m, n, j]` (C order, depth last), the unknown of the lidar model.
///
/// Its flat slice ([`Scene::as_slice`]) is the operator's input vector: index
/// `(m·N + n)·K_s + j`.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene<T> {
    data: Array3<T>,
}

impl<T: Real> Scene<T> {
    /// Wraps a cube, making it C-contiguous.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] if a dimension is zero, [`Error::NonFinite`] for NaN or
    /// infinite values.
    pub fn new(data: Array3<T>) -> Result<Self> {
        let (m, n, ks) = data.dim();
        Geometry::new(m, n, ks)?;
        if let Some(v) = data.iter().find(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: format!("scene value {v}"),
            });
        }
        let data = if data.is_standard_layout() {
            data
        } else {
            data.as_standard_layout().to_owned()
        };
        Ok(Scene { data })
    }

    /// The empty scene.
    pub fn zeros(g: Geometry) -> Self {
        Scene {
            data: Array3::zeros((g.m, g.n, g.ks)),
        }
    }

    /// A scene from a flat C-order vector of length M·N·K_s.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if the length is wrong, [`Error::NonFinite`] for NaN or infinite
    /// values.
    pub fn from_vec(g: Geometry, v: Vec<T>) -> Result<Self> {
        if v.len() != g.voxels() {
            return Err(Error::shape(
                format!("scene vector for {g}"),
                g.voxels(),
                v.len(),
            ));
        }
        Scene::new(Array3::from_shape_vec((g.m, g.n, g.ks), v).expect("length checked"))
    }

    /// The grid.
    pub fn geometry(&self) -> Geometry {
        let (m, n, ks) = self.data.dim();
        Geometry { m, n, ks }
    }

    /// The cube.
    pub fn data(&self) -> &Array3<T> {
        &self.data
    }

    /// The cube, mutably.
    pub fn data_mut(&mut self) -> &mut Array3<T> {
        &mut self.data
    }

    /// Unwraps the cube.
    pub fn into_inner(self) -> Array3<T> {
        self.data
    }

    /// The flat C-order values: the operator's input vector.
    pub fn as_slice(&self) -> &[T] {
        self.data.as_slice().expect("scenes are C-contiguous")
    }

    /// Pixel `p`'s depth column (row-major pixels).
    ///
    /// # Panics
    /// If `p` is not a pixel of the scene.
    pub fn column(&self, p: usize) -> &[T] {
        let ks = self.data.dim().2;
        &self.as_slice()[p * ks..(p + 1) * ks]
    }

    /// The scene with the columns of the pixels whose entry of `keep` (row-major, one per
    /// pixel) is false set to zero: what an instrument that observes only the kept pixels can
    /// be judged against.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if `keep` does not have one entry per pixel.
    pub fn masked_pixels(&self, keep: &[bool]) -> Result<Self> {
        let g = self.geometry();
        if keep.len() != g.pixels() {
            return Err(Error::shape(
                "masked_pixels: keep vs pixels",
                g.pixels(),
                keep.len(),
            ));
        }
        let mut x = self.as_slice().to_vec();
        for (column, &k) in x.chunks_mut(g.ks).zip(keep) {
            if !k {
                column.fill(T::zero());
            }
        }
        Scene::from_vec(g, x)
    }

    /// Number of nonzero voxels.
    pub fn nnz(&self) -> usize {
        self.data.iter().filter(|v| **v != T::zero()).count()
    }

    /// The strongest return of each pixel as a depth map: the bin of largest |x| (the first one on
    /// ties) and its value; pixels whose column is all zero get [`NO_RETURN`] and amplitude 0.
    pub fn depth_map(&self) -> DepthMap<T> {
        let g = self.geometry();
        let mut depth = Array2::from_elem((g.m, g.n), NO_RETURN);
        let mut amp = Array2::zeros((g.m, g.n));
        for (k, peak) in column_peaks(self.as_slice(), g.ks, PeakRule::LargestMagnitude)
            .into_iter()
            .enumerate()
        {
            if let Some((d, v)) = peak {
                let at = [k / g.n, k % g.n];
                depth[at] = d as i32;
                amp[at] = T::of_f64(v);
            }
        }
        DepthMap {
            depth,
            amplitude: amp,
        }
    }
}

/// An opaque scene as a depth map: one return per pixel at most.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap<T> {
    /// Depth bin per pixel, [`NO_RETURN`] (−1) for none.
    pub depth: Array2<i32>,
    /// Reflectivity of the return (0 where there is none).
    pub amplitude: Array2<T>,
}

impl<T: Real> DepthMap<T> {
    /// The scene with one voxel per lit pixel.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if the two maps differ in shape, [`Error::InvalidParameter`] if a
    /// depth is outside `[-1, ks)`, [`Error::NonFinite`] for a NaN or infinite amplitude.
    pub fn to_scene(&self, ks: usize) -> Result<Scene<T>> {
        let (m, n) = self.depth.dim();
        if self.amplitude.dim() != (m, n) {
            return Err(Error::shape(
                "depth map: amplitude rows×columns vs depth",
                m * n,
                self.amplitude.len(),
            ));
        }
        let g = Geometry::new(m, n, ks)?;
        let mut x = Array3::zeros((g.m, g.n, g.ks));
        for ((i, j), &d) in self.depth.indexed_iter() {
            if d == NO_RETURN || d == UNOBSERVED {
                continue;
            }
            if d < 0 || d as usize >= ks {
                return Err(Error::param(
                    "depth",
                    format!("depth bin {d} at pixel ({i}, {j}) is outside [-2, {ks})"),
                ));
            }
            x[[i, j, d as usize]] = self.amplitude[[i, j]];
        }
        Scene::new(x)
    }

    /// Number of pixels with a return.
    pub fn lit(&self) -> usize {
        self.depth.iter().filter(|&&d| d >= 0).count()
    }

    /// Number of pixels marked [`UNOBSERVED`].
    pub fn unobserved(&self) -> usize {
        self.depth.iter().filter(|&&d| d == UNOBSERVED).count()
    }

    /// Marks the pixels whose entry of `observed` (row-major, one per pixel) is false as
    /// [`UNOBSERVED`], with amplitude 0.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if `observed` does not have one entry per pixel.
    pub fn mark_unobserved(&mut self, observed: &[bool]) -> Result<()> {
        if observed.len() != self.depth.len() {
            return Err(Error::shape(
                "mark_unobserved: observed vs pixels",
                self.depth.len(),
                observed.len(),
            ));
        }
        let cells = self.depth.iter_mut().zip(self.amplitude.iter_mut());
        for ((d, a), &seen) in cells.zip(observed) {
            if !seen {
                *d = UNOBSERVED;
                *a = T::zero();
            }
        }
        Ok(())
    }

    /// Fills the [`UNOBSERVED`] pixels from their neighbours, as a spatially regularized
    /// reconstruction would: in rounds, each unobserved pixel with at least one decided
    /// 8-neighbour (observed, or filled in an earlier round) takes the median depth and the mean
    /// amplitude of its lit neighbours when at least half of its decided neighbours are lit,
    /// and [`NO_RETURN`] otherwise. Rounds go on until every pixel is decided (a map with no
    /// observed pixel is left as it is). Returns how many pixels were filled with a return.
    pub fn fill_unobserved(&mut self) -> usize {
        let (m, n) = self.depth.dim();
        let mut filled = 0;
        loop {
            let mut updates = Vec::new();
            for ((i, j), &d) in self.depth.indexed_iter() {
                if d != UNOBSERVED {
                    continue;
                }
                let mut depths = Vec::new();
                let (mut decided, mut amp) = (0usize, 0.0f64);
                for di in -1i64..=1 {
                    for dj in -1i64..=1 {
                        let (a, b) = (i as i64 + di, j as i64 + dj);
                        if (di, dj) == (0, 0) || a < 0 || b < 0 || a >= m as i64 || b >= n as i64 {
                            continue;
                        }
                        let (a, b) = (a as usize, b as usize);
                        match self.depth[[a, b]] {
                            UNOBSERVED => {}
                            NO_RETURN => decided += 1,
                            e => {
                                decided += 1;
                                depths.push(e);
                                amp += self.amplitude[[a, b]].as_f64();
                            }
                        }
                    }
                }
                if decided == 0 {
                    continue;
                }
                let fill = if 2 * depths.len() >= decided {
                    let count = depths.len();
                    depths.sort_unstable();
                    (depths[(count - 1) / 2], T::of_f64(amp / count as f64))
                } else {
                    (NO_RETURN, T::zero())
                };
                updates.push(((i, j), fill));
            }
            if updates.is_empty() {
                return filled;
            }
            for (at, (d, a)) in updates {
                filled += usize::from(d >= 0);
                self.depth[at] = d;
                self.amplitude[at] = a;
            }
        }
    }
}
