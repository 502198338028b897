//! `rdlidar simulate`, run as a user would: the five files it writes, their shapes, dtypes and
//! metadata, its options, and the errors that leave nothing behind.

use ndarray::{Array1, Array3};
use ndarray_npy::read_npy;

use crate::cli_support::{listing, rdlidar, s, simulate_small, stderr, TempDir};

#[test]
fn simulate_writes_the_five_files_with_their_shapes_dtypes_and_metadata() {
    let tmp = TempDir::new("simulate");
    let dir = tmp.path("run");
    simulate_small(&dir, &[]);
    assert_eq!(
        listing(&dir),
        [
            "codes.npy",
            "meas.npy",
            "meta.json",
            "pulse.npy",
            "scene.npy"
        ],
        "only the five outputs, no temporary files"
    );
    let scene: Array3<f64> = read_npy(dir.join("scene.npy")).unwrap();
    assert_eq!(scene.dim(), (4, 5, 6));
    let pulse: Array1<f64> = read_npy(dir.join("pulse.npy")).unwrap();
    assert_eq!(pulse.len(), 50);
    assert!(pulse.iter().all(|&v| v == 0.0 || v == 1.0));
    let codes: Array3<i8> = read_npy(dir.join("codes.npy")).unwrap();
    assert_eq!(codes.dim(), (4, 5, 55));
    assert!(codes.iter().all(|&v| v == 1 || v == -1));
    let meas: Array1<f64> = read_npy(dir.join("meas.npy")).unwrap();
    assert_eq!(meas.len(), 55);
    assert!(meas.iter().any(|&v| v != 0.0));

    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["geometry"]["m"], 4);
    assert_eq!(meta["geometry"]["n"], 5);
    assert_eq!(meta["geometry"]["ks"], 6);
    assert_eq!(meta["pulse_len"], 50);
    assert_eq!(meta["k"], 55);
    assert_eq!(meta["seed"], 7);
    assert_eq!(meta["seeds"]["pulse"], 7);
    assert_eq!(meta["seeds"]["codes"], 8);
    assert_eq!(meta["seeds"]["noise"], 9);
    assert_eq!(meta["scene"]["kind"], "paper");
    assert_eq!(meta["code_alphabet"], "binary");
    assert_eq!(meta["regime"], "compressive");
    assert_eq!(meta["critical_pulse_len"], 19 * 6 + 1);
    assert_eq!(meta["noise"]["model"], "none");
    assert_eq!(meta["prng"], "ChaCha8");
    assert_eq!(meta["crate_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(meta["precision"], "f64");
}

#[test]
fn simulate_is_reproducible_and_honours_precision_alphabet_and_noise() {
    let tmp = TempDir::new("simulate-options");
    let (a, b) = (tmp.path("a"), tmp.path("b"));
    let extra = [
        "--precision",
        "f32",
        "--ternary-zero-prob",
        "0.3",
        "--snr-db",
        "-3",
    ];
    simulate_small(&a, &extra);
    simulate_small(&b, &extra);
    for f in [
        "scene.npy",
        "pulse.npy",
        "codes.npy",
        "meas.npy",
        "meta.json",
    ] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f} differs between two runs"
        );
    }
    let scene: Array3<f32> = read_npy(a.join("scene.npy")).unwrap();
    assert_eq!(scene.dim(), (4, 5, 6));
    let codes: Array3<i8> = read_npy(a.join("codes.npy")).unwrap();
    assert!(codes.iter().any(|&v| v == 0));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["code_alphabet"], "ternary");
    assert_eq!(meta["noise"]["model"], "gaussian");
    assert_eq!(meta["noise"]["snr_db"], -3.0);
    assert!(meta["noise"]["sigma"].as_f64().unwrap() > 0.0);
}

#[test]
fn simulate_random_and_transparent_scenes() {
    let tmp = TempDir::new("simulate-scenes");
    for (kind, extra) in [
        ("random", vec!["--lit-fraction", "0.4"]),
        ("transparent", vec![]),
    ] {
        let dir = tmp.path(kind);
        let mut args = vec![
            "simulate",
            "--scene",
            kind,
            "--size",
            "3x4x8",
            "--pulse-len",
            "30",
            "--out",
            s(&dir),
        ];
        args.extend(extra);
        let out = rdlidar(&args);
        assert!(out.status.success(), "{kind}: {}", stderr(&out));
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("meta.json")).unwrap()).unwrap();
        assert_eq!(meta["scene"]["kind"], kind);
        assert_eq!(meta["seeds"]["scene"], 3);
    }
}

#[test]
fn simulate_refuses_a_non_empty_directory_without_force() {
    let tmp = TempDir::new("no-force");
    let dir = tmp.path("run");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("keep.txt"), "mine").unwrap();
    let args = [
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x5x6",
        "--pulse-len",
        "50",
        "--out",
        s(&dir),
    ];
    let out = rdlidar(&args);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains(s(&dir)) && err.contains("--force"), "{err}");
    assert_eq!(listing(&dir), ["keep.txt"]);

    // With --force the five files are written and other files are left alone.
    let mut forced = args.to_vec();
    forced.push("--force");
    let out = rdlidar(&forced);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        listing(&dir),
        [
            "codes.npy",
            "keep.txt",
            "meas.npy",
            "meta.json",
            "pulse.npy",
            "scene.npy"
        ]
    );
}

