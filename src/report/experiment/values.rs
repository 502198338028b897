//! The values of an experiment's settings: precision, scene kind, noise levels, pulse lengths,
//! solver lists and per-solver iteration budgets, with their parsers for flags and files.

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::error::{Error, Result};
use crate::recon::Method;

/// Floating-point precision of an experiment's computations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub enum Precision {
    /// Single precision (the default: the operators are about twice as fast).
    #[default]
    #[serde(rename = "f32")]
    F32,
    /// Double precision.
    #[serde(rename = "f64")]
    F64,
}

impl Precision {
    /// `"f32"` or `"f64"`.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

impl std::fmt::Display for Precision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The scene an experiment reconstructs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SceneKind {
    /// The paper's scene ([`crate::lidar::paper_scene`]): a square, a disk and a slanted plane,
    /// scaled to the grid; the same for every seed.
    #[default]
    Paper,
    /// A random opaque scene ([`crate::lidar::random_opaque_scene`]) drawn from SEED+3 for each
    /// seed, each pixel lit with probability `lit_fraction`.
    Random,
    /// A semi-transparent scene ([`crate::lidar::semi_transparent_scene`]) drawn from SEED+3
    /// for each seed: every pixel has 1 to min(3, K_s) returns.
    Transparent,
    /// The paper's scene at continuous depths ([`crate::lidar::paper_returns`]) under the ideal
    /// system's `triangle` response: every method estimates continuous depths under it, and
    /// the depth RMSE is against the true continuous depths.
    PaperContinuous,
}

impl SceneKind {
    /// `"paper"`, `"random"`, `"transparent"` or `"paper-continuous"`.
    pub fn name(self) -> &'static str {
        match self {
            SceneKind::Paper => "paper",
            SceneKind::Random => "random",
            SceneKind::Transparent => "transparent",
            SceneKind::PaperContinuous => "paper-continuous",
        }
    }
}

impl std::str::FromStr for SceneKind {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        match s {
            "paper" => Ok(SceneKind::Paper),
            "random" => Ok(SceneKind::Random),
            "transparent" => Ok(SceneKind::Transparent),
            "paper-continuous" => Ok(SceneKind::PaperContinuous),
            _ => Err(Error::param(
                "scene",
                format!(
                    "unknown scene {s:?}; expected paper, random, transparent or \
                     paper-continuous"
                ),
            )),
        }
    }
}

/// The largest iteration budget of an experiment: TOML's largest integer, so that
/// `config.toml` holds every budget.
pub const MAX_BUDGET: usize = i64::MAX as usize;

/// Checks `method`'s iteration budget `limit`: 1 to [`MAX_BUDGET`].
///
/// # Errors
/// [`Error::InvalidParameter`] (`max_iter`) naming the method.
pub(super) fn check_budget(method: Method, limit: usize) -> Result<()> {
    if limit == 0 {
        return Err(Error::param(
            "max_iter",
            format!("{method}: the iteration limit must be at least 1"),
        ));
    }
    if limit > MAX_BUDGET {
        return Err(Error::param(
            "max_iter",
            format!(
                "{method}: {limit} is more than the limit of {MAX_BUDGET} (the largest integer \
                 config.toml holds)"
            ),
        ));
    }
    Ok(())
}

/// Iteration limits per method, overriding the method's default limit
/// ([`crate::recon::ReconstructOptions::max_iter`]). Methods without an entry keep their default.
///
/// In a TOML file, a table from method names to limits: `max_iter = { fista = 20, cgls = 20 }`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IterationBudgets([Option<usize>; Method::ALL.len()]);

fn method_index(method: Method) -> usize {
    Method::ALL
        .iter()
        .position(|&m| m == method)
        .unwrap_or_default()
}

impl IterationBudgets {
    /// No override: every method keeps its default limit.
    pub fn none() -> Self {
        IterationBudgets::default()
    }

