//! `rdlidar info`: what a configuration costs, from `rdlidar::report::cost::Cost`.

use crate::common::outln;
use rdlidar::lidar::{parse_tau, Geometry, DEFAULT_TAU_S};
use rdlidar::report::cost::{Cost, Throughput};

/// Timed runs of each operation of `info --calibrate`, after one warm-up run.
const CALIBRATION_REPEATS: usize = 5;

/// What a configuration costs: regime, physical scales, memory and time per apply.
///
/// For a grid MxNxKS and a pulse of K_p samples: the regime (compressive, critical or
/// redundant) and the critical K_p = (M·N − 1)·K_s + 1; at the sampling period τ (default
/// 200 ps) the depth resolution τc/2, the range K_s·τc/2, the pulse duration K_p·τ, the frame
/// time K·τ with K = K_p + K_s − 1 and the maximum frame rate 1/(K·τ); the memory of the
/// codes (packed bits, int8, dense float), pulse, measurements, a dense scene and the fused
/// operator; and the estimated time of one forward, adjoint and sparse forward application
/// in f32 and f64.
///
/// Times are the work (2·M·N·K·K_s GEMM-equivalent flops for the forward and the adjoint,
/// M·N·K_p voxel-samples for the sparse forward over one return per pixel) divided by a
/// rate: by default the documented rates of the 2-core reference machine (docs/lidar.md);
/// with --calibrate rates measured on this machine by timing the operator on the
/// configuration capped at 64x64x64 and K_p 16384. The output says which.
///
/// Nothing is read or written. --json prints the same numbers as one line of JSON.
///
/// Example: `rdlidar info --size 100x100x40 --pulse-len 30000 --tau 200ps`
#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    /// Scene grid MxNxKS: M×N pixels, K_s depth bins.
    #[arg(long, value_parser = crate::common::parse_size)]
    size: Geometry,
    /// Pulse length K_p.
    #[arg(long, value_name = "KP", value_parser = crate::common::parse_pulse_len)]
    pulse_len: usize,
    /// Sampling period τ with its unit: fs, ps, ns, us, ms or s (default 200ps).
    #[arg(
        long,
        value_name = "T",
        conflicts_with = "tau_ps",
        allow_hyphen_values = true
    )]
    tau: Option<String>,
    /// Sampling period τ in picoseconds (the same as --tau PSps).
    #[arg(long, value_name = "PS", allow_negative_numbers = true)]
    tau_ps: Option<f64>,
    /// Estimate the times from a calibration on this machine (a second or two of timed
    /// applications of the operator on the configuration capped at 64x64x64, K_p 16384) instead
    /// of the documented rates of the reference machine.
    #[arg(long)]
    calibrate: bool,
    /// Print the numbers as one line of JSON instead of the table.
    #[arg(long)]
    json: bool,
}

/// Runs `info`: validates τ, computes the budget and prints it.
pub fn run(a: &InfoArgs) -> crate::common::CliResult {
    let tau_s = match (&a.tau, a.tau_ps) {
        (Some(text), _) => parse_tau(text).map_err(|e| format!("--tau: {e}"))?,
        (None, Some(ps)) => {
            let s = ps * 1e-12;
            if !(s.is_finite() && s > 0.0) {
                return Err(format!(
                    "--tau-ps: the sampling period must be finite and > 0, got {}",
                    rdlidar::units::number(ps)
                )
                .into());
            }
            s
        }
        (None, None) => DEFAULT_TAU_S,
    };
    let throughput = if a.calibrate {
        Throughput::calibrate(a.size, a.pulse_len, CALIBRATION_REPEATS)
            .map_err(|e| format!("--calibrate: {e}"))?
    } else {
        Throughput::documented()
    };
    let threads = rayon::current_num_threads();
    let budget = Cost::new(a.size, a.pulse_len, tau_s, threads, throughput).map_err(|e| {
        let flag = match &e {
            rdlidar::Error::InvalidParameter { name: "tau", .. } if a.tau.is_some() => "--tau",
            rdlidar::Error::InvalidParameter { name: "tau", .. } => "--tau-ps",
            _ => "--pulse-len",
        };
        format!("{flag}: {e}")
    })?;
    if a.json {
        let text = serde_json::to_string(&budget)
            .map_err(|e| format!("cannot format the budget as JSON: {e}"))?;
        outln!("{text}");
    } else {
        outln!("{budget}");
    }
    Ok(())
}
