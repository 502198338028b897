//! `rdlidar simulate --scene png`: a scene read from PNG depth and reflectivity maps, simulated
//! with the same pulse, codes and noise as any other scene, and the errors of bad maps.

use std::path::Path;

use ndarray::{Array1, Array3};
use ndarray_npy::read_npy;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::cli_support::{listing, rdlidar, s, stderr, TempDir};

/// Writes a one-channel PNG of `bits` (8 or 16) bits per value.
fn write_gray(path: &Path, width: u32, height: u32, bits: u8, values: &[u16]) {
    let file = std::fs::File::create(path).unwrap();
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::from_u8(bits).unwrap());
    let data: Vec<u8> = match bits {
        8 => values.iter().map(|&v| v as u8).collect(),
        _ => values.iter().flat_map(|v| v.to_be_bytes()).collect(),
    };
    let mut w = enc.write_header().unwrap();
    w.write_image_data(&data).unwrap();
    w.finish().unwrap();
}

const M: usize = 5;
const N: usize = 7;
const KS: usize = 9;

/// A seeded 16-bit depth map with about a quarter of its pixels empty, and an 8-bit
/// reflectivity map.
fn maps(dir: &Path) -> (Vec<u16>, Vec<u16>) {
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let depth: Vec<u16> = (0..M * N)
        .map(|_| {
            if rng.random::<f64>() < 0.25 {
                0
            } else {
                rng.random_range(1..=u16::MAX)
            }
        })
        .collect();
    let refl: Vec<u16> = (0..M * N).map(|_| rng.random_range(40..=255)).collect();
    write_gray(&dir.join("depth.png"), N as u32, M as u32, 16, &depth);
    write_gray(&dir.join("refl.png"), N as u32, M as u32, 8, &refl);
    (depth, refl)
}

fn simulate_png(dir: &Path, out: &Path, size: &str, extra: &[&str]) -> std::process::Output {
    let depth = dir.join("depth.png");
    let mut args = vec![
        "simulate",
        "--scene",
        "png",
        "--depth-png",
        s(&depth),
        "--size",
        size,
        "--pulse-len",
        "40",
        "--seed",
        "5",
        "--out",
        s(out),
    ];
    args.extend(extra);
    rdlidar(&args)
}

