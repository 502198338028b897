//! Experiment descriptions as TOML: the fields a `[demo]` or `[compare]` section or the command
//! line sets ([`ExperimentPatch`]), a config file ([`ConfigFile`]), and seeds beyond TOML's
//! integers.

use std::path::{Path, PathBuf};

use serde::de::Error as _;
use serde::{Deserialize, Deserializer};

use crate::error::{Error, Result};
use crate::lidar::Geometry;
use crate::recon::Method;

use super::values::*;

/// A seed as TOML, whose integers end at `i64::MAX`: an integer up to that, the string of its
/// digits above (read back by [`ConfigFile`]).
pub(super) fn seed_value(seed: u64) -> toml::Value {
    match i64::try_from(seed) {
        Ok(v) => toml::Value::Integer(v),
        Err(_) => toml::Value::String(seed.to_string()),
    }
}

/// A seed from TOML: an integer from 0, or any `u64` as a string of digits (how
/// [`ExperimentConfig::to_toml`](super::ExperimentConfig::to_toml) writes a seed above
/// `i64::MAX`).
fn de_seed<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<Option<u64>, D::Error> {
    struct Seed;
    impl serde::de::Visitor<'_> for Seed {
        type Value = u64;

        fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(
                f,
                "a seed from 0 to {}: an integer, or its digits as a string",
                u64::MAX
            )
        }

        fn visit_i64<E: serde::de::Error>(self, v: i64) -> std::result::Result<u64, E> {
            u64::try_from(v).map_err(|_| E::invalid_value(serde::de::Unexpected::Signed(v), &self))
        }

        fn visit_u64<E: serde::de::Error>(self, v: u64) -> std::result::Result<u64, E> {
            Ok(v)
        }

        fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<u64, E> {
            v.trim()
                .parse()
                .map_err(|_| E::invalid_value(serde::de::Unexpected::Str(v), &self))
        }
    }
    d.deserialize_any(Seed).map(Some)
}

/// Some fields of an [`ExperimentConfig`](super::ExperimentConfig), to be layered over it with
/// [`ExperimentConfig::patched`](super::ExperimentConfig::patched): a `[demo]` or `[compare]`
/// section of a config file, or the flags given on the command line.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentPatch {
    /// Output folder.
    pub out: Option<PathBuf>,
    /// The scenes: one name or a list.
    #[serde(default, deserialize_with = "de_scenes")]
    pub scene: Option<Vec<SceneKind>>,
    /// The grid, `"MxNxKS"`.
    #[serde(default, deserialize_with = "de_geometry")]
    pub size: Option<Geometry>,
    /// Lit fraction of a random scene.
    pub lit_fraction: Option<f64>,
    /// Pulse lengths.
    pub pulse_lens: Option<Vec<usize>>,
    /// Methods by name.
    #[serde(default, deserialize_with = "de_methods")]
    pub solvers: Option<Vec<Method>>,
    /// Noise levels: one or a list, numbers of dB, `"none"` or `inf` for noise-free.
    #[serde(default, deserialize_with = "de_noise_levels")]
    pub snr_db: Option<Vec<NoiseLevel>>,
    /// Number of seeds.
    pub seeds: Option<usize>,
    /// Iteration budgets, per method name.
    pub max_iter: Option<IterationBudgets>,
    /// Lanczos iterations behind FISTA's step.
    pub power_iterations: Option<usize>,
}

fn de_geometry<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<Option<Geometry>, D::Error> {
    let text = String::deserialize(d)?;
    Geometry::parse(&text)
        .map(Some)
        .map_err(|e| D::Error::custom(e.to_string()))
}

/// One value or a list of them, as a list.
fn one_or_many<'de, D, T>(d: D) -> std::result::Result<Vec<T>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum OneOrMany<T> {
        One(T),
        Many(Vec<T>),
    }
    Ok(match OneOrMany::deserialize(d)? {
        OneOrMany::One(v) => vec![v],
        OneOrMany::Many(v) => v,
    })
}

