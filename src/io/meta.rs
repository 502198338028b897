//! `meta.json`, the description `rdlidar simulate` writes next to its arrays (docs/guide.md shows
//! one, docs/architectures.md the fields of codes described by a seed):
//! the geometry, the seeds of every draw, the scene, the codes, the architecture, the regime
//! and the noise.

use serde::{Deserialize, Serialize};

use std::path::Path;

use crate::error::Result;
use crate::lidar::{
    Architecture, Geometry, SeededCodes, Simulation, TileSize, SEEDED_CODES_GENERATOR,
};
use crate::limits;
use crate::real::Real;

/// The files of a simulation, in the order they are written.
pub const SIMULATION_FILES: [&str; 5] = [
    "scene.npy",
    "pulse.npy",
    "codes.npy",
    "meas.npy",
    "meta.json",
];

/// The true depths of a simulation rendered from returns ([`FilesMeta::range`]).
pub const RANGE_FILE: &str = "range.npy";

/// M, N and K_s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GeometryMeta {
    /// Pixel rows M.
    pub m: usize,
    /// Pixel columns N.
    pub n: usize,
    /// Depth bins K_s.
    pub ks: usize,
}

/// The seed of every draw ([`Seeds`](crate::lidar::Seeds)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeedsMeta {
    /// The pulse's seed.
    pub pulse: u64,
    /// The seed of the first (or only) code set.
    pub codes: u64,
    /// The seed of every code set, in order (one per ADC with several code sets).
    pub code_sets: Vec<u64>,
    /// The noise's seed.
    pub noise: u64,
    /// A random scene's seed (`None` for the deterministic paper scene).
    pub scene: Option<u64>,
    /// The seed of the coded aperture's pixel selection.
    pub aperture: Option<u64>,
}

/// The architecture of the acquisition.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArchitectureMeta {
    /// "single", "multi_adc", "tiles" or "aperture".
    pub kind: String,
    /// Number of ADCs: the rows of meas.npy when it is two-dimensional.
    pub adcs: usize,
    /// Tile size [A, B] of `--tiles AxB`.
    pub tile: Option<[usize; 2]>,
    /// Pixels that reach an ADC.
    pub active_pixels: usize,
    /// The fraction given to `--aperture`.
    pub aperture_fraction: Option<f64>,
}

/// The scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneMeta {
    /// "paper", "random", "transparent", or "supplied" (read from a depth map or given by the
    /// caller; `source` says which).
    pub kind: String,
    /// Where a supplied scene came from (the depth and reflectivity maps' file names).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// A random scene's fraction of lit pixels.
    pub lit_fraction: Option<f64>,
    /// A semi-transparent scene's range of returns per pixel.
    pub returns_per_pixel: Option<[usize; 2]>,
    /// Nonzero voxels.
    pub nonzeros: usize,
    /// Pixels with at least one return.
    pub lit_pixels: usize,
    /// The response that put a scene rendered from returns on the voxel grid (`triangle`,
    /// `gaussian:S`, …); absent for depths on the grid with no response.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kernel: Option<String>,
}

/// The noise added to the measurements.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseMeta {
    /// "none", or the stages applied, in order, joined by "+": "poisson", "gaussian",
    /// "quantized" (e.g. "poisson+gaussian+quantized").
    pub model: String,
    /// Photon noise: photon count per unit intensity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photons: Option<f64>,
    /// Photon noise: background light per sample, in units of intensity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub background: Option<f64>,
    /// Photon noise: the mean photon count per sample.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_photons: Option<f64>,
    /// The ADC's bit depth.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adc_bits: Option<u32>,
    /// The ADC's full scale F (of the first ADC when it follows each ADC's largest sample).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub full_scale: Option<f64>,
    /// The ADC's full scale is each ADC's largest |sample| (nothing clipped).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub full_scale_auto: Option<bool>,
    /// The ADC's quantization step 2F/2^bits (of the first ADC).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<f64>,
    /// Samples clipped by the ADC, over all ADCs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clipped: Option<usize>,
    /// The SNR asked for, in dB.
    pub snr_db: Option<f64>,
    /// The noise's standard deviation.
    pub sigma: Option<f64>,
    /// The SNR achieved by the draw, in dB.
    pub achieved_snr_db: Option<f64>,
    /// The noise's seed.
    pub seed: Option<u64>,
}

