//! `rdlidar._rdlidar`: the Rust core of the Python package. The package's Python layer
//! (`python/rdlidar/__init__.py`) converts its arguments to the dtypes and shapes these
//! functions take and wraps the operator as a `scipy.sparse.linalg.LinearOperator`.
//!
//! Every kernel runs with the GIL released; iterative solvers take it back once per iteration
//! to call the user's callback and to let Ctrl-C interrupt them. Errors of the library become
//! `ValueError` with its one-line message; arguments of the wrong type become `TypeError`.

use std::sync::Arc;

use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use rdlidar::lidar::{
    simulate as simulate_scene, zero_mean, Architecture, Codes, Geometry, LidarOperator,
    RdOperator, Scene, SceneSpec, SimulationSpec, DEFAULT_TAU_S,
};
use rdlidar::operator::{DotTest, LinearOperator};
use rdlidar::recon::{compare, reconstruct_observed, Method, ReconstructOptions};
use rdlidar::solver::{
    fista as fista_solver, Control, FistaParams, IterationInfo, Lambda, Report, Restart, StepRule,
    Stopping,
};
use rdlidar::Real;

/// A library error as the `ValueError` Python expects for bad values and shapes.
fn value_error(e: rdlidar::Error) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// The operator in the precision it was built for.
enum Op {
    F32(RdOperator<f32>),
    F64(RdOperator<f64>),
}

/// Codes as the Python layer passes them: int8 (M, N, K), or packed uint8 (M, N, ⌈K/8⌉).
fn read_codes(codes: &Bound<'_, PyAny>, k: usize) -> PyResult<(usize, usize, Codes)> {
    if let Ok(a) = codes.extract::<PyReadonlyArray3<'_, i8>>() {
        let (m, n, kk) = a.as_array().dim();
        if kk != k {
            return Err(PyValueError::new_err(format!(
                "codes: int8 codes of shape ({m}, {n}, {kk}) have {kk} samples per pixel, but \
                 the pulse and depth_bins give K = K_p + K_s - 1 = {k}"
            )));
        }
        let flat: Vec<i8> = a.as_array().iter().copied().collect();
        let view = numpy::ndarray::ArrayView2::from_shape((m * n, k), &flat)
            .map_err(|e| PyValueError::new_err(format!("codes: {e}")))?;
        let c =
            Codes::from_dense(view).map_err(|e| PyValueError::new_err(format!("codes: {e}")))?;
        return Ok((m, n, c));
    }
    if let Ok(a) = codes.extract::<PyReadonlyArray3<'_, u8>>() {
        let (m, n, nb) = a.as_array().dim();
        if nb != k.div_ceil(8) {
            return Err(PyValueError::new_err(format!(
                "codes: packed codes of shape ({m}, {n}, {nb}) have {nb} bytes per pixel, but \
                 K = K_p + K_s - 1 = {k} samples pack into {}",
                k.div_ceil(8)
            )));
        }
        let bytes: Vec<u8> = a.as_array().iter().copied().collect();
        let c = Codes::from_packbits(&bytes, m * n, k)
            .map_err(|e| PyValueError::new_err(format!("codes: {e}")))?;
        return Ok((m, n, c));
    }
    Err(PyTypeError::new_err(
        "codes must be a 3-D int8 array (M, N, K) of -1, 0, 1, or a 3-D uint8 array \
         (M, N, ceil(K/8)) as np.packbits(S > 0, axis=-1) writes it",
    ))
}

/// The fused lidar operator A = Σ·S·P (one ADC), in float32 or float64.
#[pyclass(name = "_Operator", module = "rdlidar._rdlidar", frozen)]
struct PyOperator {
    op: Op,
    geom: Geometry,
    samples: usize,
}

fn build<T: Real>(
    geom: Geometry,
    pulse: &[f64],
    codes: Codes,
    debiased: bool,
) -> PyResult<RdOperator<T>> {
    let p: Vec<T> = pulse.iter().map(|&v| T::of_f64(v)).collect();
    if let Some(i) = p.iter().position(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "pulse: sample {i} ({}) is not finite in the operator's dtype",
            pulse[i]
        )));
    }
    let p = if debiased { zero_mean(&p) } else { p };
    RdOperator::new(geom, p, Arc::new(codes)).map_err(value_error)
}

