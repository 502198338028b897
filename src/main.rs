//! The `rdlidar` command line.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use clap::{Parser, Subcommand, ValueEnum};
use ndarray_npy::WritableElement;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rdlidar::experiment::{
    self, Budgets, ConfigFile, Console, ExperimentConfig, ExperimentPatch, NoiseLevel,
    SceneKind as ExpSceneKind,
};
use rdlidar::io::{self, NpyDtype, ShapeExpectation, StagedFile};
use rdlidar::lidar::{
    coded_aperture, compare, depth_bin_m, multi_adc, paper_scene, pixel_groups,
    random_opaque_scene, reconstruct, semi_transparent_scene, tiles, CodeAlphabet, Codes, Geometry,
    Method, NoiseModel, NoiseStage, Pulse, RdOperator, ReconstructOptions, Scene, StageReport,
};
use rdlidar::operator::{
    BoxedOperator, ConvMethod, ConvMode, Convolve1D, DenseMatrix, Diagonal, DotTest, Gradient2D,
    HStack, Identity, NalgebraMatrix, OperatorExt, Restriction, SparseMatrix, VStack, Zero,
};
use rdlidar::{LinearOperator, Real};
use serde::Serialize;

mod cli_info;

/// Compressive time-of-flight lidar by random demodulation.
///
/// With no subcommand, runs the main job, `demo` (the options below are the demo's): the
/// paper's experiment with every solver, a table on stdout and tables and figures in out/.
///
/// Arrays are exchanged as C-order NumPy `.npy` files: scene (M, N, K_s) float32/float64, pulse
/// (K_p,) float32/float64 ≥ 0, codes (M, N, K) int8 in {-1, 0, 1}, measurements (K,)
/// float32/float64, with K = K_p + K_s − 1. Errors are printed as one line `error: ...` naming
/// the file or flag; the exit status is 1 (2 for usage errors) and no output file is left behind.
#[derive(Parser, Debug)]
#[command(name = "rdlidar", version, about, long_about)]
struct Cli {
    /// Worker threads of the parallel kernels (default: one per core).
    #[arg(long, global = true, value_parser = parse_positive)]
    threads: Option<usize>,

    /// Base seed of every random draw (default 0). simulate, bench, demo and compare draw the
    /// pulse from SEED, the codes from SEED+1, the noise from SEED+2 and random scenes from
    /// SEED+3; selfcheck and dottest seed their test vectors with it, reconstruct the solvers'
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
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Precision {
    /// Single precision (float32 files).
    #[value(name = "f32")]
    F32,
    /// Double precision (float64 files).
    #[value(name = "f64")]
    F64,
}

/// The scenes `simulate` generates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum SceneKind {
    /// The paper's experiment: a square, a disk and a slanted plane, one return per pixel.
    Paper,
    /// Random opaque scene: each pixel lit with probability --lit-fraction, random depth and
    /// amplitude in [0.2, 1].
    Random,
    /// Semi-transparent scene: 1 to 3 returns per pixel (at most K_s), amplitudes in [0.1, 1].
    Transparent,
}

impl SceneKind {
    fn name(self) -> &'static str {
        match self {
            SceneKind::Paper => "paper",
            SceneKind::Random => "random",
            SceneKind::Transparent => "transparent",
        }
    }
}

#[derive(Subcommand, Debug)]
enum Command {
    /// The main job (also what runs with no subcommand): the paper's experiment, extended.
    ///
    /// The paper scene (100x100x40, three extended reflectors) acquired with K_p = 10000,
    /// 20000 and 30000 (noise-free, seed --seed) and reconstructed by every solver
    /// (backprojection plain and debiased, cgls, fista, cosamp, model-based, tv, auto) within
    /// iteration budgets that keep the whole demo under three minutes on two cores: cgls 15,
    /// fista 15 (its step from 30 power iterations), cosamp 1, model-based 6, tv and auto 4
    /// (each of their model-based fits); change them with --max-iter or a config file.
    ///
    /// Prints a table (per solver and K_p: lit pixels at the exact depth, false detections,
    /// depth RMSE in bins, relative error ‖X − X̂‖/‖X‖, wall time, iterations/budget, why the
    /// solver stopped) and writes to --out (default out/): results.csv, results.json,
    /// results.md, config.toml (the resolved experiment, loadable with --config), one
    /// depth_kp{K_p}.png per pulse length (true and reconstructed depth maps side by side, a
    /// colour bar in metres, pixels without a return in grey) and error_vs_time.png.
    ///
    /// An existing non-empty output folder is refused unless --force. Rows are appended to
    /// results.csv.partial and results.jsonl.partial as each run finishes; Ctrl-C stops after
    /// the current run and still writes the tables and figures of the finished runs (exit
    /// status 130); a second Ctrl-C quits at once, leaving the partial files.
    ///
    /// Example: `rdlidar demo --pulse-lens 10000,30000 --solvers backprojection-debiased,model-based --out run1`
    Demo(ExperimentArgs),

    /// Sweep K_p across the compressive, critical and redundant regimes, every solver, several
    /// seeds and noise levels.
    ///
    /// Default: the paper scene 16x16x16 (critical K_p 4081), K_p = 256 … 32768 (10 lengths),
    /// 3 seeds, noise-free, 20 dB and 10 dB SNR, every solver with its default iteration limit,
    /// in f64. --quick: K_p = 512 … 16384 (6 lengths), 2 seeds, noise-free and 20 dB. Seed i
    /// of the sweep is SEED + 10·i.
    ///
    /// Writes to --out (default out-compare/): results.csv, results.json and results.md (one
    /// row per run), summary.md (median over seeds of the relative error, exact-depth
    /// percentage and time, solver x K_p, per noise level), config.toml, pareto.png (time
    /// against error, every run, with the Pareto front) and phase_{noise}.png per noise level
    /// (median error against K_p, the critical K_p marked). Existing folders, partial files
    /// and Ctrl-C behave as for `demo`.
    ///
    /// Example: `rdlidar compare --quick --solvers cgls,fista,model-based --snr-db none,30`
    Compare(CompareArgs),

    /// Run the dot test on every operator and combinator, in f32 and f64, and print the gaps.
    ///
    /// The global --seed seeds the random operators and test vectors (default 0).
    ///
    /// Example: `rdlidar selfcheck --seed 3`
    Selfcheck,

    /// Generate a scene, a pulse and codes, and simulate the measurements.
    ///
    /// Writes DIR/scene.npy (M, N, K_s), pulse.npy (K_p,), codes.npy (M, N, K) int8,
    /// meas.npy (K,) and meta.json (geometry, K_p, K, seeds, scene kind, code alphabet, regime and
    /// critical K_p, noise, PRNG, crate version), with K = K_p + K_s − 1.
    ///
    /// Seeds (all ChaCha8): the pulse is drawn from SEED, the codes from SEED+1, the noise from
    /// SEED+2 and the random and transparent scenes from SEED+3. The same arguments give the same
    /// files on every machine.
    ///
    /// Architectures (the paper's §3; at most one of the three flags, meta.json records it under
    /// "architecture"):
    ///
    /// * --adcs G (G > 1): G ADCs, every pixel modulated by G independent code sets, code set g
    ///   (g = 0 … G−1) drawn from SEED+1+1000·g. codes.npy is (G, M, N, K) int8, meas.npy (G, K),
    ///   row g measured through set g.
    ///
    /// * --tiles AxB: the array split into tiles of AxB pixels (row-major, the last ones clipped
    ///   at the edges), one ADC per tile summing only its pixels. codes.npy is the usual
    ///   (M, N, K), meas.npy (T, K) for T tiles, in row-major tile order. Read them back with
    ///   `forward`/`adjoint`/`dottest --tiles AxB`.
    ///
    /// * --aperture F: a coded aperture, only ⌈F·M·N⌉ pixels drawn at random from SEED+4 reach
    ///   the single ADC. The other pixels' codes are written as 0 in codes.npy, which is thus an
    ///   ordinary (M, N, K) file whose single-ADC operator is the coded aperture; meas.npy is (K,).
    ///
    /// DIR is created if needed (its parent must exist). An existing non-empty DIR is refused
    /// unless --force is given, which replaces the five files and leaves other files alone.
    /// Files are written under temporary names and renamed into place once all are complete; on
    /// an error nothing is left behind.
    ///
    /// Example: `rdlidar simulate --scene paper --size 100x100x40 --pulse-len 10000 --seed 0 --out run0`
    Simulate(SimulateArgs),

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
    Forward {
        /// Pulse file (K_p,), float32 or float64, ≥ 0.
        #[arg(long, value_name = "P")]
        pulse: PathBuf,
        /// Codes file (M, N, K), or (G, M, N, K) for G code sets; int8 (or float) in {-1, 0, 1}.
        #[arg(long, value_name = "S")]
        codes: PathBuf,
        /// Scene file (M, N, K_s), float32 or float64.
        #[arg(long, value_name = "X")]
        scene: PathBuf,
        /// Output measurements file (K,), or (ADCs, K) for several ADCs.
        #[arg(long, value_name = "Y")]
        out: PathBuf,
        /// One ADC per tile of AxB pixels (as written by `simulate --tiles AxB`).
        #[arg(long, value_name = "AxB", value_parser = parse_tile)]
        tiles: Option<Tile>,
    },

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
    Adjoint {
        /// Pulse file (K_p,), float32 or float64, ≥ 0.
        #[arg(long, value_name = "P")]
        pulse: PathBuf,
        /// Codes file (M, N, K), or (G, M, N, K) for G code sets; int8 (or float) in {-1, 0, 1}.
        #[arg(long, value_name = "S")]
        codes: PathBuf,
        /// Measurements file (K,), or (ADCs, K) for several ADCs; float32 or float64.
        #[arg(long, value_name = "Y")]
        meas: PathBuf,
        /// Depth bins K_s of the scene.
        #[arg(long, value_name = "KS", value_parser = parse_positive)]
        depth_bins: usize,
        /// Output file (M, N, K_s).
        #[arg(long, value_name = "XT")]
        out: PathBuf,
        /// Correlate with the zero-mean pulse (debiased backprojection).
        #[arg(long)]
        debiased: bool,
        /// One ADC per tile of AxB pixels (as written by `simulate --tiles AxB`).
        #[arg(long, value_name = "AxB", value_parser = parse_tile)]
        tiles: Option<Tile>,
    },

