//! `rdlidar compare --shard k/n` and `compare --merge`: a sweep cut into the shards of a job
//! array and joined again gives the tables of one run (run times apart), and a merge of
//! folders that are not every shard of one sweep, of rows that are not the sweep's runs, or into
//! one of the shards' folders is refused with one line and writes nothing.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{json, Value};

use crate::cli_support::{
    assert_one_line_error, assert_usage_error, rdlidar, rows_without_times, s, stderr, stdout,
    TempDir,
};

fn ok(args: &[&str]) -> String {
    let out = rdlidar(args);
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    stdout(&out)
}

/// `config.toml` without its `out` line.
fn config_without_out(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join("config.toml"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with("out = "))
        .map(String::from)
        .collect()
}

/// Runs `compare --tiny` whole into `whole` and as shards 1/3 … 3/3 into `sh1` … `sh3`.
fn whole_and_shards(t: &TempDir, extra: &[&str]) {
    let quiet = ["compare", "--tiny", "--quiet"];
    let whole = t.path("whole");
    ok(&[&quiet[..], extra, &["--out", s(&whole)]].concat());
    for k in 1..=3 {
        let out = t.path(&format!("sh{k}"));
        let shard = format!("{k}/3");
        let text = ok(&[&quiet[..], extra, &["--shard", &shard, "--out", s(&out)]].concat());
        assert!(text.contains(&format!("in shard {shard}")), "{text}");
        let json = std::fs::read_to_string(out.join("results.json")).unwrap();
        assert!(json.contains(&format!("\"shard\": \"{shard}\"")), "{json}");
    }
}

#[test]
fn shards_merged_give_the_tables_of_one_run() {
    let t = TempDir::new("shards-merge");
    whole_and_shards(&t, &["--seed", "3"]);
    let whole = t.path("whole");
    let table = rows_without_times(&whole.join("results.csv"));
    // Every run in exactly one shard, none empty at this size.
    let mut from_shards = Vec::new();
    for k in 1..=3 {
        let rows = rows_without_times(&t.path(&format!("sh{k}")).join("results.csv"));
        assert!(rows.len() > 1, "shard {k} ran nothing");
        from_shards.extend(rows.into_iter().skip(1));
    }
    let mut expected: Vec<String> = table[1..].to_vec();
    expected.sort();
    from_shards.sort();
    assert_eq!(from_shards, expected);
    // Merged in any order of the folders: the rows in the order of one run.
    let merged = t.path("merged");
    let (a, b, c) = (t.path("sh3"), t.path("sh1"), t.path("sh2"));
    let text = ok(&[
        "compare",
        "--merge",
        s(&a),
        s(&b),
        s(&c),
        "--out",
        s(&merged),
    ]);
    let runs = table.len() - 1;
    assert!(
        text.contains(&format!("merged 3 shards: {runs} of {runs} runs")),
        "{text}"
    );
    assert_eq!(rows_without_times(&merged.join("results.csv")), table);
    assert_eq!(config_without_out(&merged), config_without_out(&whole));
    let mut names = crate::cli_support::listing(&merged);
    let mut expected_names = crate::cli_support::listing(&whole);
    names.sort();
    expected_names.sort();
    assert_eq!(names, expected_names);
    let json = std::fs::read_to_string(merged.join("results.json")).unwrap();
    assert!(!json.contains("\"shard\""), "{json}");
    assert!(
        json.contains(&format!("\"planned_runs\": {runs}")),
        "{json}"
    );
}

#[test]
fn a_merge_of_what_is_not_every_shard_of_one_sweep_is_refused() {
    let t = TempDir::new("shards-bad");
    whole_and_shards(&t, &[]);
    let other = t.path("other");
    ok(&[
        "compare",
        "--tiny",
        "--quiet",
        "--seed",
        "9",
        "--shard",
        "3/3",
        "--out",
        s(&other),
    ]);
    let out = t.path("merged");
    let [sh1, sh2, sh3, whole] = ["sh1", "sh2", "sh3", "whole"].map(|n| t.path(n));
    let missing = t.path("nowhere");
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (vec![s(&sh1), s(&sh2)], vec!["--merge", "missing shard 3/3"]),
        (
            vec![s(&sh1), s(&sh1), s(&sh2), s(&sh3)],
            vec!["--merge", "both hold shard 1/3"],
        ),
        (
            vec![s(&sh1), s(&sh2), s(&other)],
            vec!["--merge", "another sweep", "config.toml"],
        ),
        (vec![s(&whole)], vec!["results.json", "not of a shard"]),
        (vec![s(&sh1), s(&missing)], vec!["nowhere", "results.json"]),
    ];
    for (dirs, needles) in cases {
        let args = [&["compare", "--merge"][..], &dirs, &["--out", s(&out)]].concat();
        assert_one_line_error(&rdlidar(&args), &needles);
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    // The sweep is the shards': no flag describing one goes with --merge.
    let e = rdlidar(&["compare", "--merge", s(&sh1), "--tiny", "--out", s(&out)]);
    assert_one_line_error(&e, &["--merge", "only", "--out"]);
    let e = rdlidar(&[
        "--seed",
        "4",
        "compare",
        "--merge",
        s(&sh1),
        "--out",
        s(&out),
    ]);
    assert_one_line_error(&e, &["--merge", "only", "--out"]);
    assert!(!out.exists());
    for bad in ["0/3", "4/3", "2", "x/y"] {
        let e = rdlidar(&["compare", "--tiny", "--shard", bad, "--out", s(&out)]);
        assert_usage_error(&e, &["--shard", bad]);
    }
    let e = rdlidar(&["compare", "--merge", s(&sh1), "--shard", "1/3"]);
    assert_usage_error(&e, &["--merge", "--shard"]);
    // An existing folder is refused without --force and keeps what it held.
    let e = rdlidar(&[
        "compare",
        "--merge",
        s(&sh1),
        s(&sh2),
        s(&sh3),
        "--out",
        s(&whole),
    ]);
    assert_one_line_error(&e, &["whole", "--force"]);
    assert!(whole.join("results.csv").is_file());
}

