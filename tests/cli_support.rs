//! Helpers for the tests that run the binary: running it, temporary directories, and the checks
//! every failing run must pass.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};

use ndarray::Array1;

/// Runs `rdlidar` with `args`.
pub fn rdlidar(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(args)
        .output()
        .expect("the binary runs")
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

pub fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A path as the `&str` a command line takes.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("temporary paths are UTF-8")
}

/// A fresh directory under the system temporary directory, removed when dropped.
pub struct TempDir(pub PathBuf);

static DIRS: AtomicUsize = AtomicUsize::new(0);

impl TempDir {
    pub fn new(tag: &str) -> Self {
        let n = DIRS.fetch_add(1, Ordering::Relaxed);
        let p = std::env::temp_dir().join(format!(
            "rdlidar-cli-support-{}-{tag}-{n}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }

    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    /// The names of the entries of the directory, sorted.
    pub fn listing(&self) -> Vec<String> {
        listing(&self.0)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The names of the entries of `dir`, sorted.
pub fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The run failed at run time: exit status 1, nothing on stdout, and exactly one line on stderr,
/// `error: …`, containing every one of `needles`.
pub fn assert_one_line_error(out: &Output, needles: &[&str]) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.starts_with("error: "), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(out.stdout.is_empty(), "stdout: {}", stdout(out));
    for n in needles {
        assert!(err.contains(n), "{n:?} missing from {err}");
    }
}

/// The command line was refused before anything ran: exit status 2, nothing on stdout, and a
/// message `error: …` (before the usage reminder) containing every one of `needles`.
pub fn assert_usage_error(out: &Output, needles: &[&str]) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.starts_with("error: "), "{err}");
    assert!(out.stdout.is_empty(), "stdout: {}", stdout(out));
    let message = err.split("\n\n").next().unwrap_or_default();
    for n in needles {
        assert!(
            message.contains(n),
            "{n:?} missing from the message of {err}"
        );
    }
}

/// The header dict numpy writes for `descr` and `shape` (C order).
pub fn npy_dict(descr: &str, shape: &str) -> String {
    format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}")
}

/// The bytes of a version 1.0 `.npy` file: the header `dict`, padded with spaces and a newline
/// to a multiple of 64 bytes as numpy pads it, then `data`.
pub fn npy_bytes(dict: &str, data: &[u8]) -> Vec<u8> {
    let mut header = dict.to_string();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    bytes.extend_from_slice(data);
    bytes
}

/// Simulates the 4x5x6 paper problem with a pulse of 50 into `dir`, noise-free.
pub(crate) fn simulate_small(dir: &Path, extra: &[&str]) {
    let mut args = vec![
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x5x6",
        "--pulse-len",
        "50",
        "--seed",
        "7",
        "--out",
        s(dir),
    ];
    args.extend_from_slice(extra);
    let out = rdlidar(&args);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// Largest |a − b| over the largest |b|.
pub(crate) fn max_rel_diff(a: &Array1<f64>, b: &Array1<f64>) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// The lines of an experiment's `results.csv` with the `time_s` field removed: what two runs of
/// one sweep share however their times differ.
pub fn rows_without_times(csv: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(csv).unwrap_or_else(|e| panic!("{}: {e}", csv.display()));
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let time = header
        .iter()
        .position(|h| *h == "time_s")
        .expect("a time_s column");
    std::iter::once(header.join(","))
        .chain(lines.map(|l| {
            let mut fields: Vec<&str> = l.split(',').collect();
            fields.remove(time);
            fields.join(",")
        }))
        .collect()
}
