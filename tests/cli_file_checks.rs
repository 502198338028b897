//! The file checks of `forward` and `adjoint`: each bad input file (wrong dtype, shape or grid,
//! NaN, infinite, negative or invalid values, truncated, not a `.npy`, missing) and an output in a
//! missing directory fail with one `error:` line naming the file, and leave no output behind.

use std::path::{Path, PathBuf};
use std::process::Output;

use ndarray::{Array1, Array3};
use ndarray_npy::{read_npy, write_npy};

use crate::cli_support::{listing, rdlidar, s, simulate_small, stderr, TempDir};

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