    /// The limit of `method`, if overridden.
    pub fn get(&self, method: Method) -> Option<usize> {
        self.0[method_index(method)]
    }

    /// Budgets from `(method, limit)` pairs of positive limits (a zero limit leaves its method
    /// unset).
    pub(super) fn from_pairs(pairs: &[(Method, usize)]) -> Self {
        let mut b = IterationBudgets::none();
        for &(m, limit) in pairs {
            b.0[method_index(m)] = (limit > 0).then_some(limit);
        }
        b
    }

    /// Sets (`Some`) or clears (`None`) the limit of `method`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`max_iter`) for a limit of 0 or above [`MAX_BUDGET`].
    pub fn set(&mut self, method: Method, limit: Option<usize>) -> Result<()> {
        if let Some(limit) = limit {
            check_budget(method, limit)?;
        }
        self.0[method_index(method)] = limit;
        Ok(())
    }

    /// With `method` limited to `limit` iterations.
    ///
    /// # Errors
    /// As [`IterationBudgets::set`].
    pub fn with(mut self, method: Method, limit: usize) -> Result<Self> {
        self.set(method, Some(limit))?;
        Ok(self)
    }

    /// The overridden limits, in the order of [`Method::ALL`].
    pub fn iter(&self) -> impl Iterator<Item = (Method, usize)> + '_ {
        Method::ALL
            .iter()
            .zip(self.0)
            .filter_map(|(&m, l)| l.map(|l| (m, l)))
    }

    /// The limits of `other` replace those of `self` where `other` has one.
    pub fn merged(mut self, other: &IterationBudgets) -> Self {
        for (m, l) in other.iter() {
            self.0[method_index(m)] = Some(l);
        }
        self
    }

    /// Parses `name=N,name=N` (e.g. `fista=20,cgls=30`).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`max_iter`) for an unknown method, a missing `=`, or a limit
    /// that is not a positive integer.
    pub fn parse(text: &str) -> Result<Self> {
        let mut b = IterationBudgets::none();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let Some((name, n)) = item.split_once('=') else {
                return Err(Error::param(
                    "max_iter",
                    format!("expected SOLVER=N (e.g. fista=20), got {item:?}"),
                ));
            };
            let method = parse_method(name.trim(), "max_iter")?;
            let n: usize = n.trim().parse().map_err(|_| {
                Error::param(
                    "max_iter",
                    format!("{name}: expected a positive integer, got {:?}", n.trim()),
                )
            })?;
            b.set(method, Some(n))?;
        }
        Ok(b)
    }
}

impl std::fmt::Display for IterationBudgets {
    /// `name=N,…`, or `defaults` when nothing is overridden.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let items: Vec<String> = self.iter().map(|(m, l)| format!("{m}={l}")).collect();
        if items.is_empty() {
            f.write_str("defaults")
        } else {
            f.write_str(&items.join(","))
        }
    }
}

impl Serialize for IterationBudgets {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_map(self.iter().map(|(m, l)| (m.name(), l)))
    }
}

impl<'de> Deserialize<'de> for IterationBudgets {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let map = std::collections::BTreeMap::<String, usize>::deserialize(d)?;
        let mut b = IterationBudgets::none();
        for (name, limit) in map {
            let method = parse_method(&name, "max_iter").map_err(D::Error::custom)?;
            b.set(method, Some(limit)).map_err(D::Error::custom)?;
        }
        Ok(b)
    }
}

/// A method by its command-line name, with the valid names in the error.
pub(super) fn parse_method(name: &str, key: &'static str) -> Result<Method> {
    name.parse::<Method>().map_err(|_| {
        Error::param(
            key,
            format!(
                "unknown solver {name:?}; valid solvers: {}",
                Method::NAMES.join(", ")
            ),
        )
    })
}