/// Runs `compare --tiny --quiet` (with `extra` flags) as shards 1/n … n/n into `sh1` … `shn`.
fn shards(t: &TempDir, n: usize, extra: &[&str]) -> Vec<PathBuf> {
    (1..=n)
        .map(|k| {
            let out = t.path(&format!("sh{k}"));
            let shard = format!("{k}/{n}");
            let quiet = ["compare", "--tiny", "--quiet"];
            ok(&[&quiet[..], extra, &["--shard", &shard, "--out", s(&out)]].concat());
            out
        })
        .collect()
}

/// The 3 problems (3 pulse lengths, one seed, noise-free) of `compare --tiny` in 2 shards.
const SMALL: [&str; 4] = ["--seeds", "1", "--snr-db", "none"];

/// A copy named `name` of the shard folder `dir`'s `results.json` and `config.toml`, the
/// results edited by `edit`.
fn forged(t: &TempDir, dir: &Path, name: &str, edit: impl FnOnce(&mut Value)) -> PathBuf {
    let copy = t.path(name);
    std::fs::create_dir(&copy).unwrap();
    std::fs::copy(dir.join("config.toml"), copy.join("config.toml")).unwrap();
    let text = std::fs::read_to_string(dir.join("results.json")).unwrap();
    let mut json: Value = serde_json::from_str(&text).unwrap();
    edit(&mut json);
    let text = serde_json::to_string_pretty(&json).unwrap();
    std::fs::write(copy.join("results.json"), text).unwrap();
    copy
}

/// `compare --merge dirs --out out` fails with one line holding every one of `needles` and
/// writes nothing.
fn merge_refused(dirs: &[&PathBuf], out: &Path, needles: &[&str]) {
    let args: Vec<&str> = ["compare", "--merge"]
        .into_iter()
        .chain(dirs.iter().map(|d| s(d)))
        .chain(["--out", s(out)])
        .collect();
    assert_one_line_error(&rdlidar(&args), needles);
    assert!(!out.exists(), "{args:?} wrote {}", out.display());
}

#[test]
fn more_shards_than_problems_are_refused_before_any_work() {
    let t = TempDir::new("shards-count");
    let out = t.path("out");
    // compare --tiny: 3 pulse lengths, 2 seeds, 2 noise levels: 12 problems.
    for shard in ["1/18446744073709551615", "1/4294967296", "13/13"] {
        let e = rdlidar(&["compare", "--tiny", "--shard", shard, "--out", s(&out)]);
        assert_one_line_error(&e, &["--shard", shard, "12 problems", "at most 12 shards"]);
        assert!(!out.exists(), "{shard}");
    }
    // A shard's results.json claiming such a count.
    let sh = shards(&t, 2, &SMALL);
    let bad = forged(&t, &sh[0], "count", |j| {
        j["shard"] = json!("1/18446744073709551615");
    });
    merge_refused(
        &[&bad, &sh[1]],
        &out,
        &["count", "results.json", "at most 3 shards"],
    );
}

#[test]
fn a_merge_refuses_times_that_are_not_seconds() {
    let t = TempDir::new("shards-times");
    let sh = shards(&t, 2, &SMALL);
    let out = t.path("merged");
    for (name, seconds) in [("huge", 1e308), ("negative", -1.0)] {
        let bad = forged(&t, &sh[0], name, |j| j["sweep_seconds"] = json!(seconds));
        merge_refused(
            &[&bad, &sh[1]],
            &out,
            &[name, "results.json", "sweep_seconds"],
        );
    }
    let bad = forged(&t, &sh[1], "slow", |j| {
        j["rows"][2]["time_s"] = json!(1e300)
    });
    merge_refused(
        &[&sh[0], &bad],
        &out,
        &["slow", "results.json", "row 3", "time_s"],
    );
}

