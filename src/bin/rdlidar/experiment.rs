//! `rdlidar demo` (also the command with no subcommand) and `rdlidar compare`: the experiments.

use std::path::PathBuf;
use std::process::ExitCode;

use rdlidar::lidar::Geometry;
use rdlidar::recon::Method;
use rdlidar::report::experiment::{
    self, ConfigFile, Console, ExperimentConfig, ExperimentObserver, ExperimentPatch,
    IterationBudgets, NoiseLevel, SceneKind as ExpSceneKind, Shard, SweepShare,
};
use rdlidar::settings::FrontEnd;

use crate::common::{
    check_not_input, errln, outln, parse_positive, parse_size, set_threads, CliResult, Failure,
    Globals, Precision,
};
use crate::ranks::Ranks;
use crate::signals::{self, Signal};

/// The options of `demo` (and of the command with no subcommand) and `compare`.
///
/// Each option overrides the experiment's preset and the config file's section.
#[derive(clap::Args, Debug, Default, PartialEq)]
pub struct ExperimentArgs {
    /// TOML file describing the experiment: top-level seed, precision, threads, quiet, and
    /// [demo] / [compare] sections with the keys out, scene, size, lit_fraction, pulse_lens,
    /// solvers, snr_db, seeds, max_iter, power_iterations (see docs/experiments.md). Flags
    /// override it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Output folder (default: out/ for demo, out-compare/ for compare).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Write into an existing non-empty output folder, replacing the experiment's files.
    #[arg(long)]
    pub force: bool,
    /// A small preset that runs in seconds (demo: 8x8x8, K_p 100,300,1000; compare: 6x6x6,
    /// K_p 50,211,800).
    #[arg(long)]
    pub tiny: bool,
    /// Scene: paper (the default), random, transparent (1 to 3 returns per pixel), or
    /// paper-continuous (the paper's scene between bins under the triangle response, every
    /// method estimating continuous depths, the depth RMSE in bins against the true ones);
    /// several, comma-separated, run one after the other with their own tables and figures.
    #[arg(long, value_name = "LIST", value_parser = parse_scenes)]
    pub scene: Option<ExpScenes>,
    /// Scene grid MxNxKS (at most 1024 rows and columns, 2^26 voxels).
    #[arg(long, value_name = "MxNxKS", value_parser = parse_size)]
    pub size: Option<Geometry>,
    /// Fraction of lit pixels of --scene random, in [0, 1] (default 0.5).
    #[arg(long, value_name = "F")]
    pub lit_fraction: Option<f64>,
    /// Pulse lengths K_p, comma-separated.
    #[arg(long, value_name = "LIST", value_parser = parse_pulse_lens)]
    pub pulse_lens: Option<PulseLens>,
    /// Solvers, comma-separated, or `all` (every solver but iht and support-ls): backprojection,
    /// backprojection-debiased, cgls, fista, iht, cosamp, support-ls, amp, model-based, tv,
    /// auto.
    #[arg(long, value_name = "LIST", value_parser = parse_solver_list)]
    pub solvers: Option<Solvers>,
    /// Noise levels in dB SNR, comma-separated; `none` for noise-free.
    #[arg(long, value_name = "LIST", value_parser = parse_noise_list, allow_hyphen_values = true)]
    pub snr_db: Option<NoiseLevels>,
    /// Number of seeds (SEED, SEED+10, …).
    #[arg(long, value_name = "N", value_parser = parse_positive)]
    pub seeds: Option<usize>,
    /// Iteration budgets, e.g. `fista=50,model-based=12` (other solvers keep the preset's).
    #[arg(long, value_name = "SOLVER=N,...", value_parser = parse_budgets)]
    pub max_iter: Option<IterationBudgets>,
    /// Lanczos iterations that estimate ‖A‖² for FISTA's step (demo default 15; compare: the
    /// solver's default of up to 200).
    #[arg(long, value_name = "N", value_parser = parse_positive)]
    pub power_iterations: Option<usize>,
}

