//! A seeded fuzz campaign over the `.npy` readers: valid files of every kind, mutated (bytes
//! flipped, inserted, deleted; the file cut or extended; the header replaced by hostile text:
//! deep nesting, control bytes, huge numbers and lengths, other dtypes and shapes), then read by
//! every reader. Each verdict must come within a second, without a panic, as a value or as a
//! one-line error that starts with the file's path and holds no control character. A sample of
//! the files also goes through the binary, which must exit with 0 or 1, never a panic (101) or a
//! signal.
//!
//! `RDLIDAR_FUZZ_CASES` sets the number of mutated files (default 3000); run with
//! `--nocapture` to see the campaign's counts.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::time::{Duration, Instant};

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rdlidar::io::{self, ShapeExpectation};

use crate::cli_support::{npy_bytes, npy_dict, rdlidar, s, TempDir};

/// Valid files of every kind the readers take (K_p = 20, K_s = 5, K = 24, 3×4 pixels).
fn seeds() -> Vec<Vec<u8>> {
    let f64s = |n: usize| -> Vec<u8> {
        (0..n)
            .flat_map(|i| (((i * 7) % 5) as f64 * 0.25).to_le_bytes())
            .collect()
    };
    let f32s = |n: usize| -> Vec<u8> {
        (0..n)
            .flat_map(|i| (((i * 3) % 2) as f32).to_le_bytes())
            .collect()
    };
    let codes = |n: usize| -> Vec<u8> {
        (0..n)
            .map(|i| if (i * 5) % 3 == 0 { 1u8 } else { 0xff })
            .collect()
    };
    vec![
        npy_bytes(&npy_dict("<f8", "(3, 4, 5)"), &f64s(60)),
        npy_bytes(&npy_dict("<f4", "(20,)"), &f32s(20)),
        npy_bytes(&npy_dict("|i1", "(3, 4, 24)"), &codes(288)),
        npy_bytes(&npy_dict("|i1", "(2, 3, 4, 24)"), &codes(576)),
        npy_bytes(&npy_dict("<f8", "(24,)"), &f64s(24)),
        npy_bytes(&npy_dict("<f8", "(2, 24)"), &f64s(48)),
        npy_bytes(
            &npy_dict("<i4", "(3, 4)"),
            &(0..12i32)
                .flat_map(|i| (i % 6 - 1).to_le_bytes())
                .collect::<Vec<_>>(),
        ),
    ]
}

/// Hostile header texts.
fn hostile_header(rng: &mut ChaCha8Rng) -> String {
    let depth = rng.random_range(1..40);
    let pick = rng.random_range(0..10);
    match pick {
        0 => npy_dict(
            "<f8",
            &format!("{}3{}", "(".repeat(depth), ",)".repeat(depth)),
        ),
        1 => npy_dict(
            "<f8",
            &format!("{}{}", "[".repeat(depth), "]".repeat(depth)),
        ),
        2 => format!(
            "{{'descr': {}'<f8'{}, 'fortran_order': False, 'shape': (3,)}}",
            "{'a': ".repeat(depth),
            "}".repeat(depth)
        ),
        3 => format!(
            "{{'descr': '<f8', 'fortran_order': False, 'shape': (3,), 'x': {}1{}}}",
            "[".repeat(depth),
            "]".repeat(depth)
        ),
        4 => npy_dict("<f8", "(99999999999999999999999999, 2)"),
        5 => npy_dict("<f8", "(4294967296, 4294967296)"),
        6 => npy_dict(
            [
                "<i8", "|b1", "<c16", "|O", "<U4", "=f4", ">f8", "|u1", "<f2", "",
            ][depth % 10],
            "(20,)",
        ),
        7 => format!(
            "{{'descr': '<f8\u{1b}[31m\u{0}', 'fortran_order': False, 'shape': ({depth},)}}"
        ),
        8 => "{".repeat(depth * 50),
        _ => npy_dict("<f8", &format!("({})", vec!["1"; depth * 10].join(", "))),
    }
}

/// One mutation of a valid file.
fn mutate(rng: &mut ChaCha8Rng, base: &[u8]) -> Vec<u8> {
    let mut v = base.to_vec();
    match rng.random_range(0..8) {
        0 => {
            // Flip bytes in the header.
            for _ in 0..rng.random_range(1..6) {
                let i = rng.random_range(0..v.len().min(128));
                v[i] ^= 1 << rng.random_range(0..8);
            }
        }
        1 => {
            // Random bytes anywhere.
            for _ in 0..rng.random_range(1..10) {
                let i = rng.random_range(0..v.len());
                v[i] = rng.random();
            }
        }
        2 => {
            let i = rng.random_range(0..v.len());
            v.insert(i, rng.random());
        }
        3 => {
            let i = rng.random_range(0..v.len());
            v.remove(i);
        }
        4 => v.truncate(rng.random_range(0..v.len())),
        5 => v.extend((0..rng.random_range(1..64)).map(|_| rng.random::<u8>())),
        6 => {
            // A header length field that lies.
            let len: u16 = rng.random();
            v[8..10].copy_from_slice(&len.to_le_bytes());
        }
        _ => {
            let data = &base[128.min(base.len())..];
            v = npy_bytes(&hostile_header(rng), data);
        }
    }
    v
}

