//! `rdlidar compare` under `mpirun -n R` (feature `mpi`): the sweep's problems dealt to the
//! processes give the tables of one process (run times apart), alone or within a shard; a
//! folder that cannot be written ends every process with one error line and nothing run; Ctrl-C
//! on `mpirun` leaves nothing new.

use std::process::Command;
use std::time::{Duration, Instant};

use crate::cli_support::{assert_one_line_error, rows_without_times, s, stderr, TempDir};
use crate::mpi_cli::{mpirun, mpirun_command, ok};

/// `compare --tiny` on one process, one rayon thread, into `out`.
fn alone(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .env("RAYON_NUM_THREADS", "1")
        .args(args)
        .output()
        .unwrap();
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
}

// Ctrl-C on `mpirun -n 2 compare` (mpirun sends every process SIGTERM, and SIGKILL a second
// later) ended the job with status 1, no message, and the hidden staging folder of the first
// process left beside the output folder. The processes now quit at once on SIGTERM and leave
// nothing new.
#[test]
fn ctrl_c_on_mpirun_leaves_no_staging_folder() {
    let t = TempDir::new("mpi-ctrlc");
    let out = t.path("cmp");
    let mut child = mpirun_command(2)
        .args([
            "compare",
            "--tiny",
            "--quiet",
            "--pulse-lens",
            "50,800",
            "--snr-db",
            "none",
            "--seeds",
            "200",
            "--solvers",
            "cgls,model-based",
            "--out",
            s(&out),
        ])
        .spawn()
        .expect("mpirun (Debian: openmpi-bin) runs");
    // Wait for rows in the first process's staging folder.
    let start = Instant::now();
    loop {
        let rows = std::fs::read_dir(&t.0)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().starts_with(".cmp.staging-"))
            .map(|e| {
                std::fs::read_to_string(e.path().join("results.csv.partial"))
                    .map_or(0, |text| text.lines().count())
            })
            .max()
            .unwrap_or(0);
        if rows >= 3 {
            break;
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the sweep ended before the interrupt"
        );
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no rows after a minute"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let interrupted = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if interrupted.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("the job did not end within 60 s of Ctrl-C");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let res = child.wait_with_output().unwrap();
    assert!(!res.status.success(), "{}", stderr(&res));
    assert!(t.listing().is_empty(), "{:?}", t.listing());
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
