//! `rdlidar compare --shard k/n` and `compare --merge`: a sweep cut into the shards of a job
//! array and joined again gives the tables of one run (run times apart), and a merge of
//! folders that are not every shard of one sweep is refused with one line and writes nothing.

use std::path::Path;

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
