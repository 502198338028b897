//! One simulated acquisition: a scene, a pulse, the code sets of an architecture, the
//! measurements and their noise, every random draw seeded from one base seed ([`Seeds`]).
//!
//! `rdlidar simulate` and the experiments both simulate through [`simulate`], so a problem of an
//! experiment is exactly the one `rdlidar simulate --seed SEED` writes.
//!
//! ```
//! use rdlidar::lidar::{simulate, Geometry, SceneSpec, SimulationSpec};
//!
//! # fn main() -> rdlidar::Result<()> {
//! let spec = SimulationSpec::new(Geometry::new(8, 8, 10)?, 400, 7);
//! let sim = simulate::<f64>(&spec)?;
//! assert_eq!(sim.meas.len(), 400 + 10 - 1);
//! assert_eq!(spec.scene, SceneSpec::Paper);
//! # Ok(())
//! # }
//! ```

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::error::{Error, Result};
use crate::limits::{self, MemoryPlan};
use crate::operator::{BoxedOperator, LinearOperator, OperatorExt};
use crate::real::Real;

use super::architectures::{aperture_pixels, coded_aperture, multi_adc, pixel_groups, tiles};
use super::seeded::SeededCodes;
use super::{
    codes::CodeAlphabet, paper_scene, random_opaque_scene, semi_transparent_scene, Architecture,
    Codes, FullScale, Geometry, NoiseModel, NoiseReport, NoiseStage, Pulse, RdOperator, Scene,
};

/// The seeds of a simulation, all derived from one base seed: the pulse from SEED, code set g
/// from SEED + 1 + 1000·g, the noise from SEED + 2, a random scene from SEED + 3 and a coded
/// aperture's pixels from SEED + 4 (wrapping).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Seeds {
    /// The base seed.
    pub base: u64,
}

impl Seeds {
    /// The seeds derived from `base`.
    pub fn new(base: u64) -> Self {
        Seeds { base }
    }

    /// The pulse's seed.
    pub fn pulse(&self) -> u64 {
        self.base
    }

    /// The seed of code set `set` (set 0 for a single code set).
    pub fn code_set(&self, set: usize) -> u64 {
        self.base
            .wrapping_add(1)
            .wrapping_add(1000u64.wrapping_mul(set as u64))
    }

    /// The noise's seed.
    pub fn noise(&self) -> u64 {
        self.base.wrapping_add(2)
    }

    /// A random scene's seed.
    pub fn scene(&self) -> u64 {
        self.base.wrapping_add(3)
    }

    /// The seed of a coded aperture's pixel selection.
    pub fn aperture(&self) -> u64 {
        self.base.wrapping_add(4)
    }
}

/// The scene of a simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SceneSpec {
    /// The paper's scene ([`paper_scene`]), deterministic.
    Paper,
    /// A random opaque scene ([`random_opaque_scene`]) with this fraction of lit pixels.
    Random {
        /// Probability that a pixel has a return.
        lit_fraction: f64,
    },
    /// A semi-transparent scene ([`semi_transparent_scene`]) with 1 to min(3, K_s) returns per
    /// pixel.
    Transparent,
    /// A scene the caller supplies (for example one read from a depth map): pass it to
    /// [`simulate_supplied`] or [`simulate_split_supplied`]; [`SceneSpec::generate`] refuses it.
    Supplied,
}

impl SceneSpec {
    /// "paper", "random" or "transparent".
    pub fn name(&self) -> &'static str {
        match self {
            SceneSpec::Paper => "paper",
            SceneSpec::Random { .. } => "random",
            SceneSpec::Transparent => "transparent",
            SceneSpec::Supplied => "supplied",
        }
    }

    /// The range of returns per pixel of a semi-transparent scene of `ks` depth bins.
    pub fn returns_per_pixel(&self, ks: usize) -> Option<[usize; 2]> {
        match self {
            SceneSpec::Transparent => Some([1, 3.min(ks)]),
            _ => None,
        }
    }

    /// The scene itself, random ones drawn from `seeds.scene()`.
    ///
    /// # Errors
    /// The generators' errors; [`Error::InvalidParameter`] (`scene`) for
    /// [`SceneSpec::Supplied`], which has no generator.
    pub fn generate<T: Real>(&self, g: Geometry, seeds: Seeds) -> Result<Scene<T>> {
        match *self {
            SceneSpec::Supplied => Err(Error::param(
                "scene",
                "a supplied scene has no generator: pass it to simulate_supplied",
            )),
            SceneSpec::Paper => paper_scene(g),
            SceneSpec::Random { lit_fraction } => {
                random_opaque_scene(g, lit_fraction, seeds.scene())
            }
            SceneSpec::Transparent => semi_transparent_scene(g, 1..=3.min(g.ks), seeds.scene()),
        }
    }
}