/// The file names of the arrays.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FilesMeta {
    /// The true scene.
    pub scene: String,
    /// The pulse.
    pub pulse: String,
    /// The codes.
    pub codes: String,
    /// The measurements.
    pub meas: String,
    /// The true depths of a scene rendered from returns (continuous depths, or a response
    /// other than delta): float64 (M, N) bins, or (R, M, N) with several returns per pixel;
    /// NaN where there is no return.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<String>,
}

/// The contents of `meta.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulationMeta {
    /// "rdlidar".
    #[serde(rename = "crate")]
    pub crate_name: String,
    /// The version that wrote the file.
    pub crate_version: String,
    /// The generator of every draw: "ChaCha8".
    pub prng: String,
    /// "f32" or "f64": the precision of the float arrays.
    pub precision: String,
    /// The scene grid.
    pub geometry: GeometryMeta,
    /// The grid as `MxNxKS`.
    pub size: String,
    /// Pulse length K_p.
    pub pulse_len: usize,
    /// Samples per ADC, K = K_p + K_s − 1.
    pub k: usize,
    /// The base seed.
    pub seed: u64,
    /// The seed of every draw.
    pub seeds: SeedsMeta,
    /// The scene.
    pub scene: SceneMeta,
    /// "binary" or "ternary".
    pub code_alphabet: String,
    /// How codes.npy holds the codes: "int8" (M, N, K), or "packed", uint8 (M, N, ⌈K/8⌉) as
    /// `np.packbits(S > 0, axis=-1)` writes ±1 codes (a leading G axis for several ADCs).
    #[serde(default = "int8_format")]
    pub codes_format: String,
    /// For "seed": the stream the codes are regenerated from
    /// ([`SEEDED_CODES_GENERATOR`]); the key is
    /// `seeds.codes`, the code sets are `architecture.adcs` for several ADCs, one otherwise.
    #[serde(default)]
    pub codes_generator: Option<String>,
    /// The probability of a zero code of ternary codes.
    pub ternary_zero_prob: Option<f64>,
    /// The architecture.
    pub architecture: ArchitectureMeta,
    /// "compressive", "critical" or "redundant".
    pub regime: String,
    /// The critical pulse length (M·N − 1)·K_s + 1.
    pub critical_pulse_len: usize,
    /// The noise.
    pub noise: NoiseMeta,
    /// The file names.
    pub files: FilesMeta,
}

