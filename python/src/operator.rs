//! The measurement operator as Python holds it: built from arrays or files, applied with the
//! GIL released.

use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use rdlidar::acquisition::{
    check_finite_result, check_pulse, pulse_in, Acquisition, AcquisitionFiles, CodeArrayView,
    InputNames, Streaming, Use,
};
use rdlidar::lidar::{zero_mean, Architecture, TileSize};
use rdlidar::operator::{BoxedOperator, DotTest, LinearOperator};
use rdlidar::Real;

use crate::{each_precision, tile_size, value_error, vector};

/// The operator in the precision it was built for.
pub(crate) enum Op {
    F32(BoxedOperator<f32>),
    F64(BoxedOperator<f64>),
}

/// The measurement operator of an acquisition (one ADC, G ADCs, tiles, a coded aperture;
/// codes held or described by a seed), in float32 or float64.
#[pyclass(name = "_Operator", module = "rdlidar._rdlidar", frozen)]
pub(crate) struct PyOperator {
    pub(crate) op: Op,
    pub(crate) acq: Acquisition,
    pub(crate) debiased: bool,
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
    let acq = if let Ok(a) = codes.extract::<PyReadonlyArrayDyn<'_, i8>>() {
        let view = CodeArrayView::Int8(a.as_array());
        Acquisition::from_code_arrays::<T>(pulse, view, depth_bins, tiles)
    } else if let Ok(a) = codes.extract::<PyReadonlyArrayDyn<'_, u8>>() {
        let view = CodeArrayView::Packed(a.as_array());
        Acquisition::from_code_arrays::<T>(pulse, view, depth_bins, tiles)
    } else {
        return Err(PyTypeError::new_err(
            "codes must be an int8 array (M, N, K) or (G, M, N, K) of -1, 0, 1, a uint8 array \
             (M, N, ceil(K/8)) or (G, M, N, ceil(K/8)) as np.packbits(S > 0, axis=-1) writes \
             it, or the path of a meta.json of seeded codes",
        ));
    };
    acq.map_err(value_error)
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
    let v = vector::<T>(x, n_in, what)?;
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
        let tiles = tile_size(tiles)?;
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
        Ok(each_precision!(&self.op, op => apply(py, op, x, false)?.into_any().unbind()))
    }

    /// x = Aᵀ y for a 1-D array of the measurements (every ADC's rows, one after the other).
    fn adjoint<'py>(&self, py: Python<'py>, y: &Bound<'py, PyAny>) -> PyResult<Py<PyAny>> {
        Ok(each_precision!(&self.op, op => apply(py, op, y, true)?.into_any().unbind()))
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
        Ok(each_precision!(&self.op, op => {
            let r = py
                .detach(|| op.restrict_columns(list))
                .map_err(value_error)?;
            apply(py, &*r, v, adjoint)?.into_any().unbind()
        }))
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
        let r = py.detach(|| each_precision!(&self.op, op => test.measure(op)));
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