/// Applies `op` (or its adjoint) to a copy of `x` with the GIL released.
fn apply<'py, T: Real + numpy::Element>(
    py: Python<'py>,
    op: &RdOperator<T>,
    x: &Bound<'py, PyAny>,
    adjoint: bool,
) -> PyResult<Bound<'py, PyArray1<T>>> {
    let (n_in, n_out, what) = if adjoint {
        (op.nrows(), op.ncols(), "y")
    } else {
        (op.ncols(), op.nrows(), "x")
    };
    let a = x.extract::<PyReadonlyArray1<'_, T>>().map_err(|_| {
        PyTypeError::new_err(format!(
            "{what}: expected a 1-D {} array",
            std::any::type_name::<T>()
        ))
    })?;
    if a.len() != n_in {
        return Err(PyValueError::new_err(format!(
            "{what}: expected {n_in} values, got {}",
            a.len()
        )));
    }
    let v: Vec<T> = a.as_array().iter().copied().collect();
    drop(a);
    let out = py.detach(|| {
        let mut o = vec![T::zero(); n_out];
        if adjoint {
            op.apply_adjoint(&v, &mut o);
        } else {
            op.apply(&v, &mut o);
        }
        o
    });
    Ok(out.into_pyarray(py))
}

#[pymethods]
impl PyOperator {
    #[new]
    #[pyo3(signature = (pulse, codes, depth_bins, double, debiased))]
    fn new(
        pulse: PyReadonlyArray1<'_, f64>,
        codes: &Bound<'_, PyAny>,
        depth_bins: usize,
        double: bool,
        debiased: bool,
    ) -> PyResult<Self> {
        let p: Vec<f64> = pulse.as_array().iter().copied().collect();
        if p.is_empty() {
            return Err(PyValueError::new_err(
                "pulse: must have at least one sample",
            ));
        }
        if depth_bins == 0 {
            return Err(PyValueError::new_err("depth_bins: must be at least 1"));
        }
        let k = p
            .len()
            .checked_add(depth_bins - 1)
            .ok_or_else(|| PyValueError::new_err("depth_bins: too large"))?;
        let (m, n, c) = read_codes(codes, k)?;
        let geom = Geometry::new(m, n, depth_bins).map_err(value_error)?;
        let op = if double {
            Op::F64(build(geom, &p, c, debiased)?)
        } else {
            Op::F32(build(geom, &p, c, debiased)?)
        };
        Ok(PyOperator {
            op,
            geom,
            samples: k,
        })
    }

