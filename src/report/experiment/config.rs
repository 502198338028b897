//! What an experiment runs: presets with validated defaults, a TOML file layered over them, and
//! the limits that keep a run within one machine.

use std::path::{Path, PathBuf};

use serde::{Serialize, Serializer};

use crate::error::{Error, Result};
use crate::lidar::Geometry;
use crate::recon::Method;

use super::file::seed_value;
pub use super::file::{ConfigFile, ExperimentPatch};
pub use super::values::*;

/// The most seeds of one sweep.
pub const MAX_SEEDS: usize = 10_000;

/// The most Lanczos iterations of FISTA's step estimate.
pub const MAX_POWER_ITERATIONS: usize = 100_000;

/// Working copies of the scene a run holds besides the simulation (the estimate, the solver's
/// iterates, gradients and the depth maps): what the memory check of an experiment counts.
const SCENE_COPIES: u128 = 8;

/// Seed of run `i` of a sweep with base seed `seed`: `seed + 10·i`, so that the derived seeds
/// (pulse SEED, codes SEED+1, noise SEED+2, scene SEED+3) of different runs never coincide.
pub fn run_seed(seed: u64, i: usize) -> u64 {
    seed.wrapping_add(10u64.wrapping_mul(i as u64))
}

/// A complete, validated description of an experiment: the scene, the sweep (pulse lengths ×
/// seeds × noise levels) and the solvers with their iteration budgets.
///
/// Build one from a preset ([`ExperimentConfig::demo`], [`ExperimentConfig::compare_quick`], …),
/// layer [`ExperimentPatch`]es over it (a config file's section, then the command-line flags),
/// and [`validate`](ExperimentConfig::validate) the result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExperimentConfig {
    /// Output folder.
    pub out: PathBuf,
    /// The scenes, in the order they run for each seed (in TOML, `scene`: a name or a list).
    pub scenes: Vec<SceneKind>,
    /// The grid M×N×K_s (in TOML, `"100x100x40"`).
    #[serde(serialize_with = "geometry_text")]
    pub size: Geometry,
    /// Fraction of lit pixels of a [`SceneKind::Random`] scene, in [0, 1].
    pub lit_fraction: f64,
    /// Pulse lengths K_p, in the order they run.
    pub pulse_lens: Vec<usize>,
    /// Methods, in the order they run for each problem.
    #[serde(serialize_with = "method_names")]
    pub solvers: Vec<Method>,
    /// Noise levels (in TOML, dB numbers or `"none"` / `inf` for noise-free).
    #[serde(serialize_with = "noise_levels")]
    pub snr_db: Vec<NoiseLevel>,
    /// Number of seeds: run `i` uses [`run_seed`]`(seed, i)`.
    pub seeds: usize,
    /// Base seed.
    pub seed: u64,
    /// Precision of the computations.
    pub precision: Precision,
    /// Iteration budgets.
    pub max_iter: IterationBudgets,
    /// Lanczos iterations behind FISTA's step
    /// ([`crate::recon::ReconstructOptions::power_iterations`]; `None`: its default of up to
    /// 200).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub power_iterations: Option<usize>,
}

fn geometry_text<S: Serializer>(g: &Geometry, s: S) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_str(&g.to_string())
}

/// One scene is written as its name, several as a list.
fn scene_names<S: Serializer>(v: &[SceneKind], s: S) -> std::result::Result<S::Ok, S::Error> {
    match v {
        [one] => one.serialize(s),
        many => s.collect_seq(many),
    }
}

fn method_names<S: Serializer>(m: &[Method], s: S) -> std::result::Result<S::Ok, S::Error> {
    s.collect_seq(m.iter().map(|m| m.name()))
}

