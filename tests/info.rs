//! The budget of a configuration (`rdlidar::lidar::Cost`) and `rdlidar info`: regime, physical
//! scales, memory against the operator's own count, the time model, and invalid inputs.

use std::sync::Arc;

use rdlidar::lidar::{
    parse_tau, CodeAlphabet, Codes, Geometry, Pulse, RdOperator, Regime, DEFAULT_TAU_S,
    SPEED_OF_LIGHT,
};
use rdlidar::report::cost::{Cost, Throughput, ThroughputSource};
use rdlidar::Error;

use crate::cli_support::{assert_one_line_error, assert_usage_error, rdlidar, stderr, stdout};

fn geometry(text: &str) -> Geometry {
    Geometry::parse(text).unwrap()
}

fn budget(size: &str, kp: usize) -> Cost {
    Cost::new(
        geometry(size),
        kp,
        DEFAULT_TAU_S,
        2,
        Throughput::documented(),
    )
    .unwrap()
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * b.abs()
}

/// The name of an `InvalidParameter` error, or a panic naming what came instead.
fn param_name<T: std::fmt::Debug>(r: rdlidar::Result<T>) -> &'static str {
    match r {
        Err(Error::InvalidParameter { name, .. }) => name,
        other => panic!("expected an invalid parameter, got {other:?}"),
    }
}

#[test]
fn the_paper_experiment_is_compressive_with_its_physical_scales() {
    let b = budget("100x100x40", 30_000);
    assert_eq!((b.m, b.n, b.ks, b.pulse_len), (100, 100, 40, 30_000));
    assert_eq!(b.samples, 30_039);
    assert_eq!(b.unknowns, 400_000);
    assert_eq!(b.regime, Regime::Compressive);
    assert_eq!(b.critical_pulse_len, 399_961);
    assert!(close(
        b.measurements_per_unknown,
        30_039.0 / 400_000.0,
        1e-12
    ));
    let p = &b.physical;
    let bin = 200e-12 * SPEED_OF_LIGHT / 2.0;
    assert!(close(p.depth_resolution_m, bin, 1e-12));
    assert!(close(p.depth_resolution_m, 0.029_979_245_8, 1e-9));
    assert!(close(p.range_m, 40.0 * bin, 1e-12));
    assert!(close(p.pulse_duration_s, 6e-6, 1e-12));
    assert!(close(p.frame_duration_s, 30_039.0 * 200e-12, 1e-12));
    assert!(close(
        p.max_frame_rate_hz,
        1.0 / (30_039.0 * 200e-12),
        1e-12
    ));
    assert!(close(
        p.critical_pulse_duration_s,
        399_961.0 * 200e-12,
        1e-12
    ));

    let m = &b.memory;
    assert_eq!(m.codes_packed_bytes, 1250 * 30_039); // 37.5 MB: one bit per ±1 code
    assert_eq!(m.codes_int8_bytes, 10_000 * 30_039);
    // ⌈30 039 / 8⌉ = 3755 bytes per pixel.
    assert_eq!(m.codes_packbits_bytes, 10_000 * 3755);
    assert_eq!(m.codes_dense_bytes.f32, 4 * 10_000 * 30_039); // 1.2 GB
    assert_eq!(m.codes_dense_bytes.f64, 8 * 10_000 * 30_039);
    assert_eq!((m.pulse_bytes.f32, m.pulse_bytes.f64), (120_000, 240_000));
    assert_eq!(
        (m.measurements_bytes.f32, m.measurements_bytes.f64),
        (4 * 30_039, 8 * 30_039)
    );
    assert_eq!(
        (m.scene_bytes.f32, m.scene_bytes.f64),
        (1_600_000, 3_200_000)
    );
    assert_eq!(m.operator_threads, 2);
    // The operator holds the packed codes plus the pulse and a few megabytes of working buffers
    // per thread (the forward's sums over K, the adjoint's partial sums of a block of pixels).
    for op in [m.operator_bytes.f32, m.operator_bytes.f64] {
        assert!(op > m.codes_packed_bytes && op < m.codes_packed_bytes + 16_000_000);
    }
}

