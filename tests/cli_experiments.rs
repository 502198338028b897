//! `rdlidar demo` (also the command with no subcommand) and `rdlidar compare`, run as a user
//! would in their tiny modes: output files, table contents, existing folders, config files, bad
//! flags and Ctrl-C.

use std::path::Path;
use std::process::{Command, Output, Stdio};

use crate::cli_support::{listing, rdlidar, s, stderr, stdout, TempDir};

fn rdlidar_in(dir: Option<&Path>, args: &[&str]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rdlidar"));
    c.args(args);
    if let Some(d) = dir {
        c.current_dir(d);
    }
    c.output().expect("the binary runs")
}

/// The CSV as a header and rows of fields (no field of these runs is quoted).
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect::<Vec<_>>())
        .collect();
    (header, rows)
}

fn field<'a>(header: &[String], row: &'a [String], name: &str) -> &'a str {
    let i = header.iter().position(|h| h == name).unwrap();
    &row[i]
}

fn is_png(path: &Path) -> bool {
    std::fs::read(path).is_ok_and(|b| b.starts_with(b"\x89PNG\r\n\x1a\n") && b.len() > 1000)
}

/// Checks the tables of a finished experiment with `runs` rows; returns the CSV.
fn check_tables(dir: &Path, runs: usize) -> (Vec<String>, Vec<Vec<String>>) {
    let (header, rows) = read_csv(&dir.join("results.csv"));
    assert_eq!(
        header.join(","),
        rdlidar::report::experiment::CSV_COLUMNS.join(","),
        "CSV header"
    );
    assert_eq!(rows.len(), runs, "CSV rows");
    for r in &rows {
        assert_eq!(r.len(), header.len(), "{r:?}");
        assert_eq!(field(&header, r, "status"), "ok", "{r:?}");
        let num = |name: &str| -> f64 { field(&header, r, name).parse().unwrap() };
        let pct = num("exact_pct");
        assert!((0.0..=100.0).contains(&pct), "{r:?}");
        let rel = num("relative_error");
        assert!(rel.is_finite() && rel >= 0.0, "{r:?}");
        let rmse = num("depth_rmse_bins");
        assert!(rmse.is_finite() && rmse >= 0.0, "{r:?}");
        let t = num("time_s");
        assert!(t.is_finite() && t >= 0.0, "{r:?}");
        let exact: usize = field(&header, r, "exact").parse().unwrap();
        let lit: usize = field(&header, r, "lit").parse().unwrap();
        assert!(exact <= lit && lit > 0, "{r:?}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap();
    assert_eq!(json["rows"].as_array().unwrap().len(), runs);
    assert_eq!(json["finished_runs"], runs);
    assert_eq!(json["interrupted"], false);
    let md = std::fs::read_to_string(dir.join("results.md")).unwrap();
    assert_eq!(md.lines().count(), runs + 2, "{md}");
    assert!(dir.join("config.toml").is_file());
    assert!(!dir.join("results.csv.partial").exists());
    assert!(!dir.join("results.jsonl.partial").exists());
    (header, rows)
}

#[test]
fn no_subcommand_runs_the_tiny_demo_and_writes_tables_and_figures() {
    let dir = TempDir::new("demo");
    let out = dir.path("out");
    let res = rdlidar(&["--tiny", "--out", s(&out), "--quiet"]);
    assert!(res.status.success(), "{}", stderr(&res));
    let (header, rows) = check_tables(&out, 27);
    // Every solver at each of the three pulse lengths, across the three regimes.
    let solvers: std::collections::BTreeSet<&str> =
        rows.iter().map(|r| field(&header, r, "solver")).collect();
    assert_eq!(solvers.len(), 9, "{solvers:?}");
    let regimes: std::collections::BTreeSet<&str> =
        rows.iter().map(|r| field(&header, r, "regime")).collect();
    assert_eq!(
        regimes.into_iter().collect::<Vec<_>>(),
        ["compressive", "redundant"]
    );
    // The model-based solver recovers the tiny scene exactly at K_p = 1000 (redundant).
    let mb = rows
        .iter()
        .find(|r| {
            field(&header, r, "solver") == "model-based" && field(&header, r, "pulse_len") == "1000"
        })
        .unwrap();
    assert_eq!(field(&header, mb, "exact_pct"), "100.0");
    for kp in [100, 300, 1000] {
        assert!(
            is_png(&out.join(format!("depth_kp{kp}.png"))),
            "depth_kp{kp}.png"
        );
    }
    assert!(is_png(&out.join("error_vs_time.png")));
    // The table on stdout: the header and one line per run; --quiet leaves stderr empty.
    let text = stdout(&res);
    assert!(
        text.contains("| solver ") && text.contains(" exact depth |"),
        "{text}"
    );
    assert_eq!(text.lines().filter(|l| l.starts_with("| ")).count(), 28);
    assert!(text.contains("27 of 27 runs finished"), "{text}");
    assert!(stderr(&res).is_empty(), "{}", stderr(&res));
}

#[test]
fn an_existing_output_folder_is_refused_without_force() {
    let dir = TempDir::new("force");
    let out = dir.path("out");
    let args = [
        "demo",
        "--tiny",
        "--pulse-lens",
        "300",
        "--solvers",
        "backprojection-debiased,model-based",
        "--out",
        s(&out),
        "--quiet",
    ];
    let res = rdlidar(&args);
    assert!(res.status.success(), "{}", stderr(&res));
    check_tables(&out, 2);
    let before = std::fs::read(out.join("results.csv")).unwrap();

    let res = rdlidar(&args);
    assert_eq!(res.status.code(), Some(1));
    let err = stderr(&res);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with("error: ") && err.contains(s(&out)) && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read(out.join("results.csv")).unwrap(), before);

    // With --force the files are replaced; other files are left alone.
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let mut forced = args.to_vec();
    forced.push("--force");
    let res = rdlidar(&forced);
    assert!(res.status.success(), "{}", stderr(&res));
    check_tables(&out, 2);
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
}

#[test]
fn with_no_arguments_the_demo_refuses_an_existing_out_folder() {
    // The real default path: `rdlidar` in a folder whose out/ is not empty stops at once.
    let dir = TempDir::new("noargs");
    std::fs::create_dir(dir.path("out")).unwrap();
    std::fs::write(dir.path("out/keep.txt"), "x").unwrap();
    let res = rdlidar_in(Some(&dir.0), &[]);
    assert_eq!(res.status.code(), Some(1));
    let err = stderr(&res);
    assert!(
        err.starts_with("error: out: the output folder exists") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read_dir(dir.path("out")).unwrap().count(), 1);
}

#[test]
fn compare_tiny_sweeps_every_regime_and_writes_its_figures() {
    let dir = TempDir::new("compare");
    let out = dir.path("cmp");
    let res = rdlidar(&["compare", "--tiny", "--out", s(&out), "--quiet"]);
    assert!(res.status.success(), "{}", stderr(&res));
    // 3 pulse lengths x 2 seeds x 2 noise levels x 9 solvers.
    let (header, rows) = check_tables(&out, 108);
    let regimes: std::collections::BTreeSet<&str> =
        rows.iter().map(|r| field(&header, r, "regime")).collect();
    assert_eq!(regimes.len(), 3, "{regimes:?}");
    let seeds: std::collections::BTreeSet<&str> =
        rows.iter().map(|r| field(&header, r, "seed")).collect();
    assert_eq!(seeds.into_iter().collect::<Vec<_>>(), ["0", "10"]);
    let snrs: std::collections::BTreeSet<&str> =
        rows.iter().map(|r| field(&header, r, "snr_db")).collect();
    assert_eq!(snrs.into_iter().collect::<Vec<_>>(), ["", "20.0"]);
    for r in &rows {
        assert_eq!(field(&header, r, "critical_pulse_len"), "211");
        assert_eq!(field(&header, r, "precision"), "f64");
    }
    // In the redundant regime without noise, least squares recovers the scene.
    let cgls = rows
        .iter()
        .find(|r| {
            field(&header, r, "solver") == "cgls"
                && field(&header, r, "pulse_len") == "800"
                && field(&header, r, "snr_db").is_empty()
        })
        .unwrap();
    let rel: f64 = field(&header, cgls, "relative_error").parse().unwrap();
    assert!(rel < 1e-3, "{cgls:?}");
    for f in ["pareto.png", "phase_noise-free.png", "phase_20db.png"] {
        assert!(is_png(&out.join(f)), "{f}");
    }
    let summary = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        summary.contains("critical K_p = 211") && summary.contains("## 20 dB"),
        "{summary}"
    );
    assert!(summary.contains("| model-based |"), "{summary}");
}

