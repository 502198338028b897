//! `rdlidar dottest`, run as a user would: the dot tests pass on simulated codes in both
//! precisions.

use crate::cli_support::{rdlidar, s, simulate_small, stderr, stdout, TempDir};

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