#[test]
fn the_paper_large_example_needs_a_5_ms_pulse_and_runs_at_200_frames_per_second() {
    // The paper's §5.3: 500×500 pixels, K_s = 100, τ = 200 ps, K_p ≈ 2.5·10⁷.
    let b = budget("500x500x100", 25_000_000);
    assert_eq!(b.critical_pulse_len, 24_999_901);
    assert_eq!(b.regime, Regime::Redundant);
    assert!(close(b.physical.pulse_duration_s, 5e-3, 1e-12));
    assert!(close(b.physical.critical_pulse_duration_s, 5e-3, 1e-4));
    assert!(close(b.physical.max_frame_rate_hz, 200.0, 1e-4));
    // Five times longer pulse: 25 ms, 40 frames per second.
    let b5 = budget("500x500x100", 125_000_000);
    assert!(close(b5.physical.max_frame_rate_hz, 40.0, 1e-4));
    // 100 bins of 3 cm span 3 m.
    assert!(close(b.physical.range_m, 2.998, 1e-3));
}

#[test]
fn the_regime_changes_at_the_critical_pulse_length() {
    let g = geometry("3x4x5");
    let crit = g.critical_pulse_len();
    assert_eq!(crit, 56);
    for (kp, regime) in [
        (crit - 1, Regime::Compressive),
        (crit, Regime::Critical),
        (crit + 1, Regime::Redundant),
    ] {
        let b = Cost::new(g, kp, DEFAULT_TAU_S, 1, Throughput::documented()).unwrap();
        assert_eq!(b.regime, regime, "K_p = {kp}");
        assert_eq!(b.samples >= b.unknowns, kp >= crit);
    }
    let at = Cost::new(g, crit, DEFAULT_TAU_S, 1, Throughput::documented()).unwrap();
    assert_eq!(at.samples, at.unknowns);
    assert_eq!(at.measurements_per_unknown, 1.0);
}

#[test]
fn the_physical_scales_follow_tau() {
    let g = geometry("10x10x16");
    let at = |tau: f64| Cost::new(g, 1000, tau, 1, Throughput::documented()).unwrap();
    let (b1, b2) = (at(200e-12), at(1e-9));
    assert!(close(
        b2.physical.depth_resolution_m,
        5.0 * b1.physical.depth_resolution_m,
        1e-12
    ));
    assert!(close(b2.physical.range_m, 5.0 * b1.physical.range_m, 1e-12));
    assert!(close(b2.physical.pulse_duration_s, 1e-6, 1e-12));
    assert!(close(
        b2.physical.max_frame_rate_hz,
        b1.physical.max_frame_rate_hz / 5.0,
        1e-12
    ));
    // Memory and times do not depend on τ.
    assert_eq!(b1.memory, b2.memory);
    assert_eq!(b1.time, b2.time);
}

