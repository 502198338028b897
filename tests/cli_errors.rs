//! Bad flags and bad files for every subcommand that reads or generates data: impossible sizes,
//! unknown names, unreadable and invalid files. Each run must fail with exit status 1 and one
//! line `error: …` naming the flag or the file (or, for command lines clap refuses, status 2 and
//! a message naming the flag), and must leave no output behind.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::cli_support::{
    assert_one_line_error, assert_usage_error, listing, npy_bytes, npy_dict, rdlidar, s, stderr,
    TempDir,
};

/// A simulated 4×5×6 problem (K_p = 50, K = 55), the same with two ADCs, invalid files, and an
/// output directory that must stay empty.
struct Fixture {
    tmp: TempDir,
    out: PathBuf,
}

impl Fixture {
    fn new(tag: &str) -> Self {
        let tmp = TempDir::new(tag);
        for (dir, extra) in [("run", vec![]), ("multi", vec!["--adcs", "2"])] {
            let d = tmp.path(dir);
            let mut args = vec![
                "simulate",
                "--scene",
                "paper",
                "--size",
                "4x5x6",
                "--pulse-len",
                "50",
                "--out",
                s(&d),
            ];
            args.extend(extra);
            let out = rdlidar(&args);
            assert!(out.status.success(), "{}", stderr(&out));
        }
        std::fs::write(tmp.path("text.npy"), "0.1 0.2 0.3\n").unwrap();
        std::fs::create_dir(tmp.path("a_directory")).unwrap();
        // A valid header promising 8 TB of float64 that the file does not hold.
        write_header_only(&tmp.path("huge.npy"), "<f8", "(1000000000000,)");
        write_header_only(&tmp.path("objects.npy"), "|O", "(50,)");
        let out = tmp.path("out");
        std::fs::create_dir(&out).unwrap();
        Fixture { tmp, out }
    }

    fn run(&self, name: &str) -> String {
        s(&self.tmp.path("run").join(name)).to_string()
    }

    fn file(&self, name: &str) -> String {
        s(&self.tmp.path(name)).to_string()
    }

    fn out(&self, name: &str) -> String {
        s(&self.out.join(name)).to_string()
    }

    /// Nothing was written into the output directory.
    fn assert_nothing_written(&self) {
        assert!(listing(&self.out).is_empty(), "{:?}", listing(&self.out));
    }
}

/// A `.npy` file with a version 1.0 header and no data.
fn write_header_only(path: &Path, descr: &str, shape: &str) {
    std::fs::write(path, npy_bytes(&npy_dict(descr, shape), &[])).unwrap();
}

fn run(args: &[String]) -> Output {
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    rdlidar(&args)
}

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|a| a.to_string()).collect()
}

#[test]
fn simulate_refuses_impossible_sizes_and_unknown_scenes() {
    let tmp = TempDir::new("sim-sizes");
    let dir = tmp.path("run");
    let max = usize::MAX.to_string();
    for (size, kp, scene, needles) in [
        ("0x4x4", "5", "paper", vec!["--size", "at least 1", "0x4x4"]),
        ("4x4x0", "5", "paper", vec!["--size", "at least 1"]),
        ("4x4", "5", "paper", vec!["--size", "MxNxKS"]),
        ("4xx4", "5", "paper", vec!["--size", "MxNxKS"]),
        (
            "4294967296x4294967296x2",
            "5",
            "paper",
            vec!["--size", "overflow"],
        ),
        ("4x4x4", "0", "paper", vec!["--pulse-len", "at least 1"]),
        ("4x4x4", "ten", "paper", vec!["--pulse-len", "ten"]),
        (
            "4x4x4",
            "5",
            "cube",
            vec!["--scene", "cube", "paper", "random", "transparent"],
        ),
    ] {
        let out = rdlidar(&[
            "simulate",
            "--scene",
            scene,
            "--size",
            size,
            "--pulse-len",
            kp,
            "--out",
            s(&dir),
        ]);
        assert_usage_error(&out, &needles);
    }
    // K = K_p + K_s − 1 overflows: refused at run time, before any file exists.
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x4x4",
        "--pulse-len",
        &max,
        "--out",
        s(&dir),
    ]);
    assert_usage_error(&out, &["--pulse-len", &max, "limit"]);
    assert!(listing(&tmp.0).is_empty(), "{:?}", listing(&tmp.0));
}

#[test]
fn bench_refuses_impossible_sizes() {
    assert_usage_error(&rdlidar(&["bench", "--size", "0x1x1"]), &["--size"]);
    assert_usage_error(
        &rdlidar(&["bench", "--size", "4x4x4", "--pulse-len", "0"]),
        &["--pulse-len"],
    );
    assert_usage_error(
        &rdlidar(&["bench", "--precision", "f16"]),
        &["--precision", "f16"],
    );
    let max = usize::MAX.to_string();
    assert_usage_error(
        &rdlidar(&["bench", "--size", "4x4x4", "--pulse-len", &max]),
        &["--pulse-len", "limit"],
    );
}

