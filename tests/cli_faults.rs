//! Faults around the commands: closed and full output streams, outputs that name inputs, requests
//! beyond the limits or the memory, values that overflow or underflow, and header fields numpy
//! writes that must be read.

use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};

use crate::cli_support::{
    assert_one_line_error, assert_usage_error, npy_bytes, npy_dict, rdlidar, s, stderr, TempDir,
};

/// Writes a version 1.0 `.npy` file of float64 values with the given `descr` and shape.
pub fn write_f64(path: &Path, descr: &str, shape: &str, values: &[f64]) {
    let big = descr.starts_with('>');
    let data: Vec<u8> = values
        .iter()
        .flat_map(|v| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        })
        .collect();
    std::fs::write(path, npy_bytes(&npy_dict(descr, shape), &data)).unwrap();
}

/// A float64 pulse file of K_p = 20 samples, `value` at every third one and 0 elsewhere.
fn pulse_file(tmp: &TempDir, name: &str, value: f64) {
    let pulse: Vec<f64> = (0..20)
        .map(|i| if i % 3 == 0 { value } else { 0.0 })
        .collect();
    write_f64(&tmp.path(name), "<f8", "(20,)", &pulse);
}

/// `reconstruct` on the problem of [`problem`] with CGLS, without its outputs.
const RECONSTRUCT: [&str; 11] = [
    "reconstruct",
    "--pulse",
    "@s/pulse.npy",
    "--codes",
    "@s/codes.npy",
    "--meas",
    "@s/meas.npy",
    "--depth-bins",
    "4",
    "--solver",
    "cgls",
];

/// A simulated 4×4×4 problem with K_p = 20 in `dir/s`.
fn problem(tag: &str) -> TempDir {
    let tmp = TempDir::new(tag);
    let d = tmp.path("s");
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x4x4",
        "--pulse-len",
        "20",
        "--out",
        s(&d),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    tmp
}

/// Runs the binary with `args`, `@rel` standing for `tmp/rel`, and the environment `env`.
fn run_env(tmp: &TempDir, args: &[&str], env: &[(&str, &str)]) -> std::process::Output {
    let args: Vec<String> = args
        .iter()
        .map(|a| match a.strip_prefix('@') {
            Some(rel) => s(&tmp.path(rel)).to_string(),
            None => a.to_string(),
        })
        .collect();
    Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(&args)
        .envs(env.iter().copied())
        .output()
        .expect("the binary runs")
}

fn run_in(tmp: &TempDir, args: &[&str]) -> std::process::Output {
    run_env(tmp, args, &[])
}

#[test]
fn a_broken_pipe_ends_quietly_with_status_141() {
    for args in [
        &["selfcheck"][..],
        &["info", "--size", "100x100x40", "--pulse-len", "1000"],
    ] {
        // A pipe whose reading end is closed before the command starts.
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let mut child = Command::new(env!("CARGO_BIN_EXE_rdlidar"))
            .args(args)
            .stdout(writer)
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut err = String::new();
        child
            .stderr
            .take()
            .unwrap()
            .read_to_string(&mut err)
            .unwrap();
        let status = child.wait().unwrap();
        assert_eq!(status.code(), Some(141), "{args:?}: {err}");
        assert!(err.is_empty(), "{args:?}: {err}");
    }
}

#[test]
fn a_full_stdout_is_a_one_line_error() {
    let full = Path::new("/dev/full");
    if !full.exists() {
        return;
    }
    let out = Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(["info", "--size", "100x100x40", "--pulse-len", "1000"])
        .stdout(std::fs::File::options().write(true).open(full).unwrap())
        .output()
        .unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("cannot write to standard output"), "{err}");
}

