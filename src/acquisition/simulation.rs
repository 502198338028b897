//! A simulated acquisition as the command line and the Python package ask for it: the request
//! checked setting by setting ([`SimulationRequest::spec`]), and the files it is written to
//! ([`write_simulation`]): `scene.npy`, `pulse.npy`, `codes.npy` (int8, packed, or none for
//! seeded codes), `meas.npy` and `meta.json`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use ndarray_npy::WritableElement;

use crate::error::{Error, Result};
use crate::io::meta::{SimulationMeta, RANGE_FILE, SIMULATION_FILES};
use crate::io::{self, StagedFile};
use crate::lidar::{
    packed_len, AdcQuantization, Architecture, FullScale, Geometry, NoiseStage, PhotonNoise,
    Response, SceneSpec, Simulation, SimulationSpec, TileSize, SEEDED_CODES_GENERATOR,
};
use crate::limits;
use crate::real::Real;

/// How the codes of a simulation are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CodesFormat {
    /// `codes.npy` int8 (M, N, K) (or (G, M, N, K)), entries −1, 0, +1.
    #[default]
    Int8,
    /// `codes.npy` uint8 (M, N, ⌈K/8⌉) (or (G, M, N, ⌈K/8⌉)) as `np.packbits(S > 0, axis=-1)`
    /// writes ±1 codes.
    Packed,
    /// No codes file: `meta.json` describes ±1 codes by their seed and stream.
    Seed,
}

impl CodesFormat {
    /// Every format, in the order of [`CodesFormat::name`]'s list.
    pub const ALL: [CodesFormat; 3] = [CodesFormat::Int8, CodesFormat::Packed, CodesFormat::Seed];

    /// "int8", "packed" or "seed".
    pub fn name(self) -> &'static str {
        match self {
            CodesFormat::Int8 => "int8",
            CodesFormat::Packed => "packed",
            CodesFormat::Seed => "seed",
        }
    }
}

impl std::str::FromStr for CodesFormat {
    type Err = Error;

    fn from_str(text: &str) -> Result<Self> {
        CodesFormat::ALL
            .into_iter()
            .find(|f| f.name() == text)
            .ok_or_else(|| {
                Error::param(
                    "codes_format",
                    format!(
                        "{} is not one of \"int8\", \"packed\", \"seed\"",
                        crate::io::meta::excerpt(text)
                    ),
                )
            })
    }
}

/// The scenes a simulation generates or reads, by name ("png": from a depth map, see
/// [`SimulationRequest::depth_png`]).
pub const SCENES: [&str; 4] = ["paper", "random", "transparent", "png"];

/// What a user asks `simulate` for, setting by setting, as the command line and Python take
/// it. [`SimulationRequest::spec`] checks every setting and their combinations; errors name
/// the setting (`lit_fraction`, `aperture`, …).
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationRequest {
    /// "paper", "random", "transparent" or "png".
    pub scene: String,
    /// The png scene's depth map ([`crate::io::scene_from_pngs`]: a value v > 0 of the first
    /// channel is depth bin round(v / full scale · (K_s − 1)), 0 no return); its height and
    /// width must be the grid's M and N.
    pub depth_png: Option<PathBuf>,
    /// The png scene's reflectivity map (same size; amplitude v / full scale), or `None` for
    /// amplitude 1 at every return.
    pub reflectivity_png: Option<PathBuf>,
    /// The grid.
    pub geometry: Geometry,
    /// K_p.
    pub pulse_len: usize,
    /// The base seed.
    pub seed: u64,
    /// A random scene's fraction of lit pixels, in [0, 1] (default 0.5).
    pub lit_fraction: Option<f64>,
    /// Ternary codes with zeros of this probability, in [0, 1).
    pub ternary_zero_prob: Option<f64>,
    /// Gaussian noise at this SNR (dB).
    pub snr_db: Option<f64>,
    /// Photon noise with this photon count per unit intensity (finite, > 0).
    pub photons: Option<f64>,
    /// The photon noise's background light per sample, in units of intensity (finite, ≥ 0;
    /// default 0); only with `photons`.
    pub background: Option<f64>,
    /// An ADC of this many bits (1 … 32) quantizes the measurements.
    pub adc_bits: Option<u32>,
    /// The ADC's full scale (finite, > 0; default: each ADC's largest |sample|); only with
    /// `adc_bits`.
    pub full_scale: Option<f64>,
    /// G ADCs with one code set each (1: one ADC).
    pub adcs: usize,
    /// One ADC per tile of this size.
    pub tiles: Option<TileSize>,
    /// A coded aperture: the fraction of pixels that reach the ADC, in (0, 1].
    pub aperture: Option<f64>,
    /// How the codes are written.
    pub codes_format: CodesFormat,
    /// Reflectors at continuous depths (`true`) or on the grid.
    pub continuous: bool,
    /// The system's response that puts the reflectors on the voxel grid (default: triangle at
    /// continuous depths, delta on the grid).
    pub kernel: Option<Response>,
}

