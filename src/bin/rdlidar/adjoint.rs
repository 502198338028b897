//! `rdlidar adjoint`: x̃ = A* y from files, plain or debiased.

use std::path::PathBuf;

use ndarray_npy::WritableElement;
use rdlidar::io;
use rdlidar::lidar::{zero_mean, Scene, TileSize};
use rdlidar::Real;

use rdlidar::acquisition::{pulse_in, Use};

use crate::common::{
    architecture_note, at_pulse, check_finite_result, check_out_file, npy_dtype, outln, parse_tile,
    with_precision, CliResult, Globals, MeasurementFiles,
};
use crate::ranks::Ranks;

/// Apply the adjoint (backprojection): x̃ = A* y.
///
/// Reads the pulse (K_p,), the codes (M, N, K) and the measurements (K,), with
/// K = K_p + K_s − 1, and writes x̃ (M, N, K_s) to OUT. With --debiased the zero-mean pulse
/// p − mean(p) is used, which removes the constant floor plain backprojection adds to every
/// depth bin of a pixel with a 0/1 pulse.
///
/// Codes of shape (G, M, N, K) (`simulate --adcs G`) need measurements (G, K); with
/// --tiles AxB the measurements are (T, K), one row per tile.
///
/// Example: `rdlidar adjoint --pulse run0/pulse.npy --codes run0/codes.npy --meas run0/meas.npy --depth-bins 40 --out xt.npy --debiased`
#[derive(clap::Args, Debug)]
pub struct AdjointArgs {
    #[command(flatten)]
    pub files: MeasurementFiles,
    /// Output file (M, N, K_s).
    #[arg(long, value_name = "XT")]
    pub out: PathBuf,
    /// Correlate with the zero-mean pulse (debiased backprojection).
    #[arg(long)]
    pub debiased: bool,
    /// One ADC per tile of AxB pixels (as written by `simulate --tiles AxB`).
    #[arg(long, value_name = "AxB", value_parser = parse_tile)]
    pub tiles: Option<TileSize>,
    /// Codes described by a seed (meta.json) of one ADC: regenerate them block by block on every
    /// application instead of holding them (automatic when holding them would take over 1 GiB).
    #[arg(long)]
    pub stream_codes: bool,
}

/// Runs `adjoint`.
pub fn run(a: &AdjointArgs, globals: &Globals, ranks: &Ranks) -> CliResult {
    check_out_file(&a.out, "--out", &a.files.inputs())?;
    with_precision!(
        globals.precision_of(&[&a.files.meas, &a.files.pulse])?,
        adjoint(a, ranks)
    )
}

fn adjoint<T: Real + WritableElement>(a: &AdjointArgs, ranks: &Ranks) -> CliResult {
    let out = &a.out;
    // Every process backprojects onto its own rows, then they agree on any failure.
    let local = (|| -> CliResult<_> {
        let (acq, y) = ranks.load::<T>(
            &a.files,
            (a.tiles, a.stream_codes),
            ("adjoint", 2, Use::Operator),
        )?;
        let pulse = pulse_in::<T>(acq.pulse()).map_err(at_pulse(&a.files.pulse))?;
        let pulse = if a.debiased { zero_mean(&pulse) } else { pulse };
        let op = acq.operator_with_pulse(pulse)?;
        let mut x = vec![T::zero(); acq.geometry().voxels()];
        op.apply_adjoint(&y, &mut x);
        check_finite_result(&x, "backprojection", &a.files.meas, "--meas")?;
        Ok((acq, x))
    })();
    let (acq, x) = ranks.agree(local)?;
    let g = acq.whole_geometry();
    let x = match acq.share() {
        Some(share) => share.gather(&x),
        None => x,
    };
    if !ranks.is_first() {
        return Ok(());
    }
    let xt = Scene::from_vec(g, x).map_err(|e| {
        format!(
            "{}: the backprojection overflows {}: {e}",
            out.display(),
            T::NAME
        )
    })?;
    io::write_scene(out, &xt)?;
    outln!(
        "wrote {}: {}backprojection ({}, {}, {}) {}{}",
        out.display(),
        if a.debiased { "debiased " } else { "" },
        g.m,
        g.n,
        a.files.depth_bins,
        npy_dtype::<T>(),
        architecture_note(&acq)
    );
    Ok(())
}
