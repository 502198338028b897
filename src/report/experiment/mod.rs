//! Experiments: the paper's experiment extended to every solver ([`run_demo`]), and a sweep of
//! the pulse length across the compressive, critical and redundant regimes ([`run_compare`]).
//!
//! An experiment is described by an [`ExperimentConfig`] (a preset, a TOML file and flags layered
//! over it). It simulates one problem per pulse length, seed and noise level — the scene, a
//! Bernoulli pulse from SEED, binary codes from SEED+1, Gaussian noise from SEED+2 (a random
//! scene from SEED+3), exactly as `rdlidar simulate --seed SEED` does — and reconstructs each
//! problem with every solver through [`crate::recon::reconstruct`], with the iteration budgets of
//! the configuration. Every run gives one [`Row`]: the solver, K_p and its regime, the lit
//! pixels recovered at the exact depth, false detections, the depth RMSE, ‖X − X̂‖/‖X‖, the
//! wall time, iterations and why the solver stopped.
//!
//! The output folder receives the complete set of files or nothing new ([`StagedDir`]): every
//! file is written into a staging folder beside it, `.NAME.staging-PID`, and moved into place at
//! the end. Rows are appended there to `results.csv.partial` and `results.jsonl.partial` as each
//! run finishes (flushed, so that a process killed outright leaves its finished rows in the
//! staging folder). When the sweep ends — or is stopped through the `stop` flag, which is checked
//! between runs — the tables (`results.csv`, `results.json`, `results.md`), the resolved
//! `config.toml` and the figures are written, the partial files removed and the set moved into
//! the output folder. Any error on the way (a full disk, say) removes the staging folder.
//!
//! ```
//! use std::sync::atomic::AtomicBool;
//! use rdlidar::report::experiment::{run_demo, ExperimentConfig};
//! use rdlidar::recon::Method;
//!
//! # fn main() -> rdlidar::Result<()> {
//! let dir = std::env::temp_dir().join(format!("rdlidar-doc-demo-{}", std::process::id()));
//! let config = ExperimentConfig {
//!     out: dir.clone(),
//!     pulse_lens: vec![300],
//!     solvers: vec![Method::BackprojectionDebiased, Method::ModelBased],
//!     ..ExperimentConfig::demo_tiny()
//! };
//! let outcome = run_demo(&config, true, &mut (), &AtomicBool::new(false))?;
//! assert_eq!(outcome.rows.len(), 2);
//! assert!(dir.join("results.csv").is_file() && dir.join("depth_kp300.png").is_file());
//! # std::fs::remove_dir_all(&dir).ok();
//! # Ok(())
//! # }
//! ```

mod config;
mod console;
mod deal;
mod figures;
mod file;
mod merge;
mod presets;
mod run;
mod staging;
mod sweep;
mod table;
mod values;

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use serde::{Deserialize, Serialize};

pub use config::{
    noise_text, parse_noise_level, parse_noise_levels, parse_pulse_lens, parse_scenes,
    parse_solvers, run_seed, ConfigFile, ExperimentConfig, ExperimentPatch, IterationBudgets,
    NoiseLevel, Precision, SceneKind, DEFAULT_SOLVERS, MAX_BUDGET, MAX_POWER_ITERATIONS, MAX_SEEDS,
};
pub use console::Console;
pub use deal::{deal, in_sweep_order, Shard, SweepShare};
pub use figures::{
    check_depth_figure, depth_figure, error_vs_time, pareto_chart, phase_chart, ERROR_FLOOR,
};
pub use merge::merge_compare;
use run::Run;
pub use staging::{abandon_staged_and_exit, StagedDir};
pub use sweep::{CaseDepths, Sweep};
pub use table::{
    csv_header, csv_line, markdown_header, markdown_row, markdown_table, summary_markdown, Column,
    PartialFiles, CSV_COLUMNS,
};

use crate::error::Result;
use crate::lidar::Geometry;
use crate::recon::Method;

/// One simulated problem of a sweep: a scene, a pulse length, a seed and a noise level.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Case {
    /// The scene.
    pub scene: SceneKind,
    /// Pulse length K_p.
    pub pulse_len: usize,
    /// Seed: pulse SEED, codes SEED+1, noise SEED+2, random scene SEED+3.
    pub seed: u64,
    /// Noise level (`None`: noise-free).
    pub snr_db: NoiseLevel,
}

