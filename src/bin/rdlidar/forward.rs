//! `rdlidar forward`: y = A x from files.

use std::path::PathBuf;

use ndarray_npy::WritableElement;
use rdlidar::io;
use rdlidar::lidar::{Scene, TileSize};
use rdlidar::Real;

use rdlidar::acquisition::{pulse_in, Use};

use crate::common::{
    architecture_note, at_pulse, check_finite_result, check_out_file, npy_dtype, outln, parse_tile,
    with_precision, CliResult, Globals,
};
use crate::ranks::Ranks;

/// Apply the measurement operator: y = A x.
///
/// Reads the pulse (K_p,), the codes (M, N, K_p + K_s − 1) and the scene (M, N, K_s), and
/// writes the measurements (K,) to OUT.
///
/// Codes of shape (G, M, N, K), as `simulate --adcs G` writes them, are G code sets with one
/// ADC each, and OUT is (G, K). With --tiles AxB the array is split into T tiles with one
/// ADC each, and OUT is (T, K).
///
/// Example: `rdlidar forward --pulse run0/pulse.npy --codes run0/codes.npy --scene run0/scene.npy --out y.npy`
#[derive(clap::Args, Debug)]
pub struct ForwardArgs {
    /// Pulse file (K_p,), float32 or float64, ≥ 0.
    #[arg(long, value_name = "P")]
    pub pulse: PathBuf,
    /// Codes file (M, N, K), or (G, M, N, K) for G code sets; int8 (or float) in {-1, 0, 1}, or
    /// uint8 ±1 codes packed as `np.packbits(S > 0, axis=-1)` writes them (last axis ⌈K/8⌉).
    #[arg(long, value_name = "S")]
    pub codes: PathBuf,
    /// Scene file (M, N, K_s), float32 or float64.
    #[arg(long, value_name = "X")]
    pub scene: PathBuf,
    /// Output measurements file (K,), or (ADCs, K) for several ADCs.
    #[arg(long, value_name = "Y")]
    pub out: PathBuf,
    /// One ADC per tile of AxB pixels (as written by `simulate --tiles AxB`).
    #[arg(long, value_name = "AxB", value_parser = parse_tile)]
    pub tiles: Option<TileSize>,
    /// Codes described by a seed (meta.json) of one ADC: regenerate them block by block on every
    /// application instead of holding them (automatic when holding them would take over 1 GiB).
    #[arg(long)]
    pub stream_codes: bool,
}

/// Runs `forward`.
pub fn run(a: &ForwardArgs, globals: &Globals, ranks: &Ranks) -> CliResult {
    check_out_file(
        &a.out,
        "--out",
        &[
            (&a.pulse, "--pulse"),
            (&a.codes, "--codes"),
            (&a.scene, "--scene"),
        ],
    )?;
    with_precision!(
        globals.precision_of(&[&a.scene, &a.pulse])?,
        forward(a, ranks)
    )
}

fn forward<T: Real + WritableElement>(a: &ForwardArgs, ranks: &Ranks) -> CliResult {
    let out = &a.out;
    // Every process reads its inputs; they agree on any failure before computing together.
    let prepared = (|| -> CliResult<_> {
        let p = io::read_pulse::<f64>(&a.pulse)?;
        let ((m, n, ks), x) = read_my_scene::<T>(&a.scene, ranks)?;
        let files = ranks.describe(
            &a.codes,
            (p.len(), ks),
            Some((m, n)),
            a.tiles,
            a.stream_codes,
        )?;
        files.check_memory::<T>("forward", 2, Use::Operator)?;
        let acq = files.load(p.into_inner())?;
        let pulse = pulse_in::<T>(acq.pulse()).map_err(at_pulse(&a.pulse))?;
        let op = acq.operator_with_pulse(pulse)?;
        Ok((x, acq, op))
    })();
    let (x, acq, op) = ranks.agree(prepared)?;
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(x.as_slice(), &mut y);
    // The measurements are the same in every process.
    check_finite_result(&y, "measurements", &a.scene, "--scene")?;
    if !ranks.is_first() {
        return Ok(());
    }
    let k = acq.samples();
    match acq.rows() {
        None => {
            io::write_measurements(out, &y)?;
            outln!(
                "wrote {}: measurements ({},) {}{}",
                out.display(),
                y.len(),
                npy_dtype::<T>(),
                architecture_note(&acq)
            );
        }
        Some(rows) => {
            let y2 = ndarray::ArrayView2::from_shape((rows, k), &y[..])
                .map_err(|e| format!("cannot shape the measurements: {e}"))?;
            io::write_array(out, &y2)?;
            outln!(
                "wrote {}: measurements ({rows}, {k}) {}, one row per ADC{}",
                out.display(),
                npy_dtype::<T>(),
                architecture_note(&acq)
            );
        }
    }
    Ok(())
}

/// The scene file's grid (M, N, K_s) and this process's rows of the scene: all of them alone,
/// its band of rows when the rows are split over processes (only those bytes are read).
fn read_my_scene<T: Real>(
    path: &std::path::Path,
    ranks: &Ranks,
) -> CliResult<((usize, usize, usize), Scene<T>)> {
    let whole = |x: Scene<T>| {
        let g = x.geometry();
        ((g.m, g.n, g.ks), x)
    };
    let Some(space) = ranks.space() else {
        return Ok(whole(io::read_scene(path)?));
    };
    let shape = io::read_header(path)?.shape;
    let m = shape.first().copied().unwrap_or(0);
    if shape.len() != 3 || m < space.parts() {
        // The scene's own error, or the split's (more processes than rows), as one process.
        return Ok(whole(io::read_scene(path)?));
    }
    let rows = rdlidar::space::my_band(&**space, m);
    Ok(io::read_scene_rows(path, rows)?)
}
