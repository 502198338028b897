//! An acquisition from the files `rdlidar simulate` writes: its codes (an int8 or packed `.npy`
//! array, or a `meta.json` describing them by a seed) described from their header, checked
//! and planned before any data are read, then loaded.

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
    /// This process's band of rows, when the rows are split over processes.
    share: Option<Share>,
}

/// What the messages call the inputs: the command line's flags, or the Python arguments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputNames {
    /// The codes (`--codes`, `codes`).
    pub codes: &'static str,
    /// The tile size (`--tiles`, `tiles`).
    pub tiles: &'static str,
    /// How a tile size is given (`--tiles AxB`, `tiles=(A, B)`).
    pub tile_hint: &'static str,
    /// Streaming asked for (`--stream-codes`, `stream_codes=True`).
    pub stream: &'static str,
}

impl InputNames {
    /// The names of `rdlidar`'s flags.
    pub const COMMAND_LINE: InputNames = InputNames {
        codes: "--codes",
        tiles: "--tiles",
        tile_hint: "--tiles AxB",
        stream: "--stream-codes",
    };
    /// The names of the Python package's arguments.
    pub const PYTHON: InputNames = InputNames {
        codes: "codes",
        tiles: "tiles",
        tile_hint: "tiles=(A, B)",
        stream: "stream_codes=True",
    };

    /// A tile size as given: `--tiles 2x2` or `tiles=(2, 2)`.
    pub fn tile(&self, t: TileSize) -> String {
        if self.tiles.starts_with("--") {
            format!("{} {t}", self.tiles)
        } else {
            format!("{}=({}, {})", self.tiles, t.m, t.n)
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
                    names.tiles
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
            .map_err(|why| fail(why.describe(names.stream)))?;
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
            share: None,
        })
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
        // Whether this process's seeded codes are streamed is decided on its band.
        if let (Some(_), Streaming::Never) = (self.seeded, self.streaming) {
            self.streamed = streams(
                Streaming::Auto,
                true,
                self.architecture,
                share.geometry(),
                self.samples(),
            )
            .unwrap_or(false);
        }
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
        let geometry = self.share.as_ref().map_or(self.geometry, Share::geometry);
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
                self.names.codes,
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
            None if self.share.is_some() => {
                let rows = self.share.as_ref().map_or(0..0, Share::rows);
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
        if let Some(share) = &self.share {
            return self.load_share(share, pulse, codes);
        }
        let acq = Acquisition::new(self.geometry, pulse, codes, self.tiles, self.streaming)
            .map_err(|e| file_error(&self.codes, e.to_string()))?;
        Ok(if self.architecture == Architecture::MultiAdc(1) {
            acq.with_code_set_axis()
        } else {
            acq
        })
    }

    /// This process's share of the acquisition, from its band's `codes` (a seed: the whole's).
    fn load_share(&self, share: &Share, pulse: Vec<f64>, codes: CodeStore) -> Result<Acquisition> {
        let codes = match codes {
            CodeStore::Seeded(s) => CodeStore::Seeded(s.band(share.pixels())?),
            held => held,
        };
        let streaming = if self.streamed {
            Streaming::Always
        } else {
            Streaming::Never
        };
        let at_codes = |e: Error| file_error(&self.codes, e.to_string());
        let acq =
            Acquisition::new(share.geometry(), pulse, codes, None, streaming).map_err(at_codes)?;
        acq.band_of(share.clone(), self.architecture)
            .map_err(at_codes)
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
                        self.names.tile_hint
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
