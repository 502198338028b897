//! The codes of a problem read as its architecture says: one code set (M, N, K) with one ADC
//! (a coded aperture is such a file with zero codes), G code sets (G, M, N, K) with one ADC
//! each, or one code set with one ADC per tile (`--tiles AxB`); int8 or packed `.npy` files, or
//! a `meta.json` that describes ±1 codes by their seed.

use std::path::Path;
use std::sync::Arc;

use rdlidar::io::meta::{is_codes_description, read_seeded_codes, SimulationMeta};
use rdlidar::io::{self, NpyDtype, ShapeExpectation};
use rdlidar::lidar::{
    multi_adc, packed_len, pixel_groups, tiles, Architecture, CodeAlphabet, Codes, Geometry,
    RdOperator, SeededCodes, StreamedOperator, TileSize, STREAM_BLOCK_BYTES,
};
use rdlidar::operator::{BoxedOperator, OperatorExt};
use rdlidar::Real;

use crate::common::CliResult;

/// The architecture of a problem, from the header of its codes file and `--tiles`, with the
/// codes' shape; the codes themselves are not read.
pub fn architecture_of(
    codes: &Path,
    tile: Option<TileSize>,
) -> CliResult<(Architecture, Vec<usize>)> {
    if is_codes_description(codes) {
        return seeded_architecture(codes, tile);
    }
    let h = io::read_header(codes)?;
    let arch = match (h.shape.len(), tile) {
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
        (4, None) => Architecture::MultiAdc(h.shape[0]),
        (_, Some(t)) => Architecture::Tiles(t),
        (_, None) => Architecture::Single,
    };
    Ok((arch, h.shape))
}

/// Reads a `meta.json` whose codes are described by a seed: the whole description is checked by
/// [`Layout::read`]; this parses enough of it for the architecture, from its own `architecture`
/// (a tiled acquisition takes its tile size from there unless `--tiles` gives the same), and
/// the shape its codes would have as int8 (G, M, N, K) or (M, N, K).
fn seeded_architecture(
    codes: &Path,
    tile: Option<TileSize>,
) -> CliResult<(Architecture, Vec<usize>)> {
    let text = std::fs::read_to_string(codes)
        .map_err(|e| format!("{}: cannot read: {e}", codes.display()))?;
    let meta: SimulationMeta = serde_json::from_str(&text).map_err(|e| {
        format!(
            "{}: not a meta.json written by rdlidar simulate: {e}",
            codes.display()
        )
    })?;
    let (m, n, k) = (meta.geometry.m, meta.geometry.n, meta.k);
    let arch = meta.architecture;
    let described = match (arch.kind.as_str(), arch.tile) {
        ("multi_adc", _) => Architecture::MultiAdc(arch.adcs),
        ("tiles", Some([tm, tn])) => Architecture::Tiles(TileSize { m: tm, n: tn }),
        _ => Architecture::Single,
    };
    let arch = match (described, tile) {
        (Architecture::Tiles(d), Some(t)) if d != t => {
            return Err(format!(
                "{}: describes an acquisition in tiles of {d}, but --tiles says {t}",
                codes.display()
            )
            .into())
        }
        (Architecture::MultiAdc(g), Some(t)) => {
            return Err(format!(
                "{}: describes {g} code sets, one ADC each; --tiles {t} and several code sets \
                 are not supported together",
                codes.display()
            )
            .into())
        }
        (Architecture::Single, Some(t)) => Architecture::Tiles(t),
        (a, _) => a,
    };
    let shape = match arch {
        Architecture::MultiAdc(g) => vec![g, m, n, k],
        _ => vec![m, n, k],
    };
    Ok((arch, shape))
}

/// Seeded codes of one ADC larger than this are regenerated block by block on every
/// application ([`StreamedOperator`]) instead of being held.
pub const STREAM_ABOVE_BYTES: u128 = 1 << 30;