/// Photon (shot) noise of a simulation, as [`add_photon_noise`](super::add_photon_noise)
/// models it: each ADC's sample k gets the noise of Poisson(photons · (light\[k\] + background))
/// counts, light\[k\] the unmodulated light of the pixels it sums.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotonNoise {
    /// Photon count per unit intensity (finite, > 0).
    pub photons: f64,
    /// Background light and dark counts per sample, in units of intensity (finite, ≥ 0).
    pub background: f64,
}

/// The ADC's quantization of a simulation, as [`quantize`](super::quantize) models it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdcQuantization {
    /// Bit depth, 1 … 32.
    pub bits: u32,
    /// The full scale: fixed, or the largest |y| of each ADC's noisy samples.
    pub full_scale: FullScale,
}

/// What to simulate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimulationSpec {
    /// M×N pixels, K_s depth bins.
    pub geometry: Geometry,
    /// Pulse length K_p.
    pub pulse_len: usize,
    /// The base seed of every draw ([`Seeds`]).
    pub seed: u64,
    /// The scene.
    pub scene: SceneSpec,
    /// `None` for ±1 codes; `Some(p)` for {−1, 0, +1} codes with zeros of probability p.
    pub ternary_zero_prob: Option<f64>,
    /// How the pixels reach the ADCs.
    pub architecture: Architecture,
    /// Gaussian noise at this SNR (dB) on the measurements; `None` for none.
    pub snr_db: Option<f64>,
    /// Photon noise, drawn before the Gaussian noise; `None` for none.
    pub photon_noise: Option<PhotonNoise>,
    /// The ADC's quantization, applied last (to each ADC's row of samples); `None` for
    /// measurements of full precision.
    pub quantization: Option<AdcQuantization>,
    /// ±1 codes from the seeded stream of [`SeededCodes`] (key: the first code set's seed,
    /// [`Seeds::code_set`]`(0)`), which can be regenerated pixel by pixel without a file,
    /// instead of [`Codes::random_binary`]'s stream. Not with ternary codes.
    pub seeded_codes: bool,
}

impl SimulationSpec {
    /// The paper's scene, ±1 codes, one ADC, no noise.
    pub fn new(geometry: Geometry, pulse_len: usize, seed: u64) -> Self {
        SimulationSpec {
            geometry,
            pulse_len,
            seed,
            scene: SceneSpec::Paper,
            ternary_zero_prob: None,
            architecture: Architecture::Single,
            snr_db: None,
            photon_noise: None,
            quantization: None,
            seeded_codes: false,
        }
    }

    /// The seeded description of its codes ([`SimulationSpec::seeded_codes`]), `None` when its
    /// codes are drawn otherwise.
    ///
    /// # Errors
    /// As [`SeededCodes::new`], and [`Error::InvalidParameter`] for a pulse length that
    /// overflows.
    pub fn seeded(&self) -> Result<Option<SeededCodes>> {
        if !self.seeded_codes {
            return Ok(None);
        }
        let g = self.geometry;
        let sets = self.architecture.code_sets();
        SeededCodes::new(self.seeds().code_set(0), sets, g.pixels(), self.samples()?).map(Some)
    }

    /// The seeds of its draws.
    pub fn seeds(&self) -> Seeds {
        Seeds::new(self.seed)
    }

