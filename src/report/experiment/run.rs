//! What the two experiments share: the sweep of a [`SweepShare`] with rows streamed to partial
//! files and gathered from the processes, then the tables and the experiment's own files
//! written into a staged folder.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::error::{Error, Result};

use super::{
    csv_header, csv_line, figures, markdown_table, sweep, Column, Event, ExperimentConfig,
    ExperimentObserver, Outcome, PartialFiles, Precision, Row, Shard, StagedDir, Sweep, SweepShare,
};

/// The JSON document of `results.json`.
#[derive(Serialize)]
struct ResultsJson<'a> {
    experiment: &'a str,
    crate_version: &'a str,
    /// The share of the sweep, `k/n`, when the folder holds one shard's runs.
    #[serde(skip_serializing_if = "Option::is_none")]
    shard: Option<String>,
    interrupted: bool,
    planned_runs: usize,
    finished_runs: usize,
    sweep_seconds: f64,
    config: &'a ExperimentConfig,
    rows: &'a [Row],
}

/// What the tables of an experiment are written for.
struct Tables<'a> {
    /// `demo` or `compare`.
    experiment: &'a str,
    /// The columns of `results.md`.
    columns: &'a [Column],
    /// The share of the sweep, when a folder holds one shard's runs.
    shard: Option<Shard>,
}

/// The tables common to both experiments: results.csv, results.json, results.md, config.toml.
fn write_tables(
    tables: &Tables<'_>,
    config: &ExperimentConfig,
    sweep: &Sweep,
    dir: &Path,
    files: &mut Vec<PathBuf>,
) -> Result<()> {
    let experiment = tables.experiment;
    let mut csv = csv_header();
    for r in &sweep.rows {
        csv.push_str(&csv_line(r));
    }
    let json = serde_json::to_string_pretty(&ResultsJson {
        experiment,
        crate_version: env!("CARGO_PKG_VERSION"),
        shard: tables.shard.map(|s| s.to_string()),
        interrupted: sweep.interrupted,
        planned_runs: sweep.planned,
        finished_runs: sweep.rows.len(),
        sweep_seconds: sweep.elapsed.as_secs_f64(),
        config,
        rows: &sweep.rows,
    })
    .map_err(|e| Error::param("results", format!("cannot write JSON: {e}")))?
        + "\n";
    let md = markdown_table(&sweep.rows, tables.columns);
    let toml = config.to_toml(experiment)?;
    for (name, text) in [
        ("results.csv", csv),
        ("results.json", json),
        ("results.md", md),
        ("config.toml", toml),
    ] {
        let path = dir.join(name);
        crate::io::write_bytes_atomic(&path, text.as_bytes())?;
        files.push(path);
    }
    Ok(())
}

/// What the two experiments share: the sweep with rows streamed to partial files, the tables,
/// then the experiment's own files.
pub(super) struct Run {
    pub(super) name: &'static str,
    pub(super) columns: &'static [Column],
    /// Whether the sweep keeps each problem's depth maps (for the depth figures).
    pub(super) keep_depths: bool,
}

/// Writes an experiment's own files (figures, summaries) for a finished sweep into a folder,
/// adding their paths to the list.
pub(super) type Figures<'a> = dyn Fn(&Sweep, &Path, &mut Vec<PathBuf>) -> Result<()> + 'a;

impl Run {
    /// Runs `share`'s problems of `config` and, on the first process, writes every process's
    /// rows, the tables and the experiment's files. The other processes of an MPI job return
    /// every row and no files.
    pub(super) fn execute(
        &self,
        config: &ExperimentConfig,
        (force, share): (bool, &SweepShare<'_>),
        observer: &mut dyn ExperimentObserver,
        stop: &AtomicBool,
        figures: &Figures<'_>,
    ) -> Result<Outcome> {
        let start = Instant::now();
        config.validate()?;
        share.shard.check(config)?;
        if self.keep_depths {
            figures::check_depth_figure(config)?;
        }
        // config.toml is written after the sweep: a setting it cannot hold fails before any run.
        config.to_toml(self.name)?;
        let staged = share.agree(if share.writes() {
            StagedDir::create(&config.out, force).map(Some)
        } else {
            Ok(None)
        })?;
        let local = (|| -> Result<(Sweep, Option<PartialFiles>)> {
            let mut partial = match &staged {
                Some(s) => Some(PartialFiles::create(s.dir())?),
                None => None,
            };
            let mut on_row = |r: &Row| partial.as_mut().map_or(Ok(()), |p| p.append(r));
            let cases = share.cases(config);
            let sweep = match config.precision {
                Precision::F32 => {
                    sweep::sweep::<f32>(config, &cases, self, observer, stop, &mut on_row)?
                }
                Precision::F64 => {
                    sweep::sweep::<f64>(config, &cases, self, observer, stop, &mut on_row)?
                }
            };
            Ok((sweep, partial))
        })();
        let explain = |e: Error| match &staged {
            Some(s) => s.explain(e),
            None => e,
        };
        let (mut sweep, partial) = share.agree(local).map_err(explain)?;
        if !share.is_whole() {
            let planned = crate::space::count(share.space, sweep.planned);
            let seconds = crate::space::max(share.space, sweep.elapsed.as_secs_f64());
            sweep.elapsed = Duration::from_secs_f64(seconds.max(0.0));
            let rows = std::mem::take(&mut sweep.rows);
            let (rows, interrupted) = share.gather(config, rows, sweep.interrupted)?;
            sweep.rows = rows;
            sweep.interrupted = interrupted;
            sweep.planned = planned;
            observer.event(&Event::Gathered {
                processes: share.space.parts(),
                rows: &sweep.rows,
            });
        }
        let Some(staged) = staged else {
            return Ok(Outcome {
                rows: sweep.rows,
                interrupted: sweep.interrupted,
                planned: sweep.planned,
                files: Vec::new(),
                elapsed: sweep.elapsed,
                total: start.elapsed(),
            });
        };
        if let Some(p) = partial {
            p.remove();
        }
        let shard = Some(share.shard).filter(|s| !s.is_whole());
        self.publish(config, staged, sweep, shard, figures, start)
    }

    /// Writes the tables of `sweep` and the experiment's files into `staged` and moves them into
    /// the output folder.
    pub(super) fn publish(
        &self,
        config: &ExperimentConfig,
        staged: StagedDir,
        sweep: Sweep,
        shard: Option<Shard>,
        figures: &Figures<'_>,
        start: Instant,
    ) -> Result<Outcome> {
        let filled = (|| -> Result<Vec<PathBuf>> {
            let mut files = Vec::new();
            let tables = Tables {
                experiment: self.name,
                columns: self.columns,
                shard,
            };
            write_tables(&tables, config, &sweep, staged.dir(), &mut files)?;
            figures(&sweep, staged.dir(), &mut files)?;
            Ok(files)
        })();
        let files = filled.map_err(|e| staged.explain(e))?;
        staged.commit()?;
        let files = files
            .iter()
            .filter_map(|f| f.file_name())
            .map(|name| config.out.join(name))
            .collect();
        Ok(Outcome {
            rows: sweep.rows,
            interrupted: sweep.interrupted,
            planned: sweep.planned,
            files,
            elapsed: sweep.elapsed,
            total: start.elapsed(),
        })
    }
}
