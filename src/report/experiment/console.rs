//! Progress and the table on the terminal, as an [`ExperimentObserver`].

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use super::config::noise_text;
use super::table::{markdown_header, markdown_row, Column};
use super::{Event, ExperimentObserver};

/// The bar: elapsed time, bar, percentage of the estimated work, the run under way, the
/// estimated time left.
const TEMPLATE: &str = "[{elapsed_precise}] {bar:30} {percent:>3}% {msg} (ETA {eta})";

/// Work units of the bar per unit of [`super::estimated_work`].
const SCALE: f64 = 100.0;

/// Prints the table to stdout, one row as each run finishes, and shows progress on stderr.
///
/// On a terminal, progress is an indicatif bar with the run under way and the estimated time
/// left (the table's rows are printed above it). When stderr is not a terminal, each problem's
/// simulation and each run's start are logged as plain lines instead, so that logs stay
/// readable. `quiet` hides both; the table is printed in every case. In a sweep shared by
/// several processes, the first process's console prints its own rows as they finish and the
/// other processes' rows once they are gathered.
#[derive(Debug)]
pub struct Console {
    quiet: bool,
    bar: Option<ProgressBar>,
    lines: bool,
    columns: Vec<Column>,
    done: f64,
    /// The rows printed so far.
    printed: Vec<super::Row>,
    started: Instant,
    /// Set when a write to stdout failed because its reader has gone.
    closed: AtomicBool,
    /// Raised when stdout closes, so that the sweep stops after the current run.
    stop: Option<&'static AtomicBool>,
}

impl Console {
    /// A console for an experiment; `quiet` hides the progress.
    pub fn new(quiet: bool) -> Self {
        Console {
            quiet,
            bar: None,
            lines: !quiet && !std::io::stderr().is_terminal(),
            columns: Vec::new(),
            done: 0.0,
            printed: Vec::new(),
            started: Instant::now(),
            closed: AtomicBool::new(false),
            stop: None,
        }
    }

    /// Raises `stop` (the experiment's stop flag) when stdout turns out to be a broken pipe, so
    /// that the sweep ends after the current run as it does on Ctrl-C.
    pub fn stopping_on_closed_stdout(mut self, stop: &'static AtomicBool) -> Self {
        self.stop = Some(stop);
        self
    }

    /// Whether a write to stdout failed because its reader has gone (a broken pipe).
    pub fn stdout_closed(&self) -> bool {
        self.closed.load(Ordering::SeqCst)
    }

    /// Prints a line on stdout without breaking the bar.
    fn print(&self, text: &str) {
        let out = || {
            if self.stdout_closed() {
                return;
            }
            let mut o = std::io::stdout().lock();
            let written = o.write_all(text.as_bytes()).and_then(|()| o.flush());
            if let Err(e) = written {
                if e.kind() == std::io::ErrorKind::BrokenPipe {
                    self.closed.store(true, Ordering::SeqCst);
                    if let Some(stop) = self.stop {
                        stop.store(true, Ordering::SeqCst);
                    }
                }
            }
        };
        match &self.bar {
            Some(b) => b.suspend(out),
            None => out(),
        }
    }

    /// A progress line on stderr (non-terminal runs).
    fn log(&self, text: &str) {
        if self.lines {
            let _ = writeln!(
                std::io::stderr().lock(),
                "[{:>7.1} s] {text}",
                self.started.elapsed().as_secs_f64()
            );
        }
    }

    /// Clears the bar.
    pub fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}

impl Drop for Console {
    fn drop(&mut self) {
        self.finish();
    }
}

impl ExperimentObserver for Console {
    fn event(&mut self, event: &Event<'_>) {
        match event {
            Event::Planned {
                problems,
                runs,
                work,
                columns,
            } => {
                self.started = Instant::now();
                self.columns = columns.to_vec();
                if !self.quiet && !self.lines {
                    let style = ProgressStyle::with_template(TEMPLATE)
                        .unwrap_or_else(|_| ProgressStyle::default_bar());
                    let bar = ProgressBar::with_draw_target(
                        Some((work * SCALE).ceil().max(1.0) as u64),
                        ProgressDrawTarget::stderr(),
                    )
                    .with_style(style);
                    bar.enable_steady_tick(Duration::from_millis(250));
                    self.bar = Some(bar);
                }
                self.log(&format!("{runs} runs on {problems} simulated problems"));
                self.print(&markdown_header(&self.columns));
            }
            Event::Simulating { case, geometry } => {
                let what = format!(
                    "simulating {geometry}, K_p {}, seed {}, {}",
                    case.pulse_len,
                    case.seed,
                    noise_text(case.snr_db)
                );
                if let Some(b) = &self.bar {
                    b.set_message(what.clone());
                }
                self.log(&what);
            }
            Event::RunStarted {
                index,
                runs,
                method,
                case,
            } => {
                let what = format!("run {}/{runs}: {method}, K_p {}", index + 1, case.pulse_len);
                if let Some(b) = &self.bar {
                    b.set_message(what.clone());
                }
                self.log(&what);
            }
            Event::RunFinished { row, work, .. } => {
                self.done += work;
                if let Some(b) = &self.bar {
                    b.set_position((self.done * SCALE) as u64);
                }
                self.print(&markdown_row(row, &self.columns));
                self.printed.push((*row).clone());
            }
            Event::Gathered { processes, rows } => {
                self.finish();
                let others: Vec<&super::Row> =
                    rows.iter().filter(|r| !self.printed.contains(r)).collect();
                let from = match processes - 1 {
                    1 => "the other process".to_string(),
                    n => format!("the other {n} processes"),
                };
                self.log(&format!("{} rows of {from}:", others.len()));
                for row in others {
                    self.print(&markdown_row(row, &self.columns));
                }
            }
            Event::Interrupted { finished, runs } => {
                self.finish();
                if !self.quiet {
                    let _ = writeln!(
                        std::io::stderr().lock(),
                        "interrupted: {finished} of {runs} runs finished"
                    );
                }
            }
        }
    }
}