/// Parses a comma-separated list of solver names (`all` for every method but IHT, as in the
/// demo).
///
/// # Errors
/// [`Error::InvalidParameter`] (`solvers`) for an unknown name or an empty list.
pub fn parse_solvers(text: &str) -> Result<Vec<Method>> {
    let names = list_items(text);
    if names == ["all"] {
        return Ok(DEFAULT_SOLVERS.to_vec());
    }
    if names.is_empty() {
        return Err(Error::param("solvers", "the list of solvers is empty"));
    }
    names.iter().map(|n| parse_method(n, "solvers")).collect()
}

/// Parses a comma-separated list of scene names (`paper,transparent`).
///
/// # Errors
/// [`Error::InvalidParameter`] (`scene`) for an unknown name or an empty list.
pub fn parse_scenes(text: &str) -> Result<Vec<SceneKind>> {
    let names = list_items(text);
    if names.is_empty() {
        return Err(Error::param("scene", "the list of scenes is empty"));
    }
    names.iter().map(|n| n.parse()).collect()
}

/// A noise level: `None` is noise-free, `Some(s)` white Gaussian noise at s dB SNR.
pub type NoiseLevel = Option<f64>;

/// Parses one noise level: `none`, `inf` (noise-free) or a number of dB.
///
/// # Errors
/// [`Error::InvalidParameter`] (`snr_db`) for anything else, NaN or −∞.
pub fn parse_noise_level(text: &str) -> Result<NoiseLevel> {
    let t = text.trim();
    if t.eq_ignore_ascii_case("none") {
        return Ok(None);
    }
    let v: f64 = t.parse().map_err(|_| {
        Error::param(
            "snr_db",
            format!("expected a number of dB, or none for noise-free, got {t:?}"),
        )
    })?;
    noise_level(v).map_err(|e| Error::param("snr_db", e))
}

/// +∞ is noise-free; other values must be finite.
pub(super) fn noise_level(v: f64) -> std::result::Result<NoiseLevel, String> {
    if v == f64::INFINITY {
        Ok(None)
    } else if v.is_finite() {
        Ok(Some(v))
    } else {
        Err(format!(
            "the SNR must be a finite number of dB (or none / inf for noise-free), got {}",
            crate::units::number(v)
        ))
    }
}

/// Parses a comma-separated list of noise levels (see [`parse_noise_level`]).
///
/// # Errors
/// As [`parse_noise_level`], and for an empty list.
pub fn parse_noise_levels(text: &str) -> Result<Vec<NoiseLevel>> {
    let items = list_items(text);
    if items.is_empty() {
        return Err(Error::param("snr_db", "the list of noise levels is empty"));
    }
    items.into_iter().map(parse_noise_level).collect()
}

/// Parses a comma-separated list of pulse lengths.
///
/// # Errors
/// [`Error::InvalidParameter`] (`pulse_lens`) for an entry that is not a positive integer, or an
/// empty list.
pub fn parse_pulse_lens(text: &str) -> Result<Vec<usize>> {
    let items = list_items(text);
    if items.is_empty() {
        return Err(Error::param(
            "pulse_lens",
            "the list of pulse lengths is empty",
        ));
    }
    items
        .into_iter()
        .map(|t| match t.parse::<usize>() {
            Ok(v) if v > 0 => Ok(v),
            _ => Err(Error::param(
                "pulse_lens",
                format!("expected positive integers (e.g. 10000,20000), got {t:?}"),
            )),
        })
        .collect()
}

/// `noise-free` or `20 dB`.
pub fn noise_text(level: NoiseLevel) -> String {
    match level {
        None => "noise-free".into(),
        Some(db) => format!("{db} dB"),
    }
}

/// The solvers of the demo: every method but IHT.
pub const DEFAULT_SOLVERS: [Method; 9] = [
    Method::Backprojection,
    Method::BackprojectionDebiased,
    Method::Cgls,
    Method::Fista,
    Method::Cosamp,
    Method::Amp,
    Method::ModelBased,
    Method::Tv,
    Method::Auto,
];

/// The non-empty, trimmed items of a comma-separated list.
fn list_items(text: &str) -> Vec<&str> {
    text.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect()
}
