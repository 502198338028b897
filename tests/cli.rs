//! The command line, run as a user would.

use std::process::Command;

fn rdlidar(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(args)
        .output()
        .expect("the binary runs")
}

#[test]
fn selfcheck_dot_tests_every_operator_in_both_precisions() {
    let out = rdlidar(&["selfcheck", "--seed", "5"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    for name in [
        "Identity",
        "Gradient2D",
        "Convolve1D FFT",
        "SparseMatrix",
        "Normal",
        "BlockDiag",
        "Counted",
    ] {
        assert!(text.contains(name), "{name} missing from\n{text}");
    }
    assert!(!text.contains("FAILED"), "{text}");
    // Every row carries two gaps in scientific notation.
    let rows = text
        .lines()
        .filter(|l| l.split_whitespace().filter(|w| w.contains('e')).count() >= 2)
        .count();
    assert!(rows >= 24, "{text}");
}

#[test]
fn the_version_flag_prints_the_version() {
    // With no arguments the binary runs the demo (tests/cli_experiments.rs).
    let out = rdlidar(&["--version"]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains(env!("CARGO_PKG_VERSION")));
}

#[test]
fn unknown_subcommands_and_bad_flags_fail_with_a_message() {
    let out = rdlidar(&["frobnicate"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("frobnicate"));
    let out = rdlidar(&["selfcheck", "--seed", "minus-one"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--seed"));
}
