//! The acquisition: a pulse, the codes of every pixel and how the pixels reach the ADCs (the
//! paper's §3), as one value that knows its geometry, regime, memory plan and architecture
//! and gives the operator the reconstructions run on.
//!
//! An [`Acquisition`] is built from arrays ([`Acquisition::new`]) or from the files that
//! `rdlidar simulate` writes ([`AcquisitionFiles::describe`], then
//! [`AcquisitionFiles::load`]). Every rule about inputs lives here, the same for the command
//! line and the Python package: the pulse is ≥ 0, finite, not all zero and representable in the
//! precision of the computation; the geometry is within [`crate::limits`]; codes fit the
//! geometry and the K = K_p + K_s − 1 samples; measurements are finite and shaped as the
//! architecture says; the memory a request needs is checked before anything is allocated.
//!
//! | architecture | codes | measurements | operator |
//! |---|---|---|---|
//! | one ADC | one code set | (K,) | [`RdOperator`], or [`StreamedOperator`] for large seeded codes |
//! | G ADCs | G code sets | (G, K) | [`MultiAdcOperator`](crate::lidar::MultiAdcOperator) |
//! | tiles of A×B pixels | one code set | (T, K) | block-diagonal: one [`RdOperator`] per tile |
//! | coded aperture | one code set, zero codes for blocked pixels | (K,) | [`RdOperator`] |
//!
//! ```
//! use std::sync::Arc;
//! use rdlidar::acquisition::{Acquisition, CodeStore, Streaming};
//! use rdlidar::lidar::{Codes, Geometry, Pulse};
//!
//! # fn main() -> rdlidar::Result<()> {
//! let g = Geometry::new(4, 4, 6)?;
//! let pulse = Pulse::<f64>::bernoulli(50, 1)?.into_inner();
//! let k = g.samples(pulse.len());
//! let codes = (0..2)
//!     .map(|s| Codes::random_binary(g.pixels(), k, 10 + s).map(Arc::new))
//!     .collect::<rdlidar::Result<Vec<_>>>()?;
//! // Two ADCs, each with its own code set: 2·K measurements.
//! let acq = Acquisition::new(g, pulse, CodeStore::Held(codes), None, Streaming::Never)?;
//! assert_eq!(acq.rows(), Some(2));
//! let op = acq.operator::<f64>()?;
//! assert_eq!(op.nrows(), 2 * k);
//! # Ok(())
//! # }
//! ```

mod arrays;
mod bound;
mod censor;
mod files;
mod outcome;
mod plan;
mod reconstructed;
mod request;
mod returns;
mod rules;
mod share;
mod simulation;
#[cfg(test)]
mod tests;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::error::{Error, Result};
use crate::lidar::{
    multi_adc, packed_len, pixel_groups, tiles, Architecture, Cancellable, CodeAlphabet, Codes,
    DepthMap, Geometry, LidarOperator, Pulse, RdOperator, Regime, Scene, SeededCodes,
    StreamedOperator, TileSize, STREAM_BLOCK_BYTES,
};
use crate::limits::{self, MemoryPlan};
use crate::operator::{BoxedOperator, OperatorExt, Part};
use crate::real::Real;
use crate::recon::{
    reconstruct_observed, tile_places, ArrayCodes, Method, ReconstructOptions, Reconstruction,
    TilePlace, TileReconstruction, TiledArray, TiledReconstruction,
};
use crate::solver::{Control, IterationInfo};

pub use arrays::{code_array, CodeArray, CodeArrayView};
pub use bound::RangeComparison;
pub use censor::{at_top, Censoring, Clipping};
pub use files::{AcquisitionFiles, InputNames};
pub use outcome::{Outcome, Run, Summary, TileRun};
pub use plan::Use;
pub(crate) use plan::{held, plan, streams};
pub use reconstructed::{observe_nothing, Reconstructed};
pub use request::{ReconstructRequest, RECONSTRUCT_SCENES};
pub use rules::{check_finite, check_finite_result, check_pulse, count_of, pulse_in};
pub use share::Share;
pub use simulation::{
    check_simulation_dir, codes_shape, simulation_meta, write_simulation,
    write_simulation_cancellable, CodesFormat, SimulationRequest, SCENES,
};

/// Seeded codes of one ADC larger than this (as packed bits) are regenerated block by block
/// on every application ([`StreamedOperator`]) under [`Streaming::Auto`].
pub const STREAM_ABOVE_BYTES: u128 = 1 << 30;