    /// Checks the request against [`crate::limits`] (grid, pulse length, ADCs) and returns the
    /// memory simulating it in `T` needs: the scene, each code set with its operator's
    /// buffers, the measurements and their noise.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the setting beyond its bound (`size`, `pulse_len`,
    /// `adcs`).
    pub fn memory_plan<T: Real>(&self) -> Result<MemoryPlan> {
        let g = self.geometry;
        g.check_bounds()?;
        limits::check_count("pulse_len", self.pulse_len, limits::MAX_PULSE_LEN)?;
        let sets = self.architecture.code_sets();
        limits::check_count("adcs", sets, limits::MAX_ADCS)?;
        let k = self.samples()?;
        let rows = self.architecture.rows(g.m, g.n).unwrap_or(1);
        let alphabet = match self.ternary_zero_prob {
            None => CodeAlphabet::Binary,
            Some(_) => CodeAlphabet::Ternary,
        };
        let size = std::mem::size_of::<T>();
        let operator = RdOperator::<T>::estimated_memory_bytes(
            g,
            self.pulse_len,
            alphabet,
            rayon::current_num_threads(),
        )
        .map_or(u128::MAX, |b| b as u128);
        let samples = (rows as u128).saturating_mul(k as u128);
        Ok(MemoryPlan::new()
            .add("scene", g.voxels() as u128, size)
            .add(
                "codes and operator",
                operator.saturating_mul(sets as u128),
                1,
            )
            .add("measurements", samples.saturating_mul(2), size))
    }

    /// Checks, before any work, that the ADC's levels are finite in `T` (a fixed full scale
    /// beyond the range of `f32` would turn every quantized sample into an infinity).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`full_scale`), as [`NoiseStage::validate_in`].
    pub fn check_quantization<T: Real>(&self) -> Result<()> {
        match self.quantization {
            Some(q) => NoiseStage::Quantized {
                bits: q.bits,
                full_scale: q.full_scale,
            }
            .validate_in::<T>(),
            None => Ok(()),
        }
    }

    /// Number of measurements per ADC, K = K_p + K_s − 1.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`pulse_len`) if it overflows.
    pub fn samples(&self) -> Result<usize> {
        self.pulse_len
            .checked_add(self.geometry.ks - 1)
            .ok_or_else(|| Error::param("pulse_len", format!("{} is too large", self.pulse_len)))
    }
}

/// A simulated acquisition.
#[derive(Debug)]
pub struct Simulation<T> {
    /// What was simulated.
    pub spec: SimulationSpec,
    /// The true scene.
    pub scene: Scene<T>,
    /// The pulse.
    pub pulse: Pulse<T>,
    /// The code sets, one per ADC for [`Architecture::MultiAdc`], one otherwise.
    pub code_sets: Vec<Arc<Codes>>,
    /// The pixels that reach the ADC, in increasing order ([`Architecture::Aperture`] only).
    pub active: Option<Vec<usize>>,
    /// The pixel groups of the tiles, row-major ([`Architecture::Tiles`] only).
    pub groups: Option<Vec<Vec<usize>>>,
    /// The measurements, ADC by ADC (R·K values for R ADCs).
    pub meas: Vec<T>,
    /// What the noise did (`None` when noise-free).
    pub noise: Option<NoiseReport>,
    /// Where a supplied scene came from (for example its depth map's file name), as the caller
    /// describes it; `meta.json` records it. `None` for generated scenes.
    pub scene_source: Option<String>,
    /// The returns at continuous depths the scene was rendered from, when the caller rendered
    /// it from returns ([`Returns::render`](super::Returns::render)); `range.npy` holds their
    /// depths.
    pub returns: Option<super::Returns>,
    /// The response that rendered [`returns`](Self::returns).
    pub response: Option<super::Response>,
}

impl<T: Real> Simulation<T> {
    /// The measurement operator of the architecture (the one that took [`meas`](Self::meas)).
    ///
    /// # Errors
    /// None for a simulation made by [`simulate`]; the operators' constructors' errors otherwise.
    pub fn operator(&self) -> Result<BoxedOperator<T>> {
        let g = self.spec.geometry;
        let p = self.pulse.as_slice();
        let codes = &self.code_sets[0];
        Ok(
            match (&self.spec.architecture, &self.groups, &self.active) {
                (Architecture::MultiAdc(_), _, _) => {
                    multi_adc(g, p, self.code_sets.clone())?.boxed()
                }
                (Architecture::Tiles(_), Some(groups), _) => {
                    pixel_groups(g, p, codes, groups)?.boxed()
                }
                (Architecture::Aperture(_), _, Some(active)) => {
                    coded_aperture(g, p, codes, active)?.boxed()
                }
                _ => self.single_operator()?.boxed(),
            },
        )
    }

    /// The fused operator of the first code set, every pixel reaching one ADC: the measurement
    /// operator of [`Architecture::Single`].
    ///
    /// # Errors
    /// Those of [`RdOperator::new`].
    pub fn single_operator(&self) -> Result<RdOperator<T>> {
        RdOperator::new(
            self.spec.geometry,
            self.pulse.as_slice().to_vec(),
            self.code_sets[0].clone(),
        )
    }

