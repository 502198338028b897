//! `rdlidar._rdlidar`: the Rust core of the Python package. The package's Python layer
//! (`python/rdlidar/__init__.py`) converts its arguments to the dtypes and shapes these
//! functions take and wraps the operator as a `scipy.sparse.linalg.LinearOperator`.
//!
//! Every kernel runs with the GIL released; iterative solvers take it back once per iteration
//! to call the user's callback and to let Ctrl-C interrupt them. Errors of the library become
//! `ValueError` with its one-line message; arguments of the wrong type become `TypeError`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use numpy::ndarray::Array3;
use numpy::{
    IntoPyArray, PyArray1, PyReadonlyArray1, PyReadonlyArray3, PyReadonlyArrayDyn,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyMemoryError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use rdlidar::acquisition::{
    check_finite, check_finite_result, check_pulse, pulse_in, simulation_meta,
    write_simulation_cancellable, Acquisition, AcquisitionFiles, Clipping, CodeStore, CodesFormat,
    InputNames, ReconstructRequest, Reconstructed, SimulationRequest, Streaming, Use,
};
use rdlidar::lidar::{
    simulate_cancellable, zero_mean, Architecture, Cancellable, Codes, Geometry, Scene, Simulation,
    SimulationSpec, TileSize, DEFAULT_TAU_S,
};
use rdlidar::operator::{BoxedOperator, DotTest, LinearOperator};
use rdlidar::recon::{compare, Method, NoiseModel, ReconstructOptions, TileReconstruction};
use rdlidar::settings::FrontEnd;
use rdlidar::solver::{
    fista as fista_solver, Control, FistaParams, IterationInfo, Lambda, Report, Restart, StepRule,
    Stopping,
};
use rdlidar::Real;

/// A library error as Python expects it: `MemoryError` for a request beyond memory,
/// `ValueError` naming the argument for bad values and shapes.
fn value_error(e: rdlidar::Error) -> PyErr {
    let text = FrontEnd::Python.render(&e);
    match e {
        rdlidar::Error::TooLarge { .. } => PyMemoryError::new_err(text),
        _ => PyValueError::new_err(text),
    }
}

/// The operator in the precision it was built for.
enum Op {
    F32(BoxedOperator<f32>),
    F64(BoxedOperator<f64>),
}

/// Code sets as the Python layer passes them: int8 (M, N, K) or (G, M, N, K), or packed
/// uint8 (M, N, ⌈K/8⌉) or (G, M, N, ⌈K/8⌉). Shapes and memory are checked before anything is
/// copied.
fn read_code_arrays<T: Real>(
    codes: &Bound<'_, PyAny>,
    pulse_len: usize,
    depth_bins: usize,
    tiles: Option<TileSize>,
) -> PyResult<(Geometry, Vec<Arc<Codes>>, bool)> {
    rdlidar::limits::check_count("depth_bins", depth_bins, rdlidar::limits::MAX_DEPTH_BINS)
        .map_err(value_error)?;
    let k = pulse_len
        .checked_add(depth_bins - 1)
        .ok_or_else(|| PyValueError::new_err("depth_bins: too large"))?;
    let (packed, view) = if let Ok(a) = codes.extract::<PyReadonlyArrayDyn<'_, i8>>() {
        (false, ArrayLike::I8(a))
    } else if let Ok(a) = codes.extract::<PyReadonlyArrayDyn<'_, u8>>() {
        (true, ArrayLike::U8(a))
    } else {
        return Err(PyTypeError::new_err(
            "codes must be an int8 array (M, N, K) or (G, M, N, K) of -1, 0, 1, a uint8 array \
             (M, N, ceil(K/8)) or (G, M, N, ceil(K/8)) as np.packbits(S > 0, axis=-1) writes \
             it, or the path of a meta.json of seeded codes",
        ));
    };
    let shape = view.shape();
    let (sets, m, n, last) = match shape[..] {
        [m, n, l] => (1, m, n, l),
        [g, m, n, l] => (g, m, n, l),
        _ => {
            return Err(PyValueError::new_err(format!(
                "codes: expected a 3-D array (M, N, K) or a 4-D array (G, M, N, K), got shape \
                 {shape:?}"
            )))
        }
    };
    let want = if packed { k.div_ceil(8) } else { k };
    if last != want {
        let (kind, unit) = if packed {
            ("packed", "bytes per pixel")
        } else {
            ("int8", "samples per pixel")
        };
        return Err(PyValueError::new_err(format!(
            "codes: {kind} codes of shape {shape:?} have {last} {unit}, but the pulse and \
             depth_bins give K = K_p + K_s - 1 = {k}{}",
            if packed {
                format!(" samples, which pack into {want}")
            } else {
                String::new()
            }
        )));
    }
    let geom = Acquisition::check_arrays::<T>((sets, m, n), depth_bins, pulse_len, tiles, 2)
        .map_err(value_error)?;
    let mut out = Vec::with_capacity(sets);
    for g in 0..sets {
        let c = match &view {
            ArrayLike::I8(a) => {
                let flat = code_set(a, g);
                let v = numpy::ndarray::ArrayView2::from_shape((m * n, k), &flat)
                    .map_err(|e| PyValueError::new_err(format!("codes: {e}")))?;
                Codes::from_dense(v)
            }
            ArrayLike::U8(a) => Codes::from_packbits(&code_set(a, g), m * n, k),
        }
        .map_err(|e| {
            let at = if sets > 1 {
                format!(" (code set {g})")
            } else {
                String::new()
            };
            PyValueError::new_err(format!("codes{at}: {e}"))
        })?;
        out.push(Arc::new(c));
    }
    Ok((geom, out, shape.len() == 4))
}