impl ExperimentConfig {
    /// The problems of the sweep in the order they run: seeds, then scenes, then noise levels,
    /// then pulse lengths (so that a sweep stopped early has covered every scene and pulse
    /// length for its first seeds).
    pub fn cases(&self) -> Vec<Case> {
        let mut cases = Vec::with_capacity(self.problems());
        for i in 0..self.seeds {
            for &scene in &self.scenes {
                for &snr_db in &self.snr_db {
                    for &pulse_len in &self.pulse_lens {
                        cases.push(Case {
                            scene,
                            pulse_len,
                            seed: run_seed(self.seed, i),
                            snr_db,
                        });
                    }
                }
            }
        }
        cases
    }
}

/// The result of one reconstruction.
///
/// Quality fields are `None` when the solver failed (then `error` says why); `iterations`,
/// `termination` and the apply counts are `None` for the backprojections, which do not iterate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Scene kind.
    pub scene: String,
    /// Grid, `MxNxKS`.
    pub size: String,
    /// `f32` or `f64`.
    pub precision: String,
    /// The problem's seed.
    pub seed: u64,
    /// Noise level in dB (`None`: noise-free).
    pub snr_db: Option<f64>,
    /// Pulse length K_p.
    pub pulse_len: usize,
    /// Measurements K = K_p + K_s − 1.
    pub samples: usize,
    /// `compressive`, `critical` or `redundant`.
    pub regime: String,
    /// The critical pulse length (M·N − 1)·K_s + 1.
    pub critical_pulse_len: usize,
    /// The method asked for.
    pub solver: String,
    /// The method that produced the estimate (differs from `solver` for `auto`).
    pub method_used: String,
    /// The iteration budget given to the solver (`None`: its default limit).
    pub max_iter: Option<usize>,
    /// Lit pixels of the truth.
    pub lit: usize,
    /// Lit pixels recovered at the exact depth.
    pub exact: Option<usize>,
    /// `exact / lit` in percent.
    pub exact_pct: Option<f64>,
    /// Pixels lit in the estimate but empty in the truth.
    pub false_detections: Option<usize>,
    /// Pixels lit in the truth but empty in the estimate.
    pub missed: Option<usize>,
    /// Returns (nonzero voxels) of the truth: more than `lit` in a semi-transparent scene.
    pub true_returns: usize,
    /// Returns of the estimate at the voxel of a true return.
    pub returns_exact: Option<usize>,
    /// Returns of the estimate at a voxel that is empty in the truth.
    pub returns_false: Option<usize>,
    /// Root-mean-square depth error over the detected lit pixels, in bins.
    pub depth_rmse_bins: Option<f64>,
    /// ‖X − X̂‖ / ‖X‖ over the whole cubes.
    pub relative_error: Option<f64>,
    /// Wall time of the reconstruction in seconds (peak extraction included, simulation not).
    pub time_s: f64,
    /// Iterations of the iterative solver.
    pub iterations: Option<usize>,
    /// Why the solver stopped (`max_iterations`, `converged`, `residual`, …).
    pub termination: Option<String>,
    /// Forward applications of the operator.
    pub forward_applies: Option<usize>,
    /// Adjoint applications of the operator (correlations included).
    pub adjoint_applies: Option<usize>,
    /// Applications of the operator restricted to a few columns (a support, a pixel's columns),
    /// each costing about its share of a full application.
    pub support_applies: Option<usize>,
    /// The solver's error, if it failed.
    pub error: Option<String>,
}

/// `MaxIterations` → `max_iterations`.
fn snake_case(name: &str) -> String {
    let mut s = String::with_capacity(name.len() + 4);
    for (i, c) in name.chars().enumerate() {
        if c.is_ascii_uppercase() {
            if i > 0 {
                s.push('_');
            }
            s.push(c.to_ascii_lowercase());
        } else {
            s.push(c);
        }
    }
    s
}