/// Whether the codes `codes` of architecture `arch` are streamed: seeded codes of one ADC when
/// `--stream-codes` asks for it or when holding them would take more than
/// [`STREAM_ABOVE_BYTES`]. `--stream-codes` with codes that are not seeded, or with several
/// ADCs, is an error.
pub fn streams(
    codes: &Path,
    arch: Architecture,
    forced: bool,
    expect: &ShapeExpectation,
) -> CliResult<bool> {
    let seeded = is_codes_description(codes);
    if forced && !seeded {
        return Err(format!(
            "--stream-codes regenerates codes described by a seed, but {} is a codes file: pass              the meta.json of `simulate --codes-format seed`",
            codes.display()
        )
        .into());
    }
    if !seeded || !matches!(arch, Architecture::Single) {
        if forced {
            return Err(format!(
                "--stream-codes streams the codes of one ADC, but {} describes {}: its {} are \
                 generated one code set or tile at a time already",
                codes.display(),
                arch.kind(),
                match arch {
                    Architecture::Tiles(_) => "tiles",
                    _ => "code sets",
                }
            )
            .into());
        }
        return Ok(false);
    }
    let pixels = match seeded_architecture(codes, None) {
        Ok((_, shape)) => shape.iter().rev().skip(1).product::<usize>() as u128,
        Err(_) => return Ok(forced),
    };
    let held = pixels.saturating_mul(packed_len(expect.samples()) as u128);
    Ok(forced || held > STREAM_ABOVE_BYTES)
}

/// The codes of a problem with its architecture.
pub struct Layout {
    /// How the pixels reach the ADCs.
    pub arch: Architecture,
    /// The scene grid.
    pub geometry: Geometry,
    /// One code set per ADC for several code sets, one otherwise.
    pub code_sets: Vec<Arc<Codes>>,
    /// The tiles' pixel groups ([`Architecture::Tiles`] only).
    pub groups: Option<Vec<Vec<usize>>>,
    /// Codes described by a seed (a `meta.json` given to --codes).
    pub seeded: Option<SeededCodes>,
    /// Seeded codes of one ADC regenerated on every application ([`streams`]): `code_sets`
    /// is empty.
    pub streamed: bool,
}

impl Layout {
    /// Reads the codes as `arch` says, for `ks` depth bins.
    ///
    /// Seeded codes are generated here, every code set of the whole array, unless `lazy_tiles`
    /// and the array is tiled, or `stream` (see [`streams`]): then `code_sets` is empty and
    /// [`Layout::seeded`] gives the codes on demand.
    pub fn read(
        codes: &Path,
        arch: Architecture,
        expect: &ShapeExpectation,
        ks: usize,
        lazy_tiles: bool,
        stream: bool,
    ) -> CliResult<Layout> {
        let geometry = |(m, n): (usize, usize)| {
            Geometry::new(m, n, ks).map_err(|e| format!("--depth-bins: {e}"))
        };
        let mut seeded = None;
        let (grid, code_sets) = match arch {
            _ if is_codes_description(codes) => {
                let file = read_seeded_codes(codes, expect)?;
                let s = file.codes;
                seeded = Some(s);
                let lazy = match arch {
                    Architecture::Tiles(_) => lazy_tiles,
                    Architecture::Single => stream,
                    _ => false,
                };
                let sets = if lazy {
                    Vec::new()
                } else {
                    (0..s.sets())
                        .map(|g| s.materialize(g).map(Arc::new))
                        .collect::<rdlidar::Result<Vec<_>>>()
                        .map_err(|e| format!("{}: {e}", codes.display()))?
                };
                (file.grid, sets)
            }
            Architecture::MultiAdc(_) => {
                let (grid, sets) = io::read_code_sets(codes, expect)?;
                (grid, sets.into_iter().map(Arc::new).collect())
            }
            _ => {
                let (grid, s) = io::read_codes(codes, expect)?;
                (grid, vec![Arc::new(s)])
            }
        };
        let geometry = geometry(grid)?;
        let groups = match arch {
            Architecture::Tiles(t) => {
                Some(tiles(geometry, t.m, t.n).map_err(|e| format!("--tiles: {e}"))?)
            }
            _ => None,
        };
        let streamed = stream && seeded.is_some() && matches!(arch, Architecture::Single);
        Ok(Layout {
            arch,
            geometry,
            code_sets,
            groups,
            seeded,
            streamed,
        })
    }

