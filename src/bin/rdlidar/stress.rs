//! `rdlidar stress`: the numerical stress suite.

use std::ops::ControlFlow;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use rdlidar::lidar::{Codes, Geometry, RdOperator};
use rdlidar::report::stress::{
    failures, run_stress, table_header, table_line, Preset, StressConfig, StressRow,
};
use serde::Serialize;

use crate::common::{errln, outln, write_stdout, CliResult, Failure, Globals};

/// Run the numerical stress suite: precision, dot tests, conditioning and solvers, in f32 and f64.
///
/// Four groups of rows, every draw seeded from --seed (same seed, same table apart from the
/// times, on one machine and thread count):
///
/// precision: the f32 operator against the f64 one on the same pulse, codes and inputs, K from
/// 10^4 to 10^7 samples on a 4x4x8 grid: ‖A32 x − A64 x‖/‖A64 x‖ for the dense and sparse
/// forward paths and the same for the adjoint (beside the gap of a naive f32 sum). dot-test:
/// |<Ax,y> − <x,A*y>| / max(‖Ax‖‖y‖, ‖x‖‖A*y‖) of the same operators. conditioning: σ_max
/// (Lanczos iteration), σ_min (inverse iteration with conjugate gradients) and κ of A restricted
/// to the support of the 8x8x8 paper scene, K_p from below the support size to redundant,
/// checked against a dense eigendecomposition. solvers: every method on the 8x8x8 paper scene
/// (K_p 300) with amplitudes spanning 1e-6..1, a pulse of duty 0.05, ternary codes with
/// P(0) 0.9, and Gaussian noise at 40, 20, 10 and 0 dB SNR: relative error ‖X − X̂‖/‖X‖ and
/// exact-depth fraction.
///
/// The default (full) suite takes about 12 s on two cores and 1.6 GB of memory (at K = 10^7);
/// --quick stops at K = 10^6 and takes four pulse lengths for the conditioning (about 3 s).
/// Every check runs in both precisions, so --precision is refused. Prints a Markdown table row by row (--json: one JSON document at
/// the end); exit status 0 when every row passes, 1 otherwise with
/// `error: N of M stress rows failed`. docs/stress.md explains each tolerance.
///
/// Example: `rdlidar stress --quick --seed 3`
#[derive(clap::Args, Debug)]
pub struct StressArgs {
    /// The small suite (seconds; the one the tests run).
    #[arg(long)]
    pub quick: bool,
    /// Print one JSON document {"preset", "seed", "threads", "kernels", "rows": [...], "passed",
    /// "failed", "seconds"} instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// The JSON form of `stress`.
/// The memory of the largest precision check: both operators at the longest K, in f32 and f64,
/// with their inputs, outputs and the forward's per-thread buffers.
fn check_memory(config: &StressConfig) -> CliResult {
    let g = config.precision_geometry;
    let k = config.samples.iter().copied().max().unwrap_or(1);
    let pulse_len = k.saturating_sub(g.ks - 1).max(1);
    let threads = rayon::current_num_threads();
    let bytes = |b: rdlidar::Result<usize>| b.map_or(u128::MAX, |b| b as u128);
    let f32_op = bytes(RdOperator::<f32>::estimated_memory_bytes(
        g,
        pulse_len,
        rdlidar::lidar::CodeAlphabet::Binary,
        threads,
    ));
    let f64_op = bytes(RdOperator::<f64>::estimated_memory_bytes(
        g,
        pulse_len,
        rdlidar::lidar::CodeAlphabet::Binary,
        threads,
    ));
    rdlidar::limits::MemoryPlan::new()
        .add("operators", f32_op.saturating_add(f64_op), 1)
        .add("measurements and references", k as u128, 4 * 8)
        .check(
            &format!("stress at K up to {k}"),
            "use --quick, or free memory",
        )?;
    Ok(())
}

#[derive(Serialize)]
struct StressReport<'a> {
    preset: Preset,
    seed: u64,
    threads: usize,
    kernels: &'static str,
    rows: &'a [StressRow],
    passed: usize,
    failed: usize,
    seconds: f64,
}

/// Runs `stress`: exit status 1 when a row fails.
pub fn run(a: &StressArgs, globals: &Globals) -> CliResult<ExitCode> {
    if globals.precision.is_some() {
        return Err("--precision: stress runs every check in both f32 and f64"
            .to_string()
            .into());
    }
    let preset = if a.quick { Preset::Quick } else { Preset::Full };
    let config = StressConfig::preset(preset, globals.seed());
    check_memory(&config)?;
    let threads = rayon::current_num_threads();
    let kernels = kernels()?;
    let start = Instant::now();
    let rows = if a.json {
        run_stress(&config, |_| ControlFlow::Continue(()))?
    } else {
        outln!(
            "rdlidar stress: {} preset, seed {}, {threads} threads, kernels {kernels}",
            preset.name(),
            config.seed
        );
        for line in table_header() {
            outln!("{line}");
        }
        // A failed write (a closed pipe) stops the suite; the failure is reported after it.
        let mut written: CliResult = Ok(());
        let rows = run_stress(&config, |row| {
            written = write_stdout(format_args!("{}", table_line(row)));
            if written.is_ok() {
                ControlFlow::Continue(())
            } else {
                ControlFlow::Break(())
            }
        })?;
        written?;
        rows
    };
    let seconds = start.elapsed().as_secs_f64();
    let failed = failures(&rows);
    if a.json {
        let report = StressReport {
            preset,
            seed: config.seed,
            threads,
            kernels,
            rows: &rows,
            passed: rows.len() - failed,
            failed,
            seconds,
        };
        let text = serde_json::to_string(&report)
            .map_err(|e| Failure::Message(format!("cannot format the rows as JSON: {e}")))?;
        outln!("{text}");
    } else {
        outln!(
            "{} of {} rows passed in {seconds:.1} s",
            rows.len() - failed,
            rows.len()
        );
    }
    if failed == 0 {
        Ok(ExitCode::SUCCESS)
    } else {
        errln!("error: {failed} of {} stress rows failed", rows.len());
        Ok(ExitCode::FAILURE)
    }
}

/// The instruction set the operator's kernels run with on this machine.
fn kernels() -> CliResult<&'static str> {
    let g = Geometry::new(1, 1, 1)?;
    let codes = Arc::new(Codes::random_binary(1, 1, 0)?);
    Ok(RdOperator::<f32>::new(g, vec![1.0], codes)?.isa())
}