    /// Check the adjoint identity <Ax, y> = <x, A*y> of the operator built from files.
    ///
    /// Builds the operator from the pulse and codes in f32 and in f64 (with the pulse as given
    /// and with the zero-mean pulse), prints each relative gap
    /// |<Ax,y> - <x,A*y>| / max(|Ax||y|, |x||A*y|) on seeded Gaussian vectors and exits with
    /// status 1 if one is above its tolerance (1e-4 in f32, 1e-10 in f64).
    ///
    /// Codes of shape (G, M, N, K) give the stacked operator of G ADCs; --tiles AxB the stacked
    /// operator of one ADC per tile.
    ///
    /// Example: `rdlidar dottest --pulse run0/pulse.npy --codes run0/codes.npy --depth-bins 40`
    Dottest {
        /// Pulse file (K_p,), float32 or float64, ≥ 0.
        #[arg(long, value_name = "P")]
        pulse: PathBuf,
        /// Codes file (M, N, K), or (G, M, N, K) for G code sets; int8 (or float) in {-1, 0, 1}.
        #[arg(long, value_name = "S")]
        codes: PathBuf,
        /// Depth bins K_s of the scene.
        #[arg(long, value_name = "KS", value_parser = parse_positive)]
        depth_bins: usize,
        /// One ADC per tile of AxB pixels (as written by `simulate --tiles AxB`).
        #[arg(long, value_name = "AxB", value_parser = parse_tile)]
        tiles: Option<Tile>,
    },

    /// Reconstruct the scene from measurements: a depth map and a one-return-per-pixel scene.
    ///
    /// Reads the pulse (K_p,), the codes (M, N, K) and the measurements (K,), with
    /// K = K_p + K_s − 1, runs the solver and writes the depth map (M, N) int32 (−1 = no return)
    /// to --out-depth and the scene (M, N, K_s) to --out-scene, with the dtype of --precision.
    /// The files (and the --png image) are written together: on any error none is left behind.
    ///
    /// Solvers: backprojection (the paper's: adjoint, per-pixel peak, robust threshold),
    /// backprojection-debiased (zero-mean pulse), cgls (least squares), fista (nonnegative
    /// lasso), iht and cosamp (sparsity estimated from the debiased backprojection), model-based
    /// (one reflector per pixel), tv (TV on the depth map) and auto: debiased backprojection in
    /// the redundant regime, cgls in the critical one, model-based in the compressive one,
    /// followed by tv (from scratch) when the model-based fit does not explain the data, keeping
    /// tv's scene when it fits about as well.
    ///
    /// With --truth SCENE.npy the estimate is compared with the true scene (exact depths,
    /// RMSE, misses, false detections, relative error; τ = 200 ps per bin).
    ///
    /// Example: `rdlidar reconstruct --pulse run0/pulse.npy --codes run0/codes.npy --meas run0/meas.npy --depth-bins 40 --solver auto --out-depth d.npy --out-scene xh.npy --png d.png --truth run0/scene.npy`
    Reconstruct(ReconstructArgs),

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
    Info(cli_info::InfoArgs),

    /// Time the forward, adjoint and sparse forward operators on a generated problem.
    ///
    /// Generates the paper scene, a Bernoulli pulse (seed SEED) and binary codes (seed SEED+1)
    /// before timing; no file is read or written. Each operation runs once as a warm-up, then
    /// --repeats times; the median and the minimum wall time are reported. "forward" is the
    /// dense table path over all pixels, "adjoint" the backprojection, "sparse forward" the
    /// forward product over the nonzero voxels of the scene only.
    ///
    /// --json prints {"forward": {"median_s": .., "min_s": ..}, "adjoint": {..},
    /// "sparse_forward": {..}, ...} on one line instead of the table.
    ///
    /// Example: `rdlidar bench --size 100x100x40 --pulse-len 30000 --precision f32 --json`
    Bench {
        /// Scene grid MxNxKS.
        #[arg(long, value_parser = parse_size, default_value = "100x100x40")]
        size: Geometry,
        /// Pulse length K_p.
        #[arg(long, value_parser = parse_positive, default_value_t = 30000)]
        pulse_len: usize,
        /// Print the timings as JSON.
        #[arg(long)]
        json: bool,
        /// Timed runs of each operation, after one warm-up run.
        #[arg(long, value_parser = parse_positive, default_value_t = 7)]
        repeats: usize,
    },
}

/// The options of `demo` (and of the command with no subcommand) and `compare`.
///
/// Each option overrides the experiment's preset and the config file's section.
#[derive(clap::Args, Debug, Default, PartialEq)]
struct ExperimentArgs {
    /// TOML file describing the experiment: top-level seed, precision, threads, quiet, and
    /// [demo] / [compare] sections with the keys out, scene, size, lit_fraction, pulse_lens,
    /// solvers, snr_db, seeds, max_iter, power_iterations (see docs/experiments.md). Flags
    /// override it.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Output folder (default: out/ for demo, out-compare/ for compare).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Write into an existing non-empty output folder, replacing the experiment's files.
    #[arg(long)]
    force: bool,
    /// A small preset that runs in seconds (demo: 8x8x8, K_p 100,300,1000; compare: 6x6x6,
    /// K_p 50,211,800).
    #[arg(long)]
    tiny: bool,
    /// Scene: paper (the default) or random.
    #[arg(long, value_parser = parse_scene)]
    scene: Option<ExpScene>,
    /// Scene grid MxNxKS (at most 1024 rows and columns, 2^26 voxels).
    #[arg(long, value_name = "MxNxKS", value_parser = parse_size)]
    size: Option<Geometry>,
    /// Fraction of lit pixels of --scene random, in [0, 1] (default 0.5).
    #[arg(long, value_name = "F")]
    lit_fraction: Option<f64>,
    /// Pulse lengths K_p, comma-separated.
    #[arg(long, value_name = "LIST", value_parser = parse_pulse_lens)]
    pulse_lens: Option<PulseLens>,
    /// Solvers, comma-separated, or `all` (every solver but iht): backprojection,
    /// backprojection-debiased, cgls, fista, iht, cosamp, model-based, tv, auto.
    #[arg(long, value_name = "LIST", value_parser = parse_solver_list)]
    solvers: Option<Solvers>,
    /// Noise levels in dB SNR, comma-separated; `none` for noise-free.
    #[arg(long, value_name = "LIST", value_parser = parse_noise_list, allow_hyphen_values = true)]
    snr_db: Option<NoiseLevels>,
    /// Number of seeds (SEED, SEED+10, …).
    #[arg(long, value_name = "N", value_parser = parse_positive)]
    seeds: Option<usize>,
    /// Iteration budgets, e.g. `fista=50,model-based=12` (other solvers keep the preset's).
    #[arg(long, value_name = "SOLVER=N,...", value_parser = parse_budgets)]
    max_iter: Option<Budgets>,
    /// Power iterations that estimate ‖A‖² for FISTA's step (demo default 30; compare: the
    /// solver's default of up to 200).
    #[arg(long, value_name = "N", value_parser = parse_positive)]
    power_iterations: Option<usize>,
}

/// The options of `compare`.
#[derive(clap::Args, Debug)]
struct CompareArgs {
    #[command(flatten)]
    common: ExperimentArgs,
    /// The quick sweep: 6 pulse lengths, 2 seeds, 2 noise levels (under 5 minutes on 2 cores).
    #[arg(long, conflicts_with = "tiny")]
    quick: bool,
}

/// Values of the experiment flags (newtypes, so that clap takes each list as one value).
#[derive(Debug, Clone, PartialEq)]
struct PulseLens(Vec<usize>);
#[derive(Debug, Clone, PartialEq)]
struct Solvers(Vec<Method>);
#[derive(Debug, Clone, PartialEq)]
struct NoiseLevels(Vec<NoiseLevel>);
#[derive(Debug, Clone, Copy, PartialEq)]
struct ExpScene(ExpSceneKind);

fn parse_scene(text: &str) -> Result<ExpScene, String> {
    text.parse()
        .map(ExpScene)
        .map_err(|e: rdlidar::Error| e.to_string())
}

fn parse_pulse_lens(text: &str) -> Result<PulseLens, String> {
    experiment::parse_pulse_lens(text)
        .map(PulseLens)
        .map_err(|e| e.to_string())
}

fn parse_solver_list(text: &str) -> Result<Solvers, String> {
    experiment::parse_solvers(text)
        .map(Solvers)
        .map_err(|e| e.to_string())
}

fn parse_noise_list(text: &str) -> Result<NoiseLevels, String> {
    experiment::parse_noise_levels(text)
        .map(NoiseLevels)
        .map_err(|e| e.to_string())
}

fn parse_budgets(text: &str) -> Result<Budgets, String> {
    Budgets::parse(text).map_err(|e| e.to_string())
}