/// Code set `g` of an array of code sets (its first axis, when it has four), copied in C
/// order.
fn code_set<E: numpy::Element + Copy>(a: &PyReadonlyArrayDyn<'_, E>, g: usize) -> Vec<E> {
    let view = a.as_array();
    if view.ndim() == 4 {
        view.index_axis(numpy::ndarray::Axis(0), g)
            .iter()
            .copied()
            .collect()
    } else {
        view.iter().copied().collect()
    }
}

/// An int8 or uint8 array of any dimension.
enum ArrayLike<'py> {
    I8(PyReadonlyArrayDyn<'py, i8>),
    U8(PyReadonlyArrayDyn<'py, u8>),
}

impl ArrayLike<'_> {
    fn shape(&self) -> Vec<usize> {
        match self {
            ArrayLike::I8(a) => a.shape().to_vec(),
            ArrayLike::U8(a) => a.shape().to_vec(),
        }
    }
}

/// The measurement operator of an acquisition (one ADC, G ADCs, tiles, a coded aperture;
/// codes held or described by a seed), in float32 or float64.
#[pyclass(name = "_Operator", module = "rdlidar._rdlidar", frozen)]
struct PyOperator {
    op: Op,
    acq: Acquisition,
    debiased: bool,
}

/// The acquisition of `pulse` with `codes` (arrays, or the path of a codes file or seeded
/// meta.json).
fn acquisition<T: Real>(
    pulse: Vec<f64>,
    codes: &Bound<'_, PyAny>,
    (depth_bins, rows): (usize, Option<(usize, usize)>),
    tiles: Option<TileSize>,
    stream_codes: bool,
) -> PyResult<Acquisition> {
    check_pulse(&pulse).map_err(value_error)?;
    let streaming = if stream_codes {
        Streaming::Always
    } else {
        Streaming::Auto
    };
    if let Ok(path) = codes.extract::<std::path::PathBuf>() {
        let files = AcquisitionFiles::describe(
            &path,
            pulse.len(),
            depth_bins,
            None,
            tiles,
            streaming,
            InputNames::PYTHON,
        )
        .map_err(value_error)?;
        let files = match rows {
            Some((start, stop)) => files.with_rows(start..stop).map_err(value_error)?,
            None => files,
        };
        files
            .check_memory::<T>("RdOperator", 2, Use::Operator)
            .map_err(value_error)?;
        return files.load(pulse).map_err(value_error);
    }
    if stream_codes {
        return Err(PyValueError::new_err(
            "stream_codes: streaming regenerates codes described by a seed: pass the path of \
             the meta.json of `simulate --codes-format seed` as codes",
        ));
    }
    let (geom, sets, axis) = read_code_arrays::<T>(codes, pulse.len(), depth_bins, tiles)?;
    if let (true, 1, Some(t)) = (axis, sets.len(), tiles) {
        return Err(PyValueError::new_err(format!(
            "codes: codes with a code-set axis (G, M, N, K); tiles=({}, {}) needs one code set \
             (M, N, K)",
            t.m, t.n
        )));
    }
    let acq = Acquisition::new(geom, pulse, CodeStore::Held(sets), tiles, Streaming::Never)
        .map_err(value_error)?;
    // One code set with a code-set axis reads as the command line reads such a file.
    Ok(if axis { acq.with_code_set_axis() } else { acq })
}