#[test]
fn the_operator_memory_estimate_is_what_a_built_operator_reports() {
    let threads = rayon::current_num_threads();
    for (size, kp) in [
        ("4x5x6", 50),
        ("9x7x40", 300),
        ("3x3x70", 20),
        ("16x16x130", 64),
    ] {
        let g = geometry(size);
        let k = g.samples(kp);
        let binary = Arc::new(Codes::random_binary(g.pixels(), k, 1).unwrap());
        let ternary = Arc::new(Codes::random_ternary(g.pixels(), k, 0.3, 2).unwrap());
        for (codes, alphabet) in [
            (binary, CodeAlphabet::Binary),
            (ternary, CodeAlphabet::Ternary),
        ] {
            let p32 = Pulse::<f32>::bernoulli(kp, 0).unwrap().into_inner();
            let p64 = Pulse::<f64>::bernoulli(kp, 0).unwrap().into_inner();
            let op32 = RdOperator::new(g, p32, codes.clone()).unwrap();
            let op64 = RdOperator::new(g, p64, codes.clone()).unwrap();
            let e32 = RdOperator::<f32>::estimated_memory_bytes(g, kp, alphabet, threads).unwrap();
            let e64 = RdOperator::<f64>::estimated_memory_bytes(g, kp, alphabet, threads).unwrap();
            assert_eq!(op32.memory_bytes(), e32, "{size} {alphabet:?} f32");
            assert_eq!(op64.memory_bytes(), e64, "{size} {alphabet:?} f64");
            assert!(e32 >= codes.memory_bytes());
        }
        let b = Cost::new(g, kp, DEFAULT_TAU_S, threads, Throughput::documented()).unwrap();
        assert_eq!(
            b.memory.operator_bytes.f32,
            RdOperator::<f32>::estimated_memory_bytes(g, kp, CodeAlphabet::Binary, threads).unwrap()
                as u64
        );
        assert_eq!(
            b.memory.codes_packed_bytes,
            Codes::random_binary(g.pixels(), g.samples(kp), 0)
                .unwrap()
                .memory_bytes() as u64
        );
    }
}

#[test]
fn times_are_the_work_divided_by_the_rates() {
    let b = budget("100x100x40", 30_000);
    let t = &b.time;
    let flops = 2.0 * 10_000.0 * 30_039.0 * 40.0;
    assert!(close(t.flops_per_apply, flops, 1e-12));
    assert!(close(t.sparse_voxel_samples, 10_000.0 * 30_000.0, 1e-12));
    let r = &t.throughput.rates;
    assert!(close(
        t.forward_s.f32,
        flops / r.f32.forward_flops_per_s,
        1e-12
    ));
    assert!(close(
        t.adjoint_s.f64,
        flops / r.f64.adjoint_flops_per_s,
        1e-12
    ));
    assert!(close(
        t.sparse_forward_s.f32,
        3e8 / r.f32.sparse_voxel_samples_per_s,
        1e-12
    ));
    assert!(close(
        t.iteration_s.f32,
        t.forward_s.f32 + t.adjoint_s.f32,
        1e-12
    ));
    // The documented rates reproduce the documented times at the size they were measured at.
    assert!(close(t.forward_s.f32, 0.0725, 1e-9));
    assert!(close(t.adjoint_s.f32, 0.0667, 1e-9));
    assert!(close(t.forward_s.f64, 0.1228, 1e-9));
    assert!(close(t.adjoint_s.f64, 0.1200, 1e-9));
    // The sparse rates were measured on the paper scene, 5 547 lit voxels of the 10 000 pixels.
    let paper = 5_547.0 / 10_000.0;
    assert!(close(t.sparse_forward_s.f32 * paper, 0.0097, 1e-9));
    assert!(close(t.sparse_forward_s.f64 * paper, 0.0169, 1e-9));
    // f64 is slower than f32, and the work grows linearly with K.
    assert!(t.forward_s.f64 > t.forward_s.f32 && t.adjoint_s.f64 > t.adjoint_s.f32);
    let longer = budget("100x100x40", 60_039);
    assert!(close(
        longer.time.forward_s.f32,
        2.0 * t.forward_s.f32,
        1e-3
    ));
    assert!(matches!(
        t.throughput.source,
        ThroughputSource::Documented { .. }
    ));
}