/// The options of `compare`.
#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    #[command(flatten)]
    pub common: ExperimentArgs,
    /// The quick sweep: 6 pulse lengths, 2 seeds, 2 noise levels (under 5 minutes on 2 cores).
    #[arg(long, conflicts_with = "tiny")]
    pub quick: bool,
    /// The sweep at a research size: 32x32x40, the paper and a semi-transparent scene, K_p
    /// 2000 to 81842 (compressive, critical, 2x redundant), noise-free, 20 and 10 dB, 2 seeds,
    /// every solver and support-ls, written to out-research/.
    #[arg(long, conflicts_with_all = ["tiny", "quick"])]
    pub research: bool,
    /// Run share K of N of the sweep's problems (K from 1; each problem is a simulation and
    /// every solver on it, dealt by estimated work), e.g. as task K of a job array; --out then
    /// holds that shard's runs, and `compare --merge` joins the shards' folders.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    pub shard: Option<Shard>,
    /// Merge the output folders of every shard of one sweep (written by `compare --shard`)
    /// into --out: the tables, summary and figures of the whole sweep. Takes no other option
    /// but --out and --force.
    #[arg(long, value_name = "DIR", num_args = 1.., conflicts_with_all = ["shard", "quick", "research"])]
    pub merge: Vec<PathBuf>,
}

fn parse_shard(text: &str) -> Result<Shard, String> {
    Shard::parse(text).map_err(|e| FrontEnd::CommandLine.reason(&e))
}

/// Which preset an experiment starts from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Preset {
    /// The experiment's own default.
    #[default]
    Default,
    /// `--tiny`.
    Tiny,
    /// `compare --quick`.
    Quick,
    /// `compare --research`.
    Research,
}

/// Values of the experiment flags (newtypes, so that clap takes each list as one value).
#[derive(Debug, Clone, PartialEq)]
pub struct PulseLens(Vec<usize>);
#[derive(Debug, Clone, PartialEq)]
pub struct Solvers(Vec<Method>);
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseLevels(Vec<NoiseLevel>);
#[derive(Debug, Clone, PartialEq)]
pub struct ExpScenes(Vec<ExpSceneKind>);

fn parse_scenes(text: &str) -> Result<ExpScenes, String> {
    experiment::parse_scenes(text)
        .map(ExpScenes)
        .map_err(|e| e.to_string())
}

fn parse_pulse_lens(text: &str) -> Result<PulseLens, String> {
    experiment::parse_pulse_lens(text)
        .map(PulseLens)
        .map_err(|e| e.to_string())
}

fn parse_solver_list(text: &str) -> Result<Solvers, String> {
    experiment::parse_solvers(text)
        .map(Solvers)
        .map_err(|e| e.to_string())
}

fn parse_noise_list(text: &str) -> Result<NoiseLevels, String> {
    experiment::parse_noise_levels(text)
        .map(NoiseLevels)
        .map_err(|e| e.to_string())
}

fn parse_budgets(text: &str) -> Result<IterationBudgets, String> {
    IterationBudgets::parse(text).map_err(|e| e.to_string())
}

/// The two experiments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Experiment {
    /// The main job.
    Demo,
    /// The sweep across regimes.
    Compare,
}

impl Experiment {
    fn name(self) -> &'static str {
        match self {
            Experiment::Demo => "demo",
            Experiment::Compare => "compare",
        }
    }
}

/// Set by the first Ctrl-C: the experiment stops after the run under way.
static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Resolves an experiment's configuration: the preset (--tiny, --quick or the default), the
/// config file's section and top-level keys over it, the flags over both.
fn experiment_config(
    which: Experiment,
    a: &ExperimentArgs,
    preset: Preset,
    globals: &Globals,
) -> CliResult<(ExperimentConfig, Option<usize>, bool)> {
    let preset = if a.tiny { Preset::Tiny } else { preset };
    let mut config = match (which, preset) {
        (Experiment::Demo, Preset::Tiny) => ExperimentConfig::demo_tiny(),
        (Experiment::Demo, _) => ExperimentConfig::demo(),
        (Experiment::Compare, Preset::Tiny) => ExperimentConfig::compare_tiny(),
        (Experiment::Compare, Preset::Quick) => ExperimentConfig::compare_quick(),
        (Experiment::Compare, Preset::Research) => ExperimentConfig::compare_research(),
        (Experiment::Compare, Preset::Default) => ExperimentConfig::compare(),
    };
    let file = match &a.config {
        Some(path) => ConfigFile::load(path)?,
        None => ConfigFile::default(),
    };
    let section = match which {
        Experiment::Demo => &file.demo,
        Experiment::Compare => &file.compare,
    };
    if let Some(patch) = section {
        config = config.patched(patch);
    }
    let flags = ExperimentPatch {
        out: a.out.clone(),
        scene: a.scene.as_ref().map(|v| v.0.clone()),
        size: a.size,
        lit_fraction: a.lit_fraction,
        pulse_lens: a.pulse_lens.as_ref().map(|v| v.0.clone()),
        solvers: a.solvers.as_ref().map(|v| v.0.clone()),
        snr_db: a.snr_db.as_ref().map(|v| v.0.clone()),
        seeds: a.seeds,
        max_iter: a.max_iter,
        power_iterations: a.power_iterations,
    };
    config = config.patched(&flags);
    config.seed = globals.seed.or(file.seed).unwrap_or(config.seed);
    config.precision = match globals.precision {
        Some(Precision::F32) => experiment::Precision::F32,
        Some(Precision::F64) => experiment::Precision::F64,
        None => file.precision.unwrap_or(config.precision),
    };
    let checked = config.validate().and_then(|()| match which {
        Experiment::Demo => experiment::check_depth_figure(&config),
        Experiment::Compare => Ok(()),
    });
    if let Err(e) = checked {
        let msg = match e {
            rdlidar::Error::InvalidParameter { name, reason } => {
                let place = match &a.config {
                    Some(path) => format!(" (or `{name}` in {})", path.display()),
                    None => String::new(),
                };
                format!(
                    "{}{place}: {}",
                    FrontEnd::CommandLine.word(name),
                    FrontEnd::CommandLine.words(&reason)
                )
            }
            other => other.to_string(),
        };
        return Err(msg.into());
    }
    let threads = globals.threads.or(file.threads);
    let quiet = globals.quiet || file.quiet.unwrap_or(false);
    Ok((config, threads, quiet))
}