#[test]
fn a_png_scene_is_read_bin_by_bin_and_measured_as_any_other() {
    let tmp = TempDir::new("scene-png");
    let (depth, refl) = maps(&tmp.0);
    let run = tmp.path("run");
    let refl_path = tmp.path("refl.png");
    let size = format!("{M}x{N}x{KS}");
    let out = simulate_png(
        &tmp.0,
        &run,
        &size,
        &["--reflectivity-png", s(&refl_path), "--snr-db", "30"],
    );
    assert!(out.status.success(), "{}", stderr(&out));

    // Each pixel's return: bin round(v / 65535 · (K_s − 1)), amplitude r / 255; 0 is empty.
    let scene: Array3<f64> = read_npy(run.join("scene.npy")).unwrap();
    assert_eq!(scene.dim(), (M, N, KS));
    for i in 0..M {
        for j in 0..N {
            let (v, r) = (depth[i * N + j], refl[i * N + j]);
            let column = scene.slice(ndarray::s![i, j, ..]);
            if v == 0 {
                assert!(column.iter().all(|&a| a == 0.0), "pixel ({i}, {j})");
                continue;
            }
            let bin = (v as f64 / 65535.0 * (KS - 1) as f64).round() as usize;
            for (b, &a) in column.iter().enumerate() {
                let expected = if b == bin { r as f64 / 255.0 } else { 0.0 };
                assert!(
                    (a - expected).abs() < 1e-12,
                    "pixel ({i}, {j}) bin {b}: {a}"
                );
            }
        }
    }
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["scene"]["kind"], "supplied");
    assert_eq!(
        meta["scene"]["source"],
        "depth depth.png, reflectivity refl.png"
    );
    assert_eq!(meta["seeds"]["scene"], serde_json::Value::Null);
    assert_eq!(meta["noise"]["model"], "gaussian");

    // The same pulse and codes as the paper scene with the same seed, and the measurements are
    // the forward model of the scene read (plus the noise of the SNR asked for).
    let paper = tmp.path("paper");
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        &size,
        "--pulse-len",
        "40",
        "--seed",
        "5",
        "--out",
        s(&paper),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    for f in ["pulse.npy", "codes.npy"] {
        assert_eq!(
            std::fs::read(run.join(f)).unwrap(),
            std::fs::read(paper.join(f)).unwrap(),
            "{f}"
        );
    }
    let clean = tmp.path("clean.npy");
    let out = rdlidar(&[
        "forward",
        "--pulse",
        s(&run.join("pulse.npy")),
        "--codes",
        s(&run.join("codes.npy")),
        "--scene",
        s(&run.join("scene.npy")),
        "--out",
        s(&clean),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let y: Array1<f64> = read_npy(run.join("meas.npy")).unwrap();
    let y0: Array1<f64> = read_npy(&clean).unwrap();
    let power = y0.iter().map(|v| v * v).sum::<f64>() / y0.len() as f64;
    let noise = y.iter().zip(&y0).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / y0.len() as f64;
    let snr = 10.0 * (power / noise).log10();
    assert!((snr - 30.0).abs() < 2.0, "achieved SNR {snr} dB");
}

#[test]
fn bad_depth_maps_are_refused_naming_the_flag_and_leave_nothing_behind() {
    let tmp = TempDir::new("scene-png-errors");
    maps(&tmp.0);
    let run = tmp.path("run");
    let small = tmp.path("small.png");
    write_gray(&small, 3, 2, 8, &[1, 2, 3, 4, 5, 6]);
    let text = tmp.path("text.png");
    std::fs::write(&text, "not a png").unwrap();
    let missing = tmp.path("missing.png");
    // A header that claims 60 000 × 60 000 pixels and no image data: refused from the header,
    // nothing allocated for it.
    let huge = tmp.path("huge.png");
    {
        let file = std::fs::File::create(&huge).unwrap();
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), 60_000, 60_000);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Sixteen);
        let mut w = enc.write_header().unwrap();
        w.write_chunk(
            png::chunk::IDAT,
            &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
        )
        .unwrap();
        drop(w);
    }
    let e = rdlidar::io::scene_from_pngs::<f64>(&huge, None, 4).unwrap_err();
    assert!(e.to_string().contains("at most 4096"), "{e}");
    let size = format!("{M}x{N}x{KS}");
    let wrong_size = format!("{M}x{}x{KS}", N + 1);
    let cases: Vec<(String, Vec<&str>, Vec<&str>)> = vec![
        (
            wrong_size.clone(),
            vec![],
            vec![
                "--depth-png",
                "depth.png",
                "is 5 pixels high and 7 wide",
                "5 by 8",
            ],
        ),
        (
            size.clone(),
            vec!["--reflectivity-png", s(&small)],
            vec![
                "--reflectivity-png",
                "small.png",
                "is 2 pixels high and 3 wide",
            ],
        ),
        (
            size.clone(),
            vec!["--reflectivity-png", s(&text)],
            vec!["--reflectivity-png", "text.png", "not a readable PNG"],
        ),
        (
            size.clone(),
            vec!["--reflectivity-png", s(&huge)],
            vec!["--reflectivity-png", "huge.png", "60000 pixels high"],
        ),
        (
            size.clone(),
            vec!["--reflectivity-png", s(&missing)],
            vec!["--reflectivity-png", "missing.png", "cannot open"],
        ),
    ];
    for (size, extra, needles) in cases {
        let out = simulate_png(&tmp.0, &run, &size, &extra);
        assert_eq!(out.status.code(), Some(1), "{extra:?}: {}", stderr(&out));
        let err = stderr(&out);
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        for needle in needles {
            assert!(err.contains(needle), "{extra:?}: {needle:?} not in {err}");
        }
        assert!(!run.exists(), "{extra:?} left {run:?}");
    }
    // The depth map itself unreadable, and the flags without the scene or the scene without them.
    for (args, needle) in [
        (
            vec!["--scene", "png", "--depth-png", s(&text)],
            "--depth-png",
        ),
        (vec!["--scene", "png"], "--depth-png"),
        (
            vec!["--scene", "paper", "--depth-png", s(&text)],
            "--depth-png: applies only to --scene png",
        ),
        (
            vec!["--scene", "random", "--reflectivity-png", s(&small)],
            "--reflectivity-png: applies only to --scene png",
        ),
    ] {
        let mut all = vec![
            "simulate",
            "--size",
            &size,
            "--pulse-len",
            "40",
            "--out",
            s(&run),
        ];
        all.extend(args.iter().copied());
        let out = rdlidar(&all);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(needle), "{args:?}: {}", stderr(&out));
        assert!(!run.exists());
    }
    let mut left = listing(&tmp.0);
    left.sort();
    assert_eq!(
        left,
        ["depth.png", "huge.png", "refl.png", "small.png", "text.png"]
    );
}

#[test]
fn a_png_scene_beyond_memory_is_refused_before_its_maps_are_read() {
    let tmp = TempDir::new("scene-png-memory");
    maps(&tmp.0);
    let run = tmp.path("run");
    // The grid is refused for its memory before the (smaller) map is read and compared.
    let out = simulate_png(&tmp.0, &run, "4000x4000x4000", &[]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("4000x4000x4000") && err.contains("memory"),
        "{err}"
    );
    assert!(!run.exists());
}