#[test]
fn a_calibration_measures_positive_rates_on_a_capped_problem() {
    let (g, kp) = Throughput::calibration_problem(geometry("500x300x100"), 25_000_000).unwrap();
    assert_eq!((g, kp), (geometry("64x64x64"), 16_384));
    let (g, kp) = Throughput::calibration_problem(geometry("8x9x10"), 77).unwrap();
    assert_eq!((g, kp), (geometry("8x9x10"), 77));

    let t = Throughput::calibrate(geometry("8x9x10"), 200, 1).unwrap();
    match &t.source {
        ThroughputSource::Calibrated {
            size,
            pulse_len,
            repeats,
            threads,
            ..
        } => {
            assert_eq!((size.as_str(), *pulse_len, *repeats), ("8x9x10", 200, 1));
            assert_eq!(*threads, rayon::current_num_threads());
        }
        other => panic!("not calibrated: {other:?}"),
    }
    for r in [t.rates.f32, t.rates.f64] {
        for v in [
            r.forward_flops_per_s,
            r.adjoint_flops_per_s,
            r.sparse_voxel_samples_per_s,
        ] {
            assert!(v.is_finite() && v > 0.0, "{r:?}");
        }
    }
    let b = Cost::new(geometry("8x9x10"), 200, DEFAULT_TAU_S, 1, t).unwrap();
    assert!(b.time.forward_s.f32 > 0.0 && b.time.forward_s.f32.is_finite());
    assert!(b
        .to_string()
        .contains("calibration on this machine: 8x9x10, K_p 200"));
    assert_eq!(
        param_name(Throughput::calibrate(geometry("2x2x2"), 10, 0)),
        "repeats"
    );
    assert_eq!(
        param_name(Throughput::calibration_problem(geometry("2x2x2"), 0)),
        "pulse_len"
    );
}

#[test]
fn invalid_inputs_are_typed_errors() {
    let g = geometry("10x10x10");
    let new = |kp: usize, tau: f64, threads: usize| {
        Cost::new(g, kp, tau, threads, Throughput::documented())
    };
    assert_eq!(param_name(new(0, 2e-10, 1)), "pulse_len");
    assert_eq!(param_name(new(10, 2e-10, 0)), "threads");
    for tau in [f64::NAN, 0.0, -2e-10, f64::INFINITY, f64::NEG_INFINITY] {
        assert_eq!(param_name(new(10, tau, 1)), "tau", "τ = {tau}");
    }
    // τ so large or so small that the scales leave f64.
    assert_eq!(param_name(new(10, 1e300, 1)), "tau");
    assert_eq!(param_name(new(10, 1e-320, 1)), "tau");
    // K = K_p + K_s − 1 overflows.
    assert_eq!(param_name(new(usize::MAX, 2e-10, 1)), "pulse_len");
    // The codes' byte count overflows 64 bits.
    let big = geometry("100000x100000x1");
    let r = Cost::new(big, 1 << 40, 2e-10, 1, Throughput::documented());
    assert_eq!(param_name(r), "pulse_len");
    // Rates that are zero, negative or NaN.
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let mut t = Throughput::documented();
        t.rates.f64.adjoint_flops_per_s = bad;
        let r = Cost::new(g, 10, 2e-10, 1, t);
        assert_eq!(param_name(r), "throughput", "rate {bad}");
    }
    // Zero and overflowing sizes never reach a budget.
    assert_eq!(param_name(Geometry::parse("0x10x10")), "size");
    assert_eq!(
        param_name(Geometry::parse("4294967296x4294967296x2")),
        "size"
    );
    assert_eq!(
        param_name(RdOperator::<f32>::estimated_memory_bytes(
            g,
            0,
            CodeAlphabet::Binary,
            1
        )),
        "pulse_len"
    );
    assert_eq!(
        param_name(RdOperator::<f32>::estimated_memory_bytes(
            g,
            5,
            CodeAlphabet::Binary,
            0
        )),
        "threads"
    );
}

#[test]
fn tau_is_parsed_with_its_unit() {
    for (text, seconds) in [
        ("200ps", 200e-12),
        ("200 ps", 200e-12),
        (" 0.2ns ", 0.2e-9),
        ("2e-10s", 2e-10),
        ("1us", 1e-6),
        ("1µs", 1e-6),
        ("3ms", 3e-3),
        ("500fs", 500e-15),
        ("1.5E2ps", 150e-12),
    ] {
        let v = parse_tau(text).unwrap();
        assert!(close(v, seconds, 1e-12), "{text}: {v}");
    }
    for text in [
        "200", "ps", "200 px", "abc ps", "inf ps", "NaN ns", "-1ns", "0ps", "1e-400s", "", "2 2ps",
    ] {
        assert_eq!(param_name(parse_tau(text)), "tau", "{text:?}");
    }
}

