//! `rdlidar compare` under `mpirun -n R` (feature `mpi`): the sweep's problems dealt to the
//! processes give the tables of one process (run times apart), alone or within a shard; a
//! folder that cannot be written ends every process with one error line and nothing run.

use std::process::Command;

use crate::cli_support::{assert_one_line_error, rows_without_times, s, stderr, TempDir};
use crate::mpi_cli::{mpirun, ok};

/// `compare --tiny` on one process, one rayon thread, into `out`.
fn alone(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .env("RAYON_NUM_THREADS", "1")
        .args(args)
        .output()
        .unwrap();
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
}

#[test]
fn compare_dealt_to_processes_writes_the_tables_of_one_process() {
    let t = TempDir::new("mpi-compare");
    let sweep = ["compare", "--tiny", "--quiet", "--snr-db", "none,20"];
    let one = t.path("one");
    alone(&[&sweep[..], &["--out", s(&one)]].concat());
    let table = rows_without_times(&one.join("results.csv"));
    for ranks in [2, 3] {
        let out = t.path(&format!("r{ranks}"));
        let text = ok(
            mpirun(ranks, &[&sweep[..], &["--out", s(&out)]].concat()),
            "compare",
        );
        assert!(
            text.contains(&format!("dealt to {ranks} processes")),
            "{text}"
        );
        let runs = table.len() - 1;
        assert!(
            text.contains(&format!("{runs} of {runs} runs finished")),
            "{text}"
        );
        // The table on stdout holds every run once.
        let printed = text.lines().filter(|l| l.starts_with("| paper")).count();
        assert_eq!(printed, runs, "{text}");
        assert_eq!(
            rows_without_times(&out.join("results.csv")),
            table,
            "-n {ranks}"
        );
        assert_eq!(
            crate::cli_support::listing(&out),
            crate::cli_support::listing(&one)
        );
    }
    // A shard dealt to processes runs the shard's problems.
    let shard = t.path("shard");
    alone(&[&sweep[..], &["--shard", "2/3", "--out", s(&shard)]].concat());
    let dealt = t.path("shard-dealt");
    ok(
        mpirun(
            2,
            &[&sweep[..], &["--shard", "2/3", "--out", s(&dealt)]].concat(),
        ),
        "compare --shard",
    );
    assert_eq!(
        rows_without_times(&dealt.join("results.csv")),
        rows_without_times(&shard.join("results.csv"))
    );
    // An existing folder without --force: every process stops before running.
    let e = mpirun(2, &[&sweep[..], &["--out", s(&one)]].concat());
    assert_one_line_error(&e, &["one", "--force"]);
    // Merging is one process's job: the message says so, and nothing else.
    let e = mpirun(
        2,
        &["compare", "--merge", s(&shard), "--out", s(&t.path("m"))],
    );
    assert_one_line_error(
        &e,
        &[
            "rdlidar compare --merge runs on one process",
            "run it without mpirun",
        ],
    );
    assert!(!t.path("m").exists());
}