impl SimulationRequest {
    /// The paper's scene on `geometry` with a pulse of `pulse_len` samples from `seed`, one
    /// ADC, ±1 codes written as int8, no noise.
    pub fn new(geometry: Geometry, pulse_len: usize, seed: u64) -> Self {
        SimulationRequest {
            scene: "paper".into(),
            depth_png: None,
            reflectivity_png: None,
            geometry,
            pulse_len,
            seed,
            lit_fraction: None,
            ternary_zero_prob: None,
            snr_db: None,
            photons: None,
            background: None,
            adc_bits: None,
            full_scale: None,
            adcs: 1,
            tiles: None,
            aperture: None,
            codes_format: CodesFormat::Int8,
            continuous: false,
            kernel: None,
        }
    }

    /// The specification the request selects, every setting checked.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the setting: `scene` unknown; `size` beyond
    /// [`Geometry::check_bounds`](crate::lidar::Geometry::check_bounds); `pulse_len` 0 or above [`limits::MAX_PULSE_LEN`];
    /// `lit_fraction` outside [0, 1] or given for another scene than random;
    /// `ternary_zero_prob` outside [0, 1); `snr_db` not finite; `photons`, `background`,
    /// `adc_bits` or `full_scale` out of range, or `background`/`full_scale` alone; `adcs` 0
    /// or above [`limits::MAX_ADCS`]; `aperture` outside (0, 1]; several architectures at once;
    /// `codes_format` packed or seed with codes that have zeros.
    pub fn spec(&self) -> Result<SimulationSpec> {
        self.geometry.check_bounds()?;
        limits::check_count("pulse_len", self.pulse_len, limits::MAX_PULSE_LEN)?;
        limits::check_count("adcs", self.adcs, limits::MAX_ADCS)?;
        let scene = match (self.scene.as_str(), self.lit_fraction) {
            ("paper", None) => SceneSpec::Paper,
            ("png", None) => SceneSpec::Supplied,
            ("transparent", None) => SceneSpec::Transparent,
            ("random", f) => SceneSpec::Random {
                lit_fraction: f.unwrap_or(0.5),
            },
            (name @ ("paper" | "transparent" | "png"), Some(_)) => {
                return Err(Error::param(
                    "lit_fraction",
                    format!("applies only to `scene=random`, not to `scene={name}`"),
                ))
            }
            (other, _) => {
                return Err(Error::param(
                    "scene",
                    format!(
                        "{} is not one of \"paper\", \"random\", \"transparent\", \"png\"",
                        crate::io::meta::excerpt(other)
                    ),
                ))
            }
        };
        self.check_maps(&scene)?;
        if let Some(f) = self.lit_fraction {
            if !(0.0..=1.0).contains(&f) {
                return Err(Error::param(
                    "lit_fraction",
                    format!("must be in [0, 1], got {}", crate::units::number(f)),
                ));
            }
        }
        if let Some(p) = self.ternary_zero_prob {
            if !(0.0..1.0).contains(&p) {
                return Err(Error::param(
                    "ternary_zero_prob",
                    format!("must be in [0, 1), got {}", crate::units::number(p)),
                ));
            }
        }
        if let Some(s) = self.snr_db {
            if !s.is_finite() {
                return Err(Error::param(
                    "snr_db",
                    format!("must be finite, got {}", crate::units::number(s)),
                ));
            }
        }
        let (photon_noise, quantization) = self.noise_stages()?;
        if let Some(f) = self.aperture {
            if !(f > 0.0 && f <= 1.0) {
                return Err(Error::param(
                    "aperture",
                    format!("must be in (0, 1], got {}", crate::units::number(f)),
                ));
            }
        }
        if let Some(t) = self.tiles {
            let count = t.count(self.geometry.m, self.geometry.n);
            if count > limits::MAX_ADCS {
                return Err(Error::param(
                    "tiles",
                    format!(
                        "{t} splits {} into {count} tiles, more than the limit of {} ADCs",
                        self.geometry,
                        limits::MAX_ADCS
                    ),
                ));
            }
        }
        let mut chosen: Vec<(&'static str, String)> = Vec::new();
        if self.adcs > 1 {
            chosen.push(("adcs", format!("`adcs={}`", self.adcs)));
        }
        if let Some(t) = self.tiles {
            chosen.push(("tiles", format!("`tiles={t}`")));
        }
        if let Some(f) = self.aperture {
            chosen.push(("aperture", format!("`aperture={f}`")));
        }
        if let [(_, first), .., (name, last)] = &chosen[..] {
            return Err(Error::param(
                name,
                format!("{first} and {last} are not supported together: choose one architecture"),
            ));
        }
        if self.codes_format != CodesFormat::Int8 {
            let what = match (self.ternary_zero_prob, self.aperture) {
                (Some(p), _) => Some(format!("the zeros of `ternary_zero_prob` {p} codes")),
                (None, Some(f)) => {
                    Some(format!("the zero codes of `aperture` {f}'s blocked pixels"))
                }
                (None, None) => None,
            };
            if let Some(what) = what {
                return Err(Error::param(
                    "codes_format",
                    format!(
                        "`codes_format` {} holds ±1 codes only, not {what}: use int8",
                        self.codes_format.name()
                    ),
                ));
            }
        }
        let architecture = match (self.adcs, self.tiles, self.aperture) {
            (_, Some(t), _) => Architecture::Tiles(t),
            (_, _, Some(f)) => Architecture::Aperture(f),
            (1, _, _) => Architecture::Single,
            (n, _, _) => Architecture::MultiAdc(n),
        };
        // A scene rendered from returns is supplied to the simulation.
        let scene = if self.renders_returns()? {
            SceneSpec::Supplied
        } else {
            scene
        };
        Ok(SimulationSpec {
            scene,
            ternary_zero_prob: self.ternary_zero_prob,
            architecture,
            snr_db: self.snr_db,
            photon_noise,
            quantization,
            seeded_codes: self.codes_format == CodesFormat::Seed,
            ..SimulationSpec::new(self.geometry, self.pulse_len, self.seed)
        })
    }
}

impl SimulationRequest {
    /// The photon noise and the ADC the request asks for, checked.
    fn noise_stages(&self) -> Result<(Option<PhotonNoise>, Option<AdcQuantization>)> {
        let photon_noise = match (self.photons, self.background) {
            (None, None) => None,
            (None, Some(_)) => {
                return Err(Error::param(
                    "background",
                    "is the photon noise's background: it needs `photons` too",
                ))
            }
            (Some(photons), background) => {
                let stage = NoiseStage::Poisson {
                    photons,
                    background: background.unwrap_or(0.0),
                };
                stage.validate()?;
                Some(PhotonNoise {
                    photons,
                    background: background.unwrap_or(0.0),
                })
            }
        };
        let quantization = match (self.adc_bits, self.full_scale) {
            (None, None) => None,
            (None, Some(_)) => {
                return Err(Error::param(
                    "full_scale",
                    "is the ADC's full scale: it needs `adc_bits` too",
                ))
            }
            (Some(bits), full_scale) => {
                let full_scale = full_scale.map_or(FullScale::Auto, FullScale::Fixed);
                NoiseStage::Quantized { bits, full_scale }
                    .validate()
                    .map_err(|e| match e {
                        Error::InvalidParameter {
                            name: "bits",
                            reason,
                        } => Error::InvalidParameter {
                            name: "adc_bits",
                            reason,
                        },
                        other => other,
                    })?;
                Some(AdcQuantization { bits, full_scale })
            }
        };
        Ok((photon_noise, quantization))
    }

