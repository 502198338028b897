//! The numerical stress suite: the quick preset through the library, and `rdlidar stress` as a
//! user runs it.

use std::ops::ControlFlow;
use std::sync::OnceLock;

use rdlidar::recon::Method;
use rdlidar::report::stress::{
    failures, run_stress, solver_tolerance, table_header, table_line, Bound, Group, SolverCase,
    StressConfig, StressRow, EXACT_TOL,
};

use crate::cli_support::{rdlidar, stderr, stdout};

const SEED: u64 = 7;

/// The quick preset at [`SEED`], run once for the tests of this module.
fn quick_rows() -> &'static [StressRow] {
    static ROWS: OnceLock<Vec<StressRow>> = OnceLock::new();
    ROWS.get_or_init(|| {
        let mut streamed = 0;
        let rows = run_stress(&StressConfig::quick(SEED), |_| {
            streamed += 1;
            ControlFlow::Continue(())
        })
        .expect("the quick preset runs");
        assert_eq!(streamed, rows.len());
        rows
    })
}

#[test]
fn every_row_of_the_quick_preset_passes_with_finite_values() {
    let rows = quick_rows();
    let failed: Vec<String> = rows.iter().filter(|r| !r.passed).map(table_line).collect();
    assert!(failed.is_empty(), "failed rows:\n{}", failed.join("\n"));
    assert_eq!(failures(rows), 0);
    for r in rows {
        assert!(r.error.is_none(), "{}", table_line(r));
        assert!(!r.checks.is_empty(), "{}", table_line(r));
        for (name, v) in &r.values {
            // κ of a support that is not determined is huge but finite in floating point.
            assert!(v.is_finite(), "{name} = {v} in {}", table_line(r));
        }
        for c in &r.checks {
            assert!(c.passed && c.measured.is_finite(), "{}", table_line(r));
            assert_eq!(r.value(c.value), Some(c.measured), "{}", table_line(r));
        }
        assert!(r.seconds.is_finite() && r.seconds >= 0.0);
    }
}

#[test]
fn the_quick_preset_covers_every_group_precision_and_method() {
    let rows = quick_rows();
    let config = StressConfig::quick(SEED);
    let count = |g: Group| rows.iter().filter(|r| r.group == g).count();
    let ks = config.samples.len();
    assert_eq!(count(Group::Precision), 3 * ks);
    assert_eq!(count(Group::DotTest), 2 * ks);
    assert_eq!(
        count(Group::Conditioning),
        2 * config.conditioning_pulse_lens.len()
    );
    assert_eq!(
        count(Group::Solvers),
        2 * Method::ALL.len() * SolverCase::all().len()
    );
    for p in ["f32", "f64"] {
        for g in [Group::DotTest, Group::Conditioning, Group::Solvers] {
            assert!(rows.iter().any(|r| r.group == g && r.precision == p));
        }
    }
    // The f32 adjoint stays at round-off while a naive f32 sum drifts well past it.
    let adjoint = rows
        .iter()
        .rfind(|r| r.case.starts_with("adjoint"))
        .expect("an adjoint row");
    let gap = adjoint.value("rel_diff").unwrap();
    assert!(gap < 4.0 * f32::EPSILON as f64, "{}", table_line(adjoint));
    assert!(adjoint.value("naive_f32").unwrap() > 10.0 * gap);
    // The first conditioning case is below the support size: σ_min = 0, a null vector is found.
    let deficient = rows
        .iter()
        .find(|r| r.group == Group::Conditioning)
        .unwrap();
    assert!(
        deficient.value("min/max").is_some(),
        "{}",
        table_line(deficient)
    );
    // Exact recovery, noise-free, in both precisions.
    for r in rows.iter().filter(|r| r.case == "model-based, baseline") {
        assert!(
            r.value("rel_error").unwrap() <= EXACT_TOL,
            "{}",
            table_line(r)
        );
        assert_eq!(r.value("exact_depth"), Some(1.0));
    }
}

