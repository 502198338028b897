//! `reconstruct` on every architecture `simulate` writes: G ADCs (codes (G, M, N, K),
//! measurements (G, K)) and tiles (`--tiles AxB`, measurements (T, K)), end to end, and the
//! refusals of files and flags that do not fit each other.

use std::path::Path;

use ndarray::{Array1, Array2, Array3};
use ndarray_npy::{read_npy, write_npy};

use super::cli_support::{assert_one_line_error, rdlidar, s, stderr, stdout, TempDir};

fn simulate(dir: &Path, size: &str, kp: &str, extra: &[&str]) {
    let mut args = vec![
        "simulate",
        "--scene",
        "paper",
        "--size",
        size,
        "--pulse-len",
        kp,
        "--seed",
        "2",
        "--out",
        s(dir),
    ];
    args.extend_from_slice(extra);
    let out = rdlidar(&args);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// `reconstruct --solver auto` of the run in `run`, with `codes` and `meas` (defaults: the
/// run's) and `extra` flags, writing into `out`.
fn reconstruct(
    run: &Path,
    out: &Path,
    files: (&Path, &Path),
    extra: &[&str],
) -> std::process::Output {
    let (codes, meas) = files;
    let (pulse, truth) = (run.join("pulse.npy"), run.join("scene.npy"));
    let (d, x) = (out.join("d.npy"), out.join("x.npy"));
    let mut args = vec![
        "reconstruct",
        "--pulse",
        s(&pulse),
        "--codes",
        s(codes),
        "--meas",
        s(meas),
        "--depth-bins",
        "8",
        "--solver",
        "auto",
        "--truth",
        s(&truth),
        "--out-depth",
        s(&d),
        "--out-scene",
        s(&x),
    ];
    args.extend_from_slice(extra);
    rdlidar(&args)
}

fn truth_depth(run: &Path) -> Array2<i32> {
    let x: Array3<f64> = read_npy(run.join("scene.npy")).unwrap();
    x.map_axis(ndarray::Axis(2), |c| {
        c.iter()
            .enumerate()
            .filter(|(_, v)| **v > 0.0)
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or(-1, |(j, _)| j as i32)
    })
}

#[test]
fn several_adcs_are_reconstructed_through_their_stacked_operator() {
    let tmp = TempDir::new("arch-adcs");
    let run = tmp.path("run");
    // 2 ADCs of K_p 300: 614 samples for 62 lit pixels.
    simulate(&run, "12x10x8", "300", &["--adcs", "2"]);
    let (codes, meas) = (run.join("codes.npy"), run.join("meas.npy"));
    let out = reconstruct(&run, &tmp.0, (&codes, &meas), &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(
        text.contains("from 2 × 307 = 614 measurements, 2 ADCs"),
        "{text}"
    );
    assert!(
        text.contains("exact depth 100.0%") && text.contains("false 0"),
        "{text}"
    );
    let d: Array2<i32> = read_npy(tmp.path("d.npy")).unwrap();
    assert_eq!(d, truth_depth(&run));
}

#[test]
fn a_tiled_array_is_reconstructed_per_tile_and_stitched() {
    let tmp = TempDir::new("arch-tiles");
    let run = tmp.path("run");
    // 13x11 in tiles of 5x4: 9 tiles, the last row and column clipped.
    simulate(&run, "13x11x8", "400", &["--tiles", "5x4"]);
    let (codes, meas) = (run.join("codes.npy"), run.join("meas.npy"));
    let out = reconstruct(&run, &tmp.0, (&codes, &meas), &["--tiles", "5x4"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("of 9 tiles of 5x4"), "{text}");
    assert!(
        text.contains("exact depth 100.0%") && text.contains("false 0"),
        "{text}"
    );
    let progress = stderr(&out);
    assert_eq!(
        progress.lines().filter(|l| l.starts_with("tile ")).count(),
        9,
        "{progress}"
    );
    assert!(
        progress.contains("rows 10..13, columns 8..11"),
        "{progress}"
    );
    let d: Array2<i32> = read_npy(tmp.path("d.npy")).unwrap();
    assert_eq!(d, truth_depth(&run));
    let x: Array3<f64> = read_npy(tmp.path("x.npy")).unwrap();
    let t: Array3<f64> = read_npy(run.join("scene.npy")).unwrap();
    assert!(x.iter().zip(&t).all(|(a, b)| (a - b).abs() < 1e-6));
}

#[test]
fn architectures_whose_files_and_flags_disagree_are_refused_before_any_work() {
    let tmp = TempDir::new("arch-bad");
    let (tiled, adcs, single) = (tmp.path("tiled"), tmp.path("adcs"), tmp.path("single"));
    simulate(&tiled, "13x11x8", "100", &["--tiles", "5x4"]);
    simulate(&adcs, "6x5x8", "100", &["--adcs", "2"]);
    simulate(&single, "6x5x8", "100", &[]);
    let outs = tmp.path("outs");
    std::fs::create_dir_all(&outs).unwrap();
    let files = |run: &Path| (run.join("codes.npy"), run.join("meas.npy"));
    let check = |out: std::process::Output, needles: &[&str]| {
        assert_one_line_error(&out, needles);
        assert!(
            std::fs::read_dir(&outs).unwrap().next().is_none(),
            "no output left behind"
        );
    };

    // Tiled measurements without --tiles, or with another tile size.
    let (c, m) = files(&tiled);
    check(
        reconstruct(&tiled, &outs, (&c, &m), &[]),
        &[s(&m), "--tiles AxB"],
    );
    check(
        reconstruct(&tiled, &outs, (&c, &m), &["--tiles", "4x4"]),
        &[s(&m), "have 9 rows", "--tiles 4x4", "12 tiles"],
    );
    // --tiles with several code sets.
    let (c2, m2) = files(&adcs);
    check(
        reconstruct(&adcs, &outs, (&c2, &m2), &["--tiles", "2x2"]),
        &[s(&c2), "--tiles 2x2", "2 code sets"],
    );
    // Two code sets, one ADC's measurements; and three rows for two sets.
    let (_, m1) = files(&single);
    check(
        reconstruct(&adcs, &outs, (&c2, &m1), &[]),
        &[s(&m1), "those of one ADC", "2 code sets"],
    );
    let y: Array2<f64> = read_npy(&m2).unwrap();
    let three = tmp.path("three.npy");
    write_npy(
        &three,
        &ndarray::concatenate(ndarray::Axis(0), &[y.view(), y.slice(ndarray::s![..1, ..])])
            .unwrap(),
    )
    .unwrap();
    check(
        reconstruct(&adcs, &outs, (&c2, &three), &[]),
        &[s(&three), "have 3 rows", "2 code sets"],
    );
    // One code set with rows of several ADCs.
    let (c1, _) = files(&single);
    check(
        reconstruct(&single, &outs, (&c1, &m2), &[]),
        &[s(&m2), "one row per ADC", "--tiles"],
    );
    // Rows of the wrong length.
    let short: Array1<f64> = read_npy::<_, Array1<f64>>(&m1)
        .unwrap()
        .slice(ndarray::s![..50])
        .to_owned();
    let bad = tmp.path("short.npy");
    write_npy(&bad, &short).unwrap();
    check(reconstruct(&single, &outs, (&c1, &bad), &[]), &[s(&bad)]);
}

#[test]
fn a_coded_apertures_blocked_pixels_are_unobserved_and_can_be_filled() {
    let tmp = TempDir::new("arch-aperture");
    let run = tmp.path("run");
    simulate(&run, "12x10x8", "300", &["--aperture", "0.6"]);
    let (codes, meas) = (run.join("codes.npy"), run.join("meas.npy"));
    let out = reconstruct(&run, &tmp.0, (&codes, &meas), &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    let c: Array3<i8> = read_npy(&codes).unwrap();
    let blocked: Vec<bool> = c
        .outer_iter()
        .flat_map(|row| {
            row.outer_iter()
                .map(|px| px.iter().all(|&v| v == 0))
                .collect::<Vec<_>>()
        })
        .collect();
    let n_blocked = blocked.iter().filter(|&&b| b).count();
    assert_eq!(n_blocked, 48, "60% of 120 pixels reach the ADC");
    assert!(
        text.contains(&format!(
            "on the {} observed pixels: exact depth 100.0%",
            120 - n_blocked
        )),
        "{text}"
    );
    assert!(text.contains("48 pixels unobserved"), "{text}");
    let d: Array2<i32> = read_npy(tmp.path("d.npy")).unwrap();
    let t = truth_depth(&run);
    for ((&e, &td), &b) in d.iter().zip(&t).zip(&blocked) {
        assert_eq!(e, if b { -2 } else { td });
    }
    // Filled from the neighbours: no pixel left unobserved, most lit ones at their depth.
    std::fs::remove_file(tmp.path("d.npy")).unwrap();
    std::fs::remove_file(tmp.path("x.npy")).unwrap();
    let out = reconstruct(&run, &tmp.0, (&codes, &meas), &["--fill-unobserved"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("filled from their neighbours"), "{text}");
    let d: Array2<i32> = read_npy(tmp.path("d.npy")).unwrap();
    assert!(d.iter().all(|&v| v >= -1));
    let hidden_lit = t
        .iter()
        .zip(&blocked)
        .filter(|(&v, &b)| b && v >= 0)
        .count();
    let right = d
        .iter()
        .zip(&t)
        .zip(&blocked)
        .filter(|((&e, &v), &b)| b && v >= 0 && e == v)
        .count();
    assert!(2 * right > hidden_lit, "{right} of {hidden_lit}: {text}");
}
