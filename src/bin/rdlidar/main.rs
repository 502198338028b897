//! The `rdlidar` command line: flags and dispatch; a file per subcommand.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod adjoint;
mod bench;
mod common;
mod dottest;
mod experiment;
mod forward;
mod info;
mod ranks;
mod reconstruct;
mod selfcheck;
mod signals;
mod simulate;
mod stress;

use common::{errln, parse_threads, set_threads, CliResult, Failure, Globals, Precision};
use experiment::{CompareArgs, Experiment, ExperimentArgs, Preset};
use ranks::Ranks;
use rdlidar::lidar::TileSize;
use rdlidar::report::experiment::Shard;
use signals::Signal;

/// Compressive time-of-flight lidar by random demodulation.
///
/// With no subcommand, runs the main job, `demo` (the options below are the demo's): the
/// paper's experiment with every solver, a table on stdout and tables and figures in out/.
///
/// Arrays are exchanged as C-order NumPy `.npy` files: scene (M, N, K_s) float32/float64, pulse
/// (K_p,) float32/float64 ≥ 0, codes (M, N, K) int8 in {-1, 0, 1} or ±1 codes packed as
/// `np.packbits(S > 0, axis=-1)` writes them (uint8 (M, N, ⌈K/8⌉)), measurements (K,)
/// float32/float64, with K = K_p + K_s − 1. Errors are printed as one line `error: ...` naming
/// the file or flag; the exit status is 1 (2 for usage errors) and no output file is left behind.
/// A closed pipe on stdout ends a command quietly with status 141. Sizes and counts have bounds
/// and a request needing more memory than is available is refused before allocating
/// (RDLIDAR_MEMORY_LIMIT=BYTES lowers the budget: bytes, or with a unit, 4G or 4GiB in powers
/// of 1024, 4GB in powers of 1000; any other value is refused); see docs/reliability.md.
///
/// Built with the feature `mpi`, forward, adjoint, dottest, reconstruct and simulate
/// --codes-format seed run under `mpirun -n R` with the pixel rows split over the R processes,
/// and reconstruct --tiles deals the tiles to them (docs/scale.md).
#[derive(Parser, Debug)]
#[command(name = "rdlidar", version, about, long_about)]
struct Cli {
    /// Worker threads of the parallel kernels, 1 … 1024 (default: one per core).
    #[arg(long, global = true, value_parser = parse_threads)]
    threads: Option<usize>,

    /// Base seed of every random draw (default 0). simulate, bench, demo and compare draw the
    /// pulse from SEED, code set g from SEED+1+1000·g (the codes of one ADC from SEED+1), the
    /// noise from SEED+2, random scenes from SEED+3 and a coded aperture from SEED+4;
    /// selfcheck and dottest seed their test vectors with it, reconstruct the solvers'
    /// randomized parts.
    #[arg(long, global = true)]
    seed: Option<u64>,

    /// Floating-point precision of the computation and of the float arrays written (default:
    /// f64 for simulate and compare, f32 for bench and demo; for forward, adjoint and reconstruct,
    /// f64 if an input array is float64, f32 otherwise).
    #[arg(long, global = true, value_enum)]
    precision: Option<Precision>,

    /// Hide progress bars and progress lines.
    #[arg(long, global = true)]
    quiet: bool,

    /// The demo's options, when no subcommand is given.
    #[command(flatten)]
    demo: ExperimentArgs,

    #[command(subcommand)]
    command: Option<Command>,
}

/// Floating-point precision of a computation and of the float arrays it writes.

#[derive(Subcommand, Debug)]
enum Command {
    /// The main job (also what runs with no subcommand): the paper's experiment, extended.
    ///
    /// The paper scene (100x100x40, three extended reflectors) acquired with K_p = 10000,
    /// 20000 and 30000 (noise-free, seed --seed) and reconstructed by every solver
    /// (backprojection plain and debiased, cgls, fista, cosamp, amp, model-based, tv, auto) within
    /// iteration budgets that keep the whole demo under three minutes on two cores: cgls 15,
    /// fista 15 (its step from 15 Lanczos iterations), cosamp 1, model-based 6, tv and auto 4
    /// (each of their model-based fits); change them with --max-iter or a config file.
    ///
    /// Prints a table (per solver and K_p: lit pixels at the exact depth, false detections,
    /// depth RMSE in bins, relative error ‖X − X̂‖/‖X‖, wall time, iterations/budget, why the
    /// solver stopped) and writes to --out (default out/): results.csv, results.json,
    /// results.md, config.toml (the resolved experiment, loadable with --config), one
    /// depth_kp{K_p}.png per pulse length (true and reconstructed depth maps side by side, a
    /// colour bar in metres, pixels without a return in grey) and error_vs_time.png.
    ///
    /// An existing non-empty output folder is refused unless --force. Files are written into a
    /// staging folder .OUT.staging-PID beside --out and moved into place together at the end
    /// (rows are appended there to results.csv.partial and results.jsonl.partial as each run
    /// finishes); Ctrl-C stops after the current run and still writes the tables and figures
    /// of the finished runs (exit status 130); a second Ctrl-C quits at once, leaving nothing
    /// new, and so does SIGTERM (exit status 143; `mpirun` sends it to every process of a job
    /// it stops, Ctrl-C included, and kills them a second later).
    ///
    /// Example: `rdlidar demo --pulse-lens 10000,30000 --solvers backprojection-debiased,model-based --out run1`
    Demo(ExperimentArgs),

