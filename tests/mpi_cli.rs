//! The command line under `mpirun -n R` (feature `mpi`): `forward`, `adjoint`, `dottest` and
//! `reconstruct` split the pixel rows over R = 2 and 3 processes and give the one-process
//! outputs (depth maps identical, scenes and measurements within round-off), for int8 codes,
//! packed codes of two ADCs and seeded codes (streamed), and `reconstruct` of tiled arrays deals
//! the tiles to the processes; bad inputs end every process with one error line from the first
//! and status 1, and no output; a process killed while solving ends the job with no output.
//!
//! Needs `mpirun` (Debian: openmpi-bin); as root, OpenMPI's run-as-root variables are set here.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use ndarray::ArrayD;
use ndarray_npy::read_npy;

use crate::cli_support::{assert_one_line_error, rdlidar, s, stderr, stdout, TempDir};

/// How long one job may take before it is killed.
const JOB_LIMIT: Duration = Duration::from_secs(120);

/// The binary under `mpirun -q -n ranks` (one rayon thread per process, as root and
/// oversubscribed if need be), its output captured.
pub(crate) fn mpirun_command(ranks: usize) -> Command {
    let mut c = Command::new("mpirun");
    c.args([
        "-q",
        "-n",
        &ranks.to_string(),
        env!("CARGO_BIN_EXE_rdlidar"),
    ])
    .env("RAYON_NUM_THREADS", "1")
    .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
    .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    .env("OMPI_MCA_rmaps_base_oversubscribe", "1")
    .stdout(Stdio::piped())
    .stderr(Stdio::piped());
    c
}