    /// y = A x for a 1-D array of M·N·K_s values of the operator's dtype.
    fn forward<'py>(&self, py: Python<'py>, x: &Bound<'py, PyAny>) -> PyResult<Py<PyAny>> {
        Ok(match &self.op {
            Op::F32(op) => apply(py, op, x, false)?.into_any().unbind(),
            Op::F64(op) => apply(py, op, x, false)?.into_any().unbind(),
        })
    }

    /// x = Aᵀ y for a 1-D array of K values of the operator's dtype.
    fn adjoint<'py>(&self, py: Python<'py>, y: &Bound<'py, PyAny>) -> PyResult<Py<PyAny>> {
        Ok(match &self.op {
            Op::F32(op) => apply(py, op, y, true)?.into_any().unbind(),
            Op::F64(op) => apply(py, op, y, true)?.into_any().unbind(),
        })
    }

    /// (M, N, K_s).
    #[getter]
    fn geometry(&self) -> (usize, usize, usize) {
        (self.geom.m, self.geom.n, self.geom.ks)
    }

    /// K = K_p + K_s − 1.
    #[getter]
    fn samples(&self) -> usize {
        self.samples
    }

    /// The instruction set of the kernels.
    #[getter]
    fn isa(&self) -> &'static str {
        match &self.op {
            Op::F32(op) => op.isa(),
            Op::F64(op) => op.isa(),
        }
    }

    /// The pulse the operator applies (zero-mean when built debiased), as float64.
    #[getter]
    fn pulse<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let p: Vec<f64> = match &self.op {
            Op::F32(op) => op.pulse().iter().map(|v| v.as_f64()).collect(),
            Op::F64(op) => op.pulse().to_vec(),
        };
        p.into_pyarray(py)
    }

    /// The dot test ⟨Ax, y⟩ = ⟨x, Aᵀy⟩ with Gaussian x, y from `seed`.
    #[pyo3(signature = (seed=0, tolerance=None))]
    fn dot_test<'py>(
        &self,
        py: Python<'py>,
        seed: u64,
        tolerance: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mut test = DotTest::new().seed(seed);
        if let Some(t) = tolerance {
            if !(t.is_finite() && t > 0.0) {
                return Err(PyValueError::new_err(format!(
                    "tolerance: must be positive and finite, got {t}"
                )));
            }
            test = test.tolerance(t);
        }
        let r = py.detach(|| match &self.op {
            Op::F32(op) => test.measure(op),
            Op::F64(op) => test.measure(op),
        });
        let d = PyDict::new(py);
        d.set_item("lhs", r.lhs)?;
        d.set_item("rhs", r.rhs)?;
        d.set_item("gap", r.gap)?;
        d.set_item("tolerance", r.tolerance)?;
        d.set_item("passed", r.passed())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let (d, kp) = match &self.op {
            Op::F32(op) => ("float32", op.pulse().len()),
            Op::F64(op) => ("float64", op.pulse().len()),
        };
        format!(
            "rdlidar operator {}x{}x{}, K_p {kp}, K {}, {d}, {}",
            self.geom.m,
            self.geom.n,
            self.geom.ks,
            self.samples,
            self.isa()
        )
    }
}

/// Simulates an acquisition with one ADC; returns a dict of arrays and the description.
#[pyfunction]
#[pyo3(signature = (scene, size, pulse_len, seed, snr_db, ternary_zero_prob, lit_fraction, double))]
#[allow(clippy::too_many_arguments)]
fn simulate<'py>(
    py: Python<'py>,
    scene: &str,
    size: (usize, usize, usize),
    pulse_len: usize,
    seed: u64,
    snr_db: Option<f64>,
    ternary_zero_prob: Option<f64>,
    lit_fraction: Option<f64>,
    double: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let geometry = Geometry::new(size.0, size.1, size.2).map_err(value_error)?;
    let spec_scene = match (scene, lit_fraction) {
        ("paper", None) => SceneSpec::Paper,
        ("transparent", None) => SceneSpec::Transparent,
        ("random", f) => SceneSpec::Random {
            lit_fraction: f.unwrap_or(0.1),
        },
        ("paper" | "transparent", Some(_)) => {
            return Err(PyValueError::new_err(format!(
                "lit_fraction: only the random scene has one, not {scene:?}"
            )))
        }
        _ => {
            return Err(PyValueError::new_err(format!(
                "scene: {scene:?} is not one of \"paper\", \"transparent\", \"random\""
            )))
        }
    };
    if pulse_len == 0 {
        return Err(PyValueError::new_err("pulse_len: must be at least 1"));
    }
    let spec = SimulationSpec {
        scene: spec_scene,
        ternary_zero_prob,
        snr_db,
        architecture: Architecture::Single,
        ..SimulationSpec::new(geometry, pulse_len, seed)
    };
    spec.memory_plan::<f64>()
        .and_then(|plan| plan.check("simulate", "use a smaller size or pulse"))
        .map_err(value_error)?;
    let d = PyDict::new(py);
    if double {
        fill_simulation::<f64>(py, &spec, &d)?;
    } else {
        fill_simulation::<f32>(py, &spec, &d)?;
    }
    Ok(d)
}