    /// Rows of the measurements: `None` for one ADC's (K,), `Some(R)` for (R, K).
    pub fn rows(&self) -> Option<usize> {
        let g = self.spec.geometry;
        self.spec.architecture.rows(g.m, g.n)
    }
}

/// Simulates `spec`: draws the scene, the pulse and the codes from its [`Seeds`], measures the
/// scene through the architecture's operator and adds the noise.
///
/// # Errors
/// [`Error::InvalidParameter`] naming the setting for an impossible request (a pulse length
/// that overflows, a zero-size tile, an aperture fraction outside (0, 1], too many ADCs, a
/// ternary zero probability outside [0, 1)); the generators' and operators' errors.
pub fn simulate<T: Real>(spec: &SimulationSpec) -> Result<Simulation<T>> {
    simulate_inner(spec, None, &AtomicBool::new(false))
}

/// [`simulate`] of `scene`, which the caller supplies: `spec.scene` must be
/// [`SceneSpec::Supplied`] and the scene's grid `spec.geometry`.
///
/// # Errors
/// [`Error::InvalidParameter`] (`scene`) for another scene kind or a scene of another grid;
/// the errors of [`simulate`].
pub fn simulate_supplied<T: Real>(spec: &SimulationSpec, scene: Scene<T>) -> Result<Simulation<T>> {
    simulate_inner(spec, Some(scene), &AtomicBool::new(false))
}

/// [`simulate`] (of the scene `supplied`, if any, as [`simulate_supplied`]), cancelled by
/// `cancel`: once it is raised (from another thread, e.g. on Ctrl-C), the simulation stops at
/// its next step (the scene, the pulse, each code set, each tile, the measurement, the noise).
///
/// # Errors
/// As [`simulate`] and [`simulate_supplied`]; [`Error::Cancelled`] when `cancel` was raised.
pub fn simulate_cancellable<T: Real>(
    spec: &SimulationSpec,
    supplied: Option<Scene<T>>,
    cancel: &AtomicBool,
) -> Result<Simulation<T>> {
    simulate_inner(spec, supplied, cancel)
}

/// The scene of `spec`: `supplied` (checked against the spec) or the generated one.
fn scene_of<T: Real>(spec: &SimulationSpec, supplied: Option<Scene<T>>) -> Result<Scene<T>> {
    let g = spec.geometry;
    match (spec.scene, supplied) {
        (SceneSpec::Supplied, Some(scene)) => {
            let found = scene.geometry();
            if found != g {
                return Err(Error::param(
                    "scene",
                    format!("the supplied scene is {found}, the simulation's grid {g}"),
                ));
            }
            Ok(scene)
        }
        (SceneSpec::Supplied, None) => spec.scene.generate(g, spec.seeds()),
        (other, Some(_)) => Err(Error::param(
            "scene",
            format!(
                "a scene was supplied for the {} scene: ask for SceneSpec::Supplied",
                other.name()
            ),
        )),
        (other, None) => other.generate(g, spec.seeds()),
    }
}