/// The operator of `acq` in `T`, with the zero-mean pulse if `debiased`.
fn operator_of<T: Real>(acq: &Acquisition, debiased: bool) -> PyResult<BoxedOperator<T>> {
    let p = pulse_in::<T>(acq.pulse()).map_err(value_error)?;
    let p = if debiased { zero_mean(&p) } else { p };
    acq.operator_with_pulse(p).map_err(value_error)
}

/// Applies `op` (or its adjoint) to a copy of `x` with the GIL released; refuses non-finite
/// inputs and results that overflow.
fn apply<'py, T: Real + numpy::Element>(
    py: Python<'py>,
    op: &dyn LinearOperator<T>,
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
    check_finite(&v, if adjoint { "y" } else { "x" }).map_err(value_error)?;
    let out = py.detach(|| {
        let mut o = vec![T::zero(); n_out];
        if adjoint {
            op.apply_adjoint(&v, &mut o);
        } else {
            op.apply(&v, &mut o);
        }
        o
    });
    check_finite_result(
        &out,
        if adjoint { "adjoint" } else { "forward" },
        if adjoint { "y" } else { "x" },
    )
    .map_err(value_error)?;
    Ok(out.into_pyarray(py))
}

#[pymethods]
impl PyOperator {
    #[new]
    #[pyo3(signature = (pulse, codes, depth_bins, double, debiased, tiles=None, stream_codes=false, rows=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        pulse: PyReadonlyArray1<'_, f64>,
        codes: &Bound<'_, PyAny>,
        depth_bins: usize,
        double: bool,
        debiased: bool,
        tiles: Option<(usize, usize)>,
        stream_codes: bool,
        rows: Option<(usize, usize)>,
    ) -> PyResult<Self> {
        let p: Vec<f64> = pulse.as_array().iter().copied().collect();
        if depth_bins == 0 {
            return Err(PyValueError::new_err("depth_bins: must be at least 1"));
        }
        let tiles = match tiles {
            None => None,
            Some((m, n)) if m > 0 && n > 0 => Some(TileSize { m, n }),
            Some((m, n)) => {
                return Err(PyValueError::new_err(format!(
                    "tiles: tile rows and columns must be at least 1, got ({m}, {n})"
                )))
            }
        };
        let (acq, op) = if double {
            let acq = acquisition::<f64>(p, codes, (depth_bins, rows), tiles, stream_codes)?;
            let op = Op::F64(operator_of::<f64>(&acq, debiased)?);
            (acq, op)
        } else {
            let acq = acquisition::<f32>(p, codes, (depth_bins, rows), tiles, stream_codes)?;
            let op = Op::F32(operator_of::<f32>(&acq, debiased)?);
            (acq, op)
        };
        Ok(PyOperator { op, acq, debiased })
    }

    /// y = A x for a 1-D array of M·N·K_s values of the operator's dtype.
    fn forward<'py>(&self, py: Python<'py>, x: &Bound<'py, PyAny>) -> PyResult<Py<PyAny>> {
        Ok(match &self.op {
            Op::F32(op) => apply(py, op, x, false)?.into_any().unbind(),
            Op::F64(op) => apply(py, op, x, false)?.into_any().unbind(),
        })
    }

    /// x = Aᵀ y for a 1-D array of the measurements (every ADC's rows, one after the other).
    fn adjoint<'py>(&self, py: Python<'py>, y: &Bound<'py, PyAny>) -> PyResult<Py<PyAny>> {
        Ok(match &self.op {
            Op::F32(op) => apply(py, op, y, true)?.into_any().unbind(),
            Op::F64(op) => apply(py, op, y, true)?.into_any().unbind(),
        })
    }

    /// The operator restricted to the columns `voxels` (flat scene indices, int64, repeats
    /// allowed), A·Rᵀ, applied to `v`: forward from one amplitude per listed voxel to the
    /// measurements, or (`adjoint`) from the measurements to the listed voxels' correlations.
    /// One ADC costs O(|voxels|·K_p) in both directions, G ADCs G times that; tiles apply the
    /// whole operator. The restriction is built and applied with the GIL released.
    fn restricted<'py>(
        &self,
        py: Python<'py>,
        voxels: PyReadonlyArray1<'py, i64>,
        v: &Bound<'py, PyAny>,
        adjoint: bool,
    ) -> PyResult<Py<PyAny>> {
        let g = self.acq.geometry();
        let n = g.m * g.n * g.ks;
        let mut list = Vec::with_capacity(voxels.len());
        for (i, &c) in voxels.as_array().iter().enumerate() {
            match usize::try_from(c) {
                Ok(c) if c < n => list.push(c),
                _ => {
                    return Err(PyValueError::new_err(format!(
                        "voxels: entry {i} is {c}, outside the scene's {n} voxels"
                    )))
                }
            }
        }
        drop(voxels);
        Ok(match &self.op {
            Op::F32(op) => {
                let r = py
                    .detach(|| op.restrict_columns(list))
                    .map_err(value_error)?;
                apply(py, &*r, v, adjoint)?.into_any().unbind()
            }
            Op::F64(op) => {
                let r = py
                    .detach(|| op.restrict_columns(list))
                    .map_err(value_error)?;
                apply(py, &*r, v, adjoint)?.into_any().unbind()
            }
        })
    }

    /// (M, N, K_s).
    #[getter]
    fn geometry(&self) -> (usize, usize, usize) {
        let g = self.acq.geometry();
        (g.m, g.n, g.ks)
    }

    /// K = K_p + K_s − 1, the samples of one ADC.
    #[getter]
    fn samples(&self) -> usize {
        self.acq.samples()
    }

    /// Rows of the measurements: None for (K,), R for (R, K).
    #[getter]
    fn rows(&self) -> Option<usize> {
        self.acq.rows()
    }

    /// "single", "multi_adc" or "tiles".
    #[getter]
    fn architecture(&self) -> &'static str {
        self.acq.architecture().kind()
    }

    /// The tile size (A, B) of a tiled acquisition, None otherwise.
    #[getter]
    fn tiles(&self) -> Option<(usize, usize)> {
        match self.acq.architecture() {
            Architecture::Tiles(t) => Some((t.m, t.n)),
            _ => None,
        }
    }

    /// "compressive", "critical" or "redundant".
    #[getter]
    fn regime(&self) -> String {
        self.acq.regime().to_string()
    }

    /// Whether seeded codes are regenerated block by block on every application.
    #[getter]
    fn streamed(&self) -> bool {
        self.acq.is_streamed()
    }

    /// The instruction set of the kernels.
    #[getter]
    fn isa(&self) -> &'static str {
        rdlidar::lidar::kernel_isa()
    }

    /// The pulse the operator applies (zero-mean when built debiased), as float64.
    #[getter]
    fn pulse<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let p = self.acq.pulse().to_vec();
        let p = if self.debiased { zero_mean(&p) } else { p };
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
                    "tolerance: must be positive and finite, got {}",
                    rdlidar::units::number(t)
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
        let g = self.acq.geometry();
        let d = match &self.op {
            Op::F32(_) => "float32",
            Op::F64(_) => "float64",
        };
        let arch = match self.acq.architecture() {
            Architecture::MultiAdc(n) => format!(", {n} ADCs"),
            Architecture::Tiles(t) => format!(", tiles of {t} ({} ADCs)", t.count(g.m, g.n)),
            _ => String::new(),
        };
        format!(
            "rdlidar operator {}x{}x{}, K_p {}, K {}{arch}, {d}, {}",
            g.m,
            g.n,
            g.ks,
            self.acq.pulse_len(),
            self.acq.samples(),
            self.isa()
        )
    }
}