    /// Sweep K_p across the compressive, critical and redundant regimes, every solver, several
    /// seeds and noise levels.
    ///
    /// Default: the paper scene 16x16x16 (critical K_p 4081), K_p = 256 … 32768 (10 lengths),
    /// 3 seeds, noise-free, 20 dB and 10 dB SNR, every solver with its default iteration limit,
    /// in f64. --quick: K_p = 512 … 16384 (6 lengths), 2 seeds, noise-free and 20 dB.
    /// --research: 32x32x40 (critical K_p 40921), the paper and a semi-transparent scene, K_p =
    /// 2000 … 81842, noise-free, 20 and 10 dB, 2 seeds, every solver and support-ls. Seed i of
    /// the sweep is SEED + 10·i.
    ///
    /// Writes to --out (default out-compare/): results.csv, results.json and results.md (one
    /// row per run), summary.md (median over seeds of the relative error, exact-depth
    /// percentage, returns found, false detections and time, solver x K_p, per scene and noise
    /// level), config.toml, pareto.png (time against error, every run, with the Pareto front)
    /// and phase_{noise}.png per noise level (median error against K_p, the critical K_p
    /// marked); with several scenes, pareto_{scene}.png and phase_{scene}_{noise}.png.
    /// Existing folders, partial files and Ctrl-C behave as for `demo`.
    ///
    /// Example: `rdlidar compare --quick --solvers cgls,fista,model-based --snr-db none,30`
    Compare(CompareArgs),

    /// Run the dot test on every operator and combinator, in f32 and f64, and print the gaps.
    ///
    /// The global --seed seeds the random operators and test vectors (default 0).
    ///
    /// Example: `rdlidar selfcheck --seed 3`
    Selfcheck,

    Simulate(simulate::SimulateArgs),

    Forward(forward::ForwardArgs),

    Adjoint(adjoint::AdjointArgs),

    Dottest(dottest::DottestArgs),

    Reconstruct(reconstruct::ReconstructArgs),

    Info(info::InfoArgs),

    Bench(bench::BenchArgs),

    Stress(stress::StressArgs),
}

impl Command {
    /// The subcommand's name.
    fn name(&self) -> &'static str {
        match self {
            Command::Demo(_) => "demo",
            Command::Compare(_) => "compare",
            Command::Selfcheck => "selfcheck",
            Command::Simulate(_) => "simulate",
            Command::Forward(_) => "forward",
            Command::Adjoint(_) => "adjoint",
            Command::Dottest(_) => "dottest",
            Command::Reconstruct(_) => "reconstruct",
            Command::Info(_) => "info",
            Command::Bench(_) => "bench",
            Command::Stress(_) => "stress",
        }
    }

    /// Whether it splits its work over the processes of an MPI job: its pixel rows, or for
    /// `reconstruct` of a tiled array its tiles.
    fn splits(&self) -> bool {
        match self {
            Command::Forward(a) => a.tiles.is_none(),
            Command::Adjoint(a) => a.tiles.is_none(),
            Command::Dottest(a) => a.tiles.is_none(),
            Command::Reconstruct(_) => true,
            Command::Compare(a) => a.merge.is_empty(),
            Command::Simulate(a) => simulate::splits(a).is_ok(),
            _ => false,
        }
    }
}

