//! Packed codes from the command line: `simulate --codes-format packed` writes what numpy's
//! `packbits` writes, and every subcommand that reads codes gives the same bytes from them as
//! from the int8 file.

use std::path::Path;

use ndarray::{Array3, Array4};
use ndarray_npy::{read_npy, write_npy};

use super::cli_support::{assert_one_line_error, rdlidar, s, TempDir};

/// `np.packbits(S > 0, axis=-1)` of the last axis, bit by bit.
fn packbits(codes: &[i8], len: usize) -> Vec<u8> {
    let nb = len.div_ceil(8);
    let mut out = Vec::new();
    for row in codes.chunks(len) {
        let mut bytes = vec![0u8; nb];
        for (k, &v) in row.iter().enumerate() {
            if v > 0 {
                bytes[k / 8] |= 0x80 >> (k % 8);
            }
        }
        out.extend(bytes);
    }
    out
}

fn simulate(dir: &Path, extra: &[&str]) {
    let mut args = vec![
        "simulate",
        "--scene",
        "transparent",
        "--size",
        "5x7x6",
        "--pulse-len",
        "50",
        "--seed",
        "3",
        "--out",
        s(dir),
    ];
    args.extend_from_slice(extra);
    let out = rdlidar(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn bytes(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap()
}

/// Runs a subcommand with the codes of `codes_dir` and the rest of `run`, writing `out`.
fn run_with(codes_dir: &Path, run: &Path, out: &Path, what: &str) {
    let codes = codes_dir.join("codes.npy");
    let (pulse, scene, meas) = (
        run.join("pulse.npy"),
        run.join("scene.npy"),
        run.join("meas.npy"),
    );
    let scene_out = out.with_extension("scene.npy");
    let args: Vec<&str> = match what {
        "forward" => vec![
            "forward",
            "--pulse",
            s(&pulse),
            "--codes",
            s(&codes),
            "--scene",
            s(&scene),
            "--out",
            s(out),
        ],
        "adjoint" => vec![
            "adjoint",
            "--pulse",
            s(&pulse),
            "--codes",
            s(&codes),
            "--meas",
            s(&meas),
            "--depth-bins",
            "6",
            "--out",
            s(out),
        ],
        _ => vec![
            "reconstruct",
            "--pulse",
            s(&pulse),
            "--codes",
            s(&codes),
            "--meas",
            s(&meas),
            "--depth-bins",
            "6",
            "--solver",
            what,
            "--out-depth",
            s(out),
            "--out-scene",
            s(&scene_out),
        ],
    };
    let o = rdlidar(&args);
    assert!(
        o.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn packed_codes_are_numpys_packbits_and_give_bit_identical_results() {
    let tmp = TempDir::new("packed");
    let (int8, packed) = (tmp.path("int8"), tmp.path("packed"));
    simulate(&int8, &[]);
    simulate(&packed, &["--codes-format", "packed"]);
    // K = 55: 7 bytes per pixel, the last with 7 samples and 1 pad bit.
    let dense: Array3<i8> = read_npy(int8.join("codes.npy")).unwrap();
    let bits: Array3<u8> = read_npy(packed.join("codes.npy")).unwrap();
    assert_eq!(bits.dim(), (5, 7, 7));
    assert_eq!(
        bits.as_slice().unwrap(),
        &packbits(dense.as_slice().unwrap(), 55)[..]
    );
    for f in ["scene.npy", "pulse.npy", "meas.npy"] {
        assert_eq!(bytes(&int8.join(f)), bytes(&packed.join(f)), "{f}");
    }
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(packed.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["codes_format"], "packed");
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(int8.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["codes_format"], "int8");
    for what in ["forward", "adjoint", "auto", "fista"] {
        let (a, b) = (
            tmp.path(&format!("{what}-a.npy")),
            tmp.path(&format!("{what}-b.npy")),
        );
        run_with(&int8, &int8, &a, what);
        run_with(&packed, &int8, &b, what);
        assert_eq!(bytes(&a), bytes(&b), "{what}");
        if what != "forward" && what != "adjoint" {
            assert_eq!(
                bytes(&a.with_extension("scene.npy")),
                bytes(&b.with_extension("scene.npy")),
                "{what}"
            );
        }
    }
}

#[test]
fn packed_code_sets_of_several_adcs_read_as_the_int8_ones() {
    let tmp = TempDir::new("packed-adcs");
    let (int8, packed) = (tmp.path("int8"), tmp.path("packed"));
    simulate(&int8, &["--adcs", "2"]);
    simulate(&packed, &["--adcs", "2", "--codes-format", "packed"]);
    let dense: Array4<i8> = read_npy(int8.join("codes.npy")).unwrap();
    let bits: Array4<u8> = read_npy(packed.join("codes.npy")).unwrap();
    assert_eq!(bits.dim(), (2, 5, 7, 7));
    assert_eq!(
        bits.as_slice().unwrap(),
        &packbits(dense.as_slice().unwrap(), 55)[..]
    );
    assert_eq!(
        bytes(&int8.join("meas.npy")),
        bytes(&packed.join("meas.npy"))
    );
    for what in ["forward", "adjoint", "auto"] {
        let (a, b) = (
            tmp.path(&format!("{what}-a.npy")),
            tmp.path(&format!("{what}-b.npy")),
        );
        run_with(&int8, &int8, &a, what);
        run_with(&packed, &int8, &b, what);
        assert_eq!(bytes(&a), bytes(&b), "{what}");
    }
}

#[test]
fn packed_codes_that_do_not_fit_are_refused_naming_the_file() {
    let tmp = TempDir::new("packed-bad");
    let run = tmp.path("run");
    simulate(&run, &["--codes-format", "packed"]);
    let good: Array3<u8> = read_npy(run.join("codes.npy")).unwrap();
    let bad = tmp.path("bad.npy");
    let forward = |codes: &Path| {
        rdlidar(&[
            "forward",
            "--pulse",
            s(&run.join("pulse.npy")),
            "--codes",
            s(codes),
            "--scene",
            s(&run.join("scene.npy")),
            "--out",
            s(&tmp.path("y.npy")),
        ])
    };
    // A pad bit set at pixel (2, 3).
    let mut padded = good.clone();
    padded[[2, 3, 6]] |= 0x01;
    write_npy(&bad, &padded).unwrap();
    assert_one_line_error(&forward(&bad), &[s(&bad), "pad bit", "(2, 3)"]);
    // One byte too few per pixel.
    write_npy(&bad, &good.slice(ndarray::s![.., .., ..6]).to_owned()).unwrap();
    assert_one_line_error(&forward(&bad), &[s(&bad), "⌈K/8⌉", "found 6"]);
    // Another grid.
    write_npy(&bad, &good.slice(ndarray::s![..4, .., ..]).to_owned()).unwrap();
    assert_one_line_error(&forward(&bad), &[s(&bad), "4x7 pixels"]);
    assert!(!tmp.path("y.npy").exists());
    // Codes with zeros have no packed form.
    for flags in [["--aperture", "0.5"], ["--ternary-zero-prob", "0.3"]] {
        let out = rdlidar(&[
            "simulate",
            "--scene",
            "paper",
            "--size",
            "4x4x4",
            "--pulse-len",
            "20",
            "--codes-format",
            "packed",
            flags[0],
            flags[1],
            "--out",
            s(&tmp.path("never")),
        ]);
        assert_one_line_error(&out, &["--codes-format packed", flags[0], "int8"]);
        assert!(!tmp.path("never").exists());
    }
}