/// Where the codes of an acquisition come from.
#[derive(Debug, Clone)]
pub enum CodeStore {
    /// Codes held in memory: one code set per ADC for several ADCs, one otherwise.
    Held(Vec<Arc<Codes>>),
    /// Codes described by a seed: every code set of the acquisition.
    Seeded(SeededCodes),
}

/// Whether seeded codes of one ADC are held or regenerated block by block on every
/// application.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Streaming {
    /// Streamed when holding them would take more than [`STREAM_ABOVE_BYTES`].
    #[default]
    Auto,
    /// Always streamed (seeded codes of one ADC only).
    Always,
    /// Never streamed.
    Never,
}

/// An acquisition: the pulse, the codes and the architecture, checked against each other.
#[derive(Debug, Clone)]
pub struct Acquisition {
    geometry: Geometry,
    pulse: Vec<f64>,
    architecture: Architecture,
    codes: CodeStore,
    streamed: bool,
    /// This process's band of rows, when the rows are split over processes.
    share: Option<Share>,
}

impl Acquisition {
    /// The acquisition of `geometry` with the pulse `pulse`, the codes `codes` and one ADC per
    /// tile of `tiles` pixels (None: one ADC per code set). Seeded codes are generated here
    /// unless they are streamed (see [`Streaming`]) or the array is tiled (each tile's codes
    /// are generated when needed).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`]: the pulse ([`check_pulse`]); a geometry beyond
    /// [`Geometry::check_bounds`](crate::lidar::Geometry::check_bounds) (`size`); no code sets, more than [`limits::MAX_ADCS`], or
    /// code sets without M·N pixels and K samples (`codes`); tiles with several code sets, or
    /// more tiles than [`limits::MAX_ADCS`] (`tiles`); streaming asked of codes that are not
    /// seeded codes of one ADC (`stream`).
    pub fn new(
        geometry: Geometry,
        pulse: Vec<f64>,
        codes: CodeStore,
        tiles: Option<TileSize>,
        streaming: Streaming,
    ) -> Result<Self> {
        check_pulse(&pulse)?;
        geometry.check_bounds()?;
        let k = geometry.samples(pulse.len());
        let sets = match &codes {
            CodeStore::Held(sets) => {
                for (i, c) in sets.iter().enumerate() {
                    if c.pixels() != geometry.pixels() || c.len() != k {
                        return Err(Error::param(
                            "codes",
                            format!(
                                "code set {i} has {} of {} samples, but the {geometry} scene \
                                 and the pulse of {} samples need {} of K = K_p + K_s − 1 = {k}",
                                count_of(c.pixels(), "pixel", "pixels"),
                                c.len(),
                                pulse.len(),
                                count_of(geometry.pixels(), "pixel", "pixels"),
                            ),
                        ));
                    }
                }
                sets.len()
            }
            CodeStore::Seeded(s) => {
                if s.pixels() != geometry.pixels() || s.len() != k {
                    return Err(Error::param(
                        "codes",
                        format!(
                            "seeded codes of {} pixels and {} samples do not fit the {geometry} \
                             scene and K = {k}",
                            s.pixels(),
                            s.len()
                        ),
                    ));
                }
                s.sets()
            }
        };
        if sets == 0 {
            return Err(Error::param("codes", "need at least one code set"));
        }
        limits::check_count("codes", sets, limits::MAX_ADCS)?;
        let architecture = match (sets, tiles) {
            (1, Some(t)) => {
                let count = t.count(geometry.m, geometry.n);
                if count > limits::MAX_ADCS {
                    return Err(Error::param(
                        "tiles",
                        format!(
                            "{t} splits {geometry} into {count} tiles, more than the limit of \
                             {} ADCs",
                            limits::MAX_ADCS
                        ),
                    ));
                }
                Architecture::Tiles(t)
            }
            (g, Some(t)) => {
                return Err(Error::param(
                    "tiles",
                    format!(
                        "{g} code sets are {g} ADCs already; tiles of {t} and several code \
                         sets are not supported together"
                    ),
                ))
            }
            (1, None) => Architecture::Single,
            (g, None) => Architecture::MultiAdc(g),
        };
        let seeded = matches!(codes, CodeStore::Seeded(_));
        let streamed = streams(streaming, seeded, architecture, geometry, k)
            .map_err(|why| Error::param("stream", why.describe("streaming")))?;
        // Seeded codes are generated now unless streamed or tiled (then on demand).
        let codes = match codes {
            CodeStore::Seeded(s)
                if !streamed && !matches!(architecture, Architecture::Tiles(_)) =>
            {
                CodeStore::Held(
                    (0..s.sets())
                        .map(|g| s.materialize(g).map(Arc::new))
                        .collect::<Result<Vec<_>>>()?,
                )
            }
            other => other,
        };
        Ok(Acquisition {
            geometry,
            pulse,
            architecture,
            codes,
            streamed,
            share: None,
        })
    }

