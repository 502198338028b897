//! Reflectors at continuous depths: what a scene is before the system's response puts it on
//! the voxel grid ([`Returns::render`]).

use ndarray::{Array2, Array3, ArrayD, Axis};

use crate::error::{Error, Result};
use crate::real::Real;

use super::geometry::Geometry;
use super::response::Response;
use super::scene::{DepthMap, Scene, NO_RETURN};

/// Up to R returns per pixel, each an amplitude at a continuous depth in bins (bin k's centre
/// at depth k). Two are equal when their shapes, amplitudes and depths are, a NaN depth (no
/// return) equal to another.
#[derive(Debug, Clone)]
pub struct Returns {
    /// (R, M, N) depths in bins, NaN where a pixel has fewer than R returns.
    pub depth: Array3<f64>,
    /// (R, M, N) amplitudes, 0 where there is no return.
    pub amplitude: Array3<f64>,
}

impl PartialEq for Returns {
    fn eq(&self, other: &Self) -> bool {
        self.amplitude == other.amplitude
            && self.depth.dim() == other.depth.dim()
            && self
                .depth
                .iter()
                .zip(other.depth.iter())
                .all(|(a, b)| a == b || (a.is_nan() && b.is_nan()))
    }
}

impl Returns {
    /// The returns of `depth` and `amplitude`, both (R, M, N).
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if their shapes differ; [`Error::InvalidParameter`] (`depth`)
    /// for an infinite depth, a return with a non-finite or negative amplitude, or an amplitude
    /// where the depth is NaN.
    pub fn new(depth: Array3<f64>, amplitude: Array3<f64>) -> Result<Returns> {
        if depth.dim() != amplitude.dim() {
            return Err(Error::shape(
                "returns: amplitudes vs depths",
                depth.len(),
                amplitude.len(),
            ));
        }
        for ((i, &d), &a) in depth.indexed_iter().zip(amplitude.iter()) {
            let ok = if d.is_nan() {
                a == 0.0
            } else {
                d.is_finite() && a.is_finite() && a >= 0.0
            };
            if !ok {
                return Err(Error::param(
                    "depth",
                    format!("return {i:?}: depth {d}, amplitude {a}"),
                ));
            }
        }
        Ok(Returns { depth, amplitude })
    }

    /// One return per pixel at most: `depth` (NaN for none) and `amplitude`, both (M, N).
    ///
    /// # Errors
    /// As [`new`](Self::new).
    pub fn single(depth: Array2<f64>, amplitude: Array2<f64>) -> Result<Returns> {
        Returns::new(depth.insert_axis(Axis(0)), amplitude.insert_axis(Axis(0)))
    }

    /// The returns of a voxel scene: every nonzero voxel a return at its bin, nearest first.
    pub fn of_scene<T: Real>(scene: &Scene<T>) -> Returns {
        let g = scene.geometry();
        let r = (0..g.pixels())
            .map(|p| scene.column(p).iter().filter(|v| **v != T::zero()).count())
            .max()
            .unwrap_or(0)
            .max(1);
        let mut depth = Array3::from_elem((r, g.m, g.n), f64::NAN);
        let mut amplitude = Array3::zeros((r, g.m, g.n));
        for p in 0..g.pixels() {
            let (i, j) = (p / g.n, p % g.n);
            let hits = scene
                .column(p)
                .iter()
                .enumerate()
                .filter(|(_, v)| **v != T::zero());
            for (q, (k, v)) in hits.enumerate() {
                depth[[q, i, j]] = k as f64;
                amplitude[[q, i, j]] = v.as_f64();
            }
        }
        Returns { depth, amplitude }
    }