/// The options of `simulate`.
#[derive(clap::Args, Debug)]
struct SimulateArgs {
    /// Scene to generate.
    #[arg(long, value_enum)]
    scene: SceneKind,
    /// Scene grid MxNxKS: M×N pixels, K_s depth bins.
    #[arg(long, value_parser = parse_size)]
    size: Geometry,
    /// Pulse length K_p (Bernoulli 0/1 samples).
    #[arg(long, value_parser = parse_positive)]
    pulse_len: usize,
    /// Base seed (the global --seed, default 0; see above for the derived seeds).
    #[arg(skip)]
    seed: u64,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Precision of the computation and dtype of scene.npy, pulse.npy and meas.npy (the
    /// global --precision, default f64).
    #[arg(skip = Precision::F64)]
    precision: Precision,
    /// Fraction of lit pixels of `--scene random`, in [0, 1] (default 0.5).
    #[arg(long, value_name = "F")]
    lit_fraction: Option<f64>,
    /// Draw ternary codes in {-1, 0, 1} with P(0) = P, in [0, 1) (default: binary ±1 codes).
    #[arg(long, value_name = "P")]
    ternary_zero_prob: Option<f64>,
    /// Add white Gaussian noise at this SNR in dB, relative to the mean power of the
    /// noiseless measurements (default: noise-free).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    snr_db: Option<f64>,
    /// Replace scene.npy, pulse.npy, codes.npy, meas.npy and meta.json in a non-empty DIR.
    #[arg(long)]
    force: bool,
    /// Number of ADCs G ≥ 1, each with its own code set for every pixel (G > 1 writes codes.npy
    /// (G, M, N, K) and meas.npy (G, K)).
    #[arg(long, value_name = "G", value_parser = parse_positive, default_value_t = 1)]
    adcs: usize,
    /// Split the array into tiles of AxB pixels with one ADC each (meas.npy (T, K) for T tiles).
    #[arg(long, value_name = "AxB", value_parser = parse_tile)]
    tiles: Option<Tile>,
    /// Coded aperture: only a random fraction F in (0, 1] of the pixels (⌈F·M·N⌉ of them)
    /// reaches the ADC; the others' codes are written as 0.
    #[arg(long, value_name = "F")]
    aperture: Option<f64>,
}

/// The options of `reconstruct`.
#[derive(clap::Args, Debug)]
struct ReconstructArgs {
    /// Pulse file (K_p,), float32 or float64, ≥ 0.
    #[arg(long, value_name = "P")]
    pulse: PathBuf,
    /// Codes file (M, N, K), int8 (or float) in {-1, 0, 1}.
    #[arg(long, value_name = "S")]
    codes: PathBuf,
    /// Measurements file (K,), float32 or float64.
    #[arg(long, value_name = "Y")]
    meas: PathBuf,
    /// Depth bins K_s of the scene.
    #[arg(long, value_name = "KS", value_parser = parse_positive)]
    depth_bins: usize,
    /// Reconstruction method.
    #[arg(long, value_name = "NAME", value_parser = parse_method)]
    solver: Method,
    /// Output depth map (M, N), int32, −1 = no return.
    #[arg(long, value_name = "D")]
    out_depth: PathBuf,
    /// Output scene (M, N, K_s), float32 or float64 as --precision.
    #[arg(long, value_name = "XH")]
    out_scene: PathBuf,
    /// Precision of the computation and of the scene file (the global --precision; default:
    /// f64 if the measurements or the pulse are float64, f32 otherwise).
    #[arg(skip)]
    precision: Option<Precision>,
    /// Overrides the solver's iteration limit.
    #[arg(long, value_name = "N", value_parser = parse_positive)]
    max_iter: Option<usize>,
    /// Also write the depth map as a PNG image (with the true one beside it under --truth).
    #[arg(long, value_name = "D.png")]
    png: Option<PathBuf>,
    /// The true scene (M, N, K_s): print how well the estimate matches it.
    #[arg(long, value_name = "SCENE")]
    truth: Option<PathBuf>,
    /// Seed of the solvers' randomized parts (the global --seed, default 0).
    #[arg(skip)]
    seed: u64,
    /// Hide the progress bar (the global --quiet).
    #[arg(skip)]
    quiet: bool,
}

/// A `--solver` name, with the valid names listed on error.
fn parse_method(text: &str) -> Result<Method, String> {
    text.parse::<Method>().map_err(|_| {
        format!(
            "unknown solver {text:?}; valid solvers: {}",
            Method::NAMES.join(", ")
        )
    })
}

/// A tile size, `AxB` on the command line: A rows and B columns of pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Tile {
    m: usize,
    n: usize,
}

impl std::fmt::Display for Tile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.m, self.n)
    }
}

fn parse_tile(text: &str) -> Result<Tile, String> {
    let parts: Vec<&str> = text.trim().split(['x', 'X']).collect();
    let dims: Vec<usize> = parts
        .iter()
        .map(|p| p.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected AxB (tile rows x tile columns), got {text:?}"))?;
    match dims[..] {
        [m, n] if m > 0 && n > 0 => Ok(Tile { m, n }),
        [m, n] => Err(format!("tile dimensions must be positive, got {m}x{n}")),
        _ => Err(format!(
            "expected AxB (tile rows x tile columns), got {text:?}"
        )),
    }
}

fn parse_positive(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(0) => Err("must be at least 1".to_string()),
        Ok(v) => Ok(v),
        Err(_) => Err(format!("expected a positive integer, got {text:?}")),
    }
}

fn parse_size(text: &str) -> Result<Geometry, String> {
    Geometry::parse(text).map_err(|e| e.to_string())
}

/// Deterministic values in [−1, 1) (a small LCG; the operators only need to be generic).
fn values(len: usize, seed: u64) -> Vec<f64> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..len)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        })
        .collect()
}

/// One instance of every operator and combinator, named.
fn catalogue<T: Real>(seed: u64) -> rdlidar::Result<Vec<(&'static str, BoxedOperator<T>)>> {
    let c = |v: Vec<f64>| v.into_iter().map(T::of_f64).collect::<Vec<T>>();
    let (m, n) = (23, 17);
    let dense = || -> rdlidar::Result<DenseMatrix<T>> {
        DenseMatrix::new(ndarray::Array2::from_shape_vec((m, n), c(values(m * n, seed))).unwrap())
    };
    let mut sp = sprs::TriMat::new((m, n));
    for (k, v) in values(m * n, seed + 1)
        .into_iter()
        .enumerate()
        .filter(|(k, _)| k % 4 == 0)
    {
        sp.add_triplet(k / n, k % n, T::of_f64(v));
    }
    let pulse: Vec<T> = c(values(300, seed + 2)
        .into_iter()
        .map(|v| if v > 0.0 { 1.0 } else { 0.0 })
        .collect());
    Ok(vec![
        ("Identity", Identity::<T>::new(n).boxed()),
        ("Zero", Zero::<T>::new(m, n).boxed()),
        ("Diagonal", Diagonal::new(c(values(n, seed + 3)))?.boxed()),
        (
            "Restriction (repeated indices)",
            Restriction::<T>::new(n, vec![3, 1, 3, 16, 0, 3])?.boxed(),
        ),
        ("Gradient2D 12x9", Gradient2D::<T>::new(12, 9)?.boxed()),
        (
            "Convolve1D direct, full",
            Convolve1D::new(
                7,
                40,
                c(values(9, seed + 4)),
                ConvMode::Full,
                ConvMethod::Direct,
            )?
            .boxed(),
        ),
        (
            "Convolve1D direct, same",
            Convolve1D::new(
                7,
                40,
                c(values(9, seed + 4)),
                ConvMode::Same,
                ConvMethod::Direct,
            )?
            .boxed(),
        ),
        (
            "Convolve1D direct, valid",
            Convolve1D::new(
                7,
                40,
                c(values(9, seed + 4)),
                ConvMode::Valid,
                ConvMethod::Direct,
            )?
            .boxed(),
        ),
        (
            "Convolve1D FFT, full (0/1 pulse 300)",
            Convolve1D::new(7, 40, pulse.clone(), ConvMode::Full, ConvMethod::Fft)?.boxed(),
        ),
        (
            "Convolve1D FFT, same",
            Convolve1D::new(7, 400, pulse.clone(), ConvMode::Same, ConvMethod::Fft)?.boxed(),
        ),
        (
            "Convolve1D FFT, valid",
            Convolve1D::new(7, 400, pulse, ConvMode::Valid, ConvMethod::Fft)?.boxed(),
        ),
        ("DenseMatrix", dense()?.boxed()),
        (
            "NalgebraMatrix",
            NalgebraMatrix::new(nalgebra::DMatrix::from_vec(
                m,
                n,
                c(values(m * n, seed + 5)),
            ))?
            .boxed(),
        ),
        ("SparseMatrix", SparseMatrix::new(sp.to_csr())?.boxed()),
        (
            "Compose",
            dense()?
                .compose(Diagonal::new(c(values(n, seed + 6)))?)?
                .boxed(),
        ),
        ("Adjoint", dense()?.adjoint().boxed()),
        ("Scaled", dense()?.scaled(T::of_f64(-2.5))?.boxed()),
        ("Sum", dense()?.plus(Zero::new(m, n))?.boxed()),
        ("Difference", dense()?.minus(dense()?)?.boxed()),
        ("Normal", dense()?.normal().boxed()),
        (
            "VStack",
            VStack::new(vec![dense()?.boxed(), Identity::new(n).boxed()])?.boxed(),
        ),
        (
            "HStack",
            HStack::new(vec![dense()?.boxed(), Identity::new(m).boxed()])?.boxed(),
        ),
        (
            "BlockDiag",
            rdlidar::operator::BlockDiag::new(vec![
                dense()?.boxed(),
                Gradient2D::new(3, 4)?.boxed(),
            ])?
            .boxed(),
        ),
        ("Counted", dense()?.counted().boxed()),
    ])
}

fn selfcheck(seed: u64) -> rdlidar::Result<bool> {
    let ops32 = catalogue::<f32>(seed)?;
    let ops64 = catalogue::<f64>(seed)?;
    println!("dot test |<Ax,y> - <x,A*y>| / max(|Ax||y|, |x||A*y|), seed {seed}");
    println!("{:<38} {:>12} {:>12}", "operator", "gap f32", "gap f64");
    let mut ok = true;
    for ((name, a32), (_, a64)) in ops32.iter().zip(&ops64) {
        let r32 = DotTest::new().seed(seed).measure(a32);
        let r64 = DotTest::new().seed(seed).measure(a64);
        let flag = if r32.passed() && r64.passed() {
            ""
        } else {
            "  FAILED"
        };
        ok &= flag.is_empty();
        println!("{name:<38} {:>12.2e} {:>12.2e}{flag}", r32.gap, r64.gap);
    }
    println!(
        "tolerances: f32 {:.0e}, f64 {:.0e}",
        f32::DOT_TEST_TOL,
        f64::DOT_TEST_TOL
    );
    Ok(ok)
}

/// A command-line failure: the one-line message printed after `error: `.
#[derive(Debug)]
struct Failure(String);

impl From<rdlidar::Error> for Failure {
    fn from(e: rdlidar::Error) -> Self {
        Failure(e.to_string())
    }
}

impl From<String> for Failure {
    fn from(msg: String) -> Self {
        Failure(msg)
    }
}

type CliResult<T = ()> = Result<T, Failure>;

