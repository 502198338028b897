//! `meta.json`, the description `rdlidar simulate` writes next to its arrays (DESIGN.md §8):
//! the geometry, the seeds of every draw, the scene, the codes, the architecture, the regime
//! and the noise.

use serde::{Deserialize, Serialize};

use std::path::Path;

use crate::error::Result;
use crate::lidar::{Architecture, CodeAlphabet, SeededCodes, Simulation, SEEDED_CODES_GENERATOR};
use crate::real::Real;

/// The files of a simulation, in the order they are written.
pub const SIMULATION_FILES: [&str; 5] = [
    "scene.npy",
    "pulse.npy",
    "codes.npy",
    "meas.npy",
    "meta.json",
];

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
    /// "paper", "random" or "transparent".
    pub kind: String,
    /// A random scene's fraction of lit pixels.
    pub lit_fraction: Option<f64>,
    /// A semi-transparent scene's range of returns per pixel.
    pub returns_per_pixel: Option<[usize; 2]>,
    /// Nonzero voxels.
    pub nonzeros: usize,
    /// Pixels with at least one return.
    pub lit_pixels: usize,
}

/// The noise added to the measurements.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseMeta {
    /// "none" or "gaussian".
    pub model: String,
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
        let noise = match (&sim.noise, spec.snr_db) {
            (Some(report), Some(snr_db)) => NoiseMeta {
                model: "gaussian".into(),
                snr_db: Some(snr_db),
                sigma: report.gaussian_sigma(),
                achieved_snr_db: Some(report.snr_db()).filter(|v| v.is_finite()),
                seed: Some(seeds.noise()),
            },
            _ => NoiseMeta {
                model: "none".into(),
                snr_db: None,
                sigma: None,
                achieved_snr_db: None,
                seed: None,
            },
        };
        let alphabet = match sim.code_sets[0].alphabet() {
            CodeAlphabet::Binary => "binary",
            CodeAlphabet::Ternary => "ternary",
        };
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
                scene: (spec.scene.name() != "paper").then(|| seeds.scene()),
                aperture: matches!(arch, Architecture::Aperture(_)).then(|| seeds.aperture()),
            },
            scene: SceneMeta {
                kind: spec.scene.name().into(),
                lit_fraction: match spec.scene {
                    crate::lidar::SceneSpec::Random { lit_fraction } => Some(lit_fraction),
                    _ => None,
                },
                returns_per_pixel: spec.scene.returns_per_pixel(g.ks),
                nonzeros: sim.scene.nnz(),
                lit_pixels,
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
            },
        }
    }
}

/// The codes format of files written before packed codes existed.
fn int8_format() -> String {
    "int8".into()
}

/// Codes described by a seed in a `meta.json` (`simulate --codes-format seed`).
#[derive(Debug, Clone, PartialEq)]
pub struct SeededCodesFile {
    /// (M, N) of the array.
    pub grid: (usize, usize),
    /// The codes: every code set of the acquisition.
    pub codes: SeededCodes,
    /// `architecture.kind`: "single", "multi_adc" or "tiles".
    pub architecture: String,
    /// The tile size [A, B] of a tiled acquisition.
    pub tile: Option<[usize; 2]>,
}

/// Whether `path` names a JSON description of codes rather than a `.npy` array: its extension is
/// `.json`.
pub fn is_codes_description(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

/// Reads the seeded codes that a `meta.json` written by `simulate --codes-format seed`
/// describes, for the pulse length and depth bins of `expect`.
///
/// # Errors
/// [`Error::File`](crate::Error::File) naming `path` if it cannot be read or parsed, if it
/// describes codes stored in a file (another `codes_format`), names an unknown generator, has
/// another number of samples K than `expect` gives, or another grid than `expect.grid`.
pub fn read_seeded_codes(
    path: &Path,
    expect: &crate::io::ShapeExpectation,
) -> Result<SeededCodesFile> {
    let fail = |why: String| super::file_error(path, why);
    let text = std::fs::read_to_string(path).map_err(|e| fail(format!("cannot read: {e}")))?;
    let meta: SimulationMeta = serde_json::from_str(&text)
        .map_err(|e| fail(format!("not a meta.json written by rdlidar simulate: {e}")))?;
    if meta.codes_format != "seed" {
        return Err(fail(format!(
            "describes codes stored as {} in {}, not codes described by a seed: pass that file \
             to --codes",
            meta.codes_format, meta.files.codes
        )));
    }
    match meta.codes_generator.as_deref() {
        Some(SEEDED_CODES_GENERATOR) => {}
        other => {
            return Err(fail(format!(
                "codes generator {other:?} is not known to this version (it knows \
                 {SEEDED_CODES_GENERATOR:?})"
            )))
        }
    }
    let k = expect.samples();
    if meta.k != k {
        return Err(fail(format!(
            "describes codes of K = {} samples (K_p {}, {} depth bins), but the pulse and \
             --depth-bins give K = {} + {} − 1 = {k}",
            meta.k, meta.pulse_len, meta.geometry.ks, expect.pulse_len, expect.depth_bins
        )));
    }
    let grid = (meta.geometry.m, meta.geometry.n);
    if let Some(want) = expect.grid {
        if want != grid {
            return Err(fail(format!(
                "describes codes of {}x{} pixels, the scene has {}x{}",
                grid.0, grid.1, want.0, want.1
            )));
        }
    }
    let sets = match meta.architecture.kind.as_str() {
        "multi_adc" => meta.architecture.adcs,
        "single" | "tiles" => 1,
        other => {
            return Err(fail(format!(
                "architecture {other:?} has no seeded codes (only single, multi_adc and tiles)"
            )))
        }
    };
    let codes = SeededCodes::new(meta.seeds.codes, sets, grid.0 * grid.1, k)
        .map_err(|e| fail(e.to_string()))?;
    Ok(SeededCodesFile {
        grid,
        codes,
        architecture: meta.architecture.kind,
        tile: meta.architecture.tile,
    })
}