/// Simulates an acquisition of any architecture, as `rdlidar simulate` does; returns a dict of
/// arrays (codes as the format says: int8, packed uint8, or None for seeded codes) and the
/// meta.json text; with `out`, also writes the same files as the command line.
#[pyfunction]
#[pyo3(signature = (scene, size, pulse_len, seed, snr_db, ternary_zero_prob, lit_fraction, double, adcs=1, tiles=None, aperture=None, codes_format="int8", out=None, force=false, depth_png=None, reflectivity_png=None, photons=None, background=None, adc_bits=None, full_scale=None))]
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
    adcs: usize,
    tiles: Option<(usize, usize)>,
    aperture: Option<f64>,
    codes_format: &str,
    out: Option<std::path::PathBuf>,
    force: bool,
    depth_png: Option<std::path::PathBuf>,
    reflectivity_png: Option<std::path::PathBuf>,
    photons: Option<f64>,
    background: Option<f64>,
    adc_bits: Option<u32>,
    full_scale: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let geometry = Geometry::new(size.0, size.1, size.2).map_err(value_error)?;
    let tiles = match tiles {
        None => None,
        Some((m, n)) if m > 0 && n > 0 => Some(TileSize { m, n }),
        Some((m, n)) => {
            return Err(PyValueError::new_err(format!(
                "tiles: tile rows and columns must be at least 1, got ({m}, {n})"
            )))
        }
    };
    let request = SimulationRequest {
        scene: scene.to_string(),
        depth_png,
        reflectivity_png,
        photons,
        background,
        adc_bits,
        full_scale,
        lit_fraction,
        ternary_zero_prob,
        snr_db,
        adcs,
        tiles,
        aperture,
        codes_format: codes_format.parse().map_err(value_error)?,
        ..SimulationRequest::new(geometry, pulse_len, seed)
    };
    let spec = request.spec().map_err(value_error)?;
    let held = if double {
        spec.memory_plan::<f64>()
    } else {
        spec.memory_plan::<f32>()
    };
    held.and_then(|plan| plan.check("simulate", "use a smaller size or pulse"))
        .map_err(value_error)?;
    let d = PyDict::new(py);
    if double {
        fill_simulation::<f64>(py, &request, &spec, out.as_deref(), force, &d)?;
    } else {
        fill_simulation::<f32>(py, &request, &spec, out.as_deref(), force, &d)?;
    }
    Ok(d)
}

