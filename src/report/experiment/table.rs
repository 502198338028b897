//! The results as CSV, JSON lines and Markdown, and the partial files rows are streamed to.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

use super::config::{noise_text, ExperimentConfig, NoiseLevel};
use super::Row;

/// The columns of `results.csv`, in order (the field names of [`Row`]).
pub const CSV_COLUMNS: [&str; 30] = [
    "scene",
    "size",
    "precision",
    "seed",
    "snr_db",
    "pulse_len",
    "samples",
    "regime",
    "critical_pulse_len",
    "solver",
    "method_used",
    "max_iter",
    "lit",
    "exact",
    "exact_pct",
    "false_detections",
    "missed",
    "true_returns",
    "returns_exact",
    "returns_false",
    "depth_rmse_bins",
    "relative_error",
    "time_s",
    "iterations",
    "termination",
    "forward_applies",
    "adjoint_applies",
    "support_applies",
    "error",
    "status",
];

/// The CSV header line (with its newline).
pub fn csv_header() -> String {
    CSV_COLUMNS.join(",") + "\n"
}

/// A CSV field, quoted when it holds a comma, a quote or a line break.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn opt<T: ToString>(v: &Option<T>) -> String {
    v.as_ref().map(T::to_string).unwrap_or_default()
}

/// A float in full precision (shortest round-trip form); empty for `None`.
fn num(v: Option<f64>) -> String {
    v.map(|x| format!("{x:?}")).unwrap_or_default()
}

/// One row of `results.csv` (with its newline). Missing values are empty fields; `snr_db` is
/// empty for noise-free runs; `status` is `ok` or `error`.
pub fn csv_line(r: &Row) -> String {
    let fields = [
        csv_field(&r.scene),
        csv_field(&r.size),
        csv_field(&r.precision),
        r.seed.to_string(),
        num(r.snr_db),
        r.pulse_len.to_string(),
        r.samples.to_string(),
        csv_field(&r.regime),
        r.critical_pulse_len.to_string(),
        csv_field(&r.solver),
        csv_field(&r.method_used),
        opt(&r.max_iter),
        r.lit.to_string(),
        opt(&r.exact),
        num(r.exact_pct),
        opt(&r.false_detections),
        opt(&r.missed),
        r.true_returns.to_string(),
        opt(&r.returns_exact),
        opt(&r.returns_false),
        num(r.depth_rmse_bins),
        num(r.relative_error),
        format!("{:?}", r.time_s),
        opt(&r.iterations),
        csv_field(&opt(&r.termination)),
        opt(&r.forward_applies),
        opt(&r.adjoint_applies),
        opt(&r.support_applies),
        csv_field(&opt(&r.error)),
        if r.error.is_some() { "error" } else { "ok" }.into(),
    ];
    fields.join(",") + "\n"
}

/// A column of the printed and Markdown tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Column {
    /// The scene.
    Scene,
    /// The seed.
    Seed,
    /// The noise level.
    Snr,
    /// The solver (with the method `auto` chose in parentheses).
    Solver,
    /// K_p.
    PulseLen,
    /// The regime.
    Regime,
    /// Lit pixels at the exact depth: count and percentage.
    Exact,
    /// Returns of the estimate at the voxel of a true return, of the true returns.
    Returns,
    /// False detections.
    FalseDetections,
    /// Depth RMSE in bins.
    Rmse,
    /// ‖X − X̂‖/‖X‖.
    RelativeError,
    /// Wall time in seconds.
    Time,
    /// Iterations done.
    Iterations,
    /// The iteration budget (`default` for the solver's own limit, `-` for the
    /// backprojections).
    Cost,
    /// Why the solver stopped.
    Termination,
}

