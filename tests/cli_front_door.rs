//! The front door of the command line: what `forward`, `adjoint`, `dottest` and `reconstruct`
//! accept from their files (`meta.json` fields, array shapes beyond the bounds) and where they
//! write (devices, FIFOs, two flags naming one file).
//!
//! Every bad input must fail with exit status 1 (no panic, no abort or other signal) and exactly
//! one line `error: …` that names the file, flag or `meta.json` field concerned, and must leave
//! no output behind. The checks look for the key words any fix must print (a field name, a flag,
//! a file name, a bound), not for whole sentences.
//!
//! Each test names the defect it guards (D01 …), found on the code before the fix.

use std::io::Read;
use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use crate::cli_support::{
    assert_one_line_error, listing, npy_bytes, npy_dict, rdlidar, s, stderr, stdout, TempDir,
};

// ---------------------------------------------------------------------------------------------
// Helpers

/// The subcommands that read codes.
const COMMANDS: [&str; 4] = ["forward", "adjoint", "dottest", "reconstruct"];

/// Simulates the paper scene of `size` with a pulse of 100 samples and seed 7 into `tmp/name`,
/// with the `extra` flags (architecture, codes format), and returns that folder.
fn simulate(tmp: &TempDir, name: &str, size: &str, extra: &[&str]) -> PathBuf {
    let dir = tmp.path(name);
    let mut args = vec![
        "simulate",
        "--quiet",
        "--seed",
        "7",
        "--scene",
        "paper",
        "--size",
        size,
        "--pulse-len",
        "100",
        "--out",
        s(&dir),
    ];
    args.extend_from_slice(extra);
    let out = rdlidar(&args);
    assert!(out.status.success(), "simulate {extra:?}: {}", stderr(&out));
    dir
}

/// An 8x8x6 acquisition whose codes are described by their seed (`meta.json`), with the
/// architecture flags `extra`.
fn seeded(tmp: &TempDir, name: &str, extra: &[&str]) -> PathBuf {
    let mut flags = vec!["--codes-format", "seed"];
    flags.extend_from_slice(extra);
    simulate(tmp, name, "8x8x6", &flags)
}

/// Writes the `meta.json` of the simulation `sim`, changed by `edit`, to `tmp/name` (a name
/// ending in `.json`, which the messages must quote) and returns its path.
fn edited_meta(tmp: &TempDir, sim: &Path, name: &str, edit: impl FnOnce(&mut Value)) -> PathBuf {
    let text = std::fs::read_to_string(sim.join("meta.json")).unwrap();
    let mut meta: Value = serde_json::from_str(&text).unwrap();
    edit(&mut meta);
    let path = tmp.path(name);
    std::fs::write(&path, serde_json::to_string_pretty(&meta).unwrap()).unwrap();
    path
}

/// The arguments of `what` (one of [`COMMANDS`]) on the pulse, scene and measurements of `sim`
/// with the codes `codes`, `--depth-bins ks`, and outputs in the folder `out`.
fn command(what: &str, sim: &Path, codes: &Path, ks: &str, out: &Path) -> Vec<String> {
    let file = |name: &str| s(&sim.join(name)).to_string();
    let output = |name: &str| s(&out.join(name)).to_string();
    let mut args: Vec<String> = vec![
        what.into(),
        "--quiet".into(),
        "--pulse".into(),
        file("pulse.npy"),
        "--codes".into(),
        s(codes).into(),
    ];
    let rest: Vec<String> = match what {
        "forward" => vec![
            "--scene".into(),
            file("scene.npy"),
            "--out".into(),
            output("y.npy"),
        ],
        "adjoint" => vec![
            "--meas".into(),
            file("meas.npy"),
            "--depth-bins".into(),
            ks.into(),
            "--out".into(),
            output("xt.npy"),
        ],
        "dottest" => vec!["--depth-bins".into(), ks.into()],
        "reconstruct" => vec![
            "--meas".into(),
            file("meas.npy"),
            "--depth-bins".into(),
            ks.into(),
            "--solver".into(),
            "cgls".into(),
            "--out-depth".into(),
            output("d.npy"),
            "--out-scene".into(),
            output("xh.npy"),
        ],
        _ => panic!("unknown subcommand {what}"),
    };
    args.extend(rest);
    args
}

/// Runs the binary with `args`, in the folder `cwd` if given.
fn run_in(cwd: Option<&Path>, args: &[String]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rdlidar"));
    c.args(args).stdin(Stdio::null());
    if let Some(d) = cwd {
        c.current_dir(d);
    }
    c.output().expect("the binary runs")
}

