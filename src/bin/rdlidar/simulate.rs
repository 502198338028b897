//! `rdlidar simulate`: a scene, a pulse, codes and measurements written to a folder.

use std::path::PathBuf;

use clap::ValueEnum;
use ndarray_npy::WritableElement;
use rdlidar::acquisition::{
    check_simulation_dir, codes_shape, write_simulation, CodesFormat as LibCodesFormat,
    SimulationRequest,
};
use rdlidar::io;
use rdlidar::io::meta::SimulationMeta;
use rdlidar::lidar::{
    simulate, simulate_split, simulate_split_supplied, simulate_supplied, Geometry, Response,
    SimulationSpec, TileSize, SEEDED_CODES_GENERATOR,
};
use rdlidar::settings::FrontEnd;
use rdlidar::units::number;
use rdlidar::Real;

use crate::common::{
    npy_dtype, outln, parse_adcs, parse_pulse_len, parse_size, parse_tile, with_precision,
    CliResult, Globals, Precision,
};
use crate::ranks::Ranks;

/// How `simulate` writes codes.npy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CodesFormat {
    /// int8 (M, N, K) (or (G, M, N, K)), entries −1, 0, +1.
    Int8,
    /// uint8 (M, N, ⌈K/8⌉) (or (G, M, N, ⌈K/8⌉)), eight samples to a byte exactly as
    /// `np.packbits(S > 0, axis=-1)` writes them: ±1 codes only.
    Packed,
    /// No codes file: meta.json describes ±1 codes by their seed and stream
    /// (chacha8-packbits-v1, regenerated pixel by pixel); pass meta.json to --codes.
    Seed,
}

/// The scenes `simulate` generates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SceneKind {
    /// The paper's experiment: a square, a disk and a slanted plane, one return per pixel.
    Paper,
    /// Random opaque scene: each pixel lit with probability --lit-fraction, random depth and
    /// amplitude in [0.2, 1].
    Random,
    /// Semi-transparent scene: 1 to 3 returns per pixel (at most K_s), amplitudes in [0.1, 1].
    Transparent,
    /// An opaque scene read from a PNG depth map (--depth-png) and optionally a reflectivity
    /// map (--reflectivity-png).
    Png,
}

impl SceneKind {
    fn name(self) -> &'static str {
        match self {
            SceneKind::Paper => "paper",
            SceneKind::Random => "random",
            SceneKind::Transparent => "transparent",
            SceneKind::Png => "png",
        }
    }
}