impl Column {
    fn title(self) -> &'static str {
        match self {
            Column::Scene => "scene",
            Column::Seed => "seed",
            Column::Snr => "SNR",
            Column::Solver => "solver",
            Column::PulseLen => "K_p",
            Column::Regime => "regime",
            Column::Exact => "exact depth",
            Column::Returns => "returns",
            Column::FalseDetections => "false det.",
            Column::Rmse => "depth RMSE (bins)",
            Column::RelativeError => "rel. error",
            Column::Time => "time (s)",
            Column::Iterations => "iterations",
            Column::Cost => "budget",
            Column::Termination => "termination",
        }
    }

    fn width(self) -> usize {
        let w = match self {
            Column::Scene => 11,
            Column::Seed => 4,
            Column::Snr => 10,
            Column::Solver => 30,
            Column::PulseLen => 6,
            Column::Regime => 11,
            Column::Exact => 14,
            Column::Returns => 11,
            Column::FalseDetections => 10,
            Column::Rmse => 17,
            Column::RelativeError => 10,
            Column::Time => 8,
            Column::Iterations => 10,
            Column::Cost => 7,
            Column::Termination => 14,
        };
        w.max(self.title().chars().count())
    }

    fn numeric(self) -> bool {
        !matches!(
            self,
            Column::Scene | Column::Solver | Column::Regime | Column::Termination | Column::Snr
        )
    }

    fn value(self, r: &Row) -> String {
        let failed = r.error.is_some();
        let dash = || "-".to_string();
        match self {
            Column::Scene => r.scene.clone(),
            Column::Seed => r.seed.to_string(),
            Column::Snr => match r.snr_db {
                None => "noise-free".into(),
                Some(s) => format!("{s} dB"),
            },
            Column::Solver => {
                if r.method_used != r.solver {
                    format!("{} ({})", r.solver, r.method_used)
                } else {
                    r.solver.clone()
                }
            }
            Column::PulseLen => r.pulse_len.to_string(),
            Column::Regime => r.regime.clone(),
            Column::Exact => match (r.exact, r.exact_pct) {
                (Some(e), Some(p)) => format!("{e} ({p:.1}%)"),
                _ => dash(),
            },
            Column::Returns => r
                .returns_exact
                .map_or_else(dash, |e| format!("{e}/{}", r.true_returns)),
            Column::FalseDetections => r.false_detections.map_or_else(dash, |v| v.to_string()),
            Column::Rmse => r.depth_rmse_bins.map_or_else(dash, |v| format!("{v:.3}")),
            Column::RelativeError => r.relative_error.map_or_else(dash, |v| {
                if v != 0.0 && v < 1e-3 {
                    format!("{v:.2e}")
                } else {
                    format!("{v:.4}")
                }
            }),
            Column::Time => format!("{:.2}", r.time_s),
            Column::Iterations => r.iterations.map_or_else(dash, |v| v.to_string()),
            Column::Cost => match (r.max_iter, r.solver.starts_with("backprojection")) {
                (Some(b), _) => b.to_string(),
                (None, true) => dash(),
                (None, false) => "default".into(),
            },
            Column::Termination => {
                if failed {
                    "error".into()
                } else {
                    r.termination.clone().unwrap_or_else(|| "direct".into())
                }
            }
        }
    }
}

fn pad(text: &str, width: usize, right: bool) -> String {
    let n = text.chars().count();
    let fill = " ".repeat(width.saturating_sub(n));
    if right {
        fill + text
    } else {
        text.to_string() + &fill
    }
}

/// The header and separator lines of a Markdown table with `columns` (with newlines).
pub fn markdown_header(columns: &[Column]) -> String {
    let titles: Vec<String> = columns
        .iter()
        .map(|c| pad(c.title(), c.width(), c.numeric()))
        .collect();
    let rules: Vec<String> = columns
        .iter()
        .map(|c| {
            // The cell's width plus its two spaces; a colon marks right alignment.
            let w = c.width() + 2;
            if c.numeric() {
                "-".repeat(w - 1) + ":"
            } else {
                "-".repeat(w)
            }
        })
        .collect();
    format!("| {} |\n|{}|\n", titles.join(" | "), rules.join("|"))
}

/// One row of a Markdown table with `columns` (with its newline); a failed run shows its error
/// after the table's cells.
pub fn markdown_row(row: &Row, columns: &[Column]) -> String {
    let cells: Vec<String> = columns
        .iter()
        .map(|c| {
            let w = c.width();
            pad(&c.value(row).replace('|', "/"), w, c.numeric())
        })
        .collect();
    let mut line = format!("| {} |", cells.join(" | "));
    if let Some(e) = &row.error {
        line += &format!(" error: {}", e.replace('|', "/"));
    }
    line + "\n"
}

/// A Markdown table of `rows`.
pub fn markdown_table(rows: &[Row], columns: &[Column]) -> String {
    let mut s = markdown_header(columns);
    for r in rows {
        s += &markdown_row(r, columns);
    }
    s
}

/// The median of finite values (`None` if there are none).
fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    Some(crate::linalg::median(&mut v))
}