/// What an experiment reports while it runs, to an [`ExperimentObserver`].
#[derive(Debug)]
pub enum Event<'a> {
    /// The sweep is about to start: `runs` reconstructions of `problems` problems, with an
    /// estimated total work (arbitrary units, for progress and ETA).
    Planned {
        /// Problems to simulate.
        problems: usize,
        /// Reconstructions.
        runs: usize,
        /// Estimated total work.
        work: f64,
        /// The columns of the table to print.
        columns: &'a [Column],
    },
    /// A problem is being simulated.
    Simulating {
        /// The problem.
        case: &'a Case,
        /// The grid.
        geometry: Geometry,
    },
    /// A reconstruction starts: run `index` (from 0) of `runs`.
    RunStarted {
        /// Index of the run.
        index: usize,
        /// Total runs.
        runs: usize,
        /// The method.
        method: Method,
        /// The problem.
        case: &'a Case,
    },
    /// A reconstruction finished, with its estimated work.
    RunFinished {
        /// Index of the run.
        index: usize,
        /// Total runs.
        runs: usize,
        /// The result.
        row: &'a Row,
        /// Its estimated work (the units of [`Event::Planned`]).
        work: f64,
    },
    /// The rows of every process were gathered (a sweep shared by several processes), in the
    /// order one process runs them.
    Gathered {
        /// Processes that ran the sweep.
        processes: usize,
        /// Every row.
        rows: &'a [Row],
    },
    /// The sweep stopped before its end (the stop flag was raised).
    Interrupted {
        /// Runs finished.
        finished: usize,
        /// Runs planned.
        runs: usize,
    },
}