/// The codes of a simulation as `simulate` returns them, with their shape.
enum CodesArray {
    /// int8 samples −1, 0, +1.
    Int8(Vec<usize>, Vec<i8>),
    /// ±1 samples packed as `np.packbits(S > 0, axis=-1)` writes them.
    Packed(Vec<usize>, Vec<u8>),
}

/// The codes of `sim` as `format` gives them (none for seeded codes), pixel by pixel until
/// `cancel` is raised; a coded aperture's inactive pixels have zero codes.
fn codes_array<T>(
    sim: &Simulation<T>,
    format: CodesFormat,
    cancel: &AtomicBool,
) -> rdlidar::Result<Option<CodesArray>> {
    let g = sim.spec.geometry;
    let k = g.samples(sim.spec.pulse_len);
    let sets = sim.code_sets.len();
    let shape = |last: usize| match sim.spec.architecture {
        Architecture::MultiAdc(_) => vec![sets, g.m, g.n, last],
        _ => vec![g.m, g.n, last],
    };
    let go_on = || {
        if cancel.load(Ordering::Relaxed) {
            Err(rdlidar::Error::Cancelled {
                what: "simulate".into(),
            })
        } else {
            Ok(())
        }
    };
    match format {
        CodesFormat::Seed => Ok(None),
        CodesFormat::Packed => {
            let nb = k.div_ceil(8);
            let mut bytes = Vec::with_capacity(sets * g.pixels() * nb);
            for c in &sim.code_sets {
                go_on()?;
                bytes.extend(c.to_packbits()?);
            }
            Ok(Some(CodesArray::Packed(shape(nb), bytes)))
        }
        CodesFormat::Int8 => {
            let keep = sim.active.as_ref().map(|active| {
                let mut keep = vec![false; g.pixels()];
                for &p in active {
                    keep[p] = true;
                }
                keep
            });
            let mut dense = Vec::with_capacity(sets * g.pixels() * k);
            for c in &sim.code_sets {
                for p in 0..g.pixels() {
                    if p.is_multiple_of(256) {
                        go_on()?;
                    }
                    if keep.as_ref().is_some_and(|keep| !keep[p]) {
                        dense.resize(dense.len() + k, 0);
                    } else {
                        dense.extend((0..k).map(|t| c.get(p, t)));
                    }
                }
            }
            Ok(Some(CodesArray::Int8(shape(k), dense)))
        }
    }
}