#[test]
fn a_config_file_describes_the_experiment_and_flags_override_it() {
    let dir = TempDir::new("config");
    let cfg = dir.path("exp.toml");
    std::fs::write(
        &cfg,
        "seed = 5\nprecision = \"f64\"\n\n[demo]\nsize = \"6x6x6\"\npulse_lens = [150, 400]\n\
         solvers = [\"cgls\", \"model-based\", \"fista\"]\nmax_iter = { cgls = 7 }\n",
    )
    .unwrap();
    let out = dir.path("a");
    let res = rdlidar(&[
        "demo",
        "--config",
        s(&cfg),
        "--solvers",
        "cgls,model-based",
        "--out",
        s(&out),
        "--quiet",
    ]);
    assert!(res.status.success(), "{}", stderr(&res));
    let (header, rows) = check_tables(&out, 4);
    for r in &rows {
        assert_eq!(field(&header, r, "size"), "6x6x6");
        assert_eq!(field(&header, r, "seed"), "5");
        assert_eq!(field(&header, r, "precision"), "f64");
    }
    let cgls: Vec<&Vec<String>> = rows
        .iter()
        .filter(|r| field(&header, r, "solver") == "cgls")
        .collect();
    assert_eq!(cgls.len(), 2);
    for r in cgls {
        assert_eq!(field(&header, r, "max_iter"), "7");
        let it: usize = field(&header, r, "iterations").parse().unwrap();
        assert!(it <= 7);
    }
    // The written config.toml reproduces the run: same rows but the times.
    let again = dir.path("b");
    let res = rdlidar(&[
        "demo",
        "--config",
        s(&out.join("config.toml")),
        "--out",
        s(&again),
        "--quiet",
    ]);
    assert!(res.status.success(), "{}", stderr(&res));
    let (_, rows2) = check_tables(&again, 4);
    let strip = |rows: &[Vec<String>]| -> Vec<Vec<String>> {
        let t = header.iter().position(|h| h == "time_s").unwrap();
        rows.iter()
            .map(|r| {
                let mut r = r.clone();
                r[t].clear();
                r
            })
            .collect()
    };
    assert_eq!(strip(&rows), strip(&rows2));
}