/// Reads `path` with every reader; returns how many verdicts were errors. Panics (through the
/// assertions) on a slow verdict, a panic or a malformed message.
fn read_all(path: &Path) -> usize {
    let expect = ShapeExpectation {
        pulse_len: 20,
        depth_bins: 5,
        grid: None,
    };
    let shown = path.display().to_string();
    let mut errors = 0;
    let mut verdict = |name: &str, f: &dyn Fn() -> Option<String>| {
        let start = Instant::now();
        let r = catch_unwind(AssertUnwindSafe(f));
        let took = start.elapsed();
        assert!(
            took < Duration::from_secs(1),
            "{name} took {took:?} on {shown}"
        );
        match r {
            Err(_) => panic!("{name} panicked on {shown}"),
            Ok(Some(msg)) => {
                errors += 1;
                assert!(msg.starts_with(&shown), "{name}: {msg:?}");
                assert!(!msg.chars().any(char::is_control), "{name}: {msg:?}");
            }
            Ok(None) => {}
        }
    };
    let err = |e: rdlidar::Error| Some(e.to_string());
    verdict("header", &|| io::read_header(path).err().and_then(err));
    verdict("scene", &|| io::read_scene::<f64>(path).err().and_then(err));
    verdict("pulse", &|| io::read_pulse::<f32>(path).err().and_then(err));
    verdict("codes", &|| {
        io::read_codes(path, &expect).err().and_then(err)
    });
    verdict("code sets", &|| {
        io::read_code_sets(path, &expect).err().and_then(err)
    });
    verdict("measurements", &|| {
        io::read_measurements::<f32>(path, Some(&expect))
            .err()
            .and_then(err)
    });
    verdict("measurement rows", &|| {
        io::read_measurement_rows::<f64>(path, Some(&expect), None)
            .err()
            .and_then(err)
    });
    verdict("depth", &|| {
        io::read_depth(path, Some(5)).err().and_then(err)
    });
    errors
}

#[test]
fn mutated_files_get_a_verdict_in_bounded_time_and_one_line() {
    let cases: usize = std::env::var("RDLIDAR_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3000);
    let tmp = TempDir::new("fuzz");
    let bases = seeds();
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let (mut verdicts, mut errors, mut cli_runs) = (0, 0, 0);
    let start = Instant::now();
    for case in 0..cases {
        let base = &bases[case % bases.len()];
        let bytes = mutate(&mut rng, base);
        let path = tmp.path(&format!("case{}.npy", case % 16));
        std::fs::write(&path, &bytes).unwrap();
        errors += read_all(&path);
        verdicts += 8;
        // A sample through the binary: an exit status of 0 or 1, one line of error at most.
        if case % 100 == 0 {
            let res = rdlidar(&[
                "forward",
                "--pulse",
                s(&path),
                "--codes",
                s(&path),
                "--scene",
                s(&path),
                "--out",
                s(&tmp.path("y.npy")),
            ]);
            let code = res.status.code();
            assert!(matches!(code, Some(0) | Some(1)), "case {case}: {code:?}");
            let err = String::from_utf8_lossy(&res.stderr);
            assert!(err.trim_end().lines().count() <= 1, "case {case}: {err}");
            cli_runs += 1;
        }
    }
    println!(
        "npy fuzz: {cases} mutated files, {verdicts} verdicts ({errors} errors), {cli_runs} \
         binary runs, 0 panics, 0 hangs, in {:.1} s",
        start.elapsed().as_secs_f64()
    );
}

#[test]
fn nested_headers_are_refused_at_once() {
    let tmp = TempDir::new("nested");
    for depth in [16, 24, 64, 1000] {
        let path = tmp.path(&format!("n{depth}.npy"));
        let shape = format!("{}3{}", "(".repeat(depth), ",)".repeat(depth));
        std::fs::write(&path, npy_bytes(&npy_dict("<f8", &shape), &[0; 24])).unwrap();
        let start = Instant::now();
        let e = io::read_header(&path).unwrap_err().to_string();
        assert!(start.elapsed() < Duration::from_secs(1));
        assert!(
            e.contains("nested") || e.contains("expected an integer"),
            "{depth}: {e}"
        );
    }
}