/// The directory a path's file lives in (`.` for a bare file name).
fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Checks, before any work, that an output file can be created where asked.
fn check_out_file(out: &Path) -> CliResult {
    if out.is_dir() {
        return Err(format!("{}: is a directory, expected a file name", out.display()).into());
    }
    let dir = parent_dir(out);
    if !dir.is_dir() {
        return Err(format!(
            "{}: directory {} does not exist",
            out.display(),
            dir.display()
        )
        .into());
    }
    Ok(())
}

/// f64 if one of the files holds float64 data, f32 otherwise (the headers are read, not the data).
fn auto_precision(files: &[&Path]) -> CliResult<Precision> {
    for f in files {
        if io::read_header(f)?.dtype == NpyDtype::Float64 {
            return Ok(Precision::F64);
        }
    }
    Ok(Precision::F32)
}

fn npy_dtype<T: Real>() -> &'static str {
    match T::NAME {
        "f32" => "float32",
        _ => "float64",
    }
}

/// How the measurements were taken, from the codes header and `--tiles`, before the codes are
/// read.
#[derive(Debug, Clone, Copy)]
enum LayoutKind {
    /// A single code set (M, N, K) and one ADC (a coded aperture has zero codes).
    Single,
    /// G code sets (G, M, N, K), one ADC each.
    MultiAdc(usize),
    /// A single code set, one ADC per tile.
    Tiles(Tile),
}

/// The codes of a problem, read according to its [`LayoutKind`].
enum Layout {
    /// One code set, one ADC.
    Single(Arc<Codes>),
    /// One ADC per code set.
    MultiAdc(Vec<Arc<Codes>>),
    /// One code set, one ADC per group of pixels (the tiles of `tile`).
    Tiles {
        codes: Arc<Codes>,
        tile: Tile,
        groups: Vec<Vec<usize>>,
    },
}

impl Layout {
    /// Rows of the measurements: `None` for the (K,) vector of one ADC, `Some(R)` for (R, K).
    fn rows(&self) -> Option<usize> {
        match self {
            Layout::Single(_) => None,
            Layout::MultiAdc(sets) => Some(sets.len()),
            Layout::Tiles { groups, .. } => Some(groups.len()),
        }
    }

    /// The measurement operator with the pulse `pulse`.
    fn operator<T: Real>(&self, g: Geometry, pulse: Vec<T>) -> rdlidar::Result<BoxedOperator<T>> {
        Ok(match self {
            Layout::Single(codes) => RdOperator::new(g, pulse, codes.clone())?.boxed(),
            Layout::MultiAdc(sets) => multi_adc(g, &pulse, sets.clone())?.boxed(),
            Layout::Tiles { codes, groups, .. } => pixel_groups(g, &pulse, codes, groups)?.boxed(),
        })
    }

    /// "binary" if every code set is ±1, "ternary" otherwise.
    fn alphabet(&self) -> &'static str {
        let binary = |c: &Arc<Codes>| c.alphabet() == CodeAlphabet::Binary;
        let all_binary = match self {
            Layout::Single(codes) | Layout::Tiles { codes, .. } => binary(codes),
            Layout::MultiAdc(sets) => sets.iter().all(binary),
        };
        if all_binary {
            "binary"
        } else {
            "ternary"
        }
    }

    /// A note for the messages of the multi-ADC layouts (empty for a single ADC).
    fn note(&self) -> String {
        match self {
            Layout::Single(_) => String::new(),
            Layout::MultiAdc(sets) => format!(", {} ADCs (one code set each)", sets.len()),
            Layout::Tiles { tile, groups, .. } => {
                format!(", tiles of {tile} pixels ({} ADCs)", groups.len())
            }
        }
    }
}

/// Decides the layout from the header of the codes file and `--tiles`; returns it with the
/// codes' shape.
fn layout_kind(codes: &Path, tile: Option<Tile>) -> CliResult<(LayoutKind, Vec<usize>)> {
    let h = io::read_header(codes)?;
    let kind = match (h.shape.len(), tile) {
        (4, Some(t)) => {
            return Err(format!(
                "{}: codes of shape {} are {} code sets, one ADC each; --tiles {t} and several \
                 code sets are not supported together",
                codes.display(),
                io::shape_text(&h.shape),
                h.shape[0]
            )
            .into())
        }
        (4, None) => LayoutKind::MultiAdc(h.shape[0]),
        (_, Some(t)) => LayoutKind::Tiles(t),
        (_, None) => LayoutKind::Single,
    };
    Ok((kind, h.shape))
}

/// Reads the codes as `kind` says: (M, N, K) or (G, M, N, K). Returns the geometry (with `ks`
/// depth bins) and the layout.
fn read_layout(
    codes: &Path,
    kind: LayoutKind,
    expect: &ShapeExpectation,
    ks: usize,
) -> CliResult<(Geometry, Layout)> {
    let geometry =
        |(m, n): (usize, usize)| Geometry::new(m, n, ks).map_err(|e| format!("--depth-bins: {e}"));
    Ok(match kind {
        LayoutKind::Single => {
            let (grid, s) = io::read_codes(codes, expect)?;
            (geometry(grid)?, Layout::Single(Arc::new(s)))
        }
        LayoutKind::MultiAdc(_) => {
            let (grid, sets) = io::read_code_sets(codes, expect)?;
            let sets = sets.into_iter().map(Arc::new).collect();
            (geometry(grid)?, Layout::MultiAdc(sets))
        }
        LayoutKind::Tiles(tile) => {
            let (grid, s) = io::read_codes(codes, expect)?;
            let g = geometry(grid)?;
            let groups = tiles(g, tile.m, tile.n).map_err(|e| format!("--tiles: {e}"))?;
            (
                g,
                Layout::Tiles {
                    codes: Arc::new(s),
                    tile,
                    groups,
                },
            )
        }
    })
}

/// p − mean(p), the pulse of the debiased adjoint (the mean taken in f64).
fn zero_mean_pulse<T: Real>(p: &[T]) -> Vec<T> {
    let mean = p.iter().map(|v| v.as_f64()).sum::<f64>() / p.len() as f64;
    p.iter().map(|v| T::of_f64(v.as_f64() - mean)).collect()
}

fn forward<T: Real + WritableElement>(
    pulse: &Path,
    codes: &Path,
    scene: &Path,
    out: &Path,
    tile: Option<Tile>,
) -> CliResult {
    let p = io::read_pulse::<T>(pulse)?;
    let x = io::read_scene::<T>(scene)?;
    let g = x.geometry();
    let expect = ShapeExpectation {
        pulse_len: p.len(),
        depth_bins: g.ks,
        grid: Some((g.m, g.n)),
    };
    let (kind, _) = layout_kind(codes, tile)?;
    let (_, layout) = read_layout(codes, kind, &expect, g.ks)?;
    let op = layout.operator(g, p.into_inner())?;
    let y = apply_to(&op, x.as_slice());
    match layout.rows() {
        None => {
            io::write_measurements(out, &y)?;
            println!(
                "wrote {}: measurements ({},) {}",
                out.display(),
                y.len(),
                npy_dtype::<T>()
            );
        }
        Some(rows) => {
            let k = expect.samples();
            let y2 = ndarray::ArrayView2::from_shape((rows, k), &y[..])
                .map_err(|e| format!("cannot shape the measurements: {e}"))?;
            io::write_array(out, &y2)?;
            println!(
                "wrote {}: measurements ({rows}, {k}) {}, one row per ADC{}",
                out.display(),
                npy_dtype::<T>(),
                layout.note()
            );
        }
    }
    Ok(())
}

/// The files of `adjoint`.
struct AdjointFiles<'a> {
    pulse: &'a Path,
    codes: &'a Path,
    meas: &'a Path,
    out: &'a Path,
}

/// Reads the measurements in the shape `kind` needs: (K,) for one ADC, (R, K) for R ADCs, with a
/// message that names the flag or the file that decides the shape when the shapes disagree.
fn read_layout_measurements<T: Real>(
    files: &AdjointFiles<'_>,
    kind: LayoutKind,
    codes_shape: &[usize],
    expect: &ShapeExpectation,
) -> CliResult<Vec<T>> {
    let meas = files.meas;
    let h = io::read_header(meas)?;
    let k = expect.samples();
    let float = matches!(h.dtype, NpyDtype::Float32 | NpyDtype::Float64);
    let (rows, why) = match kind {
        LayoutKind::Single => {
            if float && h.shape.len() == 2 && codes_shape.len() == 3 {
                return Err(format!(
                    "{}: measurements of shape {} have one row per ADC, but the codes {} are \
                     one code set read as a single ADC: for a tiled array pass --tiles AxB \
                     with its tile size (meta.json \"architecture\" \"tile\")",
                    meas.display(),
                    io::shape_text(&h.shape),
                    files.codes.display()
                )
                .into());
            }
            return Ok(io::read_measurements::<T>(meas, Some(expect))?);
        }
        LayoutKind::MultiAdc(sets) => (
            (sets > 0).then_some(sets),
            format!(
                "the codes {} of shape {} are {sets} code sets, one ADC each",
                files.codes.display(),
                io::shape_text(codes_shape)
            ),
        ),
        LayoutKind::Tiles(t) => match codes_shape {
            [m, n, _] if *m > 0 && *n > 0 => {
                let count = m.div_ceil(t.m) * n.div_ceil(t.n);
                (
                    Some(count),
                    format!(
                        "--tiles {t} splits the {m}x{n} array into {count} tiles, one ADC each"
                    ),
                )
            }
            _ => (None, String::new()),
        },
    };
    if let (Some(r), true) = (rows, float) {
        let found = match h.shape[..] {
            [_] => Some("are those of one ADC".to_string()),
            [n, _] if n != r => Some(format!("have {n} rows")),
            _ => None,
        };
        if let Some(found) = found {
            return Err(format!(
                "{}: measurements of shape {} {found}, but {why}: expected shape ({r}, {k})",
                meas.display(),
                io::shape_text(&h.shape)
            )
            .into());
        }
    }
    let y = io::read_measurement_rows::<T>(meas, Some(expect), rows)?;
    Ok(y.into_raw_vec_and_offset().0)
}

