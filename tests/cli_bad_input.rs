//! A bad-input campaign on the command line: the memory budget's variable, numbers of any size
//! echoed in messages, a full scale beyond `f32`, sockets given as outputs, and Ctrl-C or
//! SIGTERM while `simulate` writes.
//!
//! Every bad input fails with exit status 1 and one line `error: …` naming the flag, file or
//! variable concerned, and leaves no output behind, not even a hidden temporary file. Each test
//! names the defect it guards (B01 …), found on the code before the fix.

use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::cli_support::{assert_one_line_error, listing, s, stderr, TempDir};

/// The five files of a simulation, sorted.
const FILES: [&str; 5] = [
    "codes.npy",
    "meas.npy",
    "meta.json",
    "pulse.npy",
    "scene.npy",
];

/// `simulate` of the paper scene of `size` with a pulse of `kp` samples into `out`, with the
/// `extra` flags.
fn simulate_args(size: &str, kp: &str, out: &Path, extra: &[&str]) -> Vec<String> {
    let mut args: Vec<String> = [
        "simulate",
        "--quiet",
        "--scene",
        "paper",
        "--size",
        size,
        "--pulse-len",
        kp,
        "--out",
        s(out),
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    args.extend(extra.iter().map(|a| a.to_string()));
    args
}

/// Runs the binary with `args` and the environment variable `RDLIDAR_MEMORY_LIMIT` = `limit`.
fn with_limit(args: &[String], limit: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(args)
        .env("RDLIDAR_MEMORY_LIMIT", limit)
        .output()
        .expect("the binary runs")
}

/// Runs the binary with `args`.
fn run(args: &[String]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(args)
        .output()
        .expect("the binary runs")
}

/// A small simulation (8x8x6, K_p 100) in `tmp/name`.
fn small_simulation(tmp: &TempDir, name: &str) -> PathBuf {
    let dir = tmp.path(name);
    let out = run(&simulate_args("8x8x6", "100", &dir, &[]));
    assert!(out.status.success(), "{}", stderr(&out));
    dir
}

/// The pid of a process that has ended (its id is not reused this soon).
fn ended_pid() -> u32 {
    let mut child = Command::new("true").spawn().expect("true runs");
    let pid = child.id();
    child.wait().unwrap();
    pid
}

// B01: RDLIDAR_MEMORY_LIMIT=5MB, 5MiB, -1 or garbage was ignored without a word: no limit
// applied. Units are read (5MB in powers of 1000, 5MiB and 5M in powers of 1024) and any other
// value is refused by every command, naming the variable.
#[test]
fn the_memory_limit_variable_is_read_or_refused_never_ignored() {
    let tmp = TempDir::new("bad-limit");
    let out = tmp.path("run");
    // 200x200x40 in f64: a scene of 12.8 MB.
    let big = simulate_args("200x200x40", "100", &out, &[]);
    for (limit, shown) in [
        ("5MB", "the 5 MB of memory"),
        ("5 mb", "the 5 MB of memory"),
        ("5MiB", "the 5.24 MB of memory"),
        ("5M", "the 5.24 MB of memory"),
        ("5000000", "the 5 MB of memory"),
    ] {
        let res = with_limit(&big, limit);
        assert_one_line_error(&res, &["--size", shown]);
        assert!(tmp.listing().is_empty(), "{limit}: {:?}", tmp.listing());
    }
    let small = simulate_args("8x8x6", "100", &out, &[]);
    for limit in ["1G", "1GiB", "1 GB", ""] {
        let res = with_limit(&small, limit);
        assert!(res.status.success(), "{limit:?}: {}", stderr(&res));
        std::fs::remove_dir_all(out.as_path()).unwrap();
    }
    let info: Vec<String> = ["info", "--size", "8x8x6", "--pulse-len", "100"]
        .iter()
        .map(|a| a.to_string())
        .collect();
    for limit in ["-1", "5XB", "lots", "1e30", "inf", "5 M B", "-5MB"] {
        for args in [&small, &info] {
            let res = with_limit(args, limit);
            assert_one_line_error(&res, &["RDLIDAR_MEMORY_LIMIT", &format!("{limit:?}")]);
            assert!(tmp.listing().is_empty(), "{limit}: {:?}", tmp.listing());
        }
    }
}

// B02: numbers were echoed in full decimal: `--clipped 1e-300` printed a line of 763
// characters, `--snr-db -1e308` and `--tau-ps 1e-320` hundreds of digits. They are echoed as
// given, in scientific notation.
#[test]
fn numbers_of_any_size_are_echoed_in_a_few_characters() {
    let tmp = TempDir::new("bad-floats");
    let sim = small_simulation(&tmp, "sim");
    let file = |name: &str| s(&sim.join(name)).to_string();
    let reconstruct: Vec<String> = [
        "reconstruct",
        "--quiet",
        "--pulse",
        &file("pulse.npy"),
        "--codes",
        &file("codes.npy"),
        "--meas",
        &file("meas.npy"),
        "--depth-bins",
        "6",
        "--solver",
        "cgls",
        "--clipped",
        "1e-300",
        "--out-depth",
        s(&tmp.path("d.npy")),
        "--out-scene",
        s(&tmp.path("x.npy")),
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    let snr = simulate_args("8x8x6", "100", &tmp.path("noisy"), &["--snr-db", "-1e308"]);
    let tau: Vec<String> = [
        "info",
        "--size",
        "8x8x6",
        "--pulse-len",
        "100",
        "--tau-ps",
        "1e-320",
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    for (args, words) in [
        (&reconstruct, ["--clipped", "1e-300"]),
        (&snr, ["--snr-db", "-1e308"]),
        (&tau, ["--tau-ps", "1e-320"]),
    ] {
        let res = run(args);
        assert_one_line_error(&res, &words);
        let err = stderr(&res);
        assert!(err.chars().count() < 300, "{} characters: {err}", err.len());
        assert!(!err.contains("00000000"), "{err}");
    }
    assert_eq!(tmp.listing(), ["sim"]);
}

// B03: `simulate --adc-bits 8 --full-scale 1e300 --precision f32` blamed "--scene paper" (the
// ADC's levels overflow float32). The message names --full-scale and the way out, before any
// work, and nothing is written; in f64 the same full scale is fine.
#[test]
fn a_full_scale_beyond_float32_is_blamed_on_the_full_scale() {
    let tmp = TempDir::new("bad-full-scale");
    let out = tmp.path("run");
    let flags = ["--adc-bits", "8", "--full-scale", "1e300"];
    let f32_args = [&flags[..], &["--precision", "f32"]].concat();
    let res = run(&simulate_args("8x8x6", "100", &out, &f32_args));
    assert_one_line_error(&res, &["--full-scale", "1e300", "f32", "--precision f64"]);
    assert!(!stderr(&res).contains("--scene"), "{}", stderr(&res));
    assert!(tmp.listing().is_empty(), "{:?}", tmp.listing());
    let res = run(&simulate_args("8x8x6", "100", &out, &flags));
    assert!(res.status.success(), "{}", stderr(&res));
    // The small end: levels that would all read as 0 in f32 (the measurements vanishing
    // without a word), and in f64.
    let other = tmp.path("small");
    let tiny = [
        "--adc-bits",
        "8",
        "--full-scale",
        "1e-300",
        "--precision",
        "f32",
    ];
    let res = run(&simulate_args("8x8x6", "100", &other, &tiny));
    assert_one_line_error(&res, &["--full-scale", "1e-300", "f32", "read as 0"]);
    let tiniest = ["--adc-bits", "8", "--full-scale", "1e-322"];
    let res = run(&simulate_args("8x8x6", "100", &other, &tiniest));
    assert_one_line_error(&res, &["--full-scale", "f64", "read as 0"]);
    assert!(!other.exists());
}

// B05: a Unix socket given as an output was "a FIFO that nobody reads". It is refused as a
// socket, naming the flag, before any work, and left a socket; the library says the same
// to its callers.
#[test]
fn a_socket_given_as_an_output_is_refused_as_a_socket() {
    let tmp = TempDir::new("bad-socket");
    let sim = small_simulation(&tmp, "sim");
    let socket = tmp.path("out.sock");
    let _listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
    let file = |name: &str| s(&sim.join(name)).to_string();
    let outputs = [
        (
            vec![
                "forward".to_string(),
                "--scene".into(),
                file("scene.npy"),
                "--out".into(),
            ],
            "--out",
        ),
        (
            vec![
                "reconstruct".to_string(),
                "--meas".into(),
                file("meas.npy"),
                "--depth-bins".into(),
                "6".into(),
                "--solver".into(),
                "cgls".into(),
                "--out-scene".into(),
                s(&tmp.path("x.npy")).to_string(),
                "--out-depth".into(),
            ],
            "--out-depth",
        ),
    ];
    for (mut args, flag) in outputs {
        args.push(s(&socket).to_string());
        args.extend(["--pulse".into(), file("pulse.npy")]);
        args.extend(["--codes".into(), file("codes.npy")]);
        let res = run(&args);
        assert_one_line_error(&res, &["out.sock", flag, "socket"]);
        let err = stderr(&res);
        assert!(
            !err.contains("FIFO") && !err.contains("nobody reads"),
            "{err}"
        );
        let kind = std::fs::symlink_metadata(&socket).unwrap().file_type();
        assert!(
            kind.is_socket(),
            "{flag}: the socket was replaced ({kind:?})"
        );
    }
    let e = rdlidar::io::write_measurements(&socket, &[1.0f64, 2.0]).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("out.sock") && text.contains("socket"),
        "{text}"
    );
    assert!(!text.contains("FIFO"), "{text}");
    let kind = std::fs::symlink_metadata(socket).unwrap().file_type();
    assert!(
        kind.is_socket(),
        "the library replaced the socket ({kind:?})"
    );
    assert_eq!(tmp.listing(), ["out.sock", "sim"]);
}

/// Starts `simulate` of 128x128x40 with K_p 4000 (int8 codes of 66 MB) into `out` and returns
/// it once its first temporary file has appeared there: it is writing.
fn simulate_until_writing(out: &Path) -> Child {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(simulate_args("128x128x40", "4000", out, &[]))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs");
    let start = Instant::now();
    loop {
        let writing = std::fs::read_dir(out).is_ok_and(|entries| {
            entries
                .flatten()
                .any(|e| e.file_name().to_string_lossy().contains(".tmp-"))
        });
        if writing {
            return child;
        }
        if let Some(status) = child.try_wait().unwrap() {
            panic!("simulate ended ({status}) before a temporary file was seen");
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no temporary file after two minutes"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
}

// B06: Ctrl-C or SIGTERM while `simulate` wrote left its hidden temporary files in the output
// folder (710 MB at 256x256x40); the run again was refused as "not empty", and --force left
// them. An interrupt now removes them (and the folder the run made), exiting 130 or 143.
#[test]
fn an_interrupted_simulate_leaves_no_temporary_file() {
    for (signal, code) in [("-INT", 130), ("-TERM", 143)] {
        let tmp = TempDir::new("bad-interrupt");
        let out = tmp.path("run");
        let child = simulate_until_writing(&out);
        let killed = Command::new("kill")
            .args([signal, &child.id().to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        let res = child.wait_with_output().unwrap();
        assert_eq!(res.status.code(), Some(code), "{signal}: {}", stderr(&res));
        assert!(!stderr(&res).contains("panicked"), "{}", stderr(&res));
        // Nothing left, or (had the set been renamed into place first) the complete set.
        let left = tmp.listing();
        assert!(
            left.is_empty() || (left == ["run"] && listing(&out) == FILES),
            "{signal}: {left:?} {:?}",
            std::fs::read_dir(&out).map(|_| listing(&out))
        );
    }
}

// B06: temporary files that a killed writer left (`kill -9`, or a version without the handler)
// do not make the folder "not empty" and are removed by the next run; those of a process that
// still runs are files like any other. An experiment's staging folder of a killed run is
// removed by the next run into the same folder.
#[test]
fn temporary_files_of_a_killed_writer_neither_block_nor_survive_a_run() {
    let tmp = TempDir::new("bad-stale");
    let out = tmp.path("run");
    std::fs::create_dir(&out).unwrap();
    let dead = ended_pid();
    for name in [
        format!(".scene.npy.tmp-{dead}-0"),
        format!(".codes.npy.tmp-{dead}-3"),
    ] {
        std::fs::write(out.join(name), vec![0u8; 4096]).unwrap();
    }
    let res = run(&simulate_args("8x8x6", "100", &out, &[]));
    assert!(res.status.success(), "{}", stderr(&res));
    assert_eq!(listing(&out), FILES);

    // A temporary file of a process that runs (this one) is not the simulation's to remove.
    let busy = tmp.path("busy");
    std::fs::create_dir(&busy).unwrap();
    let live = format!(".meas.npy.tmp-{}-0", std::process::id());
    std::fs::write(busy.join(&live), b"writing").unwrap();
    let res = run(&simulate_args("8x8x6", "100", &busy, &[]));
    assert_one_line_error(&res, &["busy", "not empty", "--force"]);
    let res = run(&simulate_args("8x8x6", "100", &busy, &["--force"]));
    assert!(res.status.success(), "{}", stderr(&res));
    let mut expected: Vec<String> = FILES.iter().map(|f| f.to_string()).collect();
    expected.insert(0, live);
    assert_eq!(listing(&busy), expected);

    // compare: the staging folder of a killed run beside the output folder.
    let stale = tmp.path(&format!(".cmp.staging-{dead}"));
    std::fs::create_dir(&stale).unwrap();
    std::fs::write(stale.join("results.csv.partial"), "a,b\n").unwrap();
    let args: Vec<String> = [
        "compare",
        "--quiet",
        "--tiny",
        "--pulse-lens",
        "50",
        "--snr-db",
        "none",
        "--seeds",
        "1",
        "--solvers",
        "cgls",
        "--out",
        s(&tmp.path("cmp")),
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    let res = run(&args);
    assert!(res.status.success(), "{}", stderr(&res));
    assert_eq!(tmp.listing(), ["busy", "cmp", "run"]);
}
