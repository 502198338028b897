//! `rdlidar bench`: times the fused operator on a generated problem.

use std::sync::Arc;

use rdlidar::lidar::{
    gather_limit, paper_scene, CodeAlphabet, Codes, GatherLimit, Geometry, OperatorWork, Pulse,
    RdOperator, Seeds,
};
use rdlidar::limits::MemoryPlan;
use rdlidar::report::timing::{time_operator, time_restricted_adjoint, Timing, WARM_UP_S};
use rdlidar::Real;
use serde::Serialize;

use crate::common::{
    outln, parse_pulse_len, parse_repeats, parse_size, with_precision, CliResult, Globals,
    Precision,
};

/// Time the forward, adjoint, sparse forward and restricted adjoint on a generated problem.
///
/// Generates the paper scene, a Bernoulli pulse (seed SEED) and binary codes (seed SEED+1)
/// before timing; no file is read or written. Each operation runs for at least 0.5 s (and at
/// least once) as a warm-up, then --repeats times; the median and the minimum wall time are
/// reported. "forward" is the dense table path over all pixels, "adjoint" the backprojection,
/// "sparse forward" the forward product over the nonzero voxels of the scene only,
/// "restricted adjoint" the adjoint for those voxels only (what least squares on a support
/// applies).
///
/// Each dense kernel's rate is also given as table additions and table bytes read per second,
/// beside what this machine delivers to the same access pattern: random rows of the kernels'
/// width summed from a table in L1 (about 32 kB) and in L2 (about 512 kB) per thread ("limits";
/// in vectors: 512-bit on AVX-512, rows padded to whole vectors, and 256-bit on AVX2).
///
/// --json prints {"forward": {"median_s": .., "min_s": ..}, "adjoint": {..},
/// "sparse_forward": {..}, "restricted_adjoint": {..}, "work": .., "rates": .., "limits": ..,
/// ...} on one line instead of the table.
///
/// Example: `rdlidar bench --size 100x100x40 --pulse-len 30000 --precision f32 --json`
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Scene grid MxNxKS.
    #[arg(long, value_parser = parse_size, default_value = "100x100x40")]
    pub size: Geometry,
    /// Pulse length K_p.
    #[arg(long, value_parser = parse_pulse_len, default_value_t = 30000)]
    pub pulse_len: usize,
    /// Print the timings as JSON.
    #[arg(long)]
    pub json: bool,
    /// Timed runs of each operation, after 0.5 s of warm-up runs (1 … 10000).
    #[arg(long, value_parser = parse_repeats, default_value_t = 7)]
    pub repeats: usize,
}

/// The JSON form of `bench`.
#[derive(Debug, Serialize)]
struct BenchReport {
    forward: Timing,
    adjoint: Timing,
    sparse_forward: Timing,
    restricted_adjoint: Timing,
    size: String,
    pulse_len: usize,
    samples: usize,
    precision: &'static str,
    scene: &'static str,
    nonzeros: usize,
    repeats: usize,
    threads: usize,
    isa: &'static str,
    memory_bytes: usize,
    /// Additions and table bytes of one application of each dense kernel.
    work: OperatorWork,
    /// Rates of each dense kernel at its median time.
    rates: Rates,
    /// What the caches deliver to the kernels' access pattern on this machine.
    limits: Limits,
}

/// Additions and table bytes per second of the dense kernels.
#[derive(Debug, Serialize)]
struct Rates {
    forward: Rate,
    adjoint: Rate,
}

#[derive(Debug, Serialize)]
struct Rate {
    additions_per_s: f64,
    table_bytes_per_s: f64,
}

/// Random rows of the kernels' width summed from a table in L1 (about 32 kB: the forward's block
/// of quad tables on AVX-512) and in L2 (about 512 kB: the forward's block of 256-row tables on
/// the other paths, and the size of the adjoint's chunk of tables) per thread.
#[derive(Debug, Serialize)]
struct Limits {
    l1: GatherLimit,
    l2: GatherLimit,
}

/// Runs `bench` (f32 unless --precision says otherwise).
pub fn run(a: &BenchArgs, globals: &Globals) -> CliResult {
    let precision = globals.precision.unwrap_or(Precision::F32);
    with_precision!(precision, bench(a, globals.seed()))
}