fn fill_simulation<'py, T: Real + numpy::Element + ndarray_npy::WritableElement>(
    py: Python<'py>,
    request: &SimulationRequest,
    spec: &SimulationSpec,
    out: Option<&std::path::Path>,
    force: bool,
    d: &Bound<'py, PyDict>,
) -> PyResult<()> {
    let format = request.codes_format;
    // The work runs with the GIL released on a thread of its own while this one watches for
    // Ctrl-C, as the solvers do: a Ctrl-C cancels it at its next step and leaves nothing in
    // `out`.
    let observer = PyObserver::new(None);
    let cancel = &observer.cancel;
    let result = observer.watch(py, || {
        let supplied = request.supplied_scene::<T>()?;
        let mut sim = simulate_cancellable::<T>(spec, supplied, cancel)?;
        sim.scene_source = request.scene_source();
        let codes = codes_array(&sim, format, cancel)?;
        // The files last: once they are in place, there is nothing left to cancel.
        let meta = match out {
            Some(dir) => write_simulation_cancellable(dir, &sim, format, force, cancel)?,
            None => simulation_meta(&sim, format),
        };
        Ok::<_, rdlidar::Error>((sim, meta, codes))
    });
    if let Some(e) = observer.failure() {
        return Err(e);
    }
    let (sim, meta, codes) = result.map_err(value_error)?;
    let k = spec.geometry.samples(spec.pulse_len);
    let codes: Option<Py<PyAny>> = match codes {
        None => None,
        Some(CodesArray::Int8(shape, dense)) => {
            let a = numpy::ndarray::ArrayD::from_shape_vec(shape, dense)
                .map_err(|e| PyValueError::new_err(format!("codes: {e}")))?;
            Some(a.into_pyarray(py).into_any().unbind())
        }
        Some(CodesArray::Packed(shape, bytes)) => {
            let a = numpy::ndarray::ArrayD::from_shape_vec(shape, bytes)
                .map_err(|e| PyValueError::new_err(format!("codes: {e}")))?;
            Some(a.into_pyarray(py).into_any().unbind())
        }
    };
    let meas_shape: Vec<usize> = match sim.rows() {
        None => vec![k],
        Some(r) => vec![r, k],
    };
    let meas = numpy::ndarray::ArrayD::from_shape_vec(meas_shape, sim.meas)
        .map_err(|e| PyValueError::new_err(format!("meas: {e}")))?;
    let json = serde_json::to_string_pretty(&meta)
        .map_err(|e| PyValueError::new_err(format!("meta: {e}")))?;
    d.set_item("scene", sim.scene.into_inner().into_pyarray(py))?;
    d.set_item("pulse", sim.pulse.into_inner().into_pyarray(py))?;
    d.set_item("codes", codes)?;
    d.set_item("meas", meas.into_pyarray(py))?;
    d.set_item("meta", json)?;
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

/// What Python sees of the iterations of a solver: the callback, and the first exception
/// raised (in the callback, or Ctrl-C), after which `cancel` is raised: every solver then ends
/// within one operator application (see [`Cancellable`]).
struct PyObserver {
    callback: Option<Py<PyAny>>,
    failure: Mutex<Option<PyErr>>,
    cancel: AtomicBool,
}

impl PyObserver {
    fn new(callback: Option<Py<PyAny>>) -> Self {
        PyObserver {
            callback,
            failure: Mutex::new(None),
            cancel: AtomicBool::new(false),
        }
    }

    /// Keeps the first exception and cancels the work.
    fn fail(&self, e: PyErr) {
        if let Ok(mut f) = self.failure.lock() {
            f.get_or_insert(e);
        }
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// One iteration (of tile `tile` for a tiled acquisition): takes the GIL back and calls the
    /// callback with the iteration's numbers; a true return value stops the solver, an
    /// exception is kept and cancels every solver.
    fn observe<T>(&self, tile: Option<usize>, info: &IterationInfo<'_, T>) -> Control {
        if self.cancel.load(Ordering::Relaxed) {
            return Control::Stop;
        }
        let Some(cb) = &self.callback else {
            return Control::Continue;
        };
        Python::attach(|py| {
            let go_on = (|| -> PyResult<bool> {
                let d = PyDict::new(py);
                d.set_item("iteration", info.iteration)?;
                d.set_item("residual", info.residual)?;
                d.set_item("objective", info.objective)?;
                d.set_item("change", info.change)?;
                d.set_item("seconds", info.elapsed.as_secs_f64())?;
                if let Some(t) = tile {
                    d.set_item("tile", t)?;
                }
                let stop = cb.call1(py, (d,))?;
                Ok(!stop.bind(py).is_truthy()?)
            })();
            match go_on {
                Ok(true) => Control::Continue,
                Ok(false) => Control::Stop,
                Err(e) => {
                    self.fail(e);
                    Control::Stop
                }
            }
        })
    }

    /// Runs `work` on a worker thread, the GIL released, while this thread (the interpreter's
    /// main thread, where Python handles signals) looks for Ctrl-C every 50 ms and cancels the
    /// work when one comes.
    fn watch<R: Send>(&self, py: Python<'_>, work: impl FnOnce() -> R + Send) -> R {
        py.detach(|| {
            std::thread::scope(|s| {
                let me = std::thread::current();
                let worker = s.spawn(move || {
                    let r = work();
                    me.unpark();
                    r
                });
                while !worker.is_finished() {
                    std::thread::park_timeout(std::time::Duration::from_millis(50));
                    if !self.cancel.load(Ordering::Relaxed) {
                        if let Err(e) = Python::attach(|py| py.check_signals()) {
                            self.fail(e);
                        }
                    }
                }
                worker
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })
        })
    }

    /// The exception raised in the callback or by Ctrl-C, if any.
    fn failure(self) -> Option<PyErr> {
        self.failure.into_inner().ok().flatten()
    }
}

/// The measurements as a vector of the operator's dtype and length, finite.
fn measurements<T: Real + numpy::Element>(
    meas: &Bound<'_, PyAny>,
    count: usize,
) -> PyResult<Vec<T>> {
    let y = meas.extract::<PyReadonlyArray1<'_, T>>().map_err(|_| {
        PyTypeError::new_err(format!(
            "meas: expected a 1-D {} array",
            std::any::type_name::<T>()
        ))
    })?;
    if y.len() != count {
        return Err(PyValueError::new_err(format!(
            "meas: expected {count} values, got {}",
            y.len()
        )));
    }
    let y: Vec<T> = y.as_array().iter().copied().collect();
    check_finite(&y, "meas").map_err(value_error)?;
    Ok(y)
}

