//! `rdlidar._rdlidar`: the Rust core of the Python package. The package's Python layer
//! (`python/rdlidar/__init__.py`) converts its arguments to the dtypes and shapes these
//! functions take and wraps the operator as a `scipy.sparse.linalg.LinearOperator`.
//!
//! Every kernel runs with the GIL released; iterative solvers take it back once per iteration
//! to call the user's callback and to let Ctrl-C interrupt them. Errors of the library become
//! `ValueError` with its one-line message; arguments of the wrong type become `TypeError`.

mod continuous;
mod observer;
mod operator;
mod simulate;
mod solve;

use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::{PyMemoryError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pythonize::pythonize;

use rdlidar::lidar::{Scene, TileSize, DEFAULT_TAU_S};
use rdlidar::recon::{compare, Method};
use rdlidar::settings::FrontEnd;

/// A library error as Python expects it: `MemoryError` for a request beyond memory,
/// `ValueError` naming the argument for bad values and shapes.
fn value_error(e: rdlidar::Error) -> PyErr {
    let text = FrontEnd::Python.render(&e);
    match e {
        rdlidar::Error::TooLarge { .. } => PyMemoryError::new_err(text),
        _ => PyValueError::new_err(text),
    }
}

/// `$body` with `$name` bound to the operator `$op` (an [`operator::Op`]) in its precision.
#[macro_export]
#[doc(hidden)]
macro_rules! each_precision {
    ($op:expr, $name:ident => $body:expr) => {
        match $op {
            $crate::operator::Op::F32($name) => $body,
            $crate::operator::Op::F64($name) => $body,
        }
    };
}

/// The 1-D array `x` (named `what`) of `count` finite values of `T`.
fn vector<T: rdlidar::Real + numpy::Element>(
    x: &Bound<'_, PyAny>,
    count: usize,
    what: &'static str,
) -> PyResult<Vec<T>> {
    let a = x.extract::<PyReadonlyArray1<'_, T>>().map_err(|_| {
        PyTypeError::new_err(format!(
            "{what}: expected a 1-D {} array",
            std::any::type_name::<T>()
        ))
    })?;
    if a.len() != count {
        return Err(PyValueError::new_err(format!(
            "{what}: expected {count} values, got {}",
            a.len()
        )));
    }
    let v: Vec<T> = a.as_array().iter().copied().collect();
    rdlidar::acquisition::check_finite(&v, what).map_err(value_error)?;
    Ok(v)
}

/// The tile size of Python's `tiles=(A, B)`, if given.
fn tile_size(tiles: Option<(usize, usize)>) -> PyResult<Option<TileSize>> {
    tiles
        .map(|(m, n)| TileSize::new(m, n))
        .transpose()
        .map_err(value_error)
}

fn scene_of(a: &PyReadonlyArray3<'_, f64>, what: &str) -> PyResult<Scene<f64>> {
    let arr: Array3<f64> = a.as_array().to_owned();
    Scene::new(arr).map_err(|e| PyValueError::new_err(format!("{what}: {e}")))
}

/// Detection and error metrics of an estimated scene against the truth.
#[pyfunction]
#[pyo3(signature = (truth, estimate, tau_s=None))]
fn metrics<'py>(
    py: Python<'py>,
    truth: PyReadonlyArray3<'py, f64>,
    estimate: PyReadonlyArray3<'py, f64>,
    tau_s: Option<f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let t = scene_of(&truth, "truth")?;
    let e = scene_of(&estimate, "estimate")?;
    let m = compare(&t, &e, tau_s.unwrap_or(DEFAULT_TAU_S)).map_err(value_error)?;
    Ok(pythonize(py, &m)?)
}

/// Checks, before any work, that a simulation can be written into the folder `out`.
#[pyfunction]
fn check_simulation_dir(out: std::path::PathBuf, force: bool) -> PyResult<()> {
    rdlidar::acquisition::check_simulation_dir(&out, force).map_err(value_error)
}

/// The names of the reconstruction methods, as `reconstruct` takes them.
#[pyfunction]
fn solvers() -> Vec<&'static str> {
    Method::ALL.iter().map(|m| m.name()).collect()
}

/// The Rust core of the `rdlidar` Python package.
#[pymodule]
fn _rdlidar(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // NumPy's C API is set up by the first array made, and the setup runs Python code
    // (numpy.lib.NumpyVersion), where an exception such as a pending Ctrl-C becomes a panic of
    // rust-numpy (a PanicException): set it up now, at import, before any work can be
    // interrupted.
    PyModule::import(m.py(), "numpy")?;
    let _api = Vec::<f64>::new().into_pyarray(m.py());
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<operator::PyOperator>()?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(solve::reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(solve::fista, m)?)?;
    m.add_function(wrap_pyfunction!(metrics, m)?)?;
    m.add_function(wrap_pyfunction!(continuous::depth_bound, m)?)?;
    m.add_function(wrap_pyfunction!(continuous::range_metrics, m)?)?;
    m.add_function(wrap_pyfunction!(continuous::points, m)?)?;
    m.add_function(wrap_pyfunction!(solvers, m)?)?;
    m.add_function(wrap_pyfunction!(check_simulation_dir, m)?)?;
    Ok(())
}