/// Per solver and pulse length, the median over seeds of a row value, for one noise level.
pub(crate) fn medians(
    rows: &[Row],
    level: NoiseLevel,
    solver: &str,
    pulse_len: usize,
    value: impl Fn(&Row) -> Option<f64>,
) -> Option<f64> {
    median(
        rows.iter()
            .filter(|r| r.snr_db == level && r.solver == solver && r.pulse_len == pulse_len)
            .filter_map(&value)
            .collect(),
    )
}

/// `summary.md` of the compare sweep for one scene (`config.scenes[0]`; `rows` are its runs):
/// for each noise level, solver × K_p tables of the median over seeds of ‖X − X̂‖/‖X‖, of the
/// exact-depth percentage, of the returns found at their voxel in percent (only when the scene
/// has more returns than lit pixels), of the false detections and of the wall time.
pub fn summary_markdown(config: &ExperimentConfig, rows: &[Row]) -> String {
    let g = config.size;
    let mut kps = config.pulse_lens.clone();
    kps.sort_unstable();
    let mut s = format!(
        "# compare: {} scene {g}, critical K_p = {}, {} seed(s), {}\n\n\
         Medians over the seeds of the finished runs (`-`: no finished run).\n",
        config.scene_names(),
        g.critical_pulse_len(),
        config.seeds,
        config.precision
    );
    let header = |first: &str| {
        let mut h = format!("| {first} |");
        let mut rule = "|---|".to_string();
        for kp in &kps {
            h += &format!(" {kp} |");
            rule += "---:|";
        }
        format!("{h}\n{rule}\n")
    };
    let multi_return = rows.iter().any(|r| r.true_returns > r.lit);
    type Value = fn(&Row) -> Option<f64>;
    let mut tables: Vec<(&str, usize, bool, Value)> = vec![
        ("relative error ‖X − X̂‖/‖X‖", 4, true, |r| {
            r.relative_error
        }),
        ("lit pixels at the exact depth (%)", 1, false, |r| {
            r.exact_pct
        }),
    ];
    if multi_return {
        tables.push(("returns found at their voxel (%)", 1, false, |r| {
            r.returns_exact
                .map(|e| 100.0 * e as f64 / r.true_returns.max(1) as f64)
        }));
    }
    tables.push(("false detections (pixels)", 1, false, |r| {
        r.false_detections.map(|v| v as f64)
    }));
    tables.push(("wall time (s)", 4, false, |r| Some(r.time_s)));
    for &level in &config.snr_db {
        s += &format!("\n## {}\n", noise_text(level));
        for &(title, digits, scientific, value) in &tables {
            s += &format!("\n{title}, by K_p:\n\n");
            s += &header("solver");
            for m in &config.solvers {
                s += &format!("| {} |", m.name());
                for &kp in &kps {
                    let cell = match medians(rows, level, m.name(), kp, value) {
                        Some(v) if scientific && v != 0.0 && v.abs() < 1e-3 => {
                            format!("{v:.2e}")
                        }
                        Some(v) => format!("{v:.digits$}"),
                        None => "-".into(),
                    };
                    s += &format!(" {cell} |");
                }
                s += "\n";
            }
        }
    }
    s
}

/// `results.csv.partial` and `results.jsonl.partial`: every finished row appended and flushed
/// as it comes, so that a killed run keeps them. Removed once the final tables are written.
#[derive(Debug)]
pub struct PartialFiles {
    csv: (PathBuf, File),
    jsonl: (PathBuf, File),
}

impl PartialFiles {
    /// Creates (truncates) the two files in `dir` and writes the CSV header.
    ///
    /// # Errors
    /// [`Error::File`] naming the file that cannot be created or written.
    pub fn create(dir: &Path) -> Result<Self> {
        let open = |name: &str| -> Result<(PathBuf, File)> {
            let path = dir.join(name);
            let f = OpenOptions::new()
                .write(true)
                .create(true)
                .truncate(true)
                .open(&path)
                .map_err(|e| file_err(&path, format!("cannot create: {e}")))?;
            Ok((path, f))
        };
        let mut p = PartialFiles {
            csv: open("results.csv.partial")?,
            jsonl: open("results.jsonl.partial")?,
        };
        let (path, f) = &mut p.csv;
        f.write_all(csv_header().as_bytes())
            .and_then(|()| f.flush())
            .map_err(|e| file_err(path, format!("cannot write: {e}")))?;
        Ok(p)
    }

