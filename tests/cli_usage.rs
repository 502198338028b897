//! Usage errors and help of the lidar subcommands (`simulate`, `forward`, `adjoint`, `dottest`,
//! `bench`): status 2 naming the flag, and an example in every `--help`.

use crate::cli_support::{rdlidar, stderr, stdout};

#[test]
fn usage_errors_exit_with_status_two_and_name_the_flag() {
    let out = rdlidar(&[
        "simulate",
        "--scene",
        "paper",
        "--size",
        "4x5",
        "--pulse-len",
        "50",
        "--out",
        "x",
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--size"));
    let out = rdlidar(&["bench", "--repeats", "0"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--repeats"));
    for sub in ["simulate", "forward", "adjoint", "dottest", "bench"] {
        let out = rdlidar(&[sub, "--help"]);
        assert!(out.status.success());
        assert!(stdout(&out).contains("Example"), "{sub} --help");
    }
}