#[test]
fn the_table_and_the_json_carry_the_numbers() {
    let b = budget("100x100x40", 30_000);
    let text = b.to_string();
    for needle in [
        "100x100x40",
        "K = K_p + K_s − 1 = 30039",
        "regime compressive",
        "critical K_p = (M·N − 1)·K_s + 1 = 399961",
        "τ = 200 ps",
        "2.998 cm",
        "1.199 m",
        "6 µs",
        "166450 frames/s",
        "37.5 MB",
        "300 MB",
        "1.2 GB",
        "operator, 2 threads",
        "72.5 ms",
        "66.7 ms",
        "2.403e10 flops",
        "documented rates",
    ] {
        assert!(text.contains(needle), "{needle:?} missing from\n{text}");
    }
    let v: serde_json::Value = serde_json::to_value(&b).unwrap();
    assert_eq!(v["regime"], "compressive");
    assert_eq!(v["critical_pulse_len"], 399_961);
    assert_eq!(v["samples"], 30_039);
    assert_eq!(v["memory"]["codes_packed_bytes"], 37_548_750u64);
    assert_eq!(v["memory"]["scene_bytes"]["f64"], 3_200_000);
    assert_eq!(v["time"]["throughput"]["source"]["kind"], "documented");
    assert!(v["physical"]["max_frame_rate_hz"].as_f64().unwrap() > 166_000.0);
}

// ---- the command line ----

fn info(args: &[&str]) -> std::process::Output {
    let mut all = vec!["info"];
    all.extend_from_slice(args);
    rdlidar(&all)
}

fn info_json(args: &[&str]) -> serde_json::Value {
    let mut all = args.to_vec();
    all.push("--json");
    let out = info(&all);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert_eq!(text.trim_end().lines().count(), 1, "{text}");
    serde_json::from_str(&text).unwrap()
}