/// FISTA on ½‖Ax − y‖² + λ‖x‖₁ from x = 0 with the step 1/L (L = 1/`step`, or a Lanczos
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
    match &operator.op {
        Op::F32(op) => run_fista(py, acq, op, meas, &params, callback),
        Op::F64(op) => run_fista(py, acq, op, meas, &params, callback),
    }
}

fn run_fista<'py, T: Real + numpy::Element>(
    py: Python<'py>,
    acq: &Acquisition,
    op: &BoxedOperator<T>,
    meas: &Bound<'py, PyAny>,
    params: &FistaParams,
    callback: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let y = measurements::<T>(meas, op.nrows())?;
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
    let r = result.map_err(value_error)?;
    let report = PyDict::new(py);
    report_dict(py, &r, &report)?;
    pyo3::types::PyTuple::new(py, [x.into_pyarray(py).into_any(), report.into_any()])
}

/// Runs a reconstruction method on any architecture; returns (depth, scene, report).
#[pyfunction]
#[pyo3(signature = (operator, meas, solver, max_iter, callback, seed, fill_unobserved=false, clipped=None, false_rate=None, noise="gaussian", background=None))]
#[allow(clippy::too_many_arguments)]
fn reconstruct<'py>(
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
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
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
) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let y = measurements::<T>(meas, acq.measurements())?;
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
    let mut r = result.map_err(value_error)?;
    let filled = job.finish(&mut r).unwrap_or(0);
    let report = PyDict::new(py);
    report.set_item("method", job.method.name())?;
    report.set_item("architecture", acq.architecture().kind())?;
    report.set_item("seconds", r.elapsed().as_secs_f64())?;
    report.set_item("filled", filled)?;
    report.set_item("request", FrontEnd::Python.words(&job.summary()))?;
    if let Some(c) = &censoring {
        report.set_item("censored", c.total())?;
        report.set_item("censored_levels", c.levels.clone())?;
    }
    let rdlidar::operator::Applies {
        forward: f,
        adjoint: a,
        support: s,
    } = r.applies();
    match &r {
        Reconstructed::Single(r) => {
            single_report(py, r, &report)?;
        }
        Reconstructed::Tiled(t) => {
            report.set_item("regime", t.regime().to_string())?;
            let used: Vec<String> = t
                .methods_used()
                .iter()
                .map(|(m, n)| format!("{} on {n}", m.name()))
                .collect();
            report.set_item("method_used", used.join(", "))?;
            let tiles = PyList::empty(py);
            for tile in &t.tiles {
                let d = PyDict::new(py);
                let p = &tile.place;
                d.set_item("index", p.index)?;
                d.set_item("row", p.row)?;
                d.set_item("col", p.col)?;
                d.set_item("shape", (p.geometry.m, p.geometry.n))?;
                single_report(py, &tile.reconstruction, &d)?;
                tiles.append(d)?;
            }
            report.set_item("tiles", tiles)?;
        }
    }
    report.set_item("forward_applies", f)?;
    report.set_item("adjoint_applies", a)?;
    report.set_item("support_applies", s)?;
    let depth = r.depth().depth.clone().into_pyarray(py);
    let scene = match r {
        Reconstructed::Single(r) => r.scene,
        Reconstructed::Tiled(r) => r.scene,
    };
    let scene = scene.into_inner().into_pyarray(py);
    pyo3::types::PyTuple::new(py, [depth.into_any(), scene.into_any(), report.into_any()])
}