fn run(args: &[String]) -> Output {
    run_in(None, args)
}

/// Runs the binary with `args`, killed if it has not ended after `limit` (a killed run ends by a
/// signal, which the callers' checks of the exit status report).
fn run_with_deadline(args: &[String], limit: Duration) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs");
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child.wait_with_output().unwrap()
}

/// Where `word` follows a count of exactly 1 (`1 rows`, `(1 ADCs)`): a plural after one (not
/// counted: `1 of 1 tiles`).
fn one_with_plural(text: &str, word: &str) -> bool {
    let needle = format!("1 {word}");
    text.match_indices(&needle).any(|(i, _)| {
        let before = &text[..i];
        (before.is_empty() || matches!(before.chars().next_back(), Some(' ' | '(' | '[')))
            && !before.ends_with(" of ")
    })
}

/// Plurals after a count of one in `text`, for the messages' grammar.
fn assert_no_plural_after_one(text: &str) {
    for word in ["rows", "code sets", "tiles", "ADCs"] {
        assert!(!one_with_plural(text, word), "\"1 {word}\" in {text}");
    }
}

/// The run failed as a bad input must: status 1, not a signal; no panic; one line `error: …`
/// containing every one of `needles`, without runs of spaces or plurals after one; and the
/// output folder `out` left empty.
fn assert_refused(out: &Output, needles: &[&str], outputs: &Path) {
    let err = stderr(out);
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.status.code().is_some(), "ended by a signal: {err}");
    assert_one_line_error(out, needles);
    assert!(!err.contains("  "), "a run of spaces in {err:?}");
    assert_no_plural_after_one(&err);
    assert!(
        listing(outputs).is_empty(),
        "{:?} left by {err}",
        listing(outputs)
    );
}

/// Standard error without the name of this process's temporary folders, whose process id
/// could hold any number (a bound such as 4096 must come from the message itself).
fn message(out: &Output) -> String {
    let tmp = format!("rdlidar-cli-support-{}", std::process::id());
    stderr(out).replace(&tmp, "TMP")
}

/// The error line contains at least one of `words` (outside the temporary folder's name).
fn assert_mentions_any(out: &Output, words: &[&str]) {
    let err = message(out);
    assert!(
        words.iter().any(|w| err.contains(w)),
        "none of {words:?} in {err}"
    );
}

/// The file name of `path`, as the messages must quote it.
fn name(path: &Path) -> &str {
    path.file_name().unwrap().to_str().unwrap()
}

/// A seeded stream of ±1 int8 codes (xorshift64), as bytes.
fn codes_bytes(count: usize, seed: u64) -> Vec<u8> {
    let mut x = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    (0..count)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            if x & 1 == 1 {
                1u8
            } else {
                (-1i8) as u8
            }
        })
        .collect()
}

/// The data of a `.npy` file, after its header.
fn npy_data(path: &Path) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    bytes[10 + len..].to_vec()
}

/// `bytes` are a version 1.0 `.npy` file of shape `shape` (as numpy prints it) holding exactly
/// `data_len` bytes of data.
fn assert_npy(bytes: &[u8], shape: &str, data_len: usize) {
    assert!(
        bytes.starts_with(b"\x93NUMPY"),
        "not a .npy: {:?}",
        &bytes[..bytes.len().min(16)]
    );
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = String::from_utf8_lossy(&bytes[10..10 + len]);
    assert!(header.contains(&format!("'shape': {shape}")), "{header}");
    assert_eq!(bytes.len(), 10 + len + data_len, "{header}");
}

/// Makes a FIFO at `path` with mkfifo(1); false where that is not possible.
fn mkfifo(path: &Path) -> bool {
    Command::new("mkfifo")
        .arg(path)
        .status()
        .is_ok_and(|st| st.success())
}