#[test]
fn a_merge_into_one_of_its_shards_is_refused() {
    let t = TempDir::new("shards-into");
    let sh = shards(&t, 2, &SMALL);
    let before = std::fs::read(sh[0].join("results.json")).unwrap();
    let link = t.path("link");
    std::os::unix::fs::symlink(&sh[0], &link).unwrap();
    let dotted = sh[0].join(".");
    for out in [&sh[0], &link, &dotted] {
        let e = rdlidar(&[
            "compare",
            "--merge",
            s(&sh[0]),
            s(&sh[1]),
            "--out",
            s(out),
            "--force",
        ]);
        assert_one_line_error(&e, &["--out", "is the shard folder"]);
    }
    assert_eq!(std::fs::read(sh[0].join("results.json")).unwrap(), before);
    assert_eq!(t.listing(), ["link", "sh1", "sh2"]);
}

#[test]
fn a_merge_refuses_rows_that_are_not_runs_of_the_sweep() {
    let t = TempDir::new("shards-rows");
    let sh = shards(&t, 2, &SMALL);
    let out = t.path("merged");
    type Edit = fn(&mut Value);
    // Shard 1's rows 1 to 3 are backprojection, backprojection-debiased and cgls on one problem.
    let cases: [(&str, Edit, &[&str]); 7] = [
        (
            "kp",
            |j| j["rows"][1]["pulse_len"] = json!(123456),
            &["row 2", "K_p 123456", "not a run of shard 1/2"],
        ),
        (
            "seed",
            |j| j["rows"][0]["seed"] = json!(12345),
            &["row 1", "seed 12345", "not a run"],
        ),
        (
            "solver",
            |j| j["rows"][0]["solver"] = json!("iht"),
            &["row 1", "iht on", "not a run"],
        ),
        (
            "budget",
            |j| j["rows"][2]["max_iter"] = json!(5),
            &["row 3", "max_iter", "not the sweep's"],
        ),
        (
            "size",
            |j| j["rows"][0]["size"] = json!("7x7x7"),
            &["row 1", "size", "not the sweep's"],
        ),
        (
            "planned",
            |j| j["planned_runs"] = json!(99),
            &["planned_runs is 99"],
        ),
        (
            "missing",
            |j| {
                j["rows"].as_array_mut().unwrap().pop();
            },
            &["rows", "was not interrupted"],
        ),
    ];
    for (name, edit, needles) in cases {
        let bad = forged(&t, &sh[0], name, edit);
        let needles = [&[name, "results.json"][..], needles].concat();
        merge_refused(&[&bad, &sh[1]], &out, &needles);
    }
}

#[test]
fn seeds_beyond_toml_integers_round_trip_through_config_toml() {
    let t = TempDir::new("shards-seed");
    let seed = u64::MAX.to_string();
    let sh = shards(&t, 2, &[&SMALL[..], &["--seed", &seed]].concat());
    let text = std::fs::read_to_string(sh[0].join("config.toml")).unwrap();
    assert!(text.contains(&format!("seed = \"{seed}\"")), "{text}");
    let merged = t.path("merged");
    let text = ok(&[
        "compare",
        "--merge",
        s(&sh[0]),
        s(&sh[1]),
        "--out",
        s(&merged),
    ]);
    assert!(text.contains("27 of 27 runs"), "{text}");
    // The merged config.toml describes the same sweep, seed included.
    let again = t.path("again");
    let config = merged.join("config.toml");
    ok(&[
        "compare",
        "--quiet",
        "--config",
        s(&config),
        "--out",
        s(&again),
    ]);
    assert_eq!(
        rows_without_times(&again.join("results.csv")),
        rows_without_times(&merged.join("results.csv"))
    );
}

#[test]
fn settings_config_toml_cannot_hold_are_refused_before_any_run() {
    use std::os::unix::ffi::OsStrExt;
    let t = TempDir::new("shards-toml");
    let out = t.path("out");
    let e = rdlidar(&[
        "compare",
        "--tiny",
        "--max-iter",
        "cgls=9223372036854775808",
        "--out",
        s(&out),
    ]);
    assert_usage_error(&e, &["--max-iter", "cgls", "9223372036854775807"]);
    let bad = t.0.join(std::ffi::OsStr::from_bytes(b"bad\xff"));
    let e = Command::new(env!("CARGO_BIN_EXE_rdlidar"))
        .args(["compare", "--tiny", "--quiet", "--out"])
        .arg(&bad)
        .output()
        .unwrap();
    assert_one_line_error(&e, &["--out", "UTF-8"]);
    assert!(t.listing().is_empty(), "{:?}", t.listing());
    // The largest budget is written and read back.
    ok(&[
        "compare",
        "--tiny",
        "--quiet",
        "--solvers",
        "cgls",
        "--pulse-lens",
        "50",
        "--max-iter",
        "cgls=9223372036854775807",
        "--out",
        s(&out),
    ]);
    let config = out.join("config.toml");
    let text = std::fs::read_to_string(&config).unwrap();
    assert!(text.contains("cgls = 9223372036854775807"), "{text}");
    let again = t.path("again");
    ok(&[
        "compare",
        "--quiet",
        "--config",
        s(&config),
        "--out",
        s(&again),
    ]);
}