/// The report of one reconstruction (of the whole array, or of a tile) into `report`.
fn single_report<'py, T>(
    py: Python<'py>,
    r: &rdlidar::recon::Reconstruction<T>,
    report: &Bound<'py, PyDict>,
) -> PyResult<()> {
    report.set_item("method_used", r.method_used.name())?;
    report.set_item("regime", format!("{}", r.regime))?;
    report.set_item("seconds", r.elapsed.as_secs_f64())?;
    match &r.report {
        Some(rep) => report_dict(py, rep, report)?,
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
    if let Some(t) = &r.detection {
        let d = PyDict::new(py);
        d.set_item("false_rate", t.false_rate)?;
        d.set_item("bar", t.bar)?;
        d.set_item("sigma", t.sigma)?;
        d.set_item("tested", t.tested)?;
        d.set_item("dropped", t.dropped)?;
        d.set_item("skipped", t.skipped)?;
        report.set_item("detection", d)?;
    }
    if let Some(p) = &r.photon {
        let d = PyDict::new(py);
        d.set_item("background", p.background)?;
        d.set_item("offset", p.offset)?;
        d.set_item("scale", p.scale)?;
        d.set_item("slope_z", p.slope_z)?;
        d.set_item("light_share", p.light_share)?;
        d.set_item("gain", p.gain)?;
        d.set_item("skipped", p.skipped)?;
        report.set_item("photon", d)?;
    }
    Ok(())
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
    d.set_item("within_one", m.within_one)?;
    d.set_item("within_one_fraction", m.within_one_fraction)?;
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
    m.add_class::<PyOperator>()?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(fista, m)?)?;
    m.add_function(wrap_pyfunction!(metrics, m)?)?;
    m.add_function(wrap_pyfunction!(solvers, m)?)?;
    m.add_function(wrap_pyfunction!(check_simulation_dir, m)?)?;
    Ok(())
}