fn bench<T: Real>(a: &BenchArgs, seed: u64) -> CliResult {
    let (g, kp, repeats) = (a.size, a.pulse_len, a.repeats);
    let k = kp
        .checked_add(g.ks - 1)
        .ok_or_else(|| format!("--pulse-len {kp} is too large"))?;
    let operator = RdOperator::<T>::estimated_memory_bytes(
        g,
        kp,
        CodeAlphabet::Binary,
        rayon::current_num_threads(),
    )
    .map_or(u128::MAX, |b| b as u128);
    MemoryPlan::new()
        .add(
            "scene (dense and sparse)",
            g.voxels() as u128,
            3 * std::mem::size_of::<T>(),
        )
        .add("codes and operator", operator, 1)
        .add("measurements", k as u128, 2 * std::mem::size_of::<T>())
        .check(
            &format!("bench --size {g} --pulse-len {kp}"),
            "lower --size or --pulse-len",
        )?;
    let seeds = Seeds::new(seed);
    let scene = paper_scene::<T>(g).map_err(|e| format!("--size: {e}"))?;
    let pulse =
        Pulse::<T>::bernoulli(kp, seeds.pulse()).map_err(|e| format!("--pulse-len: {e}"))?;
    let codes = Codes::random_binary(g.pixels(), k, seeds.code_set(0))?;
    let op = RdOperator::new(g, pulse.into_inner(), Arc::new(codes))?;
    let t = time_operator(&op, scene.as_slice(), repeats);
    let work = op.work();
    let rate = |w: rdlidar::lidar::KernelWork, seconds: f64| Rate {
        additions_per_s: w.additions_per_s(seconds),
        table_bytes_per_s: w.table_bytes_per_s(seconds),
    };
    let nch = g.ks.min(64).div_ceil(8);
    let limits = Limits {
        l1: gather_limit::<T>(nch, 32 * 1024, repeats)?,
        l2: gather_limit::<T>(nch, 512 * 1024, repeats)?,
    };
    let report = BenchReport {
        forward: t.forward,
        adjoint: t.adjoint,
        sparse_forward: t.sparse_forward,
        restricted_adjoint: time_restricted_adjoint(&op, scene.as_slice(), repeats),
        size: g.to_string(),
        pulse_len: kp,
        samples: k,
        precision: T::NAME,
        scene: "paper",
        nonzeros: scene.nnz(),
        repeats,
        threads: rayon::current_num_threads(),
        isa: op.isa(),
        memory_bytes: op.memory_bytes(),
        rates: Rates {
            forward: rate(work.forward, t.forward.median_s),
            adjoint: rate(work.adjoint, t.adjoint.median_s),
        },
        work,
        limits,
    };
    if a.json {
        let text = serde_json::to_string(&report)
            .map_err(|e| format!("cannot format the report as JSON: {e}"))?;
        outln!("{text}");
        return Ok(());
    }
    print_table(&report, g)
}

fn print_table(report: &BenchReport, g: Geometry) -> CliResult {
    // The equivalent dense matrix product costs 2·M·N·K·K_s flops (docs/math.md §5).
    let flops = 2.0 * g.pixels() as f64 * report.samples as f64 * g.ks as f64;
    outln!(
        "rdlidar bench: paper scene {g} ({} nonzero voxels), K_p {}, K {}, {}, binary codes",
        report.nonzeros,
        report.pulse_len,
        report.samples,
        report.precision
    );
    outln!(
        "threads {}, kernels {}, operator memory {:.1} MB ({} bytes)",
        report.threads,
        report.isa,
        report.memory_bytes as f64 / 1e6,
        report.memory_bytes
    );
    outln!(
        "{} s of warm-up, then {} timed runs per operation",
        WARM_UP_S,
        report.repeats
    );
    outln!(
        "{:<16} {:>12} {:>12} {:>12} {:>14} {:>12}",
        "operation",
        "median (s)",
        "min (s)",
        "GEMM GFLOP/s",
        "Gadditions/s",
        "table GB/s"
    );
    let rates = [
        Some(&report.rates.forward),
        Some(&report.rates.adjoint),
        None,
        None,
    ];
    for ((name, t), r) in [
        ("forward", report.forward),
        ("adjoint", report.adjoint),
        ("sparse forward", report.sparse_forward),
        ("restricted adj.", report.restricted_adjoint),
    ]
    .into_iter()
    .zip(rates)
    {
        let (gemm, adds, bytes) = match r {
            Some(r) if t.median_s > 0.0 => (
                format!("{:.1}", flops / t.median_s / 1e9),
                format!("{:.1}", r.additions_per_s / 1e9),
                format!("{:.1}", r.table_bytes_per_s / 1e9),
            ),
            _ => ("-".into(), "-".into(), "-".into()),
        };
        outln!(
            "{name:<16} {:>12.6} {:>12.6} {gemm:>12} {adds:>14} {bytes:>12}",
            t.median_s,
            t.min_s
        );
    }
    for (name, l) in [("L1", &report.limits.l1), ("L2", &report.limits.l2)] {
        outln!(
            "limit: random {}-byte rows from a {} kB table in {name} per thread: {:.1} Gadditions/s, {:.1} GB/s",
            l.row_bytes,
            l.table_bytes / 1024,
            l.additions_per_s / 1e9,
            l.bytes_per_s / 1e9
        );
    }
    Ok(())
}