    /// Checks the shape of an acquisition given as arrays, before any is copied: `sets` code
    /// sets of `m`×`n` pixels, `depth_bins` depth bins, a pulse of `pulse_len` samples and
    /// tiles of `tiles` pixels; then that a request on it with `scenes` scenes fits in memory
    /// in `T`. Returns the geometry.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming `codes`, `depth_bins`, `pulse` or `tiles` for a count
    /// beyond [`crate::limits`]; [`Error::TooLarge`] for a request beyond memory.
    pub fn check_arrays<T: Real>(
        (sets, m, n): (usize, usize, usize),
        depth_bins: usize,
        pulse_len: usize,
        tiles: Option<TileSize>,
        scenes: u128,
    ) -> Result<Geometry> {
        limits::check_count("depth_bins", depth_bins, limits::MAX_DEPTH_BINS)?;
        limits::check_count("pulse", pulse_len, limits::MAX_PULSE_LEN)?;
        limits::check_count("codes", sets, limits::MAX_ADCS)?;
        if m == 0 || n == 0 || m > limits::MAX_SIDE || n > limits::MAX_SIDE {
            return Err(Error::param(
                "codes",
                format!(
                    "{m}x{n} pixels: 1 to {} pixel rows and columns",
                    limits::MAX_SIDE
                ),
            ));
        }
        let g = Geometry::new(m, n, depth_bins)?;
        let rows = match tiles {
            Some(t) => {
                let count = t.count(m, n);
                limits::check_count("tiles", count, limits::MAX_ADCS)?;
                count
            }
            None => sets,
        };
        plan::<T>(g, pulse_len, &[(g, sets)], rows, scenes)
            .add(
                "a copy of one code set",
                (m * n) as u128,
                g.samples(pulse_len),
            )
            .check(
                &format!("an acquisition of {g} with K_p = {pulse_len}"),
                "use smaller arrays or free memory",
            )?;
        Ok(g)
    }

    /// One code set given with a code-set axis ((1, M, N, K) codes): one ADC whose
    /// measurements are one row (1, K), as the command line reads such a file.
    pub fn with_code_set_axis(mut self) -> Self {
        if self.architecture == Architecture::Single {
            self.architecture = Architecture::MultiAdc(1);
        }
        self
    }

    /// The scene grid.
    pub fn geometry(&self) -> Geometry {
        self.geometry
    }

    /// The pulse, as given.
    pub fn pulse(&self) -> &[f64] {
        &self.pulse
    }

    /// The pulse length K_p.
    pub fn pulse_len(&self) -> usize {
        self.pulse.len()
    }

    /// Samples per ADC: K = K_p + K_s − 1.
    pub fn samples(&self) -> usize {
        self.geometry.samples(self.pulse.len())
    }

    /// How the pixels reach the ADCs: one ADC, G ADCs or tiles. A coded aperture is one ADC
    /// whose blocked pixels have zero codes ([`Acquisition::observed_pixels`]).
    pub fn architecture(&self) -> Architecture {
        self.architecture
    }

    /// Rows of the measurements: `None` for the (K,) vector of one ADC, `Some(R)` for (R, K).
    pub fn rows(&self) -> Option<usize> {
        let g = self.whole_geometry();
        self.architecture.rows(g.m, g.n)
    }

    /// The number of measurements: K, or R·K for R ADCs.
    pub fn measurements(&self) -> usize {
        self.rows().unwrap_or(1) * self.samples()
    }