#[test]
fn the_tolerances_follow_the_documented_rules() {
    let case = SolverCase::Noise { snr_db: 20.0 };
    assert_eq!(
        solver_tolerance(Method::ModelBased, SolverCase::Baseline, 0.0),
        EXACT_TOL
    );
    assert!((solver_tolerance(Method::Amp, case, 0.0) - 0.17).abs() < 1e-12);
    // A method that never recovers the scene keeps its ceiling when the noise bound is lower.
    assert_eq!(solver_tolerance(Method::Fista, case, 0.0), 0.6);
    let floor = solver_tolerance(Method::Tv, SolverCase::DynamicRange, 0.04);
    assert!(floor > 0.04 && floor < 0.041, "{floor}");
    assert!(Bound::AtMost(1.0).holds(1.0));
    assert!(!Bound::AtMost(1.0).holds(f64::NAN));
    assert!(!Bound::Above(0.0).holds(0.0));
    assert!(!Bound::Above(0.0).holds(f64::INFINITY));
    let header = table_header();
    let line = table_line(&quick_rows()[0]);
    assert_eq!(header[0].chars().filter(|&c| c == '|').count(), 8);
    assert_eq!(line.chars().filter(|&c| c == '|').count(), 8, "{line}");
}

#[test]
fn stress_quick_json_passes_and_repeats_the_library_run() {
    let seed = SEED.to_string();
    let out = rdlidar(&["stress", "--quick", "--json", "--seed", &seed]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(out.stderr.is_empty(), "{}", stderr(&out));
    let text = stdout(&out);
    assert_eq!(text.trim_end().lines().count(), 1, "one JSON document");
    let doc: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    assert_eq!(doc["preset"], "quick");
    assert_eq!(doc["seed"], SEED);
    assert_eq!(doc["failed"], 0);
    let rows = doc["rows"].as_array().expect("rows");
    let lib = quick_rows();
    assert_eq!(rows.len(), lib.len());
    assert_eq!(doc["passed"], lib.len());
    // Same seed, same rows, apart from the times.
    for (j, r) in rows.iter().zip(lib) {
        assert_eq!(j["group"], serde_json::to_value(r.group).unwrap());
        assert_eq!(j["case"], r.case.as_str());
        assert_eq!(j["precision"], r.precision);
        assert_eq!(j["passed"], true);
        for (name, v) in &r.values {
            assert_eq!(j["values"][name].as_f64(), Some(*v), "{name} of {}", r.case);
        }
        let checks = j["checks"].as_array().unwrap();
        assert_eq!(checks.len(), r.checks.len());
        assert!(checks.iter().all(|c| c["passed"] == true));
    }
}

#[test]
fn stress_refuses_a_precision_and_documents_its_flags() {
    let out = rdlidar(&["stress", "--quick", "--precision", "f32"]);
    crate::cli_support::assert_one_line_error(&out, &["--precision", "f32 and f64"]);
    let out = rdlidar(&["stress", "--help"]);
    assert!(out.status.success());
    let help = stdout(&out);
    for needle in ["--quick", "--json", "Example:"] {
        assert!(help.contains(needle), "{needle} missing from\n{help}");
    }
}

#[test]
fn coarse_to_fine_stays_bounded_in_f32_where_its_least_squares_once_broke_down() {
    // Seeds at which the refinement's last least squares, run in f32 to an f64 tolerance, once
    // broke down or returned amplitudes of 10¹⁴ and more: every row passes now.
    for seed in [24, 27] {
        let rows = run_stress(&StressConfig::quick(seed), |_| ControlFlow::Continue(()))
            .expect("the quick preset runs");
        let failed: Vec<String> = rows
            .iter()
            .filter(|r| r.case.starts_with("coarse-to-fine") && !r.passed)
            .map(table_line)
            .collect();
        assert!(failed.is_empty(), "seed {seed}:\n{}", failed.join("\n"));
    }
}
