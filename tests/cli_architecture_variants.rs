//! Architecture variants, run as a user would: `simulate --adcs / --tiles / --aperture`, and
//! `forward`, `adjoint` and `dottest` on the files they write, with the refusals of invalid
//! architectures and of files of another architecture.

use std::path::Path;
use std::process::Output;

use ndarray::{Array1, Array3};
use ndarray_npy::read_npy;

use crate::cli_support::{listing, max_rel_diff, rdlidar, s, stderr, stdout, TempDir};

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
