//! Continuous depths: the Cramér–Rao bound of a problem, the errors of an estimate against
//! the truth, and returns as points.

use numpy::ndarray::{Array3, Ix3};
use numpy::{IntoPyArray, PyArray2, PyReadonlyArrayDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pythonize::pythonize;

use rdlidar::io::read_response;
use rdlidar::lidar::{depth_bin_m, Camera, Returns, DEFAULT_TAU_S};
use rdlidar::recon::compare_range;

use crate::operator::PyOperator;
use crate::value_error;

/// (R, M, N) depths and amplitudes from (M, N) or (R, M, N) arrays named `what`.
fn returns_of(
    depth: &PyReadonlyArrayDyn<'_, f64>,
    amplitude: Option<&PyReadonlyArrayDyn<'_, f64>>,
    what: &str,
) -> PyResult<Returns> {
    let three = |a: &PyReadonlyArrayDyn<'_, f64>, name: &str| -> PyResult<Array3<f64>> {
        let a = a.as_array().to_owned();
        let a = if a.ndim() == 2 {
            a.insert_axis(numpy::ndarray::Axis(0))
        } else {
            a
        };
        a.into_dimensionality::<Ix3>().map_err(|_| {
            PyValueError::new_err(format!("{name}: expected an (M, N) or (R, M, N) array"))
        })
    };
    let d = three(depth, what)?;
    let a = match amplitude {
        Some(a) => three(a, "amplitude")?,
        None => d.mapv(|v| if v.is_nan() { 0.0 } else { 1.0 }),
    };
    Returns::new(d, a).map_err(|e| PyValueError::new_err(format!("{what}: {e}")))
}

/// The per-return Cramér–Rao bound on the depths `range` with amplitudes `amplitude` under
/// `kernel` and the noise level `sigma`, for the operator `op`: every other pixel known, or
/// with `joint` every return unknown at once.
#[pyfunction]
#[pyo3(signature = (op, range, amplitude, kernel, sigma, joint=false))]
pub(crate) fn depth_bound<'py>(
    py: Python<'py>,
    op: &PyOperator,
    range: PyReadonlyArrayDyn<'py, f64>,
    amplitude: PyReadonlyArrayDyn<'py, f64>,
    kernel: &str,
    sigma: f64,
    joint: bool,
) -> PyResult<Bound<'py, numpy::PyArray3<f64>>> {
    let truth = returns_of(&range, Some(&amplitude), "range")?;
    let response = read_response(kernel).map_err(value_error)?;
    let acq = &op.acq;
    let bound = py
        .detach(|| {
            if joint {
                acq.joint_depth_bound::<f64>(&truth, &response, sigma)
            } else {
                acq.depth_bound::<f64>(&truth, &response, sigma)
            }
        })
        .map_err(value_error)?;
    Ok(bound.into_pyarray(py))
}

/// Continuous depths against the true ones (and the bound over the same returns).
#[pyfunction]
#[pyo3(signature = (truth, estimate, bound=None, tau_s=None))]
pub(crate) fn range_metrics<'py>(
    py: Python<'py>,
    truth: PyReadonlyArrayDyn<'py, f64>,
    estimate: PyReadonlyArrayDyn<'py, f64>,
    bound: Option<PyReadonlyArrayDyn<'py, f64>>,
    tau_s: Option<f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let t = returns_of(&truth, None, "truth")?;
    let e = returns_of(&estimate, None, "estimate")?;
    let b = bound
        .map(|b| returns_of(&b, None, "bound").map(|r| r.depth))
        .transpose()?;
    let bin_m = depth_bin_m(tau_s.unwrap_or(DEFAULT_TAU_S)).map_err(value_error)?;
    let m = compare_range(&t, &e, b.as_ref(), bin_m).map_err(value_error)?;
    Ok(pythonize(py, &m)?)
}

/// Points (P, 4) and their pixels (P, 2).
type Cloud<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<u32>>);

/// Every return as a point (x, y, z, intensity) and its pixel (row, column).
#[pyfunction]
#[pyo3(signature = (range, amplitude, fov=None, pixel_pitch=None, focal_length=None, tau_s=None))]
pub(crate) fn points<'py>(
    py: Python<'py>,
    range: PyReadonlyArrayDyn<'py, f64>,
    amplitude: PyReadonlyArrayDyn<'py, f64>,
    fov: Option<(f64, Option<f64>)>,
    pixel_pitch: Option<f64>,
    focal_length: Option<f64>,
    tau_s: Option<f64>,
) -> PyResult<Cloud<'py>> {
    let returns = returns_of(&range, Some(&amplitude), "range")?;
    let (_, m, n) = returns.depth.dim();
    let camera = match (fov, pixel_pitch, focal_length) {
        (Some((h, v)), None, None) => Camera::field_of_view(h, v, m, n),
        (None, Some(p), Some(f)) => Camera::pinhole(p, f),
        _ => {
            return Err(PyValueError::new_err(
                "fov: give the camera, fov=H or (H, V) in degrees, or pixel_pitch= and \
                 focal_length=",
            ))
        }
    }
    .map_err(value_error)?;
    let bin_m = depth_bin_m(tau_s.unwrap_or(DEFAULT_TAU_S)).map_err(value_error)?;
    let cloud = rdlidar::lidar::points(&returns, bin_m, &camera).map_err(value_error)?;
    let pixels = numpy::ndarray::Array2::from_shape_fn((cloud.pixels.len(), 2), |(p, c)| {
        if c == 0 {
            cloud.pixels[p].0
        } else {
            cloud.pixels[p].1
        }
    });
    Ok((cloud.points.into_pyarray(py), pixels.into_pyarray(py)))
}