fn adjoint<T: Real + WritableElement>(
    files: &AdjointFiles<'_>,
    depth_bins: usize,
    debiased: bool,
    tile: Option<Tile>,
) -> CliResult {
    let out = files.out;
    let p = io::read_pulse::<T>(files.pulse)?;
    if p.len().checked_add(depth_bins).is_none() {
        return Err(format!("--depth-bins {depth_bins} is too large").into());
    }
    let expect = ShapeExpectation {
        pulse_len: p.len(),
        depth_bins,
        grid: None,
    };
    let (kind, codes_shape) = layout_kind(files.codes, tile)?;
    let y = read_layout_measurements::<T>(files, kind, &codes_shape, &expect)?;
    let (g, layout) = read_layout(files.codes, kind, &expect, depth_bins)?;
    let pulse = if debiased {
        zero_mean_pulse(p.as_slice())
    } else {
        p.into_inner()
    };
    let op = layout.operator(g, pulse)?;
    let mut x = vec![T::zero(); g.voxels()];
    op.apply_adjoint(&y, &mut x);
    let xt = Scene::from_vec(g, x).map_err(|e| {
        format!(
            "{}: the backprojection overflows {}: {e}",
            out.display(),
            T::NAME
        )
    })?;
    io::write_scene(out, &xt)?;
    println!(
        "wrote {}: {}backprojection ({}, {}, {depth_bins}) {}{}",
        out.display(),
        if debiased { "debiased " } else { "" },
        g.m,
        g.n,
        npy_dtype::<T>(),
        layout.note()
    );
    Ok(())
}

/// Sampling period the depth figures assume: τ = 200 ps, a bin of 3 cm.
const TAU_S: f64 = 200e-12;

fn reconstruct_cmd<T: Real + WritableElement>(a: &ReconstructArgs) -> CliResult {
    let p = io::read_pulse::<T>(&a.pulse)?;
    let kp = p.len();
    if kp.checked_add(a.depth_bins).is_none() {
        return Err(format!("--depth-bins {} is too large", a.depth_bins).into());
    }
    let expect = ShapeExpectation {
        pulse_len: kp,
        depth_bins: a.depth_bins,
        grid: None,
    };
    let y = io::read_measurements::<T>(&a.meas, Some(&expect))?;
    let h = io::read_header(&a.codes)?;
    if h.shape.len() == 4 {
        return Err(format!(
            "{}: codes of shape {} are {} code sets; reconstruct needs one code set (M, N, K)",
            a.codes.display(),
            io::shape_text(&h.shape),
            h.shape[0]
        )
        .into());
    }
    let ((m, n), codes) = io::read_codes(&a.codes, &expect)?;
    let g = Geometry::new(m, n, a.depth_bins).map_err(|e| format!("--depth-bins: {e}"))?;
    let truth = match &a.truth {
        Some(path) => {
            let t = io::read_scene::<T>(path)?;
            if t.geometry() != g {
                return Err(format!(
                    "{}: the true scene is {}, but the codes and --depth-bins give {g}",
                    path.display(),
                    t.geometry()
                )
                .into());
            }
            Some(t)
        }
        None => None,
    };
    let op = RdOperator::new(g, p.into_inner(), Arc::new(codes))?;
    let options = ReconstructOptions {
        max_iter: a.max_iter,
        progress: !a.quiet,
        seed: a.seed,
        power_iterations: None,
    };
    let r = reconstruct(&op, &y, a.solver, &options)?;
    let metrics = match &truth {
        Some(t) => Some(compare(t, &r.scene, TAU_S)?),
        None => None,
    };
    // Stage every output, then rename them into place together; on an error the staged files
    // are dropped, which removes them.
    let mut staged: Vec<StagedFile> = vec![
        io::stage_array(&a.out_depth, &r.depth.depth)?,
        io::stage_array(&a.out_scene, r.scene.data())?,
    ];
    if let Some(png) = &a.png {
        let bin_m = depth_bin_m(TAU_S)?;
        let options = rdlidar::plot::DepthOptions::new(bin_m, "m")
            .title(format!("{} ({})", r.method_used, g));
        let truth_depth = truth.as_ref().map(|t| t.depth_map().depth);
        let panels: Vec<(&str, &ndarray::Array2<i32>)> = match &truth_depth {
            Some(d) => vec![("truth", d), ("estimate", &r.depth.depth)],
            None => vec![("estimate", &r.depth.depth)],
        };
        let fig = rdlidar::plot::depth_panels(&panels, &options)
            .map_err(|e| format!("{}: {e}", png.display()))?;
        staged.push(io::stage_bytes(png, &fig.encode_png())?);
    }
    let written = io::commit_all(staged)?;

    let chosen = if a.solver == Method::Auto {
        format!(
            "{} (auto: {} regime, K_p {kp}, critical K_p {})",
            r.method_used,
            r.regime,
            g.critical_pulse_len()
        )
    } else {
        format!("{} ({} regime)", r.method_used, r.regime)
    };
    let iterations = match &r.report {
        Some(rep) => format!(
            "{} iterations, termination {:?}, {} forward and {} adjoint applications",
            rep.iterations, rep.termination, rep.forward_applies, rep.adjoint_applies
        ),
        None => "one adjoint application".to_string(),
    };
    let files: Vec<String> = written.iter().map(|f| f.display().to_string()).collect();
    println!(
        "reconstruct {g} from K = {}: solver {chosen}; {iterations}; {:.3} s; {} of {} pixels \
         with a return; wrote {} (depth int32, scene {}).",
        y.len(),
        r.elapsed.as_secs_f64(),
        r.depth.lit(),
        g.pixels(),
        files.join(", "),
        npy_dtype::<T>()
    );
    if let Some(m) = metrics {
        println!("versus the truth: {m}");
    }
    Ok(())
}

/// Refuses outputs of `reconstruct` that name the same file.
fn check_distinct_outputs(a: &ReconstructArgs) -> CliResult {
    let mut outs: Vec<(&str, &Path)> = vec![
        ("--out-depth", a.out_depth.as_path()),
        ("--out-scene", a.out_scene.as_path()),
    ];
    if let Some(png) = &a.png {
        outs.push(("--png", png.as_path()));
    }
    for (i, (fa, pa)) in outs.iter().enumerate() {
        for (fb, pb) in &outs[i + 1..] {
            if pa == pb {
                return Err(format!("{}: given to both {fa} and {fb}", pa.display()).into());
            }
        }
    }
    Ok(())
}

fn dottest(
    pulse: &Path,
    codes: &Path,
    depth_bins: usize,
    seed: u64,
    tile: Option<Tile>,
) -> CliResult<bool> {
    let p = io::read_pulse::<f64>(pulse)?;
    if p.len().checked_add(depth_bins).is_none() {
        return Err(format!("--depth-bins {depth_bins} is too large").into());
    }
    let expect = ShapeExpectation {
        pulse_len: p.len(),
        depth_bins,
        grid: None,
    };
    let (kind, _) = layout_kind(codes, tile)?;
    let (g, layout) = read_layout(codes, kind, &expect, depth_bins)?;
    let p64 = p.as_slice().to_vec();
    let p32: Vec<f32> = p.as_slice().iter().map(|&v| v as f32).collect();
    let test = DotTest::new().seed(seed);
    let rows = [
        (
            "pulse as given",
            test.measure(&layout.operator(g, p32.clone())?),
            test.measure(&layout.operator(g, p64.clone())?),
        ),
        (
            "zero-mean pulse",
            test.measure(&layout.operator(g, zero_mean_pulse(&p32))?),
            test.measure(&layout.operator(g, zero_mean_pulse(&p64))?),
        ),
    ];
    println!(
        "dot test |<Ax,y> - <x,A*y>| / max(|Ax||y|, |x||A*y|): {g}, K_p {}, K {}, {} \
         codes{}, seed {seed}",
        p.len(),
        expect.samples(),
        layout.alphabet(),
        layout.note()
    );
    println!(
        "{:<16} {:<9} {:>10} {:>10}",
        "pulse", "precision", "gap", "tolerance"
    );
    let mut failed = Vec::new();
    for (name, r32, r64) in rows {
        for (prec, r) in [("f32", r32), ("f64", r64)] {
            let flag = if r.passed() { "ok" } else { "FAILED" };
            println!(
                "{name:<16} {prec:<9} {:>10.2e} {:>10.0e}  {flag}",
                r.gap, r.tolerance
            );
            if !r.passed() {
                failed.push(format!(
                    "{name} in {prec}: gap {:.2e} above tolerance {:.0e}",
                    r.gap, r.tolerance
                ));
            }
        }
    }
    if failed.is_empty() {
        Ok(true)
    } else {
        eprintln!("error: dot test failed: {}", failed.join("; "));
        Ok(false)
    }
}

/// Median and minimum wall time of one operation, in seconds.
#[derive(Debug, Clone, Copy, Serialize)]
struct Timing {
    median_s: f64,
    min_s: f64,
}

/// Runs `f` once as a warm-up, then `repeats` timed times.
fn time_runs(repeats: usize, mut f: impl FnMut()) -> Timing {
    f();
    let mut t: Vec<f64> = (0..repeats)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    let mid = t.len() / 2;
    let median_s = if t.len() % 2 == 1 {
        t[mid]
    } else {
        0.5 * (t[mid - 1] + t[mid])
    };
    Timing {
        median_s,
        min_s: t[0],
    }
}

/// The JSON form of `bench`.
#[derive(Debug, Serialize)]
struct BenchReport {
    forward: Timing,
    adjoint: Timing,
    sparse_forward: Timing,
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
}