/// Noise-free levels are written as the string `"none"` (TOML has no null).
fn noise_levels<S: Serializer>(v: &[NoiseLevel], s: S) -> std::result::Result<S::Ok, S::Error> {
    #[derive(Serialize)]
    #[serde(untagged)]
    enum Level {
        Db(f64),
        Text(&'static str),
    }
    s.collect_seq(v.iter().map(|l| match l {
        Some(db) => Level::Db(*db),
        None => Level::Text("none"),
    }))
}

impl ExperimentConfig {
    /// This configuration with the fields `patch` sets replaced (budgets merged per method).
    pub fn patched(mut self, patch: &ExperimentPatch) -> Self {
        if let Some(v) = &patch.out {
            self.out = v.clone();
        }
        if let Some(v) = &patch.scene {
            self.scenes = v.clone();
        }
        if let Some(v) = patch.size {
            self.size = v;
        }
        if let Some(v) = patch.lit_fraction {
            self.lit_fraction = v;
        }
        if let Some(v) = &patch.pulse_lens {
            self.pulse_lens = v.clone();
        }
        if let Some(v) = &patch.solvers {
            self.solvers = v.clone();
        }
        if let Some(v) = &patch.snr_db {
            self.snr_db = v.clone();
        }
        if let Some(v) = patch.seeds {
            self.seeds = v;
        }
        if let Some(v) = &patch.max_iter {
            self.max_iter = self.max_iter.merged(v);
        }
        if let Some(v) = patch.power_iterations {
            self.power_iterations = Some(v);
        }
        self
    }

    /// Number of problems simulated: scenes × pulse lengths × seeds × noise levels.
    pub fn problems(&self) -> usize {
        self.scenes.len() * self.pulse_lens.len() * self.seeds * self.snr_db.len()
    }

    /// This configuration restricted to one of its scenes (for the per-scene tables and
    /// figures).
    pub fn for_scene(&self, scene: SceneKind) -> Self {
        ExperimentConfig {
            scenes: vec![scene],
            ..self.clone()
        }
    }

    /// The scenes' names joined by `+`, e.g. `paper+transparent`.
    pub fn scene_names(&self) -> String {
        let names: Vec<&str> = self.scenes.iter().map(|s| s.name()).collect();
        names.join("+")
    }

    /// Number of reconstructions: problems × solvers.
    pub fn runs(&self) -> usize {
        self.problems() * self.solvers.len()
    }

    /// Checks every field, naming the first offending one (`scene`, `pulse_lens`, `solvers`,
    /// `snr_db`, `seeds`, `size`, `lit_fraction`, `out`, `power_iterations`, `max_iter`).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the field: an empty or repeated list entry, a zero
    /// count, a non-finite SNR, a lit fraction outside [0, 1], an output folder name that is not
    /// UTF-8, an iteration budget above [`MAX_BUDGET`], or a problem too large for the limits
    /// of [`crate::limits`] and [`MAX_SEEDS`], or one whose largest problem needs more memory
    /// than is available ([`Error::TooLarge`]).
    pub fn validate(&self) -> Result<()> {
        if self.out.as_os_str().is_empty() {
            return Err(Error::param("out", "the output folder name is empty"));
        }
        if self.out.to_str().is_none() {
            return Err(Error::param(
                "out",
                format!(
                    "{}: the folder name is not UTF-8 text, which config.toml and results.json \
                     cannot hold",
                    self.out.display()
                ),
            ));
        }
        let g = self.size;
        Geometry::new(g.m, g.n, g.ks)?;
        g.check_bounds()?;
        if g.ks > i32::MAX as usize {
            return Err(Error::param("size", format!("{g}: too many depth bins")));
        }
        if self.scenes.is_empty() {
            return Err(Error::param("scene", "the list of scenes is empty"));
        }
        for (i, s) in self.scenes.iter().enumerate() {
            if self.scenes[..i].contains(s) {
                return Err(Error::param(
                    "scene",
                    format!("{} is listed twice", s.name()),
                ));
            }
        }
        if self.pulse_lens.is_empty() {
            return Err(Error::param(
                "pulse_lens",
                "the list of pulse lengths is empty",
            ));
        }
        for (i, &kp) in self.pulse_lens.iter().enumerate() {
            if kp == 0 {
                return Err(Error::param(
                    "pulse_lens",
                    "pulse lengths must be at least 1",
                ));
            }
            if self.pulse_lens[..i].contains(&kp) {
                return Err(Error::param(
                    "pulse_lens",
                    format!("K_p = {kp} is listed twice"),
                ));
            }
            crate::limits::check_count("pulse_lens", kp, crate::limits::MAX_PULSE_LEN)?;
        }
        // The largest problem must fit in memory: its simulation and a run's working copies.
        let size = match self.precision {
            Precision::F32 => 4,
            Precision::F64 => 8,
        };
        if let Some(&kp) = self.pulse_lens.iter().max() {
            let spec = crate::lidar::SimulationSpec::new(g, kp, self.seed);
            let simulation = match self.precision {
                Precision::F32 => spec.memory_plan::<f32>(),
                Precision::F64 => spec.memory_plan::<f64>(),
            }
            .map_err(|e| match e {
                Error::InvalidParameter { reason, .. } => Error::param("size", reason),
                other => other,
            })?;
            simulation
                .add(
                    "solver working copies",
                    SCENE_COPIES * g.voxels() as u128,
                    size,
                )
                .check(
                    &format!("an experiment on {g} with K_p up to {kp}"),
                    "lower --size or --pulse-lens",
                )?;
        }
        if self.solvers.is_empty() {
            return Err(Error::param("solvers", "the list of solvers is empty"));
        }
        for (i, m) in self.solvers.iter().enumerate() {
            if self.solvers[..i].contains(m) {
                return Err(Error::param("solvers", format!("{m} is listed twice")));
            }
        }
        if self.snr_db.is_empty() {
            return Err(Error::param("snr_db", "the list of noise levels is empty"));
        }
        for (i, l) in self.snr_db.iter().enumerate() {
            if let Some(v) = l {
                if !v.is_finite() {
                    return Err(Error::param(
                        "snr_db",
                        format!(
                            "the SNR must be a finite number of dB, got {}",
                            crate::units::number(*v)
                        ),
                    ));
                }
            }
            if self.snr_db[..i].contains(l) {
                return Err(Error::param(
                    "snr_db",
                    format!("{} is listed twice", noise_text(*l)),
                ));
            }
        }
        crate::limits::check_count("seeds", self.seeds, MAX_SEEDS)?;
        if !(0.0..=1.0).contains(&self.lit_fraction) {
            return Err(Error::param(
                "lit_fraction",
                format!(
                    "must be in [0, 1], got {}",
                    crate::units::number(self.lit_fraction)
                ),
            ));
        }
        if let Some(n) = self.power_iterations {
            crate::limits::check_count("power_iterations", n, MAX_POWER_ITERATIONS)?;
        }
        for (m, l) in self.max_iter.iter() {
            check_budget(m, l)?;
        }
        Ok(())
    }

    /// The configuration as TOML (a `[demo]` or `[compare]` section under `section`, with the
    /// seed and precision at the top), loadable again with `--config`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`config`) if the configuration cannot be written as TOML.
    pub fn to_toml(&self, section: &str) -> Result<String> {
        #[derive(Serialize)]
        struct Section<'a> {
            out: &'a Path,
            #[serde(serialize_with = "scene_names")]
            scene: &'a [SceneKind],
            #[serde(serialize_with = "geometry_text")]
            size: &'a Geometry,
            lit_fraction: f64,
            pulse_lens: &'a [usize],
            #[serde(serialize_with = "method_names")]
            solvers: &'a [Method],
            #[serde(serialize_with = "noise_levels")]
            snr_db: &'a [NoiseLevel],
            seeds: usize,
            max_iter: &'a IterationBudgets,
            #[serde(skip_serializing_if = "Option::is_none")]
            power_iterations: Option<usize>,
        }
        let mut doc = toml::Table::new();
        doc.insert("seed".into(), seed_value(self.seed));
        doc.insert(
            "precision".into(),
            toml::Value::String(self.precision.name().into()),
        );
        let body = Section {
            out: &self.out,
            scene: &self.scenes,
            size: &self.size,
            lit_fraction: self.lit_fraction,
            pulse_lens: &self.pulse_lens,
            solvers: &self.solvers,
            snr_db: &self.snr_db,
            seeds: self.seeds,
            max_iter: &self.max_iter,
            power_iterations: self.power_iterations,
        };
        let value = toml::Value::try_from(body)
            .map_err(|e| Error::param("config", format!("cannot write it as TOML: {e}")))?;
        doc.insert(section.into(), value);
        toml::to_string(&doc)
            .map_err(|e| Error::param("config", format!("cannot write it as TOML: {e}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid() {
        for c in [
            ExperimentConfig::demo(),
            ExperimentConfig::demo_tiny(),
            ExperimentConfig::compare(),
            ExperimentConfig::compare_quick(),
            ExperimentConfig::compare_tiny(),
            ExperimentConfig::compare_research(),
        ] {
            c.validate().unwrap();
        }
        assert_eq!(ExperimentConfig::demo().runs(), 27);
        assert_eq!(
            ExperimentConfig::compare_quick().size.critical_pulse_len(),
            4081
        );
    }

    #[test]
    fn a_file_patches_a_preset_and_round_trips() {
        let file = ConfigFile::parse(
            "seed = 4\n[demo]\npulse_lens = [100, 200]\nsolvers = [\"cgls\", \"tv\"]\n\
             snr_db = [\"none\", 20, inf]\nmax_iter = { cgls = 7 }\n",
        );
        // inf and "none" are the same level: listed twice.
        let file = file.unwrap();
        let c = ExperimentConfig::demo_tiny().patched(file.demo.as_ref().unwrap());
        assert_eq!(c.pulse_lens, [100, 200]);
        assert_eq!(c.solvers, [Method::Cgls, Method::Tv]);
        assert_eq!(c.max_iter.get(Method::Cgls), Some(7));
        assert_eq!(
            c.max_iter.get(Method::Fista),
            ExperimentConfig::demo_budgets().get(Method::Fista)
        );
        let e = c.validate().unwrap_err();
        assert!(e.to_string().contains("listed twice"), "{e}");

        let c = ExperimentConfig {
            snr_db: vec![None, Some(20.0)],
            seed: 4,
            ..c
        };
        c.validate().unwrap();
        let text = c.to_toml("demo").unwrap();
        let back = ConfigFile::parse(&text).unwrap();
        assert_eq!(back.seed, Some(4));
        let again = ExperimentConfig::demo().patched(back.demo.as_ref().unwrap());
        assert_eq!(ExperimentConfig { seed: 4, ..again }, c);
    }

    #[test]
    fn bad_files_name_the_line_and_the_problem() {
        let e = ConfigFile::parse("[demo]\nsolvers = [\"cgls\", \"nope\"]\n").unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("line 2") && msg.contains("unknown solver"),
            "{msg}"
        );
        assert!(!msg.contains('\n'), "{msg}");
        let e = ConfigFile::parse("[demo]\ncolour = 1\n").unwrap_err();
        assert!(e.to_string().contains("colour"), "{e}");
        let e = ConfigFile::parse("[demo]\nsize = \"0x4x4\"\n").unwrap_err();
        assert!(e.to_string().contains("at least 1"), "{e}");
    }

    #[test]
    fn flags_parse_with_their_own_messages() {
        assert_eq!(
            parse_solvers("cgls, fista").unwrap(),
            [Method::Cgls, Method::Fista]
        );
        assert_eq!(parse_solvers("all").unwrap(), DEFAULT_SOLVERS);
        assert!(parse_solvers("lasso")
            .unwrap_err()
            .to_string()
            .contains("valid solvers"));
        assert_eq!(
            parse_noise_levels("none, 20,inf").unwrap(),
            [None, Some(20.0), None]
        );
        assert!(parse_noise_levels("loud").is_err());
        assert!(parse_pulse_lens("10,0").is_err());
        let b = IterationBudgets::parse("fista=3,model-based=2").unwrap();
        assert_eq!(b.to_string(), "fista=3,model-based=2");
        assert!(IterationBudgets::parse("fista=0").is_err());
        assert!(IterationBudgets::parse("fista").is_err());
    }

    #[test]
    fn seeds_beyond_toml_integers_are_written_as_digits_and_read_back() {
        let big = i64::MAX as u64;
        for seed in [0, big, big + 1, u64::MAX] {
            let c = ExperimentConfig {
                seed,
                ..ExperimentConfig::compare_tiny()
            };
            let text = c.to_toml("compare").unwrap();
            assert_eq!(ConfigFile::parse(&text).unwrap().seed, Some(seed), "{text}");
        }
        assert_eq!(ConfigFile::parse("seed = \"12\"\n").unwrap().seed, Some(12));
        for bad in [
            "seed = -1\n",
            "seed = \"-1\"\n",
            "seed = \"x\"\n",
            "seed = 1.5\n",
        ] {
            let e = ConfigFile::parse(bad).unwrap_err().to_string();
            assert!(
                e.contains("line 1") && e.contains("a seed from 0"),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn settings_config_toml_cannot_hold_are_refused() {
        let budgets = IterationBudgets::parse(&format!("cgls={MAX_BUDGET}")).unwrap();
        let c = ExperimentConfig {
            max_iter: budgets,
            ..ExperimentConfig::compare_tiny()
        };
        c.validate().unwrap();
        let text = c.to_toml("compare").unwrap();
        assert!(text.contains(&format!("cgls = {MAX_BUDGET}")), "{text}");
        let e = IterationBudgets::parse(&format!("cgls={}", MAX_BUDGET + 1))
            .unwrap_err()
            .to_string();
        assert!(e.contains("max_iter:") && e.contains("config.toml"), "{e}");
        #[cfg(unix)]
        {
            use std::os::unix::ffi::OsStrExt;
            let c = ExperimentConfig {
                out: std::ffi::OsStr::from_bytes(b"bad\xff").into(),
                ..ExperimentConfig::compare_tiny()
            };
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains("out:") && e.contains("UTF-8"), "{e}");
        }
    }

    #[test]
    fn impossible_sizes_are_refused() {
        let mut c = ExperimentConfig::demo_tiny();
        c.size = Geometry {
            m: 5000,
            n: 8,
            ks: 8,
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("size") && e.contains("4096"), "{e}");
        c.size = Geometry {
            m: 4000,
            n: 4000,
            ks: 1000,
        };
        c.pulse_lens = vec![100_000];
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("more than the") && e.contains("bytes"), "{e}");
        c.size = Geometry {
            m: 100,
            n: 100,
            ks: 4,
        };
        c.pulse_lens = vec![usize::MAX / 2];
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("pulse_lens"), "{e}");
    }
}