fn de_scenes<'de, D: Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<Vec<SceneKind>>, D::Error> {
    let names: Vec<String> = one_or_many(d)?;
    if names.is_empty() {
        return Err(D::Error::custom("the list of scenes is empty"));
    }
    names
        .iter()
        .map(|n| {
            n.parse::<SceneKind>()
                .map_err(|e| D::Error::custom(e.to_string()))
        })
        .collect::<std::result::Result<Vec<_>, _>>()
        .map(Some)
}

fn de_methods<'de, D: Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<Vec<Method>>, D::Error> {
    let names = Vec::<String>::deserialize(d)?;
    if names.is_empty() {
        return Err(D::Error::custom("the list of solvers is empty"));
    }
    names
        .iter()
        .map(|n| parse_method(n, "solvers").map_err(|e| D::Error::custom(e.to_string())))
        .collect::<std::result::Result<Vec<_>, _>>()
        .map(Some)
}

fn de_noise_levels<'de, D: Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<Vec<NoiseLevel>>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Level {
        Db(f64),
        Text(String),
    }
    let levels: Vec<Level> = one_or_many(d)?;
    levels
        .into_iter()
        .map(|l| match l {
            Level::Db(v) => noise_level(v).map_err(D::Error::custom),
            Level::Text(t) => parse_noise_level(&t).map_err(|e| D::Error::custom(e.to_string())),
        })
        .collect::<std::result::Result<Vec<_>, _>>()
        .map(Some)
}

/// A TOML experiment file: settings shared by every experiment at the top, then a `[demo]` and
/// a `[compare]` section.
///
/// ```toml
/// seed = 3
/// precision = "f64"
///
/// [demo]
/// pulse_lens = [10000, 30000]
/// solvers = ["backprojection-debiased", "model-based", "tv"]
/// max_iter = { model-based = 12 }
///
/// [compare]
/// size = "12x12x12"
/// snr_db = ["none", 30, 10]
/// seeds = 4
/// ```
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConfigFile {
    /// Base seed: an integer, or any `u64` as a string of digits (TOML's integers end at
    /// `i64::MAX`, so `config.toml` writes a larger seed so).
    #[serde(default, deserialize_with = "de_seed")]
    pub seed: Option<u64>,
    /// Precision of the computations.
    pub precision: Option<Precision>,
    /// Worker threads.
    pub threads: Option<usize>,
    /// Hide progress bars.
    pub quiet: Option<bool>,
    /// The `[demo]` section.
    pub demo: Option<ExperimentPatch>,
    /// The `[compare]` section.
    pub compare: Option<ExperimentPatch>,
}

impl ConfigFile {
    /// Parses TOML text; errors carry the line and column.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`config`) with a one-line message `line L, column C: what`.
    pub fn parse(text: &str) -> Result<Self> {
        let file: ConfigFile = toml::from_str(text).map_err(|e| {
            let what = e.message().trim().replace('\n', "; ");
            let at = match e.span() {
                Some(span) => {
                    let before = &text[..span.start.min(text.len())];
                    let line = before.matches('\n').count() + 1;
                    let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
                    format!("line {line}, column {column}: ")
                }
                None => String::new(),
            };
            Error::param("config", format!("{at}{what}"))
        })?;
        if file.threads == Some(0) {
            return Err(Error::param("config", "threads must be at least 1"));
        }
        Ok(file)
    }

    /// Reads and parses a file.
    ///
    /// # Errors
    /// [`Error::File`] naming the file when it cannot be read or parsed (the reason says where).
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let file_err = |reason: String| Error::File {
            path: path.display().to_string(),
            reason,
        };
        let text = std::fs::read_to_string(path)
            .map_err(|e| file_err(format!("cannot read the config file: {e}")))?;
        ConfigFile::parse(&text).map_err(|e| match e {
            Error::InvalidParameter { reason, .. } => file_err(reason),
            other => other,
        })
    }
}
