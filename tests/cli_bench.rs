//! `rdlidar bench`, run as a user would: the timings, memory, ISA and threads it reports, as JSON
//! and as text.

use crate::cli_support::{rdlidar, stderr, stdout};

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