#[test]
fn simulate_errors_leave_nothing_behind() {
    let tmp = TempDir::new("sim-errors");
    let dir = tmp.path("run");
    for (extra, needle) in [
        (vec!["--lit-fraction", "0.3"], "--lit-fraction"),
        (
            vec!["--ternary-zero-prob", "1.5", "--scene", "random"],
            "--ternary-zero-prob",
        ),
    ] {
        let mut args = vec![
            "simulate",
            "--size",
            "4x5x6",
            "--pulse-len",
            "50",
            "--out",
            s(&dir),
        ];
        if !extra.contains(&"--scene") {
            args.extend(["--scene", "paper"]);
        }
        args.extend(extra);
        let out = rdlidar(&args);
        assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
        assert!(stderr(&out).contains(needle), "{}", stderr(&out));
        assert!(!dir.exists());
    }
    // A missing parent directory.
    let deep = tmp.path("a").join("b");
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x5x6",
        "--pulse-len",
        "50",
        "--out",
        s(&deep),
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains(s(&deep)), "{}", stderr(&out));
    assert!(listing(&tmp.0).is_empty());
}

#[test]
fn simulate_with_photon_noise_and_an_adc_records_them_and_refuses_bad_values() {
    let tmp = TempDir::new("sim-noise-models");
    let dir = tmp.path("run");
    let base = [
        "simulate",
        "--scene",
        "paper",
        "--size",
        "6x6x5",
        "--pulse-len",
        "120",
        "--out",
        s(&dir),
    ];
    let mut args = base.to_vec();
    args.extend([
        "--photons",
        "25",
        "--background",
        "3",
        "--adc-bits",
        "5",
        "--full-scale",
        "4",
    ]);
    let out = rdlidar(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("meta.json")).unwrap()).unwrap();
    let noise = &meta["noise"];
    assert_eq!(noise["model"], "poisson+quantized");
    assert_eq!(noise["photons"], 25.0);
    assert_eq!(noise["background"], 3.0);
    assert_eq!(noise["adc_bits"], 5);
    assert_eq!(noise["full_scale"], 4.0);
    let meas: Array1<f64> = read_npy(dir.join("meas.npy")).unwrap();
    let clipped = meas.iter().filter(|v| v.abs() == 4.0 - 0.125).count();
    assert!(noise["clipped"].as_u64().unwrap() as usize <= clipped);
    assert!(meas
        .iter()
        .all(|v| ((v + 4.0) / 0.25 - 0.5).fract().abs() < 1e-9));
    std::fs::remove_dir_all(&dir).unwrap();
    for (extra, needle) in [
        (vec!["--background", "2"], "--background: "),
        (vec!["--full-scale", "2"], "--full-scale: "),
        (vec!["--adc-bits", "33"], "--adc-bits: "),
        (vec!["--photons", "inf"], "--photons: "),
        (
            vec!["--adc-bits", "8", "--full-scale", "0"],
            "--full-scale: ",
        ),
    ] {
        let mut args = base.to_vec();
        args.extend(extra.iter().copied());
        let out = rdlidar(&args);
        assert_eq!(out.status.code(), Some(1), "{extra:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(needle), "{extra:?}: {}", stderr(&out));
        assert!(!dir.exists());
    }
}

/// The same arguments write the same files whatever `--threads` says (the paper scene at
/// 16×16×8 with K_p 150, whose measurements once differed in the last bits between 1 and 2
/// threads), noise-free and with noise, and reconstruct from them the same depth map.
#[test]
fn simulate_and_reconstruct_write_the_same_files_for_any_thread_count() {
    let tmp = TempDir::new("simulate-threads");
    for (tag, noise) in [("clean", None), ("noisy", Some("20"))] {
        let mut files: Vec<Vec<Vec<u8>>> = Vec::new();
        for threads in ["1", "2", "3"] {
            let dir = tmp.path(&format!("{tag}-{threads}"));
            let mut args = vec![
                "--threads",
                threads,
                "simulate",
                "--scene",
                "paper",
                "--size",
                "16x16x8",
                "--pulse-len",
                "150",
                "--seed",
                "0",
                "--out",
                s(&dir),
            ];
            if let Some(db) = noise {
                args.extend(["--snr-db", db]);
            }
            let out = rdlidar(&args);
            assert!(out.status.success(), "{}", stderr(&out));
            let depth = dir.join("depth.npy");
            let scene = dir.join("xh.npy");
            let out = rdlidar(&[
                "--threads",
                threads,
                "reconstruct",
                "--quiet",
                "--pulse",
                s(&dir.join("pulse.npy")),
                "--codes",
                s(&dir.join("codes.npy")),
                "--meas",
                s(&dir.join("meas.npy")),
                "--depth-bins",
                "8",
                "--solver",
                "cgls",
                "--max-iter",
                "20",
                "--out-depth",
                s(&depth),
                "--out-scene",
                s(&scene),
            ]);
            assert!(out.status.success(), "{}", stderr(&out));
            files.push(
                [
                    "meas.npy",
                    "codes.npy",
                    "pulse.npy",
                    "scene.npy",
                    "depth.npy",
                    "xh.npy",
                ]
                .iter()
                .map(|f| std::fs::read(dir.join(f)).unwrap())
                .collect(),
            );
        }
        for (i, threads) in [(1, "2"), (2, "3")] {
            assert!(
                files[i] == files[0],
                "{tag}: --threads {threads} wrote other files than --threads 1"
            );
        }
    }
}