    /// The regime of every measurement against the unknowns; for tiles, of one tile's
    /// measurements against the largest tile's unknowns.
    pub fn regime(&self) -> Regime {
        match self.architecture {
            Architecture::Tiles(t) => Regime::of(
                self.samples(),
                t.m.min(self.geometry.m) * t.n.min(self.geometry.n) * self.geometry.ks,
            ),
            _ => Regime::of(self.measurements(), self.whole_geometry().voxels()),
        }
    }

    /// The codes.
    pub fn codes(&self) -> &CodeStore {
        &self.codes
    }

    /// Whether the codes are regenerated from their seed block by block on every application.
    pub fn is_streamed(&self) -> bool {
        self.streamed
    }

    /// "binary" if every code is ±1, "ternary" otherwise.
    pub fn alphabet(&self) -> CodeAlphabet {
        match &self.codes {
            CodeStore::Held(sets) if sets.iter().any(|c| c.alphabet() == CodeAlphabet::Ternary) => {
                CodeAlphabet::Ternary
            }
            _ => CodeAlphabet::Binary,
        }
    }

    /// Per pixel, whether it reaches an ADC (some code of it is nonzero); `None` when every
    /// pixel does.
    pub fn observed_pixels(&self) -> Option<Vec<bool>> {
        match &self.codes {
            CodeStore::Held(sets) => {
                let mut seen = vec![false; self.geometry.pixels()];
                for c in sets {
                    for (s, o) in seen.iter_mut().zip(c.observed_pixels()) {
                        *s |= o;
                    }
                }
                seen.iter().any(|&s| !s).then_some(seen)
            }
            CodeStore::Seeded(_) => None,
        }
    }

    /// The memory one request on this acquisition needs in `T`: the codes held at once with
    /// the operators' buffers (as `request` uses them), `scenes` scenes (inputs, outputs, a
    /// solver's working copies) and two copies of the measurements.
    pub fn memory_plan<T: Real>(&self, scenes: u128, request: Use) -> MemoryPlan {
        let held = held(
            self.geometry,
            self.samples(),
            self.architecture,
            matches!(self.codes, CodeStore::Seeded(_)),
            self.streamed,
            request,
        );
        plan::<T>(
            self.geometry,
            self.pulse.len(),
            &held,
            self.rows().unwrap_or(1),
            scenes,
        )
    }

    /// The memory a solver adds to an operator already built: `scenes` scenes and two copies
    /// of the measurements (and, for a tiled acquisition, the tiles being solved).
    pub fn solver_memory_plan<T: Real>(&self, scenes: u128) -> MemoryPlan {
        let held: Vec<(Geometry, usize)> = match self.architecture {
            Architecture::Tiles(_) => held(
                self.geometry,
                self.samples(),
                self.architecture,
                true,
                false,
                Use::Reconstruct,
            ),
            _ => Vec::new(),
        };
        plan::<T>(
            self.geometry,
            self.pulse.len(),
            &held,
            self.rows().unwrap_or(1),
            scenes,
        )
    }

    /// The measurement operator of any architecture, in `T`, with the acquisition's pulse.
    ///
    /// # Errors
    /// The pulse is not representable in `T` ([`pulse_in`]); the errors of the operators'
    /// constructors.
    pub fn operator<T: Real>(&self) -> Result<BoxedOperator<T>> {
        self.operator_with_pulse(pulse_in::<T>(&self.pulse)?)
    }

    /// The measurement operator of any architecture with another pulse of the same length
    /// (e.g. the zero-mean pulse of the debiased backprojection).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`pulse`) for another length; the operators' errors.
    pub fn operator_with_pulse<T: Real>(&self, pulse: Vec<T>) -> Result<BoxedOperator<T>> {
        self.check_pulse_len(pulse.len())?;
        if let Architecture::Tiles(t) = self.architecture {
            if self.share.is_some() {
                return Err(Error::param(
                    "tiles",
                    format!(
                        "the tiles of {t} are dealt to processes: each process reconstructs its \
                         own (Acquisition::reconstruct); the block-diagonal operator of the \
                         whole array is one process's"
                    ),
                ));
            }
            let g = self.geometry;
            let groups = tiles(g, t.m, t.n)?;
            return match &self.codes {
                CodeStore::Held(sets) => Ok(pixel_groups(g, &pulse, &sets[0], &groups)?.boxed()),
                CodeStore::Seeded(s) => {
                    Ok(pixel_groups(g, &pulse, &s.materialize(0)?, &groups)?.boxed())
                }
            };
        }
        Ok(self.lidar_operator_with_pulse(pulse)?.boxed())
    }