impl SimulationMeta {
    /// The description of `sim`.
    pub fn new<T: Real>(sim: &Simulation<T>) -> Self {
        let spec = &sim.spec;
        let (g, kp) = (spec.geometry, spec.pulse_len);
        let seeds = spec.seeds();
        let arch = spec.architecture;
        let lit_pixels = sim
            .scene
            .data()
            .lanes(ndarray::Axis(2))
            .into_iter()
            .filter(|c| c.iter().any(|v| *v != T::zero()))
            .count();
        let noise = noise_meta(sim.noise.as_ref(), spec, seeds.noise());
        let alphabet = sim.code_sets[0].alphabet().name();
        let [scene, pulse, codes, meas, _] = SIMULATION_FILES;
        SimulationMeta {
            crate_name: env!("CARGO_PKG_NAME").into(),
            crate_version: env!("CARGO_PKG_VERSION").into(),
            prng: "ChaCha8".into(),
            precision: T::NAME.into(),
            geometry: GeometryMeta {
                m: g.m,
                n: g.n,
                ks: g.ks,
            },
            size: g.to_string(),
            pulse_len: kp,
            k: g.samples(kp),
            seed: spec.seed,
            seeds: SeedsMeta {
                pulse: seeds.pulse(),
                codes: seeds.code_set(0),
                code_sets: (0..arch.code_sets()).map(|i| seeds.code_set(i)).collect(),
                noise: seeds.noise(),
                scene: (matches!(
                    spec.scene,
                    crate::lidar::SceneSpec::Random { .. } | crate::lidar::SceneSpec::Transparent
                ) || sim.returns.is_some())
                .then(|| seeds.scene()),
                aperture: matches!(arch, Architecture::Aperture(_)).then(|| seeds.aperture()),
            },
            scene: SceneMeta {
                kind: spec.scene.name().into(),
                source: sim.scene_source.clone(),
                lit_fraction: match spec.scene {
                    crate::lidar::SceneSpec::Random { lit_fraction } => Some(lit_fraction),
                    _ => None,
                },
                returns_per_pixel: spec.scene.returns_per_pixel(g.ks),
                nonzeros: sim.scene.nnz(),
                lit_pixels,
                kernel: sim.response.as_ref().map(|r| r.spec()),
            },
            code_alphabet: alphabet.into(),
            codes_format: int8_format(),
            codes_generator: None,
            ternary_zero_prob: spec.ternary_zero_prob,
            architecture: ArchitectureMeta {
                kind: arch.kind().into(),
                adcs: sim.rows().unwrap_or(1),
                tile: match arch {
                    Architecture::Tiles(t) => Some([t.m, t.n]),
                    _ => None,
                },
                active_pixels: sim.active.as_ref().map_or(g.pixels(), Vec::len),
                aperture_fraction: match arch {
                    Architecture::Aperture(f) => Some(f),
                    _ => None,
                },
            },
            regime: g.regime(kp).to_string(),
            critical_pulse_len: g.critical_pulse_len(),
            noise,
            files: FilesMeta {
                scene: scene.into(),
                pulse: pulse.into(),
                codes: codes.into(),
                meas: meas.into(),
                range: sim.returns.as_ref().map(|_| RANGE_FILE.into()),
            },
        }
    }
}

/// The `noise` entry of a simulation's description.
fn noise_meta(
    report: Option<&crate::lidar::NoiseReport>,
    spec: &crate::lidar::SimulationSpec,
    seed: u64,
) -> NoiseMeta {
    use crate::lidar::{FullScale, StageReport};
    let mut meta = NoiseMeta {
        model: "none".into(),
        photons: None,
        background: None,
        mean_photons: None,
        adc_bits: None,
        full_scale: None,
        full_scale_auto: None,
        step: None,
        clipped: None,
        snr_db: None,
        sigma: None,
        achieved_snr_db: None,
        seed: None,
    };
    let Some(report) = report else {
        return meta;
    };
    let mut names: Vec<&str> = Vec::new();
    for stage in &report.stages {
        match stage {
            StageReport::Gaussian { sigma } => {
                names.push("gaussian");
                meta.sigma = Some(*sigma);
            }
            StageReport::Poisson { mean_photons } => {
                names.push("poisson");
                meta.mean_photons = Some(*mean_photons);
            }
            StageReport::Quantized(q) => {
                if meta.adc_bits.is_none() {
                    names.push("quantized");
                    meta.adc_bits = Some(q.bits);
                    meta.full_scale = Some(q.full_scale);
                    meta.step = Some(q.step);
                }
            }
        }
    }
    meta.model = names.join("+");
    meta.snr_db = spec.snr_db;
    if let Some(p) = spec.photon_noise {
        meta.photons = Some(p.photons);
        meta.background = Some(p.background);
    }
    if let Some(q) = spec.quantization {
        meta.full_scale_auto = Some(matches!(q.full_scale, FullScale::Auto));
        meta.clipped = Some(report.clipped());
    }
    meta.achieved_snr_db = Some(report.snr_db()).filter(|v| v.is_finite());
    meta.seed = Some(seed);
    meta
}

/// The codes format of files written before packed codes existed.
fn int8_format() -> String {
    "int8".into()
}