#[test]
fn adjoint_and_dottest_refuse_impossible_depth_bins() {
    let f = Fixture::new("bins");
    let max = usize::MAX.to_string();
    // A negative number is taken for an unknown flag, which the message names.
    for (bins, needle) in [
        ("0", "--depth-bins"),
        ("-6", "'-6'"),
        ("six", "--depth-bins"),
    ] {
        let out = run(&strings(&[
            "adjoint",
            "--pulse",
            &f.run("pulse.npy"),
            "--codes",
            &f.run("codes.npy"),
            "--meas",
            &f.run("meas.npy"),
            "--depth-bins",
            bins,
            "--out",
            &f.out("xt.npy"),
        ]));
        assert_usage_error(&out, &[needle]);
    }
    let out = run(&strings(&[
        "adjoint",
        "--pulse",
        &f.run("pulse.npy"),
        "--codes",
        &f.run("codes.npy"),
        "--meas",
        &f.run("meas.npy"),
        "--depth-bins",
        &max,
        "--out",
        &f.out("xt.npy"),
    ]));
    assert_usage_error(&out, &["--depth-bins", "limit"]);
    let out = run(&strings(&[
        "dottest",
        "--pulse",
        &f.run("pulse.npy"),
        "--codes",
        &f.run("codes.npy"),
        "--depth-bins",
        &max,
    ]));
    assert_usage_error(&out, &["--depth-bins", "limit"]);
    // Depth bins that do not match the codes' length name the codes file.
    let out = run(&strings(&[
        "dottest",
        "--pulse",
        &f.run("pulse.npy"),
        "--codes",
        &f.run("codes.npy"),
        "--depth-bins",
        "7",
    ]));
    assert_one_line_error(&out, &[&f.run("codes.npy")]);
    f.assert_nothing_written();
}

#[test]
fn unreadable_and_invalid_files_are_named() {
    let f = Fixture::new("files");
    let dir = f.file("a_directory");
    let text = f.file("text.npy");
    let huge = f.file("huge.npy");
    let objects = f.file("objects.npy");
    // forward: each input replaced in turn.
    for (slot, bad, needles) in [
        (2, dir.as_str(), vec!["is a directory"]),
        (2, huge.as_str(), vec!["truncated", "8000000000000 bytes"]),
        (
            0,
            objects.as_str(),
            vec!["dtype object", "float32 or float64"],
        ),
        (1, text.as_str(), vec!["not a .npy file"]),
        (0, dir.as_str(), vec!["is a directory"]),
    ] {
        let mut inputs = [f.run("pulse.npy"), f.run("codes.npy"), f.run("scene.npy")];
        inputs[slot] = bad.to_string();
        let out = run(&strings(&[
            "forward",
            "--pulse",
            &inputs[0],
            "--codes",
            &inputs[1],
            "--scene",
            &inputs[2],
            "--out",
            &f.out("y.npy"),
        ]));
        let mut all = vec![bad];
        all.extend(needles);
        assert_one_line_error(&out, &all);
    }
    // dottest with codes that are not .npy, or a pulse that is a directory.
    for (pulse, codes, bad) in [
        (f.run("pulse.npy"), text.clone(), &text),
        (dir.clone(), f.run("codes.npy"), &dir),
    ] {
        let out = run(&strings(&[
            "dottest",
            "--pulse",
            &pulse,
            "--codes",
            &codes,
            "--depth-bins",
            "6",
        ]));
        assert_one_line_error(&out, &[bad]);
    }
    // An output that is a directory is refused before any work.
    let out = run(&strings(&[
        "adjoint",
        "--pulse",
        &f.run("pulse.npy"),
        "--codes",
        &f.run("codes.npy"),
        "--meas",
        &f.run("meas.npy"),
        "--depth-bins",
        "6",
        "--out",
        s(&f.out),
    ]));
    assert_one_line_error(&out, &[s(&f.out), "is a directory"]);
    f.assert_nothing_written();
}

/// `reconstruct` on the fixture with the given replacements.
fn reconstruct(f: &Fixture, replace: &[(&str, &str)], extra: &[&str]) -> Output {
    let mut flags: Vec<(&str, String)> = vec![
        ("--pulse", f.run("pulse.npy")),
        ("--codes", f.run("codes.npy")),
        ("--meas", f.run("meas.npy")),
        ("--depth-bins", "6".into()),
        ("--solver", "cgls".into()),
        ("--out-depth", f.out("d.npy")),
        ("--out-scene", f.out("x.npy")),
    ];
    for (flag, value) in replace {
        match flags.iter_mut().find(|(f, _)| f == flag) {
            Some(slot) => slot.1 = value.to_string(),
            None => flags.push((flag, value.to_string())),
        }
    }
    let mut args = vec!["reconstruct".to_string(), "--quiet".to_string()];
    for (flag, value) in flags {
        args.push(flag.to_string());
        args.push(value);
    }
    args.extend(extra.iter().map(|a| a.to_string()));
    run(&args)
}

