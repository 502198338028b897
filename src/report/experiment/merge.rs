//! The folders of a sweep's shards merged into the folder one run would have written.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde::Deserialize;

use crate::error::{Error, Result};

use super::deal::{in_sweep_order, repeated_run};
use super::{
    compare_files, ConfigFile, ExperimentConfig, Outcome, Row, Shard, StagedDir, Sweep, COMPARE,
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
    let toml = dir.join("config.toml");
    let file = ConfigFile::load(&toml)?;
    let Some(section) = &file.compare else {
        return Err(file_error(&toml, "has no [compare] section"));
    };
    let mut config = ExperimentConfig::compare().patched(section);
    config.seed = file.seed.unwrap_or(config.seed);
    config.precision = file.precision.unwrap_or(config.precision);
    Ok(ShardFolder {
        dir: dir.to_path_buf(),
        shard,
        config,
        results,
    })
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
/// [`Error::File`] naming a folder's file that cannot be read or is not a shard's;
/// [`Error::InvalidParameter`] (`merge`) when the folders are not every shard of one sweep,
/// each once, or hold a run twice; the errors of writing the output folder, which is left as
/// it was.
pub fn merge_compare(shards: &[PathBuf], out: &Path, force: bool) -> Result<Outcome> {
    let start = Instant::now();
    if shards.is_empty() {
        return Err(Error::param("merge", "no shard folders given"));
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
        let seconds = f.results.sweep_seconds;
        if seconds.is_finite() && seconds >= 0.0 {
            sweep.elapsed = sweep.elapsed.max(Duration::from_secs_f64(seconds));
        }
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
