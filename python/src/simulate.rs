//! `simulate`: an acquisition of any architecture, as arrays and, on request, files.

use numpy::IntoPyArray;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use rdlidar::acquisition::{
    code_array, simulation_meta, write_simulation_cancellable, CodeArray, SimulationRequest,
};
use rdlidar::io::read_response;
use rdlidar::lidar::{simulate_cancellable, Geometry, SimulationSpec};
use rdlidar::Real;

use crate::observer::PyObserver;
use crate::{tile_size, value_error};

/// Simulates an acquisition of any architecture, as `rdlidar simulate` does; returns a dict of
/// arrays (codes as the format says: int8, packed uint8, or None for seeded codes) and the
/// meta.json text; with `out`, also writes the same files as the command line.
#[pyfunction]
#[pyo3(signature = (scene, size, pulse_len, seed, snr_db, ternary_zero_prob, lit_fraction, double, adcs=1, tiles=None, aperture=None, codes_format="int8", out=None, force=false, depth_png=None, reflectivity_png=None, photons=None, background=None, adc_bits=None, full_scale=None, depth="grid", kernel=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate<'py>(
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
    depth: &str,
    kernel: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let geometry = Geometry::new(size.0, size.1, size.2).map_err(value_error)?;
    let tiles = tile_size(tiles)?;
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
        continuous: depth == "continuous",
        kernel: kernel.map(read_response).transpose().map_err(value_error)?,
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

/// The simulation of `request` in `T` into `d` (and `out`), cancelled by Ctrl-C.
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
        request.describe(&mut sim)?;
        let codes = code_array(&sim, format, cancel)?;
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
    let codes: Option<Py<PyAny>> = codes.map(|c| match c {
        CodeArray::Int8(a) => a.into_pyarray(py).into_any().unbind(),
        CodeArray::Packed(a) => a.into_pyarray(py).into_any().unbind(),
    });
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
    d.set_item(
        "amplitude",
        sim.returns
            .as_ref()
            .map(|r| r.amplitude_map().into_pyarray(py)),
    )?;
    d.set_item("range", sim.returns.map(|r| r.range_map().into_pyarray(py)))?;
    Ok(())
}