/// Starts a long tiny sweep (2 pulse lengths x 200 seeds x 2 solvers) into `out` and waits
/// until its staging folder holds a few finished rows.
fn start_long_sweep(dir: &TempDir, out: &Path) -> std::process::Child {
    let child = Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args([
            "compare",
            "--tiny",
            "--pulse-lens",
            "50,800",
            "--snr-db",
            "none",
            "--seeds",
            "200",
            "--solvers",
            "cgls,model-based",
            "--out",
            s(out),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let partial = dir
        .path(&format!(".cmp.staging-{}", child.id()))
        .join("results.csv.partial");
    let start = std::time::Instant::now();
    loop {
        let lines = std::fs::read_to_string(&partial).map_or(0, |t| t.lines().count());
        if lines >= 4 {
            break;
        }
        assert!(
            start.elapsed().as_secs() < 60,
            "no rows after a minute ({lines} lines)"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child
}

fn interrupt(child: &std::process::Child) {
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

#[test]
fn an_interrupted_sweep_keeps_its_finished_rows() {
    let dir = TempDir::new("ctrlc");
    let out = dir.path("cmp");
    let child = start_long_sweep(&dir, &out);
    interrupt(&child);
    let res = child.wait_with_output().unwrap();
    assert_eq!(res.status.code(), Some(130), "{}", stderr(&res));
    let err = stderr(&res);
    assert!(err.contains("stopping after the current run"), "{err}");
    let (_, rows) = read_csv(&out.join("results.csv"));
    assert!(rows.len() >= 3 && rows.len() < 800, "{} rows", rows.len());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(json["interrupted"], true);
    assert_eq!(json["planned_runs"], 800);
    assert_eq!(json["rows"].as_array().unwrap().len(), rows.len());
    assert!(is_png(&out.join("pareto.png")));
    // The complete set, and nothing else: no partial files, no staging folder.
    assert_eq!(dir.listing(), vec!["cmp"]);
    assert!(!listing(&out)
        .iter()
        .any(|f| f.contains("partial") || f.contains("tmp")));
}

#[test]
fn a_second_interrupt_leaves_nothing_new() {
    for trial in 0..3 {
        let dir = TempDir::new("ctrlc2");
        let out = dir.path("cmp");
        let child = start_long_sweep(&dir, &out);
        interrupt(&child);
        std::thread::sleep(std::time::Duration::from_millis(5 * trial));
        interrupt(&child);
        let res = child.wait_with_output().unwrap();
        assert_eq!(res.status.code(), Some(130), "{}", stderr(&res));
        let left = dir.listing();
        // Either the set was already complete when the second interrupt came, or nothing.
        assert!(
            left.is_empty() || (left == vec!["cmp"] && out.join("results.json").is_file()),
            "trial {trial}: {left:?}"
        );
    }
}

// SIGTERM (`kill`, a batch system; `mpirun` sends it to every process of a job it stops, a
// second before SIGKILL) killed the sweep at once and left its hidden staging folder beside
// the output folder. It now quits at once leaving nothing new, with status 143.
#[test]
fn a_termination_leaves_nothing_new() {
    let dir = TempDir::new("sigterm");
    let out = dir.path("cmp");
    let child = start_long_sweep(&dir, &out);
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let res = child.wait_with_output().unwrap();
    assert_eq!(res.status.code(), Some(143), "{}", stderr(&res));
    assert!(stderr(&res).contains("terminated"), "{}", stderr(&res));
    assert!(dir.listing().is_empty(), "{:?}", dir.listing());
}

#[test]
fn progress_is_logged_as_lines_when_stderr_is_not_a_terminal() {
    let dir = TempDir::new("lines");
    let out = dir.path("out");
    let res = rdlidar(&[
        "--tiny",
        "--pulse-lens",
        "300",
        "--solvers",
        "cgls,tv",
        "--out",
        s(&out),
    ]);
    assert!(res.status.success(), "{}", stderr(&res));
    let err = stderr(&res);
    assert!(err.contains("simulating 8x8x8, K_p 300, seed 0"), "{err}");
    assert!(err.contains("run 2/2: tv, K_p 300"), "{err}");
    assert!(!err.contains('\r') && !err.contains('\x1b'), "{err:?}");
}

/// Runs a failing command and returns its stderr, checking the exit status, that the message
/// is one `error:` line and that no output folder was created.
fn fails(args: &[&str], code: i32, dir: &TempDir) -> String {
    let res = rdlidar(args);
    let err = stderr(&res);
    assert_eq!(res.status.code(), Some(code), "{args:?}: {err}");
    assert!(err.starts_with("error: "), "{err}");
    assert!(!dir.path("out").exists(), "{args:?} created its folder");
    err.lines().next().unwrap().to_string()
}

#[test]
fn unknown_solvers_are_refused_with_the_valid_names() {
    let dir = TempDir::new("badsolver");
    let out = dir.path("out");
    let err = fails(
        &[
            "demo",
            "--tiny",
            "--solvers",
            "cgls,lasso",
            "--out",
            s(&out),
        ],
        2,
        &dir,
    );
    assert!(
        err.contains("--solvers") && err.contains("\"lasso\"") && err.contains("model-based"),
        "{err}"
    );
    let err = fails(
        &[
            "compare",
            "--tiny",
            "--max-iter",
            "magic=3",
            "--out",
            s(&out),
        ],
        2,
        &dir,
    );
    assert!(
        err.contains("--max-iter") && err.contains("\"magic\""),
        "{err}"
    );
    let err = fails(
        &["demo", "--tiny", "--solvers", "cgls,cgls", "--out", s(&out)],
        1,
        &dir,
    );
    assert!(err.contains("--solvers: cgls is listed twice"), "{err}");
}

#[test]
fn scene_lists_and_presets_are_checked() {
    let dir = TempDir::new("badscene");
    let out = dir.path("out");
    let err = fails(
        &[
            "compare",
            "--tiny",
            "--scene",
            "paper,glass",
            "--out",
            s(&out),
        ],
        2,
        &dir,
    );
    assert!(
        err.contains("--scene") && err.contains("\"glass\""),
        "{err}"
    );
    let err = fails(
        &[
            "compare",
            "--tiny",
            "--scene",
            "paper,paper",
            "--out",
            s(&out),
        ],
        1,
        &dir,
    );
    assert!(err.contains("--scene: paper is listed twice"), "{err}");
    let err = fails(
        &["compare", "--quick", "--research", "--out", s(&out)],
        2,
        &dir,
    );
    assert!(
        err.contains("--research") && err.contains("--quick"),
        "{err}"
    );
}

#[test]
fn impossible_sizes_are_refused_before_any_work() {
    let dir = TempDir::new("badsize");
    let out = dir.path("out");
    let err = fails(&["demo", "--size", "0x8x8", "--out", s(&out)], 2, &dir);
    assert!(
        err.contains("--size") && err.contains("at least 1"),
        "{err}"
    );
    let err = fails(&["demo", "--size", "8x8", "--out", s(&out)], 2, &dir);
    assert!(err.contains("MxNxKS"), "{err}");
    let err = fails(&["demo", "--size", "5000x10x10", "--out", s(&out)], 2, &dir);
    assert!(err.contains("--size") && err.contains("4096"), "{err}");
    let err = fails(
        &["compare", "--size", "4000x4000x100", "--out", s(&out)],
        1,
        &dir,
    );
    assert!(
        err.contains("--size") && err.contains("bytes") && err.contains("more than the"),
        "{err}"
    );
    // The demo's depth figure must fit: 2000 columns by 10 maps do not.
    let err = fails(&["demo", "--size", "10x2000x10", "--out", s(&out)], 1, &dir);
    assert!(
        err.contains("--size") && err.contains("depth figure"),
        "{err}"
    );
    let err = fails(
        &[
            "demo",
            "--size",
            "100x100x40",
            "--pulse-lens",
            "2000000000",
            "--out",
            s(&out),
        ],
        1,
        &dir,
    );
    assert!(
        err.contains("--pulse-lens") && err.contains("bytes"),
        "{err}"
    );
    let err = fails(&["demo", "--pulse-lens", "10,0", "--out", s(&out)], 2, &dir);
    assert!(err.contains("--pulse-lens"), "{err}");
    let err = fails(&["compare", "--seeds", "0", "--out", s(&out)], 2, &dir);
    assert!(err.contains("--seeds"), "{err}");
    let err = fails(&["compare", "--tiny", "--quick", "--out", s(&out)], 2, &dir);
    assert!(err.contains("--quick") && err.contains("--tiny"), "{err}");
    let err = fails(&["demo", "--out", s(&dir.path("missing/out"))], 1, &dir);
    assert!(err.contains("does not exist"), "{err}");
}

#[test]
fn unreadable_or_invalid_config_files_are_named_in_the_error() {
    let dir = TempDir::new("badconfig");
    let out = dir.path("out");
    let missing = dir.path("missing.toml");
    let err = fails(
        &["demo", "--config", s(&missing), "--out", s(&out)],
        1,
        &dir,
    );
    assert!(
        err.contains(s(&missing)) && err.contains("cannot read the config file"),
        "{err}"
    );
    for (text, expect) in [
        ("[demo]\npulse_lens = [100,\n", "line "),
        (
            "[demo]\nsolvers = [\"cgls\", \"lasso\"]\n",
            "unknown solver \"lasso\"",
        ),
        ("[demo]\ncolour = \"red\"\n", "colour"),
        ("[demo]\nsnr_db = \"loud\"\n", "snr_db"),
        ("precision = \"f16\"\n", "f16"),
    ] {
        let cfg = dir.path("bad.toml");
        std::fs::write(&cfg, text).unwrap();
        let err = fails(&["demo", "--config", s(&cfg), "--out", s(&out)], 1, &dir);
        assert!(
            err.contains(s(&cfg)) && err.contains(expect),
            "{text}: {err}"
        );
    }
    // A valid file with an impossible value names the key and the flag.
    let cfg = dir.path("big.toml");
    std::fs::write(&cfg, "[demo]\nseeds = 0\n").unwrap();
    let err = fails(&["demo", "--config", s(&cfg), "--out", s(&out)], 1, &dir);
    assert!(
        err.contains("--seeds") && err.contains("`seeds` in") && err.contains("at least 1"),
        "{err}"
    );
}