    /// The returns at the depths `range` (in bins, NaN where there is none: (M, N), or
    /// (R, M, N) for several per pixel, as `range.npy` holds them) whose amplitudes best explain
    /// `scene` under `response`: each pixel's amplitudes are the least squares of its column on
    /// its returns' columns g(k − d) (exact for a scene rendered from such returns), negative
    /// ones set to 0.
    ///
    /// # Errors
    /// [`Error::ShapeMismatch`] if `range` is not (M, N) or (R, M, N) on the scene's grid;
    /// [`Error::InvalidParameter`] (`depth`) for an infinite depth or one outside
    /// [0, K_s − 1].
    pub fn fit_to_scene<T: Real>(
        range: ArrayD<f64>,
        scene: &Scene<T>,
        response: &Response,
    ) -> Result<Returns> {
        let g = scene.geometry();
        let depth = match range.ndim() {
            2 => range.insert_axis(Axis(0)),
            _ => range,
        }
        .into_dimensionality::<ndarray::Ix3>()
        .map_err(|_| Error::shape("range: (M, N) or (R, M, N)", 3, 0))?;
        let (r, m, n) = depth.dim();
        if (m, n) != (g.m, g.n) {
            return Err(Error::shape(
                "range vs the scene's pixels",
                g.m * g.n,
                m * n,
            ));
        }
        let top = (g.ks - 1) as f64;
        if let Some(d) = depth
            .iter()
            .find(|d| !d.is_nan() && !(0.0..=top).contains(*d))
        {
            return Err(Error::param(
                "depth",
                format!("a depth of {d} bins is outside [0, {top}]"),
            ));
        }
        let mut amplitude = Array3::zeros((r, m, n));
        for p in 0..g.pixels() {
            let (i, j) = (p / n, p % n);
            let layers: Vec<usize> = (0..r).filter(|&q| !depth[[q, i, j]].is_nan()).collect();
            if layers.is_empty() {
                continue;
            }
            let column: Vec<f64> = scene.column(p).iter().map(|v| v.as_f64()).collect();
            let a = nalgebra::DMatrix::from_fn(g.ks, layers.len(), |k, c| {
                response.value(k as f64 - depth[[layers[c], i, j]])
            });
            let b = nalgebra::DVector::from_vec(column);
            let fit = a
                .svd(true, true)
                .solve(&b, 1e-12)
                .map_err(|e| Error::param("depth", format!("pixel ({i}, {j}): {e}")))?;
            for (c, &q) in layers.iter().enumerate() {
                amplitude[[q, i, j]] = fit[c].max(0.0);
            }
        }
        Returns::new(depth, amplitude)
    }

    /// Returns per pixel at most (R).
    pub fn layers(&self) -> usize {
        self.depth.dim().0
    }

    /// Pixels with at least one return.
    pub fn lit_pixels(&self) -> usize {
        let (_, m, n) = self.depth.dim();
        (0..m * n)
            .filter(|p| {
                self.depth
                    .index_axis(Axis(1), p / n)
                    .column(p % n)
                    .iter()
                    .any(|d| !d.is_nan())
            })
            .count()
    }

    /// The scene of `ks` bins the response `response` makes of the returns: voxel k of a
    /// pixel holds Σ a·g(k − d) over its returns (summed in `f64`).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`depth`) for the delta response and a depth off the grid,
    /// or for a depth outside [0, K_s − 1]; the geometry's errors.
    pub fn render<T: Real>(&self, ks: usize, response: &Response) -> Result<Scene<T>> {
        let (r, m, n) = self.depth.dim();
        let g = Geometry::new(m, n, ks)?;
        let top = (ks - 1) as f64;
        let mut x = Array3::<f64>::zeros((m, n, ks));
        for q in 0..r {
            for i in 0..m {
                for j in 0..n {
                    let d = self.depth[[q, i, j]];
                    if d.is_nan() {
                        continue;
                    }
                    if !(0.0..=top).contains(&d) || (response.is_delta() && d != d.round()) {
                        return Err(Error::param(
                            "depth",
                            format!(
                                "pixel ({i}, {j}): depth {d} bins {}",
                                if response.is_delta() {
                                    "is off the grid, which the delta response cannot hold"
                                        .to_string()
                                } else {
                                    format!("is outside [0, {top}]")
                                }
                            ),
                        ));
                    }
                    let mut col = x.slice_mut(ndarray::s![i, j, ..]);
                    let col = col.as_slice_mut().expect("a C-order column");
                    response.add_to(self.amplitude[[q, i, j]], d, col);
                }
            }
        }
        let scene = Scene::new(x.mapv(T::of_f64))?;
        debug_assert_eq!(scene.geometry(), g);
        Ok(scene)
    }

    /// The depths as `range.npy` holds them: (M, N) for one return per pixel, (R, M, N) for
    /// several; NaN where there is none.
    pub fn range_map(&self) -> ArrayD<f64> {
        if self.layers() == 1 {
            self.depth.index_axis(Axis(0), 0).to_owned().into_dyn()
        } else {
            self.depth.clone().into_dyn()
        }
    }

    /// The amplitudes in the shape of [`range_map`](Self::range_map): (M, N) for one return per
    /// pixel, (R, M, N) for several; 0 where there is none.
    pub fn amplitude_map(&self) -> ArrayD<f64> {
        if self.layers() == 1 {
            self.amplitude.index_axis(Axis(0), 0).to_owned().into_dyn()
        } else {
            self.amplitude.clone().into_dyn()
        }
    }