/// Runs the binary with `args`, one of which names the FIFO `fifo`, while a thread reads the
/// FIFO to its end; returns the run and what was read. Nothing can hang: the run is killed after
/// a deadline, and a reader still waiting for a writer (when the binary never opened the FIFO,
/// e.g. renamed a file over it) is released through a second link to the FIFO.
fn run_reading_fifo(args: &[String], fifo: &Path) -> (Output, Vec<u8>) {
    let spare = fifo.with_extension("spare-link");
    std::fs::hard_link(fifo, &spare).unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let path = fifo.to_path_buf();
    std::thread::spawn(move || {
        let mut data = Vec::new();
        if let Ok(mut f) = std::fs::File::open(&path) {
            let _ = f.read_to_end(&mut data);
        }
        let _ = tx.send(data);
    });
    // The reader may not have reached open() yet (a loaded machine): the command refuses a FIFO
    // nobody reads, so it runs again until the reader waits.
    let mut out = run_with_deadline(args, Duration::from_secs(30));
    for _ in 0..100 {
        if !stderr(&out).contains("nobody reads") {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
        out = run_with_deadline(args, Duration::from_secs(30));
    }
    let data = match rx.recv_timeout(Duration::from_secs(5)) {
        Ok(d) => d,
        Err(_) => {
            // The reader waits in open() for a writer that never came: be that writer.
            drop(std::fs::OpenOptions::new().write(true).open(&spare));
            rx.recv_timeout(Duration::from_secs(5)).unwrap_or_default()
        }
    };
    let _ = std::fs::remove_file(&spare);
    (out, data)
}

/// A successful run.
fn assert_ok(out: &Output, what: &str) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(0), "{what}: {err}");
    assert!(!err.contains("panicked"), "{what}: {err}");
}

// ---------------------------------------------------------------------------------------------
// meta.json fields

// D01: a tiled seeded meta.json with `architecture.tile` [0, 0] or [0, 4] made `adjoint` and
// `reconstruct` panic with "attempt to divide by zero". Every command must refuse it, naming the
// file and the tile.
#[test]
fn a_zero_tile_in_meta_json_is_refused_by_every_command() {
    let tmp = TempDir::new("front-zero");
    let sim = seeded(&tmp, "in-fours", &["--tiles", "4x4"]);
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    for (i, tile) in [[0, 0], [0, 4], [4, 0]].into_iter().enumerate() {
        let meta = edited_meta(&tmp, &sim, &format!("zero-{i}.json"), |m| {
            m["architecture"]["tile"] = json!(tile);
        });
        for what in COMMANDS {
            let out = run(&command(what, &sim, &meta, "6", &outputs));
            assert_refused(&out, &[name(&meta), "tile"], &outputs);
        }
    }
}

// D02, D08: a multi-ADC (and a single-ADC) seeded meta.json with geometry.m = geometry.n = 2^32 + 1
// made `adjoint` abort ("memory allocation … failed"); with 2^32 the message blamed a wrapped
// product ("got 1 × 0"), with 2^32 + 1 it blamed --depth-bins. The message must name the file and
// the geometry or its bound of 4096.
#[test]
fn a_geometry_beyond_the_bounds_in_meta_json_is_refused_without_wrapping() {
    let tmp = TempDir::new("front-huge");
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    for (arch, extra) in [("multi", &["--adcs", "2"][..]), ("single", &[][..])] {
        let sim = seeded(&tmp, arch, extra);
        for side in [1u64 << 32, (1u64 << 32) + 1] {
            let meta = edited_meta(&tmp, &sim, &format!("{arch}-{side}.json"), |m| {
                m["geometry"]["m"] = json!(side);
                m["geometry"]["n"] = json!(side);
            });
            for what in COMMANDS {
                let out = run(&command(what, &sim, &meta, "6", &outputs));
                assert_refused(&out, &[name(&meta)], &outputs);
                assert_mentions_any(&out, &["geometry", "4096"]);
                let err = message(&out);
                assert!(!err.contains("1 × 0") && !err.contains("1x0"), "{err}");
                assert!(!err.contains("--depth-bins"), "{err}");
            }
        }
    }
}

// D07: the bounds M, N ≤ 4096 and K_s ≤ 65536 hold for a seeded meta.json too: geometry
// 4097x4097 (size and k consistent) and 8x8x65537 are refused, naming the file and the bound.
#[test]
fn a_meta_json_beyond_the_bounds_is_refused_naming_the_bound() {
    let tmp = TempDir::new("front-wide");
    let sim = seeded(&tmp, "single", &[]);
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    let wide = edited_meta(&tmp, &sim, "wide.json", |m| {
        m["geometry"]["m"] = json!(4097);
        m["geometry"]["n"] = json!(4097);
        m["size"] = json!("4097x4097x6");
    });
    let deep = edited_meta(&tmp, &sim, "deep.json", |m| {
        m["geometry"]["ks"] = json!(65537);
        m["size"] = json!("8x8x65537");
        m["k"] = json!(100 + 65537 - 1);
    });
    for what in COMMANDS {
        let out = run(&command(what, &sim, &wide, "6", &outputs));
        assert_refused(&out, &[name(&wide)], &outputs);
        assert_mentions_any(&out, &["4096"]);
        let out = run(&command(what, &sim, &deep, "6", &outputs));
        assert_refused(&out, &[name(&deep)], &outputs);
        assert_mentions_any(&out, &["65536", "ks", "depth"]);
    }
}

