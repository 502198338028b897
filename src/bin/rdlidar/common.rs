//! What every subcommand shares: the one-line failure, the precision flag, value parsers, and
//! the checks of output paths made before any work.

use std::path::{Path, PathBuf};

use clap::ValueEnum;
use rdlidar::acquisition::{count_of, Acquisition, Streaming};
use rdlidar::io::{self, NpyDtype};
use rdlidar::lidar::{Architecture, Geometry, TileSize};
use rdlidar::settings::FrontEnd;
use rdlidar::{limits, Real};

/// A command-line failure.
#[derive(Debug)]
pub enum Failure {
    /// The one-line message printed after `error: `; exit status 1.
    Message(String),
    /// Standard output is a pipe whose reader has gone: the command ends quietly with status 141
    /// (128 + SIGPIPE), what a shell reports for a standard tool ended by a broken pipe.
    BrokenPipe,
}

/// A library error in the command line's words: its settings as flags.
impl From<rdlidar::Error> for Failure {
    fn from(e: rdlidar::Error) -> Self {
        Failure::Message(FrontEnd::CommandLine.render(&e))
    }
}

impl From<String> for Failure {
    fn from(msg: String) -> Self {
        Failure::Message(msg)
    }
}

/// Set in every process but the first of an MPI job: its lines are not printed.
static SILENT: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether this process prints nothing (a process other than the first of an MPI job).
pub fn silent() -> bool {
    SILENT.load(std::sync::atomic::Ordering::Relaxed)
}

/// From now on this process prints nothing.
pub fn silence() {
    SILENT.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// Writes one line to standard output. A broken pipe becomes [`Failure::BrokenPipe`], any other
/// write error (a full device, a closed descriptor) a one-line failure; never a panic.
pub fn write_stdout(line: std::fmt::Arguments<'_>) -> CliResult {
    use std::io::Write;
    if silent() {
        return Ok(());
    }
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}")
        .and_then(|()| out.flush())
        .map_err(stdout_failure)
}

/// The failure of a write to standard output.
pub fn stdout_failure(e: std::io::Error) -> Failure {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        Failure::BrokenPipe
    } else {
        Failure::Message(format!("cannot write to standard output: {e}"))
    }
}

/// Writes one line to standard error, ignoring failure: diagnostics must never stop a command
/// (nor panic, as `eprintln!` does when standard error is closed or full).
pub fn write_stderr(line: std::fmt::Arguments<'_>) {
    use std::io::Write;
    if silent() {
        return;
    }
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}

/// `println!` that returns a [`Failure`] from the enclosing function instead of panicking.
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::common::write_stdout(format_args!($($arg)*))?
    };
}
pub(crate) use outln;

/// `eprintln!` that never panics.
macro_rules! errln {
    ($($arg:tt)*) => {
        $crate::common::write_stderr(format_args!($($arg)*))
    };
}
pub(crate) use errln;

/// The result of a subcommand.
pub type CliResult<T = ()> = Result<T, Failure>;

/// Floating-point precision of a computation and of the float arrays it writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Precision {
    /// Single precision (float32 files).
    #[value(name = "f32")]
    F32,
    /// Double precision (float64 files).
    #[value(name = "f64")]
    F64,
}

/// The files of a measured acquisition and the depth bins of its scene.
#[derive(clap::Args, Debug)]
pub struct MeasurementFiles {
    /// Pulse file (K_p,), float32 or float64, ≥ 0.
    #[arg(long, value_name = "P")]
    pub pulse: PathBuf,
    /// Codes file (M, N, K), int8 (or float) in {-1, 0, 1}, or uint8 (M, N, ⌈K/8⌉) ±1 codes as
    /// `np.packbits(S > 0, axis=-1)` writes them; `adjoint` also reads G code sets (G, M, N, …).
    #[arg(long, value_name = "S")]
    pub codes: PathBuf,
    /// Measurements file (K,), float32 or float64; `adjoint` also reads one row per ADC
    /// (ADCs, K).
    #[arg(long, value_name = "Y")]
    pub meas: PathBuf,
    /// Depth bins K_s of the scene (at most 65536).
    #[arg(long, value_name = "KS", value_parser = parse_depth_bins)]
    pub depth_bins: usize,
}