    /// Each pixel's strongest return at its nearest bin (clamped to [0, `ks`)), as a depth map.
    pub fn nearest(&self, ks: usize) -> DepthMap<f64> {
        let (r, m, n) = self.depth.dim();
        let mut out = DepthMap {
            depth: Array2::from_elem((m, n), NO_RETURN),
            amplitude: Array2::zeros((m, n)),
        };
        for i in 0..m {
            for j in 0..n {
                let best = (0..r)
                    .filter(|&q| !self.depth[[q, i, j]].is_nan())
                    .max_by(|&a, &b| {
                        self.amplitude[[a, i, j]].total_cmp(&self.amplitude[[b, i, j]])
                    });
                if let Some(q) = best {
                    let top = ks.saturating_sub(1) as f64;
                    out.depth[[i, j]] = self.depth[[q, i, j]].round().clamp(0.0, top) as i32;
                    out.amplitude[[i, j]] = self.amplitude[[q, i, j]];
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn amplitudes_fitted_to_a_rendered_scene_are_its_own() {
        let nan = f64::NAN;
        let depth = ndarray::arr3(&[[[2.3, nan], [5.0, 1.7]], [[6.6, nan], [nan, nan]]]);
        let amplitude = ndarray::arr3(&[[[1.5, 0.0], [0.4, 2.0]], [[0.7, 0.0], [0.0, 0.0]]]);
        let truth = Returns::new(depth.clone(), amplitude).unwrap();
        for response in [Response::Triangle, Response::gaussian(0.8).unwrap()] {
            let scene = truth.render::<f64>(9, &response).unwrap();
            let fitted =
                Returns::fit_to_scene(depth.clone().into_dyn(), &scene, &response).unwrap();
            for (a, b) in fitted.amplitude.iter().zip(truth.amplitude.iter()) {
                assert!((a - b).abs() < 1e-12, "{response}: {a} vs {b}");
            }
        }
        let flat = Returns::fit_to_scene(
            depth.index_axis(Axis(0), 0).to_owned().into_dyn(),
            &truth.render::<f64>(9, &Response::Triangle).unwrap(),
            &Response::Triangle,
        )
        .unwrap();
        assert_eq!(flat.layers(), 1);
        let scene = truth.render::<f64>(9, &Response::Triangle).unwrap();
        let mut far = depth.clone();
        far[[0, 0, 0]] = 8.5;
        assert!(matches!(
            Returns::fit_to_scene(far.into_dyn(), &scene, &Response::Triangle),
            Err(Error::InvalidParameter { name: "depth", .. })
        ));
        assert!(matches!(
            Returns::fit_to_scene(ndarray::ArrayD::zeros(vec![2]), &scene, &Response::Triangle),
            Err(Error::ShapeMismatch { .. })
        ));
    }

    #[test]
    fn grid_returns_render_to_the_scene_they_came_from() {
        let g = Geometry::new(3, 4, 6).unwrap();
        let mut x = Array3::<f64>::zeros((3, 4, 6));
        x[[0, 1, 2]] = 0.5;
        x[[2, 3, 0]] = 1.0;
        x[[2, 3, 4]] = 0.25;
        let scene = Scene::new(x).unwrap();
        let r = Returns::of_scene(&scene);
        assert_eq!(r.layers(), 2);
        assert_eq!(r.lit_pixels(), 2);
        assert_eq!(r.render::<f64>(g.ks, &Response::Delta).unwrap(), scene);
        assert_eq!(r.nearest(g.ks).depth[[2, 3]], 0);
    }

    #[test]
    fn off_grid_returns_need_a_response_and_a_depth_in_range() {
        let depth = Array2::from_shape_vec((1, 2), vec![1.5, f64::NAN]).unwrap();
        let amp = Array2::from_shape_vec((1, 2), vec![2.0, 0.0]).unwrap();
        let r = Returns::single(depth, amp).unwrap();
        assert!(r.render::<f32>(4, &Response::Delta).is_err());
        let s = r.render::<f64>(4, &Response::Triangle).unwrap();
        assert_eq!(s.column(0), &[0.0, 1.0, 1.0, 0.0]);
        assert!(r.render::<f64>(2, &Response::Triangle).is_err());
        assert_eq!(r.range_map().shape(), &[1, 2]);
        let bad = Array2::from_shape_vec((1, 1), vec![f64::NAN]).unwrap();
        assert!(Returns::single(bad.clone(), bad.mapv(|_| 1.0)).is_err());
    }
}