    fn check_pulse_len(&self, len: usize) -> Result<()> {
        if len != self.pulse.len() {
            return Err(Error::param(
                "pulse",
                format!(
                    "{len} samples, but the acquisition's pulse has {}",
                    self.pulse.len()
                ),
            ));
        }
        Ok(())
    }

    /// The lidar operator that the reconstructions run on, in `T`: one ADC, G ADCs or
    /// streamed codes. A tiled acquisition is reconstructed tile by tile
    /// ([`Acquisition::tiled`]).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`tiles`) for a tiled acquisition; the pulse is not
    /// representable in `T`; the operators' errors.
    pub fn lidar_operator<T: Real>(&self) -> Result<Box<dyn LidarOperator<T>>> {
        self.lidar_operator_with_pulse(pulse_in::<T>(&self.pulse)?)
    }

    fn lidar_operator_with_pulse<T: Real>(
        &self,
        pulse: Vec<T>,
    ) -> Result<Box<dyn LidarOperator<T>>> {
        self.check_pulse_len(pulse.len())?;
        let g = self.geometry;
        let op: Box<dyn LidarOperator<T>> = match (&self.codes, self.architecture) {
            (_, Architecture::Tiles(t)) => {
                return Err(Error::param(
                    "tiles",
                    format!(
                        "a tiled acquisition (tiles of {t}) is block-diagonal: reconstruct it \
                         tile by tile"
                    ),
                ))
            }
            (CodeStore::Seeded(s), _) => Box::new(StreamedOperator::new(g, pulse, *s, 0)?),
            (CodeStore::Held(sets), Architecture::MultiAdc(_)) => {
                Box::new(multi_adc(g, &pulse, sets.clone())?)
            }
            (CodeStore::Held(sets), _) => Box::new(RdOperator::new(g, pulse, sets[0].clone())?),
        };
        Ok(match &self.share {
            Some(share) => Box::new(Part::new(op, Arc::clone(share.space()))),
            None => op,
        })
    }