impl MeasurementFiles {
    /// The three input files with their flags.
    pub fn inputs(&self) -> [Input<'_>; 3] {
        [
            (&self.pulse, "--pulse"),
            (&self.codes, "--codes"),
            (&self.meas, "--meas"),
        ]
    }
}

/// The global flags, as every subcommand sees them.
#[derive(Debug, Clone, Copy)]
pub struct Globals {
    /// --threads.
    pub threads: Option<usize>,
    /// --seed.
    pub seed: Option<u64>,
    /// --precision.
    pub precision: Option<Precision>,
    /// --quiet.
    pub quiet: bool,
}

impl Globals {
    /// The base seed (default 0).
    pub fn seed(&self) -> u64 {
        self.seed.unwrap_or(0)
    }

    /// --precision, or f64 if one of `files` holds float64 data and f32 otherwise (the headers
    /// are read, not the data).
    pub fn precision_of(&self, files: &[&Path]) -> CliResult<Precision> {
        if let Some(p) = self.precision {
            return Ok(p);
        }
        for f in files {
            if io::read_header(f)?.dtype == NpyDtype::Float64 {
                return Ok(Precision::F64);
            }
        }
        Ok(Precision::F32)
    }
}

/// Calls `$f::<f32>` or `$f::<f64>` with the arguments, as the precision says.
macro_rules! with_precision {
    ($precision:expr, $f:ident($($arg:expr),* $(,)?)) => {
        match $precision {
            $crate::common::Precision::F32 => $f::<f32>($($arg),*),
            $crate::common::Precision::F64 => $f::<f64>($($arg),*),
        }
    };
}
pub(crate) use with_precision;

/// A positive integer flag value.
pub fn parse_positive(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(0) => Err("must be at least 1".to_string()),
        Ok(v) => Ok(v),
        Err(_) => Err(format!("expected a positive integer, got {text:?}")),
    }
}

/// A positive integer flag value of at most `bound` (one of [`rdlidar::limits`]' bounds).
fn parse_bounded(text: &str, bound: usize) -> Result<usize, String> {
    let v = parse_positive(text)?;
    if v > bound {
        return Err(format!("{v} is more than the limit of {bound}"));
    }
    Ok(v)
}

/// A thread count, 1 … [`limits::MAX_THREADS`].
pub fn parse_threads(text: &str) -> Result<usize, String> {
    parse_bounded(text, limits::MAX_THREADS)
}

/// A repeat count, 1 … [`limits::MAX_REPEATS`].
pub fn parse_repeats(text: &str) -> Result<usize, String> {
    parse_bounded(text, limits::MAX_REPEATS)
}

/// A pulse length, 1 … [`limits::MAX_PULSE_LEN`].
pub fn parse_pulse_len(text: &str) -> Result<usize, String> {
    parse_bounded(text, limits::MAX_PULSE_LEN)
}

/// A number of ADCs, 1 … [`limits::MAX_ADCS`].
pub fn parse_adcs(text: &str) -> Result<usize, String> {
    parse_bounded(text, limits::MAX_ADCS)
}

/// A number of depth bins, 1 … [`limits::MAX_DEPTH_BINS`].
pub fn parse_depth_bins(text: &str) -> Result<usize, String> {
    parse_bounded(text, limits::MAX_DEPTH_BINS)
}

/// A grid `MxNxKS` within [`Geometry::check_bounds`].
pub fn parse_size(text: &str) -> Result<Geometry, String> {
    let g = Geometry::parse(text).map_err(|e| e.to_string())?;
    g.check_bounds()
        .map_err(|e| FrontEnd::CommandLine.reason(&e))?;
    Ok(g)
}

/// A tile size `AxB`.
pub fn parse_tile(text: &str) -> Result<TileSize, String> {
    TileSize::parse(text).map_err(|e| e.to_string())
}

/// The npy name of `T`'s dtype.
pub fn npy_dtype<T: Real>() -> &'static str {
    match T::NAME {
        "f32" => "float32",
        _ => "float64",
    }
}