/// Checks that the output folder can be used and that no table would replace the config file.
fn check_output(a: &ExperimentArgs, config: &ExperimentConfig) -> CliResult<()> {
    rdlidar::io::check_output_dir(&config.out, a.force, "the results in it")?;
    if let Some(file) = &a.config {
        // With --force the tables replace files of the same name in the folder.
        for name in TABLES {
            check_not_input(&config.out.join(name), "--out", &[(file, "--config")])?;
        }
    }
    Ok(())
}

/// Refuses a `--shard` count above the number of the sweep's problems (before anything is
/// dealt: a share is made for each shard).
fn check_shard(shard: Shard, config: &ExperimentConfig) -> CliResult {
    shard.check(config).map_err(|e| match e {
        rdlidar::Error::InvalidParameter { reason, .. } => {
            Failure::Message(format!("--shard {reason}"))
        }
        other => other.into(),
    })
}

/// The files of an experiment that a --config file could be.
const TABLES: [&str; 5] = [
    "config.toml",
    "results.csv",
    "results.json",
    "results.md",
    "summary.md",
];

/// `compare --merge`: the shards' folders joined into --out.
pub fn merge(a: &CompareArgs, globals: &Globals) -> CliResult<ExitCode> {
    let only_out = ExperimentArgs {
        out: a.common.out.clone(),
        force: a.common.force,
        ..ExperimentArgs::default()
    };
    if a.common != only_out || globals.seed.is_some() || globals.precision.is_some() {
        return Err(
            "compare --merge takes the sweep from the shards' folders: give only \
                    --out and --force with it"
                .to_string()
                .into(),
        );
    }
    let out = a
        .common
        .out
        .clone()
        .unwrap_or_else(|| ExperimentConfig::compare().out);
    rdlidar::io::check_output_dir(&out, a.common.force, "the results in it")?;
    let outcome =
        experiment::merge_compare(&a.merge, &out, a.common.force).map_err(|e| match e {
            rdlidar::Error::InvalidParameter {
                name: name @ ("merge" | "out"),
                reason,
            } => Failure::Message(format!(
                "{}: {}",
                FrontEnd::CommandLine.word(name),
                FrontEnd::CommandLine.words(&reason)
            )),
            other => other.into(),
        })?;
    outln!(
        "merged {} shards: {} of {} runs{}; wrote {}: {}",
        a.merge.len(),
        outcome.rows.len(),
        outcome.planned,
        if outcome.interrupted {
            " (a shard was interrupted)"
        } else {
            ""
        },
        out.display(),
        file_names(&outcome.files)
    );
    Ok(ExitCode::SUCCESS)
}

/// The files' names, comma-separated.
fn file_names(files: &[PathBuf]) -> String {
    let names: Vec<String> = files
        .iter()
        .map(|f| {
            f.file_name()
                .map_or_else(|| f.display().to_string(), |n| n.to_string_lossy().into())
        })
        .collect();
    names.join(", ")
}