fn run(cli: Cli) -> CliResult<ExitCode> {
    // A memory budget that was asked for is never ignored: a value that is not a byte count is
    // refused before anything runs.
    rdlidar::limits::memory_limit()?;
    let globals = Globals {
        threads: cli.threads,
        seed: cli.seed,
        precision: cli.precision,
        quiet: cli.quiet,
    };
    let Some(command) = cli.command else {
        let alone = Ranks::start("demo", false)?;
        return experiment::run(
            Experiment::Demo,
            &cli.demo,
            (Preset::Default, Shard::WHOLE),
            &globals,
            &alone,
        );
    };
    if cli.demo != ExperimentArgs::default() {
        return Err(
            "the demo's options (--out, --tiny, --pulse-lens, …) before a subcommand \
             apply only without one: put them after the subcommand"
                .to_string()
                .into(),
        );
    }
    // The experiments may also take the thread count from their config file.
    if !matches!(command, Command::Demo(_) | Command::Compare(_)) {
        set_threads(cli.threads, "--threads")?;
    }
    // Under mpirun, the commands that split the pixel rows over the processes start MPI; the
    // others refuse to run as several processes.
    let with_tiles = |t: &Option<TileSize>| if t.is_some() { " --tiles" } else { "" };
    let label = match &command {
        Command::Forward(a) => with_tiles(&a.tiles),
        Command::Adjoint(a) => with_tiles(&a.tiles),
        Command::Dottest(a) => with_tiles(&a.tiles),
        Command::Simulate(a) => simulate::splits(a).err().unwrap_or(""),
        Command::Compare(a) if !a.merge.is_empty() => " --merge",
        _ => "",
    };
    let name = format!("{}{label}", command.name());
    let ranks = Ranks::start(&name, command.splits())?;
    // The experiments stop after the run under way on a first Ctrl-C; the other commands quit.
    match &command {
        Command::Demo(_) => {}
        Command::Compare(a) if a.merge.is_empty() => {}
        Command::Simulate(a) => quit_on_signals((!a.out.exists()).then(|| a.out.clone()))?,
        _ => quit_on_signals(None)?,
    }
    let done = |()| ExitCode::SUCCESS;
    match command {
        Command::Demo(a) => experiment::run(
            Experiment::Demo,
            &a,
            (Preset::Default, Shard::WHOLE),
            &globals,
            &ranks,
        ),
        Command::Compare(a) if !a.merge.is_empty() => experiment::merge(&a, &globals),
        Command::Compare(a) => {
            let preset = match (a.quick, a.research) {
                (true, _) => Preset::Quick,
                (_, true) => Preset::Research,
                _ => Preset::Default,
            };
            let shard = a.shard.unwrap_or(Shard::WHOLE);
            experiment::run(
                Experiment::Compare,
                &a.common,
                (preset, shard),
                &globals,
                &ranks,
            )
        }
        Command::Selfcheck => selfcheck::run(&globals),
        Command::Simulate(a) => simulate::run(&a, &globals, &ranks).map(done),
        Command::Forward(a) => forward::run(&a, &globals, &ranks).map(done),
        Command::Adjoint(a) => adjoint::run(&a, &globals, &ranks).map(done),
        Command::Dottest(a) => dottest::run(&a, &globals, &ranks),
        Command::Reconstruct(a) => reconstruct::run(&a, &globals, &ranks).map(done),
        Command::Info(a) => info::run(&a).map(done),
        Command::Bench(a) => bench::run(&a, &globals).map(done),
        Command::Stress(a) => stress::run(&a, &globals),
    }
}

/// Quits at once on Ctrl-C or SIGTERM (exit status 130 or 143), leaving no partial output: the
/// temporary files of the outputs being written are removed (an output renamed into place
/// meanwhile is complete), so is `created`, the output folder this run made, if it holds
/// nothing, and so is the staging folder of `compare --merge`.
fn quit_on_signals(created: Option<PathBuf>) -> CliResult {
    signals::handle(move |signal| {
        let _held = rdlidar::io::abandon_staged_files();
        if let Some(dir) = &created {
            let _ = std::fs::remove_dir(dir);
        }
        let what = match signal {
            Signal::Interrupt => "interrupted",
            Signal::Terminate => "terminated",
        };
        errln!("\n{what}: quitting; no partial output is left");
        rdlidar::report::experiment::abandon_staged_and_exit(signal.exit_code());
    })?;
    Ok(())
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        // Under mpirun, the first process reports a failure that every process agreed on; the
        // others end quietly, so that the launcher does not end the job before it has.
        Err(Failure::Message(_)) if common::silent() => ExitCode::SUCCESS,
        Err(Failure::Message(msg)) => {
            errln!("error: {msg}");
            ExitCode::FAILURE
        }
        Err(Failure::BrokenPipe) => ExitCode::from(141),
    }
}