fn fill_simulation<'py, T: Real + numpy::Element>(
    py: Python<'py>,
    spec: &SimulationSpec,
    d: &Bound<'py, PyDict>,
) -> PyResult<()> {
    let sim = py
        .detach(|| simulate_scene::<T>(spec))
        .map_err(value_error)?;
    let g = spec.geometry;
    let codes = sim.code_sets[0].to_dense();
    let k = codes.ncols();
    let codes = codes
        .into_shape_with_order((g.m, g.n, k))
        .map_err(|e| PyValueError::new_err(format!("codes: {e}")))?;
    d.set_item("scene", sim.scene.into_inner().into_pyarray(py))?;
    d.set_item("pulse", sim.pulse.into_inner().into_pyarray(py))?;
    d.set_item("codes", codes.into_pyarray(py))?;
    d.set_item("meas", sim.meas.into_pyarray(py))?;
    let meta = PyDict::new(py);
    meta.set_item("size", (g.m, g.n, g.ks))?;
    meta.set_item("pulse_len", spec.pulse_len)?;
    meta.set_item("samples", k)?;
    meta.set_item("seed", spec.seed)?;
    meta.set_item("scene", spec.scene.name())?;
    meta.set_item("snr_db", spec.snr_db)?;
    meta.set_item("ternary_zero_prob", spec.ternary_zero_prob)?;
    meta.set_item(
        "regime",
        format!("{}", rdlidar::lidar::Regime::of(k, g.voxels())),
    )?;
    if let Some(noise) = &sim.noise {
        meta.set_item("noise", format!("{noise:?}"))?;
    }
    d.set_item("meta", meta)?;
    Ok(())
}

/// The report of a solver as a dict.
fn report_dict<'py>(py: Python<'py>, r: &Report, d: &Bound<'py, PyDict>) -> PyResult<()> {
    d.set_item("solver", r.solver)?;
    d.set_item("iterations", r.iterations)?;
    d.set_item("termination", format!("{:?}", r.termination))?;
    d.set_item("residual_history", PyList::new(py, &r.residual_history)?)?;
    d.set_item("objective_history", PyList::new(py, &r.objective_history)?)?;
    d.set_item("forward_applies", r.forward_applies)?;
    d.set_item("adjoint_applies", r.adjoint_applies)?;
    d.set_item("support_applies", r.support_applies)?;
    d.set_item("solver_seconds", r.elapsed.as_secs_f64())?;
    Ok(())
}

/// One iteration seen from Python: takes the GIL back, lets Ctrl-C interrupt, and calls the
/// callback (if any) with the iteration's numbers; a true return value stops the solver, an
/// exception is kept in `failure` and stops it too.
fn observe<T>(
    info: &IterationInfo<'_, T>,
    callback: Option<&Py<PyAny>>,
    failure: &mut Option<PyErr>,
) -> Control {
    Python::attach(|py| {
        let go_on = (|| -> PyResult<bool> {
            py.check_signals()?;
            if let Some(cb) = callback {
                let d = PyDict::new(py);
                d.set_item("iteration", info.iteration)?;
                d.set_item("residual", info.residual)?;
                d.set_item("objective", info.objective)?;
                d.set_item("change", info.change)?;
                d.set_item("seconds", info.elapsed.as_secs_f64())?;
                let stop = cb.call1(py, (d,))?;
                return Ok(!stop.bind(py).is_truthy()?);
            }
            Ok(true)
        })();
        match go_on {
            Ok(true) => Control::Continue,
            Ok(false) => Control::Stop,
            Err(e) => {
                *failure = Some(e);
                Control::Stop
            }
        }
    })
}

/// The measurements as a vector of the operator's dtype and length, finite.
fn measurements<T: Real + numpy::Element>(
    meas: &Bound<'_, PyAny>,
    rows: usize,
) -> PyResult<Vec<T>> {
    let y = meas.extract::<PyReadonlyArray1<'_, T>>().map_err(|_| {
        PyTypeError::new_err(format!(
            "meas: expected a 1-D {} array",
            std::any::type_name::<T>()
        ))
    })?;
    if y.len() != rows {
        return Err(PyValueError::new_err(format!(
            "meas: expected K = {rows} values, got {}",
            y.len()
        )));
    }
    let y: Vec<T> = y.as_array().iter().copied().collect();
    if let Some(i) = y.iter().position(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "meas: value {i} ({}) is not finite",
            y[i]
        )));
    }
    Ok(y)
}

