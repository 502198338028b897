//! `rdlidar dottest`: the adjoint identity of the operator built from files.

use std::path::PathBuf;
use std::process::ExitCode;

use rdlidar::io;
use rdlidar::lidar::{zero_mean, TileSize};
use rdlidar::operator::DotTest;

use rdlidar::acquisition::{pulse_in, Use};

use crate::common::{
    architecture_note, errln, outln, parse_depth_bins, parse_tile, CliResult, Globals,
};
use crate::ranks::Ranks;

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
#[derive(clap::Args, Debug)]
pub struct DottestArgs {
    /// Pulse file (K_p,), float32 or float64, ≥ 0.
    #[arg(long, value_name = "P")]
    pub pulse: PathBuf,
    /// Codes file (M, N, K), or (G, M, N, K) for G code sets; int8 (or float) in {-1, 0, 1}, or
    /// uint8 ±1 codes packed as `np.packbits(S > 0, axis=-1)` writes them (last axis ⌈K/8⌉).
    #[arg(long, value_name = "S")]
    pub codes: PathBuf,
    /// Depth bins K_s of the scene.
    #[arg(long, value_name = "KS", value_parser = parse_depth_bins)]
    pub depth_bins: usize,
    /// One ADC per tile of AxB pixels (as written by `simulate --tiles AxB`).
    #[arg(long, value_name = "AxB", value_parser = parse_tile)]
    pub tiles: Option<TileSize>,
    /// Codes described by a seed (meta.json) of one ADC: regenerate them block by block on every
    /// application instead of holding them (automatic when holding them would take over 1 GiB).
    #[arg(long)]
    pub stream_codes: bool,
}

/// Runs `dottest`: exit status 1 when a gap is above its tolerance.
pub fn run(a: &DottestArgs, globals: &Globals, ranks: &Ranks) -> CliResult<ExitCode> {
    let seed = globals.seed();
    // Every process reads its rows' codes; they agree on any failure before testing together.
    let prepared = (|| -> CliResult<_> {
        let p = io::read_pulse::<f64>(&a.pulse)?;
        // Operators in both precisions, each with its test vectors.
        let files = ranks.describe(
            &a.codes,
            (p.len(), a.depth_bins),
            None,
            a.tiles,
            a.stream_codes,
        )?;
        files.check_memory::<f64>("dottest", 6, Use::Operator)?;
        let acq = files.load(p.into_inner())?;
        let p64 = acq.pulse().to_vec();
        let p32 = pulse_in::<f32>(&p64).map_err(|e| {
            format!(
                "{} (--pulse): {e}; the dot test runs in f32 too",
                a.pulse.display()
            )
        })?;
        Ok((acq, p64, p32))
    })();
    let (acq, p64, p32) = ranks.agree(prepared)?;
    let test = DotTest::new().seed(seed);
    // One operator at a time: each holds the codes (and a tiled one its tiles' copies).
    let measure32 =
        |p: Vec<f32>| -> CliResult<_> { Ok(test.measure(&acq.operator_with_pulse(p)?)) };
    let measure64 =
        |p: Vec<f64>| -> CliResult<_> { Ok(test.measure(&acq.operator_with_pulse(p)?)) };
    let rows = [
        (
            "pulse as given",
            measure32(p32.clone())?,
            measure64(p64.clone())?,
        ),
        (
            "zero-mean pulse",
            measure32(zero_mean(&p32))?,
            measure64(zero_mean(&p64))?,
        ),
    ];
    outln!(
        "dot test |<Ax,y> - <x,A*y>| / max(|Ax||y|, |x||A*y|): {}, K_p {}, K {}, {} \
         codes{}, seed {seed}",
        acq.whole_geometry(),
        acq.pulse_len(),
        acq.samples(),
        acq.alphabet().name(),
        architecture_note(&acq)
    );
    outln!(
        "{:<16} {:<9} {:>10} {:>10}",
        "pulse",
        "precision",
        "gap",
        "tolerance"
    );
    let mut failed = Vec::new();
    for (name, r32, r64) in rows {
        for (prec, r) in [("f32", r32), ("f64", r64)] {
            let flag = if r.passed() { "ok" } else { "FAILED" };
            outln!(
                "{name:<16} {prec:<9} {:>10.2e} {:>10.0e}  {flag}",
                r.gap,
                r.tolerance
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
        Ok(ExitCode::SUCCESS)
    } else {
        errln!("error: dot test failed: {}", failed.join("; "));
        Ok(ExitCode::FAILURE)
    }
}
