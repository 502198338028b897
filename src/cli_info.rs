//! `rdlidar info`: what a configuration costs, from `rdlidar::lidar::Budget`.

use rdlidar::lidar::{parse_tau, Budget, Geometry, Throughput, DEFAULT_TAU_S};

/// Timed runs of each operation of `info --calibrate`, after one warm-up run.
const CALIBRATION_REPEATS: usize = 5;

/// The options of `info`.
#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    /// Scene grid MxNxKS: M×N pixels, K_s depth bins.
    #[arg(long, value_parser = crate::parse_size)]
    size: Geometry,
    /// Pulse length K_p.
    #[arg(long, value_name = "KP", value_parser = crate::parse_positive)]
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
pub fn run(a: &InfoArgs) -> Result<(), String> {
    let tau_s = match (&a.tau, a.tau_ps) {
        (Some(text), _) => parse_tau(text).map_err(|e| format!("--tau: {e}"))?,
        (None, Some(ps)) => {
            let s = ps * 1e-12;
            if !(s.is_finite() && s > 0.0) {
                return Err(format!(
                    "--tau-ps: the sampling period must be finite and > 0, got {ps}"
                ));
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
    let budget = Budget::new(a.size, a.pulse_len, tau_s, threads, throughput).map_err(|e| {
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
        println!("{text}");
    } else {
        println!("{budget}");
    }
    Ok(())
}
