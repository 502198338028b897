//! The binary end to end on a tiny problem: `simulate` writes the five files, `reconstruct`
//! (several solvers, with the PNG and the comparison with the truth) writes the depth map and
//! the scene, and the files are read back and checked against each other.

use std::path::{Path, PathBuf};

use ndarray::{Array1, Array2, Array3, Axis};
use ndarray_npy::read_npy;
use rdlidar::io::{read_header, NpyDtype};

use crate::cli_support::{rdlidar, s, stderr, stdout, TempDir};

/// A random opaque 6×7 scene with 10 depth bins (non-square, so that rows and columns cannot
/// be swapped unnoticed), K_p = 1500: redundant, so an easy case.
const SIZE: (usize, usize, usize) = (6, 7, 10);
const KP: usize = 1500;

fn simulate(dir: &TempDir) -> PathBuf {
    let sim = dir.path("sim");
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "random",
        "--size",
        "6x7x10",
        "--pulse-len",
        &KP.to_string(),
        "--seed",
        "4",
        "--out",
        s(&sim),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(
        text.contains("redundant regime (critical K_p = 411)"),
        "{text}"
    );
    sim
}

/// Each pixel's depth in a one-return-per-pixel scene: the bin of its nonzero, −1 for none.
fn depth_of(scene: &Array3<f64>) -> Array2<i32> {
    let (m, n, _) = scene.dim();
    let mut d = Array2::from_elem((m, n), -1);
    for (p, col) in scene.lanes(Axis(2)).into_iter().enumerate() {
        let nz: Vec<usize> = (0..col.len()).filter(|&j| col[j] != 0.0).collect();
        assert!(nz.len() <= 1, "pixel {p} has {} returns", nz.len());
        if let Some(&j) = nz.first() {
            d[[p / n, p % n]] = j as i32;
        }
    }
    d
}

/// The numbers of the "versus the truth" line: exact %, RMSE in bins, missed, false, relative
/// error.
fn metrics(text: &str) -> (f64, f64, usize, usize, f64) {
    let line = text
        .lines()
        .find(|l| l.starts_with("versus the truth: "))
        .unwrap_or_else(|| panic!("no metrics in {text}"));
    let after = |key: &str| -> &str {
        let i = line
            .find(key)
            .unwrap_or_else(|| panic!("{key:?} in {line}"))
            + key.len();
        line[i..].split([' ', '%', ',']).next().unwrap()
    };
    (
        after("exact depth ").parse().unwrap(),
        after("depth RMSE ").parse().unwrap(),
        after("missed ").parse().unwrap(),
        after("false ").parse().unwrap(),
        after("relative error ").parse().unwrap(),
    )
}