    /// The tiled array of a tiled acquisition, with the pulse `pulse` (in `T`).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`tiles`) when the acquisition is not tiled.
    pub fn tiled<'a, T: Real>(&'a self, pulse: &'a [T]) -> Result<TiledArray<'a, T>> {
        let Architecture::Tiles(t) = self.architecture else {
            return Err(Error::param("tiles", "the acquisition is not tiled"));
        };
        let codes: ArrayCodes<'a> = match &self.codes {
            CodeStore::Held(sets) => sets[0].as_ref().into(),
            CodeStore::Seeded(s) => (*s).into(),
        };
        TiledArray::new(self.geometry, pulse, codes, t)
    }

    /// The tiles of a tiled acquisition, row-major (edge tiles clipped); none otherwise.
    pub fn tile_places(&self) -> Vec<TilePlace> {
        match self.architecture {
            Architecture::Tiles(t) => tile_places(self.geometry, t).unwrap_or_default(),
            _ => Vec::new(),
        }
    }

    /// The sub-acquisition of one tile of a tiled acquisition: one ADC summing the tile's
    /// pixels, on the tile's own grid, with their codes (seeded codes are generated for the
    /// tile's pixels only). Its measurements are row `place.index` of the whole one's.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`tiles`) when the acquisition is not tiled or `place` is
    /// not one of its tiles.
    pub fn tile(&self, place: &TilePlace) -> Result<Acquisition> {
        if !self.tile_places().contains(place) {
            return Err(Error::param(
                "tiles",
                format!("tile {} is not a tile of this acquisition", place.index),
            ));
        }
        let pixels = place.pixels(self.geometry);
        let codes = match &self.codes {
            CodeStore::Held(sets) => sets[0].select_pixels(&pixels)?,
            CodeStore::Seeded(s) => s.select(0, &pixels)?,
        };
        Acquisition::new(
            place.geometry,
            self.pulse.clone(),
            CodeStore::Held(vec![Arc::new(codes)]),
            None,
            Streaming::Never,
        )
    }

    /// Checks measurements for this acquisition: [`Acquisition::measurements`] values (rows
    /// of K samples, one per ADC), every one finite. `what` names them (`meas`, a flag).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming `what`.
    pub fn check_measurements<T: Real>(&self, y: &[T], what: &'static str) -> Result<()> {
        if y.len() != self.measurements() {
            let shape = match self.rows() {
                None => format!("({},)", self.samples()),
                Some(r) => format!("({r}, {}): {}", self.samples(), self.rows_why()),
            };
            return Err(Error::param(
                what,
                format!(
                    "expected {} values, shape {shape}; got {}",
                    self.measurements(),
                    y.len()
                ),
            ));
        }
        check_finite(y, what)
    }

    /// Why the measurements have the rows they have.
    pub(crate) fn rows_why(&self) -> String {
        let g = self.geometry;
        match self.architecture {
            Architecture::MultiAdc(s) => format!("{s} code sets, one ADC each"),
            Architecture::Tiles(t) => format!(
                "tiles of {t} split the {}x{} array into {}, one ADC each",
                g.m,
                g.n,
                count_of(t.count(g.m, g.n), "tile", "tiles")
            ),
            _ => "one ADC".to_string(),
        }
    }

    /// Reconstructs the scene from `y` (every ADC's rows, one after the other) by `method`,
    /// whatever the architecture: through the lidar operator, or tile by tile in parallel for
    /// a tiled acquisition (`on_tile` is called as each tile finishes, from its worker thread).
    /// `observe` sees every iteration of every solver (with the tile's index for tiles, 0
    /// otherwise); [`Control::Stop`] ends the solver that reported it.
    ///
    /// # Errors
    /// [`Acquisition::check_measurements`]; the pulse is not representable in `T`; the
    /// errors of the reconstruction.
    pub fn reconstruct<T: Real>(
        &self,
        y: &[T],
        method: Method,
        options: &ReconstructOptions,
        observe: &(dyn Fn(usize, &IterationInfo<'_, T>) -> Control + Sync),
        on_tile: &(dyn Fn(&TileReconstruction<T>) + Sync),
    ) -> Result<Reconstructed<T>> {
        let never = AtomicBool::new(false);
        self.reconstruct_cancellable(y, method, options, observe, on_tile, &never)
    }

    /// [`Acquisition::reconstruct`], cancelled by `cancel`: once it is raised (from another
    /// thread, e.g. on Ctrl-C), every solver ends within one operator application, however
    /// deep in its work it is, and the result is [`Error::Cancelled`].
    ///
    /// # Errors
    /// As [`Acquisition::reconstruct`]; [`Error::Cancelled`] when `cancel` was raised.
    pub fn reconstruct_cancellable<T: Real>(
        &self,
        y: &[T],
        method: Method,
        options: &ReconstructOptions,
        observe: &(dyn Fn(usize, &IterationInfo<'_, T>) -> Control + Sync),
        on_tile: &(dyn Fn(&TileReconstruction<T>) + Sync),
        cancel: &AtomicBool,
    ) -> Result<Reconstructed<T>> {
        self.check_measurements(y, "meas")?;
        let cancelled = || {
            cancel.load(Ordering::Relaxed).then(|| Error::Cancelled {
                what: format!("reconstruct ({})", method.name()),
            })
        };
        let r = if matches!(self.architecture, Architecture::Tiles(_)) {
            let pulse = pulse_in::<T>(&self.pulse)?;
            let tiled = self.tiled(&pulse)?.cancelled_by(cancel);
            match self.share.as_ref().and_then(|s| Some((s, s.tiles()?))) {
                None => tiled
                    .reconstruct_observed(y, method, options, observe, on_tile)
                    .map(Reconstructed::Tiled),
                // A dealt tile comes back as its depth map and scene, not its returns.
                Some(_) if !options.response.is_delta() => Err(Error::param(
                    "kernel",
                    format!(
                        "continuous depths (`kernel={}`) are estimated in one process: run \
                         without mpirun",
                        options.response
                    ),
                )),
                Some((share, mine)) => self.reconstruct_dealt(
                    &tiled,
                    share,
                    mine,
                    (y, method, options),
                    observe,
                    on_tile,
                ),
            }
        } else {
            let op = self.lidar_operator::<T>()?;
            let op = Cancellable::new(op, cancel);
            let mut observer = |info: &IterationInfo<'_, T>| observe(0, info);
            reconstruct_observed(&op, y, method, options, &mut observer).map(Reconstructed::Single)
        };
        match cancelled() {
            Some(e) => Err(e),
            None => r,
        }
    }
}