#[test]
fn reconstruct_refuses_bad_flags_and_files_and_writes_nothing() {
    let f = Fixture::new("reconstruct");
    let text = f.file("text.npy");
    let dir = f.file("a_directory");
    let multi_codes = s(&f.tmp.path("multi").join("codes.npy")).to_string();
    let missing_dir_png = s(&f.out.join("no").join("d.png")).to_string();
    let pulse_as_codes = f.run("codes.npy");

    // Usage errors: unknown solver names (case matters), zero iterations, a negative seed.
    for (replace, extra, needles) in [
        (
            vec![("--solver", "CGLS")],
            vec![],
            vec!["--solver", "unknown solver \"CGLS\"", "model-based"],
        ),
        (
            vec![("--solver", "")],
            vec![],
            vec!["--solver", "valid solvers"],
        ),
        (
            vec![],
            vec!["--max-iter", "0"],
            vec!["--max-iter", "at least 1"],
        ),
        (vec![], vec!["--seed", "-1"], vec!["-1"]),
        (
            vec![],
            vec!["--precision", "f128"],
            vec!["--precision", "f128"],
        ),
    ] {
        let out = reconstruct(&f, &replace, &extra);
        assert_usage_error(&out, &needles);
    }

    // Run-time errors: one line naming the file or flag.
    for (replace, needles) in [
        (
            vec![("--meas", text.as_str())],
            vec![text.as_str(), "not a .npy file"],
        ),
        (
            vec![("--truth", text.as_str())],
            vec![text.as_str(), "not a .npy file"],
        ),
        (
            vec![("--codes", dir.as_str())],
            vec![dir.as_str(), "is a directory"],
        ),
        (
            vec![("--pulse", pulse_as_codes.as_str())],
            vec![pulse_as_codes.as_str(), "dtype int8", "pulse"],
        ),
        (
            vec![("--codes", multi_codes.as_str())],
            vec![multi_codes.as_str(), "2 code sets", "those of one ADC"],
        ),
        (
            vec![("--png", missing_dir_png.as_str())],
            vec![missing_dir_png.as_str(), "does not exist"],
        ),
        (
            vec![("--out-scene", s(&f.out))],
            vec![s(&f.out), "is a directory"],
        ),
    ] {
        let out = reconstruct(&f, &replace, &[]);
        assert_one_line_error(&out, &needles);
        f.assert_nothing_written();
    }
    let out = reconstruct(&f, &[("--depth-bins", "18446744073709551615")], &[]);
    assert_usage_error(&out, &["--depth-bins", "limit"]);
    f.assert_nothing_written();

    // The fixture itself reconstructs, so the failures above come from the replacements.
    let out = reconstruct(&f, &[], &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(listing(&f.out), ["d.npy", "x.npy"]);
}

/// `rdlidar` as process `rank` of `size` of a job, as a launcher's variables say, without a
/// launcher.
fn as_process(rank: usize, size: usize, args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(args)
        .env("OMPI_COMM_WORLD_RANK", rank.to_string())
        .env("OMPI_COMM_WORLD_SIZE", size.to_string())
        .output()
        .expect("the binary runs")
}

#[test]
fn launched_as_several_processes_a_command_that_cannot_split_refuses_from_the_first() {
    let tmp = TempDir::new("launched");
    let out = tmp.path("run");
    let simulate = [
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x4x4",
        "--pulse-len",
        "10",
        "--out",
        s(&out),
        "--quiet",
    ];
    let e = as_process(0, 3, &simulate);
    assert_one_line_error(
        &e,
        &[
            "rdlidar simulate without --codes-format seed runs on one process",
            "3 processes",
        ],
    );
    // The other processes end quietly: the first reports for the job.
    let other = as_process(2, 3, &simulate);
    assert!(other.status.success() && other.stderr.is_empty() && other.stdout.is_empty());
    assert!(!out.exists());
    // One process of one is not a job.
    assert!(as_process(0, 1, &simulate).status.success());
    #[cfg(not(feature = "mpi"))]
    {
        let run = &out;
        let xt = tmp.path("xt.npy");
        let args = [
            "adjoint",
            "--pulse",
            &format!("{}/pulse.npy", s(run)),
            "--codes",
            &format!("{}/codes.npy", s(run)),
            "--meas",
            &format!("{}/meas.npy", s(run)),
            "--depth-bins",
            "4",
            "--out",
            s(&xt),
        ];
        let e = as_process(0, 2, &args);
        assert_one_line_error(&e, &["built without MPI", "--features mpi"]);
        assert!(!xt.exists());
    }
}