    /// Appends one row to both files and flushes them.
    ///
    /// # Errors
    /// [`Error::File`] naming the file that cannot be written.
    pub fn append(&mut self, row: &Row) -> Result<()> {
        let json = serde_json::to_string(row)
            .map_err(|e| file_err(&self.jsonl.0, format!("cannot format a row: {e}")))?;
        for ((path, f), text) in [
            (&mut self.csv, csv_line(row)),
            (&mut self.jsonl, json + "\n"),
        ] {
            f.write_all(text.as_bytes())
                .and_then(|()| f.flush())
                .map_err(|e| file_err(path, format!("cannot write: {e}")))?;
        }
        Ok(())
    }

    /// The two files' paths.
    pub fn paths(&self) -> [&Path; 2] {
        [&self.csv.0, &self.jsonl.0]
    }

    /// Removes both files (best effort: the final tables are already written).
    pub fn remove(self) {
        for p in self.paths() {
            let _ = std::fs::remove_file(p);
        }
    }
}

fn file_err(path: &Path, reason: String) -> Error {
    Error::File {
        path: path.display().to_string(),
        reason,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row() -> Row {
        Row {
            scene: "paper".into(),
            size: "8x8x8".into(),
            precision: "f32".into(),
            seed: 0,
            snr_db: Some(20.0),
            pulse_len: 100,
            samples: 107,
            regime: "compressive".into(),
            critical_pulse_len: 505,
            solver: "auto".into(),
            method_used: "tv".into(),
            max_iter: Some(6),
            lit: 40,
            exact: Some(30),
            exact_pct: Some(75.0),
            false_detections: Some(1),
            missed: Some(2),
            true_returns: 40,
            returns_exact: Some(30),
            returns_false: Some(3),
            depth_rmse_bins: Some(0.5),
            relative_error: Some(0.25),
            time_s: 0.125,
            iterations: Some(4),
            termination: Some("converged".into()),
            forward_applies: Some(10),
            adjoint_applies: Some(9),
            support_applies: Some(4),
            error: Some("a, \"quoted\" error".into()),
        }
    }

    #[test]
    fn csv_lines_have_one_field_per_column() {
        let line = csv_line(&row());
        assert!(
            line.ends_with(",\"a, \"\"quoted\"\" error\",error\n"),
            "{line}"
        );
        assert!(line.starts_with("paper,8x8x8,f32,0,20.0,100,107,compressive,505,auto,tv,6,40,"));
        // Split respecting quotes.
        let mut fields = 1;
        let mut quoted = false;
        for c in line.trim_end().chars() {
            match c {
                '"' => quoted = !quoted,
                ',' if !quoted => fields += 1,
                _ => {}
            }
        }
        assert_eq!(fields, CSV_COLUMNS.len());
    }

    #[test]
    fn markdown_rows_line_up_with_the_header() {
        let cols = super::super::COMPARE_COLUMNS;
        let mut r = row();
        r.error = None;
        let h = markdown_header(&cols);
        let line = markdown_row(&r, &cols);
        let widths =
            |s: &str| -> Vec<usize> { s.split('|').map(|c| c.chars().count()).collect::<Vec<_>>() };
        let first = h.lines().next().unwrap();
        assert_eq!(widths(first), widths(line.trim_end()));
        assert_eq!(widths(h.lines().nth(1).unwrap()), widths(first));
        assert!(
            line.contains("auto (tv)")
                && line.contains("30 (75.0%)")
                && line.contains(" 30/40 |")
                && line.contains("| paper ")
                && line.contains("|          4 |       6 |")
        );
    }

    #[test]
    fn medians_ignore_other_levels() {
        let mut a = row();
        a.relative_error = Some(1.0);
        let mut b = row();
        b.relative_error = Some(3.0);
        let mut c = row();
        c.snr_db = None;
        c.relative_error = Some(100.0);
        let rows = [a, b, c];
        assert_eq!(
            medians(&rows, Some(20.0), "auto", 100, |r| r.relative_error),
            Some(2.0)
        );
        assert_eq!(
            medians(&rows, None, "auto", 100, |r| r.relative_error),
            Some(100.0)
        );
        assert_eq!(
            medians(&rows, None, "cgls", 100, |r| r.relative_error),
            None
        );
    }
}