#[test]
fn info_prints_the_table_for_the_paper_size() {
    let out = info(&["--size", "100x100x40", "--pulse-len", "30000"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(out.stderr.is_empty());
    let text = stdout(&out);
    for needle in [
        "regime compressive",
        "399961",
        "τ = 200 ps",
        "2.998 cm",
        "1.199 m",
        "6 µs",
        "166450 frames/s",
        "37.5 MB",
        "forward + adjoint",
        "documented rates",
    ] {
        assert!(text.contains(needle), "{needle:?} missing from\n{text}");
    }
}

#[test]
fn info_json_agrees_with_the_library_and_tau_is_given_either_way() {
    let v = info_json(&["--size", "100x100x40", "--pulse-len", "30000"]);
    let b = budget("100x100x40", 30_000);
    assert_eq!(v["regime"], "compressive");
    assert_eq!(v["critical_pulse_len"], 399_961);
    assert_eq!(
        v["memory"]["codes_packed_bytes"],
        b.memory.codes_packed_bytes
    );
    assert_eq!(v["physical"]["tau_s"].as_f64(), Some(200e-12));
    assert_eq!(
        v["time"]["forward_s"]["f32"].as_f64(),
        Some(b.time.forward_s.f32)
    );

    let by_unit = info_json(&["--size", "8x8x8", "--pulse-len", "600", "--tau", "1ns"]);
    let by_ps = info_json(&["--size", "8x8x8", "--pulse-len", "600", "--tau-ps", "1000"]);
    let default = info_json(&["--size", "8x8x8", "--pulse-len", "600"]);
    assert_eq!(by_unit["physical"], by_ps["physical"]);
    let res = |v: &serde_json::Value| v["physical"]["depth_resolution_m"].as_f64().unwrap();
    assert!(close(res(&by_unit), 5.0 * res(&default), 1e-12));
    assert!(close(res(&by_unit), 0.149_896_229, 1e-9));
    assert_eq!(default["regime"], "redundant"); // 600 > 63·8 + 1 = 505
}

#[test]
fn info_calibrate_says_it_measured_this_machine() {
    let v = info_json(&["--size", "8x8x16", "--pulse-len", "500", "--calibrate"]);
    let source = &v["time"]["throughput"]["source"];
    assert_eq!(source["kind"], "calibrated");
    assert_eq!(source["size"], "8x8x16");
    assert_eq!(source["pulse_len"], 500);
    for op in ["forward_s", "adjoint_s", "sparse_forward_s"] {
        for p in ["f32", "f64"] {
            let t = v["time"][op][p].as_f64().unwrap();
            assert!(t.is_finite() && t > 0.0, "{op} {p}: {t}");
        }
    }
    let out = info(&["--size", "8x8x16", "--pulse-len", "500", "--calibrate"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stdout(&out).contains("from a calibration on this machine: 8x8x16, K_p 500"));
}

#[test]
fn info_rejects_invalid_inputs_with_one_line() {
    for (args, needles) in [
        (
            vec!["--tau-ps", "NaN"],
            vec!["--tau-ps", "finite and > 0", "NaN"],
        ),
        (vec!["--tau-ps", "-5"], vec!["--tau-ps", "> 0", "-5"]),
        (vec!["--tau-ps", "0"], vec!["--tau-ps", "> 0"]),
        (vec!["--tau-ps", "inf"], vec!["--tau-ps", "finite"]),
        (vec!["--tau", "200"], vec!["--tau", "unit", "\"200\""]),
        (vec!["--tau", "-3ps"], vec!["--tau", "> 0"]),
        (vec!["--tau", "nanps"], vec!["--tau", "\"nanps\""]),
        (vec!["--tau", "1e300s"], vec!["--tau", "out of the range"]),
    ] {
        let mut all = vec!["--size", "10x10x10", "--pulse-len", "100"];
        all.extend(&args);
        assert_one_line_error(&info(&all), &needles);
    }
    // Beyond the limits shared by every subcommand.
    let max = usize::MAX.to_string();
    assert_usage_error(
        &info(&["--size", "10x10x10", "--pulse-len", &max]),
        &["--pulse-len", "limit"],
    );
    assert_usage_error(
        &info(&["--size", "100000x100000x1", "--pulse-len", "1000"]),
        &["--size", "4096"],
    );
}

#[test]
fn info_usage_errors_name_the_flag() {
    for (args, needles) in [
        (
            vec!["--size", "0x10x10", "--pulse-len", "5"],
            vec!["--size", "at least 1"],
        ),
        (
            vec!["--size", "10x10", "--pulse-len", "5"],
            vec!["--size", "MxNxKS"],
        ),
        (
            vec!["--size", "4294967296x4294967296x2", "--pulse-len", "5"],
            vec!["--size", "overflow"],
        ),
        (
            vec!["--size", "10x10x10", "--pulse-len", "0"],
            vec!["--pulse-len", "at least 1"],
        ),
        (vec!["--size", "10x10x10", "--pulse-len", "-4"], vec!["-4"]),
        (vec!["--size", "10x10x10"], vec!["--pulse-len"]),
        (
            vec![
                "--size",
                "10x10x10",
                "--pulse-len",
                "5",
                "--tau",
                "1ns",
                "--tau-ps",
                "5",
            ],
            vec!["--tau", "cannot be used with"],
        ),
        (
            vec!["--size", "10x10x10", "--pulse-len", "5", "--tau-ps", "abc"],
            vec!["--tau-ps", "abc"],
        ),
    ] {
        assert_usage_error(&info(&args), &needles);
    }
    let out = info(&["--help"]);
    assert!(out.status.success());
    let help = stdout(&out);
    assert!(
        help.contains("Example: `rdlidar info --size 100x100x40"),
        "{help}"
    );
    assert!(
        help.contains("--calibrate") && help.contains("--tau-ps"),
        "{help}"
    );
}