fn bench<T: Real>(g: Geometry, kp: usize, repeats: usize, seed: u64, json: bool) -> CliResult {
    let k = kp
        .checked_add(g.ks - 1)
        .ok_or_else(|| format!("--pulse-len {kp} is too large"))?;
    let scene = paper_scene::<T>(g).map_err(|e| format!("--size: {e}"))?;
    let pulse = Pulse::<T>::bernoulli(kp, seed).map_err(|e| format!("--pulse-len: {e}"))?;
    let codes = Codes::random_binary(g.pixels(), k, seed.wrapping_add(1))?;
    let op = RdOperator::new(g, pulse.into_inner(), Arc::new(codes))?;
    let x = scene.as_slice();
    let mut y = vec![T::zero(); k];
    op.apply(x, &mut y);
    let y_in = y.clone();
    let mut xt = vec![T::zero(); g.voxels()];

    let forward = time_runs(repeats, || {
        op.apply_dense(std::hint::black_box(x), &mut y);
        std::hint::black_box(&y);
    });
    let adjoint = time_runs(repeats, || {
        op.apply_adjoint(std::hint::black_box(&y_in), &mut xt);
        std::hint::black_box(&xt);
    });
    let sparse_forward = time_runs(repeats, || {
        op.apply_sparse(std::hint::black_box(x), &mut y);
        std::hint::black_box(&y);
    });

    let report = BenchReport {
        forward,
        adjoint,
        sparse_forward,
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
    };
    if json {
        let text = serde_json::to_string(&report)
            .map_err(|e| format!("cannot format the report as JSON: {e}"))?;
        println!("{text}");
        return Ok(());
    }
    // The equivalent dense matrix product costs 2·M·N·K·K_s flops (DESIGN.md §5).
    let flops = 2.0 * g.pixels() as f64 * k as f64 * g.ks as f64;
    println!(
        "rdlidar bench: paper scene {g} ({} nonzero voxels), K_p {kp}, K {k}, {}, binary codes",
        report.nonzeros,
        T::NAME
    );
    println!(
        "threads {}, kernels {}, operator memory {:.1} MB ({} bytes)",
        report.threads,
        report.isa,
        report.memory_bytes as f64 / 1e6,
        report.memory_bytes
    );
    println!("one warm-up run, then {repeats} timed runs per operation");
    println!(
        "{:<16} {:>12} {:>12} {:>22}",
        "operation", "median (s)", "min (s)", "GEMM-equiv. GFLOP/s"
    );
    for (name, t, dense) in [
        ("forward", forward, true),
        ("adjoint", adjoint, true),
        ("sparse forward", sparse_forward, false),
    ] {
        let rate = if dense && t.median_s > 0.0 {
            format!("{:.1}", flops / t.median_s / 1e9)
        } else {
            "-".to_string()
        };
        println!(
            "{name:<16} {:>12.6} {:>12.6} {rate:>22}",
            t.median_s, t.min_s
        );
    }
    Ok(())
}

/// The files `simulate` writes, in order.
const SIMULATE_FILES: [&str; 5] = [
    "scene.npy",
    "pulse.npy",
    "codes.npy",
    "meas.npy",
    "meta.json",
];

#[derive(Debug, Serialize)]
struct GeometryMeta {
    m: usize,
    n: usize,
    ks: usize,
}

#[derive(Debug, Serialize)]
struct SeedsMeta {
    pulse: u64,
    /// The seed of the first (or only) code set.
    codes: u64,
    /// The seed of every code set, in order (one per ADC with --adcs).
    code_sets: Vec<u64>,
    noise: u64,
    scene: Option<u64>,
    /// The seed of the coded aperture's pixel selection.
    aperture: Option<u64>,
}

/// The "architecture" entry of `meta.json`.
#[derive(Debug, Serialize)]
struct ArchitectureMeta {
    /// "single", "multi_adc", "tiles" or "aperture".
    kind: &'static str,
    /// Number of ADCs: the rows of meas.npy when it is two-dimensional.
    adcs: usize,
    /// Tile size [A, B] of `--tiles AxB`.
    tile: Option<[usize; 2]>,
    /// Pixels that reach an ADC.
    active_pixels: usize,
    /// The fraction given to `--aperture`.
    aperture_fraction: Option<f64>,
}

#[derive(Debug, Serialize)]
struct SceneMeta {
    kind: &'static str,
    lit_fraction: Option<f64>,
    returns_per_pixel: Option<[usize; 2]>,
    nonzeros: usize,
    lit_pixels: usize,
}

#[derive(Debug, Serialize)]
struct NoiseMeta {
    model: &'static str,
    snr_db: Option<f64>,
    sigma: Option<f64>,
    achieved_snr_db: Option<f64>,
    seed: Option<u64>,
}

#[derive(Debug, Serialize)]
struct FilesMeta {
    scene: &'static str,
    pulse: &'static str,
    codes: &'static str,
    meas: &'static str,
}

/// The contents of `meta.json`.
#[derive(Debug, Serialize)]
struct Meta {
    #[serde(rename = "crate")]
    crate_name: &'static str,
    crate_version: &'static str,
    prng: &'static str,
    precision: &'static str,
    geometry: GeometryMeta,
    size: String,
    pulse_len: usize,
    k: usize,
    seed: u64,
    seeds: SeedsMeta,
    scene: SceneMeta,
    code_alphabet: &'static str,
    ternary_zero_prob: Option<f64>,
    architecture: ArchitectureMeta,
    regime: String,
    critical_pulse_len: usize,
    noise: NoiseMeta,
    files: FilesMeta,
}

/// The measurement architecture `simulate` produces (the paper's §3).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Architecture {
    /// One ADC summing every pixel.
    Single,
    /// G > 1 ADCs, each with its own code set.
    MultiAdc(usize),
    /// One ADC per tile.
    Tiles(Tile),
    /// One ADC summing a random fraction of the pixels.
    Aperture(f64),
}

/// Checks the flags of `simulate` that the generators would otherwise reject later, by name, and
/// returns the architecture they select.
fn check_simulate_flags(a: &SimulateArgs) -> CliResult<Architecture> {
    if let Some(f) = a.lit_fraction {
        if a.scene != SceneKind::Random {
            return Err(format!(
                "--lit-fraction applies only to --scene random, not --scene {}",
                a.scene.name()
            )
            .into());
        }
        if !(0.0..=1.0).contains(&f) {
            return Err(format!("--lit-fraction: must be in [0, 1], got {f}").into());
        }
    }
    if let Some(p) = a.ternary_zero_prob {
        if !(0.0..1.0).contains(&p) {
            return Err(format!("--ternary-zero-prob: must be in [0, 1), got {p}").into());
        }
    }
    if let Some(s) = a.snr_db {
        if !s.is_finite() {
            return Err(format!("--snr-db: must be finite, got {s}").into());
        }
    }
    if let Some(f) = a.aperture {
        if !(f > 0.0 && f <= 1.0) {
            return Err(format!("--aperture: must be in (0, 1], got {f}").into());
        }
    }
    let mut chosen = Vec::new();
    if a.adcs > 1 {
        chosen.push(format!("--adcs {}", a.adcs));
    }
    if let Some(t) = a.tiles {
        chosen.push(format!("--tiles {t}"));
    }
    if let Some(f) = a.aperture {
        chosen.push(format!("--aperture {f}"));
    }
    if let [first @ .., last] = &chosen[..] {
        if !first.is_empty() {
            return Err(format!(
                "{} and {last} are not supported together: choose one architecture",
                first.join(", ")
            )
            .into());
        }
    }
    let arch = match (a.adcs, a.tiles, a.aperture) {
        (_, Some(t), _) => Architecture::Tiles(t),
        (_, _, Some(f)) => Architecture::Aperture(f),
        (1, _, _) => Architecture::Single,
        (n, _, _) => Architecture::MultiAdc(n),
    };
    let out = &a.out;
    if out.exists() {
        if !out.is_dir() {
            return Err(format!("{}: exists and is not a directory", out.display()).into());
        }
        let mut entries = std::fs::read_dir(out)
            .map_err(|e| format!("{}: cannot read the directory: {e}", out.display()))?;
        if entries.next().is_some() && !a.force {
            return Err(format!(
                "{}: directory is not empty; use --force to replace its {}",
                out.display(),
                SIMULATE_FILES.join(", ")
            )
            .into());
        }
    } else {
        let parent = parent_dir(out);
        if !parent.is_dir() {
            return Err(format!(
                "{}: parent directory {} does not exist",
                out.display(),
                parent.display()
            )
            .into());
        }
    }
    Ok(arch)
}

/// Code set `set` of `--adcs` is drawn from this seed (set 0 from SEED+1).
fn code_seed(seed: u64, set: usize) -> u64 {
    seed.wrapping_add(1)
        .wrapping_add(1000u64.wrapping_mul(set as u64))
}

/// An integer in [0, n), n ≥ 1, uniformly (rejection of the incomplete last block).
fn below(rng: &mut ChaCha8Rng, n: u64) -> u64 {
    // 2^64 mod n: the values at or above 2^64 − r would favour the first r results.
    let r = (u64::MAX % n + 1) % n;
    loop {
        let v = rng.next_u64();
        if r == 0 || v <= u64::MAX - r {
            return v % n;
        }
    }
}

/// The active pixels of a coded aperture: ⌈fraction·pixels⌉ distinct pixels (at least one; a
/// product within 1e-9 of an integer counts as that integer), drawn by a partial Fisher–Yates
/// shuffle of 0 … pixels−1 on a ChaCha8 stream seeded with `seed`, in increasing order.
fn aperture_pixels(pixels: usize, fraction: f64, seed: u64) -> Vec<usize> {
    let x = fraction * pixels as f64;
    let count = if (x - x.round()).abs() <= 1e-9 * x.max(1.0) {
        x.round()
    } else {
        x.ceil()
    };
    let count = (count as usize).clamp(1, pixels);
    let mut order: Vec<usize> = (0..pixels).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for i in 0..count {
        let j = i + below(&mut rng, (pixels - i) as u64) as usize;
        order.swap(i, j);
    }
    order.truncate(count);
    order.sort_unstable();
    order
}

/// y = A x for a freshly allocated y.
fn apply_to<T: Real>(op: &impl LinearOperator<T>, x: &[T]) -> Vec<T> {
    let mut y = vec![T::zero(); op.nrows()];
    op.apply(x, &mut y);
    y
}