/// Generate a scene, a pulse and codes, and simulate the measurements.
///
/// Writes DIR/scene.npy (M, N, K_s), pulse.npy (K_p,), codes.npy (M, N, K) int8 (with
/// --codes-format packed: uint8 (M, N, ⌈K/8⌉) as `np.packbits(S > 0, axis=-1)` writes them),
/// meas.npy (K,) and meta.json (geometry, K_p, K, seeds, scene kind, code alphabet and format,
/// regime and critical K_p, noise, PRNG, crate version), with K = K_p + K_s − 1.
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
/// an error nothing is left behind, and Ctrl-C or SIGTERM quits at once the same way (exit
/// status 130 or 143). Temporary files that a killed run left in DIR do not make it
/// non-empty, and are removed.
///
/// Example: `rdlidar simulate --scene paper --size 100x100x40 --pulse-len 10000 --seed 0 --out run0`
#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
    /// Scene to generate.
    #[arg(long, value_enum)]
    pub scene: SceneKind,
    /// Scene grid MxNxKS: M×N pixels, K_s depth bins.
    #[arg(long, value_parser = parse_size)]
    pub size: Geometry,
    /// Pulse length K_p (Bernoulli 0/1 samples).
    #[arg(long, value_parser = parse_pulse_len)]
    pub pulse_len: usize,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The depth map of `--scene png`: a PNG (8- or 16-bit; grayscale, or the first channel of
    /// colour) whose value v > 0 is depth bin round(v / full scale · (K_s − 1)) and 0 no return.
    /// Its height and width must be --size's M and N.
    #[arg(long, value_name = "FILE")]
    pub depth_png: Option<PathBuf>,
    /// The reflectivity map of `--scene png` (same size as the depth map): amplitude
    /// v / full scale at each return (default: 1).
    #[arg(long, value_name = "FILE")]
    pub reflectivity_png: Option<PathBuf>,
    /// Fraction of lit pixels of `--scene random`, in [0, 1] (default 0.5).
    #[arg(long, value_name = "F")]
    pub lit_fraction: Option<f64>,
    /// Draw ternary codes in {-1, 0, 1} with P(0) = P, in [0, 1) (default: binary ±1 codes).
    #[arg(long, value_name = "P")]
    pub ternary_zero_prob: Option<f64>,
    /// Add white Gaussian noise at this SNR in dB, relative to the mean power of the
    /// noiseless measurements (default: noise-free).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub snr_db: Option<f64>,
    /// Add photon (shot) noise, drawn before the Gaussian noise: each ADC's sample k gets the
    /// noise of Poisson(P · (light[k] + B)) photon counts, divided by P, light[k] the
    /// unmodulated light of the pixels it sums (finite, > 0).
    #[arg(long, value_name = "P")]
    pub photons: Option<f64>,
    /// The photon noise's background light and dark counts per sample, in units of intensity
    /// (finite, ≥ 0; default 0; only with --photons).
    #[arg(long, value_name = "B")]
    pub background: Option<f64>,
    /// Quantize the measurements with an ADC of B bits (1 … 32), mid-rise levels over
    /// [−F, F], after the noise.
    #[arg(long, value_name = "B")]
    pub adc_bits: Option<u32>,
    /// The ADC's full scale F (finite, > 0; samples beyond ±F are clipped and counted in
    /// meta.json; default: each ADC's largest |sample|, nothing clipped; only with --adc-bits).
    #[arg(long, value_name = "F")]
    pub full_scale: Option<f64>,
    /// Replace scene.npy, pulse.npy, codes.npy, meas.npy and meta.json in a non-empty DIR.
    #[arg(long)]
    pub force: bool,
    /// Number of ADCs G (1 … 4096), each with its own code set for every pixel (G > 1 writes codes.npy
    /// (G, M, N, K) and meas.npy (G, K)).
    #[arg(long, value_name = "G", value_parser = parse_adcs, default_value_t = 1)]
    pub adcs: usize,
    /// Split the array into tiles of AxB pixels with one ADC each (meas.npy (T, K) for T tiles).
    #[arg(long, value_name = "AxB", value_parser = parse_tile)]
    pub tiles: Option<TileSize>,
    /// Coded aperture: only a random fraction F in (0, 1] of the pixels (⌈F·M·N⌉ of them)
    /// reaches the ADC; the others' codes are written as 0.
    #[arg(long, value_name = "F")]
    pub aperture: Option<f64>,
    /// How to write the codes: int8, codes.npy (M, N, K); packed, codes.npy uint8 (M, N, ⌈K/8⌉)
    /// as `np.packbits(S > 0, axis=-1)` writes ±1 codes, 8× smaller (read back with
    /// `np.unpackbits(b, axis=-1, count=K)`); or seed, no codes file at all: meta.json
    /// describes ±1 codes by their seed and a documented stream (chacha8-packbits-v1) that
    /// regenerates them pixel by pixel, and is passed to --codes. Every subcommand that reads
    /// codes takes all three.
    #[arg(long, value_enum, value_name = "FORMAT", default_value_t = CodesFormat::Int8)]
    pub codes_format: CodesFormat,
    /// Where the reflectors lie: on the grid (each in one depth bin), or at continuous depths
    /// (the paper's reflectors, random and semi-transparent scenes and PNG depth maps
    /// unrounded), put on the voxel grid by --kernel (default triangle). With continuous
    /// depths or a kernel other than delta, range.npy holds the true depths: float64 (M, N)
    /// bins, (R, M, N) with several returns per pixel, NaN where there is none.
    #[arg(long, value_enum, value_name = "WHERE", default_value_t = DepthMode::Grid)]
    pub depth: DepthMode,
    /// The system's response g (g(0) = 1) that puts a reflector of amplitude a at depth d
    /// into its voxel column as a·g(k − d): delta (depths on the grid, the default on the
    /// grid), triangle (max(0, 1 − |t|): rectangular chips and an integrating ADC, the
    /// default at continuous depths), gaussian:S (exp(−t²/(2S²)), S in bins), or
    /// measured:O:FILE (a float64 .npy of samples of g, O per bin; its largest sample is
    /// t = 0, scaled to 1).
    #[arg(long, value_name = "SPEC", value_parser = parse_kernel)]
    pub kernel: Option<Response>,
}

/// Where a simulation's reflectors lie.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthMode {
    /// Each reflector in one depth bin.
    Grid,
    /// At continuous depths.
    Continuous,
}