    /// Rows of the measurements: `None` for the (K,) vector of one ADC, `Some(R)` for (R, K).
    pub fn rows(&self) -> Option<usize> {
        self.arch.rows(self.geometry.m, self.geometry.n)
    }

    /// The measurement operator with the pulse `pulse`.
    pub fn operator<T: Real>(&self, pulse: Vec<T>) -> rdlidar::Result<BoxedOperator<T>> {
        let g = self.geometry;
        if let Some(op) = self.streamed_operator(pulse.clone())? {
            return Ok(op.boxed());
        }
        let codes = &self.code_sets[0];
        Ok(match (&self.arch, &self.groups) {
            (Architecture::MultiAdc(_), _) => multi_adc(g, &pulse, self.code_sets.clone())?.boxed(),
            (Architecture::Tiles(_), Some(groups)) => {
                pixel_groups(g, &pulse, codes, groups)?.boxed()
            }
            _ => RdOperator::new(g, pulse, codes.clone())?.boxed(),
        })
    }

    /// The streamed operator of seeded codes of one ADC, if they are streamed.
    pub fn streamed_operator<T: Real>(
        &self,
        pulse: Vec<T>,
    ) -> rdlidar::Result<Option<StreamedOperator<T>>> {
        match (self.streamed, self.seeded) {
            (true, Some(s)) => Ok(Some(StreamedOperator::new(self.geometry, pulse, s, 0)?)),
            _ => Ok(None),
        }
    }

    /// "binary" if every code set is ±1, "ternary" otherwise.
    pub fn alphabet(&self) -> &'static str {
        if self.seeded.is_some()
            || self
                .code_sets
                .iter()
                .all(|c| c.alphabet() == CodeAlphabet::Binary)
        {
            "binary"
        } else {
            "ternary"
        }
    }

    /// A note for the messages of the multi-ADC layouts (empty for a single ADC).
    pub fn note(&self) -> String {
        match (self.arch, self.rows()) {
            (Architecture::MultiAdc(g), _) => format!(", {g} ADCs (one code set each)"),
            (Architecture::Tiles(t), Some(r)) => format!(", tiles of {t} pixels ({r} ADCs)"),
            _ => String::new(),
        }
    }
}