fn simulate<T: Real + WritableElement>(a: &SimulateArgs, arch: Architecture) -> CliResult {
    let g = a.size;
    let kp = a.pulse_len;
    let k = kp
        .checked_add(g.ks - 1)
        .ok_or_else(|| format!("--pulse-len {kp} is too large"))?;
    let sets = match arch {
        Architecture::MultiAdc(n) => n,
        _ => 1,
    };
    let groups = match arch {
        Architecture::Tiles(t) => Some(tiles(g, t.m, t.n).map_err(|e| format!("--tiles: {e}"))?),
        _ => None,
    };
    // Rows of meas.npy when it is two-dimensional (one per ADC).
    let rows = match arch {
        Architecture::MultiAdc(n) => Some(n),
        Architecture::Tiles(_) => groups.as_ref().map(Vec::len),
        _ => None,
    };
    if let Some(r) = rows {
        let too_large = r
            .checked_mul(k)
            .and_then(|v| v.checked_mul(g.pixels()))
            .is_none();
        if too_large {
            let flag = match arch {
                Architecture::Tiles(t) => format!("--tiles {t}"),
                _ => format!("--adcs {r}"),
            };
            return Err(format!("{flag}: {r} ADCs of {k} samples are too many").into());
        }
    }
    let seeds = SeedsMeta {
        pulse: a.seed,
        codes: code_seed(a.seed, 0),
        code_sets: (0..sets).map(|i| code_seed(a.seed, i)).collect(),
        noise: a.seed.wrapping_add(2),
        scene: match a.scene {
            SceneKind::Paper => None,
            _ => Some(a.seed.wrapping_add(3)),
        },
        aperture: matches!(arch, Architecture::Aperture(_)).then(|| a.seed.wrapping_add(4)),
    };
    let scene_seed = a.seed.wrapping_add(3);
    let lit_fraction = (a.scene == SceneKind::Random).then(|| a.lit_fraction.unwrap_or(0.5));
    let returns = (a.scene == SceneKind::Transparent).then(|| [1, 3.min(g.ks)]);
    let scene: Scene<T> = match a.scene {
        SceneKind::Paper => paper_scene(g),
        SceneKind::Random => random_opaque_scene(g, lit_fraction.unwrap_or(0.5), scene_seed),
        SceneKind::Transparent => semi_transparent_scene(g, 1..=3.min(g.ks), scene_seed),
    }
    .map_err(|e| format!("--scene {}: {e}", a.scene.name()))?;
    let pulse = Pulse::<T>::bernoulli(kp, seeds.pulse).map_err(|e| format!("--pulse-len: {e}"))?;
    let code_sets = seeds
        .code_sets
        .iter()
        .map(|&seed| {
            match a.ternary_zero_prob {
                None => Codes::random_binary(g.pixels(), k, seed),
                Some(p) => Codes::random_ternary(g.pixels(), k, p, seed),
            }
            .map(Arc::new)
        })
        .collect::<rdlidar::Result<Vec<_>>>()?;
    let codes = code_sets[0].clone();
    let active = match arch {
        Architecture::Aperture(f) => Some(aperture_pixels(
            g.pixels(),
            f,
            seeds.aperture.unwrap_or_default(),
        )),
        _ => None,
    };
    let x = scene.as_slice();
    let mut y = match (arch, &groups, &active) {
        (Architecture::MultiAdc(_), _, _) => {
            apply_to(&multi_adc(g, pulse.as_slice(), code_sets.clone())?, x)
        }
        (Architecture::Tiles(_), Some(groups), _) => {
            apply_to(&pixel_groups(g, pulse.as_slice(), &codes, groups)?, x)
        }
        (Architecture::Aperture(_), _, Some(active)) => {
            apply_to(&coded_aperture(g, pulse.as_slice(), &codes, active)?, x)
        }
        _ => {
            let op = RdOperator::new(g, pulse.as_slice().to_vec(), codes.clone())?;
            let mut y = vec![T::zero(); k];
            op.apply(x, &mut y);
            y
        }
    };
    let noise = match a.snr_db {
        None => NoiseMeta {
            model: "none",
            snr_db: None,
            sigma: None,
            achieved_snr_db: None,
            seed: None,
        },
        Some(snr_db) => {
            let report = NoiseModel::none()
                .then(NoiseStage::Gaussian { snr_db })
                .apply(&mut y, seeds.noise)
                .map_err(|e| format!("--snr-db: {e}"))?;
            let sigma = report.stages.iter().find_map(|s| match s {
                StageReport::Gaussian { sigma } => Some(*sigma),
                _ => None,
            });
            NoiseMeta {
                model: "gaussian",
                snr_db: Some(snr_db),
                sigma,
                achieved_snr_db: Some(report.snr_db()).filter(|v| v.is_finite()),
                seed: Some(seeds.noise),
            }
        }
    };
    let lit_pixels = scene
        .data()
        .lanes(ndarray::Axis(2))
        .into_iter()
        .filter(|c| c.iter().any(|v| *v != T::zero()))
        .count();
    let alphabet = match codes.alphabet() {
        CodeAlphabet::Binary => "binary",
        CodeAlphabet::Ternary => "ternary",
    };
    let architecture = ArchitectureMeta {
        kind: match arch {
            Architecture::Single => "single",
            Architecture::MultiAdc(_) => "multi_adc",
            Architecture::Tiles(_) => "tiles",
            Architecture::Aperture(_) => "aperture",
        },
        adcs: rows.unwrap_or(1),
        tile: match arch {
            Architecture::Tiles(t) => Some([t.m, t.n]),
            _ => None,
        },
        active_pixels: active.as_ref().map_or(g.pixels(), Vec::len),
        aperture_fraction: match arch {
            Architecture::Aperture(f) => Some(f),
            _ => None,
        },
    };
    let arch_note = match arch {
        Architecture::Single => None,
        Architecture::MultiAdc(n) => Some(format!(
            "{n} ADCs, one code set each (code seeds {})",
            seeds
                .code_sets
                .iter()
                .map(u64::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        )),
        Architecture::Tiles(t) => Some(format!(
            "tiles of {t} pixels, {} ADCs (one per tile)",
            architecture.adcs
        )),
        Architecture::Aperture(f) => Some(format!(
            "coded aperture, {} of {} pixels active (fraction {f}, seed {})",
            architecture.active_pixels,
            g.pixels(),
            a.seed.wrapping_add(4)
        )),
    };
    let meta = Meta {
        crate_name: env!("CARGO_PKG_NAME"),
        crate_version: env!("CARGO_PKG_VERSION"),
        prng: "ChaCha8",
        precision: T::NAME,
        geometry: GeometryMeta {
            m: g.m,
            n: g.n,
            ks: g.ks,
        },
        size: g.to_string(),
        pulse_len: kp,
        k,
        seed: a.seed,
        seeds,
        scene: SceneMeta {
            kind: a.scene.name(),
            lit_fraction,
            returns_per_pixel: returns,
            nonzeros: scene.nnz(),
            lit_pixels,
        },
        code_alphabet: alphabet,
        ternary_zero_prob: a.ternary_zero_prob,
        architecture,
        regime: g.regime(kp).to_string(),
        critical_pulse_len: g.critical_pulse_len(),
        noise,
        files: FilesMeta {
            scene: SIMULATE_FILES[0],
            pulse: SIMULATE_FILES[1],
            codes: SIMULATE_FILES[2],
            meas: SIMULATE_FILES[3],
        },
    };
    let mut json =
        serde_json::to_string_pretty(&meta).map_err(|e| format!("cannot format meta.json: {e}"))?;
    json.push('\n');
    let meas_shape = match rows {
        None => vec![k],
        Some(r) => vec![r, k],
    };
    let meas = ndarray::ArrayView::from_shape(ndarray::IxDyn(&meas_shape), &y[..])
        .map_err(|e| format!("cannot shape the measurements: {e}"))?;
    let codes_shape = match arch {
        Architecture::MultiAdc(n) => vec![n, g.m, g.n, k],
        _ => vec![g.m, g.n, k],
    };

    let dir = &a.out;
    let created = !dir.exists();
    if created {
        std::fs::create_dir(dir)
            .map_err(|e| format!("{}: cannot create the directory: {e}", dir.display()))?;
    }
    let written = (|| -> rdlidar::Result<Vec<PathBuf>> {
        let [f_scene, f_pulse, f_codes, f_meas, f_meta] = SIMULATE_FILES.map(|f| dir.join(f));
        let grid = (g.m, g.n);
        // Each file is complete and synced before the first one is renamed into place; on an
        // error the staged files are dropped, which removes them.
        let staged: Vec<StagedFile> = vec![
            io::stage_array(f_scene, scene.data())?,
            io::stage_array(f_pulse, &ndarray::ArrayView1::from(pulse.as_slice()))?,
            match (arch, &active) {
                (Architecture::MultiAdc(_), _) => io::stage_code_sets(f_codes, grid, &code_sets)?,
                (_, Some(active)) => io::stage_masked_codes(f_codes, grid, &codes, active)?,
                _ => io::stage_codes(f_codes, grid, &codes)?,
            },
            io::stage_array(f_meas, &meas)?,
            io::stage_bytes(f_meta, json.as_bytes())?,
        ];
        io::commit_all(staged)
    })();
    if let Err(e) = written {
        if created {
            for f in SIMULATE_FILES {
                let _ = std::fs::remove_file(dir.join(f));
            }
            let _ = std::fs::remove_dir(dir);
        }
        return Err(e.into());
    }
    let dt = npy_dtype::<T>();
    println!(
        "wrote {}: scene.npy ({}, {}, {}) {dt}, pulse.npy ({kp},) {dt}, codes.npy {} int8, \
         meas.npy {} {dt}, meta.json",
        dir.display(),
        g.m,
        g.n,
        g.ks,
        io::shape_text(&codes_shape),
        io::shape_text(&meas_shape),
    );
    println!(
        "{} scene, {lit_pixels} lit pixels; {alphabet} codes; {} regime (critical K_p = {}); {}",
        a.scene.name(),
        g.regime(kp),
        g.critical_pulse_len(),
        match a.snr_db {
            Some(s) => format!("Gaussian noise at {s} dB SNR"),
            None => "noise-free".to_string(),
        }
    );
    if let Some(note) = arch_note {
        println!("architecture: {note}");
    }
    Ok(())
}

fn set_threads(threads: Option<usize>, source: &str) -> CliResult {
    if let Some(n) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| format!("{source} {n}: {e}"))?;
    }
    Ok(())
}