/// A response specification, read (a measured response's file too).
pub fn parse_kernel(text: &str) -> Result<Response, String> {
    rdlidar::io::read_response(text).map_err(|e| match e {
        rdlidar::Error::InvalidParameter { reason, .. } => FrontEnd::CommandLine.words(&reason),
        e => FrontEnd::CommandLine.render(&e),
    })
}

/// The request the flags make.
fn request_of(a: &SimulateArgs, seed: u64) -> SimulationRequest {
    SimulationRequest {
        scene: a.scene.name().into(),
        depth_png: a.depth_png.clone(),
        reflectivity_png: a.reflectivity_png.clone(),
        lit_fraction: a.lit_fraction,
        ternary_zero_prob: a.ternary_zero_prob,
        snr_db: a.snr_db,
        photons: a.photons,
        background: a.background,
        adc_bits: a.adc_bits,
        full_scale: a.full_scale,
        adcs: a.adcs,
        tiles: a.tiles,
        aperture: a.aperture,
        codes_format: a.codes_format.into(),
        continuous: a.depth == DepthMode::Continuous,
        kernel: a.kernel.clone(),
        ..SimulationRequest::new(a.size, a.pulse_len, seed)
    }
}

/// Whether `simulate` with these flags splits the pixel rows over the processes of an MPI job
/// (seeded codes of one ADC or of several code sets), or why not.
pub fn splits(a: &SimulateArgs) -> Result<(), &'static str> {
    match (a.codes_format, a.tiles, a.aperture) {
        (CodesFormat::Seed, None, None) => Ok(()),
        (CodesFormat::Seed, Some(_), _) => Err(" --tiles"),
        (CodesFormat::Seed, _, Some(_)) => Err(" --aperture"),
        _ => Err(" without --codes-format seed"),
    }
}

/// Runs `simulate` (in f64 unless --precision says otherwise).
pub fn run(a: &SimulateArgs, globals: &Globals, ranks: &Ranks) -> CliResult {
    let request = request_of(a, globals.seed());
    let spec = request.spec()?;
    check_simulation_dir(&a.out, a.force)?;
    let precision = globals.precision.unwrap_or(Precision::F64);
    with_precision!(precision, simulate_into(a, &request, &spec, ranks))
}

fn simulate_into<T: Real + WritableElement>(
    a: &SimulateArgs,
    request: &SimulationRequest,
    spec: &SimulationSpec,
    ranks: &Ranks,
) -> CliResult {
    let g = spec.geometry;
    let kp = spec.pulse_len;
    // Under mpirun, each process generates and measures its own rows' codes.
    let sim = request
        .supplied_scene::<T>()
        .and_then(|supplied| match (ranks.space(), supplied) {
            (Some(space), Some(scene)) => simulate_split_supplied::<T>(spec, space, scene),
            (Some(space), None) => simulate_split::<T>(spec, space),
            (None, Some(scene)) => simulate_supplied::<T>(spec, scene),
            (None, None) => simulate::<T>(spec),
        })
        .and_then(|mut sim| {
            request.describe(&mut sim)?;
            Ok(sim)
        })
        .map_err(|e| match e {
            rdlidar::Error::InvalidParameter {
                name: "parts",
                reason,
            } => {
                format!("mpirun -n {}: {reason}", ranks.processes())
            }
            e @ rdlidar::Error::InvalidParameter { .. } => {
                // A full scale beyond the range of f32: the flag that computes in f64.
                let hint = if e.to_string().ends_with("compute in f64") {
                    " (--precision f64)"
                } else {
                    ""
                };
                format!("{}{hint}", FrontEnd::CommandLine.render(&e))
            }
            e @ (rdlidar::Error::TooLarge { .. } | rdlidar::Error::ShapeMismatch { .. }) => {
                FrontEnd::CommandLine.render(&e)
            }
            other => format!(
                "--scene {}: {}",
                a.scene.name(),
                FrontEnd::CommandLine.render(&other)
            ),
        });
    let sim = ranks.agree(sim.map_err(Into::into))?;
    if !ranks.is_first() {
        return Ok(());
    }
    let format: LibCodesFormat = a.codes_format.into();
    let meta = write_simulation(&a.out, &sim, format, a.force)?;
    let dt = npy_dtype::<T>();
    let meas_shape = match sim.rows() {
        None => vec![meta.k],
        Some(r) => vec![r, meta.k],
    };
    let codes_text = match codes_shape(&sim, format) {
        None => format!(
            "codes described by seed {} in meta.json ({SEEDED_CODES_GENERATOR})",
            meta.seeds.codes
        ),
        Some(shape) if format == LibCodesFormat::Packed => {
            format!("codes.npy {} uint8 (packed bits)", io::shape_text(&shape))
        }
        Some(shape) => format!("codes.npy {} int8", io::shape_text(&shape)),
    };
    outln!(
        "wrote {}: scene.npy ({}, {}, {}) {dt}, pulse.npy ({kp},) {dt}, {codes_text}, meas.npy \
         {} {dt}, meta.json",
        a.out.display(),
        g.m,
        g.n,
        g.ks,
        io::shape_text(&meas_shape),
    );
    outln!(
        "{} scene, {} lit pixels; {} codes; {} regime (critical K_p = {}); {}",
        a.scene.name(),
        meta.scene.lit_pixels,
        meta.code_alphabet,
        g.regime(kp),
        g.critical_pulse_len(),
        noise_text(&meta)
    );
    if let Some(note) = architecture_note(&meta, g) {
        outln!("architecture: {note}");
    }
    if let (Some(returns), Some(file)) = (&sim.returns, &meta.files.range) {
        outln!(
            "{}; range.npy {} float64: the true depths in bins ({} returns)",
            sim.scene_source
                .as_deref()
                .unwrap_or("rendered from returns"),
            io::shape_text(returns.range_map().shape()),
            returns.depth.iter().filter(|d| !d.is_nan()).count()
        );
        debug_assert_eq!(file, "range.npy");
    }
    if ranks.processes() > 1 {
        outln!(
            "simulated by {} processes, each generating and measuring its own pixel rows' codes",
            ranks.processes()
        );
    }
    Ok(())
}

