//! `rdlidar reconstruct`, run as a user would: every solver on a tiny simulated problem, the
//! output files, exact recovery checked against the truth, and errors that leave no file behind.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};

use ndarray::{Array2, Array3, Axis};
use ndarray_npy::read_npy;

fn rdlidar(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A fresh directory under the system temporary directory, removed when dropped.
struct TempDir(PathBuf);

static DIRS: AtomicUsize = AtomicUsize::new(0);

impl TempDir {
    fn new(tag: &str) -> Self {
        let n = DIRS.fetch_add(1, Ordering::Relaxed);
        let p = std::env::temp_dir().join(format!(
            "rdlidar-cli-reconstruct-{}-{tag}-{n}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn s(p: &Path) -> &str {
    p.to_str().expect("temporary paths are UTF-8")
}

/// Simulates the noise-free 8x8x8 paper scene with a pulse of `kp` into DIR/sim.
fn simulate(dir: &TempDir, kp: usize) -> PathBuf {
    let sim = dir.path("sim");
    let kp = kp.to_string();
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "8x8x8",
        "--pulse-len",
        &kp,
        "--seed",
        "0",
        "--out",
        s(&sim),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    sim
}

/// `reconstruct` on the files of `sim` with depth and scene written into `dir`.
fn reconstruct(dir: &TempDir, sim: &Path, solver: &str, extra: &[&str]) -> Output {
    let (pulse, codes, meas) = (
        sim.join("pulse.npy"),
        sim.join("codes.npy"),
        sim.join("meas.npy"),
    );
    let (depth, scene) = (dir.path("depth.npy"), dir.path("xh.npy"));
    let mut args = vec![
        "reconstruct",
        "--pulse",
        s(&pulse),
        "--codes",
        s(&codes),
        "--meas",
        s(&meas),
        "--depth-bins",
        "8",
        "--solver",
        solver,
        "--out-depth",
        s(&depth),
        "--out-scene",
        s(&scene),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    rdlidar(&args)
}

/// The names of the files in `dir` (not the simulation directory), sorted.
fn outputs(dir: &TempDir) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(&dir.0)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "sim")
        .collect();
    v.sort();
    v
}

/// Each pixel's strongest return in a scene file, −1 for none.
fn true_depth(scene: &Path) -> Array2<i32> {
    let x: Array3<f64> = read_npy(scene).unwrap();
    let (m, n, _) = x.dim();
    let mut d = Array2::from_elem((m, n), -1);
    for (p, col) in x.lanes(Axis(2)).into_iter().enumerate() {
        let best = col
            .iter()
            .enumerate()
            .filter(|(_, v)| **v != 0.0)
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()));
        if let Some((j, _)) = best {
            d[[p / n, p % n]] = j as i32;
        }
    }
    d
}

#[test]
fn every_solver_writes_a_depth_map_and_a_scene() {
    let dir = TempDir::new("all");
    let sim = simulate(&dir, 2000);
    for solver in [
        "backprojection",
        "backprojection-debiased",
        "cgls",
        "fista",
        "iht",
        "cosamp",
        "model-based",
        "tv",
        "auto",
    ] {
        let out = reconstruct(&dir, &sim, solver, &["--max-iter", "40"]);
        assert!(out.status.success(), "{solver}: {}", stderr(&out));
        let text = stdout(&out);
        assert!(text.contains("solver "), "{text}");
        assert!(text.contains(" s;"), "{text}");
        let depth: Array2<i32> = read_npy(dir.path("depth.npy")).unwrap();
        assert_eq!(depth.dim(), (8, 8), "{solver}");
        assert!(depth.iter().all(|&d| (-1..8).contains(&d)), "{solver}");
        let scene: Array3<f64> = read_npy(dir.path("xh.npy")).unwrap();
        assert_eq!(scene.dim(), (8, 8, 8), "{solver}");
        for ((p, col), d) in scene
            .lanes(Axis(2))
            .into_iter()
            .enumerate()
            .zip(depth.iter())
        {
            let nz: Vec<usize> = (0..8).filter(|&j| col[j] != 0.0).collect();
            match *d {
                -1 => assert!(nz.is_empty(), "{solver}: pixel {p}"),
                d => assert_eq!(nz, vec![d as usize], "{solver}: pixel {p}"),
            }
        }
        assert_eq!(outputs(&dir), ["depth.npy", "xh.npy"], "{solver}");
    }
}

#[test]
fn f32_precision_writes_a_float32_scene() {
    let dir = TempDir::new("f32");
    let sim = simulate(&dir, 2000);
    let out = reconstruct(&dir, &sim, "model-based", &["--precision", "f32"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let scene: Array3<f32> = read_npy(dir.path("xh.npy")).unwrap();
    assert_eq!(scene.dim(), (8, 8, 8));
    assert!(stdout(&out).contains("float32"), "{}", stdout(&out));
}

#[test]
fn model_based_and_auto_recover_the_tiny_scene_exactly() {
    // Redundant (K_p 2000) for model-based; compressive (K_p 300 < 505) for auto, which then
    // runs the model-based solver.
    for (kp, solver) in [(2000, "model-based"), (300, "auto")] {
        let dir = TempDir::new("exact");
        let sim = simulate(&dir, kp);
        let truth = sim.join("scene.npy");
        let png = dir.path("depth.png");
        let out = reconstruct(
            &dir,
            &sim,
            solver,
            &["--truth", s(&truth), "--png", s(&png)],
        );
        assert!(out.status.success(), "{}", stderr(&out));
        let text = stdout(&out);
        assert!(text.contains("exact depth 100.0%"), "{text}");
        assert!(text.contains("false 0 "), "{text}");
        if solver == "auto" {
            assert!(text.contains("compressive regime"), "{text}");
        }
        let depth: Array2<i32> = read_npy(dir.path("depth.npy")).unwrap();
        assert_eq!(depth, true_depth(&truth));
        let bytes = std::fs::read(&png).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        assert_eq!(outputs(&dir), ["depth.npy", "depth.png", "xh.npy"]);
    }
}

#[test]
fn an_unknown_solver_is_a_usage_error_listing_the_valid_names() {
    let dir = TempDir::new("unknown");
    let sim = simulate(&dir, 200);
    let out = reconstruct(&dir, &sim, "lasso", &[]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("lasso"), "{err}");
    for name in [
        "backprojection",
        "cgls",
        "fista",
        "cosamp",
        "model-based",
        "tv",
        "auto",
    ] {
        assert!(err.contains(name), "{name} missing from {err}");
    }
    assert!(outputs(&dir).is_empty());
}

#[test]
fn returns_per_pixel_takes_a_count_or_auto_and_refuses_anything_else() {
    let dir = TempDir::new("returns");
    let sim = simulate(&dir, 2000);
    let truth = sim.join("scene.npy");
    for k in ["2", "auto"] {
        let out = reconstruct(
            &dir,
            &sim,
            "model-based",
            &["--returns", k, "--truth", s(&truth)],
        );
        assert!(out.status.success(), "--returns {k}: {}", stderr(&out));
        assert!(
            stdout(&out).contains("exact depth 100.0%"),
            "{}",
            stdout(&out)
        );
    }
    for bad in ["0", "9", "two"] {
        let dir = TempDir::new("returns-bad");
        let out = reconstruct(&dir, &sim, "model-based", &["--returns", bad]);
        assert_eq!(out.status.code(), Some(2), "--returns {bad}");
        let err = stderr(&out);
        assert!(
            err.contains("--returns") && err.contains("from 1 to 8 or auto"),
            "{err}"
        );
        assert!(outputs(&dir).is_empty());
    }
}

#[test]
fn a_missing_file_is_named_and_nothing_is_written() {
    let dir = TempDir::new("missing");
    let sim = simulate(&dir, 200);
    std::fs::remove_file(sim.join("codes.npy")).unwrap();
    let out = reconstruct(&dir, &sim, "auto", &[]);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.starts_with("error: "), "{err}");
    assert!(err.contains("codes.npy"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(outputs(&dir).is_empty());
}

#[test]
fn mismatched_depth_bins_are_refused_and_nothing_is_written() {
    let dir = TempDir::new("bins");
    let sim = simulate(&dir, 200);
    let (pulse, codes, meas) = (
        sim.join("pulse.npy"),
        sim.join("codes.npy"),
        sim.join("meas.npy"),
    );
    let (depth, scene, png) = (dir.path("d.npy"), dir.path("x.npy"), dir.path("d.png"));
    let out = rdlidar(&[
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
        "model-based",
        "--out-depth",
        s(&depth),
        "--out-scene",
        s(&scene),
        "--png",
        s(&png),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("meas.npy"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(outputs(&dir).is_empty());
}

#[test]
fn a_truth_of_another_shape_is_refused_and_nothing_is_written() {
    let dir = TempDir::new("truth");
    let sim = simulate(&dir, 200);
    let other = TempDir::new("truth-other");
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x4x8",
        "--pulse-len",
        "50",
        "--out",
        s(&other.0),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let truth = other.path("scene.npy");
    let out = reconstruct(&dir, &sim, "backprojection", &["--truth", s(&truth)]);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("scene.npy") && err.contains("8x8x8"), "{err}");
    assert!(outputs(&dir).is_empty());
}

#[test]
fn the_same_file_for_two_outputs_is_refused() {
    let dir = TempDir::new("same");
    let sim = simulate(&dir, 200);
    let depth = dir.path("depth.npy");
    let out = reconstruct(&dir, &sim, "backprojection", &["--png", s(&depth)]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("--png"), "{}", stderr(&out));
    assert!(outputs(&dir).is_empty());
}

/// Each of `values` given to `flag` is a usage error (status 2) naming the flag.
fn refused_values(dir: &TempDir, sim: &Path, flag: &str, values: &[&str]) {
    for bad in values {
        let arg = format!("{flag}={bad}");
        let out = reconstruct(dir, sim, "auto", &[&arg]);
        assert_eq!(out.status.code(), Some(2), "{arg}: {}", stderr(&out));
        assert!(stderr(&out).contains(flag), "{arg}: {}", stderr(&out));
    }
}

#[test]
fn clipped_samples_are_censored_and_bad_levels_refused() {
    // The noise-free scene at K_p 300 (compressive): censoring each ADC's largest sample or
    // every sample beyond a level leaves enough to recover it exactly.
    let dir = TempDir::new("clipped");
    let sim = simulate(&dir, 300);
    let truth = sim.join("scene.npy");
    let meas: ndarray::Array1<f64> = read_npy(sim.join("meas.npy")).unwrap();
    let top = meas.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let level = format!("{}", 0.9 * top);
    let beyond = meas.iter().filter(|v| v.abs() >= 0.9 * top).count();
    let (hi, lo) = meas
        .iter()
        .fold((0.0f64, 0.0f64), |(h, l), &v| (h.max(v), l.min(v)));
    let extremes = meas.iter().filter(|&&v| v == hi || v == lo).count();
    for (clipped, count) in [("top", extremes), (level.as_str(), beyond)] {
        let out = reconstruct(
            &dir,
            &sim,
            "auto",
            &["--truth", s(&truth), "--clipped", clipped],
        );
        assert!(out.status.success(), "{}", stderr(&out));
        let text = stdout(&out);
        let k = meas.len();
        assert!(
            text.contains(&format!("censored {count} of {k} samples")),
            "{text}"
        );
        assert!(text.contains("exact depth 100.0%"), "{text}");
    }
    // Noise-free samples: no hint of clipping. An ADC that clips at 30% of the largest sample:
    // the hint without --clipped.
    let out = reconstruct(&dir, &sim, "auto", &[]);
    assert!(!stdout(&out).contains("sit at"), "{}", stdout(&out));
    let clipped = dir.path("clipped");
    let full_scale = format!("{}", 0.3 * top);
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "8x8x8",
        "--pulse-len",
        "300",
        "--seed",
        "0",
        "--adc-bits",
        "8",
        "--full-scale",
        &full_scale,
        "--out",
        s(&clipped),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = reconstruct(&dir, &clipped, "auto", &[]);
    let text = stdout(&out);
    assert!(
        text.contains("sit at their ADC's largest or smallest y"),
        "{text}"
    );
    assert!(text.contains("--clipped top"), "{text}");
    std::fs::remove_dir_all(&clipped).unwrap();
    // Bad levels are usage errors naming the flag; a level at or below every sample leaves
    // nothing to fit. No output is written.
    let _ = std::fs::remove_file(dir.path("depth.npy"));
    let _ = std::fs::remove_file(dir.path("xh.npy"));
    refused_values(&dir, &sim, "--clipped", &["abc", "0", "-1", "nan", "inf"]);
    let out = reconstruct(&dir, &sim, "auto", &["--clipped", "1e-300"]);
    let err = stderr(&out);
    assert!(!out.status.success());
    assert!(
        err.contains("--clipped") && err.contains("nothing would be left"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(outputs(&dir).is_empty());
}

#[test]
fn a_false_rate_runs_the_detection_test_and_bad_rates_are_refused() {
    let dir = TempDir::new("false-rate");
    let sim = simulate(&dir, 300);
    let truth = sim.join("scene.npy");
    let out = reconstruct(
        &dir,
        &sim,
        "auto",
        &["--truth", s(&truth), "--false-rate", "0.01"],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("false-detection test at α = 0.01"), "{text}");
    assert!(text.contains("dropped 0 of"), "{text}");
    assert!(text.contains("exact depth 100.0%"), "{text}");
    let _ = std::fs::remove_file(dir.path("depth.npy"));
    let _ = std::fs::remove_file(dir.path("xh.npy"));
    refused_values(
        &dir,
        &sim,
        "--false-rate",
        &["0", "1", "-0.1", "abc", "nan", "inf"],
    );
    assert!(outputs(&dir).is_empty());
}

#[test]
fn the_photon_noise_model_reports_its_weighting_and_bad_models_are_refused() {
    // Noise-free: the estimate explains the data, so nothing is reweighted and the line says so.
    let dir = TempDir::new("photon");
    let sim = simulate(&dir, 300);
    let truth = sim.join("scene.npy");
    let out = reconstruct(
        &dir,
        &sim,
        "auto",
        &[
            "--truth",
            s(&truth),
            "--noise",
            "photon",
            "--background",
            "0.5",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("photon-noise weighting"), "{text}");
    assert!(text.contains("not reweighted"), "{text}");
    assert!(text.contains("exact depth 100.0%"), "{text}");
    let _ = std::fs::remove_file(dir.path("depth.npy"));
    let _ = std::fs::remove_file(dir.path("xh.npy"));
    refused_values(&dir, &sim, "--noise", &["poisson", "", "1"]);
    refused_values(&dir, &sim, "--background", &["-1", "nan", "inf", "abc"]);
    // A background without the photon model is a mistake, not ignored.
    let out = reconstruct(&dir, &sim, "auto", &["--background", "1"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("--background"), "{}", stderr(&out));
    assert!(outputs(&dir).is_empty());
}

/// `auto` on valid data whose least-squares refits converge to what the arithmetic resolves
/// (a search direction of zero curvature): the refit ends there, and auto goes on, where it
/// once failed with "numerical breakdown". The two cases the failure was seen on.
#[test]
fn auto_ends_a_refit_at_zero_curvature_instead_of_failing() {
    let dir = TempDir::new("zero-curvature");
    for (size, kp, seed, snr) in [
        ("16x16x8", "150", "2", None),
        ("8x8x6", "60", "19", Some("20")),
    ] {
        let sim = dir.0.join(format!("sim-{size}-{seed}"));
        let mut args = vec![
            "simulate",
            "--scene",
            "paper",
            "--quiet",
            "--size",
            size,
            "--pulse-len",
            kp,
            "--seed",
            seed,
            "--out",
            s(&sim),
        ];
        if let Some(db) = snr {
            args.extend(["--snr-db", db]);
        }
        let out = rdlidar(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        let ks = size.rsplit('x').next().unwrap();
        let depth = dir.0.join(format!("depth-{size}-{seed}.npy"));
        let out = rdlidar(&[
            "reconstruct",
            "--quiet",
            "--pulse",
            s(&sim.join("pulse.npy")),
            "--codes",
            s(&sim.join("codes.npy")),
            "--meas",
            s(&sim.join("meas.npy")),
            "--depth-bins",
            ks,
            "--solver",
            "auto",
            "--out-depth",
            s(&depth),
            "--out-scene",
            s(&dir.0.join(format!("xh-{size}-{seed}.npy"))),
        ]);
        assert!(out.status.success(), "{size} seed {seed}: {}", stderr(&out));
        let d: Array2<i32> = read_npy(&depth).unwrap();
        assert!(d.iter().any(|&v| v >= 0), "{size} seed {seed}: no return");
    }
}
