//! The solvers as Python runs them: FISTA on the operator, and every reconstruction method.

use numpy::IntoPyArray;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use pythonize::pythonize;

use rdlidar::acquisition::{Acquisition, Clipping, ReconstructRequest};
use rdlidar::io::read_response;
use rdlidar::lidar::{Architecture, Cancellable, Response};
use rdlidar::operator::{BoxedOperator, LinearOperator};
use rdlidar::recon::{NoiseModel, ReconstructOptions, TileReconstruction};
use rdlidar::settings::FrontEnd;
use rdlidar::solver::{
    fista as fista_solver, FistaParams, IterationInfo, Lambda, Restart, StepRule, Stopping,
};
use rdlidar::Real;

use crate::observer::PyObserver;
use crate::operator::{Op, PyOperator};
use crate::{each_precision, value_error, vector};

/// FISTA on ½‖Ax − y‖² + λ‖x‖₁ from x = 0 with the step 1/L (L = 1/`step`, or a Lanczos
/// estimate of ‖A‖² when `step` is None), for exactly `niter` iterations unless `tol` (the
/// relative change of x) stops it first; returns (x, report).
#[pyfunction]
#[pyo3(signature = (operator, meas, lam, step, niter, nonnegative, restart, tol, callback))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn fista<'py>(
    py: Python<'py>,
    operator: &PyOperator,
    meas: &Bound<'py, PyAny>,
    lam: f64,
    step: Option<f64>,
    niter: usize,
    nonnegative: bool,
    restart: bool,
    tol: Option<f64>,
    callback: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    if niter == 0 {
        return Err(PyValueError::new_err("niter: must be at least 1"));
    }
    let step_rule = match step {
        Some(s) if s.is_finite() && s > 0.0 => StepRule::Fixed { lipschitz: 1.0 / s },
        Some(s) => {
            return Err(PyValueError::new_err(format!(
                "step: must be positive and finite, got {}",
                rdlidar::units::number(s)
            )))
        }
        None => StepRule::default(),
    };
    let params = FistaParams {
        lambda: Lambda::Absolute(lam),
        nonnegative,
        step: step_rule,
        restart: if restart {
            Restart::Function
        } else {
            Restart::Off
        },
        stopping: Stopping {
            max_iter: niter,
            rel_residual: None,
            rel_change: tol,
            ..Stopping::default()
        },
    };
    let acq = &operator.acq;
    each_precision!(&operator.op, op => run_fista(py, acq, op, meas, &params, callback))
}

fn run_fista<'py, T: Real + numpy::Element>(
    py: Python<'py>,
    acq: &Acquisition,
    op: &BoxedOperator<T>,
    meas: &Bound<'py, PyAny>,
    params: &FistaParams,
    callback: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let y = vector::<T>(meas, op.nrows(), "meas")?;
    // FISTA holds a few scenes: the iterate, the momentum point, the gradient.
    acq.solver_memory_plan::<T>(6)
        .check("fista", "use a smaller acquisition or free memory")
        .map_err(value_error)?;
    let observer = PyObserver::new(callback);
    let mut x = vec![T::zero(); op.ncols()];
    let result = observer.watch(py, || {
        let mut observe = |info: &IterationInfo<'_, T>| observer.observe(None, info);
        let op = Cancellable::new(op.as_ref(), &observer.cancel);
        fista_solver(&op, &y, &mut x, params, &mut observe)
    });
    if let Some(e) = observer.failure() {
        return Err(e);
    }
    let report = pythonize(py, &result.map_err(value_error)?)?;
    PyTuple::new(py, [x.into_pyarray(py).into_any(), report])
}

/// Runs a reconstruction method on any architecture; returns (depth, scene, report).
#[pyfunction]
#[pyo3(signature = (operator, meas, solver, max_iter, callback, seed, fill_unobserved=false, clipped=None, false_rate=None, noise="gaussian", background=None, kernel=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn reconstruct<'py>(
    py: Python<'py>,
    operator: &PyOperator,
    meas: &Bound<'py, PyAny>,
    solver: &str,
    max_iter: Option<usize>,
    callback: Option<Py<PyAny>>,
    seed: u64,
    fill_unobserved: bool,
    clipped: Option<&str>,
    false_rate: Option<f64>,
    noise: &str,
    background: Option<f64>,
    kernel: Option<&str>,
) -> PyResult<Bound<'py, PyTuple>> {
    if operator.debiased {
        return Err(PyValueError::new_err(
            "operator: reconstruct needs the operator of the physical pulse, not debiased",
        ));
    }
    let noise = noise.parse::<NoiseModel>().map_err(value_error)?;
    let job = ReconstructRequest {
        method: solver.parse().map_err(value_error)?,
        options: ReconstructOptions {
            max_iter,
            seed,
            false_rate,
            noise: ReconstructRequest::noise_model(noise, background).map_err(value_error)?,
            response: kernel
                .map(read_response)
                .transpose()
                .map_err(value_error)?
                .unwrap_or(Response::Delta),
            ..ReconstructOptions::default()
        },
        clipped: clipped
            .map(str::parse::<Clipping>)
            .transpose()
            .map_err(value_error)?,
        fill_unobserved,
    };
    job.validate().map_err(value_error)?;
    match &operator.op {
        Op::F32(_) => run_reconstruct::<f32>(py, &operator.acq, meas, &job, callback),
        Op::F64(_) => run_reconstruct::<f64>(py, &operator.acq, meas, &job, callback),
    }
}

fn run_reconstruct<'py, T: Real + numpy::Element>(
    py: Python<'py>,
    acq: &Acquisition,
    meas: &Bound<'py, PyAny>,
    job: &ReconstructRequest,
    callback: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let y = vector::<T>(meas, acq.measurements(), "meas")?;
    job.check_memory::<T>(acq).map_err(value_error)?;
    let (acq, y, censoring) = job.censor(acq.clone(), y).map_err(value_error)?;
    let acq = &acq;
    let observer = PyObserver::new(callback);
    let tiled = matches!(acq.architecture(), Architecture::Tiles(_));
    let result = observer.watch(py, || {
        let observe = |tile: usize, info: &IterationInfo<'_, T>| {
            observer.observe(tiled.then_some(tile), info)
        };
        job.run(
            acq,
            &y,
            &observe,
            &|_: &TileReconstruction<T>| {},
            &observer.cancel,
        )
    });
    if let Some(e) = observer.failure() {
        return Err(e);
    }
    let r = result.map_err(value_error)?;
    let outcome = job.finish(r, acq, censoring.as_ref());
    let report = pythonize(py, &outcome.summary)?.cast_into::<PyDict>()?;
    report.set_item("request", FrontEnd::Python.words(&job.summary()))?;
    if let Some(returns) = outcome.returns {
        report.set_item("range", returns.range_map().into_pyarray(py))?;
        report.set_item("amplitude", returns.amplitude_map().into_pyarray(py))?;
    }
    let depth = outcome.depth.depth.into_pyarray(py);
    let scene = outcome.scene.into_inner().into_pyarray(py);
    PyTuple::new(py, [depth.into_any(), scene.into_any(), report.into_any()])
}
