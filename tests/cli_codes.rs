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

/// The arguments of `forward` with the codes `codes`, the scene and pulse of `run`, into `out`.
fn forward_args<'a>(
    run: &'a Path,
    codes: &'a Path,
    out: &'a Path,
    tiles: Option<&'a str>,
) -> Vec<String> {
    let mut v: Vec<String> = vec![
        "forward".into(),
        "--pulse".into(),
        s(&run.join("pulse.npy")).into(),
        "--codes".into(),
        s(codes).into(),
        "--scene".into(),
        s(&run.join("scene.npy")).into(),
        "--out".into(),
        s(out).into(),
    ];
    if let Some(t) = tiles {
        v.extend(["--tiles".into(), t.into()]);
    }
    v
}

fn run_ok(args: &[String]) -> std::process::Output {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = rdlidar(&refs);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn seeded_codes_need_no_file_and_give_the_simulated_measurements_back() {
    use rdlidar::io::meta::SimulationMeta;
    use rdlidar::lidar::SeededCodes;
    let tmp = TempDir::new("seeded");
    for (name, extra, tiles) in [
        ("single", vec![], None),
        ("adcs", vec!["--adcs", "3"], None),
        ("tiles", vec!["--tiles", "2x3"], Some("2x3")),
    ] {
        let run = tmp.path(name);
        let mut flags = vec!["--codes-format", "seed"];
        flags.extend(extra);
        simulate(&run, &flags);
        assert!(!run.join("codes.npy").exists(), "{name}: no codes file");
        let meta_path = run.join("meta.json");
        let meta: SimulationMeta =
            serde_json::from_str(&std::fs::read_to_string(&meta_path).unwrap()).unwrap();
        assert_eq!(meta.codes_format, "seed");
        assert_eq!(meta.codes_generator.as_deref(), Some("chacha8-packbits-v1"));
        assert_eq!(meta.files.codes, "meta.json");
        // The readers regenerate the codes the simulation used: the same measurements.
        let y = tmp.path(&format!("{name}-y.npy"));
        run_ok(&forward_args(&run, &meta_path, &y, tiles));
        assert_eq!(bytes(&y), bytes(&run.join("meas.npy")), "{name}");
        // ... and they are the seeded stream itself, materialized to a packed file.
        let sets = if name == "adcs" { 3 } else { 1 };
        let seeded = SeededCodes::new(meta.seeds.codes, sets, 35, 55).unwrap();
        let packed = tmp.path(&format!("{name}-codes.npy"));
        let all: Vec<_> = (0..sets).map(|g| seeded.materialize(g).unwrap()).collect();
        if sets == 1 {
            rdlidar::io::write_packed_codes(&packed, (5, 7), &all[0]).unwrap();
        } else {
            rdlidar::io::write_packed_code_sets(&packed, (5, 7), &all).unwrap();
        }
        let y2 = tmp.path(&format!("{name}-y2.npy"));
        run_ok(&forward_args(&run, &packed, &y2, tiles));
        assert_eq!(bytes(&y2), bytes(&y), "{name}");
        // Reconstruction from the description and from the packed file: the same bytes.
        let rec = |codes: &Path, tag: &str| {
            let (d, x) = (
                tmp.path(&format!("{name}-{tag}-d.npy")),
                tmp.path(&format!("{name}-{tag}-x.npy")),
            );
            let mut args: Vec<String> = [
                "reconstruct",
                "--pulse",
                s(&run.join("pulse.npy")),
                "--codes",
                s(codes),
                "--meas",
                s(&run.join("meas.npy")),
                "--depth-bins",
                "6",
                "--solver",
                "fista",
                "--out-depth",
                s(&d),
                "--out-scene",
                s(&x),
            ]
            .map(String::from)
            .to_vec();
            if let Some(t) = tiles {
                args.extend(["--tiles".into(), t.into()]);
            }
            run_ok(&args);
            (bytes(&d), bytes(&x))
        };
        assert_eq!(rec(&meta_path, "seed"), rec(&packed, "packed"), "{name}");
    }
}

#[test]
fn streamed_seeded_codes_give_the_held_codes_results() {
    let tmp = TempDir::new("streamed");
    let run = tmp.path("run");
    simulate(&run, &["--codes-format", "seed"]);
    let meta = run.join("meta.json");
    let with = |args: Vec<String>, stream: bool| {
        let mut args = args;
        if stream {
            args.push("--stream-codes".into());
        }
        run_ok(&args);
    };
    // Forward: one block holds these 35 pixels, so the same bytes.
    let (y1, y2) = (tmp.path("y1.npy"), tmp.path("y2.npy"));
    with(forward_args(&run, &meta, &y1, None), false);
    with(forward_args(&run, &meta, &y2, None), true);
    assert_eq!(bytes(&y1), bytes(&y2));
    assert_eq!(bytes(&y1), bytes(&run.join("meas.npy")));
    let files = |extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = [
            "--pulse",
            s(&run.join("pulse.npy")),
            "--codes",
            s(&meta),
            "--meas",
            s(&run.join("meas.npy")),
            "--depth-bins",
            "6",
        ]
        .map(String::from)
        .to_vec();
        v.extend(extra.iter().map(|a| a.to_string()));
        v
    };
    // Adjoint, debiased: a pixel's backprojection depends on its codes only.
    let (a1, a2) = (tmp.path("a1.npy"), tmp.path("a2.npy"));
    for (out, stream) in [(&a1, false), (&a2, true)] {
        let mut args = vec!["adjoint".to_string()];
        args.extend(files(&["--debiased", "--out", s(out)]));
        with(args, stream);
    }
    assert_eq!(bytes(&a1), bytes(&a2));
    // Reconstruction with auto: the same depth map.
    let (d1, d2) = (tmp.path("d1.npy"), tmp.path("d2.npy"));
    for (out, stream) in [(&d1, false), (&d2, true)] {
        let scene = out.with_extension("scene.npy");
        let mut args = vec!["reconstruct".to_string()];
        args.extend(files(&[
            "--solver",
            "auto",
            "--out-depth",
            s(out),
            "--out-scene",
            s(&scene),
        ]));
        with(args, stream);
    }
    assert_eq!(bytes(&d1), bytes(&d2));
    // The dot test runs on the streamed operator.
    let out = rdlidar(&[
        "dottest",
        "--pulse",
        s(&run.join("pulse.npy")),
        "--codes",
        s(&meta),
        "--depth-bins",
        "6",
        "--stream-codes",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Streaming is for seeded codes of one ADC.
    let int8 = tmp.path("int8");
    simulate(&int8, &[]);
    let codes = int8.join("codes.npy");
    let mut f = forward_args(&int8, &codes, &y1, None);
    f.push("--stream-codes".into());
    let refs: Vec<&str> = f.iter().map(String::as_str).collect();
    assert_one_line_error(&rdlidar(&refs), &["--stream-codes", s(&codes), "seed"]);
    let tiled = tmp.path("tiled");
    simulate(&tiled, &["--codes-format", "seed", "--tiles", "2x3"]);
    let tmeta = tiled.join("meta.json");
    let mut f = forward_args(&tiled, &tmeta, &y1, Some("2x3"));
    f.push("--stream-codes".into());
    let refs: Vec<&str> = f.iter().map(String::as_str).collect();
    assert_one_line_error(&rdlidar(&refs), &["--stream-codes", s(&tmeta), "tiles"]);
}

#[test]
fn seeded_codes_that_do_not_fit_are_refused_naming_the_file() {
    let tmp = TempDir::new("seeded-bad");
    let (seed, int8, other) = (tmp.path("seed"), tmp.path("int8"), tmp.path("other"));
    simulate(&seed, &["--codes-format", "seed", "--tiles", "2x3"]);
    simulate(&int8, &[]);
    let meta = seed.join("meta.json");
    let y = tmp.path("y.npy");
    let fails = |args: Vec<String>, needles: &[&str]| {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        assert_one_line_error(&rdlidar(&refs), needles);
        assert!(!y.exists());
    };
    // A meta.json whose codes are in a file.
    let m8 = int8.join("meta.json");
    fails(
        forward_args(&int8, &m8, &y, None),
        &[s(&m8), "stored as int8 in codes.npy"],
    );
    // Another pulse length: K does not fit.
    let args = vec![
        "simulate",
        "--scene",
        "paper",
        "--size",
        "5x7x6",
        "--pulse-len",
        "40",
        "--out",
        s(&other),
    ];
    assert!(rdlidar(&args).status.success());
    let mut f = forward_args(&seed, &meta, &y, Some("2x3"));
    f[2] = s(&other.join("pulse.npy")).into();
    fails(f, &[s(&meta), "K = 55", "K = 40 + 6 − 1 = 45"]);
    // Another tile size than the acquisition's.
    fails(
        forward_args(&seed, &meta, &y, Some("3x3")),
        &[s(&meta), "tiles of 2x3", "--tiles says 3x3"],
    );
    // An unknown generator, and a file that is not a description at all.
    let edited = tmp.path("edited.json");
    let text = std::fs::read_to_string(&meta).unwrap();
    std::fs::write(
        &edited,
        text.replace("chacha8-packbits-v1", "chacha8-packbits-v9"),
    )
    .unwrap();
    fails(
        forward_args(&seed, &edited, &y, Some("2x3")),
        &[s(&edited), "chacha8-packbits-v9"],
    );
    let junk = tmp.path("junk.json");
    std::fs::write(&junk, "{\"not\": 1}").unwrap();
    fails(
        forward_args(&seed, &junk, &y, None),
        &[s(&junk), "not a meta.json"],
    );
}
