//! An acquisition from the files `rdlidar simulate` writes: its codes (an int8 or packed `.npy`
//! array, or a `meta.json` describing them by a seed) described from their header, checked
//! and planned before any data are read, then loaded.

use crate::settings::FrontEnd;
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::io::meta::{is_codes_description, read_seeded_codes};
use crate::io::{self, file_error, NpyDtype, ShapeExpectation};
use crate::lidar::{Architecture, Geometry, SeededCodes, TileSize};
use crate::limits::{self, MemoryPlan};
use crate::real::Real;

use std::sync::Arc;

use crate::space::Space;

use super::{count_of, held, plan, streams, Acquisition, CodeStore, Share, Streaming, Use};

/// The codes file of an acquisition, described from its header (or its `meta.json`) and
/// checked against the pulse length, the depth bins and the architecture, before any data are
/// read: [`AcquisitionFiles::memory_plan`] says what loading and using it will take, and
/// [`AcquisitionFiles::load`] reads it.
#[derive(Debug, Clone)]
pub struct AcquisitionFiles {
    codes: PathBuf,
    geometry: Geometry,
    pulse_len: usize,
    architecture: Architecture,
    /// The codes' shape as int8 would hold them: (M, N, K) or (G, M, N, K).
    shape: Vec<usize>,
    seeded: Option<SeededCodes>,
    streamed: bool,
    tiles: Option<TileSize>,
    streaming: Streaming,
    names: InputNames,
    /// The band of pixel rows to load, when not all of them.
    band: Option<Range<usize>>,
    /// This process's share, when the rows are split over processes.
    share: Option<Share>,
}

/// What the messages call the inputs: the command line's flags, or the Python arguments, as
/// [`FrontEnd::word`] gives them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputNames(pub FrontEnd);

impl InputNames {
    /// The names of `rdlidar`'s flags.
    pub const COMMAND_LINE: InputNames = InputNames(FrontEnd::CommandLine);
    /// The names of the Python package's arguments.
    pub const PYTHON: InputNames = InputNames(FrontEnd::Python);

    /// The codes.
    pub fn codes(&self) -> String {
        self.0.word("codes")
    }

    /// The tile size.
    pub fn tiles(&self) -> String {
        self.0.word("tiles")
    }

    /// Streaming asked for.
    pub fn stream(&self) -> String {
        self.0.word("stream_codes")
    }

    /// How a tile size is given: `--tiles AxB` or `tiles=(A, B)`.
    pub fn tile_hint(&self) -> String {
        match self.0 {
            FrontEnd::CommandLine => format!("{} AxB", self.tiles()),
            FrontEnd::Python => format!("{}=(A, B)", self.tiles()),
        }
    }

    /// A tile size as given: `--tiles 2x2` or `tiles=(2, 2)`.
    pub fn tile(&self, t: TileSize) -> String {
        match self.0 {
            FrontEnd::CommandLine => format!("{} {t}", self.tiles()),
            FrontEnd::Python => format!("{}=({}, {})", self.tiles(), t.m, t.n),
        }
    }
}