/// `demo` (also the command with no subcommand) and `compare`, on `shard` of the sweep, dealt to
/// the processes of `ranks` (compare only).
pub fn run(
    which: Experiment,
    a: &ExperimentArgs,
    (preset, shard): (Preset, Shard),
    globals: &Globals,
    ranks: &Ranks,
) -> CliResult<ExitCode> {
    let resolved = experiment_config(which, a, preset, globals)
        .and_then(|resolved| check_shard(shard, &resolved.0).map(|()| resolved));
    let (config, threads, quiet) = ranks.agree(resolved)?;
    ranks.agree(if ranks.is_first() {
        check_output(a, &config)
    } else {
        Ok(())
    })?;
    set_threads(threads, "threads")?;
    // SIGTERM (`kill`, a batch system, `mpirun` stopping the job with SIGKILL a second later)
    // quits at once: nothing new is left, not even the staging folder.
    signals::handle(move |signal| {
        if signal == Signal::Terminate {
            errln!("\nterminated: quitting without writing results");
            experiment::abandon_staged_and_exit(signal.exit_code());
        }
        if STOP.swap(true, std::sync::atomic::Ordering::SeqCst) {
            errln!("\ninterrupted again: quitting without writing results");
            experiment::abandon_staged_and_exit(signal.exit_code());
        }
        errln!("\nCtrl-C: stopping after the current run (Ctrl-C again to quit at once)");
    })?;

    let kps: Vec<String> = config.pulse_lens.iter().map(usize::to_string).collect();
    let levels: Vec<String> = config
        .snr_db
        .iter()
        .map(|l| experiment::noise_text(*l))
        .collect();
    let shard_runs = SweepShare {
        shard,
        space: &rdlidar::space::WHOLE,
    }
    .cases(&config)
    .len()
        * config.solvers.len();
    let dealt = match (shard.is_whole(), ranks.processes()) {
        (true, 1) => String::new(),
        (false, 1) => format!(", {shard_runs} of them in shard {shard}"),
        (true, r) => format!(", dealt to {r} processes"),
        (false, r) => format!(", {shard_runs} of them in shard {shard}, dealt to {r} processes"),
    };
    outln!(
        "rdlidar {}: {} scene {} (critical K_p {}), K_p {}, {}, {} seed(s) from {}, {}, {} \
         threads; {} runs{dealt}",
        which.name(),
        config.scene_names(),
        config.size,
        config.size.critical_pulse_len(),
        kps.join(", "),
        levels.join(", "),
        config.seeds,
        config.seed,
        config.precision,
        rayon::current_num_threads(),
        config.runs()
    );
    outln!(
        "iteration budgets: {}; FISTA step from {} Lanczos iterations",
        config.max_iter,
        config
            .power_iterations
            .map_or_else(|| "up to 200".to_string(), |n| n.to_string())
    );
    let mut console = Console::new(quiet).stopping_on_closed_stdout(&STOP);
    let mut nothing = ();
    let observer: &mut dyn ExperimentObserver = if ranks.is_first() {
        &mut console
    } else {
        &mut nothing
    };
    let space = ranks
        .space()
        .map_or(&rdlidar::space::WHOLE as &dyn rdlidar::space::Space, |s| {
            &**s
        });
    let share = SweepShare { shard, space };
    let outcome = match which {
        Experiment::Demo => experiment::run_demo(&config, a.force, observer, &STOP),
        Experiment::Compare => {
            experiment::run_compare_shared(&config, (a.force, &share), observer, &STOP)
        }
    };
    console.finish();
    let outcome = outcome.map_err(|e| match e {
        rdlidar::Error::InvalidParameter {
            name: "parts",
            reason,
        } => Failure::Message(reason),
        other => other.into(),
    })?;
    if !ranks.is_first() {
        return Ok(ExitCode::SUCCESS);
    }
    if console.stdout_closed() {
        // The reader of the table has gone: the finished runs are written; end as a broken pipe.
        return Err(Failure::BrokenPipe);
    }
    let failed = outcome.rows.iter().filter(|r| r.error.is_some()).count();
    outln!(
        "{} of {} runs finished{} in {:.1} s (total {:.1} s with tables and figures); wrote {}: {}",
        outcome.rows.len(),
        outcome.planned,
        if failed > 0 {
            format!(" ({failed} with a solver error)")
        } else {
            String::new()
        },
        outcome.elapsed.as_secs_f64(),
        outcome.total.as_secs_f64(),
        config.out.display(),
        file_names(&outcome.files)
    );
    if outcome.interrupted {
        errln!(
            "interrupted: the tables and figures hold the {} finished runs",
            outcome.rows.len()
        );
        return Ok(ExitCode::from(130));
    }
    Ok(ExitCode::SUCCESS)
}