impl From<CodesFormat> for LibCodesFormat {
    fn from(f: CodesFormat) -> Self {
        match f {
            CodesFormat::Int8 => LibCodesFormat::Int8,
            CodesFormat::Packed => LibCodesFormat::Packed,
            CodesFormat::Seed => LibCodesFormat::Seed,
        }
    }
}

/// The noise of a simulation, in words.
fn noise_text(meta: &SimulationMeta) -> String {
    let n = &meta.noise;
    let mut parts = Vec::new();
    if let (Some(p), Some(mean)) = (n.photons, n.mean_photons) {
        parts.push(format!(
            "photon noise ({} photons per unit intensity, background {}; {mean:.3e} photons per \
             sample on average)",
            number(p),
            number(n.background.unwrap_or(0.0))
        ));
    }
    if let Some(s) = n.snr_db {
        parts.push(format!("Gaussian noise at {} dB SNR", number(s)));
    }
    if let Some(bits) = n.adc_bits {
        let scale = match (n.full_scale_auto, n.full_scale) {
            (Some(false), Some(f)) => format!("full scale {}", number(f)),
            _ => "full scale at the largest sample".into(),
        };
        parts.push(format!(
            "a {bits}-bit ADC ({scale}, {} samples clipped)",
            n.clipped.unwrap_or(0)
        ));
    }
    match (parts.is_empty(), n.achieved_snr_db) {
        (true, _) => "noise-free".into(),
        (false, Some(snr)) if parts.len() > 1 || n.snr_db.is_none() => {
            format!("{}; {snr:.1} dB SNR achieved", parts.join(", "))
        }
        _ => parts.join(", "),
    }
}

/// The line that describes a multi-ADC, tiled or coded-aperture acquisition.
fn architecture_note(meta: &SimulationMeta, g: Geometry) -> Option<String> {
    let arch = &meta.architecture;
    match arch.kind.as_str() {
        "multi_adc" => Some(format!(
            "{} ADCs, one code set each (code seeds {})",
            arch.adcs,
            meta.seeds
                .code_sets
                .iter()
                .map(u64::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        )),
        "tiles" => {
            let [tm, tn] = arch.tile.unwrap_or_default();
            Some(format!(
                "tiles of {tm}x{tn} pixels, {} ADCs (one per tile)",
                arch.adcs
            ))
        }
        "aperture" => Some(format!(
            "coded aperture, {} of {} pixels active (fraction {}, seed {})",
            arch.active_pixels,
            g.pixels(),
            arch.aperture_fraction.unwrap_or_default(),
            meta.seeds.aperture.unwrap_or_default()
        )),
        _ => None,
    }
}