fn run(cli: Cli) -> CliResult<ExitCode> {
    let globals = Globals {
        threads: cli.threads,
        seed: cli.seed,
        precision: cli.precision,
        quiet: cli.quiet,
    };
    let Some(command) = cli.command else {
        return experiment_cmd(Experiment::Demo, &cli.demo, false, &globals);
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
    let (seed, precision, quiet) = (cli.seed.unwrap_or(0), cli.precision, cli.quiet);
    let ok = |b: bool| {
        if b {
            ExitCode::SUCCESS
        } else {
            ExitCode::FAILURE
        }
    };
    match command {
        Command::Demo(a) => experiment_cmd(Experiment::Demo, &a, false, &globals),
        Command::Compare(a) => experiment_cmd(Experiment::Compare, &a.common, a.quick, &globals),
        Command::Selfcheck => {
            let passed = selfcheck(seed)?;
            if !passed {
                eprintln!("error: some operators failed the dot test");
            }
            Ok(ok(passed))
        }
        Command::Simulate(mut a) => {
            a.seed = seed;
            a.precision = precision.unwrap_or(Precision::F64);
            let arch = check_simulate_flags(&a)?;
            match a.precision {
                Precision::F32 => simulate::<f32>(&a, arch)?,
                Precision::F64 => simulate::<f64>(&a, arch)?,
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Forward {
            pulse,
            codes,
            scene,
            out,
            tiles,
        } => {
            check_out_file(&out)?;
            let precision = match precision {
                Some(p) => p,
                None => auto_precision(&[&scene, &pulse])?,
            };
            match precision {
                Precision::F32 => forward::<f32>(&pulse, &codes, &scene, &out, tiles)?,
                Precision::F64 => forward::<f64>(&pulse, &codes, &scene, &out, tiles)?,
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Adjoint {
            pulse,
            codes,
            meas,
            depth_bins,
            out,
            debiased,
            tiles,
        } => {
            check_out_file(&out)?;
            let precision = match precision {
                Some(p) => p,
                None => auto_precision(&[&meas, &pulse])?,
            };
            let files = AdjointFiles {
                pulse: &pulse,
                codes: &codes,
                meas: &meas,
                out: &out,
            };
            match precision {
                Precision::F32 => adjoint::<f32>(&files, depth_bins, debiased, tiles)?,
                Precision::F64 => adjoint::<f64>(&files, depth_bins, debiased, tiles)?,
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Dottest {
            pulse,
            codes,
            depth_bins,
            tiles,
        } => Ok(ok(dottest(&pulse, &codes, depth_bins, seed, tiles)?)),
        Command::Reconstruct(mut a) => {
            a.seed = seed;
            a.precision = precision;
            a.quiet = quiet;
            check_out_file(&a.out_depth)?;
            check_out_file(&a.out_scene)?;
            if let Some(png) = &a.png {
                check_out_file(png)?;
            }
            check_distinct_outputs(&a)?;
            let precision = match a.precision {
                Some(p) => p,
                None => auto_precision(&[&a.meas, &a.pulse])?,
            };
            match precision {
                Precision::F32 => reconstruct_cmd::<f32>(&a)?,
                Precision::F64 => reconstruct_cmd::<f64>(&a)?,
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Info(a) => {
            cli_info::run(&a)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench {
            size,
            pulse_len,
            json,
            repeats,
        } => {
            match precision.unwrap_or(Precision::F32) {
                Precision::F32 => bench::<f32>(size, pulse_len, repeats, seed, json)?,
                Precision::F64 => bench::<f64>(size, pulse_len, repeats, seed, json)?,
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// The global flags.
#[derive(Debug, Clone, Copy)]
struct Globals {
    threads: Option<usize>,
    seed: Option<u64>,
    precision: Option<Precision>,
    quiet: bool,
}

/// The two experiments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Experiment {
    Demo,
    Compare,
}

impl Experiment {
    fn name(self) -> &'static str {
        match self {
            Experiment::Demo => "demo",
            Experiment::Compare => "compare",
        }
    }
}

/// Set by the first Ctrl-C: the experiment stops after the run under way.
static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// The flag an experiment setting (a configuration key) is given with on the command line.
fn flag_of(key: &str) -> String {
    format!("--{}", key.replace('_', "-"))
}

/// Resolves an experiment's configuration: the preset (--tiny, --quick or the default), the
/// config file's section and top-level keys over it, the flags over both.
fn experiment_config(
    which: Experiment,
    a: &ExperimentArgs,
    quick: bool,
    globals: &Globals,
) -> CliResult<(ExperimentConfig, Option<usize>, bool)> {
    let mut config = match (which, a.tiny, quick) {
        (Experiment::Demo, true, _) => ExperimentConfig::demo_tiny(),
        (Experiment::Demo, false, _) => ExperimentConfig::demo(),
        (Experiment::Compare, true, _) => ExperimentConfig::compare_tiny(),
        (Experiment::Compare, false, true) => ExperimentConfig::compare_quick(),
        (Experiment::Compare, false, false) => ExperimentConfig::compare(),
    };
    let file = match &a.config {
        Some(path) => ConfigFile::load(path)?,
        None => ConfigFile::default(),
    };
    let section = match which {
        Experiment::Demo => &file.demo,
        Experiment::Compare => &file.compare,
    };
    if let Some(patch) = section {
        config = config.patched(patch);
    }
    let flags = ExperimentPatch {
        out: a.out.clone(),
        scene: a.scene.map(|s| s.0),
        size: a.size,
        lit_fraction: a.lit_fraction,
        pulse_lens: a.pulse_lens.as_ref().map(|v| v.0.clone()),
        solvers: a.solvers.as_ref().map(|v| v.0.clone()),
        snr_db: a.snr_db.as_ref().map(|v| v.0.clone()),
        seeds: a.seeds,
        max_iter: a.max_iter,
        power_iterations: a.power_iterations,
    };
    config = config.patched(&flags);
    config.seed = globals.seed.or(file.seed).unwrap_or(config.seed);
    config.precision = match globals.precision {
        Some(Precision::F32) => experiment::Precision::F32,
        Some(Precision::F64) => experiment::Precision::F64,
        None => file.precision.unwrap_or(config.precision),
    };
    if let Err(e) = config.validate() {
        let msg = match e {
            rdlidar::Error::InvalidParameter { name, reason } => {
                let place = match &a.config {
                    Some(path) => format!(" (or `{name}` in {})", path.display()),
                    None => String::new(),
                };
                format!("{}{place}: {reason}", flag_of(name))
            }
            other => other.to_string(),
        };
        return Err(msg.into());
    }
    let threads = globals.threads.or(file.threads);
    let quiet = globals.quiet || file.quiet.unwrap_or(false);
    Ok((config, threads, quiet))
}

/// Refuses an existing non-empty output folder without --force, before any work.
fn check_experiment_out(dir: &Path, force: bool) -> CliResult {
    if dir.exists() {
        if !dir.is_dir() {
            return Err(format!("{}: exists and is not a folder (--out)", dir.display()).into());
        }
        let mut entries = std::fs::read_dir(dir)
            .map_err(|e| format!("{}: cannot read the folder: {e}", dir.display()))?;
        if entries.next().is_some() && !force {
            return Err(format!(
                "{}: the output folder exists and is not empty; pass --force to overwrite the \
                 results in it, or --out DIR to write elsewhere",
                dir.display()
            )
            .into());
        }
    } else {
        let parent = parent_dir(dir);
        if !parent.is_dir() {
            return Err(format!(
                "{}: the parent folder {} does not exist (--out)",
                dir.display(),
                parent.display()
            )
            .into());
        }
    }
    Ok(())
}

/// `demo` (also the command with no subcommand) and `compare`.
fn experiment_cmd(
    which: Experiment,
    a: &ExperimentArgs,
    quick: bool,
    globals: &Globals,
) -> CliResult<ExitCode> {
    let (config, threads, quiet) = experiment_config(which, a, quick, globals)?;
    check_experiment_out(&config.out, a.force)?;
    set_threads(threads, "threads")?;
    let out = config.out.display().to_string();
    ctrlc::set_handler(move || {
        if STOP.swap(true, std::sync::atomic::Ordering::SeqCst) {
            eprintln!(
                "\ninterrupted again: quitting; finished rows are in {out}/results.csv.partial"
            );
            std::process::exit(130);
        }
        eprintln!("\nCtrl-C: stopping after the current run (Ctrl-C again to quit at once)");
    })
    .map_err(|e| format!("cannot handle Ctrl-C: {e}"))?;

    let kps: Vec<String> = config.pulse_lens.iter().map(usize::to_string).collect();
    let levels: Vec<String> = config
        .snr_db
        .iter()
        .map(|l| experiment::noise_text(*l))
        .collect();
    println!(
        "rdlidar {}: {} scene {} (critical K_p {}), K_p {}, {}, {} seed(s) from {}, {}, {} \
         threads; {} runs",
        which.name(),
        config.scene.name(),
        config.size,
        config.size.critical_pulse_len(),
        kps.join(", "),
        levels.join(", "),
        config.seeds,
        config.seed,
        config.precision,
        rayon::current_num_threads(),
        config.runs()
    );
    println!(
        "iteration budgets: {}; FISTA step from {} power iterations",
        config.max_iter,
        config
            .power_iterations
            .map_or_else(|| "up to 200".to_string(), |n| n.to_string())
    );
    let mut console = Console::new(quiet);
    let outcome = match which {
        Experiment::Demo => experiment::run_demo(&config, a.force, &mut console, &STOP),
        Experiment::Compare => experiment::run_compare(&config, a.force, &mut console, &STOP),
    };
    console.finish();
    let outcome = outcome?;
    let names: Vec<String> = outcome
        .files
        .iter()
        .map(|f| {
            f.file_name()
                .map_or_else(|| f.display().to_string(), |n| n.to_string_lossy().into())
        })
        .collect();
    let failed = outcome.rows.iter().filter(|r| r.error.is_some()).count();
    println!(
        "{} of {} runs finished{} in {:.1} s (total {:.1} s with tables and figures); wrote {}: {}",
        outcome.rows.len(),
        outcome.planned,
        if failed > 0 {
            format!(" ({failed} with a solver error)")
        } else {
            String::new()
        },
        outcome.elapsed.as_secs_f64(),
        outcome.total.as_secs_f64(),
        config.out.display(),
        names.join(", ")
    );
    if outcome.interrupted {
        eprintln!(
            "interrupted: the tables and figures hold the {} finished runs",
            outcome.rows.len()
        );
        return Ok(ExitCode::from(130));
    }
    Ok(ExitCode::SUCCESS)
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(Failure(msg)) => {
            eprintln!("error: {msg}");
            ExitCode::FAILURE
        }
    }
}