impl AcquisitionFiles {
    /// Describes the codes `codes` for a pulse of `pulse_len` samples and `depth_bins` depth
    /// bins, with one ADC per tile of `tiles` pixels (None: as the codes say). `grid` is the
    /// scene's (M, N) when a scene is given. Only the header of an `.npy` file is read; a
    /// `meta.json` (see [`crate::io::meta::read_seeded_codes`]) is parsed and checked whole.
    ///
    /// # Errors
    /// [`Error::File`] naming `codes`: it cannot be read, it is neither three- nor
    /// four-dimensional, its grid or number of code sets is beyond [`crate::limits`], its
    /// grid is not `grid`, its samples are not K = `pulse_len` + `depth_bins` − 1, its tiles
    /// disagree with `tiles`, tiles are asked of several code sets, or streaming is asked of
    /// codes that are not seeded codes of one ADC. [`Error::InvalidParameter`] (`depth_bins`,
    /// `pulse`) for counts beyond their bounds.
    pub fn describe(
        codes: &Path,
        pulse_len: usize,
        depth_bins: usize,
        grid: Option<(usize, usize)>,
        tiles: Option<TileSize>,
        streaming: Streaming,
        names: InputNames,
    ) -> Result<Self> {
        limits::check_count("depth_bins", depth_bins, limits::MAX_DEPTH_BINS)?;
        limits::check_count("pulse", pulse_len, limits::MAX_PULSE_LEN)?;
        let fail = |why: String| file_error(codes, why);
        let k = pulse_len + depth_bins - 1;
        let (grid_of_codes, sets, seeded, described) = if is_codes_description(codes) {
            // Its samples are checked against K in `load`, after the measurements, as for
            // a codes file.
            let file = read_seeded_codes(codes)?;
            let g = file.geometry;
            let sets = file.codes.sets();
            ((g.m, g.n), sets, Some(file.codes), Some(file.architecture))
        } else {
            // The last axis (K, or ⌈K/8⌉ packed) is checked by the readers in `load`, after
            // the measurements have been checked against K.
            let h = io::read_header(codes)?;
            let (sets, m, n) = match h.shape[..] {
                [m, n, _] => (1, m, n),
                [g, m, n, _] => (g, m, n),
                _ => {
                    return Err(fail(format!(
                        "codes of shape {}: expected (M, N, K) for one code set or \
                         (G, M, N, K) for G code sets",
                        io::shape_text(&h.shape)
                    )))
                }
            };
            if m > limits::MAX_SIDE || n > limits::MAX_SIDE {
                return Err(fail(format!(
                    "codes of shape {} have {m}x{n} pixels: at most {} pixel rows and {} \
                     columns",
                    io::shape_text(&h.shape),
                    limits::MAX_SIDE,
                    limits::MAX_SIDE
                )));
            }
            if sets > limits::MAX_ADCS {
                return Err(fail(format!(
                    "codes of shape {} are {sets} code sets, more than the limit of {} ADCs",
                    io::shape_text(&h.shape),
                    limits::MAX_ADCS
                )));
            }
            if sets == 0 {
                return Err(fail(format!(
                    "codes of shape {} hold no code set",
                    io::shape_text(&h.shape)
                )));
            }
            if h.shape.len() == 4 && sets == 1 {
                if let Some(t) = tiles {
                    return Err(fail(format!(
                        "codes of shape {} have a code-set axis (G, M, N, K); {} needs one \
                         code set (M, N, K)",
                        io::shape_text(&h.shape),
                        names.tile(t)
                    )));
                }
            }
            let described = (h.shape.len() == 4).then_some(Architecture::MultiAdc(sets));
            ((m, n), sets, None, described)
        };
        let (m, n) = grid_of_codes;
        let geometry = Geometry::new(m, n, depth_bins)
            .and_then(|g| g.check_bounds().map(|()| g))
            .map_err(|e| fail(format!("the codes' grid: {e}")))?;
        if let Some(want) = grid {
            if want != (m, n) {
                return Err(fail(format!(
                    "codes of {m}x{n} pixels, but the scene has {}x{}",
                    want.0, want.1
                )));
            }
        }
        let architecture = match (described, tiles, sets) {
            (Some(Architecture::Tiles(d)), Some(t), _) if d != t => {
                return Err(fail(format!(
                    "describes an acquisition in tiles of {d}, but {} says {t}",
                    names.tiles()
                )))
            }
            (Some(Architecture::Tiles(d)), _, _) => Architecture::Tiles(d),
            (_, Some(t), 1) => Architecture::Tiles(t),
            (_, Some(t), g) => {
                return Err(fail(format!(
                    "{g} code sets, one ADC each; {} and several code sets are not supported \
                     together",
                    names.tile(t)
                )))
            }
            (Some(Architecture::MultiAdc(1)), None, 1) => Architecture::MultiAdc(1),
            (_, None, 1) => Architecture::Single,
            (_, None, g) => Architecture::MultiAdc(g),
        };
        if let Some(rows) = architecture.rows(m, n) {
            if rows > limits::MAX_ADCS {
                return Err(fail(format!(
                    "{} of the {m}x{n} array, more than the limit of {} ADCs",
                    count_of(rows, "tile", "tiles"),
                    limits::MAX_ADCS
                )));
            }
        }
        let streamed = streams(streaming, seeded.is_some(), architecture, geometry, k)
            .map_err(|why| fail(why.describe(&names.stream())))?;
        let shape = match architecture {
            Architecture::MultiAdc(g) => vec![g, m, n, k],
            _ => vec![m, n, k],
        };
        Ok(AcquisitionFiles {
            codes: codes.to_path_buf(),
            geometry,
            pulse_len,
            architecture,
            shape,
            seeded,
            streamed,
            tiles: match architecture {
                Architecture::Tiles(t) => Some(t),
                _ => None,
            },
            streaming: if streamed {
                Streaming::Always
            } else {
                Streaming::Never
            },
            names,
            band: None,
            share: None,
        })
    }

