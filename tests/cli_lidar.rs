//! The lidar subcommands (`simulate`, `forward`, `adjoint`, `dottest`, `bench`) and their file
//! checks, run as a user would.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};

use ndarray::{Array1, Array3};
use ndarray_npy::{read_npy, write_npy};

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
            "rdlidar-cli-lidar-{}-{tag}-{n}",
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

/// Simulates the 4x5x6 paper problem with a pulse of 50 into `dir`, noise-free.
fn simulate_small(dir: &Path, extra: &[&str]) {
    let mut args = vec![
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x5x6",
        "--pulse-len",
        "50",
        "--seed",
        "7",
        "--out",
        s(dir),
    ];
    args.extend_from_slice(extra);
    let out = rdlidar(&args);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// The names in a directory, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn max_rel_diff(a: &Array1<f64>, b: &Array1<f64>) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

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
fn forward_on_the_simulated_files_reproduces_the_measurements() {
    let tmp = TempDir::new("forward");
    let dir = tmp.path("run");
    simulate_small(&dir, &[]);
    let meas: Array1<f64> = read_npy(dir.join("meas.npy")).unwrap();
    for precision in [None, Some("f32"), Some("f64")] {
        let y = tmp.path("y.npy");
        let mut args = vec![
            "forward",
            "--pulse",
            s(&dir.join("pulse.npy")),
            "--codes",
            s(&dir.join("codes.npy")),
            "--scene",
            s(&dir.join("scene.npy")),
            "--out",
            s(&y),
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
        if let Some(p) = precision {
            args.extend(["--precision".to_string(), p.to_string()]);
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = rdlidar(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        let got: Array1<f64> = if precision == Some("f32") {
            read_npy::<_, Array1<f32>>(&y).unwrap().mapv(f64::from)
        } else {
            read_npy(&y).unwrap()
        };
        assert_eq!(got.len(), 55);
        let rel = max_rel_diff(&got, &meas);
        assert!(rel <= 1e-5, "{precision:?}: relative difference {rel}");
        std::fs::remove_file(&y).unwrap();
    }
}

#[test]
fn forward_reads_fortran_order_and_float32_inputs() {
    let tmp = TempDir::new("fortran");
    let dir = tmp.path("run");
    simulate_small(&dir, &[]);
    let scene: Array3<f64> = read_npy(dir.join("scene.npy")).unwrap();
    // Same values, column-major in memory: written with fortran_order = True.
    let mut fortran = Array3::<f32>::zeros((6, 5, 4)).reversed_axes();
    fortran.assign(&scene.mapv(|v| v as f32));
    assert!(!fortran.is_standard_layout());
    let fscene = tmp.path("scene_f.npy");
    write_npy(&fscene, &fortran).unwrap();
    let head = std::fs::read(&fscene).unwrap();
    assert!(String::from_utf8_lossy(&head[..128]).contains("'fortran_order': True"));

    let y = tmp.path("y.npy");
    let out = rdlidar(&[
        "forward",
        "--pulse",
        s(&dir.join("pulse.npy")),
        "--codes",
        s(&dir.join("codes.npy")),
        "--scene",
        s(&fscene),
        "--out",
        s(&y),
        "--precision",
        "f64",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let got: Array1<f64> = read_npy(&y).unwrap();
    let meas: Array1<f64> = read_npy(dir.join("meas.npy")).unwrap();
    assert!(max_rel_diff(&got, &meas) <= 1e-6);
}

#[test]
fn adjoint_writes_a_scene_shaped_backprojection() {
    let tmp = TempDir::new("adjoint");
    let dir = tmp.path("run");
    simulate_small(&dir, &[]);
    let (pulse, codes, meas) = (
        dir.join("pulse.npy"),
        dir.join("codes.npy"),
        dir.join("meas.npy"),
    );
    for debiased in [false, true] {
        let xt = tmp.path(if debiased { "xd.npy" } else { "xt.npy" });
        let mut args = vec![
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
            s(&xt),
        ];
        if debiased {
            args.push("--debiased");
        }
        let out = rdlidar(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        let x: Array3<f64> = read_npy(&xt).unwrap();
        assert_eq!(x.dim(), (4, 5, 6));
        assert!(x.iter().all(|v| v.is_finite()) && x.iter().any(|&v| v != 0.0));
    }
}

#[test]
fn dottest_passes_on_simulated_codes() {
    let tmp = TempDir::new("dottest");
    let dir = tmp.path("run");
    simulate_small(&dir, &["--ternary-zero-prob", "0.25"]);
    let out = rdlidar(&[
        "dottest",
        "--pulse",
        s(&dir.join("pulse.npy")),
        "--codes",
        s(&dir.join("codes.npy")),
        "--depth-bins",
        "6",
        "--seed",
        "3",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("f32") && text.contains("f64"), "{text}");
    assert!(!text.contains("FAILED"), "{text}");
    assert_eq!(
        text.lines().filter(|l| l.ends_with("ok")).count(),
        4,
        "{text}"
    );
}

#[test]
fn bench_json_has_the_three_timings() {
    let out = rdlidar(&[
        "bench",
        "--size",
        "4x5x6",
        "--pulse-len",
        "50",
        "--repeats",
        "3",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    for key in ["forward", "adjoint", "sparse_forward"] {
        for stat in ["median_s", "min_s"] {
            let t = v[key][stat].as_f64().unwrap_or(-1.0);
            assert!(t >= 0.0, "{key}.{stat} in {v}");
        }
        assert!(v[key]["min_s"].as_f64() <= v[key]["median_s"].as_f64());
    }
    assert!(v["memory_bytes"].as_u64().unwrap() > 0);
}

#[test]
fn bench_text_reports_memory_isa_and_threads() {
    let out = rdlidar(&[
        "--threads",
        "1",
        "bench",
        "--size",
        "4x5x6",
        "--pulse-len",
        "50",
        "--repeats",
        "1",
        "--precision",
        "f64",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    for needle in [
        "threads 1",
        "memory",
        "forward",
        "adjoint",
        "sparse forward",
    ] {
        assert!(text.contains(needle), "{needle} missing from\n{text}");
    }
}

/// A problem on disk plus a place for an output that must never appear.
struct Fixture {
    tmp: TempDir,
    dir: PathBuf,
    out: PathBuf,
}

impl Fixture {
    fn new(tag: &str) -> Self {
        let tmp = TempDir::new(tag);
        let dir = tmp.path("run");
        simulate_small(&dir, &[]);
        let out = tmp.path("out.npy");
        Fixture { tmp, dir, out }
    }

    fn file(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// A new file in the fixture's directory.
    fn new_file(&self, name: &str) -> PathBuf {
        self.tmp.path(name)
    }

    /// Runs `forward` with the given replacements of the simulated inputs.
    fn forward(&self, pulse: Option<&Path>, codes: Option<&Path>, scene: Option<&Path>) -> Output {
        let p = pulse.map_or(self.file("pulse.npy"), Path::to_path_buf);
        let c = codes.map_or(self.file("codes.npy"), Path::to_path_buf);
        let x = scene.map_or(self.file("scene.npy"), Path::to_path_buf);
        rdlidar(&[
            "forward",
            "--pulse",
            s(&p),
            "--codes",
            s(&c),
            "--scene",
            s(&x),
            "--out",
            s(&self.out),
        ])
    }

    /// Runs `adjoint` with the given replacements of the simulated inputs.
    fn adjoint(&self, codes: Option<&Path>, meas: Option<&Path>, depth_bins: &str) -> Output {
        let c = codes.map_or(self.file("codes.npy"), Path::to_path_buf);
        let y = meas.map_or(self.file("meas.npy"), Path::to_path_buf);
        rdlidar(&[
            "adjoint",
            "--pulse",
            s(&self.file("pulse.npy")),
            "--codes",
            s(&c),
            "--meas",
            s(&y),
            "--depth-bins",
            depth_bins,
            "--out",
            s(&self.out),
        ])
    }

    /// The run failed with status 1 and one `error:` line naming `file` and containing each of
    /// `problem`, and left no output behind.
    fn assert_rejected(&self, out: &Output, file: &Path, problem: &[&str]) {
        let err = stderr(out);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.starts_with("error: "), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(
            err.contains(s(file)),
            "the message does not name {}: {err}",
            file.display()
        );
        for p in problem {
            assert!(err.contains(p), "{p:?} missing from {err}");
        }
        assert!(!self.out.exists(), "{} was written", self.out.display());
        let leftovers: Vec<String> = listing(&self.tmp.0)
            .into_iter()
            .filter(|n| n.contains(".tmp-"))
            .collect();
        assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
    }
}

#[test]
fn rejects_a_scene_of_the_wrong_dtype() {
    let f = Fixture::new("dtype");
    let bad = f.new_file("scene_i32.npy");
    write_npy(&bad, &Array3::<i32>::zeros((4, 5, 6))).unwrap();
    let out = f.forward(None, None, Some(&bad));
    f.assert_rejected(&out, &bad, &["dtype int32", "float32 or float64"]);
}

#[test]
fn rejects_codes_whose_length_is_not_kp_plus_ks_minus_one() {
    let f = Fixture::new("codes-len");
    let bad = f.new_file("codes_short.npy");
    write_npy(&bad, &Array3::<i8>::ones((4, 5, 54))).unwrap();
    let out = f.forward(None, Some(&bad), None);
    f.assert_rejected(&out, &bad, &["K = K_p + K_s − 1", "55", "found 54"]);
    let out = f.adjoint(Some(&bad), None, "6");
    f.assert_rejected(&out, &bad, &["K = K_p + K_s − 1", "55", "found 54"]);
}

#[test]
fn rejects_codes_for_another_grid() {
    let f = Fixture::new("codes-grid");
    let bad = f.new_file("codes_grid.npy");
    write_npy(&bad, &Array3::<i8>::ones((5, 4, 55))).unwrap();
    let out = f.forward(None, Some(&bad), None);
    f.assert_rejected(&out, &bad, &["5x4 pixels", "4x5"]);
}

#[test]
fn rejects_measurements_of_the_wrong_length() {
    let f = Fixture::new("meas-len");
    let out = f.adjoint(None, None, "7");
    f.assert_rejected(&out, &f.file("meas.npy"), &["56", "55 samples"]);
}

#[test]
fn rejects_nan_in_the_scene_naming_its_index() {
    let f = Fixture::new("nan");
    let mut x: Array3<f64> = read_npy(f.file("scene.npy")).unwrap();
    x[[1, 2, 3]] = f64::NAN;
    let bad = f.new_file("scene_nan.npy");
    write_npy(&bad, &x).unwrap();
    let out = f.forward(None, None, Some(&bad));
    f.assert_rejected(&out, &bad, &["NaN", "(1, 2, 3)"]);
}

#[test]
fn rejects_inf_in_the_pulse_naming_its_index() {
    let f = Fixture::new("inf");
    let mut p: Array1<f64> = read_npy(f.file("pulse.npy")).unwrap();
    p[7] = f64::INFINITY;
    let bad = f.new_file("pulse_inf.npy");
    write_npy(&bad, &p).unwrap();
    let out = f.forward(Some(&bad), None, None);
    f.assert_rejected(&out, &bad, &["infinite", "index 7"]);
}

#[test]
fn rejects_a_negative_pulse_value() {
    let f = Fixture::new("negative");
    let mut p: Array1<f32> = read_npy::<_, Array1<f64>>(f.file("pulse.npy"))
        .unwrap()
        .mapv(|v| v as f32);
    p[3] = -0.5;
    let bad = f.new_file("pulse_neg.npy");
    write_npy(&bad, &p).unwrap();
    let out = f.forward(Some(&bad), None, None);
    f.assert_rejected(&out, &bad, &["negative", "index 3"]);
}

#[test]
fn rejects_an_all_zero_pulse() {
    let f = Fixture::new("zero-pulse");
    let bad = f.new_file("pulse_zero.npy");
    write_npy(&bad, &Array1::<f64>::zeros(50)).unwrap();
    let out = f.forward(Some(&bad), None, None);
    f.assert_rejected(&out, &bad, &["all zero"]);
}

#[test]
fn rejects_a_code_value_outside_minus_one_zero_one() {
    let f = Fixture::new("code-2");
    let mut c: Array3<i8> = read_npy(f.file("codes.npy")).unwrap();
    c[[0, 1, 3]] = 2;
    let bad = f.new_file("codes_2.npy");
    write_npy(&bad, &c).unwrap();
    let out = f.forward(None, Some(&bad), None);
    f.assert_rejected(&out, &bad, &["value 2", "(0, 1, 3)", "{-1, 0, 1}"]);
    // Float codes are held to the same values.
    let mut cf = c.mapv(f32::from);
    cf[[0, 1, 3]] = 0.5;
    let badf = f.new_file("codes_half.npy");
    write_npy(&badf, &cf).unwrap();
    let out = f.forward(None, Some(&badf), None);
    f.assert_rejected(&out, &badf, &["value 0.5", "(0, 1, 3)"]);
}

#[test]
fn rejects_a_truncated_npy_file() {
    let f = Fixture::new("truncated");
    let bytes = std::fs::read(f.file("scene.npy")).unwrap();
    let bad = f.new_file("scene_cut.npy");
    std::fs::write(&bad, &bytes[..bytes.len() - 20]).unwrap();
    let out = f.forward(None, None, Some(&bad));
    f.assert_rejected(&out, &bad, &["truncated"]);
    // Cut inside the header.
    std::fs::write(&bad, &bytes[..40]).unwrap();
    let out = f.forward(None, None, Some(&bad));
    f.assert_rejected(&out, &bad, &["truncated", "header"]);
}

#[test]
fn rejects_a_text_file_named_npy() {
    let f = Fixture::new("text");
    let bad = f.new_file("scene.txt.npy");
    std::fs::write(&bad, "0.1 0.2 0.3\n0.4 0.5 0.6\n").unwrap();
    let out = f.forward(None, None, Some(&bad));
    f.assert_rejected(&out, &bad, &["not a .npy file"]);
}

#[test]
fn rejects_a_missing_file() {
    let f = Fixture::new("missing");
    let bad = f.new_file("no_such_codes.npy");
    let out = f.forward(None, Some(&bad), None);
    f.assert_rejected(&out, &bad, &["no such file"]);
}

#[test]
fn rejects_an_output_in_a_missing_directory_before_any_work() {
    let f = Fixture::new("out-dir");
    let out_path = f.new_file("missing-dir").join("y.npy");
    let out = rdlidar(&[
        "forward",
        "--pulse",
        s(&f.file("pulse.npy")),
        "--codes",
        s(&f.file("codes.npy")),
        "--scene",
        s(&f.file("scene.npy")),
        "--out",
        s(&out_path),
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains(s(&out_path)), "{}", stderr(&out));
    assert!(!out_path.exists());
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
fn usage_errors_exit_with_status_two_and_name_the_flag() {
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x5",
        "--pulse-len",
        "50",
        "--out",
        "x",
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--size"));
    let out = rdlidar(&["bench", "--repeats", "0"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--repeats"));
    for sub in ["simulate", "forward", "adjoint", "dottest", "bench"] {
        let out = rdlidar(&[sub, "--help"]);
        assert!(out.status.success());
        assert!(stdout(&out).contains("Example"), "{sub} --help");
    }
}

#[test]
fn io_codes_and_depth_round_trip_through_npy() {
    use rdlidar::io::{read_codes, read_depth, write_codes, write_depth, ShapeExpectation};
    use rdlidar::lidar::Codes;
    let tmp = TempDir::new("io-roundtrip");
    let expect = ShapeExpectation {
        pulse_len: 9,
        depth_bins: 4,
        grid: Some((3, 5)),
    };
    for codes in [
        Codes::random_binary(15, 12, 1).unwrap(),
        Codes::random_ternary(15, 12, 0.4, 2).unwrap(),
    ] {
        let p = tmp.path("codes.npy");
        write_codes(&p, (3, 5), &codes).unwrap();
        let dense: Array3<i8> = read_npy(&p).unwrap();
        assert_eq!(dense.dim(), (3, 5, 12));
        let ((m, n), back) = read_codes(&p, &expect).unwrap();
        assert_eq!((m, n), (3, 5));
        assert_eq!(back.to_dense(), codes.to_dense());
    }
    let depth = ndarray::array![[0i32, -1, 3], [2, 1, -1]];
    let p = tmp.path("depth.npy");
    write_depth(&p, &depth).unwrap();
    assert_eq!(read_depth(&p, Some(4)).unwrap(), depth);
    let err = read_depth(&p, Some(3)).unwrap_err().to_string();
    assert!(
        err.contains(s(&p)) && err.contains("depth bin 3 at index (0, 2)"),
        "{err}"
    );
    let err = read_depth(tmp.path("codes.npy"), None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("dtype int8") && err.contains("int32"), "{err}");
}

#[test]
fn io_atomic_writes_leave_the_destination_whole() {
    use rdlidar::io::{write_atomic, StagedFile};
    let tmp = TempDir::new("io-atomic");
    let dest = tmp.path("data.bin");
    std::fs::write(&dest, b"old").unwrap();
    // A writer that fails part-way: the old contents survive, no temporary file remains.
    let err = write_atomic(&dest, |w| {
        use std::io::Write;
        w.write_all(b"partial").unwrap();
        Err(rdlidar::Error::File {
            path: "data.bin".into(),
            reason: "simulated failure".into(),
        })
    });
    assert!(err.is_err());
    assert_eq!(std::fs::read(&dest).unwrap(), b"old");
    assert_eq!(listing(&tmp.0), ["data.bin"]);
    // A staged file dropped without commit leaves nothing.
    {
        let mut f = StagedFile::create(tmp.path("other.bin")).unwrap();
        std::io::Write::write_all(f.writer(), b"abc").unwrap();
    }
    assert_eq!(listing(&tmp.0), ["data.bin"]);
    // A committed one replaces the destination.
    write_atomic(&dest, |w| {
        std::io::Write::write_all(w, b"new").map_err(|e| rdlidar::Error::File {
            path: "data.bin".into(),
            reason: e.to_string(),
        })
    })
    .unwrap();
    assert_eq!(std::fs::read(&dest).unwrap(), b"new");
    assert_eq!(listing(&tmp.0), ["data.bin"]);
}

// ---- Architecture variants: simulate --adcs / --tiles / --aperture and the readers of their
// files.

/// Simulates the 4x6x5 paper problem with a pulse of 40 and seed 11 into `dir`, noise-free, with
/// the extra flags `extra`; returns the standard output.
fn simulate_variant(dir: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x6x5",
        "--pulse-len",
        "40",
        "--seed",
        "11",
        "--out",
        s(dir),
    ];
    args.extend_from_slice(extra);
    let out = rdlidar(&args);
    assert!(out.status.success(), "{extra:?}: {}", stderr(&out));
    stdout(&out)
}

fn meta_of(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("meta.json")).unwrap()).unwrap()
}

/// Largest |a − b| over the largest |b|.
fn max_rel_diff_nd<D: ndarray::Dimension>(
    a: &ndarray::Array<f64, D>,
    b: &ndarray::Array<f64, D>,
) -> f64 {
    assert_eq!(a.shape(), b.shape());
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// Runs `forward` on the simulated files of `dir` (with `extra` flags) into `y` and returns the
/// process output.
fn forward_on(dir: &Path, y: &Path, extra: &[&str]) -> Output {
    let (p, c, x) = (
        dir.join("pulse.npy"),
        dir.join("codes.npy"),
        dir.join("scene.npy"),
    );
    let mut args = vec![
        "forward",
        "--pulse",
        s(&p),
        "--codes",
        s(&c),
        "--scene",
        s(&x),
        "--out",
        s(y),
    ];
    args.extend_from_slice(extra);
    rdlidar(&args)
}

/// Runs `adjoint` (K_s = 5) on the pulse and codes of `dir` and the measurements `meas`.
fn adjoint_on(dir: &Path, meas: &Path, out: &Path, extra: &[&str]) -> Output {
    let (p, c) = (dir.join("pulse.npy"), dir.join("codes.npy"));
    let mut args = vec![
        "adjoint",
        "--pulse",
        s(&p),
        "--codes",
        s(&c),
        "--meas",
        s(meas),
        "--depth-bins",
        "5",
        "--out",
        s(out),
    ];
    args.extend_from_slice(extra);
    rdlidar(&args)
}

/// Runs `dottest` (K_s = 5) on the files of `dir` and checks that the four gaps pass.
fn assert_dottest_passes(dir: &Path, extra: &[&str]) {
    let (p, c) = (dir.join("pulse.npy"), dir.join("codes.npy"));
    let mut args = vec![
        "dottest",
        "--pulse",
        s(&p),
        "--codes",
        s(&c),
        "--depth-bins",
        "5",
        "--seed",
        "2",
    ];
    args.extend_from_slice(extra);
    let out = rdlidar(&args);
    assert!(out.status.success(), "{extra:?}: {}", stderr(&out));
    let text = stdout(&out);
    assert!(!text.contains("FAILED"), "{text}");
    assert_eq!(
        text.lines().filter(|l| l.ends_with("ok")).count(),
        4,
        "{text}"
    );
}

/// The run failed with status 1 and one `error:` line naming `file` (if given) and containing
/// each of `needles`, and `out` was not written.
fn assert_one_line_error(out: &Output, file: Option<&Path>, needles: &[&str], not_written: &Path) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.starts_with("error: "), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    if let Some(f) = file {
        assert!(err.contains(s(f)), "{} not named: {err}", f.display());
    }
    for n in needles {
        assert!(err.contains(n), "{n:?} missing from {err}");
    }
    assert!(
        !not_written.exists(),
        "{} was written",
        not_written.display()
    );
}

#[test]
fn simulate_multi_adc_writes_g_code_sets_and_g_measurement_rows() {
    use ndarray::{s as sl, Array2, Array4};
    let tmp = TempDir::new("arch-multi");
    let (dir, single) = (tmp.path("multi"), tmp.path("single"));
    let text = simulate_variant(&dir, &["--adcs", "3"]);
    assert!(text.contains("codes.npy (3, 4, 6, 44) int8"), "{text}");
    simulate_variant(&single, &[]);
    assert_eq!(
        listing(&dir),
        [
            "codes.npy",
            "meas.npy",
            "meta.json",
            "pulse.npy",
            "scene.npy"
        ]
    );

    let codes: Array4<i8> = read_npy(dir.join("codes.npy")).unwrap();
    assert_eq!(codes.dim(), (3, 4, 6, 44));
    assert!(codes.iter().all(|&v| v == 1 || v == -1));
    // Set 0 is drawn from SEED+1, as the single-ADC codes; the other sets are independent.
    let single_codes: Array3<i8> = read_npy(single.join("codes.npy")).unwrap();
    assert_eq!(codes.slice(sl![0, .., .., ..]), single_codes);
    assert_ne!(
        codes.slice(sl![0, .., .., ..]),
        codes.slice(sl![1, .., .., ..])
    );
    assert_ne!(
        codes.slice(sl![1, .., .., ..]),
        codes.slice(sl![2, .., .., ..])
    );

    let meas: Array2<f64> = read_npy(dir.join("meas.npy")).unwrap();
    assert_eq!(meas.dim(), (3, 44));
    let single_meas: Array1<f64> = read_npy(single.join("meas.npy")).unwrap();
    assert!(max_rel_diff(&meas.row(0).to_owned(), &single_meas) <= 1e-12);
    assert!(max_rel_diff(&meas.row(1).to_owned(), &single_meas) > 1e-3);

    let meta = meta_of(&dir);
    assert_eq!(meta["architecture"]["kind"], "multi_adc");
    assert_eq!(meta["architecture"]["adcs"], 3);
    assert!(meta["architecture"]["tile"].is_null());
    assert_eq!(meta["architecture"]["active_pixels"], 24);
    assert_eq!(meta["seeds"]["codes"], 12);
    assert_eq!(
        meta["seeds"]["code_sets"],
        serde_json::json!([12, 1012, 2012])
    );
    assert_eq!(meta_of(&single)["architecture"]["kind"], "single");
    assert_eq!(meta_of(&single)["architecture"]["adcs"], 1);

    // forward on the (G, M, N, K) codes reproduces the (G, K) measurements.
    let y = tmp.path("y.npy");
    let out = forward_on(&dir, &y, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let got: Array2<f64> = read_npy(&y).unwrap();
    let rel = max_rel_diff_nd(&got, &meas);
    assert!(rel <= 1e-5, "relative difference {rel}");

    assert_dottest_passes(&dir, &[]);
    let xt = tmp.path("xt.npy");
    let out = adjoint_on(&dir, &dir.join("meas.npy"), &xt, &["--debiased"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let x: Array3<f64> = read_npy(&xt).unwrap();
    assert_eq!(x.dim(), (4, 6, 5));
    assert!(x.iter().all(|v| v.is_finite()) && x.iter().any(|&v| v != 0.0));
}

#[test]
fn simulate_with_one_adc_writes_exactly_the_single_adc_files() {
    let tmp = TempDir::new("arch-one");
    let (a, b) = (tmp.path("default"), tmp.path("adcs1"));
    simulate_variant(&a, &[]);
    simulate_variant(&b, &["--adcs", "1"]);
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
            "{f} differs"
        );
    }
    let codes: Array3<i8> = read_npy(b.join("codes.npy")).unwrap();
    assert_eq!(codes.dim(), (4, 6, 44));
    let meas: Array1<f64> = read_npy(b.join("meas.npy")).unwrap();
    assert_eq!(meas.len(), 44);
}

#[test]
fn simulate_tiles_writes_one_measurement_row_per_tile() {
    use ndarray::Array2;
    let tmp = TempDir::new("arch-tiles");
    let (dir, single) = (tmp.path("tiles"), tmp.path("single"));
    simulate_variant(&dir, &["--tiles", "2x4"]);
    simulate_variant(&single, &[]);

    // Each pixel keeps its usual code.
    let codes: Array3<i8> = read_npy(dir.join("codes.npy")).unwrap();
    assert_eq!(codes.dim(), (4, 6, 44));
    let single_codes: Array3<i8> = read_npy(single.join("codes.npy")).unwrap();
    assert_eq!(codes, single_codes);
    // 4x6 in tiles of 2x4: 2 x 2 tiles (the right ones 2x2).
    let meas: Array2<f64> = read_npy(dir.join("meas.npy")).unwrap();
    assert_eq!(meas.dim(), (4, 44));
    // The tiles partition the array: their ADCs sum to the single ADC.
    let single_meas: Array1<f64> = read_npy(single.join("meas.npy")).unwrap();
    let total = meas.sum_axis(ndarray::Axis(0));
    assert!(max_rel_diff(&total, &single_meas) <= 1e-12);

    let meta = meta_of(&dir);
    assert_eq!(meta["architecture"]["kind"], "tiles");
    assert_eq!(meta["architecture"]["tile"], serde_json::json!([2, 4]));
    assert_eq!(meta["architecture"]["adcs"], 4);
    assert_eq!(meta["architecture"]["active_pixels"], 24);

    let y = tmp.path("y.npy");
    let out = forward_on(&dir, &y, &["--tiles", "2x4"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let got: Array2<f64> = read_npy(&y).unwrap();
    let rel = max_rel_diff_nd(&got, &meas);
    assert!(rel <= 1e-5, "relative difference {rel}");
    std::fs::remove_file(&y).unwrap();

    assert_dottest_passes(&dir, &["--tiles", "2x4"]);
    let xt = tmp.path("xt.npy");
    let out = adjoint_on(&dir, &dir.join("meas.npy"), &xt, &["--tiles", "2x4"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let x: Array3<f64> = read_npy(&xt).unwrap();
    assert_eq!(x.dim(), (4, 6, 5));
    std::fs::remove_file(&xt).unwrap();

    // The (T, K) measurements need --tiles, and the right one.
    let meas_file = dir.join("meas.npy");
    let out = adjoint_on(&dir, &meas_file, &xt, &[]);
    assert_one_line_error(&out, Some(&meas_file), &["(4, 44)", "--tiles"], &xt);
    let out = adjoint_on(&dir, &meas_file, &xt, &["--tiles", "2x2"]);
    assert_one_line_error(
        &out,
        Some(&meas_file),
        &["--tiles 2x2", "6 tiles", "(6, 44)"],
        &xt,
    );
    // One ADC's measurements do not fit --tiles either.
    let single_file = single.join("meas.npy");
    let out = adjoint_on(&dir, &single_file, &xt, &["--tiles", "2x4"]);
    assert_one_line_error(&out, Some(&single_file), &["(44,)", "(4, 44)"], &xt);
    assert!(listing(&tmp.0).iter().all(|n| !n.contains(".tmp-")));
}

#[test]
fn simulate_aperture_zeroes_the_codes_of_inactive_pixels() {
    use ndarray::Axis;
    let tmp = TempDir::new("arch-aperture");
    let (dir, single) = (tmp.path("aperture"), tmp.path("single"));
    simulate_variant(&dir, &["--aperture", "0.5"]);
    simulate_variant(&single, &[]);

    let codes: Array3<i8> = read_npy(dir.join("codes.npy")).unwrap();
    assert_eq!(codes.dim(), (4, 6, 44));
    let single_codes: Array3<i8> = read_npy(single.join("codes.npy")).unwrap();
    let mut active = 0;
    for ((c, sc), i) in codes
        .lanes(Axis(2))
        .into_iter()
        .zip(single_codes.lanes(Axis(2)))
        .zip(0..)
    {
        if c.iter().all(|&v| v == 0) {
            continue;
        }
        active += 1;
        assert_eq!(c, sc, "active pixel {i} keeps its code");
    }
    assert_eq!(active, 12, "⌈0.5·24⌉ active pixels");

    let meas: Array1<f64> = read_npy(dir.join("meas.npy")).unwrap();
    assert_eq!(meas.len(), 44);
    let meta = meta_of(&dir);
    assert_eq!(meta["architecture"]["kind"], "aperture");
    assert_eq!(meta["architecture"]["adcs"], 1);
    assert_eq!(meta["architecture"]["active_pixels"], 12);
    assert_eq!(meta["architecture"]["aperture_fraction"], 0.5);
    assert_eq!(meta["seeds"]["aperture"], 15);

    // simulate measures through the coded-aperture operator; forward on the files uses the
    // single-ADC operator with zero codes. The two must agree.
    let y = tmp.path("y.npy");
    let out = forward_on(&dir, &y, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let got: Array1<f64> = read_npy(&y).unwrap();
    let rel = max_rel_diff(&got, &meas);
    assert!(rel <= 1e-5, "relative difference {rel}");
    assert_dottest_passes(&dir, &[]);

    // ⌈F·M·N⌉: 0.3·24 = 7.2 gives 8 pixels, 1 gives all; the same seed gives the same files.
    for (f, want) in [("0.3", 8), ("1", 24)] {
        let (d1, d2) = (tmp.path(&format!("a{f}")), tmp.path(&format!("b{f}")));
        simulate_variant(&d1, &["--aperture", f]);
        simulate_variant(&d2, &["--aperture", f]);
        assert_eq!(meta_of(&d1)["architecture"]["active_pixels"], want);
        let c: Array3<i8> = read_npy(d1.join("codes.npy")).unwrap();
        let lit = c
            .lanes(Axis(2))
            .into_iter()
            .filter(|l| l.iter().any(|&v| v != 0))
            .count();
        assert_eq!(lit, want, "--aperture {f}");
        assert_eq!(
            std::fs::read(d1.join("codes.npy")).unwrap(),
            std::fs::read(d2.join("codes.npy")).unwrap()
        );
    }
}

#[test]
fn simulate_rejects_invalid_architectures_and_leaves_nothing_behind() {
    let tmp = TempDir::new("arch-errors");
    let dir = tmp.path("run");
    for (extra, code, needles) in [
        (vec!["--adcs", "0"], 2, vec!["--adcs", "at least 1"]),
        (
            vec!["--tiles", "0x2"],
            2,
            vec!["--tiles", "positive", "0x2"],
        ),
        (vec!["--tiles", "3"], 2, vec!["--tiles", "AxB"]),
        (vec!["--aperture", "0"], 1, vec!["--aperture", "(0, 1]"]),
        (
            vec!["--aperture", "1.5"],
            1,
            vec!["--aperture", "(0, 1]", "1.5"],
        ),
        (
            vec!["--adcs", "2", "--tiles", "2x2"],
            1,
            vec!["--adcs 2", "--tiles 2x2", "not supported together"],
        ),
        (
            vec!["--adcs", "2", "--aperture", "0.5"],
            1,
            vec!["--adcs 2", "--aperture 0.5", "not supported together"],
        ),
        (
            vec!["--tiles", "2x2", "--aperture", "0.5"],
            1,
            vec!["not supported together"],
        ),
    ] {
        let mut args = vec![
            "simulate",
            "--scene",
            "paper",
            "--size",
            "4x6x5",
            "--pulse-len",
            "40",
            "--out",
            s(&dir),
        ];
        args.extend(&extra);
        let out = rdlidar(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(code), "{extra:?}: {err}");
        assert!(err.starts_with("error: "), "{err}");
        for n in needles {
            assert!(err.contains(n), "{extra:?}: {n:?} missing from {err}");
        }
        assert!(!dir.exists(), "{extra:?} created {}", dir.display());
    }
    assert!(listing(&tmp.0).is_empty());
}

#[test]
fn forward_and_adjoint_reject_files_of_another_architecture() {
    let tmp = TempDir::new("arch-mismatch");
    let (multi, single) = (tmp.path("multi"), tmp.path("single"));
    simulate_variant(&multi, &["--adcs", "2"]);
    simulate_variant(&single, &[]);
    let out_file = tmp.path("out.npy");

    // G code sets need (G, K) measurements.
    let one = single.join("meas.npy");
    let out = adjoint_on(&multi, &one, &out_file, &[]);
    assert_one_line_error(
        &out,
        Some(&one),
        &["(44,)", "2 code sets", "(2, 44)"],
        &out_file,
    );
    // Several code sets and --tiles are not combined.
    let codes = multi.join("codes.npy");
    let out = forward_on(&multi, &out_file, &["--tiles", "2x2"]);
    assert_one_line_error(&out, Some(&codes), &["not supported together"], &out_file);
    // Single-ADC files are refused by --tiles only when the measurements do not fit.
    let out = adjoint_on(&single, &one, &out_file, &["--tiles", "2x2"]);
    assert_one_line_error(&out, Some(&one), &["--tiles 2x2", "(6, 44)"], &out_file);
    assert!(listing(&tmp.0).iter().all(|n| !n.contains(".tmp-")));
}

#[test]
fn io_code_sets_and_measurement_rows_are_read_only_when_asked() {
    use ndarray::{Array2, Array4};
    use rdlidar::io::{
        read_code_sets, read_codes, read_measurement_rows, read_measurements, write_code_sets,
        write_masked_codes, ShapeExpectation,
    };
    use rdlidar::lidar::Codes;
    let tmp = TempDir::new("io-arch");
    let expect = ShapeExpectation {
        pulse_len: 9,
        depth_bins: 4,
        grid: Some((3, 5)),
    };
    let sets = vec![
        Codes::random_binary(15, 12, 1).unwrap(),
        Codes::random_ternary(15, 12, 0.4, 2).unwrap(),
    ];
    let p = tmp.path("sets.npy");
    write_code_sets(&p, (3, 5), &sets).unwrap();
    let dense: Array4<i8> = read_npy(&p).unwrap();
    assert_eq!(dense.dim(), (2, 3, 5, 12));
    let ((m, n), back) = read_code_sets(&p, &expect).unwrap();
    assert_eq!((m, n), (3, 5));
    assert_eq!(back.len(), 2);
    for (a, b) in back.iter().zip(&sets) {
        assert_eq!(a.to_dense(), b.to_dense());
    }
    // The (M, N, K) reader does not take G sets, nor the (G, M, N, K) reader one set.
    let err = read_codes(&p, &expect).unwrap_err().to_string();
    assert!(err.contains(s(&p)) && err.contains("3 dimensions"), "{err}");
    let one = tmp.path("one.npy");
    rdlidar::io::write_codes(&one, (3, 5), &sets[0]).unwrap();
    let err = read_code_sets(&one, &expect).unwrap_err().to_string();
    assert!(
        err.contains(s(&one)) && err.contains("4 dimensions"),
        "{err}"
    );
    // Values, grid and K are checked in every set.
    let mut bad = dense.clone();
    bad[[1, 2, 4, 7]] = 3;
    write_npy(&p, &bad).unwrap();
    let err = read_code_sets(&p, &expect).unwrap_err().to_string();
    assert!(
        err.contains("value 3") && err.contains("(1, 2, 4, 7)"),
        "{err}"
    );
    let wrong_k = ShapeExpectation {
        pulse_len: 10,
        ..expect
    };
    write_code_sets(&p, (3, 5), &sets).unwrap();
    let err = read_code_sets(&p, &wrong_k).unwrap_err().to_string();
    assert!(
        err.contains("K = K_p + K_s − 1") && err.contains("found 12"),
        "{err}"
    );
    assert!(write_code_sets::<Codes>(&p, (3, 5), &[]).is_err());
    assert!(write_code_sets(&p, (5, 5), &sets).is_err());

    // Masked codes: zero rows outside the active pixels.
    let masked = tmp.path("masked.npy");
    write_masked_codes(&masked, (3, 5), &sets[0], &[0, 7, 14]).unwrap();
    let d: Array3<i8> = read_npy(&masked).unwrap();
    for (i, lane) in d.lanes(ndarray::Axis(2)).into_iter().enumerate() {
        assert_eq!(
            lane.iter().any(|&v| v != 0),
            [0, 7, 14].contains(&i),
            "pixel {i}"
        );
    }
    assert!(write_masked_codes(&masked, (3, 5), &sets[0], &[15]).is_err());

    // Measurement rows.
    let y = tmp.path("rows.npy");
    let rows = Array2::from_shape_fn((3, 12), |(i, k)| (i * 12 + k) as f32);
    write_npy(&y, &rows).unwrap();
    let got = read_measurement_rows::<f64>(&y, Some(&expect), Some(3)).unwrap();
    assert_eq!(got, rows.mapv(f64::from));
    let err = read_measurement_rows::<f64>(&y, Some(&expect), Some(4))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(s(&y)) && err.contains("3 rows, expected 4"),
        "{err}"
    );
    let err = read_measurement_rows::<f64>(&y, Some(&wrong_k), None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("13"), "{err}");
    let err = read_measurements::<f64>(&y, None).unwrap_err().to_string();
    assert!(err.contains(s(&y)) && err.contains("1 dimension"), "{err}");
    let mut nan = rows.mapv(f64::from);
    nan[[2, 5]] = f64::NAN;
    write_npy(&y, &nan).unwrap();
    let err = read_measurement_rows::<f64>(&y, None, None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("NaN") && err.contains("(2, 5)"), "{err}");
    let vec_file = tmp.path("vec.npy");
    write_npy(&vec_file, &Array1::<f64>::zeros(12)).unwrap();
    let err = read_measurement_rows::<f64>(&vec_file, None, None)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(s(&vec_file)) && err.contains("2 dimensions"),
        "{err}"
    );
}