/// Width and height from a PNG's IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
    assert_eq!(&b[12..16], b"IHDR");
    let w = u32::from_be_bytes(b[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(b[20..24].try_into().unwrap());
    (w, h)
}

fn reconstruct(sim: &Path, out: &TempDir, tag: &str, solver: &str, extra: &[&str]) -> String {
    let file = |p: PathBuf| s(&p).to_string();
    let mut args: Vec<String> = vec![
        "reconstruct".into(),
        "--pulse".into(),
        file(sim.join("pulse.npy")),
        "--codes".into(),
        file(sim.join("codes.npy")),
        "--meas".into(),
        file(sim.join("meas.npy")),
        "--depth-bins".into(),
        "10".into(),
        "--solver".into(),
        solver.into(),
        "--out-depth".into(),
        file(out.path(&format!("{tag}-depth.npy"))),
        "--out-scene".into(),
        file(out.path(&format!("{tag}-scene.npy"))),
        "--truth".into(),
        file(sim.join("scene.npy")),
        "--quiet".into(),
    ];
    args.extend(extra.iter().map(|a| a.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let run = rdlidar(&args);
    assert!(run.status.success(), "{solver}: {}", stderr(&run));
    assert!(run.stderr.is_empty(), "{solver}: {}", stderr(&run));
    stdout(&run)
}

#[test]
fn simulate_then_reconstruct_recovers_the_depth_map() {
    let (m, n, ks) = SIZE;
    let k = KP + ks - 1;
    let dir = TempDir::new("e2e");
    let sim = simulate(&dir);

    // simulate: the five files, their dtypes and shapes, and their contents.
    assert_eq!(
        crate::cli_support::listing(&sim),
        [
            "codes.npy",
            "meas.npy",
            "meta.json",
            "pulse.npy",
            "scene.npy"
        ]
    );
    for (file, dtype, shape) in [
        ("scene.npy", NpyDtype::Float64, vec![m, n, ks]),
        ("pulse.npy", NpyDtype::Float64, vec![KP]),
        ("codes.npy", NpyDtype::Int8, vec![m, n, k]),
        ("meas.npy", NpyDtype::Float64, vec![k]),
    ] {
        let h = read_header(sim.join(file)).unwrap();
        assert_eq!((h.dtype, h.shape), (dtype, shape), "{file}");
    }
    let truth: Array3<f64> = read_npy(sim.join("scene.npy")).unwrap();
    let pulse: Array1<f64> = read_npy(sim.join("pulse.npy")).unwrap();
    let codes: Array3<i8> = read_npy(sim.join("codes.npy")).unwrap();
    let meas: Array1<f64> = read_npy(sim.join("meas.npy")).unwrap();
    assert!(pulse.iter().all(|&v| v == 0.0 || v == 1.0));
    assert!(pulse.sum() > 0.3 * KP as f64 && pulse.sum() < 0.7 * KP as f64);
    assert!(codes.iter().all(|&c| c == 1 || c == -1));
    assert!(truth.iter().all(|&v| v == 0.0 || (0.2..=1.0).contains(&v)));
    let true_depth = depth_of(&truth);
    let lit = true_depth.iter().filter(|&&d| d >= 0).count();
    assert!(lit > 5 && lit < m * n, "{lit} lit pixels");
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sim.join("meta.json")).unwrap()).unwrap();
    assert_eq!(meta["k"], k);
    assert_eq!(meta["regime"], "redundant");
    assert_eq!(meta["scene"]["lit_pixels"], lit);
    // The measurements are y[k] = Σ_p s[p,k] Σ_j x[p,j] p[k−j], computed here directly.
    let mut y = vec![0.0f64; k];
    for (idx, &a) in truth.indexed_iter().filter(|(_, &a)| a != 0.0) {
        let (i, jn, j) = idx;
        for (t, &pv) in pulse.iter().enumerate() {
            y[t + j] += a * pv * f64::from(codes[[i, jn, t + j]]);
        }
    }
    let err = y
        .iter()
        .zip(&meas)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(err < 1e-9, "measurements differ by {err}");

    // reconstruct: least squares and the model-based solver recover the easy case exactly.
    let out = TempDir::new("e2e-out");
    for (tag, solver) in [("cgls", "cgls"), ("mb", "model-based")] {
        let png = out.path(&format!("{tag}.png"));
        let text = reconstruct(&sim, &out, tag, solver, &["--png", s(&png)]);
        assert!(
            text.contains(&format!("solver {solver} (redundant regime)")),
            "{text}"
        );
        let (exact, rmse, missed, false_, rel) = metrics(&text);
        assert_eq!(
            (exact, rmse, missed, false_),
            (100.0, 0.0, 0, 0),
            "{solver}: {text}"
        );
        assert!(rel < 1e-3, "{solver}: {text}");

        let depth_file = out.path(&format!("{tag}-depth.npy"));
        let scene_file = out.path(&format!("{tag}-scene.npy"));
        let h = read_header(&depth_file).unwrap();
        assert_eq!((h.dtype, h.shape), (NpyDtype::Int32, vec![m, n]));
        let h = read_header(&scene_file).unwrap();
        assert_eq!((h.dtype, h.shape), (NpyDtype::Float64, vec![m, n, ks]));
        let depth: Array2<i32> = read_npy(&depth_file).unwrap();
        assert_eq!(depth, true_depth, "{solver}");
        let scene: Array3<f64> = read_npy(&scene_file).unwrap();
        assert_eq!(
            depth_of(&scene),
            depth,
            "{solver}: the scene and the depth map disagree"
        );
        let diff = (&scene - &truth).mapv(|v| v * v).sum().sqrt();
        let norm = truth.mapv(|v| v * v).sum().sqrt();
        assert!(
            diff / norm < 1e-3,
            "{solver}: relative error {}",
            diff / norm
        );
        assert!((diff / norm - rel).abs() < 1e-4, "{solver}: printed {rel}");

        // The PNG shows the truth and the estimate side by side: wider than high.
        let (w, h) = png_size(&png);
        assert!(w > h && h > 50, "{solver}: {w}x{h}");
    }

    // Debiased backprojection: every detection at its true depth, no false one; it may miss
    // weak pixels under its robust threshold.
    let text = reconstruct(
        &sim,
        &out,
        "bp",
        "backprojection-debiased",
        &["--threshold", "robust"],
    );
    let (exact, rmse, missed, false_, rel) = metrics(&text);
    assert_eq!((rmse, false_), (0.0, 0), "{text}");
    assert!(exact >= 70.0 && missed <= lit / 4, "{text}");
    assert!((0.0..1.0).contains(&rel), "{text}");
    let depth: Array2<i32> = read_npy(out.path("bp-depth.npy")).unwrap();
    for (d, t) in depth.iter().zip(&true_depth) {
        assert!(*d == -1 || d == t, "detected at {d}, true {t}");
    }

    // f32: a float32 scene with the same depth map.
    let text = reconstruct(&sim, &out, "f32", "model-based", &["--precision", "f32"]);
    assert!(text.contains("scene float32"), "{text}");
    let h = read_header(out.path("f32-scene.npy")).unwrap();
    assert_eq!((h.dtype, h.shape), (NpyDtype::Float32, vec![m, n, ks]));
    let depth: Array2<i32> = read_npy(out.path("f32-depth.npy")).unwrap();
    assert_eq!(depth, true_depth);

    // Exactly the files asked for, no temporary file left.
    let mut expected: Vec<String> = ["cgls", "mb", "bp", "f32"]
        .iter()
        .flat_map(|t| [format!("{t}-depth.npy"), format!("{t}-scene.npy")])
        .chain(["cgls.png".to_string(), "mb.png".to_string()])
        .collect();
    expected.sort();
    assert_eq!(out.listing(), expected);
}