#[test]
fn outputs_that_name_inputs_are_refused_before_any_work() {
    let tmp = problem("inputs");
    std::fs::hard_link(tmp.path("s/scene.npy"), tmp.path("hard.npy")).unwrap();
    let before = std::fs::read(tmp.path("s/meas.npy")).unwrap();
    let common = ["--pulse", "@s/pulse.npy", "--codes", "@s/codes.npy"];
    let cases: Vec<(Vec<&str>, [&str; 2])> = vec![
        (
            [
                &["forward"][..],
                &common,
                &["--scene", "@s/scene.npy", "--out", "@hard.npy"],
            ]
            .concat(),
            ["--out names the same file as --scene", "hard.npy"],
        ),
        (
            [
                &["adjoint"][..],
                &common,
                &[
                    "--meas",
                    "@s/meas.npy",
                    "--depth-bins",
                    "4",
                    "--out",
                    "@s/../s/meas.npy",
                ],
            ]
            .concat(),
            ["--out names the same file as --meas", "meas.npy"],
        ),
        (
            [
                &RECONSTRUCT[..],
                &["--out-depth", "@s/meas.npy", "--out-scene", "@x.npy"],
            ]
            .concat(),
            ["--out-depth names the same file as --meas", "meas.npy"],
        ),
        (
            [
                &RECONSTRUCT[..],
                &[
                    "--out-depth",
                    "@d.npy",
                    "--out-scene",
                    "@x.npy",
                    "--truth",
                    "@hard.npy",
                ],
                &["--png", "@s/scene.npy"],
            ]
            .concat(),
            ["--png names the same file as --truth", "scene.npy"],
        ),
    ];
    for (args, needles) in cases {
        let out = run_in(&tmp, &args);
        assert_one_line_error(&out, &needles);
    }
    assert_eq!(std::fs::read(tmp.path("s/meas.npy")).unwrap(), before);
    assert!(!tmp.path("x.npy").exists() && !tmp.path("d.npy").exists());
}

#[test]
fn counts_beyond_their_bounds_are_usage_errors() {
    for (args, flag) in [
        (&["--threads", "1000000", "selfcheck"][..], "--threads"),
        (
            &["bench", "--repeats", "18446744073709551615"][..],
            "--repeats",
        ),
        (&["bench", "--repeats", "1000000000000"][..], "--repeats"),
        (
            &[
                "simulate",
                "--scene",
                "paper",
                "--size",
                "4x4x4",
                "--pulse-len",
                "99999999999",
                "--out",
                "x",
            ][..],
            "--pulse-len",
        ),
        (
            &[
                "simulate",
                "--scene",
                "paper",
                "--size",
                "4x4x4",
                "--pulse-len",
                "9",
                "--adcs",
                "100000",
                "--out",
                "x",
            ][..],
            "--adcs",
        ),
        (
            &[
                "simulate",
                "--scene",
                "paper",
                "--size",
                "100000x100000x100",
                "--pulse-len",
                "9",
                "--out",
                "x",
            ][..],
            "--size",
        ),
    ] {
        assert_usage_error(&rdlidar(args), &[flag]);
    }
}

#[test]
fn requests_beyond_the_memory_are_refused_before_allocating() {
    let tmp = TempDir::new("memory");
    let out = tmp.path("run");
    let limited = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_rdlidar"))
            .args(args)
            .env("RDLIDAR_MEMORY_LIMIT", "1M")
            .output()
            .unwrap()
    };
    let res = limited(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "100x100x40",
        "--pulse-len",
        "1000",
        "--out",
        s(&out),
    ]);
    assert_one_line_error(&res, &["bytes", "scene", "more than the 1.05 MB", "--size"]);
    assert!(tmp.listing().is_empty());
    let res = limited(&["bench", "--size", "100x100x40", "--pulse-len", "30000"]);
    assert_one_line_error(&res, &["bench --size 100x100x40", "bytes", "--pulse-len"]);
    let res = limited(&["compare", "--quick", "--out", s(&out)]);
    assert_one_line_error(&res, &["an experiment on 16x16x16", "--pulse-lens"]);
    assert!(tmp.listing().is_empty());
    // Reading a file whose data would not fit.
    let tmp = problem("memory-file");
    let res = Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args([
            "forward",
            "--pulse",
            s(&tmp.path("s/pulse.npy")),
            "--codes",
            s(&tmp.path("s/codes.npy")),
            "--scene",
            s(&tmp.path("s/scene.npy")),
            "--out",
            s(&tmp.path("y.npy")),
        ])
        .env("RDLIDAR_MEMORY_LIMIT", "100")
        .output()
        .unwrap();
    assert_one_line_error(&res, &["reading an array of shape", "bytes"]);
    // Files that fit, but not the operator and the scenes built on them.
    let common = ["--pulse", "@s/pulse.npy", "--codes", "@s/codes.npy"];
    for args in [
        [
            &["forward"][..],
            &common,
            &["--scene", "@s/scene.npy", "--out", "@y.npy"],
        ]
        .concat(),
        [
            &["adjoint"][..],
            &common,
            &[
                "--meas",
                "@s/meas.npy",
                "--depth-bins",
                "4",
                "--out",
                "@y.npy",
            ],
        ]
        .concat(),
        [&["dottest"][..], &common, &["--depth-bins", "4"]].concat(),
        [
            &RECONSTRUCT[..],
            &["--out-depth", "@y.npy", "--out-scene", "@x.npy"],
        ]
        .concat(),
    ] {
        let res = run_env(&tmp, &args, &[("RDLIDAR_MEMORY_LIMIT", "20K")]);
        assert_one_line_error(&res, &[args[0], "codes and operator", "--codes", "bytes"]);
        assert!(!tmp.path("y.npy").exists() && !tmp.path("x.npy").exists());
    }
}