/// Refuses a computed result holding a NaN or an infinite value: the finite values of the input
/// (`flag`, file `input`) overflow `T` through the operator.
pub fn check_finite_result<T: Real>(
    values: &[T],
    what: &str,
    input: &Path,
    flag: &str,
) -> CliResult {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(format!(
            "{}: the {what} of these values ({flag}) overflow {} (entry {i} is {}); scale \
             the input down{}",
            input.display(),
            npy_dtype::<T>(),
            values[i],
            if T::NAME == "f32" {
                " or use --precision f64"
            } else {
                ""
            }
        )
        .into()),
    }
}

/// An input file of a subcommand and the flag that named it.
pub type Input<'a> = (&'a Path, &'a str);

/// Checks, before any work, that an output file (given by `flag`) can be created where asked and
/// is none of the `inputs` (the same file after symbolic links, hard links included). A FIFO or
/// a device is written in place; a socket cannot be written to.
pub fn check_out_file(out: &Path, flag: &str, inputs: &[Input<'_>]) -> CliResult {
    if out.is_dir() {
        return Err(format!(
            "{}: {flag} is a directory, expected a file name",
            out.display()
        )
        .into());
    }
    if io::special_file_kind(out) == Some("a socket") {
        return Err(format!(
            "{}: {flag} is a socket, not a file: an output cannot be written to a socket",
            out.display()
        )
        .into());
    }
    let dir = io::parent_dir(out);
    if !dir.is_dir() {
        return Err(format!(
            "{}: directory {} does not exist ({flag})",
            out.display(),
            dir.display()
        )
        .into());
    }
    check_not_input(out, flag, inputs)
}

/// Refuses an output path that names one of the `inputs`.
pub fn check_not_input(out: &Path, flag: &str, inputs: &[Input<'_>]) -> CliResult {
    match inputs.iter().find(|(input, _)| io::same_file(out, input)) {
        Some((_, input_flag)) => Err(format!(
            "{}: {flag} names the same file as {input_flag}; refusing to overwrite an input",
            out.display()
        )
        .into()),
        None => Ok(()),
    }
}

/// Sets the size of the global thread pool; `source` names where the count came from.
pub fn set_threads(threads: Option<usize>, source: &str) -> CliResult {
    if let Some(n) = threads {
        limits::check_count("threads", n, limits::MAX_THREADS)
            .map_err(|e| format!("{source} {n}: {e}"))?;
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| format!("{source} {n}: {e}"))?;
    }
    Ok(())
}

/// `--stream-codes`: always stream, or leave it to the size of the codes.
pub fn streaming(forced: bool) -> Streaming {
    if forced {
        Streaming::Always
    } else {
        Streaming::Auto
    }
}

/// Names the pulse file in an error about the pulse (e.g. one not representable in the
/// precision of the computation).
pub fn at_pulse(path: &Path) -> impl Fn(rdlidar::Error) -> Failure + '_ {
    move |e| {
        let e = e.to_string();
        let hint = if e.ends_with("compute in f64") {
            " (--precision f64)"
        } else {
            ""
        };
        Failure::Message(format!("{} (--pulse): {e}{hint}", path.display()))
    }
}

/// A note on the architecture for the messages of several ADCs (empty for one ADC).
pub fn architecture_note(acq: &Acquisition) -> String {
    let g = acq.whole_geometry();
    let mut note = match acq.architecture() {
        Architecture::MultiAdc(n) => {
            format!(", {} (one code set each)", count_of(n, "ADC", "ADCs"))
        }
        Architecture::Tiles(t) => format!(
            ", tiles of {t} pixels ({})",
            count_of(t.count(g.m, g.n), "ADC", "ADCs")
        ),
        _ => String::new(),
    };
    if let Some(share) = acq.share() {
        let how = if share.tiles().is_some() {
            "tiles dealt to"
        } else {
            "pixel rows split over"
        };
        note.push_str(&format!(", {how} {} processes", share.space().parts()));
    }
    note
}

/// Refuses outputs that name one destination, however spelt (see [`io::same_destination`]).
pub fn check_distinct_outputs(outputs: &[(&str, &Path)]) -> CliResult {
    for (i, (fa, pa)) in outputs.iter().enumerate() {
        for (fb, pb) in &outputs[i + 1..] {
            if io::same_destination(pa, pb) {
                return Err(format!(
                    "{}: {fa} and {fb} ({}) name the same file",
                    pa.display(),
                    pb.display()
                )
                .into());
            }
        }
    }
    Ok(())
}