/// Codes described by a seed in a `meta.json` (`simulate --codes-format seed`), as the file
/// describes them, every field checked against the others.
#[derive(Debug, Clone, PartialEq)]
pub struct SeededCodesFile {
    /// The scene grid (`geometry`).
    pub geometry: Geometry,
    /// The pulse length K_p (`pulse_len`).
    pub pulse_len: usize,
    /// How the pixels reach the ADCs (`architecture`): one ADC, G ADCs or tiles.
    pub architecture: Architecture,
    /// The codes: every code set of the acquisition.
    pub codes: SeededCodes,
}

/// Whether `path` names a JSON description of codes rather than a `.npy` array: its extension is
/// `.json`.
pub fn is_codes_description(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

/// At most 40 characters of a value quoted in a message, with an ellipsis when it was longer.
pub fn excerpt(text: &str) -> String {
    const MAX: usize = 40;
    let mut out: String = text.chars().take(MAX).collect();
    if text.chars().nth(MAX).is_some() {
        out.push('…');
    }
    format!("{out:?}")
}

/// A message of at most about 200 characters: a parser's message may quote a whole value.
fn shortened(text: &str) -> String {
    const MAX: usize = 200;
    if text.chars().nth(MAX).is_none() {
        return text.to_string();
    }
    let head: String = text.chars().take(MAX).collect();
    format!("{head}…")
}

/// Reads the seeded codes that a `meta.json` written by `simulate --codes-format seed`
/// describes: the one parser of that description. Every field the codes depend on is checked
/// against its bound and against the others before anything is allocated.
///
/// # Errors
/// [`Error::File`](crate::Error::File) naming `path` and the field at fault: the file cannot be
/// read or parsed; it describes codes stored in a file (another `codes_format`) or names an
/// unknown generator; `geometry` is outside the bounds of [`crate::limits`] or disagrees with
/// `size`; `pulse_len` is out of bounds or `k` is not `pulse_len + geometry.ks − 1`; the
/// architecture has no seeded codes (a coded aperture), a zero or too large tile or ADC count,
/// or an `adcs` that disagrees with its tiles. Quoted values are shortened to an excerpt.
pub fn read_seeded_codes(path: &Path) -> Result<SeededCodesFile> {
    let fail = |why: String| super::file_error(path, why);
    // A description is a few kilobytes: refuse what cannot be one before reading it.
    const MAX_BYTES: u64 = 1 << 20;
    let info = std::fs::metadata(path).map_err(|e| fail(format!("cannot read: {e}")))?;
    if !info.is_file() {
        return Err(fail("is not a regular file".to_string()));
    }
    if info.len() > MAX_BYTES {
        return Err(fail(format!(
            "is {} bytes, more than a meta.json holds (at most {MAX_BYTES})",
            info.len()
        )));
    }
    let text = std::fs::read_to_string(path).map_err(|e| fail(format!("cannot read: {e}")))?;
    let meta: SimulationMeta = serde_json::from_str(&text).map_err(|e| {
        fail(format!(
            "not a meta.json written by rdlidar simulate: {}",
            shortened(&e.to_string())
        ))
    })?;
    if meta.codes_format != "seed" {
        return Err(fail(format!(
            "describes codes stored as {} in {} (codes_format), not codes described by a \
             seed: pass that file as the codes (`codes`)",
            shortened(&meta.codes_format),
            shortened(&meta.files.codes)
        )));
    }
    match meta.codes_generator.as_deref() {
        Some(SEEDED_CODES_GENERATOR) => {}
        other => {
            return Err(fail(format!(
                "codes_generator {} is not known to this version (it knows \
                 {SEEDED_CODES_GENERATOR:?})",
                other.map_or("(missing)".to_string(), excerpt)
            )))
        }
    }
    if meta.code_alphabet != "binary" || meta.ternary_zero_prob.is_some() {
        return Err(fail(format!(
            "code_alphabet {} (ternary_zero_prob {:?}): codes described by a seed are ±1 \
             (\"binary\")",
            excerpt(&meta.code_alphabet),
            meta.ternary_zero_prob
        )));
    }
    let GeometryMeta { m, n, ks } = meta.geometry;
    let geometry = Geometry::new(m, n, ks)
        .and_then(|g| g.check_bounds().map(|()| g))
        .map_err(|_| {
            fail(format!(
                "geometry {m} × {n} × {ks} is outside the bounds: 1 to {} pixel rows and \
                 columns, 1 to {} depth bins",
                limits::MAX_SIDE,
                limits::MAX_DEPTH_BINS
            ))
        })?;
    if meta.size != geometry.to_string() {
        return Err(fail(format!(
            "size {} disagrees with geometry {geometry}",
            excerpt(&meta.size)
        )));
    }
    let kp = meta.pulse_len;
    if kp == 0 || kp > limits::MAX_PULSE_LEN {
        return Err(fail(format!(
            "pulse_len {kp} is outside 1 to {}",
            limits::MAX_PULSE_LEN
        )));
    }
    let k = geometry.samples(kp);
    if meta.k != k {
        return Err(fail(format!(
            "k = {} disagrees with pulse_len + geometry.ks − 1 = {kp} + {ks} − 1 = {k}",
            meta.k
        )));
    }
    let architecture = seeded_architecture(&meta.architecture, m, n).map_err(fail)?;
    let codes = SeededCodes::new(
        meta.seeds.codes,
        architecture.code_sets(),
        geometry.pixels(),
        k,
    )
    .map_err(|e| fail(e.to_string()))?;
    Ok(SeededCodesFile {
        geometry,
        pulse_len: kp,
        architecture,
        codes,
    })
}

/// The architecture a seeded `meta.json` describes (`architecture` of an `m`×`n` array),
/// checked: a known kind with seeded codes, a tile only for tiles and of at least one pixel,
/// at most [`limits::MAX_ADCS`] ADCs, and `adcs` equal to the architecture's.
fn seeded_architecture(
    arch: &ArchitectureMeta,
    m: usize,
    n: usize,
) -> std::result::Result<Architecture, String> {
    if arch.kind != "tiles" && arch.tile.is_some() {
        return Err(format!(
            "architecture.tile is given for the {} architecture, which has no tiles",
            excerpt(&arch.kind)
        ));
    }
    let architecture = match arch.kind.as_str() {
        "single" => Architecture::Single,
        "multi_adc" => {
            limits::check_count("architecture.adcs", arch.adcs, limits::MAX_ADCS)
                .map_err(|e| e.to_string())?;
            Architecture::MultiAdc(arch.adcs)
        }
        "tiles" => {
            let t = match arch.tile {
                Some([tm, tn]) if tm > 0 && tn > 0 => TileSize { m: tm, n: tn },
                Some([tm, tn]) => {
                    return Err(format!(
                        "architecture.tile [{tm}, {tn}]: tile rows and columns must be at \
                         least 1"
                    ))
                }
                None => {
                    return Err(
                        "architecture.tile is missing for the tiles architecture".to_string()
                    )
                }
            };
            Architecture::Tiles(t)
        }
        "aperture" => {
            return Err(
                "architecture \"aperture\" has no seeded codes (its blocked pixels have zero \
                 codes, which a seed does not describe)"
                    .to_string(),
            )
        }
        other => {
            return Err(format!(
                "architecture.kind {} is not one of \"single\", \"multi_adc\", \"tiles\"",
                excerpt(other)
            ))
        }
    };
    let rows = architecture.rows(m, n).unwrap_or(1);
    if rows > limits::MAX_ADCS {
        return Err(format!(
            "architecture.tile: {rows} tiles of {m} × {n} pixels, more than the limit of {} \
             ADCs",
            limits::MAX_ADCS
        ));
    }
    if arch.adcs != rows {
        return Err(format!(
            "architecture.adcs = {} disagrees with the architecture, which has {rows} {}",
            arch.adcs,
            if rows == 1 { "ADC" } else { "ADCs" }
        ));
    }
    Ok(architecture)
}