// D08: a meta.json whose `codes_generator` is a string of 100 000 characters: the message names
// the field and quotes at most an excerpt of the value.
#[test]
fn a_huge_codes_generator_is_quoted_in_a_short_line() {
    let tmp = TempDir::new("front-generator");
    let sim = seeded(&tmp, "single", &[]);
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    let meta = edited_meta(&tmp, &sim, "generator.json", |m| {
        m["codes_generator"] = json!("x".repeat(100_000));
    });
    for what in COMMANDS {
        let out = run(&command(what, &sim, &meta, "6", &outputs));
        assert_refused(&out, &[name(&meta), "codes_generator"], &outputs);
        let err = stderr(&out);
        assert!(
            err.chars().count() < 400,
            "{} characters",
            err.chars().count()
        );
    }
}

// D14: a seeded meta.json with pulse_len 1000000000000 and geometry.ks 7 while k stays 105
// (= 100 + 6 − 1) ran with exit status 0. The fields disagree: it must be refused, naming
// pulse_len or ks. The same with only ks changed (k no longer pulse_len + ks − 1).
#[test]
fn a_meta_json_whose_pulse_len_ks_and_k_disagree_is_refused() {
    let tmp = TempDir::new("front-kp");
    let sim = seeded(&tmp, "single", &[]);
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    let huge_kp = edited_meta(&tmp, &sim, "huge.json", |m| {
        m["pulse_len"] = json!(1_000_000_000_000u64);
        m["geometry"]["ks"] = json!(7);
        m["size"] = json!("8x8x7");
    });
    // As first found: `size` left as written too.
    let huge_kp_stale_size = edited_meta(&tmp, &sim, "stale.json", |m| {
        m["pulse_len"] = json!(1_000_000_000_000u64);
        m["geometry"]["ks"] = json!(7);
    });
    let ks_only = edited_meta(&tmp, &sim, "bins.json", |m| {
        m["geometry"]["ks"] = json!(7);
        m["size"] = json!("8x8x7");
    });
    for what in COMMANDS {
        for ks in ["6", "7"] {
            for meta in [&huge_kp, &ks_only] {
                let out = run(&command(what, &sim, meta, ks, &outputs));
                assert_refused(&out, &[name(meta)], &outputs);
                assert_mentions_any(&out, &["pulse_len", "ks"]);
            }
            let out = run(&command(what, &sim, &huge_kp_stale_size, ks, &outputs));
            assert_refused(&out, &[name(&huge_kp_stale_size)], &outputs);
            assert_mentions_any(&out, &["pulse_len", "ks", "size", "geometry"]);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Array files beyond the bounds

// D07: `forward` on int8 codes of shape (4097, 1, 105) with a matching scene (4097, 1, 6) and a
// pulse of 100: refused, naming the bound of 4096 and the file or its size.
#[test]
fn codes_with_more_than_4096_rows_are_refused() {
    let tmp = TempDir::new("front-rows");
    let sim = simulate(&tmp, "sim", "4x4x6", &[]);
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    let codes = tmp.path("tall-codes.npy");
    std::fs::write(
        &codes,
        npy_bytes(
            &npy_dict("|i1", "(4097, 1, 105)"),
            &codes_bytes(4097 * 105, 11),
        ),
    )
    .unwrap();
    let scene = tmp.path("tall-scene.npy");
    std::fs::write(
        &scene,
        npy_bytes(&npy_dict("<f8", "(4097, 1, 6)"), &vec![0u8; 4097 * 6 * 8]),
    )
    .unwrap();
    let args: Vec<String> = [
        "forward",
        "--pulse",
        s(&sim.join("pulse.npy")),
        "--codes",
        s(&codes),
        "--scene",
        s(&scene),
        "--out",
        s(&outputs.join("y.npy")),
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    let out = run(&args);
    assert_refused(&out, &[], &outputs);
    assert_mentions_any(&out, &["4096"]);
    assert_mentions_any(&out, &[name(&codes), name(&scene), "4097"]);
}

// ---------------------------------------------------------------------------------------------
// Outputs

// D03: an output that exists and is not a regular file (a FIFO) was renamed over. It must be
// written in place: the FIFO stays a FIFO and its reader receives the whole file, for
// `forward --out`, `adjoint --out`, `reconstruct --out-depth`, `--out-scene` and `--png`.
#[test]
fn a_fifo_output_is_written_in_place() {
    let tmp = TempDir::new("front-fifo");
    let sim = simulate(&tmp, "sim", "8x8x6", &[]);
    let codes = sim.join("codes.npy");
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    let fifo = tmp.path("pipe");
    if !mkfifo(&fifo) {
        eprintln!("mkfifo is not available: skipped");
        return;
    }
    const NPY: &[u8] = b"\x93NUMPY";
    const PNG: &[u8] = b"\x89PNG\r\n\x1a\n";
    // (subcommand, flag given the FIFO, the reader's data: magic, .npy shape, data bytes)
    let cases: [(&str, &str, &[u8], &str, usize); 5] = [
        ("forward", "--out", NPY, "(105,)", 105 * 8),
        ("adjoint", "--out", NPY, "(8, 8, 6)", 8 * 8 * 6 * 8),
        ("reconstruct", "--out-depth", NPY, "(8, 8)", 8 * 8 * 4),
        (
            "reconstruct",
            "--out-scene",
            NPY,
            "(8, 8, 6)",
            8 * 8 * 6 * 8,
        ),
        ("reconstruct", "--png", PNG, "", 0),
    ];
    for (what, flag, magic, shape, data_len) in cases {
        let mut args = command(what, &sim, &codes, "6", &outputs);
        if flag == "--png" {
            args.extend(["--png".to_string(), s(&fifo).to_string()]);
        } else {
            let i = args.iter().position(|a| a == flag).unwrap();
            args[i + 1] = s(&fifo).to_string();
        }
        let (out, data) = run_reading_fifo(&args, &fifo);
        assert_ok(&out, &format!("{what} {flag}"));
        let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
        assert!(
            kind.is_fifo(),
            "{what} {flag}: the FIFO was replaced ({kind:?})"
        );
        assert!(
            data.starts_with(magic),
            "{what} {flag}: read {} bytes",
            data.len()
        );
        if !shape.is_empty() {
            assert_npy(&data, shape, data_len);
        }
    }
}

// D03: a character device given as an output (`/dev/null`) was renamed over (as root, /dev/null
// became a regular file). It must be written in place: the command succeeds and the device is
// still a character device. A private device node (the same device as /dev/null, made in the
// temporary folder where allowed) is tried first, so that a binary that renames over outputs
// fails there before it could touch /dev/null; /dev/null itself only if it is writable.
#[test]
fn a_character_device_output_is_written_in_place() {
    let tmp = TempDir::new("front-null");
    let sim = simulate(&tmp, "sim", "8x8x6", &[]);
    let codes = sim.join("codes.npy");
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    let writable = |p: &Path| std::fs::OpenOptions::new().write(true).open(p).is_ok();
    let mut devices = Vec::new();
    let private = tmp.path("null");
    let made = Command::new("mknod")
        .args([s(&private), "c", "1", "3"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|st| st.success());
    if made && writable(&private) {
        devices.push(private);
    } else {
        // No device node here: a FIFO must then have been written in place first.
        let fifo = tmp.path("canary");
        assert!(mkfifo(&fifo), "neither mknod nor mkfifo works");
        let mut args = command("forward", &sim, &codes, "6", &outputs);
        let i = args.iter().position(|a| a == "--out").unwrap();
        args[i + 1] = s(&fifo).to_string();
        let (out, _) = run_reading_fifo(&args, &fifo);
        assert_ok(&out, "forward --out FIFO");
        assert!(std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo());
    }
    let null = PathBuf::from("/dev/null");
    if writable(&null) {
        devices.push(null);
    }
    for device in devices {
        for (what, flag) in [
            ("forward", "--out"),
            ("adjoint", "--out"),
            ("reconstruct", "--out-scene"),
            ("reconstruct", "--out-depth"),
            ("reconstruct", "--png"),
        ] {
            let mut args = command(what, &sim, &codes, "6", &outputs);
            if flag == "--png" {
                args.extend(["--png".to_string(), s(&device).to_string()]);
            } else {
                let i = args.iter().position(|a| a == flag).unwrap();
                args[i + 1] = s(&device).to_string();
            }
            let out = run_with_deadline(&args, Duration::from_secs(30));
            assert_ok(&out, &format!("{what} {flag} {}", device.display()));
            let kind = std::fs::metadata(&device).unwrap().file_type();
            assert!(
                kind.is_char_device(),
                "{what} {flag}: {} is no longer a character device ({kind:?})",
                device.display()
            );
        }
        for entry in listing(&outputs) {
            std::fs::remove_file(outputs.join(entry)).unwrap();
        }
    }
}

// D04: `reconstruct --out-depth x.npy --out-scene ./x.npy` exited 0 with the scene in x.npy.
// Two outputs naming one file however spelt (./x.npy, an absolute path, a symbolic link to the
// other output, a path through a symbolic link to the folder) are refused naming both flags, and
// nothing is written.
#[test]
fn two_outputs_naming_one_file_are_refused() {
    let tmp = TempDir::new("front-same");
    let sim = simulate(&tmp, "sim", "8x8x6", &[]);
    let work = tmp.path("work");
    std::fs::create_dir_all(work.join("sub")).unwrap();
    std::os::unix::fs::symlink("sub", work.join("sub-link")).unwrap();
    let absolute = s(&work.join("x.npy")).to_string();
    let cases: Vec<[(&str, &str); 2]> = vec![
        [("--out-depth", "x.npy"), ("--out-scene", "./x.npy")],
        [("--out-scene", "x.npy"), ("--out-depth", "./x.npy")],
        [("--out-depth", "x.npy"), ("--out-scene", absolute.as_str())],
        [
            ("--out-depth", "sub/x.npy"),
            ("--out-scene", "sub-link/x.npy"),
        ],
        [
            ("--out-depth", "sub/x.npy"),
            ("--png", "./sub/../sub/x.npy"),
        ],
        [("--out-scene", "x.npy"), ("--png", "./x.npy")],
    ];
    let base = |out_depth: &str, out_scene: &str| -> Vec<String> {
        let mut args = command("reconstruct", &sim, &sim.join("codes.npy"), "6", &work);
        for (flag, path) in [("--out-depth", out_depth), ("--out-scene", out_scene)] {
            let i = args.iter().position(|a| a == flag).unwrap();
            args[i + 1] = path.to_string();
        }
        args
    };
    let files = |dir: &Path| {
        let mut v = listing(dir);
        v.extend(
            listing(&dir.join("sub"))
                .into_iter()
                .map(|n| format!("sub/{n}")),
        );
        v
    };
    let before = files(&work);
    for [(fa, pa), (fb, pb)] in &cases {
        let mut args = base("depth.npy", "scene.npy");
        for (flag, path) in [(fa, pa), (fb, pb)] {
            if *flag == "--png" {
                args.extend([flag.to_string(), path.to_string()]);
            } else {
                let i = args.iter().position(|a| a == flag).unwrap();
                args[i + 1] = path.to_string();
            }
        }
        let out = run_in(Some(&work), &args);
        let what = format!("{fa} {pa} {fb} {pb}");
        assert!(
            !stderr(&out).contains("panicked"),
            "{what}: {}",
            stderr(&out)
        );
        assert_one_line_error(&out, &[*fa, *fb, "x.npy"]);
        assert_eq!(files(&work), before, "{what}");
    }
    // A symbolic link to the other, existing output: refused, the file left as it was.
    std::fs::write(work.join("x.npy"), b"before").unwrap();
    std::os::unix::fs::symlink("x.npy", work.join("link.npy")).unwrap();
    for (depth, scene) in [("x.npy", "link.npy"), ("link.npy", "x.npy")] {
        let out = run_in(Some(&work), &base(depth, scene));
        assert_one_line_error(&out, &["--out-depth", "--out-scene"]);
        assert_mentions_any(&out, &["x.npy", "link.npy"]);
        assert_eq!(std::fs::read(work.join("x.npy")).unwrap(), b"before");
        let link = std::fs::symlink_metadata(work.join("link.npy")).unwrap();
        assert!(link.file_type().is_symlink(), "link.npy was replaced");
        assert_eq!(listing(&work), ["link.npy", "sub", "sub-link", "x.npy"]);
    }
}

// ---------------------------------------------------------------------------------------------
// Message grammar

// Minor: `--stream-codes` with an int8 codes file printed a message with 14 stray spaces (a line
// continuation inside the string). Every command must print one clean line naming the file.
#[test]
fn stream_codes_with_a_codes_file_is_one_clean_line() {
    let tmp = TempDir::new("front-stream");
    let sim = simulate(&tmp, "sim", "8x8x6", &[]);
    let codes = sim.join("codes.npy");
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    for what in COMMANDS {
        let mut args = command(what, &sim, &codes, "6", &outputs);
        args.push("--stream-codes".into());
        let out = run(&args);
        assert_refused(&out, &["codes.npy"], &outputs);
    }
}

// Minor: measurements with the wrong number of rows for the codes said "have 1 rows" (one row
// for two code sets) and "are 1 code sets" (codes (1, M, N, K), one ADC, with two rows); a tile
// as large as the array was "1 tiles". Counts of one are singular.
#[test]
fn counts_of_one_are_singular_in_row_mismatches() {
    let tmp = TempDir::new("front-one");
    let single = simulate(&tmp, "single", "8x8x6", &[]);
    let multi = simulate(&tmp, "multi", "8x8x6", &["--adcs", "2"]);
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    let y = npy_data(&single.join("meas.npy"));
    assert_eq!(y.len(), 105 * 8);
    let rows = |n: usize| {
        let path = tmp.path(&format!("meas-{n}-rows.npy"));
        let data: Vec<u8> = (0..n).flat_map(|_| y.iter().copied()).collect();
        std::fs::write(
            &path,
            npy_bytes(&npy_dict("<f8", &format!("({n}, 105)")), &data),
        )
        .unwrap();
        path
    };
    let (one_row, two_rows) = (rows(1), rows(2));
    // The codes of one ADC as one code set of a (G, M, N, K) file with G = 1.
    let one_set = tmp.path("one-set.npy");
    std::fs::write(
        &one_set,
        npy_bytes(
            &npy_dict("|i1", "(1, 8, 8, 105)"),
            &npy_data(&single.join("codes.npy")),
        ),
    )
    .unwrap();
    let cases: Vec<(PathBuf, &Path, Vec<&str>)> = vec![
        (multi.join("codes.npy"), one_row.as_path(), vec![]),
        (one_set.clone(), two_rows.as_path(), vec![]),
        (
            single.join("codes.npy"),
            two_rows.as_path(),
            vec!["--tiles", "8x8"],
        ),
        (
            single.join("codes.npy"),
            one_row.as_path(),
            vec!["--tiles", "4x4"],
        ),
    ];
    for (codes, meas, extra) in &cases {
        for what in ["adjoint", "reconstruct"] {
            let mut args = command(what, &single, codes, "6", &outputs);
            let i = args.iter().position(|a| a == "--meas").unwrap();
            args[i + 1] = s(meas).to_string();
            args.extend(extra.iter().map(|a| a.to_string()));
            let out = run(&args);
            assert_refused(&out, &[], &outputs);
            assert_mentions_any(&out, &[name(meas), name(codes)]);
        }
    }
    // Codes (1, M, N, K) with the measurements of one ADC, (K,): accepted or refused, but a
    // refusal is one clean line.
    for what in ["adjoint", "reconstruct"] {
        let out = run(&command(what, &single, &one_set, "6", &outputs));
        if !out.status.success() {
            assert_refused(&out, &[], &outputs);
            assert_mentions_any(&out, &[name(&one_set), "meas.npy"]);
        }
        for entry in listing(&outputs) {
            std::fs::remove_file(outputs.join(entry)).unwrap();
        }
    }
}

// Minor: a tiled array of a single tile was reported as "tiles of 8x8 pixels (1 ADCs)" on
// stdout by every command.
#[test]
fn a_single_tile_is_one_adc_in_the_summaries() {
    let tmp = TempDir::new("front-one-tile");
    let sim = simulate(&tmp, "sim", "8x8x6", &[]);
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    let meas = tmp.path("meas-1-row.npy");
    std::fs::write(
        &meas,
        npy_bytes(
            &npy_dict("<f8", "(1, 105)"),
            &npy_data(&sim.join("meas.npy")),
        ),
    )
    .unwrap();
    for what in COMMANDS {
        let mut args = command(what, &sim, &sim.join("codes.npy"), "6", &outputs);
        if let Some(i) = args.iter().position(|a| a == "--meas") {
            args[i + 1] = s(&meas).to_string();
        }
        args.extend(["--tiles".to_string(), "8x8".to_string()]);
        let out = run(&args);
        assert_ok(&out, &format!("{what} --tiles 8x8"));
        assert_no_plural_after_one(&stdout(&out));
    }
}

// Found while writing these tests (the rewrite in progress): codes of shape (1, M, N, K), one
// code set with one ADC, as the (G, M, N, K) files of `simulate --adcs G` with G = 1, were
// refused by forward, adjoint and dottest ("codes must have 3 dimensions (M, N, K), found 4").
// They are read as one ADC: forward's measurements go back through adjoint, and the dot test
// passes.
#[test]
fn codes_of_one_code_set_in_four_dimensions_are_read() {
    let tmp = TempDir::new("front-g1");
    let sim = simulate(&tmp, "sim", "8x8x6", &[]);
    let outputs = tmp.path("out");
    std::fs::create_dir(&outputs).unwrap();
    let codes = tmp.path("one-set.npy");
    std::fs::write(
        &codes,
        npy_bytes(
            &npy_dict("|i1", "(1, 8, 8, 105)"),
            &npy_data(&sim.join("codes.npy")),
        ),
    )
    .unwrap();
    let out = run(&command("forward", &sim, &codes, "6", &outputs));
    assert_ok(&out, "forward");
    assert_no_plural_after_one(&stdout(&out));
    let y = outputs.join("y.npy");
    let mut args = command("adjoint", &sim, &codes, "6", &outputs);
    let i = args.iter().position(|a| a == "--meas").unwrap();
    args[i + 1] = s(&y).to_string();
    let out = run(&args);
    assert_ok(&out, "adjoint");
    assert_no_plural_after_one(&stdout(&out));
    assert!(outputs.join("xt.npy").is_file());
    let out = run(&command("dottest", &sim, &codes, "6", &outputs));
    assert_ok(&out, "dottest");
    assert_no_plural_after_one(&stdout(&out));
}

// ---------------------------------------------------------------------------------------------
// Found in review of the fixes above.

// A FIFO output that nobody reads is refused at once, never waited on.
#[test]
fn a_fifo_output_without_a_reader_is_refused_at_once() {
    let tmp = TempDir::new("fifo-no-reader");
    let sim = simulate(&tmp, "sim", "8x8x6", &[]);
    let fifo = tmp.path("y.npy");
    if !mkfifo(&fifo) {
        return;
    }
    let args: Vec<String> = [
        "forward",
        "--quiet",
        "--pulse",
        s(&sim.join("pulse.npy")),
        "--codes",
        s(&sim.join("codes.npy")),
        "--scene",
        s(&sim.join("scene.npy")),
        "--out",
        s(&fifo),
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    let out = run_with_deadline(&args, Duration::from_secs(30));
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_one_line_error(&out, &["y.npy", "nobody reads"]);
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
}

// Codes with a code-set axis and --tiles, codes without any code set, and meta.json fields
// that contradict seeded codes (a ternary alphabet, a tile on another architecture, a file
// far too large to be a description) are refused before any work, naming the file.
#[test]
fn codes_and_descriptions_that_contradict_the_request_are_refused() {
    let tmp = TempDir::new("contradictions");
    let sim = simulate(&tmp, "multi", "8x8x6", &["--adcs", "2"]);
    let codes: ndarray::Array4<i8> = ndarray_npy::read_npy(sim.join("codes.npy")).unwrap();
    let one = tmp.path("one_set.npy");
    ndarray_npy::write_npy(&one, &codes.slice(ndarray::s![0..1, .., .., ..]).to_owned()).unwrap();
    let none = tmp.path("no_set.npy");
    ndarray_npy::write_npy(
        &none,
        &codes.slice(ndarray::s![0..0, .., .., ..]).to_owned(),
    )
    .unwrap();
    let out_dir = tmp.path("out");
    std::fs::create_dir(&out_dir).unwrap();
    let mut args = command("adjoint", &sim, &one, "6", &out_dir);
    args.extend(["--tiles".to_string(), "4x4".to_string()]);
    let out = run(&args);
    assert_refused(
        &out,
        &["one_set.npy", "--tiles 4x4", "code-set axis"],
        &out_dir,
    );
    let out = run(&command("forward", &sim, &none, "6", &out_dir));
    assert_refused(&out, &["no_set.npy", "no code set"], &out_dir);

    let seed = seeded(&tmp, "seed", &[]);
    let ternary = edited_meta(&tmp, &seed, "ternary.json", |m| {
        m["code_alphabet"] = json!("ternary");
        m["ternary_zero_prob"] = json!(0.3);
    });
    let tile = edited_meta(&tmp, &seed, "tile_on_single.json", |m| {
        m["architecture"]["tile"] = json!([2, 2]);
    });
    let big = tmp.path("big.json");
    let mut text = std::fs::read_to_string(seed.join("meta.json")).unwrap();
    text.push_str(&" ".repeat(2 << 20));
    std::fs::write(&big, text).unwrap();
    for (file, words) in [
        (&ternary, ["ternary.json", "code_alphabet"]),
        (&tile, ["tile_on_single.json", "architecture.tile"]),
        (&big, ["big.json", "bytes"]),
    ] {
        let out = run(&command("adjoint", &seed, file, "6", &out_dir));
        assert_refused(&out, &words, &out_dir);
    }
}