/// FISTA on ½‖Ax − y‖² + λ‖x‖₁ from x = 0 with the step 1/L (L = 1/`step`, or a power-iteration
/// estimate of ‖A‖² when `step` is None), for exactly `niter` iterations unless `tol` (the
/// relative change of x) stops it first; returns (x, report).
#[pyfunction]
#[pyo3(signature = (operator, meas, lam, step, niter, nonnegative, restart, tol, callback))]
#[allow(clippy::too_many_arguments)]
fn fista<'py>(
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
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    if niter == 0 {
        return Err(PyValueError::new_err("niter: must be at least 1"));
    }
    let step_rule = match step {
        Some(s) if s.is_finite() && s > 0.0 => StepRule::Fixed { lipschitz: 1.0 / s },
        Some(s) => {
            return Err(PyValueError::new_err(format!(
                "step: must be positive and finite, got {s}"
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
    match &operator.op {
        Op::F32(op) => run_fista(py, op, meas, &params, callback),
        Op::F64(op) => run_fista(py, op, meas, &params, callback),
    }
}

fn run_fista<'py, T: Real + numpy::Element>(
    py: Python<'py>,
    op: &RdOperator<T>,
    meas: &Bound<'py, PyAny>,
    params: &FistaParams,
    callback: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let y = measurements::<T>(meas, op.nrows())?;
    let mut failure: Option<PyErr> = None;
    let mut x = vec![T::zero(); op.ncols()];
    let result = py.detach(|| {
        let mut observe =
            |info: &IterationInfo<'_, T>| observe(info, callback.as_ref(), &mut failure);
        fista_solver(op, &y, &mut x, params, &mut observe)
    });
    if let Some(e) = failure {
        return Err(e);
    }
    let r = result.map_err(value_error)?;
    let report = PyDict::new(py);
    report_dict(py, &r, &report)?;
    pyo3::types::PyTuple::new(py, [x.into_pyarray(py).into_any(), report.into_any()])
}

/// Runs a reconstruction method; returns (depth, scene, report).
#[pyfunction]
#[pyo3(signature = (operator, meas, solver, max_iter, callback, seed))]
fn reconstruct<'py>(
    py: Python<'py>,
    operator: &PyOperator,
    meas: &Bound<'py, PyAny>,
    solver: &str,
    max_iter: Option<usize>,
    callback: Option<Py<PyAny>>,
    seed: u64,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let method: Method = solver
        .parse()
        .map_err(|e: rdlidar::Error| PyValueError::new_err(format!("solver: {e}")))?;
    if max_iter == Some(0) {
        return Err(PyValueError::new_err("max_iter: must be at least 1"));
    }
    let options = ReconstructOptions {
        max_iter,
        seed,
        ..ReconstructOptions::default()
    };
    match &operator.op {
        Op::F32(op) => run_reconstruct(py, op, meas, method, &options, callback),
        Op::F64(op) => run_reconstruct(py, op, meas, method, &options, callback),
    }
}

fn run_reconstruct<'py, T: Real + numpy::Element>(
    py: Python<'py>,
    op: &RdOperator<T>,
    meas: &Bound<'py, PyAny>,
    method: Method,
    options: &ReconstructOptions,
    callback: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let y = measurements::<T>(meas, op.nrows())?;
    let mut failure: Option<PyErr> = None;
    let result = py.detach(|| {
        let mut observe = |info: &IterationInfo<'_, T>| -> Control {
            Python::attach(|py| {
                let go_on = (|| -> PyResult<bool> {
                    py.check_signals()?;
                    if let Some(cb) = &callback {
                        let d = PyDict::new(py);
                        d.set_item("iteration", info.iteration)?;
                        d.set_item("residual", info.residual)?;
                        d.set_item("objective", info.objective)?;
                        d.set_item("change", info.change)?;
                        d.set_item("seconds", info.elapsed.as_secs_f64())?;
                        let stop = cb.call1(py, (d,))?;
                        return Ok(!stop.bind(py).is_truthy()?);
                    }
                    Ok(true)
                })();
                match go_on {
                    Ok(true) => Control::Continue,
                    Ok(false) => Control::Stop,
                    Err(e) => {
                        failure = Some(e);
                        Control::Stop
                    }
                }
            })
        };
        reconstruct_observed(
            op as &dyn LidarOperator<T>,
            &y,
            method,
            options,
            &mut observe,
        )
    });
    if let Some(e) = failure {
        return Err(e);
    }
    let r = result.map_err(value_error)?;
    let depth = r.depth.depth.clone().into_pyarray(py);
    let report = PyDict::new(py);
    report.set_item("method", method.name())?;
    report.set_item("method_used", r.method_used.name())?;
    report.set_item("regime", format!("{}", r.regime))?;
    report.set_item("seconds", r.elapsed.as_secs_f64())?;
    match &r.report {
        Some(rep) => report_dict(py, rep, &report)?,
        None => {
            report.set_item("iterations", 0)?;
            report.set_item("termination", py.None())?;
            report.set_item("residual_history", PyList::empty(py))?;
        }
    }
    let stages = PyList::empty(py);
    for s in &r.stages {
        let d = PyDict::new(py);
        d.set_item("method", s.method.name())?;
        d.set_item("relative_residual", s.relative_residual)?;
        d.set_item("returns", s.returns)?;
        d.set_item("kept", s.kept)?;
        d.set_item("verdict", &s.verdict)?;
        if let Some(rep) = &s.report {
            report_dict(py, rep, &d)?;
        }
        stages.append(d)?;
    }
    report.set_item("stages", stages)?;
    let scene = r.scene.into_inner().into_pyarray(py);
    pyo3::types::PyTuple::new(py, [depth.into_any(), scene.into_any(), report.into_any()])
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
) -> PyResult<Bound<'py, PyDict>> {
    let t = scene_of(&truth, "truth")?;
    let e = scene_of(&estimate, "estimate")?;
    let m = compare(&t, &e, tau_s.unwrap_or(DEFAULT_TAU_S)).map_err(value_error)?;
    let d = PyDict::new(py);
    d.set_item("pixels", m.pixels)?;
    d.set_item("lit", m.lit)?;
    d.set_item("empty", m.empty)?;
    d.set_item("exact", m.exact)?;
    d.set_item("exact_fraction", m.exact_fraction)?;
    d.set_item("detected", m.detected)?;
    d.set_item("depth_rmse_bins", m.depth_rmse_bins)?;
    d.set_item("depth_rmse_m", m.depth_rmse_m)?;
    d.set_item("bin_m", m.bin_m)?;
    d.set_item("missed", m.missed)?;
    d.set_item("missed_fraction", m.missed_fraction)?;
    d.set_item("false_detections", m.false_detections)?;
    d.set_item("false_fraction_all", m.false_fraction_all)?;
    d.set_item("false_fraction_empty", m.false_fraction_empty)?;
    d.set_item("relative_error", m.relative_error)?;
    d.set_item("true_returns", m.true_returns)?;
    d.set_item("returns_exact", m.returns_exact)?;
    d.set_item("returns_missed", m.returns_missed)?;
    d.set_item("returns_false", m.returns_false)?;
    Ok(d)
}

/// The names of the reconstruction methods, as `reconstruct` takes them.
#[pyfunction]
fn solvers() -> Vec<&'static str> {
    Method::ALL.iter().map(|m| m.name()).collect()
}

/// The Rust core of the `rdlidar` Python package.
#[pymodule]
fn _rdlidar(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<PyOperator>()?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(fista, m)?)?;
    m.add_function(wrap_pyfunction!(metrics, m)?)?;
    m.add_function(wrap_pyfunction!(solvers, m)?)?;
    Ok(())
}