#[test]
fn overflow_and_underflow_are_errors_naming_the_file() {
    let tmp = problem("overflow");
    // A finite scene whose measurements overflow float64.
    let scene: Vec<f64> = (0..64)
        .map(|i| if i % 5 == 0 { 1.7e308 } else { 0.0 })
        .collect();
    write_f64(&tmp.path("huge.npy"), "<f8", "(4, 4, 4)", &scene);
    let res = run_in(
        &tmp,
        &[
            "forward",
            "--pulse",
            "@s/pulse.npy",
            "--codes",
            "@s/codes.npy",
            "--scene",
            "@huge.npy",
            "--out",
            "@y.npy",
        ],
    );
    assert_one_line_error(&res, &["huge.npy", "overflow float64", "--scene"]);
    assert!(!tmp.path("y.npy").exists());
    // A float64 pulse of 1e-300 read in f32 underflows to zero.
    pulse_file(&tmp, "tiny.npy", 1e-300);
    let res = run_in(
        &tmp,
        &[
            "--precision",
            "f32",
            "reconstruct",
            "--pulse",
            "@tiny.npy",
            "--codes",
            "@s/codes.npy",
            "--meas",
            "@s/meas.npy",
            "--depth-bins",
            "4",
            "--solver",
            "cgls",
            "--out-depth",
            "@d.npy",
            "--out-scene",
            "@x.npy",
        ],
    );
    assert_one_line_error(&res, &["tiny.npy", "underflows f32", "--precision f64"]);
    // A pulse too large for the f32 half of the dot test.
    pulse_file(&tmp, "big.npy", 1e300);
    let res = run_in(
        &tmp,
        &[
            "dottest",
            "--pulse",
            "@big.npy",
            "--codes",
            "@s/codes.npy",
            "--depth-bins",
            "4",
        ],
    );
    assert_one_line_error(&res, &["big.npy", "overflows f32"]);
}

#[test]
fn native_and_big_endian_headers_are_read() {
    let tmp = problem("endian");
    let pulse: Vec<f64> = (0..20).map(|i| f64::from(i % 2)).collect();
    let mut outputs = Vec::new();
    for (name, descr) in [("le.npy", "<f8"), ("eq.npy", "=f8"), ("be.npy", ">f8")] {
        write_f64(&tmp.path(name), descr, "(20,)", &pulse);
        let y = format!("y-{name}");
        let res = run_in(
            &tmp,
            &[
                "forward",
                "--pulse",
                &format!("@{name}"),
                "--codes",
                "@s/codes.npy",
                "--scene",
                "@s/scene.npy",
                "--out",
                &format!("@{y}"),
            ],
        );
        assert!(res.status.success(), "{descr}: {}", stderr(&res));
        outputs.push(std::fs::read(tmp.path(&y)).unwrap());
    }
    assert_eq!(outputs[0], outputs[1]);
    assert_eq!(outputs[0], outputs[2]);
}

#[test]
fn an_empty_truth_is_reported_as_such() {
    let tmp = problem("empty-truth");
    write_f64(&tmp.path("empty.npy"), "<f8", "(4, 4, 4)", &[0.0; 64]);
    let args = [
        &RECONSTRUCT[..],
        &[
            "--out-depth",
            "@d.npy",
            "--out-scene",
            "@x.npy",
            "--truth",
            "@empty.npy",
        ],
    ]
    .concat();
    let res = run_in(&tmp, &args);
    assert!(res.status.success(), "{}", stderr(&res));
    let out = String::from_utf8_lossy(&res.stdout);
    assert!(out.contains("the true scene has no lit pixel"), "{out}");
    assert!(!out.contains("relative error"), "{out}");
}