    /// Only the pixel rows `rows` of the codes: [`AcquisitionFiles::memory_plan`] is then the
    /// band's, and [`AcquisitionFiles::load`] reads only those rows of the codes (of an `.npy`
    /// file in C order, only those bytes; seeded codes are generated for those pixels only) and
    /// gives the acquisition of the band: its grid is those rows, its operator the block A_r of
    /// the whole operator that maps them to every measurement (as pylops-mpi's `MPIHStack`
    /// stacks blocks). Of an array in tiles, a band holds whole rows of tiles and is itself an
    /// array in tiles: its operator is the block of those tiles, mapping the band's unknowns to
    /// its tiles' measurements (consecutive rows of the whole array's (T, K)), so that the
    /// bands' blocks sit on the diagonal of the whole operator (as pylops-mpi's `MPIBlockDiag`
    /// places them).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`rows`) for an empty band or one beyond the grid, and for
    /// a band of an array in tiles that cuts through its tiles.
    pub fn with_rows(mut self, rows: Range<usize>) -> Result<Self> {
        let m = self.geometry.m;
        if rows.is_empty() || rows.end > m {
            return Err(Error::param(
                "rows",
                format!(
                    "rows {}..{} are not a band of the {m} pixel rows of {}",
                    rows.start,
                    rows.end,
                    self.codes.display()
                ),
            ));
        }
        if let Architecture::Tiles(t) = self.architecture {
            if !rows.start.is_multiple_of(t.m) || (!rows.end.is_multiple_of(t.m) && rows.end != m) {
                return Err(Error::param(
                    "rows",
                    format!(
                        "rows {}..{} cut through the tiles of {t} of {}: a band of an array in \
                         tiles holds whole rows of tiles (start and stop multiples of {}, or \
                         stop = {m})",
                        rows.start,
                        rows.end,
                        self.codes.display(),
                        t.m
                    ),
                ));
            }
        }
        self.set_band(rows);
        Ok(self)
    }

    /// Loads only `rows`, and decides on the band whether seeded codes are streamed.
    fn set_band(&mut self, rows: Range<usize>) {
        if let (Some(_), Streaming::Never) = (self.seeded, self.streaming) {
            self.streamed = streams(
                Streaming::Auto,
                true,
                self.architecture,
                band_geometry(self.geometry, &rows),
                self.samples(),
            )
            .unwrap_or(false);
        }
        self.band = Some(rows);
    }

    /// The codes split by pixel rows over the parts of `space` (the processes of an MPI job):
    /// [`AcquisitionFiles::memory_plan`] is then this process's, and
    /// [`AcquisitionFiles::load`] reads only its band of rows of the codes (of an `.npy` file
    /// in C order, only those bytes) and gives its share of the acquisition
    /// ([`Acquisition::split_over`]). With one part, unchanged.
    ///
    /// # Errors
    /// [`Share::of`] or [`Share::of_tiles`]: more parts than pixel rows, or than tiles.
    pub fn split_over(mut self, space: Arc<dyn Space>) -> Result<Self> {
        if space.parts() == 1 {
            return Ok(self);
        }
        let share = match self.architecture {
            Architecture::Tiles(t) => Share::of_tiles(space, self.geometry, t)?,
            _ => Share::of(space, self.geometry)?,
        };
        self.set_band(share.rows());
        self.share = Some(share);
        Ok(self)
    }