/// Reads the measurements in the shape `arch` needs: (K,) for one ADC, (R, K) for R ADCs, with
/// a message that names the flag or the file that decides the shape when the shapes disagree.
pub fn read_measurements<T: Real>(
    meas: &Path,
    codes: &Path,
    arch: Architecture,
    codes_shape: &[usize],
    expect: &ShapeExpectation,
) -> CliResult<Vec<T>> {
    let h = io::read_header(meas)?;
    let k = expect.samples();
    let float = matches!(h.dtype, NpyDtype::Float32 | NpyDtype::Float64);
    let (rows, why) = match arch {
        Architecture::MultiAdc(sets) => (
            (sets > 0).then_some(sets),
            format!(
                "the codes {} of shape {} are {sets} code sets, one ADC each",
                codes.display(),
                io::shape_text(codes_shape)
            ),
        ),
        Architecture::Tiles(t) => match codes_shape {
            [m, n, _] if *m > 0 && *n > 0 => {
                let count = t.count(*m, *n);
                (
                    Some(count),
                    format!(
                        "--tiles {t} splits the {m}x{n} array into {count} tiles, one ADC each"
                    ),
                )
            }
            _ => (None, String::new()),
        },
        Architecture::Single | Architecture::Aperture(_) => {
            if float && h.shape.len() == 2 && codes_shape.len() == 3 {
                return Err(format!(
                    "{}: measurements of shape {} have one row per ADC, but the codes {} are \
                     one code set read as a single ADC: for a tiled array pass --tiles AxB \
                     with its tile size (meta.json \"architecture\" \"tile\")",
                    meas.display(),
                    io::shape_text(&h.shape),
                    codes.display()
                )
                .into());
            }
            return Ok(io::read_measurements::<T>(meas, Some(expect))?);
        }
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

/// The expectation of the other files for a pulse of `pulse_len` samples and `depth_bins` bins.
pub fn expectation(pulse_len: usize, depth_bins: usize) -> CliResult<ShapeExpectation> {
    if pulse_len.checked_add(depth_bins).is_none() {
        return Err(format!("--depth-bins {depth_bins} is too large").into());
    }
    Ok(ShapeExpectation {
        pulse_len,
        depth_bins,
        grid: None,
    })
}

/// Checks, from the codes file's header and before any data are read, that `command` fits in
/// memory in `T`: the codes with the operator's per-thread buffers (one per code set), `copies`
/// scenes (inputs, outputs and a solver's working copies) and the measurements. With
/// `per_tile`, a tiled array whose codes are seeded counts one tile's codes per thread; with
/// `streamed`, one block of codes. A file the readers will refuse is left to them.
pub fn check_memory<T: Real>(
    command: &str,
    codes: &Path,
    expect: &ShapeExpectation,
    copies: u128,
    per_tile: bool,
    streamed: bool,
) -> CliResult {
    let (shape, held) = if is_codes_description(codes) {
        match seeded_architecture(codes, None) {
            // Streamed codes of one ADC: a block of about STREAM_BLOCK_BYTES at a time.
            Ok((_, shape)) if streamed => {
                let per_pixel = packed_len(expect.samples()).max(1);
                let block = (STREAM_BLOCK_BYTES / per_pixel).max(8);
                let pixels = shape.iter().rev().skip(1).product::<usize>();
                (shape, Some((1, 1, block.min(pixels))))
            }
            // A tiled array with seeded codes holds only the tiles being solved.
            Ok((Architecture::Tiles(t), shape)) if per_tile => {
                (shape, Some((rayon::current_num_threads(), t.m, t.n)))
            }
            Ok((_, shape)) => (shape, None),
            Err(_) => return Ok(()),
        }
    } else {
        (io::read_header(codes)?.shape, None)
    };
    let (sets, m, n) = match shape.as_slice() {
        [g, m, n, _] => (*g, *m, *n),
        [m, n, _] => (1, *m, *n),
        _ => return Ok(()),
    };
    // The grid and count of the codes held at once: the whole array's, or a block's or tiles'.
    let (held_sets, hm, hn) = held.unwrap_or((sets, m, n));
    let (Ok(g), Ok(held_grid)) = (
        Geometry::new(m, n, expect.depth_bins),
        Geometry::new(hm, hn, expect.depth_bins),
    ) else {
        return Ok(());
    };
    let operator = RdOperator::<T>::estimated_memory_bytes(
        held_grid,
        expect.pulse_len,
        CodeAlphabet::Ternary,
        rayon::current_num_threads(),
    )
    .map_or(u128::MAX, |b| b as u128);
    let size = std::mem::size_of::<T>();
    rdlidar::limits::MemoryPlan::new()
        .add(
            "codes and operator",
            operator.saturating_mul(held_sets as u128),
            1,
        )
        .add("scenes", copies.saturating_mul(g.voxels() as u128), size)
        .add(
            "measurements",
            (sets as u128).saturating_mul(expect.samples() as u128) * 2,
            size,
        )
        .check(
            &format!(
                "{command} on {g} with K_p = {} (--codes {})",
                expect.pulse_len,
                codes.display()
            ),
            "use smaller inputs or free memory",
        )?;
    Ok(())
}