/// Receives the [`Event`]s of an experiment (progress bars, logs). `()` ignores them.
pub trait ExperimentObserver {
    /// Called for each event, in order.
    fn event(&mut self, event: &Event<'_>);
}

impl ExperimentObserver for () {
    fn event(&mut self, _: &Event<'_>) {}
}

/// Estimated cost of one run, in operator applications at K_p = 1000, for the progress bar's
/// ETA (rough, measured at 100×100×40; the bar's rate estimate corrects it as runs finish).
pub fn estimated_work(method: Method, budget: Option<usize>, pulse_len: usize) -> f64 {
    let it = |default: usize| budget.unwrap_or(default) as f64;
    let applies = match method {
        Method::Backprojection | Method::BackprojectionDebiased => 1.0,
        Method::Cgls => 2.0 * it(300),
        Method::Fista => 3.0 * it(200) + 20.0,
        Method::Iht => 3.0 * it(100),
        Method::Cosamp => 10.0 * it(100),
        Method::SupportLs => 10.0 * it(12),
        Method::Amp => 2.0 * it(60),
        Method::ModelBased => 15.0 * it(30),
        Method::Tv => 30.0 * it(30),
        Method::CoarseToFine => 40.0 * it(30),
        Method::Auto => 45.0 * it(30),
    };
    applies * pulse_len.max(1) as f64 / 1000.0
}

/// What [`run_demo`] and [`run_compare`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// One row per finished run.
    pub rows: Vec<Row>,
    /// Whether the sweep was stopped before its end.
    pub interrupted: bool,
    /// Runs planned.
    pub planned: usize,
    /// The files written, in order.
    pub files: Vec<PathBuf>,
    /// Wall time of the sweep (simulations and reconstructions).
    pub elapsed: Duration,
    /// Wall time of the whole experiment, tables and figures included.
    pub total: Duration,
}

/// The columns of the demo's table.
pub const DEMO_COLUMNS: [Column; 11] = [
    Column::Solver,
    Column::PulseLen,
    Column::Regime,
    Column::Exact,
    Column::FalseDetections,
    Column::Rmse,
    Column::RelativeError,
    Column::Time,
    Column::Iterations,
    Column::Cost,
    Column::Termination,
];

/// The columns of the compare sweep's table.
pub const COMPARE_COLUMNS: [Column; 15] = [
    Column::Scene,
    Column::Seed,
    Column::Snr,
    Column::Solver,
    Column::PulseLen,
    Column::Regime,
    Column::Exact,
    Column::Returns,
    Column::FalseDetections,
    Column::Rmse,
    Column::RelativeError,
    Column::Time,
    Column::Iterations,
    Column::Cost,
    Column::Termination,
];

/// The main job: `config` swept (by default the paper scene at K_p = 10000, 20000, 30000, every
/// solver), then, in `config.out`: `results.csv`, `results.json`, `results.md`, `config.toml`,
/// one `depth_kp{K_p}.png` per problem (the true depth map and every solver's, side by side,
/// with a colour bar in metres and a key for pixels without a return; problems of further seeds
/// or noise levels add `_seed{S}` / `_snr{X}db` to the name) and `error_vs_time.png`. With
/// several scenes, each scene has its own figures: `depth_{scene}_kp…` and
/// `error_vs_time_{scene}.png`.
///
/// The folder is created if needed; an existing non-empty folder is refused unless `force`.
/// Rows are streamed to partial files while the sweep runs (see the module documentation).
///
/// # Errors
/// An invalid configuration, an output folder that cannot be used, or a file that cannot be
/// written; errors of the simulation. A solver's failure is recorded in its row.
pub fn run_demo(
    config: &ExperimentConfig,
    force: bool,
    observer: &mut dyn ExperimentObserver,
    stop: &AtomicBool,
) -> Result<Outcome> {
    let run = Run {
        name: "demo",
        columns: &DEMO_COLUMNS,
        keep_depths: true,
    };
    let figures = |sweep: &Sweep, dir: &Path, files: &mut Vec<PathBuf>| -> Result<()> {
        let several = config.seeds > 1 || config.snr_db.len() > 1;
        for d in &sweep.depths {
            let scene = config.for_scene(d.case.scene);
            let name = format!(
                "depth_{}kp{}",
                scene_prefix(config, d.case.scene),
                d.case.pulse_len
            );
            let name = match (several, d.case.snr_db) {
                (false, _) => name,
                (true, None) => format!("{name}_seed{}", d.case.seed),
                (true, Some(s)) => format!("{name}_seed{}_snr{s}db", d.case.seed),
            };
            let path = dir.join(name + ".png");
            let rows: Vec<&Row> = sweep
                .rows
                .iter()
                .filter(|r| r.scene == d.case.scene.name())
                .filter(|r| r.pulse_len == d.case.pulse_len && r.seed == d.case.seed)
                .filter(|r| r.snr_db == d.case.snr_db)
                .collect();
            depth_figure(&scene, d, &rows)?.save_png(&path)?;
            files.push(path);
        }
        for (scene, rows) in per_scene(config, &sweep.rows) {
            let path = dir.join(format!(
                "error_vs_time{}.png",
                scene_suffix(config, scene.scenes[0])
            ));
            error_vs_time(&scene, &rows)?.save_png(&path)?;
            files.push(path);
        }
        Ok(())
    };
    run.execute(
        config,
        (force, &SweepShare::WHOLE),
        observer,
        stop,
        &figures,
    )
}

/// `""` for a one-scene experiment, else the scene's name and `_`: the start of its files' names.
fn scene_prefix(config: &ExperimentConfig, scene: SceneKind) -> String {
    if config.scenes.len() > 1 {
        format!("{}_", scene.name())
    } else {
        String::new()
    }
}

/// `""` for a one-scene experiment, else `_` and the scene's name: the end of its files' names.
fn scene_suffix(config: &ExperimentConfig, scene: SceneKind) -> String {
    if config.scenes.len() > 1 {
        format!("_{}", scene.name())
    } else {
        String::new()
    }
}

/// For each scene with finished rows, the configuration restricted to it and its rows.
fn per_scene(config: &ExperimentConfig, rows: &[Row]) -> Vec<(ExperimentConfig, Vec<Row>)> {
    config
        .scenes
        .iter()
        .map(|&s| {
            let mine: Vec<Row> = rows
                .iter()
                .filter(|r| r.scene == s.name())
                .cloned()
                .collect();
            (config.for_scene(s), mine)
        })
        .filter(|(_, rows)| !rows.is_empty())
        .collect()
}

/// The sweep across regimes: `config` swept (by default the paper scene 16×16×16 from K_p = 256
/// to 32768, several seeds and noise levels, every solver), then, in `config.out`:
/// `results.csv`, `results.json`, `results.md` (one row per run), `summary.md` (per scene and
/// noise level, the median over seeds of ‖X − X̂‖/‖X‖, of the exact-depth fraction — and of
/// the returns found at their voxel, for a semi-transparent scene — and of the wall time,
/// solver × K_p), `config.toml`, `pareto.png` (run time against error, every run, with the
/// Pareto front) and one `phase_{noise}.png` per noise level (median error against K_p on a log
/// axis, one line per solver, the critical K_p marked; `{noise}` is `noise-free` or e.g.
/// `20db`). With several scenes, each has its own figures: `pareto_{scene}.png` and
/// `phase_{scene}_{noise}.png`.
///
/// # Errors
/// As [`run_demo`].
pub fn run_compare(
    config: &ExperimentConfig,
    force: bool,
    observer: &mut dyn ExperimentObserver,
    stop: &AtomicBool,
) -> Result<Outcome> {
    run_compare_shared(config, (force, &SweepShare::WHOLE), observer, stop)
}

/// [`run_compare`] on `share`'s problems: one [`Shard`] of the sweep (the folder then holds
/// that shard's runs, to be merged with the others' by [`merge_compare`]), dealt again over the
/// processes of `share.space` (each runs whole problems; every row is gathered, and the first
/// process writes the folder as one process would, run times apart). The problems are dealt
/// by their estimated work (see [`deal`]).
///
/// Every process of `share.space` calls it with the same arguments; the processes agree on a
/// failure (an output folder that cannot be used, a failed simulation), which every process
/// returns. The processes but the first write nothing and return every row and no files.
///
/// # Errors
/// As [`run_compare`]; [`Error::InvalidParameter`](crate::Error::InvalidParameter) (`parts`) for another process's failure.
pub fn run_compare_shared(
    config: &ExperimentConfig,
    (force, share): (bool, &SweepShare<'_>),
    observer: &mut dyn ExperimentObserver,
    stop: &AtomicBool,
) -> Result<Outcome> {
    COMPARE.execute(
        config,
        (force, share),
        observer,
        stop,
        &|sweep, dir, files| compare_files(config, sweep, dir, files),
    )
}

/// The compare experiment's tables and columns.
const COMPARE: Run = Run {
    name: "compare",
    columns: &COMPARE_COLUMNS,
    keep_depths: false,
};

/// The compare experiment's own files: `summary.md`, the Pareto and phase charts.
fn compare_files(
    config: &ExperimentConfig,
    sweep: &Sweep,
    dir: &Path,
    files: &mut Vec<PathBuf>,
) -> Result<()> {
    let summary: Vec<String> = config
        .scenes
        .iter()
        .map(|&s| {
            let rows: Vec<Row> = sweep
                .rows
                .iter()
                .filter(|r| r.scene == s.name())
                .cloned()
                .collect();
            summary_markdown(&config.for_scene(s), &rows)
        })
        .collect();
    let path = dir.join("summary.md");
    crate::io::write_bytes_atomic(&path, summary.join("\n").as_bytes())?;
    files.push(path);
    for (scene, rows) in per_scene(config, &sweep.rows) {
        let kind = scene.scenes[0];
        let path = dir.join(format!("pareto{}.png", scene_suffix(config, kind)));
        pareto_chart(&scene, &rows)?.save_png(&path)?;
        files.push(path);
        for &level in &config.snr_db {
            let rows: Vec<Row> = rows.iter().filter(|r| r.snr_db == level).cloned().collect();
            if rows.is_empty() {
                continue;
            }
            let noise = match level {
                None => "noise-free".to_string(),
                Some(s) => format!("{s}db"),
            };
            let path = dir.join(format!("phase_{}{noise}.png", scene_prefix(config, kind)));
            phase_chart(&scene, level, &rows)?.save_png(&path)?;
            files.push(path);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn termination_names_are_snake_case() {
        assert_eq!(snake_case("MaxIterations"), "max_iterations");
        assert_eq!(snake_case("Converged"), "converged");
    }

    #[test]
    fn cases_run_seeds_then_noise_then_pulse_lengths() {
        let c = ExperimentConfig::compare_tiny();
        let cases = c.cases();
        assert_eq!(cases.len(), 3 * 2 * 2);
        assert_eq!(cases[0].pulse_len, 50);
        assert_eq!(cases[1].pulse_len, 211);
        assert_eq!(cases[3].snr_db, Some(20.0));
        assert_eq!(cases[6].seed, 10);
    }
}