    /// The codes file.
    pub fn codes_path(&self) -> &Path {
        &self.codes
    }

    /// The scene grid.
    pub fn geometry(&self) -> Geometry {
        self.geometry
    }

    /// How the pixels reach the ADCs.
    pub fn architecture(&self) -> Architecture {
        self.architecture
    }

    /// The codes' shape as int8 would hold them: (M, N, K), or (G, M, N, K) for G code sets.
    pub fn shape(&self) -> &[usize] {
        &self.shape
    }

    /// Whether the codes are described by a seed.
    pub fn is_seeded(&self) -> bool {
        self.seeded.is_some()
    }

    /// Whether seeded codes of one ADC will be regenerated block by block on every
    /// application.
    pub fn is_streamed(&self) -> bool {
        self.streamed
    }

    /// Samples per ADC: K = K_p + K_s − 1.
    pub fn samples(&self) -> usize {
        self.geometry.samples(self.pulse_len)
    }

    /// Rows of the measurements: `None` for (K,), `Some(R)` for (R, K).
    pub fn rows(&self) -> Option<usize> {
        self.architecture.rows(self.geometry.m, self.geometry.n)
    }

    /// The memory a request on the loaded acquisition needs in `T` (see
    /// [`Acquisition::memory_plan`]), before anything is read.
    pub fn memory_plan<T: Real>(&self, scenes: u128, request: Use) -> MemoryPlan {
        let geometry = self
            .band
            .as_ref()
            .map_or(self.geometry, |rows| band_geometry(self.geometry, rows));
        let held = held(
            geometry,
            self.samples(),
            self.architecture,
            self.seeded.is_some(),
            self.streamed,
            request,
        );
        plan::<T>(
            geometry,
            self.pulse_len,
            &held,
            self.rows().unwrap_or(1),
            scenes,
        )
    }

    /// Checks [`AcquisitionFiles::memory_plan`] against the memory available; `command` names
    /// the request in the message.
    ///
    /// # Errors
    /// [`Error::TooLarge`](crate::Error::TooLarge).
    pub fn check_memory<T: Real>(&self, command: &str, scenes: u128, request: Use) -> Result<()> {
        self.memory_plan::<T>(scenes, request).check(
            &format!(
                "{command} on {} with K_p = {} ({} {})",
                self.geometry,
                self.pulse_len,
                self.names.codes(),
                self.codes.display()
            ),
            "use smaller inputs or free memory",
        )
    }

    /// Reads the codes and builds the acquisition with the pulse `pulse` (of the length the
    /// codes were described for).
    ///
    /// # Errors
    /// The readers' [`Error::File`] naming the codes file; the errors of [`Acquisition::new`].
    pub fn load(&self, pulse: Vec<f64>) -> Result<Acquisition> {
        if pulse.len() != self.pulse_len {
            return Err(Error::param(
                "pulse",
                format!(
                    "{} samples, but the codes were described for {}",
                    pulse.len(),
                    self.pulse_len
                ),
            ));
        }
        let expect = ShapeExpectation {
            pulse_len: self.pulse_len,
            depth_bins: self.geometry.ks,
            grid: Some((self.geometry.m, self.geometry.n)),
        };
        let codes = match self.seeded {
            Some(s) if s.len() != self.samples() => {
                return Err(file_error(
                    &self.codes,
                    format!(
                        "describes codes of K = {} samples, but the pulse of {} samples and {} \
                         depth bins give K = {} + {} − 1 = {}",
                        s.len(),
                        self.pulse_len,
                        self.geometry.ks,
                        self.pulse_len,
                        self.geometry.ks,
                        self.samples()
                    ),
                ))
            }
            Some(s) => CodeStore::Seeded(s),
            None if self.band.is_some() => {
                let rows = self.band.clone().unwrap_or_default();
                let (_, sets) = io::read_code_band(&self.codes, &expect, rows)?;
                CodeStore::Held(sets.into_iter().map(Into::into).collect())
            }
            None if self.shape.len() == 4 => {
                let (_, sets) = io::read_code_sets(&self.codes, &expect)?;
                CodeStore::Held(sets.into_iter().map(Into::into).collect())
            }
            None => {
                let (_, c) = io::read_codes(&self.codes, &expect)?;
                CodeStore::Held(vec![c.into()])
            }
        };
        let at_codes = |e: Error| file_error(&self.codes, e.to_string());
        let acq = match &self.band {
            Some(rows) => {
                let codes = match codes {
                    CodeStore::Seeded(s) => {
                        let n = self.geometry.n;
                        CodeStore::Seeded(s.band(rows.start * n..rows.end * n)?)
                    }
                    held => held,
                };
                let streaming = if self.streamed {
                    Streaming::Always
                } else {
                    Streaming::Never
                };
                let g = band_geometry(self.geometry, rows);
                let acq =
                    Acquisition::new(g, pulse, codes, self.tiles, streaming).map_err(at_codes)?;
                if let Some(share) = &self.share {
                    return acq
                        .band_of(share.clone(), self.architecture)
                        .map_err(at_codes);
                }
                acq
            }
            None => Acquisition::new(self.geometry, pulse, codes, self.tiles, self.streaming)
                .map_err(at_codes)?,
        };
        Ok(if self.architecture == Architecture::MultiAdc(1) {
            acq.with_code_set_axis()
        } else {
            acq
        })
    }