fn simulate_inner<T: Real>(
    spec: &SimulationSpec,
    supplied: Option<Scene<T>>,
    cancel: &AtomicBool,
) -> Result<Simulation<T>> {
    let g = spec.geometry;
    let k = spec.samples()?;
    let seeds = spec.seeds();
    let arch = spec.architecture;
    let request = format!(
        "simulating {g} with K_p = {}{}",
        spec.pulse_len,
        arch.describe_suffix()
    );
    let go_on = || {
        if cancel.load(Ordering::Relaxed) {
            Err(Error::Cancelled {
                what: request.clone(),
            })
        } else {
            Ok(())
        }
    };
    spec.memory_plan::<T>()?
        .check(&request, "lower `size`, `pulse_len` or `adcs`")?;
    spec.check_quantization::<T>()?;
    let groups = match arch {
        Architecture::Tiles(t) => Some(tiles(g, t.m, t.n)?),
        _ => None,
    };
    let active = match arch {
        Architecture::Aperture(f) => Some(aperture_pixels(g.pixels(), f, seeds.aperture())?),
        _ => None,
    };
    let scene = scene_of(spec, supplied)?;
    go_on()?;
    let pulse = Pulse::<T>::bernoulli(spec.pulse_len, seeds.pulse())?;
    if spec.seeded_codes && spec.ternary_zero_prob.is_some() {
        return Err(Error::param(
            "codes",
            "seeded codes are ±1 codes: they cannot have the zeros of ternary codes",
        ));
    }
    let seeded = spec.seeded()?;
    let code_sets = (0..arch.code_sets())
        .map(|set| {
            go_on()?;
            let seed = seeds.code_set(set);
            match (spec.ternary_zero_prob, &seeded) {
                (_, Some(s)) => s.materialize(set),
                (None, None) => Codes::random_binary(g.pixels(), k, seed),
                (Some(p), None) => Codes::random_ternary(g.pixels(), k, p, seed),
            }
            .map(Arc::new)
        })
        .collect::<Result<Vec<_>>>()?;
    let sim = Simulation {
        spec: *spec,
        scene,
        pulse,
        code_sets,
        active,
        groups,
        meas: Vec::new(),
        noise: None,
        scene_source: None,
        returns: None,
        response: None,
    };
    let y = match &sim.groups {
        // One tile at a time: only one tile's operator (and copy of its codes) is alive.
        Some(groups) => {
            let mut y = Vec::with_capacity(groups.len() * k);
            for group in groups {
                go_on()?;
                let op = coded_aperture(g, sim.pulse.as_slice(), &sim.code_sets[0], group)?;
                let mut rows = vec![T::zero(); op.nrows()];
                op.apply(sim.scene.as_slice(), &mut rows);
                y.extend(rows);
            }
            y
        }
        None => {
            go_on()?;
            let op = sim.operator()?;
            let mut y = vec![T::zero(); op.nrows()];
            op.apply(sim.scene.as_slice(), &mut y);
            y
        }
    };
    go_on()?;
    sim.measured(y)
}

impl<T: Real> Simulation<T> {
    /// The simulation with the noiseless measurements `y`, and the noise its spec asks for.
    fn measured(mut self, mut y: Vec<T>) -> Result<Self> {
        let spec = self.spec;
        let mut model = NoiseModel::none();
        if let Some(p) = spec.photon_noise {
            model = model.then(NoiseStage::Poisson {
                photons: p.photons,
                background: p.background,
            });
        }
        if let Some(snr_db) = spec.snr_db {
            model = model.then(NoiseStage::Gaussian { snr_db });
        }
        if model.is_none() && spec.quantization.is_none() {
            self.meas = y;
            return Ok(self);
        }
        let light = match spec.photon_noise {
            Some(_) => Some(self.light_per_row(y.len())?),
            None => None,
        };
        let clean = spec.quantization.map(|_| y.clone());
        let mut report =
            model.apply_with_intensity(&mut y, light.as_deref(), spec.seeds().noise())?;
        if let (Some(q), Some(clean)) = (spec.quantization, clean) {
            // Each ADC quantizes its own samples (to its own full scale when automatic).
            let k = spec.samples()?;
            let stage = NoiseModel::none().then(NoiseStage::Quantized {
                bits: q.bits,
                full_scale: q.full_scale,
            });
            for row in y.chunks_mut(k) {
                report.stages.extend(stage.apply(row, 0)?.stages);
            }
            let change: f64 = y
                .iter()
                .zip(&clean)
                .map(|(&a, &b)| (a.as_f64() - b.as_f64()).powi(2))
                .sum();
            report.noise_power = change / y.len().max(1) as f64;
        }
        self.noise = Some(report);
        self.meas = y;
        Ok(self)
    }

    /// The unmodulated light reaching each ADC, one row of K samples per ADC as the
    /// measurements are laid out (`len` samples in all): all pixels' for one ADC or several code
    /// sets, a tile's pixels' per tile, the active pixels' of a coded aperture.
    fn light_per_row(&self, len: usize) -> Result<Vec<T>> {
        let pulse = self.pulse.as_slice();
        let rows = match (&self.groups, &self.active) {
            (Some(groups), _) => groups
                .iter()
                .map(|g| super::unmodulated_light_of(&self.scene, pulse, Some(g)))
                .collect::<Result<Vec<_>>>()?,
            (None, Some(active)) => vec![super::unmodulated_light_of(
                &self.scene,
                pulse,
                Some(active),
            )?],
            (None, None) => {
                let light = super::unmodulated_light(&self.scene, pulse)?;
                let k = light.len().max(1);
                vec![light; len / k]
            }
        };
        Ok(rows.concat())
    }
}

