//! The folders of a sweep's shards merged into the folder one run would have written.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde::Deserialize;

use crate::error::{Error, Result};
use crate::recon::Method;
use crate::space::WHOLE;

use super::deal::{in_sweep_order, repeated_run};
use super::sweep::blank_row;
use super::{
    compare_files, noise_text, ConfigFile, ExperimentConfig, Outcome, Row, Shard, StagedDir, Sweep,
    SweepShare, COMPARE,
};

/// What a shard's `results.json` holds that a merge needs.
#[derive(Deserialize)]
struct ShardResults {
    experiment: String,
    shard: Option<String>,
    interrupted: bool,
    planned_runs: usize,
    sweep_seconds: f64,
    rows: Vec<Row>,
}

/// One shard's folder, read.
struct ShardFolder {
    dir: PathBuf,
    shard: Shard,
    config: ExperimentConfig,
    results: ShardResults,
}

fn file_error(path: &Path, reason: impl Into<String>) -> Error {
    Error::File {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

/// Reads the results and the configuration `rdlidar compare --shard k/n` wrote into `dir`.
fn read_shard(dir: &Path) -> Result<ShardFolder> {
    let path = dir.join("results.json");
    let text = std::fs::read_to_string(&path)
        .map_err(|e| file_error(&path, format!("cannot read a shard's results: {e}")))?;
    let results: ShardResults = serde_json::from_str(&text).map_err(|e| {
        file_error(
            &path,
            format!("not the results.json of rdlidar compare: {e}"),
        )
    })?;
    if results.experiment != "compare" {
        return Err(file_error(
            &path,
            format!("the results of `{}`, not of compare", results.experiment),
        ));
    }
    let Some(text) = &results.shard else {
        return Err(file_error(
            &path,
            "the results of a whole sweep, not of a shard (rdlidar compare --shard k/n)",
        ));
    };
    let shard = Shard::parse(text).map_err(|e| file_error(&path, e.to_string()))?;
    seconds_of(results.sweep_seconds)
        .map_err(|e| file_error(&path, format!("sweep_seconds {e}")))?;
    let toml = dir.join("config.toml");
    let file = ConfigFile::load(&toml)?;
    let Some(section) = &file.compare else {
        return Err(file_error(&toml, "has no [compare] section"));
    };
    let mut config = ExperimentConfig::compare().patched(section);
    config.seed = file.seed.unwrap_or(config.seed);
    config.precision = file.precision.unwrap_or(config.precision);
    config
        .validate()
        .map_err(|e| file_error(&toml, e.to_string()))?;
    shard.check(&config).map_err(|e| match e {
        Error::InvalidParameter { reason, .. } => {
            file_error(&path, format!("shard {reason} (config.toml)"))
        }
        other => other,
    })?;
    Ok(ShardFolder {
        dir: dir.to_path_buf(),
        shard,
        config,
        results,
    })
}

/// `seconds` as a [`Duration`]: a finite number of seconds, at least 0 and within what a
/// duration holds; otherwise why not.
fn seconds_of(seconds: f64) -> std::result::Result<Duration, String> {
    Duration::try_from_secs_f64(seconds)
        .map_err(|_| format!("is {seconds:?}, not a time in seconds (finite, at least 0)"))
}

/// Checks that `folder` holds runs of its shard of the sweep `config` describes, each as that
/// sweep gives it (the problem, the solver and what follows from them: the grid, the precision,
/// K, the regime, the iteration budget), every run of the shard unless it was interrupted, and
/// run times that are times.
///
/// # Errors
/// [`Error::File`] naming the shard's `results.json` and the row (from 1).
fn check_rows(folder: &ShardFolder, config: &ExperimentConfig) -> Result<()> {
    let path = folder.dir.join("results.json");
    let results = &folder.results;
    let cases = SweepShare {
        shard: folder.shard,
        space: &WHOLE,
    }
    .cases(config);
    let runs = cases.len() * config.solvers.len();
    if results.planned_runs != runs {
        return Err(file_error(
            &path,
            format!(
                "planned_runs is {}, but shard {} of the sweep in config.toml has {runs} runs",
                results.planned_runs, folder.shard
            ),
        ));
    }
    let rows = results.rows.len();
    if rows > runs || (rows < runs && !results.interrupted) {
        return Err(file_error(
            &path,
            format!(
                "{rows} rows, but shard {} of the sweep in config.toml has {runs} runs{}",
                folder.shard,
                if results.interrupted {
                    ""
                } else {
                    " and was not interrupted"
                }
            ),
        ));
    }
    for (i, row) in results.rows.iter().enumerate() {
        let bad = |what: String| file_error(&path, format!("row {}: {what}", i + 1));
        let run = format!(
            "{} on the {} scene, K_p {}, seed {}, {}",
            row.solver,
            row.scene,
            row.pulse_len,
            row.seed,
            noise_text(row.snr_db)
        );
        let case = cases.iter().find(|c| {
            c.scene.name() == row.scene
                && c.pulse_len == row.pulse_len
                && c.seed == row.seed
                && c.snr_db == row.snr_db
        });
        let method = config.solvers.iter().find(|m| m.name() == row.solver);
        let (Some(case), Some(&method)) = (case, method) else {
            return Err(bad(format!(
                "{run} is not a run of shard {} of the sweep in config.toml",
                folder.shard
            )));
        };
        let expected = blank_row(config, case, method, config.precision.name());
        let used = match method {
            Method::Auto => row.method_used.parse::<Method>().is_ok(),
            _ => row.method_used == expected.method_used,
        };
        let differs = [
            ("size", row.size != expected.size),
            ("precision", row.precision != expected.precision),
            ("samples", row.samples != expected.samples),
            ("regime", row.regime != expected.regime),
            (
                "critical_pulse_len",
                row.critical_pulse_len != expected.critical_pulse_len,
            ),
            ("max_iter", row.max_iter != expected.max_iter),
            ("method_used", !used),
        ];
        if let Some((field, _)) = differs.iter().find(|(_, d)| *d) {
            return Err(bad(format!(
                "the {field} of {run} is not the sweep's (config.toml)"
            )));
        }
        seconds_of(row.time_s).map_err(|e| bad(format!("time_s {e}")))?;
    }
    Ok(())
}

/// Checks that `folders` are the shards 1/n … n/n of one sweep, each once.
fn check_complete(folders: &[ShardFolder]) -> Result<()> {
    let first = &folders[0];
    let count = first.shard.count;
    let mut seen: Vec<Option<&Path>> = vec![None; count];
    for f in folders {
        let same_config = ExperimentConfig {
            out: first.config.out.clone(),
            ..f.config.clone()
        } == first.config;
        if f.shard.count != count || !same_config {
            return Err(Error::param(
                "merge",
                format!(
                    "{} holds shard {} of another sweep than {} (shard {}): {}",
                    f.dir.display(),
                    f.shard,
                    first.dir.display(),
                    first.shard,
                    if same_config {
                        "the shard counts differ"
                    } else {
                        "their config.toml differ"
                    }
                ),
            ));
        }
        if let Some(other) = seen[f.shard.index] {
            return Err(Error::param(
                "merge",
                format!(
                    "{} and {} both hold shard {}",
                    other.display(),
                    f.dir.display(),
                    f.shard
                ),
            ));
        }
        seen[f.shard.index] = Some(&f.dir);
    }
    let missing: Vec<String> = (0..count)
        .filter(|&i| seen[i].is_none())
        .map(|index| Shard { index, count }.to_string())
        .collect();
    if !missing.is_empty() {
        return Err(Error::param(
            "merge",
            format!(
                "missing shard {} of the sweep: give the folder of every shard",
                missing.join(", ")
            ),
        ));
    }
    Ok(())
}

/// Merges the folders of the shards of one `compare` sweep (each written by
/// [`super::run_compare_shared`] with a [`Shard`], for example by the tasks of a job array
/// running `rdlidar compare --shard k/n`) into `out`: the tables with every row in the order
/// one run gives them, `summary.md`, the figures and `config.toml`, as one run of the whole
/// sweep writes them (run times apart). The sweep time is the longest shard's; a shard that
/// was interrupted makes the merge interrupted.
///
/// # Errors
/// [`Error::InvalidParameter`] (`out`) when `out` is one of the shards' folders (however
/// spelt); [`Error::File`] naming a folder's file that cannot be read or is not a shard's: a
/// shard count above the sweep's problems, a row that is not a run of its shard of the sweep in
/// `config.toml`, a time that is not a number of seconds; [`Error::InvalidParameter`] (`merge`)
/// when the folders are not every shard of one sweep, each once, or hold a run twice; the
/// errors of writing the output folder, which is left as it was.
pub fn merge_compare(shards: &[PathBuf], out: &Path, force: bool) -> Result<Outcome> {
    let start = Instant::now();
    if shards.is_empty() {
        return Err(Error::param("merge", "no shard folders given"));
    }
    if let Some(dir) = shards.iter().find(|d| crate::io::same_file(out, d)) {
        return Err(Error::param(
            "out",
            format!(
                "{} is the shard folder {}: the merge would replace the files it reads; give \
                 another folder",
                out.display(),
                dir.display()
            ),
        ));
    }
    let folders = shards
        .iter()
        .map(|d| read_shard(d))
        .collect::<Result<Vec<_>>>()?;
    check_complete(&folders)?;
    let config = ExperimentConfig {
        out: out.to_path_buf(),
        ..folders[0].config.clone()
    };
    config.validate()?;
    for f in &folders {
        check_rows(f, &config)?;
    }
    let mut sweep = Sweep {
        rows: Vec::new(),
        depths: Vec::new(),
        interrupted: false,
        planned: 0,
        elapsed: Duration::ZERO,
    };
    for f in folders {
        sweep.interrupted |= f.results.interrupted;
        sweep.planned += f.results.planned_runs;
        // Checked by read_shard.
        let seconds = seconds_of(f.results.sweep_seconds).unwrap_or_default();
        sweep.elapsed = sweep.elapsed.max(seconds);
        sweep.rows.extend(f.results.rows);
    }
    in_sweep_order(&config, &mut sweep.rows);
    if let Some(i) = repeated_run(&config, &sweep.rows) {
        let r = &sweep.rows[i];
        return Err(Error::param(
            "merge",
            format!(
                "the run of {} on K_p {}, seed {} appears twice among the shards",
                r.solver, r.pulse_len, r.seed
            ),
        ));
    }
    let staged = StagedDir::create(out, force)?;
    COMPARE.publish(
        &config,
        staged,
        sweep,
        None,
        &|sweep, dir, files| compare_files(&config, sweep, dir, files),
        start,
    )
}