    /// Reads the measurements `meas` in the shape the architecture needs: (K,) for one ADC,
    /// (R, K) for R ADCs, with a message that says what decides the shape when they disagree.
    ///
    /// # Errors
    /// [`Error::File`] naming `meas` (or its readers' errors).
    pub fn read_measurements<T: Real>(&self, meas: &Path) -> Result<Vec<T>> {
        let h = io::read_header(meas)?;
        let k = self.samples();
        let expect = ShapeExpectation {
            pulse_len: self.pulse_len,
            depth_bins: self.geometry.ks,
            grid: None,
        };
        let float = matches!(h.dtype, NpyDtype::Float32 | NpyDtype::Float64);
        let Some(rows) = self.rows() else {
            if float && h.shape.len() == 2 {
                return Err(file_error(
                    meas,
                    format!(
                        "measurements of shape {} have one row per ADC, but the codes {} are \
                         one code set read as one ADC: for a tiled array pass {} with its tile \
                         size (meta.json \"architecture\" \"tile\")",
                        io::shape_text(&h.shape),
                        self.codes.display(),
                        self.names.tile_hint()
                    ),
                ));
            }
            return io::read_measurements::<T>(meas, Some(&expect));
        };
        let why = match self.architecture {
            Architecture::MultiAdc(sets) => format!(
                "the codes {} of shape {} are {}, one ADC each",
                self.codes.display(),
                io::shape_text(&self.shape),
                count_of(sets, "code set", "code sets")
            ),
            Architecture::Tiles(t) => format!(
                "{} splits the {}x{} array into {}, one ADC each",
                self.names.tile(t),
                self.geometry.m,
                self.geometry.n,
                count_of(rows, "tile", "tiles")
            ),
            _ => String::new(),
        };
        if float {
            let found = match h.shape[..] {
                [_] => Some("are those of one ADC".to_string()),
                [r, _] if r != rows => Some(format!("have {}", count_of(r, "row", "rows"))),
                _ => None,
            };
            if let Some(found) = found {
                return Err(file_error(
                    meas,
                    format!(
                        "measurements of shape {} {found}, but {why}: expected shape ({rows}, \
                         {k})",
                        io::shape_text(&h.shape)
                    ),
                ));
            }
        }
        let y = io::read_measurement_rows::<T>(meas, Some(&expect), Some(rows))?;
        Ok(y.into_raw_vec_and_offset().0)
    }
}

/// The grid of the pixel rows `rows` of `whole`.
fn band_geometry(whole: Geometry, rows: &Range<usize>) -> Geometry {
    Geometry {
        m: rows.len(),
        ..whole
    }
}