    /// Checks that the png maps are given for, and only for, the png scene.
    fn check_maps(&self, scene: &SceneSpec) -> Result<()> {
        match (scene, &self.depth_png, &self.reflectivity_png) {
            (SceneSpec::Supplied, None, _) => {
                return Err(Error::param(
                    "depth_png",
                    "`scene=png` reads its depths from a PNG depth map: give its file",
                ))
            }
            (SceneSpec::Supplied, Some(_), _) => {}
            (other, depth, reflectivity) => {
                if let Some(name) = [("depth_png", depth), ("reflectivity_png", reflectivity)]
                    .into_iter()
                    .find_map(|(name, v)| v.is_some().then_some(name))
                {
                    return Err(Error::param(
                        name,
                        format!(
                            "applies only to `scene=png`, not to `scene={}`",
                            other.name()
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The scene the request reads (the png scene's, in `T`), or `None` when the simulation
    /// generates its scene. The depth map's height and width must be the grid's M and N.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming `depth_png` or `reflectivity_png` for a map whose
    /// header gives another size than the grid's M × N or for a file that cannot be read or
    /// decoded (the reason starting with the file's path), and `depth_png` for a png scene
    /// without the `images` feature;
    /// [`Error::TooLarge`] when the scene would not fit in memory (checked before reading).
    pub fn supplied_scene<T: Real>(&self) -> Result<Option<crate::lidar::Scene<T>>> {
        if let Some(returns) = self.returns()? {
            return returns.render(self.geometry.ks, &self.response()).map(Some);
        }
        #[cfg(feature = "images")]
        return self.read_pngs(std::mem::size_of::<T>(), |depth, reflectivity, ks| {
            io::scene_from_pngs::<T>(depth, reflectivity, ks)
        });
        // Without the feature, read_pngs refuses a png scene before reading.
        #[cfg(not(feature = "images"))]
        self.read_pngs(std::mem::size_of::<T>(), |depth, _, _| {
            Err(Error::param(
                "depth_png",
                format!("{}: needs the `images` feature", depth.display()),
            ))
        })
    }

    /// What `read` makes of the png scene's maps (`None` without a depth map), once the scene of
    /// `bytes` per voxel is known to fit in memory and each map's header to give the grid's
    /// size; errors name `depth_png` or `reflectivity_png`.
    #[cfg_attr(not(feature = "images"), allow(unused_variables))]
    pub(super) fn read_pngs<R>(
        &self,
        bytes: usize,
        read: impl FnOnce(&Path, Option<&Path>, usize) -> Result<R>,
    ) -> Result<Option<R>> {
        let Some(depth) = self.depth_png.as_deref() else {
            return Ok(None);
        };
        #[cfg(feature = "images")]
        {
            let g = self.geometry;
            // The scene read must fit; the simulation checks the rest (one band of rows per
            // process under MPI).
            limits::MemoryPlan::new()
                .add("scene", g.voxels() as u128, bytes)
                .check(
                    &format!(
                        "reading the scene {g} from the depth map {}",
                        depth.display()
                    ),
                    "lower `size`",
                )?;
            // Each map's size from its header, against the grid, before a pixel is decoded.
            let named = |name: &'static str| {
                move |e: Error| match e {
                    Error::InvalidParameter {
                        name: "png",
                        reason,
                    } => Error::InvalidParameter { name, reason },
                    other => other,
                }
            };
            let reflectivity = self.reflectivity_png.as_deref();
            for (name, path) in [
                ("depth_png", Some(depth)),
                ("reflectivity_png", reflectivity),
            ] {
                let Some(path) = path else { continue };
                let (h, w) = io::png_dimensions(path).map_err(named(name))?;
                if (h, w) != (g.m, g.n) {
                    return Err(Error::param(
                        name,
                        format!(
                            "{} is {h} pixels high and {w} wide, but the grid {g} asks for {} by {}",
                            path.display(),
                            g.m,
                            g.n
                        ),
                    ));
                }
            }
            let read = read(depth, reflectivity, g.ks).map_err(|e| match e {
                Error::InvalidParameter {
                    name: "png",
                    reason,
                } => {
                    let of_reflectivity = reflectivity.is_some_and(|r| {
                        r != depth && reason.starts_with(&format!("{}:", r.display()))
                    });
                    let name = if of_reflectivity {
                        "reflectivity_png"
                    } else {
                        "depth_png"
                    };
                    Error::InvalidParameter { name, reason }
                }
                other => other,
            })?;
            Ok(Some(read))
        }
        #[cfg(not(feature = "images"))]
        Err(Error::param(
            "depth_png",
            format!(
                "{}: reading PNG depth maps needs rdlidar's `images` feature",
                depth.display()
            ),
        ))
    }

    /// How `meta.json` names the supplied scene's source: its maps' file names, and for a
    /// scene rendered from returns, the scene, the depths and the response.
    pub fn scene_source(&self) -> Option<String> {
        if self.renders_returns().unwrap_or(false) {
            let maps = self.map_names();
            return Some(format!(
                "{}{} at {} depths, kernel {}",
                self.scene,
                maps.map_or(String::new(), |m| format!(" ({m})")),
                if self.continuous {
                    "continuous"
                } else {
                    "grid"
                },
                self.response()
            ));
        }
        self.map_names()
    }

    /// The maps' file names of a png scene.
    fn map_names(&self) -> Option<String> {
        let name = |p: &Path| {
            p.file_name()
                .map_or_else(|| p.display().to_string(), |f| f.to_string_lossy().into())
        };
        let depth = self.depth_png.as_deref()?;
        Some(match self.reflectivity_png.as_deref() {
            None => format!("depth {}", name(depth)),
            Some(r) => format!("depth {}, reflectivity {}", name(depth), name(r)),
        })
    }
}

/// The description of `sim` as `meta.json` holds it, with its codes written as `format`.
pub fn simulation_meta<T: Real>(sim: &Simulation<T>, format: CodesFormat) -> SimulationMeta {
    let mut meta = SimulationMeta::new(sim);
    meta.codes_format = format.name().into();
    if format == CodesFormat::Seed {
        meta.codes_generator = Some(SEEDED_CODES_GENERATOR.into());
        meta.files.codes = SIMULATION_FILES[4].into();
    }
    meta
}

/// The shape of the codes file of `sim` written as `format` (none for seeded codes).
pub fn codes_shape<T: Real>(sim: &Simulation<T>, format: CodesFormat) -> Option<Vec<usize>> {
    let g = sim.spec.geometry;
    let k = g.samples(sim.spec.pulse_len);
    let last = match format {
        CodesFormat::Seed => return None,
        CodesFormat::Packed => packed_len(k),
        CodesFormat::Int8 => k,
    };
    Some(match sim.spec.architecture {
        Architecture::MultiAdc(n) => vec![n, g.m, g.n, last],
        _ => vec![g.m, g.n, last],
    })
}

/// Writes `sim` into the folder `dir` (created if needed; an existing non-empty folder only
/// with `force`, which replaces the five files and leaves others alone): every file is staged
/// and synced, then all are renamed into place; on an error nothing new is left behind.
/// Returns the description written to `meta.json`.
///
/// # Errors
/// [`Error::File`] naming the folder or file that cannot be written.
pub fn write_simulation<T: Real + WritableElement>(
    dir: &Path,
    sim: &Simulation<T>,
    format: CodesFormat,
    force: bool,
) -> Result<SimulationMeta> {
    write_simulation_cancellable(dir, sim, format, force, &AtomicBool::new(false))
}

/// Checks, before any work, that a simulation can be written into the folder `dir`
/// ([`io::check_output_dir`]: an existing folder must be empty unless `force`, a new one needs
/// an existing parent).
///
/// # Errors
/// [`Error::File`] naming `dir`.
pub fn check_simulation_dir(dir: &Path, force: bool) -> Result<()> {
    io::check_output_dir(dir, force, &format!("its {}", SIMULATION_FILES.join(", ")))
}

/// [`write_simulation`], cancelled by `cancel`: once it is raised (from another thread, e.g. on
/// Ctrl-C), the writing stops before its next file and leaves nothing new behind.
///
/// # Errors
/// As [`write_simulation`]; [`Error::Cancelled`] when `cancel` was raised.
pub fn write_simulation_cancellable<T: Real + WritableElement>(
    dir: &Path,
    sim: &Simulation<T>,
    format: CodesFormat,
    force: bool,
    cancel: &AtomicBool,
) -> Result<SimulationMeta> {
    check_simulation_dir(dir, force)?;
    let go_on = || {
        if cancel.load(Ordering::Relaxed) {
            Err(Error::Cancelled {
                what: format!("writing {}", dir.display()),
            })
        } else {
            Ok(())
        }
    };
    let meta = simulation_meta(sim, format);
    let mut json = serde_json::to_string_pretty(&meta)
        .map_err(|e| io::file_error(dir, format!("cannot format meta.json: {e}")))?;
    json.push('\n');
    let k = meta.k;
    let meas_shape = match sim.rows() {
        None => vec![k],
        Some(r) => vec![r, k],
    };
    let meas = ndarray::ArrayView::from_shape(ndarray::IxDyn(&meas_shape), &sim.meas[..])
        .map_err(|e| io::file_error(dir, format!("cannot shape the measurements: {e}")))?;
    let created = !dir.exists();
    if created {
        std::fs::create_dir(dir)
            .map_err(|e| io::file_error(dir, format!("cannot create the directory: {e}")))?;
    } else {
        // What a writer killed in this folder left (check_output_dir did not count it).
        io::remove_stale_temporaries(dir);
    }
    let g = sim.spec.geometry;
    let written = (|| -> Result<Vec<PathBuf>> {
        let [f_scene, f_pulse, f_codes, f_meas, f_meta] = SIMULATION_FILES.map(|f| dir.join(f));
        let grid = (g.m, g.n);
        let codes = &sim.code_sets[0];
        let multi = matches!(sim.spec.architecture, Architecture::MultiAdc(_));
        go_on()?;
        let mut staged: Vec<StagedFile> = vec![io::stage_array(f_scene, sim.scene.data())?];
        go_on()?;
        staged.push(io::stage_array(
            f_pulse,
            &ndarray::ArrayView1::from(sim.pulse.as_slice()),
        )?);
        go_on()?;
        // Seeded codes have no file: meta.json describes them.
        match (format, multi, &sim.active) {
            (CodesFormat::Seed, _, _) => {}
            (CodesFormat::Int8, true, _) => {
                staged.push(io::stage_code_sets(f_codes, grid, &sim.code_sets)?)
            }
            (CodesFormat::Packed, true, _) => staged.push(io::stage_packed_code_sets(
                f_codes,
                grid,
                &sim.code_sets,
                true,
            )?),
            (_, false, Some(active)) => {
                staged.push(io::stage_masked_codes(f_codes, grid, codes, active)?)
            }
            (CodesFormat::Int8, false, None) => staged.push(io::stage_codes(f_codes, grid, codes)?),
            (CodesFormat::Packed, false, None) => {
                staged.push(io::stage_packed_codes(f_codes, grid, codes)?)
            }
        }
        go_on()?;
        staged.push(io::stage_array(f_meas, &meas)?);
        if let Some(returns) = &sim.returns {
            staged.push(io::stage_array(dir.join(RANGE_FILE), &returns.range_map())?);
        }
        staged.push(io::stage_bytes(f_meta, json.as_bytes())?);
        go_on()?;
        io::commit_all(staged)
    })();
    match written {
        Ok(_) => {
            // A codes.npy or range.npy left by an earlier run (`force`) would contradict
            // meta.json.
            let stale = [
                (format == CodesFormat::Seed, SIMULATION_FILES[2], "codes"),
                (sim.returns.is_none(), RANGE_FILE, "depths"),
            ];
            for (_, file, what) in stale.iter().filter(|s| s.0) {
                let stale = dir.join(file);
                if stale.exists() {
                    std::fs::remove_file(&stale).map_err(|e| {
                        io::file_error(&stale, format!("cannot remove the old {what}: {e}"))
                    })?;
                }
            }
            Ok(meta)
        }
        Err(e) => {
            if created {
                for f in SIMULATION_FILES.iter().chain([&RANGE_FILE]) {
                    let _ = std::fs::remove_file(dir.join(f));
                }
                let _ = std::fs::remove_dir(dir);
            }
            Err(e)
        }
    }
}