/// Runs the binary under `mpirun -q -n ranks` ([`mpirun_command`]), killed after
/// [`JOB_LIMIT`].
pub(crate) fn mpirun(ranks: usize, args: &[&str]) -> Output {
    let mut child = mpirun_command(ranks)
        .args(args)
        .spawn()
        .expect("mpirun (Debian: openmpi-bin) runs");
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > JOB_LIMIT {
            let _ = child.kill();
            panic!("mpirun -n {ranks} {args:?} did not end in {JOB_LIMIT:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

pub(crate) fn ok(out: Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what}: {}\n{}",
        stdout(&out),
        stderr(&out)
    );
    stdout(&out)
}

fn load_f64(p: &Path) -> ArrayD<f64> {
    read_npy(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// max |a − b| / max |a|.
fn rel_diff(a: &ArrayD<f64>, b: &ArrayD<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    let scale = a
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// An acquisition written by `simulate`: its folder and codes file.
struct Acquisition {
    dir: std::path::PathBuf,
    codes: &'static str,
    ks: usize,
}

fn simulate(tmp: &TempDir, name: &str, extra: &[&str], codes: &'static str) -> Acquisition {
    let dir = tmp.path(name);
    let mut args = vec!["simulate", "--scene", "paper", "--quiet", "--out", s(&dir)];
    args.extend_from_slice(extra);
    ok(rdlidar(&args), name);
    Acquisition { dir, codes, ks: 16 }
}

impl Acquisition {
    fn file(&self, name: &str) -> String {
        s(&self.dir.join(name)).to_string()
    }
}

#[test]
fn forward_adjoint_dottest_and_reconstruct_under_mpirun_give_the_one_process_outputs() {
    let tmp = TempDir::new("mpi-cli");
    let sets = [
        // int8 codes of one ADC, compressive (auto goes through TV on the depth map).
        simulate(
            &tmp,
            "int8",
            &["--size", "12x12x16", "--pulse-len", "200"],
            "codes.npy",
        ),
        // Packed codes of two ADCs, 13 rows (bands of unequal height).
        simulate(
            &tmp,
            "adcs",
            &[
                "--size",
                "13x10x16",
                "--pulse-len",
                "300",
                "--adcs",
                "2",
                "--codes-format",
                "packed",
            ],
            "codes.npy",
        ),
        // Seeded codes, regenerated block by block by each process for its rows.
        simulate(
            &tmp,
            "seeded",
            &[
                "--size",
                "13x10x16",
                "--pulse-len",
                "1500",
                "--codes-format",
                "seed",
            ],
            "meta.json",
        ),
    ];
    for acq in &sets {
        let name = acq.dir.file_name().unwrap().to_string_lossy().into_owned();
        let stream: &[&str] = if acq.codes == "meta.json" {
            &["--stream-codes"]
        } else {
            &[]
        };
        let ks = acq.ks.to_string();
        let run = |ranks: usize, tag: &str| -> Vec<String> {
            let out = |what: &str| s(&tmp.path(&format!("{name}-{tag}-{what}.npy"))).to_string();
            let files = [
                "--pulse".to_string(),
                acq.file("pulse.npy"),
                "--codes".to_string(),
                acq.file(acq.codes),
            ];
            let mut lines = Vec::new();
            let mut go = |args: Vec<String>| {
                let mut all: Vec<&str> = args.iter().map(String::as_str).collect();
                all.extend_from_slice(stream);
                lines.push(ok(
                    mpirun(ranks, &all),
                    &format!("{name} -n {ranks} {}", args[0]),
                ));
            };
            let mut forward = vec!["forward".to_string()];
            forward.extend(files.iter().cloned());
            forward.extend([
                "--scene".into(),
                acq.file("scene.npy"),
                "--out".into(),
                out("y"),
            ]);
            go(forward);
            let measured = [
                "--meas".to_string(),
                acq.file("meas.npy"),
                "--depth-bins".to_string(),
                ks.clone(),
            ];
            let mut adjoint = vec!["adjoint".to_string(), "--debiased".to_string()];
            adjoint.extend(files.iter().cloned());
            adjoint.extend(measured.iter().cloned());
            adjoint.extend(["--out".into(), out("xt")]);
            go(adjoint);
            let mut dottest = vec!["dottest".to_string()];
            dottest.extend(files.iter().cloned());
            dottest.extend(["--depth-bins".into(), ks.clone()]);
            go(dottest);
            for solver in ["auto", "cgls"] {
                let mut rec = vec!["reconstruct".to_string(), "--quiet".to_string()];
                rec.extend(files.iter().cloned());
                rec.extend(measured.iter().cloned());
                rec.extend([
                    "--solver".into(),
                    solver.into(),
                    "--max-iter".into(),
                    "40".into(),
                    "--out-depth".into(),
                    out(&format!("{solver}-depth")),
                    "--out-scene".into(),
                    out(&format!("{solver}-scene")),
                ]);
                go(rec);
            }
            lines
        };
        let one = run(1, "n1");
        for ranks in [2, 3] {
            let tag = format!("n{ranks}");
            let lines = run(ranks, &tag);
            let file = |t: &str, what: &str| tmp.path(&format!("{name}-{t}-{what}.npy"));
            // Measurements and backprojections: the same up to the order of the sums.
            for (what, tol) in [("y", 1e-13), ("xt", 1e-12)] {
                let d = rel_diff(&load_f64(&file("n1", what)), &load_f64(&file(&tag, what)));
                assert!(d <= tol, "{name} -n {ranks}: {what} differs by {d:e}");
            }
            for solver in ["auto", "cgls"] {
                let depth = |t: &str| -> ArrayD<i32> {
                    read_npy(file(t, &format!("{solver}-depth"))).unwrap()
                };
                assert_eq!(
                    depth("n1"),
                    depth(&tag),
                    "{name} -n {ranks} {solver}: depth maps"
                );
                let scene = |t: &str| load_f64(&file(t, &format!("{solver}-scene")));
                let d = rel_diff(&scene("n1"), &scene(&tag));
                assert!(
                    d <= 1e-8,
                    "{name} -n {ranks} {solver}: scenes differ by {d:e}"
                );
            }
            // Every command says how it split the rows; the reconstructions' reports (method,
            // iterations, termination, applications) are the one process's.
            let note = format!("pixel rows split over {ranks} processes");
            for (a, b) in one.iter().zip(&lines) {
                assert!(b.contains(&note), "{name} -n {ranks}: {b}");
                if a.starts_with("reconstruct") {
                    let report = |l: &str| l.split("; ").nth(1).map(str::to_string);
                    assert_eq!(report(a), report(b), "{name} -n {ranks}");
                }
            }
        }
    }
}

#[test]
fn simulate_under_mpirun_generates_each_processs_rows_and_writes_the_one_process_files() {
    let tmp = TempDir::new("mpi-cli-simulate");
    let run = |ranks: usize, extra: &[&str]| -> std::path::PathBuf {
        let dir = tmp.path(&format!("n{ranks}{}", extra.join("")));
        let mut args = vec![
            "simulate",
            "--scene",
            "transparent",
            "--size",
            "13x10x16",
            "--pulse-len",
            "300",
            "--codes-format",
            "seed",
            "--snr-db",
            "20",
            "--out",
            s(&dir),
        ];
        args.extend_from_slice(extra);
        let line = ok(mpirun(ranks, &args), &format!("simulate -n {ranks}"));
        if ranks > 1 {
            assert!(
                line.contains(&format!("simulated by {ranks} processes")),
                "{line}"
            );
        }
        dir
    };
    for extra in [&[][..], &["--adcs", "2"][..]] {
        let one = run(1, extra);
        for ranks in [2, 3] {
            let many = run(ranks, extra);
            for same in ["scene.npy", "pulse.npy", "meta.json"] {
                let (a, b) = (
                    std::fs::read(one.join(same)).unwrap(),
                    std::fs::read(many.join(same)).unwrap(),
                );
                assert!(a == b, "-n {ranks} {extra:?}: {same} differs");
            }
            let d = rel_diff(
                &load_f64(&one.join("meas.npy")),
                &load_f64(&many.join("meas.npy")),
            );
            assert!(
                d <= 1e-13,
                "-n {ranks} {extra:?}: measurements differ by {d:e}"
            );
            assert!(!many.join("codes.npy").exists());
        }
    }
}

#[test]
fn bad_inputs_under_mpirun_end_every_process_with_one_error_line_and_no_output() {
    let tmp = TempDir::new("mpi-cli-faults");
    let acq = simulate(
        &tmp,
        "a",
        &["--size", "5x6x8", "--pulse-len", "100"],
        "codes.npy",
    );
    let (depth, scene) = (tmp.path("d.npy"), tmp.path("x.npy"));
    let reconstruct = |extra: &[&str], ks: &str| -> Vec<String> {
        let mut v: Vec<String> = [
            "reconstruct",
            "--solver",
            "cgls",
            "--pulse",
            &acq.file("pulse.npy"),
            "--codes",
            &acq.file("codes.npy"),
            "--meas",
            &acq.file("meas.npy"),
            "--depth-bins",
            ks,
            "--out-depth",
            s(&depth),
            "--out-scene",
            s(&scene),
        ]
        .iter()
        .map(|a| a.to_string())
        .collect();
        v.extend(extra.iter().map(|a| a.to_string()));
        v
    };
    let truncated = tmp.path("truncated.npy");
    let bytes = std::fs::read(acq.dir.join("codes.npy")).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() - 7]).unwrap();
    let wrong_truth = tmp.path("truth.npy");
    std::fs::copy(acq.dir.join("pulse.npy"), &wrong_truth).unwrap();
    // A NaN in process 1's rows of a scene: process 1 alone reads those rows.
    let nan_scene = tmp.path("nan.npy");
    let mut x: ndarray::Array3<f64> = read_npy(acq.dir.join("scene.npy")).unwrap();
    x[[4, 1, 2]] = f64::NAN;
    ndarray_npy::write_npy(&nan_scene, &x).unwrap();
    let forward_nan: Vec<String> = [
        "forward",
        "--pulse",
        &acq.file("pulse.npy"),
        "--codes",
        &acq.file("codes.npy"),
        "--scene",
        s(&nan_scene),
        "--out",
        s(&depth),
    ]
    .iter()
    .map(|a| a.to_string())
    .collect();
    let cases: Vec<(usize, Vec<String>, Vec<&str>)> = vec![
        (
            2,
            forward_nan,
            vec!["process 1: ", "nan.npy", "NaN at index (4, 1, 2)"],
        ),
        // Measurements of another K: every process finds it.
        (3, reconstruct(&[], "9"), vec!["meas.npy", "K_p + K_s − 1"]),
        // A truncated codes file.
        (
            2,
            {
                let mut v = reconstruct(&[], "8");
                v[6] = s(&truncated).to_string();
                v
            },
            vec!["truncated.npy", "truncated"],
        ),
        // A bad true scene, read by the first process only.
        (
            2,
            reconstruct(&["--truth", s(&wrong_truth)], "8"),
            vec!["truth.npy"],
        ),
        // More processes than pixel rows.
        (
            6,
            reconstruct(&[], "8"),
            vec!["mpirun -n 6", "5 pixel rows"],
        ),
        // More processes than tiles.
        (
            5,
            reconstruct(&["--tiles", "3x6"], "8"),
            vec!["mpirun -n 5", "2 tiles of 3x6"],
        ),
        // The block-diagonal operator of tiles is one process's.
        (
            2,
            [
                "forward",
                "--pulse",
                &acq.file("pulse.npy"),
                "--codes",
                &acq.file("codes.npy"),
            ]
            .iter()
            .map(|a| a.to_string())
            .chain([
                "--scene".into(),
                acq.file("scene.npy"),
                "--tiles".into(),
                "2x3".into(),
            ])
            .chain(["--out".into(), s(&depth).to_string()])
            .collect(),
            vec!["rdlidar forward --tiles runs on one process"],
        ),
        // simulate splits only seeded codes.
        (
            2,
            [
                "simulate",
                "--scene",
                "paper",
                "--size",
                "4x4x4",
                "--pulse-len",
                "10",
                "--out",
            ]
            .iter()
            .map(|a| a.to_string())
            .chain([s(&depth).to_string()])
            .collect(),
            vec!["rdlidar simulate without --codes-format seed runs on one process"],
        ),
        // Continuous depths run in one process.
        (
            2,
            reconstruct(&["--kernel", "triangle"], "8"),
            vec!["--kernel", "in one process", "without mpirun"],
        ),
        // A command that does not split its work.
        (
            2,
            ["info", "--size", "4x4x4", "--pulse-len", "10"]
                .iter()
                .map(|a| a.to_string())
                .collect(),
            vec!["rdlidar info runs on one process", "2 processes"],
        ),
    ];
    for (ranks, args, needles) in cases {
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = mpirun(ranks, &argv);
        assert_one_line_error(&out, &needles);
        assert!(
            !depth.exists() && !scene.exists(),
            "{argv:?}: an output was written"
        );
        let leftovers: Vec<String> = crate::cli_support::listing(&tmp.0)
            .into_iter()
            .filter(|f| !["a", "truncated.npy", "truth.npy", "nan.npy"].contains(&f.as_str()))
            .collect();
        assert!(leftovers.is_empty(), "{argv:?}: left {leftovers:?}");
    }
}

#[test]
fn reconstruct_deals_the_tiles_of_a_tiled_array_to_the_processes() {
    let tmp = TempDir::new("mpi-cli-tiles");
    let tiles = ["--tiles", "5x6"];
    let sets = [
        simulate(
            &tmp,
            "int8",
            &["--size", "23x17x16", "--pulse-len", "400", "--tiles", "5x6"],
            "codes.npy",
        ),
        simulate(
            &tmp,
            "seeded",
            &[
                "--size",
                "23x17x16",
                "--pulse-len",
                "400",
                "--tiles",
                "5x6",
                "--codes-format",
                "seed",
            ],
            "meta.json",
        ),
    ];
    for acq in &sets {
        let name = acq.dir.file_name().unwrap().to_string_lossy().into_owned();
        for solver in ["auto", "cgls"] {
            let run = |ranks: usize| -> (String, ArrayD<i32>, ArrayD<f64>) {
                let (d, x) = (
                    tmp.path(&format!("{name}-{solver}-{ranks}-d.npy")),
                    tmp.path(&format!("{name}-{solver}-{ranks}-x.npy")),
                );
                let (pulse, codes, meas) = (
                    acq.file("pulse.npy"),
                    acq.file(acq.codes),
                    acq.file("meas.npy"),
                );
                let mut args = vec![
                    "reconstruct",
                    "--quiet",
                    "--pulse",
                    &pulse,
                    "--codes",
                    &codes,
                    "--meas",
                    &meas,
                    "--depth-bins",
                    "16",
                    "--solver",
                    solver,
                    "--out-depth",
                    s(&d),
                    "--out-scene",
                    s(&x),
                ];
                args.extend_from_slice(&tiles);
                let line = ok(mpirun(ranks, &args), &format!("{name} {solver} -n {ranks}"));
                (line, read_npy(&d).unwrap(), load_f64(&x))
            };
            let (one, depth, scene) = run(1);
            // 15 tiles on 2, 4 and 15 processes (one tile each).
            for ranks in [2, 4, 15] {
                let (line, d, x) = run(ranks);
                assert_eq!(d, depth, "{name} {solver} -n {ranks}: depth maps");
                let diff = rel_diff(&scene, &x);
                assert!(
                    diff <= 1e-12,
                    "{name} {solver} -n {ranks}: scenes differ by {diff:e}"
                );
                assert!(
                    line.contains(&format!("tiles dealt to {ranks} processes")),
                    "{line}"
                );
                // The tiles' methods and applications are the one process's.
                let summary = |l: &str| -> Vec<String> {
                    l.split("; ").skip(1).take(1).map(str::to_string).collect()
                };
                let methods = |l: &str| {
                    l.split(": solver ")
                        .nth(1)
                        .and_then(|r| r.split(" (").next())
                        .map(str::to_string)
                };
                assert_eq!(summary(&line), summary(&one), "{name} {solver} -n {ranks}");
                assert_eq!(methods(&line), methods(&one), "{name} {solver} -n {ranks}");
            }
        }
    }
    // Continuous depths: dealt tiles come back without their returns, so the job is refused
    // before any work (one process fits them).
    let acq = &sets[0];
    let (pulse, codes, meas) = (
        acq.file("pulse.npy"),
        acq.file(acq.codes),
        acq.file("meas.npy"),
    );
    let d = tmp.path("kernel-d.npy");
    let mut args = vec![
        "reconstruct",
        "--pulse",
        &pulse,
        "--codes",
        &codes,
        "--meas",
        &meas,
        "--depth-bins",
        "16",
        "--solver",
        "auto",
        "--kernel",
        "triangle",
        "--out-depth",
        s(&d),
        "--out-scene",
    ];
    let x = tmp.path("kernel-x.npy");
    args.push(s(&x));
    args.extend_from_slice(&tiles);
    crate::cli_support::assert_one_line_error(
        &mpirun(2, &args),
        &["--kernel", "in one process", "without mpirun"],
    );
    assert!(!d.exists() && !x.exists());
}

/// The process ids of the rank `rank` processes whose environment holds `mark`.
fn ranks_marked(mark: &str, rank: usize) -> Vec<u32> {
    let want = format!("OMPI_COMM_WORLD_RANK={rank}");
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| {
            let env = std::fs::read(format!("/proc/{pid}/environ")).unwrap_or_default();
            let vars: Vec<&[u8]> = env.split(|&b| b == 0).collect();
            vars.contains(&mark.as_bytes()) && vars.contains(&want.as_bytes())
        })
        .collect()
}

#[test]
fn a_process_that_dies_ends_the_job_without_output() {
    let tmp = TempDir::new("mpi-cli-dies");
    let acq = simulate(
        &tmp,
        "a",
        &[
            "--size",
            "60x60x40",
            "--pulse-len",
            "5000",
            "--codes-format",
            "packed",
        ],
        "codes.npy",
    );
    let (depth, scene) = (tmp.path("d.npy"), tmp.path("x.npy"));
    let mark = format!("RDLIDAR_TEST_MARK={}", std::process::id());
    let mut child = mpirun_command(2)
        .args([
            "reconstruct",
            "--solver",
            "fista",
            "--max-iter",
            "100000",
            "--quiet",
        ])
        .args([
            "--pulse",
            &acq.file("pulse.npy"),
            "--codes",
            &acq.file("codes.npy"),
        ])
        .args(["--meas", &acq.file("meas.npy"), "--depth-bins", "40"])
        .args(["--out-depth", s(&depth), "--out-scene", s(&scene)])
        .env("RDLIDAR_TEST_MARK", std::process::id().to_string())
        .spawn()
        .expect("mpirun runs");
    // Wait for process 1 to be solving, then kill it.
    let start = Instant::now();
    let victim = loop {
        if let Some(&pid) = ranks_marked(&mark, 1).first() {
            break pid;
        }
        assert!(start.elapsed() < JOB_LIMIT, "process 1 never started");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the job ended before process 1 started"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the job ended before the kill"
    );
    let killed = Command::new("kill")
        .args(["-9", &victim.to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let killed_at = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if killed_at.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("the job did not end within 60 s of a process's death");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(!status.success(), "the job of a dead process succeeded");
    assert!(
        ranks_marked(&mark, 0).is_empty(),
        "process 0 outlived the job"
    );
    assert!(!depth.exists() && !scene.exists(), "an output was written");
    assert_eq!(crate::cli_support::listing(&tmp.0), vec!["a".to_string()]);
}

/// `auto` under `mpirun` runs every stage one process runs: on the paper scene at 16×16×8, K_p
/// 150 and 15 dB one process keeps coarse-to-fine (the coarse grid needs the whole scene's
/// codes, which the processes gather), and 2 and 3 processes (the second split's bands of 6, 5
/// and 5 rows cut the coarse grid's 2×2 blocks) keep it too, with the one process's depth map.
#[test]
fn auto_under_mpirun_keeps_the_coarse_grid_stage_and_the_one_process_depth_map() {
    let tmp = TempDir::new("mpi-auto-coarse");
    let acq = simulate(
        &tmp,
        "coarse",
        &[
            "--size",
            "16x16x8",
            "--pulse-len",
            "150",
            "--snr-db",
            "15",
            "--seed",
            "0",
        ],
        "codes.npy",
    );
    let run = |ranks: usize| -> (String, ArrayD<i32>) {
        let depth = tmp.path(&format!("coarse-depth-{ranks}.npy"));
        let scene = tmp.path(&format!("coarse-scene-{ranks}.npy"));
        let args = [
            "reconstruct",
            "--pulse",
            &acq.file("pulse.npy"),
            "--codes",
            &acq.file(acq.codes),
            "--meas",
            &acq.file("meas.npy"),
            "--depth-bins",
            "8",
            "--solver",
            "auto",
            "--out-depth",
            s(&depth),
            "--out-scene",
            s(&scene),
        ];
        let text = if ranks == 1 {
            ok(rdlidar(&args), "one process")
        } else {
            ok(mpirun(ranks, &args), &format!("-n {ranks}"))
        };
        (text, read_npy(&depth).unwrap())
    };
    let (one, depth) = run(1);
    assert!(one.contains("solver coarse-to-fine"), "{one}");
    for ranks in [2, 3] {
        let (text, d) = run(ranks);
        assert!(text.contains("solver coarse-to-fine"), "-n {ranks}: {text}");
        assert_eq!(d, depth, "-n {ranks}: depth maps");
    }
}