/// [`simulate`] by every part of `space` at once (the processes of an MPI job), with the pixel
/// rows split over them ([`my_band`](crate::space::my_band)): each part generates the seeded
/// codes of its own rows only and measures them, and the parts' measurements are summed (in
/// `f64`), so that no part holds the whole array's codes. The scene, pulse, measurements and
/// noise are the whole simulation's in every part, equal to [`simulate`]'s up to the order of
/// the sums; `code_sets` holds this part's rows' codes only.
///
/// # Errors
/// [`Error::InvalidParameter`]: codes that are not seeded (`codes`), an architecture other
/// than one ADC or several code sets (`architecture`), more parts than pixel rows (`parts`);
/// the errors of [`simulate`].
pub fn simulate_split<T: Real>(
    spec: &SimulationSpec,
    space: &Arc<dyn crate::space::Space>,
) -> Result<Simulation<T>> {
    simulate_split_inner(spec, space, None)
}

/// [`simulate_split`] of a scene the caller supplies (the whole scene, in every part), as
/// [`simulate_supplied`].
///
/// # Errors
/// As [`simulate_split`] and [`simulate_supplied`].
pub fn simulate_split_supplied<T: Real>(
    spec: &SimulationSpec,
    space: &Arc<dyn crate::space::Space>,
    scene: Scene<T>,
) -> Result<Simulation<T>> {
    simulate_split_inner(spec, space, Some(scene))
}

fn simulate_split_inner<T: Real>(
    spec: &SimulationSpec,
    space: &Arc<dyn crate::space::Space>,
    supplied: Option<Scene<T>>,
) -> Result<Simulation<T>> {
    if space.parts() == 1 {
        return simulate_inner(spec, supplied, &AtomicBool::new(false));
    }
    let g = spec.geometry;
    let seeded = spec.seeded()?.ok_or_else(|| {
        Error::param(
            "codes",
            "a simulation split over processes generates seeded codes, each process its own \
             rows': ask for codes described by a seed",
        )
    })?;
    let arch = spec.architecture;
    if !matches!(arch, Architecture::Single | Architecture::MultiAdc(_)) {
        return Err(Error::param(
            "architecture",
            format!(
                "a simulation split over processes has one ADC or several code sets, not {}",
                arch.describe_suffix().trim_start_matches([',', ' '])
            ),
        ));
    }
    if space.parts() > g.m {
        return Err(Error::param(
            "parts",
            format!(
                "{} processes for the {} pixel rows of {g}: at most one process per row",
                space.parts(),
                g.m
            ),
        ));
    }
    let rows = crate::space::my_band(&**space, g.m);
    let band = Geometry { m: rows.len(), ..g };
    SimulationSpec {
        geometry: band,
        ..*spec
    }
    .memory_plan::<T>()?
    .check(
        &format!(
            "simulating the rows {}..{} of {g} with K_p = {}",
            rows.start, rows.end, spec.pulse_len
        ),
        "lower `size` or `pulse_len`, or use more processes",
    )?;
    spec.check_quantization::<T>()?;
    let seeds = spec.seeds();
    let scene = scene_of(spec, supplied)?;
    let pulse = Pulse::<T>::bernoulli(spec.pulse_len, seeds.pulse())?;
    let mine = seeded.band(rows.start * g.n..rows.end * g.n)?;
    let code_sets = (0..arch.code_sets())
        .map(|set| mine.materialize(set).map(Arc::new))
        .collect::<Result<Vec<_>>>()?;
    let op: BoxedOperator<T> = match arch {
        Architecture::MultiAdc(_) => multi_adc(band, pulse.as_slice(), code_sets.clone())?.boxed(),
        _ => RdOperator::new(band, pulse.as_slice().to_vec(), Arc::clone(&code_sets[0]))?.boxed(),
    };
    let part = crate::operator::Part::new(op, Arc::clone(space));
    let ks = g.ks;
    let x = &scene.as_slice()[rows.start * g.n * ks..rows.end * g.n * ks];
    let mut y = vec![T::zero(); part.nrows()];
    part.apply(x, &mut y);
    let sim = Simulation {
        spec: *spec,
        scene,
        pulse,
        code_sets,
        active: None,
        groups: None,
        meas: Vec::new(),
        noise: None,
        scene_source: None,
        returns: None,
        response: None,
    };
    sim.measured(y)
}
